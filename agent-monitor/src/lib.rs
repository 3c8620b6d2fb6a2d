//! Runtime monitors made from a spec's contracts ([`agent_spec::contracts`]).
//!
//! [`Monitors::new`] compiles the contracts of a [`Spec`](agent_spec::Spec) once (names resolved
//! to indices, bounds to nanoseconds, invariants to expressions over predicate
//! indices); the monitors are then fed events in time order, from an executor
//! or from a recording (the module `recording`, feature `recording`), and hand each
//! [`Violation`] to a sink. The core knows no executor: an event is an instant
//! and a few numbers. Memory is fixed at construction (a few words per
//! contract) and no event allocates ([`Violation`] is `Copy`; names are looked
//! up with [`Monitors::contract`] when a violation is shown).
//!
//! Semantics, per kind (`t` an event's instant; a bound is never violated by
//! equality):
//!
//! * **freshness** (`input`, `max_age_ms`): every activation of the reader at
//!   `t` reads the value its buffer holds, stamped `s`, of age `t - s`;
//!   violated when `t - s > max_age`. Reported at the read of a value already
//!   too old, or, when no newer value comes, at the first activation of the
//!   reader after `s + max_age` (given by the executor,
//!   [`Monitors::at_activations`]; over a recording, on the reader's period's
//!   grid from the spec), once per value held: a sensor that stops sending is
//!   found here.
//! * **rate** (`input`, `min_hz`): with `W = 1 / min_hz`, every half-open
//!   window `(u, u + W]` from the start ([`Monitors::start`]) to the end
//!   ([`Monitors::finish`]) holds at least one arrival at `input`:
//!   equivalently no gap between the start, consecutive arrivals and the end
//!   is longer than `W`. Reported once per silence, at `last + W` (the instant
//!   the window closed empty), with the instant of the last arrival.
//! * **bound** (`subsystem.behaviour`, `max_s`, `max_iterations`): a run of the
//!   behaviour lasts from the activation that enters it to the one that
//!   enters the next (or the end); violated when it lasts longer than `max_s`
//!   (reported at `entered + max_s`) or takes more than `max_iterations`
//!   activations (reported at the activation that exceeds it). At most one
//!   violation of each limit per run.
//! * **range** (`buffer`, `field`, `min`, `max`): each value `x` of the field
//!   ([`Monitors::value`]; the caller reads the field) satisfies
//!   `min <= x <= max`; NaN is out of range. Reported at the value.
//! * **response** (`trigger`, `response`, `within_s`): every value sent on
//!   `trigger` at `t` is followed by a value sent on `response` at some `t'`
//!   with `t <= t' <= t + within` (the same instant counts, as in STL's
//!   `trigger -> eventually[0, S] response`). A response answers every
//!   trigger before it, so only the oldest and the newest unanswered trigger
//!   are kept: when the oldest's deadline passes, a violation is reported at
//!   that deadline and the newest becomes the one pending. The verdict is
//!   exact; with three or more triggers pending at once, those between the
//!   oldest and the newest are not reported one by one (the count of
//!   violations is then a lower bound).
//! * **invariant** (`subsystem`, `holds`): after each activation of the
//!   subsystem whose predicate values are given ([`Monitors::predicates`]),
//!   `holds` is true. Reported at the activation, with the values of the
//!   predicates it reads (bit `i`: predicate `i`, the first 64). An
//!   activation whose values lack one of its predicates does not judge it.
//!
//! Chains are not monitored here (their data age needs the whole path's
//! stamps; the timing analysis, [`agent_spec::timing`], bounds them).

use std::fmt;
use std::time::Duration;

use agent_core::{Expr, Time};

mod compile;
mod ends;
mod events;
mod field;
pub mod live;
#[cfg(feature = "recording")]
pub mod recording;
mod show;

/// A contract, by its index in [`Monitors::contracts`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct ContractId(pub u32);

/// An input buffer some freshness or rate contract names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct InputId(u32);

/// An output buffer some response contract names.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct OutputId(u32);

/// A subsystem of the spec.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SubsystemId(u32);

/// A behaviour of a subsystem, by its index among the subsystem's behaviours.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct BehaviourId(pub u32);

/// A range contract, by its index in [`Monitors::ranges`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct RangeId(u32);

/// The kind of a contract.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum ContractKind {
    /// [`agent_spec::contracts::Freshness`].
    Freshness,
    /// [`agent_spec::contracts::Rate`].
    Rate,
    /// [`agent_spec::contracts::Bound`].
    Bound,
    /// [`agent_spec::contracts::ValueRange`].
    Range,
    /// [`agent_spec::contracts::Response`].
    Response,
    /// [`agent_spec::contracts::Invariant`].
    Invariant,
}

