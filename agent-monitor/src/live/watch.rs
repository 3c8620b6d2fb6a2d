//! A [`Live`](super::Live)'s observer: the [`Watch`] of some nodes, fed the events its
//! monitors need (see the parent module's docs for which and where from).

use std::collections::VecDeque;
use std::fmt;
use std::sync::{Arc, PoisonError};

use agent_core::trace::{
    ErasedPayload, LinkEvents, NodeEvents, NumberBound, ReadEvent, SendStamps, TransferEvent,
};
use agent_core::{ActionEvent, ExecError, Observer, Step, Time, TransitionEvent, Valuation};

use super::{ContractViolation, KEPT, LinkPlan, PENDING, Shared};
use crate::{ContractId, InputId, Monitors, SubsystemId, Violation};

/// A link whose sends only rates count, both ends watched here: its last
/// send's instant read from the executor's table when a rate's window may
/// have closed ([`Watch::lazy_arrivals`]), not told at each send.
#[derive(Debug)]
struct Lazy {
    link: usize,
    input: InputId,
    /// The last send told to the monitors.
    fed: Option<Time>,
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

/// A [`Live`](super::Live)'s observer (see the [module docs](super)).
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
    /// Per node: the predicates' values (known, value; the FSM's bits) at
    /// its last activation, if every invariant held after it.
    held: Vec<Option<(u64, u64)>>,
    /// Per node: whether it reads a freshness's input whose held values are
    /// judged at its activations (its link tells every read, not only the
    /// values too old: [`LinkEvents::older_than`]).
    held_at_activations: Vec<bool>,
    /// The executor's table of the last sends' instants, and the links read
    /// from it ([`Observer::stamps`]).
    stamps: Option<SendStamps>,
    lazy: Vec<Lazy>,
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
    /// The watch of the nodes whose subsystems are `watched`, judging
    /// `monitors` (a [`super::Live`]'s, kept to those subsystems).
    pub(super) fn new(
        shared: Arc<Shared>,
        monitors: Monitors,
        links: Vec<LinkPlan>,
        watched: Vec<Option<SubsystemId>>,
        wanted: Vec<u64>,
        judged: Vec<ContractId>,
        not_judged: Vec<(ContractId, String)>,
    ) -> Watch {
        let nodes = watched.len();
        let mut watch = Watch {
            links,
            watched,
            shared,
            monitors,
            wanted,
            current: vec![None; nodes],
            held: vec![None; nodes],
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
            stamps: None,
            lazy: Vec::new(),
        };
        watch.held_at_activations = watch.readers_held_at_activations();
        watch
    }

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

    /// Whether link `link`'s sends only rates count, its writer and reader
    /// both watched here: the executor can keep its last send's instant
    /// instead of telling each ([`LinkEvents::stamps`]).
    fn stamped(&self, link: usize) -> bool {
        let Some(p) = self.links.get(link) else {
            return false;
        };
        let c = self.monitors.counts(p.input, p.output);
        p.writer && p.reader && c.arrivals && !c.sends
    }

    /// The last send on each link read from the executor's table, told to
    /// its rates if they have not heard of it: before the monitors judge
    /// a window that may have closed. Exact in the deterministic executor,
    /// which calls [`Observer::instant`] at every instant: a window that
    /// closed at `d` is judged at the first instant after `d`, before any
    /// send of that instant, so the last send read is the last one at or
    /// before `d` (and the sends between two windows' judgements are
    /// within one window of each other: only the last counts).
    fn lazy_arrivals(&mut self) {
        let Some(stamps) = &self.stamps else {
            return;
        };
        for z in &mut self.lazy {
            let last = stamps.last(z.link);
            if last > z.fed
                && let Some(t) = last
            {
                z.fed = last;
                self.monitors
                    .arrived(z.input, t, &mut |v| self.sink.take(v));
            }
        }
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
    /// bounds checked on the typed value where it is sent); of a link whose
    /// sends only rates count, with both ends watched here, none: the
    /// deterministic executor keeps the last one's instant
    /// ([`LinkEvents::stamps`]), read when a rate's window may have closed
    /// (other executors tell every send, which the rates take as they
    /// come). The events left
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
        // Sends only rates count, both ends here: their instants kept by
        // the executor, read when a window may have closed.
        let stamps = self.stamped(link);
        LinkEvents {
            transfers: p.writer && (c.sends || (c.arrivals && p.reader && !stamps)),
            out_of,
            reads: p.reader && ((c.reads && older_than.is_none()) || other_reads),
            older_than,
            stamps,
        }
    }

    /// The executor keeps the instants of the sends `link_events` asked it
    /// to: the rates of those links read them from now on.
    fn stamps(&mut self, stamps: &SendStamps) {
        self.lazy = (0..self.links.len())
            .filter(|&l| self.stamped(l))
            .filter_map(|link| {
                let input = self.links.get(link)?.input?;
                Some(Lazy {
                    link,
                    input,
                    fed: None,
                })
            })
            .collect();
        self.stamps = Some(stamps.clone());
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
        // A window may have closed, or a silent rate waits for its arrival.
        if !self.lazy.is_empty() && (self.monitors.due_before(time) || self.monitors.silent()) {
            self.lazy_arrivals();
        }
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
            // Told of a send it also reads from the table (an executor
            // or a second observer that asked for every send).
            if let Some(z) = self.lazy.iter_mut().find(|z| z.link == e.link) {
                z.fed = Some(t);
            }
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
        let raw = (values.known, values.value & values.known);
        // The same values as at an activation after which every invariant
        // held: they hold again (an invariant is a function of them).
        if self.held.get(e.node) == Some(&Some(raw)) {
            return;
        }
        // The FSM's bits to the spec's.
        let Some(remap) = self.shared.remaps.get(e.node) else {
            return;
        };
        let (known, value) = (remap.apply(raw.0), remap.apply(raw.1));
        let mut broken = false;
        let sink = &mut self.sink;
        self.monitors
            .predicates(sub, e.time, known, value, &mut |v| {
                broken = true;
                sink.take(v);
            });
        if let Some(h) = self.held.get_mut(e.node) {
            *h = (!broken).then_some(raw);
        }
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
            self.lazy_arrivals();
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
