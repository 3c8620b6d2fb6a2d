//! Runtime monitors made from a spec's contracts ([`agent_spec::contracts`]).
//!
//! [`Monitors::new`] compiles the contracts of a [`Spec`] once (names resolved
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
//!   subsystem whose predicate values are given, `holds` is true. Reported at
//!   the activation, with the predicate values (bit `i`: predicate `i`, the
//!   first 64).
//!
//! Chains are not monitored here (their data age needs the whole path's
//! stamps; the timing analysis, [`agent_spec::timing`], bounds them).

use std::fmt;
use std::time::Duration;

use agent_core::{Expr, Time};
use agent_spec::Spec;
use agent_spec::model::Subsystem;

mod ends;
mod field;
pub mod live;
#[cfg(feature = "recording")]
pub mod recording;

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
        /// The predicate values (bit `i`: predicate `i` of the subsystem).
        predicates: u64,
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
    /// Whether the readers' activations are given ([`Monitors::at_activations`]).
    activations: bool,
}

fn positive_ns(
    kind: ContractKind,
    contract: &str,
    value: f64,
    unit: f64,
) -> Result<u64, BuildError> {
    let ns = value * unit;
    if value.is_finite() && value > 0.0 && ns < u64::MAX as f64 {
        Ok(ns.round() as u64)
    } else {
        Err(BuildError::Bound {
            kind,
            contract: contract.to_owned(),
            value,
        })
    }
}

/// How many contracts `violations` break (each counted once).
fn contracts_violated(violations: &[Violation]) -> usize {
    let mut c: Vec<ContractId> = violations.iter().map(|v| v.contract).collect();
    c.sort_unstable();
    c.dedup();
    c.len()
}

/// The period of component `name` (ns; 0 if the spec has no such component
/// or its period is not a positive finite number).
fn period_ns(spec: &Spec, name: &str) -> u64 {
    let subsystems = spec.agents.iter().flat_map(|a| a.subsystems.iter());
    let devices = spec.agents.iter().flat_map(|a| a.devices.iter());
    let period = subsystems
        .map(|s| (&s.name, s.period_ms))
        .chain(devices.map(|d| (&d.name, d.period_ms)))
        .find(|(n, _)| *n == name)
        .map_or(0.0, |(_, p)| p);
    if period.is_finite() && period > 0.0 {
        (period * 1e6).round() as u64
    } else {
        0
    }
}

/// The component a `component.group.buffer` name starts with.
fn component(name: &str) -> &str {
    name.split('.').next().unwrap_or(name)
}

fn intern(names: &mut Vec<String>, name: &str) -> u32 {
    match names.iter().position(|n| n == name) {
        Some(i) => i as u32,
        None => {
            names.push(name.to_owned());
            (names.len() - 1) as u32
        }
    }
}

impl Monitors {
    /// The monitors of `spec`'s contracts (none: a spec without contracts).
    pub fn new(spec: &Spec) -> Result<Monitors, BuildError> {
        let subsystems: Vec<&Subsystem> = spec
            .agents
            .iter()
            .flat_map(|a| a.subsystems.iter())
            .collect();
        let mut m = Monitors {
            contracts: Vec::new(),
            inputs: Vec::new(),
            outputs: Vec::new(),
            subsystems: subsystems
                .iter()
                .map(|s| SubsystemInfo {
                    name: s.name.clone(),
                    behaviours: s.behaviours.iter().map(|b| b.name.clone()).collect(),
                    predicates: s.predicates.iter().map(|p| p.name.clone()).collect(),
                    initial: s
                        .fsm
                        .initial
                        .as_ref()
                        .and_then(|i| s.behaviours.iter().position(|b| &b.name == i))
                        .map(|i| BehaviourId(i as u32)),
                })
                .collect(),
            ranges_of: Vec::new(),
            freshness: Vec::new(),
            rates: Vec::new(),
            bounds: Vec::new(),
            ranges: Vec::new(),
            responses: Vec::new(),
            invariants: Vec::new(),
            next_deadline: None,
            activations: false,
        };
        let Some(c) = &spec.contracts else {
            return Ok(m);
        };
        for f in &c.freshness {
            let contract = m.add(ContractKind::Freshness, &f.input, component(&f.input));
            let max = positive_ns(ContractKind::Freshness, &f.input, f.max_age_ms, 1e6)?;
            let input = InputId(intern(&mut m.inputs, &f.input));
            let reader = m.subsystem(component(&f.input));
            m.freshness.push(FreshnessM {
                contract,
                input,
                max,
                period: period_ns(spec, component(&f.input)),
                reader,
                held: None,
            });
        }
        for r in &c.rates {
            let contract = m.add(ContractKind::Rate, &r.input, component(&r.input));
            let window = positive_ns(ContractKind::Rate, &r.input, 1.0 / r.min_hz, 1e9)?;
            let input = InputId(intern(&mut m.inputs, &r.input));
            m.rates.push(RateM {
                contract,
                input,
                window,
                last: Time::ZERO,
                reported: false,
            });
        }
        for b in &c.bounds {
            m.add_bound(b)?;
        }
        for r in &c.ranges {
            let contract = m.add(ContractKind::Range, &r.name, component(&r.buffer));
            m.ranges_of.push((r.buffer.clone(), r.field.clone()));
            m.ranges.push(RangeM {
                contract,
                min: r.min,
                max: r.max,
                active: true,
            });
        }
        for r in &c.responses {
            let contract = m.add(ContractKind::Response, &r.name, component(&r.response));
            let within = positive_ns(ContractKind::Response, &r.name, r.within_s, 1e9)?;
            let trigger = OutputId(intern(&mut m.outputs, &r.trigger));
            let response = OutputId(intern(&mut m.outputs, &r.response));
            m.responses.push(ResponseM {
                contract,
                trigger,
                response,
                within,
                pending: None,
                last_response: None,
            });
        }
        for i in &c.invariants {
            m.add_invariant(i)?;
        }
        Ok(m)
    }