impl fmt::Display for ContractKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            ContractKind::Freshness => "freshness",
            ContractKind::Rate => "rate",
            ContractKind::Bound => "bound",
            ContractKind::Range => "range",
            ContractKind::Response => "response",
            ContractKind::Invariant => "invariant",
        })
    }
}

/// What a contract is, for showing its violations.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ContractInfo {
    /// Its kind.
    pub kind: ContractKind,
    /// Its name: the given one (ranges, responses, invariants), else what it
    /// constrains (the input of a freshness or rate, `subsystem.behaviour`).
    pub name: String,
    /// The subsystem it holds of: the reader of an input, the behaviour's or
    /// invariant's subsystem, the buffer's component (a range), the
    /// response's writer.
    pub subsystem: String,
}

/// The values that broke a contract.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Broke {
    /// A value read older than allowed.
    Age {
        /// Its age at the read.
        age: Duration,
        /// The largest allowed.
        max: Duration,
    },
    /// No value reached the input for longer than the window.
    Silent {
        /// The last arrival (or the start, before the first).
        since: Time,
        /// The window `1 / min_hz`.
        window: Duration,
    },
    /// A run of a behaviour lasted longer than allowed.
    Lasted {
        /// When the run started.
        entered: Time,
        /// The longest allowed.
        max: Duration,
    },
    /// A run of a behaviour took more activations than allowed.
    Iterations {
        /// When the run started.
        entered: Time,
        /// Activations so far in the run.
        iterations: u64,
        /// The most allowed.
        max: u64,
    },
    /// A value out of its range.
    OutOfRange {
        /// The value.
        value: f64,
        /// The least allowed.
        min: Option<f64>,
        /// The greatest allowed.
        max: Option<f64>,
    },
    /// A trigger without a response within the deadline.
    Unanswered {
        /// When the trigger was sent.
        trigger: Time,
        /// The deadline after it.
        within: Duration,
    },
    /// An invariant false after an activation.
    False {
        /// The values of the predicates it reads (bit `i`: predicate `i` of
        /// the subsystem, in the spec's order).
        predicates: u64,
        /// Which predicates it reads (the bits of `predicates` that count).
        reads: u64,
    },
}

/// A contract broken at an instant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Violation {
    /// When: the event that broke it, or the deadline that passed.
    pub time: Time,
    /// Which contract ([`Monitors::contract`]).
    pub contract: ContractId,
    /// The values that broke it.
    pub broke: Broke,
}

/// Why a spec's contracts do not make monitors (the checker,
/// [`agent_spec::check()`], reports the same with spans).
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum BuildError {
    /// A name that is not in the spec.
    #[error("{kind} contract `{contract}`: {what}")]
    Unknown {
        /// The contract's kind.
        kind: ContractKind,
        /// Its name.
        contract: String,
        /// What is missing.
        what: String,
    },
    /// A bound that is not a positive finite number.
    #[error("{kind} contract `{contract}`: the bound {value} is not a positive finite number")]
    Bound {
        /// The contract's kind.
        kind: ContractKind,
        /// Its name.
        contract: String,
        /// The bound.
        value: f64,
    },
}

#[derive(Clone, Debug)]
struct FreshnessM {
    contract: ContractId,
    input: InputId,
    max: u64,
    /// The reader's period (ns; 0: unknown, judged at reads only).
    period: u64,
    /// The reader, when it is a subsystem (its activations are given when
    /// the monitors watch a running executor).
    reader: Option<SubsystemId>,
    /// The stamp of the value the input holds, and whether its age was
    /// reported.
    held: Option<(Time, bool)>,
    /// When the value held was last told by [`Monitors::held`] (`None`: by a
    /// read): an activation at another instant does not judge it (the reader
    /// may have taken a fresh value since, which no read told).
    held_at: Option<Time>,
}

impl FreshnessM {
    /// The first activation of the reader at which the value held is too
    /// old, on its period's grid (none once reported, with no period, or when
    /// the reader's activations are given: `activations`).
    fn deadline(&self, activations: bool) -> Option<u64> {
        if activations && self.reader.is_some() {
            return None;
        }
        match self.held {
            Some((s, false)) if self.period > 0 => {
                let last_fresh = s.as_nanos().saturating_add(self.max);
                Some((last_fresh / self.period + 1).saturating_mul(self.period))
            }
            _ => None,
        }
    }
}

#[derive(Clone, Debug)]
struct RateM {
    contract: ContractId,
    input: InputId,
    window: u64,
    /// The last arrival, or the start.
    last: Time,
    /// Whether the current silence was reported.
    reported: bool,
}

