//! The spec of a fleet, generated from Rex's: Rex's agents a1 and a3 (of
//! `specs/rex.ron`) copied once per robot, each copy's components named with
//! the robot's index (`a1_3` holds `c1_3`, `e11_3`, `E1_3`...; `a3_3` holds
//! `c3_3`, `r31_3`, `R3_3`), its groups, reads, targets and links renamed
//! alike; and ONE ontology agent `a2` for the whole fleet, whose `c2`
//! dispatches plans to every robot. Nothing of a robot is copied by hand: a
//! change to Rex's spec is a change to every robot of the fleet. The
//! generated spec passes the same checker.
//!
//! The code of a copy is Rex's: its groups are named by the code's fields
//! (`e11`, `c1`), and the fleet's assembly aliases `e11_3` to `e11`
//! ([`embodied::spec::Assembly::alias`]).
//!
//! The fleet's `a2` ([`fleet_a2`]) is Rex's `a2` with its groups made fans
//! (`peers`: `c1_0` ... `c1_{M-1}`, agent-core's `Fan`, M fixed when the fleet
//! is built): Rex's links between `c2` and `c1` become, for robot `k`,
//! `c2.c1[k].desired_plan -> c1_k.c2.desired_plan` and `c1_k.c2.ack ->
//! c2.c1[k].ack` (and `outcome`, `progress`, `alive`), with Rex's policies.
//! Its memory, predicates, functions and FSM are those of
//! [`super::ontology`]: every robot's dispatch, one activation of Rex's `c2`
//! FSM per robot at each of its own (its behaviours `dispatch` and `done`).
//!
//! Deployments: `simulation` (everything in one process), `simulation_without_vo`
//! (without `r11_i` and `R1_i`), and `grouped_without_vo`: the shared world
//! (every platform and motion capture, which share the fleet's truth) with the
//! partner agents (`c2`, every `c3_i` and `r31_i`) in one process (never
//! restarted: a new one would put every platform back at its start), and the
//! robots' a1 parts in processes `robots_k` of `per_process` robots each,
//! launched over Zenoh by [`super::app`] (`fleet launch --deployment
//! grouped_without_vo`).

use embodied::spec::Report;
use embodied::spec::model::{
    Agent, Behaviour, BehaviourKind, Buffer, Deployment, Fsm, FsmArc, Function, Host, Link,
    Predicate, Process, Spec, Target,
};

/// The components of one robot (a1 and a3 of Rex), the template's names.
pub const PARTS: [&str; 8] = ["c1", "e11", "r11", "E1", "R1", "c3", "r31", "R3"];

/// The agents of Rex copied for every robot.
pub const AGENTS: [&str; 2] = ["a1", "a3"];

/// The fleet's one ontology agent and its control subsystem (Rex's names).
pub const ONTOLOGY: (&str, &str) = ("a2", "c2");

/// The name of part `name` of robot `robot`: `c1_3`.
pub fn robot_name(name: &str, robot: usize) -> String {
    format!("{name}_{robot}")
}

/// `name`, renamed for `robot` when it is one of [`PARTS`].
fn rename(name: &str, robot: usize) -> String {
    if PARTS.contains(&name) {
        robot_name(name, robot)
    } else {
        name.to_owned()
    }
}

/// A read `peer.buffer` (or a plain memory name) renamed for `robot`.
fn rename_read(read: &str, robot: usize) -> String {
    match read.split_once('.') {
        Some((peer, rest)) => format!("{}.{rest}", rename(peer, robot)),
        None => read.to_owned(),
    }
}

/// A link end `component.peer.buffer` renamed for `robot`: a robot's part
/// gets the robot's index (`c1_3.c2.ack`), the fleet's `c2` its fan's
/// element (`c2.c1[3].ack`).
fn rename_end(end: &str, robot: usize) -> String {
    let mut parts = end.splitn(3, '.');
    let (Some(c), Some(peer), Some(buffer)) = (parts.next(), parts.next(), parts.next()) else {
        return end.to_owned();
    };
    if c == ONTOLOGY.1 {
        return format!("{c}.{peer}[{robot}].{buffer}");
    }
    format!("{}.{}.{buffer}", rename(c, robot), rename(peer, robot))
}

