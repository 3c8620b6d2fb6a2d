//! Random specs for the geometry test: FSMs with random behaviours, arcs and
//! conditions of every length, and small systems of agents, components and links.

use embodied::spec::model::{
    Agent, Behaviour, BehaviourKind, Buffer, Device, DeviceKind, Fsm, FsmArc, Function, Group,
    Link, Policy, Spec, Subsystem, SubsystemKind, Target,
};
use proptest::prelude::*;

pub(crate) fn ident(prefix: &'static str) -> impl Strategy<Value = String> {
    "[a-z][a-z0-9_]{0,14}".prop_map(move |s| format!("{prefix}{s}"))
}

/// A condition: short (`true`, `p`, `!p`) or long (up to six atoms joined by `&&`
/// and `||`).
pub(crate) fn condition() -> impl Strategy<Value = String> {
    let atom = ("!?", "[a-z][a-z_]{0,15}").prop_map(|(n, a)| format!("{n}{a}"));
    prop_oneof![
        Just("true".to_owned()),
        atom.clone(),
        prop::collection::vec((atom, any::<bool>()), 2..7).prop_map(|atoms| {
            let mut s = String::new();
            for (k, (a, and)) in atoms.iter().enumerate() {
                if k > 0 {
                    s.push_str(if *and { " && " } else { " || " });
                }
                s.push_str(a);
            }
            s
        }),
    ]
}

pub(crate) fn behaviour_kind() -> impl Strategy<Value = BehaviourKind> {
    prop_oneof![Just(BehaviourKind::Repeat), Just(BehaviourKind::While)]
}

pub(crate) fn subsystem(
    name: String,
    kind: SubsystemKind,
    behaviours: Vec<Behaviour>,
    fsm: Fsm,
) -> Subsystem {
    Subsystem {
        name,
        kind,
        period_ms: 10.0,
        doc: None,
        memory: Vec::new(),
        inputs: Vec::new(),
        outputs: Vec::new(),
        predicates: Vec::new(),
        relations: Vec::new(),
        functions: Vec::new(),
        behaviours,
        fsm,
    }
}

/// One subsystem with a random FSM: 1 to 8 behaviours, up to 2n + 2 arcs between
/// any two of them (self-loops and parallel arcs included), short and long
/// conditions, a random initial behaviour (sometimes none) and random finals.
pub(crate) fn random_fsm_subsystem(k: usize) -> impl Strategy<Value = Subsystem> {
    (1usize..=8)
        .prop_flat_map(move |n| {
            (
                prop::collection::vec((ident("b"), behaviour_kind(), condition()), n),
                prop::collection::vec((0..n, 0..n, condition()), 0..=2 * n + 2),
                prop::option::weighted(0.9, 0..n),
                prop::collection::vec(any::<bool>(), n),
                ident("s"),
            )
        })
        .prop_map(move |(bs, arcs, initial, finals, name)| {
            let names: Vec<String> = bs
                .iter()
                .enumerate()
                .map(|(i, (n, _, _))| format!("{n}{i}"))
                .collect();
            let behaviours = bs
                .into_iter()
                .zip(&names)
                .map(|((_, kind, terminal), name)| Behaviour {
                    name: name.clone(),
                    kind,
                    functions: Vec::new(),
                    terminal,
                    doc: None,
                })
                .collect();
            let fsm = Fsm {
                initial: initial.map(|i| names[i].clone()),
                arcs: arcs
                    .into_iter()
                    .map(|(a, b, when)| FsmArc {
                        from: names[a].clone(),
                        to: names[b].clone(),
                        when,
                    })
                    .collect(),
                finals: names
                    .iter()
                    .zip(finals)
                    .filter(|(_, f)| *f)
                    .map(|(n, _)| n.clone())
                    .collect(),
            };
            subsystem(
                format!("{name}{k}"),
                SubsystemKind::Control,
                behaviours,
                fsm,
            )
        })
}

/// A spec of one agent with one to three random FSMs.
pub(crate) fn random_fsms() -> impl Strategy<Value = Spec> {
    prop::collection::vec(0usize..1, 1..=3)
        .prop_flat_map(|v| {
            v.iter()
                .enumerate()
                .map(|(k, _)| random_fsm_subsystem(k))
                .collect::<Vec<_>>()
        })
        .prop_map(|subsystems| Spec {
            name: "random".to_owned(),
            doc: None,
            agents: vec![Agent {
                name: "a".to_owned(),
                doc: None,
                subsystems,
                devices: Vec::new(),
            }],
            links: Vec::new(),
            deployments: Vec::new(),
            ros2: None,
            contracts: None,
            timing: None,
        })
}

/// The plan of a random agent: its subsystems (kind 0..3, name) and devices
/// (effector?, name).
type AgentPlan = (Vec<(u8, String)>, Vec<(bool, String)>);

