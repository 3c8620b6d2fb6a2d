//! The events the monitors are fed, in time order, and what each kind makes
//! of them (the semantics are the crate documentation's).

use std::time::Duration;

use agent_core::Time;

use crate::*;

impl Monitors {
    /// Start watching at `t`: the rate windows start here; every run of a
    /// behaviour and every pending trigger is forgotten.
    pub fn start(&mut self, t: Time) {
        for f in &mut self.freshness {
            f.held = None;
            f.held_at = None;
        }
        for r in &mut self.rates {
            r.last = t;
            r.reported = false;
        }
        self.silent = 0;
        for b in &mut self.bounds {
            b.run = None;
        }
        for r in &mut self.responses {
            r.pending = None;
            r.last_response = None;
        }
        self.next_deadline = self
            .rates
            .iter()
            .map(|r| Time::from_nanos(r.last.as_nanos().saturating_add(r.window)))
            .min();
    }

    /// A value stamped `stamp` read from `input` by an activation at `t`.
    pub fn read(&mut self, input: InputId, t: Time, stamp: Time, sink: &mut impl FnMut(Violation)) {
        self.advance(t, sink);
        let age = t.as_nanos().saturating_sub(stamp.as_nanos());
        let (activations, mut due) = (self.activations, None);
        for &k in listed(&self.index.freshness_of, input.0) {
            let f = &mut self.freshness[k as usize];
            f.held = Some((stamp, age > f.max));
            f.held_at = None;
            due = earliest(due, f.deadline(activations));
            if age > f.max {
                sink(Violation {
                    time: t,
                    contract: f.contract,
                    broke: Broke::Age {
                        age: Duration::from_nanos(age),
                        max: Duration::from_nanos(f.max),
                    },
                });
            }
        }
        self.due(due);
    }

    /// The reader of `input` still holds, at its read at `t`, the value
    /// stamped `stamp` (no new value taken), and it may be too old: each
    /// freshness it is too old for reports it at the reader's activation at
    /// `t` ([`Monitors::activation`]), unless reported already, as if every
    /// read had been told ([`agent_core::trace::LinkEvents::older_than`]: the reads of a
    /// fresh value may then be left out). Nothing is reported here, and time
    /// does not advance (the activation's event advances it).
    pub fn held(&mut self, input: InputId, t: Time, stamp: Time) {
        let age = t.as_nanos().saturating_sub(stamp.as_nanos());
        for &k in listed(&self.index.freshness_of, input.0) {
            let f = &mut self.freshness[k as usize];
            if age > f.max && f.held != Some((stamp, true)) {
                f.held = Some((stamp, false));
                f.held_at = Some(t);
            }
        }
    }

    /// [`Monitors::held`], judged at once: each freshness of `input` that
    /// the value is too old for reports it now, at `t`, as the reader's
    /// activation at `t` would ([`Monitors::activation`]; it then reports
    /// nothing more of it). For a caller that does not give the reader's
    /// activations (the deterministic executor's watch, which asks for the
    /// reads of too old a value instead).
    pub fn held_judged(
        &mut self,
        input: InputId,
        t: Time,
        stamp: Time,
        sink: &mut impl FnMut(Violation),
    ) {
        self.held(input, t, stamp);
        for &k in listed(&self.index.freshness_of, input.0) {
            let f = &mut self.freshness[k as usize];
            if f.held_at == Some(t)
                && let Some(v) = f.stale_at(t)
            {
                sink(v);
            }
        }
    }

    /// A new value reaches `input` at `t` (its writer's send, or its arrival
    /// from another process).
    pub fn arrived(&mut self, input: InputId, t: Time, sink: &mut impl FnMut(Violation)) {
        self.advance(t, sink);
        let mut due = None;
        for &k in listed(&self.index.rates_of, input.0) {
            let r = &mut self.rates[k as usize];
            r.last = t;
            if r.reported {
                r.reported = false;
                self.silent = self.silent.saturating_sub(1);
            }
            due = earliest(due, Some(t.as_nanos().saturating_add(r.window)));
        }
        self.due(due);
    }

    /// A value sent on `output` at `t`.
    pub fn sent(&mut self, output: OutputId, t: Time, sink: &mut impl FnMut(Violation)) {
        self.advance(t, sink);
        let mut due = None;
        for &k in listed(&self.index.responses_of, output.0) {
            let r = &mut self.responses[k as usize];
            if r.response == output {
                r.last_response = Some(t);
                r.pending = None;
            }
            if r.trigger == output && r.last_response != Some(t) {
                let oldest = r.pending.map_or(t, |(oldest, _)| oldest);
                r.pending = Some((oldest, t));
                due = earliest(due, Some(oldest.as_nanos().saturating_add(r.within)));
            }
        }
        self.due(due);
    }

    /// The field of range `range` took `x` at `t`.
    pub fn value(&mut self, range: RangeId, t: Time, x: f64, sink: &mut impl FnMut(Violation)) {
        self.advance(t, sink);
        if let Some(v) = self.judge(range, t, x) {
            sink(v);
        }
    }