/// The spec of a fleet of `robots` robots made from Rex's spec `rex`; the
/// grouped deployment puts `per_process` robots' a1 in each process.
pub fn fleet_spec(rex: &Spec, robots: usize, per_process: usize) -> Spec {
    let mut agents: Vec<Agent> = fleet_a2(rex, robots).into_iter().collect();
    let mut links = Vec::new();
    for i in 0..robots {
        agents.extend(robot_agents(rex, i));
        links.extend(rex.links.iter().map(|l| Link {
            from: rename_end(&l.from, i),
            to: rename_end(&l.to, i),
            policy: l.policy,
        }));
    }
    Spec {
        name: format!("rex_fleet_{robots}"),
        doc: Some(format!(
            "A fleet of {robots} Rex robots in one warehouse, generated from specs/rex.ron (rex-agent/src/fleet/spec.rs)."
        )),
        agents,
        links,
        deployments: deployments(robots, per_process),
        ros2: None,
        contracts: None,
        timing: None,
    }
}

/// Rex's agents a1, a2 and a3, copied for robot `i`.
fn robot_agents(rex: &Spec, i: usize) -> Vec<Agent> {
    let mut agents = Vec::new();
    for template in rex
        .agents
        .iter()
        .filter(|a| AGENTS.contains(&a.name.as_str()))
    {
        let mut a = template.clone();
        a.name = robot_name(&template.name, i);
        a.doc = template.doc.as_ref().map(|d| format!("Robot {i}: {d}"));
        for s in &mut a.subsystems {
            s.name = rename(&s.name, i);
            for g in s.inputs.iter_mut().chain(s.outputs.iter_mut()) {
                g.peer = rename(&g.peer, i);
            }
            for p in &mut s.predicates {
                p.reads = p.reads.iter().map(|r| rename_read(r, i)).collect();
            }
            for f in &mut s.functions {
                f.reads = f.reads.iter().map(|r| rename_read(r, i)).collect();
                if let Target::Output(peer) = &f.target {
                    f.target = Target::Output(rename(peer, i));
                }
            }
        }
        for d in &mut a.devices {
            d.name = rename(&d.name, i);
            for g in d.inputs.iter_mut().chain(d.outputs.iter_mut()) {
                g.peer = rename(&g.peer, i);
            }
        }
        agents.push(a);
    }
    agents
}

/// The fleet's one ontology agent: Rex's `a2` (`None` if Rex's spec has
/// none), its `c2`'s groups towards `c1` made fans of the `robots` robots'
/// `c1_k`, its memory, predicates, functions and FSM those of the fleet's
/// code ([`super::ontology::fleet_ontology_fsm`]).
pub fn fleet_a2(rex: &Spec, robots: usize) -> Option<Agent> {
    let (agent, c2) = ONTOLOGY;
    let mut a2 = rex.agents.iter().find(|a| a.name == agent)?.clone();
    a2.doc = Some(format!(
        "The fleet's ontology agent: one c2 dispatching to the {robots} robots' c1, each as Rex's a2 dispatches Rex ({})",
        a2.doc
            .as_deref()
            .unwrap_or("sends plans, waits for each acknowledgement")
    ));
    let s = a2.subsystems.iter_mut().find(|s| s.name == c2)?;
    let fan: Vec<String> = (0..robots).map(|i| robot_name("c1", i)).collect();
    for g in s.inputs.iter_mut().chain(s.outputs.iter_mut()) {
        if g.peer == "c1" {
            g.peers.clone_from(&fan);
        }
    }
    let text = |t: &str| Some(t.to_owned());
    let strings = |v: &[&str]| v.iter().map(|&x| x.to_owned()).collect::<Vec<_>>();
    s.doc = text(
        "Every robot's dispatch: at each activation, one activation of Rex's c2 FSM per robot (rex-agent/src/fleet/ontology.rs).",
    );
    s.memory = vec![Buffer {
        name: "robots".into(),
        ty: "Vec<Dispatch>".into(),
        doc: text(
            "each robot's dispatch: Rex's c2 memory (mission, plans sent, acknowledgements, outcomes, c1's incarnation) and its state in Rex's c2 FSM",
        ),
    }];
    s.predicates = vec![Predicate {
        name: "settled".into(),
        reads: strings(&["robots"]),
        doc: text(
            "every robot's mission settled, its last record made (where Rex's c2 would have halted)",
        ),
    }];
    s.relations.clear();
    let every = ["robots", "ack", "outcome", "progress", "alive"];
    let function =
        |name: &str, target: Target, reads: &[&str], writes: &[&str], doc: &str| Function {
            name: name.into(),
            target,
            reads: strings(reads),
            writes: strings(writes),
            doc: text(doc),
        };
    s.functions = vec![
        function(
            "activate_robots",
            Target::Common,
            &every,
            &["robots"],
            "each robot's activation of Rex's c2 FSM on its inputs: Rex's decisions on its predicates (more, acked, lost, settled), then Rex's action (send_plan and advance, or record), the plan sent kept",
        ),
        function(
            "send_plans",
            Target::Output("c1".into()),
            &["robots"],
            &["desired_plan"],
            "the plan each robot's activation sent, to that robot",
        ),
    ];
    s.behaviours = vec![
        Behaviour {
            name: "dispatch".into(),
            kind: BehaviourKind::While,
            functions: strings(&["activate_robots", "send_plans"]),
            terminal: "settled".into(),
            doc: text("every robot's activation of Rex's c2 FSM"),
        },
        Behaviour {
            name: "done".into(),
            kind: BehaviourKind::Repeat,
            functions: Vec::new(),
            terminal: "true".into(),
            doc: None,
        },
    ];
    s.fsm = Fsm {
        initial: text("dispatch"),
        arcs: vec![FsmArc {
            from: "dispatch".into(),
            to: "done".into(),
            when: "true".into(),
        }],
        finals: strings(&["done"]),
    };
    Some(a2)
}