/// The plan of a random system: indices are taken modulo what they select from.
#[derive(Clone, Debug)]
pub(crate) struct SystemPlan {
    agents: Vec<AgentPlan>,
    /// Links: (from component, to component, buffer name, queue bound).
    links: Vec<(usize, usize, String, Option<usize>)>,
    /// Memory buffers: (subsystem, name).
    memory: Vec<(usize, String)>,
    /// Functions: (subsystem, reads, target: 0 memory, 1 common, else an output
    /// group, writes).
    functions: Vec<(usize, Vec<usize>, usize, Vec<usize>)>,
    /// Behaviours: (subsystem, functions, terminal).
    behaviours: Vec<(usize, Vec<usize>, String)>,
}

pub(crate) fn system_plan() -> impl Strategy<Value = SystemPlan> {
    let sub = (0u8..3, ident(""));
    let dev = (any::<bool>(), ident(""));
    let agent = (
        prop::collection::vec(sub, 1..=3),
        prop::collection::vec(dev, 0..=2),
    );
    let idx = || 0usize..64;
    (
        prop::collection::vec(agent, 1..=4),
        prop::collection::vec(
            (
                idx(),
                idx(),
                "[a-z][a-z0-9_]{0,12}",
                prop::option::weighted(0.3, 1usize..16),
            ),
            0..=10,
        ),
        prop::collection::vec((idx(), ident("")), 0..=6),
        prop::collection::vec(
            (
                idx(),
                prop::collection::vec(idx(), 0..=4),
                idx(),
                prop::collection::vec(idx(), 0..=3),
            ),
            0..=8,
        ),
        prop::collection::vec(
            (idx(), prop::collection::vec(idx(), 0..=3), condition()),
            0..=6,
        ),
    )
        .prop_map(
            |(agents, links, memory, functions, behaviours)| SystemPlan {
                agents,
                links,
                memory,
                functions,
                behaviours,
            },
        )
}

pub(crate) fn buffer(name: &str) -> Buffer {
    Buffer {
        name: name.to_owned(),
        ty: "f64".to_owned(),
        doc: None,
    }
}

/// Add `buf` to the group towards `peer` (made if missing).
pub(crate) fn add_to_group(groups: &mut Vec<Group>, peer: &str, buf: &str) {
    match groups.iter_mut().find(|g| g.peer == peer) {
        Some(g) => {
            if !g.buffers.iter().any(|b| b.name == buf) {
                g.buffers.push(buffer(buf));
            }
        }
        None => groups.push(Group {
            peer: peer.to_owned(),
            buffers: vec![buffer(buf)],
            peers: Vec::new(),
        }),
    }
}

/// Build the spec a plan describes. It need not pass the checker: the diagrams draw
/// whatever resolves.
pub(crate) fn build_system(plan: &SystemPlan) -> Spec {
    let (mut agents, comps) = planned_agents(&plan.agents);
    let links = planned_links(&mut agents, &comps, &plan.links);
    let mut subs: Vec<&mut Subsystem> = agents
        .iter_mut()
        .flat_map(|a| a.subsystems.iter_mut())
        .collect();
    add_memory(&mut subs, &plan.memory);
    add_functions(&mut subs, &plan.functions);
    add_behaviours(&mut subs, &plan.behaviours);
    Spec {
        name: "system".to_owned(),
        doc: None,
        agents,
        links,
        deployments: Vec::new(),
        ros2: None,
        contracts: None,
        timing: None,
    }
}

/// A component of a planned system: its agent, its index among the agent's
/// subsystems or among its devices, its name.
type Component = (usize, Option<usize>, Option<usize>, String);

/// The agents a plan describes, each subsystem in one behaviour `idle`, and
/// their components in order.
fn planned_agents(plans: &[AgentPlan]) -> (Vec<Agent>, Vec<Component>) {
    let kinds = [
        SubsystemKind::Control,
        SubsystemKind::VirtualEffector,
        SubsystemKind::VirtualReceptor,
    ];
    let mut agents: Vec<Agent> = Vec::new();
    let mut comps: Vec<Component> = Vec::new();
    for (a, (subs, devs)) in plans.iter().enumerate() {
        let mut agent = Agent {
            name: format!("a{a}"),
            doc: None,
            subsystems: Vec::new(),
            devices: Vec::new(),
        };
        for (k, (kind, name)) in subs.iter().enumerate() {
            let name = format!("{}{name}{a}{k}", ["c", "e", "r"][*kind as usize]);
            comps.push((a, Some(agent.subsystems.len()), None, name.clone()));
            let behaviours = vec![Behaviour {
                name: "idle".to_owned(),
                kind: BehaviourKind::While,
                functions: Vec::new(),
                terminal: "false".to_owned(),
                doc: None,
            }];
            let fsm = Fsm {
                initial: Some("idle".to_owned()),
                arcs: Vec::new(),
                finals: Vec::new(),
            };
            agent
                .subsystems
                .push(subsystem(name, kinds[*kind as usize], behaviours, fsm));
        }
        for (k, (effector, name)) in devs.iter().enumerate() {
            let name = format!("{}{name}{a}{k}", if *effector { "E" } else { "R" });
            comps.push((a, None, Some(agent.devices.len()), name.clone()));
            agent.devices.push(Device {
                name,
                kind: if *effector {
                    DeviceKind::Effector
                } else {
                    DeviceKind::Receptor
                },
                period_ms: 1.0,
                doc: None,
                inputs: Vec::new(),
                outputs: Vec::new(),
            });
        }
        agents.push(agent);
    }
    (agents, comps)
}