    fn add(&mut self, kind: ContractKind, name: &str, subsystem: &str) -> ContractId {
        self.contracts.push(ContractInfo {
            kind,
            name: name.to_owned(),
            subsystem: subsystem.to_owned(),
        });
        ContractId((self.contracts.len() - 1) as u32)
    }

    fn add_bound(&mut self, b: &agent_spec::contracts::Bound) -> Result<(), BuildError> {
        let kind = ContractKind::Bound;
        let unknown = |what: String| BuildError::Unknown {
            kind,
            contract: b.behaviour.clone(),
            what,
        };
        let (sub, beh) = b
            .behaviour
            .split_once('.')
            .ok_or_else(|| unknown("not `subsystem.behaviour`".to_owned()))?;
        let subsystem = self
            .subsystem(sub)
            .ok_or_else(|| unknown(format!("no subsystem `{sub}`")))?;
        let behaviour = self
            .behaviour(subsystem, beh)
            .ok_or_else(|| unknown(format!("no behaviour `{beh}` in `{sub}`")))?;
        let max = b
            .max_s
            .map(|s| positive_ns(kind, &b.behaviour, s, 1e9))
            .transpose()?;
        let contract = self.add(kind, &b.behaviour, sub);
        self.bounds.push(BoundM {
            contract,
            subsystem,
            behaviour,
            max,
            max_iterations: b.max_iterations,
            run: None,
            lasted_reported: false,
            iterations_reported: false,
        });
        Ok(())
    }

    fn add_invariant(&mut self, i: &agent_spec::contracts::Invariant) -> Result<(), BuildError> {
        let kind = ContractKind::Invariant;
        let unknown = |what: String| BuildError::Unknown {
            kind,
            contract: i.name.clone(),
            what,
        };
        let subsystem = self
            .subsystem(&i.subsystem)
            .ok_or_else(|| unknown(format!("no subsystem `{}`", i.subsystem)))?;
        let predicates = &self.subsystems[subsystem.0 as usize].predicates;
        let parsed = Expr::parse(&i.holds)
            .map_err(|e| unknown(format!("`{}` does not parse: {}", i.holds, e.message)))?;
        let holds = parsed.try_map(&mut |name: &String| {
            predicates
                .iter()
                .position(|p| p == name)
                .ok_or_else(|| unknown(format!("no predicate `{name}` in `{}`", i.subsystem)))
        })?;
        let contract = self.add(kind, &i.name, &i.subsystem);
        self.invariants.push(InvariantM {
            contract,
            subsystem,
            holds,
        });
        Ok(())
    }

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
        self.recompute_deadline();
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

