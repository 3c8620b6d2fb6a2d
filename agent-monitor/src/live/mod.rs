//! The monitors inside a running executor: an [`Observer`](agent_core::Observer) that feeds the
//! run's events to [`Monitors`] as they happen and raises each violation as an
//! [`ExecError::Contract`](agent_core::ExecError::Contract), which the executor's error policy handles
//! ([`agent_core::OnError`]: stop, continue, or safe-stop).
//!
//! [`Live::new`] maps the spec's buffers to the system's links once (the
//! ends matched by name as over a recording) and traces the shapes of the
//! values the ranges read. [`Live::watch`] is the observer of a whole run
//! (the deterministic executor); [`Live::watch_nodes`] that of some of its
//! nodes (a thread of the real-time executor, or a process of a deployment):
//! it judges the contracts of those subsystems only, from what its thread
//! sees. Each watch hands its verdicts to the [`Live`] when it is dropped
//! (the executors drop their observers when the run ends).
//!
//! Where each kind's events come from (the semantics are the crate's):
//!
//! * freshness: the reader's reads, stamped by the sender, and its
//!   activations (a halted subsystem is judged no more); in the
//!   deterministic executor, judged where the value is read when a
//!   freshness is all that counts a link's reads
//!   ([`LinkEvents::older_than`](agent_core::trace::LinkEvents::older_than): a value is told only when older than the
//!   bound, a new one as a read, one still held through [`Observer::held`](agent_core::Observer::held),
//!   which is judged as it is told, at the read, rather than at the
//!   reader's activation of the same instant, which reports a held value
//!   when every read is told: the same violation, at the same time);
//! * rate: a value's send when its writer is watched here (its stamp, as
//!   over a recording), else the reader's take of it (from another thread or
//!   process; the instant it arrived for the reader); in the deterministic
//!   executor, when a link's sends count for rates only and both its ends
//!   are watched here, the executor keeps the instant of its last send
//!   ([`LinkEvents::stamps`](agent_core::trace::LinkEvents::stamps), one
//!   store a send) and the watch reads it at an instant when a window may
//!   have closed or a rate is silent, before judging: the same verdicts as
//!   a send told at each send, since the executor tells every instant (a
//!   window that closed at `d` is judged at the first instant after it, when
//!   the last send read is the last one at or before `d`);
//! * response: the responder's sends; the trigger's send, or its take by a
//!   watched reader when its writer is elsewhere;
//! * bound: the subsystem's behaviour switches and its activations in the
//!   bounded behaviour;
//! * range: each value sent by a watched writer, or received from another
//!   process by a watched reader: the field read from the typed value through
//!   its `Serialize` impl ([`agent_core::trace::FieldPath`]: the path's steps
//!   followed, the rest skipped, nothing encoded), the path checked once
//!   against the payload's shape ([`agent_core::reflect`]). In the
//!   deterministic executor the check is compiled into the sending link
//!   ([`Observer::link_events`](agent_core::Observer::link_events): the ranges' bounds, checked on the typed
//!   value in one walk for all the ranges of a link, by
//!   [`agent_core::trace::within`], which the monitors judge by too), and the
//!   watch hears only of the values out of a range, which it judges again;
//! * invariant: after each activation of a watched subsystem that carries
//!   invariants, the values of the predicates they read, which the watch
//!   asks of the executor ([`Observer::predicates_wanted`](agent_core::Observer::predicates_wanted): those predicates
//!   only, found in the node's FSM by name) and the executor evaluates on
//!   the memory and inputs the action left ([`Observer::predicates`](agent_core::Observer::predicates)); a
//!   subsystem without invariants costs nothing. An invariant whose
//!   subsystem is not in the system, or whose FSM lacks one of its
//!   predicates, is not judged ([`Verdicts::not_judged`] says why).
//!
//! Which events a watch takes: it tells the executor once per link
//! ([`Observer::link_events`](agent_core::Observer::link_events)) the sends and reads that change one of its
//! monitors (a rate's or response's send, a freshness's, rate's or
//! response's read) and the range checks; the deterministic executor leaves
//! out the others before calling any observer (they would only have moved
//! the watch's clock). Likewise per node ([`Observer::node_events`](agent_core::Observer::node_events)): the
//! transitions of a subsystem with behaviour bounds and its activations in
//! the bounded behaviours, every activation of a reader whose held values
//! a freshness judges at its activations, and of the other nodes none; the
//! deterministic executor tells [`Observer::instant`](agent_core::Observer::instant) at every instant
//! instead, which moves the watch's clock (a rate's or response's deadline
//! that passed is found there), and the invariants' predicates after every
//! activation of their subsystem whether its action is told or not. A watch
//! beside an observer that takes every event (a recorder) is given every
//! event and judges them the same (tests/monitor.rs checks the verdicts).
//!
//! Cost: `bench_core` measures a watch of Rex's contracts on a system shaped
//! like Rex (`monitor_ns_per_cycle`, `monitor_cost_ratio`: the watch's ns per
//! action over an action's; the aim is 0.05). What is left per watched cycle
//! is the watch's own work on the events that do change a monitor (each an
//! observer call that advances the monitors' clock and visits the monitors
//! the event concerns), the range checks' walks of the values, and the
//! clock's instant; docs/measurements.md has the counts, step by step, and
//! what was tried and taken back. The earliest deadline is kept as events
//! add one (every monitor is scanned only when it passes), and nothing is
//! allocated per event, except the error of a violation.