#[derive(Clone, Debug)]
struct BoundM {
    contract: ContractId,
    subsystem: SubsystemId,
    behaviour: BehaviourId,
    max: Option<u64>,
    max_iterations: Option<u64>,
    /// The current run: when it started and its activations so far.
    run: Option<(Time, u64)>,
    lasted_reported: bool,
    iterations_reported: bool,
}

#[derive(Clone, Debug)]
struct RangeM {
    contract: ContractId,
    min: Option<f64>,
    max: Option<f64>,
    /// Judged here ([`Monitors::retain_subsystems`] keeps the index).
    active: bool,
}

#[derive(Clone, Debug)]
struct ResponseM {
    contract: ContractId,
    trigger: OutputId,
    response: OutputId,
    within: u64,
    /// The oldest and newest unanswered triggers.
    pending: Option<(Time, Time)>,
    last_response: Option<Time>,
}

#[derive(Clone, Debug)]
struct InvariantM {
    contract: ContractId,
    subsystem: SubsystemId,
    holds: Expr<usize>,
    /// The predicates it reads (bit `i`: the subsystem's predicate `i`);
    /// `None` when one is past the 64th (then it is never judged).
    uses: Option<u64>,
    /// The last values of the predicates it reads it was judged on, and its
    /// verdict then (a subsystem's predicates rarely change from one
    /// activation to the next: the expression is evaluated when they do).
    last: Option<(u64, bool)>,
}

/// Which monitors each kind of event concerns, by their indices in the
/// monitors' vectors: made when the set of monitors changes
/// ([`Monitors::reindex`]), so that an event visits those only.
#[derive(Clone, Debug, Default)]
struct Index {
    /// Per input: its freshness monitors.
    freshness_of: Vec<Vec<u32>>,
    /// Per input: its rate monitors.
    rates_of: Vec<Vec<u32>>,
    /// Per output: the responses it triggers or answers.
    responses_of: Vec<Vec<u32>>,
    /// Per subsystem: its bounds.
    bounds_of: Vec<Vec<u32>>,
    /// Per subsystem: the freshness monitors of the inputs it reads.
    read_by: Vec<Vec<u32>>,
    /// Per subsystem: its invariants.
    invariants_of: Vec<Vec<u32>>,
}

/// What the monitors count of a link's ends ([`Monitors::counts`]).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Counts {
    /// The reads of its input (a freshness).
    pub(crate) reads: bool,
    /// The arrivals at its input (a rate).
    pub(crate) arrivals: bool,
    /// The sends on its output (a response).
    pub(crate) sends: bool,
}

/// The indices `k` of `items` (by `key`) for each of `n` keys.
fn index_by<T>(n: usize, items: &[T], key: impl Fn(&T) -> Option<usize>) -> Vec<Vec<u32>> {
    let mut out = vec![Vec::new(); n];
    for (k, item) in items.iter().enumerate() {
        if let Some(slot) = key(item).and_then(|i| out.get_mut(i)) {
            slot.push(k as u32);
        }
    }
    out
}

/// The monitors of `index`'s list `i` (none when `i` is out of it).
#[inline]
fn listed(index: &[Vec<u32>], i: u32) -> &[u32] {
    index.get(i as usize).map_or(&[], Vec::as_slice)
}

/// A subsystem's names, for resolving events.
#[derive(Clone, Debug)]
struct SubsystemInfo {
    name: String,
    behaviours: Vec<String>,
    predicates: Vec<String>,
    initial: Option<BehaviourId>,
}

/// The monitors of a spec's contracts (see the [crate] documentation).
#[derive(Clone, Debug)]
pub struct Monitors {
    contracts: Vec<ContractInfo>,
    inputs: Vec<String>,
    outputs: Vec<String>,
    subsystems: Vec<SubsystemInfo>,
    ranges_of: Vec<(String, Option<String>)>,
    freshness: Vec<FreshnessM>,
    rates: Vec<RateM>,
    bounds: Vec<BoundM>,
    ranges: Vec<RangeM>,
    responses: Vec<ResponseM>,
    invariants: Vec<InvariantM>,
    /// The earliest deadline a rate or response monitor waits for.
    next_deadline: Option<Time>,
    /// The rates whose window closed empty, waiting for an arrival (they
    /// have no deadline until it comes).
    silent: u32,
    /// Whether the readers' activations are given ([`Monitors::at_activations`]).
    activations: bool,
    /// Which monitors each event concerns.
    index: Index,
}