    /// Start watching at `t`: the rate windows start here; every run of a
    /// behaviour and every pending trigger is forgotten.
    pub fn start(&mut self, t: Time) {
        for f in &mut self.freshness {
            f.held = None;
        }
        for r in &mut self.rates {
            r.last = t;
            r.reported = false;
        }
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
        for f in self.freshness.iter_mut().filter(|f| f.input == input) {
            f.held = Some((stamp, age > f.max));
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
        self.recompute_deadline();
    }

    /// A new value reaches `input` at `t` (its writer's send, or its arrival
    /// from another process).
    pub fn arrived(&mut self, input: InputId, t: Time, sink: &mut impl FnMut(Violation)) {
        self.advance(t, sink);
        for r in self.rates.iter_mut().filter(|r| r.input == input) {
            r.last = t;
            r.reported = false;
        }
        self.recompute_deadline();
    }

    /// A value sent on `output` at `t`.
    pub fn sent(&mut self, output: OutputId, t: Time, sink: &mut impl FnMut(Violation)) {
        self.advance(t, sink);
        for r in &mut self.responses {
            if r.response == output {
                r.last_response = Some(t);
                r.pending = None;
            }
            if r.trigger == output && r.last_response != Some(t) {
                r.pending = Some(match r.pending {
                    Some((oldest, _)) => (oldest, t),
                    None => (t, t),
                });
            }
        }
        self.recompute_deadline();
    }

    /// The field of range `range` took `x` at `t`.
    pub fn value(&mut self, range: RangeId, t: Time, x: f64, sink: &mut impl FnMut(Violation)) {
        self.advance(t, sink);
        let Some(r) = self.ranges.get(range.0 as usize).filter(|r| r.active) else {
            return;
        };
        let inside = r.min.is_none_or(|m| x >= m) && r.max.is_none_or(|m| x <= m);
        if !inside {
            sink(Violation {
                time: t,
                contract: r.contract,
                broke: Broke::OutOfRange {
                    value: x,
                    min: r.min,
                    max: r.max,
                },
            });
        }
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
        for b in self.bounds.iter_mut().filter(|b| b.subsystem == subsystem) {
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
        for b in self.bounds.iter_mut().filter(|b| b.subsystem == subsystem) {
            b.activation(t, sink);
        }
        if self.activations {
            for f in &mut self.freshness {
                if let (Some(reader), Some((s, false))) = (f.reader, f.held)
                    && reader == subsystem
                    && t.as_nanos().saturating_sub(s.as_nanos()) > f.max
                {
                    f.held = Some((s, true));
                    sink(Violation {
                        time: t,
                        contract: f.contract,
                        broke: Broke::Age {
                            age: Duration::from_nanos(t.as_nanos() - s.as_nanos()),
                            max: Duration::from_nanos(f.max),
                        },
                    });
                }
            }
        }
        let Some(values) = predicates else {
            return;
        };
        for i in self.invariants.iter().filter(|i| i.subsystem == subsystem) {
            if !i
                .holds
                .eval(&mut |&k| values.get(k).copied().unwrap_or(false))
            {
                let bits = values
                    .iter()
                    .take(64)
                    .enumerate()
                    .fold(0u64, |acc, (k, &v)| acc | (u64::from(v) << k));
                sink(Violation {
                    time: t,
                    contract: i.contract,
                    broke: Broke::False { predicates: bits },
                });
            }
        }
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

    fn recompute_deadline(&mut self) {
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

    /// A violation as a line: `time subsystem kind name: values`.
    pub fn display<'a>(&'a self, v: &'a Violation) -> impl fmt::Display + 'a {
        Shown { m: self, v }
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

struct Shown<'a> {
    m: &'a Monitors,
    v: &'a Violation,
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

impl fmt::Display for Shown<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v = self.v;
        let (kind, name, sub) = match self.m.contract(v.contract) {
            Some(c) => (c.kind.to_string(), c.name.as_str(), c.subsystem.as_str()),
            None => ("?".to_owned(), "?", "?"),
        };
        write!(
            f,
            "t={:.6}s subsystem={sub} contract={kind}:{name}: ",
            v.time.as_secs_f64()
        )?;
        match v.broke {
            Broke::Age { age, max } => write!(f, "age {:.3} ms > {:.3} ms", ms(age), ms(max)),
            Broke::Silent { since, window } => write!(
                f,
                "no value for {:.3} ms since t={:.6}s",
                ms(window),
                since.as_secs_f64()
            ),
            Broke::Lasted { entered, max } => write!(
                f,
                "entered at t={:.6}s, still running after {:.3} s",
                entered.as_secs_f64(),
                max.as_secs_f64()
            ),
            Broke::Iterations {
                entered,
                iterations,
                max,
            } => write!(
                f,
                "entered at t={:.6}s, {iterations} iterations > {max}",
                entered.as_secs_f64()
            ),
            Broke::OutOfRange { value, min, max } => {
                write!(f, "value {value} outside [")?;
                match min {
                    Some(m) => write!(f, "{m}, ")?,
                    None => f.write_str("-inf, ")?,
                }
                match max {
                    Some(m) => write!(f, "{m}]"),
                    None => f.write_str("inf]"),
                }
            }
            Broke::Unanswered { trigger, within } => write!(
                f,
                "trigger at t={:.6}s unanswered within {:.3} s",
                trigger.as_secs_f64(),
                within.as_secs_f64()
            ),
            Broke::False { predicates } => write!(f, "false (predicate bits {predicates:#b})"),
        }
    }
}

#[cfg(test)]
mod tests;