use std::fmt;
use std::sync::{Arc, Mutex, PoisonError};

use agent_core::System;
use agent_core::trace::FieldPath;

use crate::ends::Ends;
use crate::field::Layout;
use crate::{
    BehaviourId, ContractId, ContractInfo, InputId, Monitors, OutputId, RangeId, SubsystemId,
    Violation,
};

mod remap;
mod watch;

pub use watch::Watch;

/// How many violations a watch keeps for its verdicts (the rest are counted).
pub const KEPT: usize = 1024;

/// How many violations may wait between two steps for the executor to take
/// them (the rest are counted in [`Verdicts::unraised`], never lost from the
/// verdicts).
const PENDING: usize = 64;

/// A contract broken while the system ran: the source of its
/// [`ExecError::Contract`](agent_core::ExecError::Contract), to downcast.
#[derive(Clone, Debug, PartialEq)]
pub struct ContractViolation {
    /// When, which contract, and the values that broke it.
    pub violation: Violation,
    /// What the contract is.
    pub contract: ContractInfo,
    /// The violation as one line (`t=... subsystem=... contract=kind:name: values`).
    pub line: String,
}

impl fmt::Display for ContractViolation {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.line)
    }
}

impl std::error::Error for ContractViolation {}

/// What one link is to the monitors.
#[derive(Clone, Debug, Default)]
struct Role {
    from: usize,
    to: usize,
    /// The spec's input it is the reader's end of.
    input: Option<InputId>,
    /// The spec's output it is the writer's end of.
    output: Option<OutputId>,
    /// The ranges its values are judged by, with their field paths (as
    /// read from the typed value, and as steps for the shape's check).
    ranges: Vec<(RangeId, FieldPath, Vec<String>)>,
    /// Its payload's layout (to check the ranges' paths once).
    shape: Option<Arc<Layout>>,
}

/// What one watch does with a link's events: [`Role`] resolved against the
/// nodes it watches, once, so that an event reads one entry.
#[derive(Clone, Debug, Default)]
struct LinkPlan {
    /// Its writer runs with this watch.
    writer: bool,
    /// Its reader runs with this watch.
    reader: bool,
    input: Option<InputId>,
    output: Option<OutputId>,
    /// The ranges judged here of its values, with their field paths.
    ranges: Vec<(RangeId, FieldPath)>,
}