/// How many contracts `violations` break (each counted once).
fn contracts_violated(violations: &[Violation]) -> usize {
    let mut c: Vec<ContractId> = violations.iter().map(|v| v.contract).collect();
    c.sort_unstable();
    c.dedup();
    c.len()
}

impl Monitors {
    /// Every contract, by [`ContractId`].
    pub fn contracts(&self) -> &[ContractInfo] {
        &self.contracts
    }

    /// One contract.
    pub fn contract(&self, id: ContractId) -> Option<&ContractInfo> {
        self.contracts.get(id.0 as usize)
    }

    /// The input `component.group.buffer`, if a freshness or rate contract names it.
    pub fn input(&self, name: &str) -> Option<InputId> {
        self.inputs
            .iter()
            .position(|n| n == name)
            .map(|i| InputId(i as u32))
    }

    /// The output `component.group.buffer`, if a response contract names it.
    pub fn output(&self, name: &str) -> Option<OutputId> {
        self.outputs
            .iter()
            .position(|n| n == name)
            .map(|i| OutputId(i as u32))
    }

    /// A subsystem of the spec.
    pub fn subsystem(&self, name: &str) -> Option<SubsystemId> {
        self.subsystems
            .iter()
            .position(|s| s.name == name)
            .map(|i| SubsystemId(i as u32))
    }

    /// A behaviour of a subsystem.
    pub fn behaviour(&self, subsystem: SubsystemId, name: &str) -> Option<BehaviourId> {
        self.subsystems
            .get(subsystem.0 as usize)?
            .behaviours
            .iter()
            .position(|b| b == name)
            .map(|i| BehaviourId(i as u32))
    }

    /// The behaviour a subsystem starts in (its FSM's initial one).
    pub fn initial(&self, subsystem: SubsystemId) -> Option<BehaviourId> {
        self.subsystems.get(subsystem.0 as usize)?.initial
    }

    /// The range contracts: each one's id, buffer and field path, for the
    /// caller to read the field of each value of the buffer and hand it to
    /// [`Monitors::value`].
    pub fn ranges(&self) -> impl Iterator<Item = (RangeId, &str, Option<&str>)> {
        self.ranges_of
            .iter()
            .enumerate()
            .map(|(i, (b, f))| (RangeId(i as u32), b.as_str(), f.as_deref()))
    }

    /// The contract a range monitor checks (`None` once it is not judged
    /// here: [`Monitors::retain_subsystems`]).
    pub fn range_contract(&self, range: RangeId) -> Option<ContractId> {
        self.ranges
            .get(range.0 as usize)
            .filter(|r| r.active)
            .map(|r| r.contract)
    }

    /// The bounds of a range monitor judged here (`None` once it is not:
    /// [`Monitors::retain_subsystems`]).
    pub(crate) fn range_bounds(&self, range: RangeId) -> Option<(Option<f64>, Option<f64>)> {
        self.ranges
            .get(range.0 as usize)
            .filter(|r| r.active)
            .map(|r| (r.min, r.max))
    }

