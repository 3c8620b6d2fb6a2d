//! Termination and liveness properties, checked with proptest on your own subsystems.
//!
//! Two properties, both run by the FSM's own code, the code the executor runs:
//!
//! * [`Termination::behaviour`]: a behaviour, started afresh, reaches its terminal
//!   condition within `bound` iterations, for every initial memory and environment
//!   drawn from strategies. Each iteration calls [`Fsm::ends`] (the terminal test
//!   with its while/repeat timing: the first half of [`Fsm::step`]) and, while the
//!   behaviour goes on, [`Fsm::act`] (its elementary action: the second half of
//!   [`Fsm::activate`]). The check stops when the behaviour ends, so no arc is
//!   selected: faults of arc selection are the business of the next property.
//! * [`Termination::returns_to`]: the FSM, started at its initial behaviour and driven
//!   by an environment, enters a designated behaviour within `bound` activations (for
//!   a behaviour that is also the initial one: leaves it and comes back). Each
//!   activation is one call of [`Fsm::activate`], exactly as in the executor.
//!
//! The environment is a model of everything outside the subsystem: an
//! [`Environment`] fills the input buffers before each activation and sees the
//! outputs of the previous action, so it can react (an effector that reports `ready`
//! some iterations after receiving a command). Strategies generate the model's
//! parameters, so proptest shrinks them; a failure prints the minimal case as a
//! readable trace, one line per iteration.
//!
//! ```
//! use agent_core::testing::{Script, Termination};
//! use agent_core::*;
//! use proptest::prelude::*;
//!
//! struct Counter;
//! #[derive(Default, Clone, Debug)]
//! struct Input { limit: In<u32> }
//! impl Subsystem for Counter {
//!     const KIND: SubsystemKind = SubsystemKind::VirtualReceptor;
//!     type Memory = u32;
//!     type Input = Input;
//!     type Output = ();
//! }
//! let fsm = Fsm::builder()
//!     .predicate("reached", |n: &u32, x: &Input| x.limit.get().is_some_and(|l| n >= l))
//!     .behaviour(Behaviour::repeat_loop(
//!         "count",
//!         Action::new().memory(|n: &mut u32, _: &Input| *n += 1),
//!         "reached",
//!     ))
//!     .behaviour(Behaviour::while_loop("rest", Action::new(), "false"))
//!     .initial("count")
//!     .arc("count", "rest", "true")
//!     .build()
//!     .unwrap();
//! let limit = (0u32..50).prop_map(|l| {
//!     Script::<Counter>::new(vec![Input { limit: In::new_value(l, Stamp::new(0, Time::ZERO)) }])
//! });
//! Termination::within(51)
//!     .behaviour(&fsm, "count", Just(0u32), limit)
//!     .unwrap();
//! ```

use std::fmt::{self, Debug, Write as _};

use proptest::strategy::Strategy;
use proptest::test_runner::{Config, TestCaseError, TestError, TestRunner};

use crate::error::FsmError;
use crate::fsm::{Activated, Fsm, Step};
use crate::subsystem::Subsystem;

/// What the rest of the world does to one subsystem's inputs.
pub trait Environment<S: Subsystem>: Debug {
    /// Fill the input buffers for activation `iteration`. `previous` holds the
    /// outputs written by the previous action (`None` before the first action, and
    /// after an activation that ran no action).
    ///
    /// The input struct persists between activations, as in the executor: use
    /// [`In::deliver`](crate::In::deliver) for a new value and
    /// [`In::age`](crate::In::age) for a buffer that receives nothing this time.
    fn inputs(&mut self, iteration: u64, previous: Option<&S::Output>, input: &mut S::Input);
}

/// A non-reactive environment: a fixed sequence of input structs, one per
/// activation; after its end the last one is repeated with every buffer as it was
/// (so a value new in the last element stays new).
pub struct Script<S: Subsystem> {
    inputs: Vec<S::Input>,
}

impl<S: Subsystem> Script<S> {
    /// A script of inputs, one per activation.
    pub fn new(inputs: Vec<S::Input>) -> Self {
        Script { inputs }
    }
}

impl<S: Subsystem> Clone for Script<S>
where
    S::Input: Clone,
{
    fn clone(&self) -> Self {
        Script {
            inputs: self.inputs.clone(),
        }
    }
}