/// The verdicts of a run's watches, gathered as each ends.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Verdicts {
    /// The contracts some watch judged.
    pub judged: Vec<ContractId>,
    /// The contracts no watch could judge, each with why.
    pub not_judged: Vec<(ContractId, String)>,
    /// The violations kept (at most [`KEPT`] per watch), in time order.
    pub violations: Vec<Violation>,
    /// Every violation, kept or not.
    pub count: u64,
    /// Violations the executor took as errors (the others were found after
    /// the run's last step, or did not fit [`Verdicts::unraised`]).
    pub raised: u64,
    /// Violations the executor did not take as errors because too many
    /// waited at once (they are in the counts and, up to the limit, kept).
    pub unraised: u64,
    /// Values a range could not read: a value whose `Serialize` impl failed
    /// where the range reads it (a broken encoder).
    pub undecodable: u64,
}

impl Verdicts {
    /// How many contracts were violated, at least once.
    pub fn contracts_violated(&self) -> usize {
        crate::contracts_violated(&self.violations)
    }
}

struct Shared {
    monitors: Monitors,
    roles: Vec<Role>,
    /// Per node of the system: its subsystem in the spec, if any.
    subsystems: Vec<Option<SubsystemId>>,
    /// Per node: its behaviours (by the executor's index) in the spec.
    behaviours: Vec<Vec<Option<BehaviourId>>>,
    /// Per range: why it cannot be judged on this system, if it cannot.
    unjudgeable: Vec<Option<String>>,
    /// Per node: its FSM's predicates that are its subsystem's in the spec,
    /// as (the FSM's index, the spec's index), both below 64.
    predicates: Vec<Vec<(u8, u8)>>,
    /// Per node: the same map, applied to a valuation's bits at once.
    remaps: Vec<remap::Remap>,
    /// The invariants that cannot be judged on this system, with why.
    invariants_unjudgeable: Vec<(ContractId, String)>,
    verdicts: Mutex<Verdicts>,
}

/// The monitors of one run: made once from the spec's [`Monitors`] and the
/// system, then watched by one or more [`Watch`]es (see the module docs).
#[derive(Clone)]
pub struct Live {
    shared: Arc<Shared>,
}

impl fmt::Debug for Live {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Live")
            .field("contracts", &self.shared.monitors.contracts().len())
            .finish_non_exhaustive()
    }
}