    /// The behaviours of `subsystem` that bounds count the activations and
    /// duration of.
    pub(crate) fn bounded(&self, subsystem: SubsystemId) -> impl Iterator<Item = BehaviourId> + '_ {
        listed(&self.index.bounds_of, subsystem.0)
            .iter()
            .map(|&k| self.bounds[k as usize].behaviour)
    }

    /// The age beyond which a read of `input` changes a monitor here, when
    /// that is all its reads are for: every freshness of `input` has the
    /// same bound and a reader whose activations are given
    /// ([`Monitors::at_activations`]). Then a read of a fresh value may be
    /// left out, and the value a reader holds is told only when it is older
    /// ([`Monitors::held`]): each activation judges it as it would have.
    pub(crate) fn freshness_bound(&self, input: InputId) -> Option<u64> {
        let mut all = listed(&self.index.freshness_of, input.0)
            .iter()
            .map(|&k| &self.freshness[k as usize]);
        let first = all.next()?;
        let same = |f: &FreshnessM| f.max == first.max && f.reader.is_some();
        (self.activations && same(first) && all.all(same)).then_some(first.max)
    }

    /// Whether a monitor here counts the reads of `input` (a freshness), its
    /// arrivals (a rate), the sends on `output` (a response).
    pub(crate) fn counts(&self, input: Option<InputId>, output: Option<OutputId>) -> Counts {
        let any =
            |index: &[Vec<u32>], i: Option<u32>| i.is_some_and(|i| !listed(index, i).is_empty());
        let i = input.map(|i| i.0);
        Counts {
            reads: any(&self.index.freshness_of, i),
            arrivals: any(&self.index.rates_of, i),
            sends: any(&self.index.responses_of, output.map(|o| o.0)),
        }
    }

    /// The name of a subsystem.
    pub fn subsystem_name(&self, id: SubsystemId) -> &str {
        self.subsystems
            .get(id.0 as usize)
            .map_or("", |s| s.name.as_str())
    }

    /// Judge only the contracts of the subsystems `keep` accepts (those of a
    /// thread or a process of a run): the others are never judged here.
    /// Contract, input, output and range ids stay what they were.
    pub fn retain_subsystems(&mut self, keep: impl Fn(&str) -> bool) {
        let contracts = &self.contracts;
        let k = |c: ContractId| keep(&contracts[c.0 as usize].subsystem);
        self.freshness.retain(|f| k(f.contract));
        self.rates.retain(|r| k(r.contract));
        self.bounds.retain(|b| k(b.contract));
        self.responses.retain(|r| k(r.contract));
        self.invariants.retain(|i| k(i.contract));
        for r in &mut self.ranges {
            r.active &= k(r.contract);
        }
        self.reindex();
        self.recompute_deadline();
    }

    /// Make the [`Index`] of the monitors as they are now.
    pub(crate) fn reindex(&mut self) {
        let (inputs, outputs, subsystems) =
            (self.inputs.len(), self.outputs.len(), self.subsystems.len());
        let reads = |f: &FreshnessM| f.reader.map(|s| s.0 as usize);
        self.index = Index {
            freshness_of: index_by(inputs, &self.freshness, |f| Some(f.input.0 as usize)),
            rates_of: index_by(inputs, &self.rates, |r| Some(r.input.0 as usize)),
            responses_of: (0..outputs)
                .map(|o| {
                    let o = OutputId(o as u32);
                    let on = self.responses.iter().enumerate();
                    on.filter(|(_, r)| r.trigger == o || r.response == o)
                        .map(|(k, _)| k as u32)
                        .collect()
                })
                .collect(),
            bounds_of: index_by(subsystems, &self.bounds, |b| Some(b.subsystem.0 as usize)),
            read_by: index_by(subsystems, &self.freshness, reads),
            invariants_of: index_by(subsystems, &self.invariants, |i| {
                Some(i.subsystem.0 as usize)
            }),
        };
    }

    /// The readers' activations will be given ([`Monitors::activation`], as a
    /// running executor's watch does): a freshness whose reader is a
    /// subsystem is then judged at each of its activations (a subsystem that
    /// halted reads nothing, and is not judged), not on its period's grid.
    pub fn at_activations(&mut self) {
        self.activations = true;
        self.recompute_deadline();
    }

    /// The contracts judged here (every one, unless
    /// [`Monitors::retain_subsystems`] kept some only).
    pub fn judged(&self) -> impl Iterator<Item = ContractId> + '_ {
        let f = self.freshness.iter().map(|m| m.contract);
        let r = self.rates.iter().map(|m| m.contract);
        let b = self.bounds.iter().map(|m| m.contract);
        let v = self.ranges.iter().filter(|m| m.active).map(|m| m.contract);
        let p = self.responses.iter().map(|m| m.contract);
        let i = self.invariants.iter().map(|m| m.contract);
        f.chain(r).chain(b).chain(v).chain(p).chain(i)
    }

    /// The contract of each invariant, for a caller that cannot evaluate them.
    pub fn invariant_contracts(&self) -> impl Iterator<Item = ContractId> + '_ {
        self.invariants.iter().map(|i| i.contract)
    }

    /// Each invariant judged here: its contract, its subsystem and the
    /// predicates it reads (bit `i`: the subsystem's predicate `i` in the
    /// spec's order, [`Monitors::predicate_names`]; `None`: one is past the
    /// 64th, which [`Monitors::predicates`] cannot be given).
    pub fn invariants(&self) -> impl Iterator<Item = (ContractId, SubsystemId, Option<u64>)> + '_ {
        self.invariants
            .iter()
            .map(|i| (i.contract, i.subsystem, i.uses))
    }

    /// The predicates of a subsystem, in the spec's order (the bits of
    /// [`Monitors::predicates`]).
    pub fn predicate_names(&self, subsystem: SubsystemId) -> &[String] {
        self.subsystems
            .get(subsystem.0 as usize)
            .map_or(&[], |s| s.predicates.as_slice())
    }

    /// A violation as a line: `time subsystem kind name: values`.
    pub fn display<'a>(&'a self, v: &'a Violation) -> impl fmt::Display + 'a {
        show::Shown { m: self, v }
    }
}

#[cfg(test)]
mod tests;