    /// What range `range` makes of `x` at `t` (time already advanced to `t`).
    #[inline]
    pub(crate) fn judge(&self, range: RangeId, t: Time, x: f64) -> Option<Violation> {
        let r = self.ranges.get(range.0 as usize).filter(|r| r.active)?;
        (!agent_core::trace::within(x, r.min, r.max)).then_some(Violation {
            time: t,
            contract: r.contract,
            broke: Broke::OutOfRange {
                value: x,
                min: r.min,
                max: r.max,
            },
        })
    }

    /// `subsystem` entered `behaviour` at `t` (leaving the one it was in); an
    /// executor calls it for the initial behaviour too. `None`: it ended (a
    /// final behaviour finished).
    pub fn entered(
        &mut self,
        subsystem: SubsystemId,
        behaviour: Option<BehaviourId>,
        t: Time,
        sink: &mut impl FnMut(Violation),
    ) {
        self.advance(t, sink);
        for &k in listed(&self.index.bounds_of, subsystem.0) {
            let b = &mut self.bounds[k as usize];
            b.close(t, sink);
            if behaviour == Some(b.behaviour) {
                b.run = Some((t, 0));
                b.lasted_reported = false;
                b.iterations_reported = false;
            }
        }
    }

    /// An activation of `subsystem` at `t` (after its transition, if it made
    /// one); with the values of its predicates (in the spec's order) when the
    /// caller has them, for the invariants.
    pub fn activation(
        &mut self,
        subsystem: SubsystemId,
        t: Time,
        predicates: Option<&[bool]>,
        sink: &mut impl FnMut(Violation),
    ) {
        self.advance(t, sink);
        for &k in listed(&self.index.bounds_of, subsystem.0) {
            self.bounds[k as usize].activation(t, sink);
        }
        if self.activations {
            for &k in listed(&self.index.read_by, subsystem.0) {
                let f = &mut self.freshness[k as usize];
                if f.held_at.is_none_or(|at| at == t)
                    && let Some(v) = f.stale_at(t)
                {
                    sink(v);
                }
            }
        }
        let Some(values) = predicates else {
            return;
        };
        let (mut known, mut value) = (0u64, 0u64);
        for (k, &v) in values.iter().take(64).enumerate() {
            known |= 1 << k;
            value |= u64::from(v) << k;
        }
        self.predicates(subsystem, t, known, value, sink);
    }

    /// The values of `subsystem`'s predicates after an activation at `t`
    /// (bit `i`: its predicate `i` in the spec's order,
    /// [`Monitors::predicate_names`]; `known`: those evaluated): each of its
    /// invariants whose predicates are all known is judged.
    pub fn predicates(
        &mut self,
        subsystem: SubsystemId,
        t: Time,
        known: u64,
        value: u64,
        sink: &mut impl FnMut(Violation),
    ) {
        for &k in listed(&self.index.invariants_of, subsystem.0) {
            let i = &mut self.invariants[k as usize];
            let Some(uses) = i.uses.filter(|u| known & u == *u) else {
                continue;
            };
            let read = value & uses;
            let holds = match i.last {
                Some((last, holds)) if last == read => holds,
                _ => {
                    let holds = i.holds.eval(&mut |&k| read >> k & 1 == 1);
                    i.last = Some((read, holds));
                    holds
                }
            };
            if !holds {
                sink(Violation {
                    time: t,
                    contract: i.contract,
                    broke: Broke::False {
                        predicates: value & uses,
                        reads: uses,
                    },
                });
            }
        }
    }

    /// Whether a deadline may have passed before `t` (a rate's window
    /// closed, a response or a freshness due): whether [`Monitors::advance`]
    /// to `t` would judge anything.
    #[inline]
    pub(crate) fn due_before(&self, t: Time) -> bool {
        self.next_deadline.is_some_and(|d| t > d)
    }

    /// Whether a rate's window closed empty and it waits for an arrival.
    #[inline]
    pub(crate) fn silent(&self) -> bool {
        self.silent > 0
    }