impl Live {
    /// The monitors of `monitors`' contracts over `system`'s links and nodes.
    /// A range whose buffer is on no link, or whose field does not lead to a
    /// number in the link's payload, is not judged ([`Verdicts::not_judged`]).
    pub fn new(monitors: Monitors, system: &System) -> Live {
        let info = system.info();
        let mut roles = Vec::with_capacity(info.links.len());
        for (i, l) in info.links.iter().enumerate() {
            let mut role = Role {
                from: l.from,
                to: l.to,
                ..Role::default()
            };
            if let Some(ends) = Ends::parse(&l.name) {
                role.input = (0..monitors.inputs.len())
                    .find(|&k| ends.is_input(&monitors.inputs[k]))
                    .map(|k| InputId(k as u32));
                role.output = (0..monitors.outputs.len())
                    .find(|&k| ends.is_output(&monitors.outputs[k]))
                    .map(|k| OutputId(k as u32));
                let shape = || system.payload_shape(i).map(|s| Arc::new(Layout::of(&s)));
                for (k, (buffer, field)) in monitors.ranges_of.iter().enumerate() {
                    if ends.is_input(buffer) || ends.is_output(buffer) {
                        role.shape = role.shape.take().or_else(shape);
                        let path = field
                            .as_deref()
                            .map(|f| f.split('.').map(str::to_owned).collect())
                            .unwrap_or_default();
                        let read = FieldPath::parse(field.as_deref().unwrap_or(""));
                        role.ranges.push((RangeId(k as u32), read, path));
                    }
                }
            }
            roles.push(role);
        }
        let unjudgeable = ranges_unjudgeable(&monitors, &roles);
        // The ranges that cannot be judged are not read.
        for role in &mut roles {
            role.ranges
                .retain(|(id, _, _)| unjudgeable.get(id.0 as usize).is_some_and(Option::is_none));
        }
        let subsystems: Vec<Option<SubsystemId>> = info
            .nodes
            .iter()
            .map(|n| monitors.subsystem(&n.name))
            .collect();
        let behaviours = info
            .nodes
            .iter()
            .zip(&subsystems)
            .map(|(n, s)| {
                n.behaviours
                    .iter()
                    .map(|b| s.and_then(|s| monitors.behaviour(s, b)))
                    .collect()
            })
            .collect();
        let predicates: Vec<Vec<(u8, u8)>> = info
            .nodes
            .iter()
            .zip(&subsystems)
            .map(|(n, s)| {
                let (Some(s), Some(fsm)) = (s, &n.fsm) else {
                    return Vec::new();
                };
                let names = monitors.predicate_names(*s).iter().enumerate().take(64);
                names
                    .filter_map(|(k, name)| {
                        let f = fsm.predicates.iter().position(|p| p == name)?;
                        Some((u8::try_from(f).ok().filter(|f| *f < 64)?, k as u8))
                    })
                    .collect()
            })
            .collect();
        let invariants_unjudgeable = invariants_unjudgeable(&monitors, &subsystems, &predicates);
        let remaps = predicates.iter().map(|p| remap::Remap::new(p)).collect();
        Live {
            shared: Arc::new(Shared {
                monitors,
                roles,
                subsystems,
                behaviours,
                unjudgeable,
                predicates,
                remaps,
                invariants_unjudgeable,
                verdicts: Mutex::new(Verdicts::default()),
            }),
        }
    }

    /// The observer of the whole run.
    pub fn watch(&self) -> Watch {
        let n = self.shared.subsystems.len();
        self.watch_nodes(&(0..n).collect::<Vec<_>>())
    }

    /// The observer of the nodes `nodes` (indices into [`agent_core::SystemInfo::nodes`],
    /// as the real-time executor gives each thread's observer maker): it
    /// judges the contracts of those subsystems only.
    pub fn watch_nodes(&self, nodes: &[usize]) -> Watch {
        let s = &self.shared;
        let mut here = vec![false; s.subsystems.len()];
        for &n in nodes {
            if let Some(h) = here.get_mut(n) {
                *h = true;
            }
        }
        let names: Vec<&str> = nodes
            .iter()
            .filter_map(|&n| s.subsystems.get(n).copied().flatten())
            .map(|id| s.monitors.subsystem_name(id))
            .collect();
        let mut monitors = s.monitors.clone();
        monitors.retain_subsystems(|sub| names.contains(&sub));
        monitors.at_activations();
        let mut not_judged: Vec<(ContractId, String)> = s
            .unjudgeable
            .iter()
            .enumerate()
            .filter_map(|(k, why)| {
                let c = monitors.range_contract(RangeId(k as u32))?;
                Some((c, why.clone()?))
            })
            .collect();
        for c in monitors.invariant_contracts() {
            if let Some((_, why)) = s.invariants_unjudgeable.iter().find(|(n, _)| *n == c) {
                not_judged.push((c, why.clone()));
            }
        }
        // The predicates each watched node's invariants read, by its FSM's index.
        let mut wanted = vec![0u64; s.subsystems.len()];
        for &n in nodes {
            let Some(Some(sub)) = s.subsystems.get(n).copied() else {
                continue;
            };
            let spec = monitors
                .invariants()
                .filter(|(c, i, _)| *i == sub && !not_judged.iter().any(|(n, _)| n == c))
                .filter_map(|(_, _, uses)| uses)
                .fold(0u64, |a, u| a | u);
            wanted[n] = s.predicates[n]
                .iter()
                .filter(|(_, k)| spec >> k & 1 == 1)
                .fold(0u64, |a, (f, _)| a | 1 << f);
        }
        let judged = monitors
            .judged()
            .filter(|c| !not_judged.iter().any(|(n, _)| n == c))
            .collect();
        let is_here = |n: usize| here.get(n).copied().unwrap_or(false);
        let watched = (s.subsystems.iter().enumerate())
            .map(|(n, sub)| sub.filter(|_| is_here(n)))
            .collect();
        let links = plans(&s.roles, &here, &monitors);
        Watch::new(
            self.shared.clone(),
            monitors,
            links,
            watched,
            wanted,
            judged,
            not_judged,
        )
    }

