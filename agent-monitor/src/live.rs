//! The monitors inside a running executor: an [`Observer`] that feeds the
//! run's events to [`Monitors`] as they happen and raises each violation as an
//! [`ExecError::Contract`], which the executor's error policy handles
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
//!   ([`LinkEvents::older_than`]: a value is told only when older than the
//!   bound, a new one as a read, one still held through [`Observer::held`],
//!   which is judged as it is told, at the read, rather than at the
//!   reader's activation of the same instant, which reports a held value
//!   when every read is told: the same violation, at the same time);
//! * rate: a value's send when its writer is watched here (its stamp, as
//!   over a recording), else the reader's take of it (from another thread or
//!   process; the instant it arrived for the reader);
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
//!   ([`Observer::link_events`]: the ranges' bounds, checked on the typed
//!   value in one walk for all the ranges of a link, by
//!   [`agent_core::trace::within`], which the monitors judge by too), and the
//!   watch hears only of the values out of a range, which it judges again;
//! * invariant: after each activation of a watched subsystem that carries
//!   invariants, the values of the predicates they read, which the watch
//!   asks of the executor ([`Observer::predicates_wanted`]: those predicates
//!   only, found in the node's FSM by name) and the executor evaluates on
//!   the memory and inputs the action left ([`Observer::predicates`]); a
//!   subsystem without invariants costs nothing. An invariant whose
//!   subsystem is not in the system, or whose FSM lacks one of its
//!   predicates, is not judged ([`Verdicts::not_judged`] says why).
//!
//! Which events a watch takes: it tells the executor once per link
//! ([`Observer::link_events`]) the sends and reads that change one of its
//! monitors (a rate's or response's send, a freshness's, rate's or
//! response's read) and the range checks; the deterministic executor leaves
//! out the others before calling any observer (they would only have moved
//! the watch's clock). Likewise per node ([`Observer::node_events`]): the
//! transitions of a subsystem with behaviour bounds and its activations in
//! the bounded behaviours, every activation of a reader whose held values
//! a freshness judges at its activations, and of the other nodes none; the
//! deterministic executor tells [`Observer::instant`] at every instant
//! instead, which moves the watch's clock (a rate's or response's deadline
//! that passed is found there), and the invariants' predicates after every
//! activation of their subsystem whether its action is told or not. A watch
//! beside an observer that takes every event (a recorder) is given every
//! event and judges them the same (tests/monitor.rs checks the verdicts).
//!
//! Cost: `bench_core` measures a watch of Rex's contracts on a system shaped
//! like Rex (`monitor_ns_per_cycle`, `monitor_cost_ratio`: the watch's ns per
//! action over an action's; the aim is 0.05). Counted in instructions per
//! cycle (callgrind over the bench), the watch added 2,261 to the plain
//! system's 3,064 before its range checks were compiled into the links and
//! it was given only the events it needs, 1,935 to 3,119 after (-14 %), and
//! 1,523 to 3,115 once its freshness contracts were judged where their values are
//! read (-21 %; `monitor_cost_ratio` about 0.25 where 1,935 measured about
//! 0.35 in the same runs; the wall-clock figures of a shared machine vary
//! more than that, docs/measurements.md), and 1,252 to 3,041 once it was
//! told only the activations that change a monitor (c1's in its bounded
//! behaviour, none of the other four) and moved its clock once an instant
//! (-17 %; the executor's `step` inclusive, watched less plain, over the
//! same 2,020,000 cycles; the plain cycle 42 instructions shorter, a send's
//! transfer to its channel inlined again; an observer that asks for every
//! event pays about 14 instructions an activation for the table it is
//! looked up in; `monitor_cost_ratio` 0.263 before and 0.183 after, medians
//! of 9 alternating runs). What is left is the watch's own work on the
//! events that do change a monitor (in that system, per cycle: 4 sends for
//! rates and responses and c2's predicates, of 14 reads and 7 sends; the 4
//! freshness reads are told only of a value too old, the torques' 4 ranges
//! are checked in their link), each an observer call that advances the
//! monitors' clock and visits the monitors the event concerns (the
//! monitors' index per input, output and subsystem; a plan per link, made
//! once per watch), the range checks' walks of the torques (about 175), and
//! the clock's instant. Reading a rate's and a response's sends from the
//! links' last stamps once an instant instead of being told of each was
//! built and measured, and cost more, not less: 1,420 instructions a cycle
//! with a flat table of stamps the sending links write (the stamps' store
//! and check on every observed send, the poll at every instant, and the
//! monitors' own work on each send, which is most of a send's cost,
//! unchanged), 1,606 with each link's channel asked through its
//! `RefCell` (its send's put then no longer inlined); taken back. What the
//! aim needs is less work per event in the monitors themselves, and a
//! range read by a compiled accessor rather than a walk of the value's
//! `Serialize`; not done. The earliest deadline
//! is kept as events add one (every monitor is scanned only when it
//! passes), and nothing is allocated per event, except the error of a
//! violation.