impl<S: Subsystem> Debug for Script<S>
where
    S::Input: Debug,
{
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_tuple("Script").field(&self.inputs).finish()
    }
}

impl<S: Subsystem> Environment<S> for Script<S>
where
    S::Input: Clone + Debug,
{
    fn inputs(&mut self, iteration: u64, _previous: Option<&S::Output>, input: &mut S::Input) {
        let k = usize::try_from(iteration).unwrap_or(usize::MAX);
        if let Some(x) = self.inputs.get(k).or(self.inputs.last()) {
            input.clone_from(x);
        }
    }
}

/// A termination property that does not hold, with the shrunk counterexample
/// rendered as a trace.
#[derive(Clone, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct TerminationFailure {
    /// The whole report: what failed, the minimal initial memory and environment,
    /// and one line per iteration.
    pub message: String,
}

/// Shows the report as it is, so that `.unwrap()` in a test prints a readable trace.
impl Debug for TerminationFailure {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.message)
    }
}

/// Settings of a termination check: the bound and the number of random cases.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Termination {
    bound: u64,
    cases: u32,
    shown: usize,
    shrink_iters: u32,
}

impl Termination {
    /// Check that termination happens within `bound` iterations (or activations).
    pub fn within(bound: u64) -> Termination {
        Termination {
            bound,
            cases: 256,
            shown: 12,
            shrink_iters: 4096,
        }
    }

    /// Number of random cases (default 256).
    pub fn cases(mut self, cases: u32) -> Termination {
        self.cases = cases;
        self
    }

    /// How many shrinking steps proptest may take to minimise a counterexample
    /// (default 4096; proptest's own default, 4 per case, often stops before the
    /// case is minimal).
    pub fn shrink_iters(mut self, steps: u32) -> Termination {
        self.shrink_iters = steps;
        self
    }

    /// In a failure report, how many iterations to print at the start and at the
    /// end of the trace (default 12 each).
    pub fn shown(mut self, shown: usize) -> Termination {
        self.shown = shown.max(1);
        self
    }

    /// The behaviour `behaviour` of `fsm`, started afresh with a memory from `memory`
    /// and driven by an environment from `environment`, reaches its terminal
    /// condition within the bound (while-type: tested before each iteration;
    /// repeat-type: after each). A failing action also fails the property.
    pub fn behaviour<S, MS, ES>(
        &self,
        fsm: &Fsm<S>,
        behaviour: &str,
        memory: MS,
        environment: ES,
    ) -> Result<(), TerminationFailure>
    where
        S: Subsystem,
        S::Memory: Clone + Debug,
        S::Input: Debug,
        S::Output: Debug,
        MS: Strategy<Value = S::Memory>,
        ES: Strategy,
        ES::Value: Environment<S> + Clone,
    {
        let Some(b) = fsm.behaviour_index(behaviour) else {
            return Err(TerminationFailure {
                message: format!("the FSM has no behaviour `{behaviour}`"),
            });
        };
        let run = |m: S::Memory, env: ES::Value, log: &mut Option<Log>| {
            run_behaviour(fsm, b, self.bound, m, env, log)
        };
        self.check(memory, environment, run)
    }

    /// The FSM, started at its initial behaviour with a memory from `memory` and
    /// driven by an environment from `environment`, enters behaviour `target` within
    /// the bound of activations. FSM faults, failing actions and halting first fail
    /// the property.
    pub fn returns_to<S, MS, ES>(
        &self,
        fsm: &Fsm<S>,
        target: &str,
        memory: MS,
        environment: ES,
    ) -> Result<(), TerminationFailure>
    where
        S: Subsystem,
        S::Memory: Clone + Debug,
        S::Input: Debug,
        S::Output: Debug,
        MS: Strategy<Value = S::Memory>,
        ES: Strategy,
        ES::Value: Environment<S> + Clone,
    {
        let Some(t) = fsm.behaviour_index(target) else {
            return Err(TerminationFailure {
                message: format!("the FSM has no behaviour `{target}`"),
            });
        };
        let run = |m: S::Memory, env: ES::Value, log: &mut Option<Log>| {
            run_fsm(fsm, t, self.bound, m, env, log)
        };
        self.check(memory, environment, run)
    }