/// The fleet's deployments (see the [module](self)).
fn deployments(robots: usize, per_process: usize) -> Vec<Deployment> {
    let names = |parts: &[&str], range: std::ops::Range<usize>| -> Vec<String> {
        range
            .flat_map(|i| parts.iter().map(move |p| robot_name(p, i)))
            .collect()
    };
    let one_process = |name: &str, omit: Vec<String>| {
        let runs = std::iter::once(ONTOLOGY.1.to_owned())
            .chain(names(&PARTS, 0..robots))
            .filter(|n| !omit.contains(n))
            .collect();
        Deployment {
            name: name.into(),
            hosts: vec![Host {
                name: "localhost".into(),
                address: None,
                processes: vec![Process {
                    name: "fleet".into(),
                    runs,
                    listen: None,
                    restarts: None,
                }],
            }],
            omit,
            ..empty_deployment()
        }
    };
    let without_vo = names(&["r11", "R1"], 0..robots);
    let per_process = per_process.max(1);
    let mut processes = vec![Process {
        name: "world".into(),
        runs: std::iter::once(ONTOLOGY.1.to_owned())
            .chain(names(&["E1", "R3", "c3", "r31"], 0..robots))
            .collect(),
        listen: None,
        // The fleet's truth lives in this process: a new one would put every
        // platform back at its start.
        restarts: Some(0),
    }];
    for (k, start) in (0..robots).step_by(per_process).enumerate() {
        processes.push(Process {
            name: format!("robots_{k}"),
            runs: names(&["c1", "e11"], start..(start + per_process).min(robots)),
            listen: None,
            restarts: None,
        });
    }
    let grouped = Deployment {
        name: "grouped_without_vo".into(),
        hosts: vec![Host {
            name: "localhost".into(),
            address: None,
            processes,
        }],
        omit: without_vo.clone(),
        secure: Some(false),
        ..empty_deployment()
    };
    vec![
        one_process("simulation", Vec::new()),
        one_process("simulation_without_vo", without_vo),
        grouped,
    ]
}

fn empty_deployment() -> Deployment {
    Deployment {
        name: String::new(),
        hosts: Vec::new(),
        omit: Vec::new(),
        port: None,
        router: None,
        timeout_ms: None,
        secure: None,
        ros2: None,
    }
}

/// The fleet's spec as RON text (what `embodied check` reads).
#[expect(
    clippy::expect_used,
    reason = "a spec is strings, numbers and lists: it always serialises"
)]
pub fn to_text(spec: &Spec) -> String {
    embodied::spec::options()
        .to_string_pretty(spec, ron::ser::PrettyConfig::default())
        .expect("a spec serialises")
}

/// Check the fleet's spec as a file would be checked: its text parsed back
/// and given to the checker. Returns the checked spec and the report.
pub fn check(spec: &Spec) -> (Option<Spec>, Report) {
    embodied::spec::check_source(format!("{}.ron", spec.name), to_text(spec))
}