    /// The verdicts of the watches that have ended.
    pub fn verdicts(&self) -> Verdicts {
        self.shared
            .verdicts
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// The monitors (their contracts' names, and [`Monitors::display`]).
    pub fn monitors(&self) -> &Monitors {
        &self.shared.monitors
    }
}

/// What a watch of the nodes `here` does with each link's events
/// (`monitors`: those it judges).
fn plans(roles: &[Role], here: &[bool], monitors: &Monitors) -> Vec<LinkPlan> {
    let is_here = |n: usize| here.get(n).copied().unwrap_or(false);
    roles
        .iter()
        .map(|r| LinkPlan {
            writer: is_here(r.from),
            reader: is_here(r.to),
            input: r.input,
            output: r.output,
            ranges: (r.ranges.iter())
                .filter(|(id, _, _)| monitors.range_contract(*id).is_some())
                .map(|(id, path, _)| (*id, path.clone()))
                .collect(),
        })
        .collect()
}

/// Per range of `monitors`: why it cannot be judged over links `roles`, if
/// it cannot (on no link, no shape, or a path to no number).
fn ranges_unjudgeable(monitors: &Monitors, roles: &[Role]) -> Vec<Option<String>> {
    (0..monitors.ranges_of.len())
        .map(|k| {
            let id = RangeId(k as u32);
            let (buffer, field) = &monitors.ranges_of[k];
            let found = roles.iter().find_map(|r| {
                let (_, _, path) = r.ranges.iter().find(|(x, _, _)| *x == id)?;
                Some((r.shape.as_deref(), path))
            });
            match found {
                None => Some(format!("`{buffer}` is on no link of the system")),
                Some((None, _)) => Some(format!("the payload of `{buffer}` has no shape to read")),
                Some((Some(shape), path)) if !crate::field::reaches_number(shape, path) => {
                    Some(format!(
                        "`{}` does not lead to a number in `{buffer}`",
                        field.as_deref().unwrap_or("")
                    ))
                }
                Some(_) => None,
            }
        })
        .collect()
}

/// The invariants that cannot be judged on a system (`subsystems`: each
/// node's subsystem; `predicates`: each node's predicates found in its FSM),
/// with why.
fn invariants_unjudgeable(
    monitors: &Monitors,
    subsystems: &[Option<SubsystemId>],
    predicates: &[Vec<(u8, u8)>],
) -> Vec<(ContractId, String)> {
    let mut out = Vec::new();
    for (c, sub, uses) in monitors.invariants() {
        let name = monitors.subsystem_name(sub);
        let Some(uses) = uses else {
            out.push((c, format!("it reads a predicate of `{name}` past the 64th")));
            continue;
        };
        let Some(node) = subsystems.iter().position(|s| *s == Some(sub)) else {
            out.push((c, format!("`{name}` is not in the system")));
            continue;
        };
        let found = predicates[node].iter().fold(0u64, |a, (_, k)| a | 1 << k);
        if let Some(k) = (0..64).find(|k| (uses & !found) >> k & 1 == 1) {
            let missing = monitors
                .predicate_names(sub)
                .get(k)
                .map_or("?", String::as_str);
            out.push((
                c,
                format!("`{name}`'s FSM has no predicate `{missing}` (by the spec's name)"),
            ));
        }
    }
    out
}