/// The links a plan describes between `comps` (a link of a component to
/// itself is left out), each buffer added to both ends' groups.
fn planned_links(
    agents: &mut [Agent],
    comps: &[Component],
    plans: &[(usize, usize, String, Option<usize>)],
) -> Vec<Link> {
    let mut links = Vec::new();
    for (f, t, buf, queue) in plans {
        let (f, t) = (f % comps.len(), t % comps.len());
        if f == t {
            continue;
        }
        let (fname, tname) = (comps[f].3.clone(), comps[t].3.clone());
        for (me, peer, out) in [(f, &tname, true), (t, &fname, false)] {
            let (a, s, d) = (comps[me].0, comps[me].1, comps[me].2);
            let groups = match (s, d, out) {
                (Some(s), _, true) => &mut agents[a].subsystems[s].outputs,
                (Some(s), _, false) => &mut agents[a].subsystems[s].inputs,
                (_, Some(d), true) => &mut agents[a].devices[d].outputs,
                (_, Some(d), false) => &mut agents[a].devices[d].inputs,
                _ => unreachable!(),
            };
            add_to_group(groups, peer, buf);
        }
        links.push(Link {
            from: format!("{fname}.{tname}.{buf}"),
            to: format!("{tname}.{fname}.{buf}"),
            policy: queue.map_or(Policy::Sample, |bound| Policy::Queue { bound }),
        });
    }
    links
}

/// The memory buffers a plan describes, each once.
fn add_memory(subs: &mut [&mut Subsystem], plans: &[(usize, String)]) {
    let n = subs.len();
    for (s, name) in plans {
        let sub = &mut subs[s % n];
        if !sub.memory.iter().any(|b| &b.name == name) {
            sub.memory.push(buffer(name));
        }
    }
}

/// The distinct elements of `list` that `idx` selects (none of an empty list).
fn pick(list: &[String], idx: &[usize]) -> Vec<String> {
    let mut out: Vec<String> = Vec::new();
    if !list.is_empty() {
        for i in idx {
            let x = &list[i % list.len()];
            if !out.contains(x) {
                out.push(x.clone());
            }
        }
    }
    out
}

/// The functions a plan describes, reading and writing what their subsystem
/// has.
fn add_functions(subs: &mut [&mut Subsystem], plans: &[(usize, Vec<usize>, usize, Vec<usize>)]) {
    let n = subs.len();
    for (k, (s, reads, target, writes)) in plans.iter().enumerate() {
        let sub = &mut subs[s % n];
        let readable: Vec<String> = sub
            .memory
            .iter()
            .map(|b| b.name.clone())
            .chain(
                sub.inputs
                    .iter()
                    .flat_map(|g| g.buffers.iter().map(|b| format!("{}.{}", g.peer, b.name))),
            )
            .collect();
        let (target, writable) = match target % (2 + sub.outputs.len()) {
            0 => (
                Target::Memory,
                sub.memory.iter().map(|b| b.name.clone()).collect(),
            ),
            1 => (
                Target::Common,
                sub.memory.iter().map(|b| b.name.clone()).collect(),
            ),
            g => {
                let g = &sub.outputs[g - 2];
                (
                    Target::Output(g.peer.clone()),
                    g.buffers.iter().map(|b| b.name.clone()).collect::<Vec<_>>(),
                )
            }
        };
        sub.functions.push(Function {
            name: format!("f{k}"),
            target,
            reads: pick(&readable, reads),
            writes: pick(&writable, writes),
            doc: None,
        });
    }
}

/// The behaviours a plan describes, each reached from `idle` when its
/// terminal condition holds.
fn add_behaviours(subs: &mut [&mut Subsystem], plans: &[(usize, Vec<usize>, String)]) {
    let n = subs.len();
    for (k, (s, fs, terminal)) in plans.iter().enumerate() {
        let sub = &mut subs[s % n];
        let names: Vec<String> = sub.functions.iter().map(|f| f.name.clone()).collect();
        let functions = pick(&names, fs);
        let name = format!("b{k}");
        sub.fsm.arcs.push(FsmArc {
            from: "idle".to_owned(),
            to: name.clone(),
            when: terminal.clone(),
        });
        sub.behaviours.push(Behaviour {
            name,
            kind: BehaviourKind::Repeat,
            functions,
            terminal: terminal.clone(),
            doc: None,
        });
    }
}