use std::collections::VecDeque;
use std::fmt;
use std::sync::{Arc, Mutex, PoisonError};

use agent_core::trace::{
    ErasedPayload, FieldPath, LinkEvents, NodeEvents, NumberBound, ReadEvent, TransferEvent,
};
use agent_core::{
    ActionEvent, ExecError, Observer, Step, System, Time, TransitionEvent, Valuation,
};

use crate::ends::Ends;
use crate::field::Layout;
use crate::{
    BehaviourId, ContractId, ContractInfo, InputId, Monitors, OutputId, RangeId, SubsystemId,
    Violation,
};

/// How many violations a watch keeps for its verdicts (the rest are counted).
pub const KEPT: usize = 1024;

/// How many violations may wait between two steps for the executor to take
/// them (the rest are counted in [`Verdicts::unraised`], never lost from the
/// verdicts).
const PENDING: usize = 64;

/// A contract broken while the system ran: the source of its
/// [`ExecError::Contract`], to downcast.
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
        Live {
            shared: Arc::new(Shared {
                monitors,
                roles,
                subsystems,
                behaviours,
                unjudgeable,
                predicates,
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
        let mut watch = Watch {
            links: plans(&s.roles, &here, &monitors),
            watched,
            shared: self.shared.clone(),
            monitors,
            wanted,
            current: vec![None; s.subsystems.len()],
            sink: Sink {
                pending: VecDeque::with_capacity(PENDING),
                kept: Vec::with_capacity(KEPT),
                count: 0,
                unraised: 0,
            },
            undecodable: 0,
            raised: 0,
            started: false,
            last: Time::ZERO,
            judged,
            not_judged,
            held_at_activations: Vec::new(),
        };
        watch.held_at_activations = watch.readers_held_at_activations();
        watch
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

/// Where a watch's violations go: raised to the executor, and kept.
struct Sink {
    pending: VecDeque<Violation>,
    kept: Vec<Violation>,
    count: u64,
    unraised: u64,
}

impl Sink {
    fn take(&mut self, v: Violation) {
        self.count += 1;
        if self.kept.len() < KEPT {
            self.kept.push(v);
        }
        if self.pending.len() < PENDING {
            self.pending.push_back(v);
        } else {
            self.unraised += 1;
        }
    }
}

/// A [`Live`]'s observer (see the module docs).
pub struct Watch {
    shared: Arc<Shared>,
    monitors: Monitors,
    /// Per link: what to do with its events.
    links: Vec<LinkPlan>,
    /// Per node: its subsystem in the spec, if this watch runs with it.
    watched: Vec<Option<SubsystemId>>,
    /// Per node: the predicates its invariants read (the FSM's bits).
    wanted: Vec<u64>,
    /// Per node: the behaviour it is in (the executor's index).
    current: Vec<Option<usize>>,
    /// Per node: whether it reads a freshness's input whose held values are
    /// judged at its activations (its link tells every read, not only the
    /// values too old: [`LinkEvents::older_than`]).
    held_at_activations: Vec<bool>,
    sink: Sink,
    undecodable: u64,
    /// Violations taken by the executor.
    raised: u64,
    started: bool,
    last: Time,
    judged: Vec<ContractId>,
    not_judged: Vec<(ContractId, String)>,
}

impl fmt::Debug for Watch {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Watch")
            .field("judged", &self.judged.len())
            .field("violations", &self.sink.count)
            .finish_non_exhaustive()
    }
}

impl Watch {
    /// Time has reached `t` (the watch starts at its first event).
    #[inline]
    fn at(&mut self, t: Time) {
        if !self.started {
            self.started = true;
            self.monitors.start(t);
        }
        self.last = self.last.max(t);
    }

    /// Per node, whether it reads a freshness's input whose held values are
    /// judged at its activations (one pass over the links).
    fn readers_held_at_activations(&self) -> Vec<bool> {
        let mut held = vec![false; self.watched.len()];
        for (l, role) in self.shared.roles.iter().enumerate() {
            if role
                .input
                .is_some_and(|i| self.monitors.counts(Some(i), None).reads)
                && self.link_events(l).older_than.is_none()
                && let Some(h) = held.get_mut(role.to)
            {
                *h = true;
            }
        }
        held
    }

    /// Judge the ranges of link `link`'s value at `t`.
    #[inline]
    fn ranges(&mut self, link: usize, t: Time, value: &dyn ErasedPayload) {
        let Some(plan) = self.links.get(link) else {
            return;
        };
        // Time advanced once for all of them (as each range's own event would).
        self.monitors.advance(t, &mut |v| self.sink.take(v));
        for (range, path) in &plan.ranges {
            match value.number_at(path) {
                Ok(Some(x)) => {
                    if let Some(v) = self.monitors.judge(*range, t, x) {
                        self.sink.take(v);
                    }
                }
                Ok(None) => {}
                Err(_) => self.undecodable += 1,
            }
        }
    }
}

impl Observer for Watch {
    /// The events of link `link` that change a monitor: the sends a response
    /// or rate counts (by a writer watched here), the reads a freshness,
    /// rate or response counts (by a reader watched here), and, of the other
    /// sends by a watched writer, those out of a range only (the range's
    /// bounds checked on the typed value where it is sent). The events left
    /// out would have moved the watch's clock only, which the same instant's
    /// activations move.
    fn link_events(&self, link: usize) -> LinkEvents {
        let Some(p) = self.links.get(link) else {
            return LinkEvents::all();
        };
        let out_of = (p.ranges.iter())
            .filter(|_| p.writer)
            .filter_map(|(id, path)| {
                let (min, max) = self.monitors.range_bounds(*id)?;
                Some(NumberBound {
                    path: path.clone(),
                    min,
                    max,
                })
            })
            .collect();
        let c = self.monitors.counts(p.input, p.output);
        let other_reads = !p.writer && (c.sends || c.arrivals);
        // A freshness alone judged where the value is read: the reads of a
        // value older than its bound only, new or held.
        let older_than = (p.input)
            .filter(|_| p.reader && c.reads && !other_reads)
            .and_then(|i| self.monitors.freshness_bound(i));
        LinkEvents {
            transfers: p.writer && (c.sends || (c.arrivals && p.reader)),
            out_of,
            reads: p.reader && ((c.reads && older_than.is_none()) || other_reads),
            older_than,
        }
    }

    /// The transitions and activations of node `node` that change a
    /// monitor: none of a node not watched here; a watched subsystem's
    /// transitions when it has behaviour bounds, and its activations in the
    /// bounded behaviours; every activation of a reader whose held values a
    /// freshness judges at its activations (a link of its that tells every
    /// read but not the held values too old, [`LinkEvents::older_than`]).
    /// The invariants' predicates are told after every activation anyway,
    /// a held value too old is judged when told ([`Observer::held`]), and the
    /// clock moves at every instant ([`Observer::instant`]).
    fn node_events(&self, node: usize) -> NodeEvents {
        let Some(Some(sub)) = self.watched.get(node).copied() else {
            return NodeEvents::none();
        };
        let mut events = NodeEvents::none();
        let behaviours = self
            .shared
            .behaviours
            .get(node)
            .map_or(&[][..], Vec::as_slice);
        for bounded in self.monitors.bounded(sub) {
            events.transitions = true;
            for (b, id) in behaviours.iter().enumerate() {
                if *id == Some(bounded) {
                    events.actions |= 1 << b.min(63);
                }
            }
        }
        if self.held_at_activations.get(node) == Some(&true) {
            events.actions = u64::MAX;
        }
        events
    }

    fn instant(&mut self, time: Time) {
        self.at(time);
        self.monitors.advance(time, &mut |v| self.sink.take(v));
    }

    fn transition(&mut self, e: &TransitionEvent) {
        self.at(e.time);
        let Some(Some(sub)) = self.watched.get(e.node).copied() else {
            return;
        };
        match e.step {
            Step::Entered { to, .. } => {
                self.current[e.node] = Some(to);
                let b = self.shared.behaviours[e.node].get(to).copied().flatten();
                self.monitors
                    .entered(sub, b, e.time, &mut |v| self.sink.take(v));
            }
            Step::Finished => {
                self.monitors
                    .entered(sub, None, e.time, &mut |v| self.sink.take(v));
            }
            Step::Run => {}
        }
    }

    fn action(&mut self, e: &ActionEvent) {
        self.at(e.time);
        let sub = self.watched.get(e.node).copied().flatten();
        match (sub, e.behaviour) {
            (Some(sub), Some(b)) => {
                if self.current[e.node].is_none() {
                    // The initial behaviour, entered at the first activation.
                    self.current[e.node] = Some(b);
                    let id = self.shared.behaviours[e.node].get(b).copied().flatten();
                    self.monitors
                        .entered(sub, id, e.time, &mut |v| self.sink.take(v));
                }
                self.monitors
                    .activation(sub, e.time, None, &mut |v| self.sink.take(v));
            }
            _ => self.monitors.advance(e.time, &mut |v| self.sink.take(v)),
        }
    }

    fn transfer(&mut self, e: &TransferEvent, value: &dyn ErasedPayload) {
        let t = e.stamp.time;
        self.at(t);
        let Some(plan) = self.links.get(e.link) else {
            return;
        };
        if !plan.writer {
            return;
        }
        let (output, input, reader) = (plan.output, plan.input, plan.reader);
        let has_ranges = !plan.ranges.is_empty();
        if let Some(o) = output {
            self.monitors.sent(o, t, &mut |v| self.sink.take(v));
        }
        if let Some(i) = input
            && reader
        {
            self.monitors.arrived(i, t, &mut |v| self.sink.take(v));
        }
        if has_ranges {
            self.ranges(e.link, t, value);
        }
    }

    fn read(&mut self, e: &ReadEvent) {
        self.at(e.time);
        let Some(plan) = self.links.get(e.link) else {
            return;
        };
        if !plan.reader {
            return;
        }
        let (output, input, writer) = (plan.output, plan.input, plan.writer);
        let stamp = e.stamp.time;
        if !writer {
            if let Some(o) = output {
                self.monitors.sent(o, stamp, &mut |v| self.sink.take(v));
            }
            if let Some(i) = input {
                self.monitors.arrived(i, e.time, &mut |v| self.sink.take(v));
            }
        }
        if let Some(i) = input {
            self.monitors
                .read(i, e.time, stamp, &mut |v| self.sink.take(v));
        }
    }

    fn held(&mut self, e: &ReadEvent) {
        self.at(e.time);
        let Some(plan) = self.links.get(e.link) else {
            return;
        };
        if let (true, Some(i)) = (plan.reader, plan.input) {
            // Judged now, at the reader's read: the deterministic executor
            // may not tell its activation (`node_events`).
            self.monitors
                .held_judged(i, e.time, e.stamp.time, &mut |v| self.sink.take(v));
        }
    }

    fn received(&mut self, e: &ReadEvent, value: &dyn ErasedPayload) {
        let Some(plan) = self.links.get(e.link) else {
            return;
        };
        if plan.reader && !plan.writer && !plan.ranges.is_empty() {
            self.ranges(e.link, e.time, value);
        }
    }

    fn predicates_wanted(&self, node: usize) -> u64 {
        self.wanted.get(node).copied().unwrap_or(0)
    }

    fn predicates(&mut self, e: &ActionEvent, values: Valuation) {
        let Some(Some(sub)) = self.watched.get(e.node).copied() else {
            return;
        };
        // The FSM's bits to the spec's.
        let (mut known, mut value) = (0u64, 0u64);
        for &(f, k) in self
            .shared
            .predicates
            .get(e.node)
            .map_or(&[][..], Vec::as_slice)
        {
            if values.known >> f & 1 == 1 {
                known |= 1 << k;
                value |= (values.value >> f & 1) << k;
            }
        }
        self.monitors
            .predicates(sub, e.time, known, value, &mut |v| self.sink.take(v));
    }

    #[inline]
    fn raised(&mut self) -> Option<ExecError> {
        if self.sink.pending.is_empty() {
            return None;
        }
        self.raise()
    }
}

impl Watch {
    /// The next violation waiting, as the executor's error.
    #[cold]
    fn raise(&mut self) -> Option<ExecError> {
        let v = self.sink.pending.pop_front()?;
        self.raised += 1;
        let contract = self.monitors.contract(v.contract)?.clone();
        let line = self.monitors.display(&v).to_string();
        Some(ExecError::Contract {
            subsystem: contract.subsystem.clone(),
            time: v.time,
            source: Box::new(ContractViolation {
                violation: v,
                contract,
                line,
            }),
        })
    }
}

impl Drop for Watch {
    fn drop(&mut self) {
        if self.started {
            let last = self.last;
            self.monitors.finish(last, &mut |v| self.sink.take(v));
        }
        let mut all = self
            .shared
            .verdicts
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        for c in &self.judged {
            if !all.judged.contains(c) {
                all.judged.push(*c);
            }
        }
        all.judged.sort_unstable();
        for (c, why) in &self.not_judged {
            if !all.not_judged.iter().any(|(n, _)| n == c) {
                all.not_judged.push((*c, why.clone()));
            }
        }
        all.violations.extend(self.sink.kept.iter().copied());
        all.violations.sort_by_key(|v| v.time);
        all.count += self.sink.count;
        all.unraised += self.sink.unraised;
        all.raised += self.raised;
        all.undecodable += self.undecodable;
    }
}