    fn check<M, E, MS, ES>(
        &self,
        memory: MS,
        environment: ES,
        run: impl Fn(M, E, &mut Option<Log>) -> Result<(), String>,
    ) -> Result<(), TerminationFailure>
    where
        M: Clone + Debug,
        E: Clone + Debug,
        MS: Strategy<Value = M>,
        ES: Strategy<Value = E>,
    {
        let mut runner = TestRunner::new(Config {
            cases: self.cases,
            max_shrink_iters: self.shrink_iters,
            failure_persistence: None,
            ..Config::default()
        });
        let outcome = runner.run(&(memory, environment), |(m, env)| {
            run(m, env, &mut None).map_err(TestCaseError::fail)
        });
        match outcome {
            Ok(()) => Ok(()),
            Err(TestError::Abort(reason)) => Err(TerminationFailure {
                message: format!("the property could not be checked: {reason}"),
            }),
            Err(TestError::Fail(_, (m, env))) => {
                let mut log = Some(Log::default());
                if let Some(l) = &mut log {
                    l.memory = format!("{m:?}");
                }
                let reason = run(m.clone(), env.clone(), &mut log)
                    .err()
                    .unwrap_or_else(|| "failed only on the first run (non-deterministic?)".into());
                let lines = log.map(|l| l.lines).unwrap_or_default();
                let mut message = format!(
                    "{reason}\nminimal counterexample (shrunk by proptest):\n  initial memory: {m:?}\n  environment:    {env:?}\n"
                );
                let n = lines.len();
                for (k, line) in lines.iter().enumerate() {
                    if n > 2 * self.shown && k == self.shown {
                        let _ =
                            writeln!(message, "  … {} iterations not shown …", n - 2 * self.shown);
                    }
                    if n <= 2 * self.shown || k < self.shown || k >= n - self.shown {
                        let _ = writeln!(message, "  {line}");
                    }
                }
                Err(TerminationFailure { message })
            }
        }
    }
}

#[derive(Default)]
struct Log {
    lines: Vec<String>,
    memory: String,
}

fn log_line(log: &mut Option<Log>, f: impl FnOnce() -> String) {
    if let Some(l) = log {
        l.lines.push(f());
    }
}

/// The memory's `Debug` text, or "unchanged" if it is the same as at the last call.
fn memory_text(log: &mut Option<Log>, memory: &impl Debug) -> String {
    let Some(l) = log else {
        return String::new();
    };
    let text = format!("{memory:?}");
    if text == l.memory {
        "unchanged".to_owned()
    } else {
        l.memory.clone_from(&text);
        text
    }
}

fn run_behaviour<S: Subsystem, E: Environment<S>>(
    fsm: &Fsm<S>,
    b: usize,
    bound: u64,
    mut memory: S::Memory,
    mut env: E,
    log: &mut Option<Log>,
) -> Result<(), String>
where
    S::Memory: Debug,
    S::Input: Debug,
    S::Output: Debug,
{
    let (Some(behaviour), Some(mut state)) = (fsm.behaviour(b), fsm.start_at(b)) else {
        return Err(format!("no behaviour #{b}"));
    };
    let mut input = S::Input::default();
    let mut previous: Option<S::Output> = None;
    for iteration in 0..=bound {
        env.inputs(iteration, previous.as_ref(), &mut input);
        // The executor's terminal test (`Fsm::step` calls the same `Fsm::ends`).
        if fsm.ends(&state, &memory, &input) {
            log_line(log, || {
                format!("ι={iteration}: inputs {input:?} -> terminal condition holds")
            });
            return Ok(());
        }
        if iteration == bound {
            log_line(log, || {
                format!("ι={iteration}: inputs {input:?} -> not ended, bound reached")
            });
            break;
        }
        let mut output = S::Output::default();
        // The executor's action (`Fsm::activate` ends with the same `Fsm::act`).
        let result = fsm.act(&mut state, &mut memory, &input, &mut output);
        let mem = memory_text(log, &memory);
        log_line(log, || {
            format!("ι={iteration}: inputs {input:?} -> outputs {output:?}, memory {mem}")
        });
        match result {
            Ok(_) => previous = Some(output),
            Err(FsmError::Action { behaviour, source }) => {
                return Err(format!(
                    "the action of behaviour `{behaviour}` failed at ι={iteration}: {source}"
                ));
            }
            Err(e) => return Err(format!("the FSM failed at ι={iteration}: {e}")),
        }
    }
    Err(format!(
        "behaviour `{}` ({}-type) did not reach its terminal condition `{}` within {bound} iterations",
        behaviour.name(),
        behaviour.kind(),
        behaviour.terminal()
    ))
}