    /// Time has reached `t`: report the rate windows and response deadlines
    /// that passed before it (every event calls this first).
    pub fn advance(&mut self, t: Time, sink: &mut impl FnMut(Violation)) {
        match self.next_deadline {
            Some(d) if t > d => {}
            _ => return,
        }
        for f in &mut self.freshness {
            if let (Some(a), Some((s, _))) = (f.deadline(self.activations), f.held)
                && t.as_nanos() > a
            {
                f.held = Some((s, true));
                sink(Violation {
                    time: Time::from_nanos(a),
                    contract: f.contract,
                    broke: Broke::Age {
                        age: Duration::from_nanos(a - s.as_nanos()),
                        max: Duration::from_nanos(f.max),
                    },
                });
            }
        }
        for r in &mut self.rates {
            let end = r.last.as_nanos().saturating_add(r.window);
            if !r.reported && t.as_nanos() > end {
                r.reported = true;
                self.silent += 1;
                sink(Violation {
                    time: Time::from_nanos(end),
                    contract: r.contract,
                    broke: Broke::Silent {
                        since: r.last,
                        window: Duration::from_nanos(r.window),
                    },
                });
            }
        }
        for r in &mut self.responses {
            while let Some((oldest, newest)) = r.pending {
                let deadline = oldest.as_nanos().saturating_add(r.within);
                if t.as_nanos() <= deadline {
                    break;
                }
                sink(Violation {
                    time: Time::from_nanos(deadline),
                    contract: r.contract,
                    broke: Broke::Unanswered {
                        trigger: oldest,
                        within: Duration::from_nanos(r.within),
                    },
                });
                r.pending = (newest != oldest).then_some((newest, newest));
            }
        }
        self.recompute_deadline();
    }

    /// The run ended at `t`: the windows and deadlines up to `t` are judged
    /// (a deadline after `t` is not: the run ended before it), and each
    /// behaviour's current run is judged on its duration so far.
    pub fn finish(&mut self, t: Time, sink: &mut impl FnMut(Violation)) {
        // `advance` reports deadlines strictly before its instant; the end
        // itself is inside every window that reaches it.
        self.advance(t, sink);
        for b in &mut self.bounds {
            b.close(t, sink);
        }
    }

    /// A deadline at `d` (ns), if any, may come before the next one known.
    /// Only deadlines added or moved earlier are told: one that passed or
    /// moved later leaves `next_deadline` early, which costs one
    /// scan in [`Monitors::advance`] when it comes (which then recomputes it),
    /// instead of a scan of every monitor at every event.
    fn due(&mut self, d: Option<u64>) {
        if let Some(d) = d.map(Time::from_nanos) {
            self.next_deadline = Some(self.next_deadline.map_or(d, |n| n.min(d)));
        }
    }

    /// The earliest deadline of every monitor (a scan of them all).
    pub(crate) fn recompute_deadline(&mut self) {
        let rates = self
            .rates
            .iter()
            .filter(|r| !r.reported)
            .map(|r| r.last.as_nanos().saturating_add(r.window));
        let responses = self.responses.iter().filter_map(|r| {
            r.pending
                .map(|(o, _)| o.as_nanos().saturating_add(r.within))
        });
        let activations = self.activations;
        let stale = self
            .freshness
            .iter()
            .filter_map(|f| f.deadline(activations));
        self.next_deadline = rates
            .chain(responses)
            .chain(stale)
            .min()
            .map(Time::from_nanos);
    }
}

/// The earlier of two deadlines, either absent.
fn earliest(a: Option<u64>, b: Option<u64>) -> Option<u64> {
    match (a, b) {
        (Some(a), Some(b)) => Some(a.min(b)),
        (a, b) => a.or(b),
    }
}

impl FreshnessM {
    /// The violation of a value held at `t` too old and not yet reported
    /// (then marked reported).
    fn stale_at(&mut self, t: Time) -> Option<Violation> {
        let Some((s, false)) = self.held else {
            return None;
        };
        let age = t.as_nanos().saturating_sub(s.as_nanos());
        if age <= self.max {
            return None;
        }
        self.held = Some((s, true));
        Some(Violation {
            time: t,
            contract: self.contract,
            broke: Broke::Age {
                age: Duration::from_nanos(age),
                max: Duration::from_nanos(self.max),
            },
        })
    }
}

impl BoundM {
    /// The current run ends at `t`: judge its duration.
    fn close(&mut self, t: Time, sink: &mut impl FnMut(Violation)) {
        let Some((entered, _)) = self.run.take() else {
            return;
        };
        self.check_lasted(entered, t, sink);
    }

    fn check_lasted(&mut self, entered: Time, t: Time, sink: &mut impl FnMut(Violation)) {
        if let Some(max) = self.max
            && !self.lasted_reported
            && t.as_nanos().saturating_sub(entered.as_nanos()) > max
        {
            self.lasted_reported = true;
            sink(Violation {
                time: Time::from_nanos(entered.as_nanos().saturating_add(max)),
                contract: self.contract,
                broke: Broke::Lasted {
                    entered,
                    max: Duration::from_nanos(max),
                },
            });
        }
    }

    fn activation(&mut self, t: Time, sink: &mut impl FnMut(Violation)) {
        let Some((entered, n)) = self.run else {
            return;
        };
        let n = n + 1;
        self.run = Some((entered, n));
        self.check_lasted(entered, t, sink);
        if let Some(max) = self.max_iterations
            && n > max
            && !self.iterations_reported
        {
            self.iterations_reported = true;
            sink(Violation {
                time: t,
                contract: self.contract,
                broke: Broke::Iterations {
                    entered,
                    iterations: n,
                    max,
                },
            });
        }
    }
}