fn run_fsm<S: Subsystem, E: Environment<S>>(
    fsm: &Fsm<S>,
    target: usize,
    bound: u64,
    mut memory: S::Memory,
    mut env: E,
    log: &mut Option<Log>,
) -> Result<(), String>
where
    S::Memory: Debug,
    S::Input: Debug,
    S::Output: Debug,
{
    let mut state = fsm.start();
    let mut input = S::Input::default();
    let mut previous: Option<S::Output> = None;
    for iteration in 0..bound {
        env.inputs(iteration, previous.as_ref(), &mut input);
        let mut output = S::Output::default();
        let mut entered = false;
        let mut path = String::new();
        let result = fsm.activate(&mut state, &mut memory, &input, &mut output, |step| {
            if let Step::Entered { to, .. } = step {
                entered |= *to == target;
                let _ = write!(path, " -> {}", fsm.behaviour_name(*to));
            }
        });
        let here = fsm.behaviour_name(state.behaviour());
        log_line(log, || {
            format!(
                "ι={iteration}: inputs {input:?}{path} | {here}: outputs {output:?}, memory {memory:?}"
            )
        });
        match result {
            Err(e) => return Err(format!("the FSM failed at activation {iteration}: {e}")),
            Ok(_) if entered => return Ok(()),
            Ok(Activated::Halted) => {
                return Err(format!(
                    "the FSM halted in `{here}` at activation {iteration} without entering `{}`",
                    fsm.behaviour_name(target)
                ));
            }
            Ok(Activated::Ran { .. }) => previous = Some(output),
        }
    }
    Err(format!(
        "the FSM did not enter `{}` within {bound} activations",
        fsm.behaviour_name(target)
    ))
}

#[cfg(test)]
mod tests {
    use proptest::strategy::Just;

    use super::*;
    use crate::behaviour::Behaviour;
    use crate::kinds::SubsystemKind;
    use crate::transition::Action;

    struct Counter;
    impl Subsystem for Counter {
        const KIND: SubsystemKind = SubsystemKind::VirtualReceptor;
        type Memory = u32;
        type Input = ();
        type Output = ();
    }

    /// `b`: while-type, `r`: repeat-type, both counting and ending when `always`.
    fn fsm() -> Fsm<Counter> {
        let count = || Action::<Counter>::new().memory(|n: &mut u32, _: &()| *n += 1);
        Fsm::builder()
            .predicate("always", |_, _| true)
            .behaviour(Behaviour::while_loop("w", count(), "always"))
            .behaviour(Behaviour::repeat_loop("r", count(), "always"))
            .initial("w")
            .arc("w", "r", "true")
            .arc("r", "w", "true")
            .build()
            .unwrap()
    }

    fn none() -> Just<Script<Counter>> {
        Just(Script::new(vec![()]))
    }

    #[test]
    fn behaviour_uses_the_terminal_test_timing_of_the_fsm() {
        let fsm = fsm();
        // While-type: tested before the first iteration, so no action is needed.
        Termination::within(0)
            .cases(1)
            .behaviour(&fsm, "w", Just(0), none())
            .unwrap();
        // Repeat-type: the action runs once before the first test.
        Termination::within(1)
            .cases(1)
            .behaviour(&fsm, "r", Just(0), none())
            .unwrap();
        let err = Termination::within(0)
            .cases(1)
            .behaviour(&fsm, "r", Just(7), none())
            .unwrap_err();
        assert_eq!(
            err.message,
            "behaviour `r` (repeat-type) did not reach its terminal condition `always` within 0 iterations\n\
             minimal counterexample (shrunk by proptest):\n  initial memory: 7\n  environment:    Script([()])\n  \
             ι=0: inputs () -> not ended, bound reached\n"
        );
        let err = Termination::within(3)
            .behaviour(&fsm, "nope", Just(0), none())
            .unwrap_err();
        assert_eq!(err.message, "the FSM has no behaviour `nope`");
    }
}
