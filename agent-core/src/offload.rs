//! Work started in one iteration and collected in a later one: a subsystem's or a
//! driver's long computation (rendering an image, visual odometry, planning) on a
//! worker thread, while the executor goes on with the other components.
//!
//! Determinism is the caller's rule, not the clock's: the component decides in
//! which iteration it [`submit`](Offload::submit)s a job and in which it
//! [`collect`](Offload::collect)s the result, from its inputs and memory only, and
//! `collect` waits for the worker when it is not done yet. The result is a pure
//! function of the state and the input, so a run is the same, bit for bit, with the
//! job on a worker ([`OffloadMode::Worker`]) or computed inside `submit`
//! ([`OffloadMode::Inline`], for tests, replay and single-core targets). What the
//! worker buys is wall-clock time: the iterations between `submit` and `collect`
//! run concurrently with the job.
//!
//! The state `S` travels with the job (it is moved to the worker and back), so the
//! job needs no lock, and the state can be read between jobs ([`Offload::state`]).
//! A job that panics is caught: `collect` reports [`OffloadError::Failed`] with the
//! panic's message, and the offload refuses further jobs (its state may be
//! half-updated), so a component can report the fault instead of unwinding through
//! the executor.
//!
//! ```
//! use agent_core::offload::{Offload, OffloadMode};
//!
//! // A running sum, computed on a worker thread.
//! let mut sum = Offload::new("sum", 0u64, |s: &mut u64, x: u64| { *s += x; *s }, OffloadMode::Worker);
//! sum.submit(3)?;
//! // ... other work, in this or later iterations ...
//! assert_eq!(sum.collect()?, Some(3));
//! sum.submit(4)?;
//! assert_eq!(sum.collect()?, Some(7));
//! assert_eq!(sum.collect()?, None, "nothing in flight");
//! assert_eq!(sum.state(), Some(&7));
//! # Ok::<(), agent_core::offload::OffloadError>(())
//! ```

use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};
use std::thread::JoinHandle;

/// Where an [`Offload`]'s jobs run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum OffloadMode {
    /// On a worker thread of its own, concurrently with the caller.
    #[default]
    Worker,
    /// Inside [`Offload::submit`].
    Inline,
}

impl std::str::FromStr for OffloadMode {
    type Err = UnknownOffloadMode;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "worker" => Ok(OffloadMode::Worker),
            "inline" => Ok(OffloadMode::Inline),
            _ => Err(UnknownOffloadMode(s.to_owned())),
        }
    }
}

/// A name that is not an [`OffloadMode`].
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("unknown offload mode `{0}` (worker, inline)")]
pub struct UnknownOffloadMode(pub String);

/// Why an [`Offload`] refused a call.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum OffloadError {
    /// `submit` while a job is in flight (collect it first).
    #[error("offload `{0}`: a job is already in flight")]
    Busy(String),
    /// A job panicked, or the worker thread is gone; the offload takes no more jobs.
    #[error("offload `{name}` failed: {message}")]
    Failed {
        /// The offload's name.
        name: String,
        /// The panic's message, or what went wrong.
        message: String,
    },
}

type Answer<S, O> = (S, Result<O, String>);

struct Worker<S, I, O> {
    jobs: Option<SyncSender<(S, I)>>,
    answers: Receiver<Answer<S, O>>,
    handle: Option<JoinHandle<()>>,
}

impl<S, I, O> Drop for Worker<S, I, O> {
    fn drop(&mut self) {
        // Closing the job channel ends the worker's loop (after a job in flight).
        self.jobs.take();
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

fn run<S, I, O>(f: fn(&mut S, I) -> O, state: &mut S, input: I) -> Result<O, String> {
    catch_unwind(AssertUnwindSafe(|| f(state, input))).map_err(|panic| {
        panic
            .downcast_ref::<&str>()
            .map(|s| (*s).to_owned())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_else(|| "the job panicked".to_owned())
    })
}

/// A computation `f(&mut state, input) -> output` started by [`submit`](Self::submit)
/// and finished by [`collect`](Self::collect), at most one job at a time; see the
/// [module docs](self).
pub struct Offload<S, I, O> {
    name: String,
    f: fn(&mut S, I) -> O,
    mode: OffloadMode,
    /// The state between jobs (`None` while it is on the worker, or after a failure).
    state: Option<S>,
    worker: Option<Worker<S, I, O>>,
    /// An inline job's result, until collected.
    done: Option<Result<O, String>>,
    in_flight: bool,
    failure: Option<String>,
    jobs: u64,
}

impl<S, I, O> std::fmt::Debug for Offload<S, I, O> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Offload")
            .field("name", &self.name)
            .field("mode", &self.mode)
            .field("in_flight", &self.in_flight)
            .field("jobs", &self.jobs)
            .field("failure", &self.failure)
            .finish()
    }
}

impl<S: Send + 'static, I: Send + 'static, O: Send + 'static> Offload<S, I, O> {
    /// An offload named `name` (the worker thread's name, and errors') computing
    /// `f` from `state`. When no thread can be spawned in [`OffloadMode::Worker`],
    /// it computes inline rather than not at all ([`Offload::mode`] tells).
    pub fn new(
        name: impl Into<String>,
        state: S,
        f: fn(&mut S, I) -> O,
        mode: OffloadMode,
    ) -> Offload<S, I, O> {
        let name = name.into();
        let worker = match mode {
            OffloadMode::Worker => Self::spawn(&name, f),
            OffloadMode::Inline => None,
        };
        Offload {
            mode: if worker.is_some() {
                OffloadMode::Worker
            } else {
                OffloadMode::Inline
            },
            name,
            f,
            state: Some(state),
            worker,
            done: None,
            in_flight: false,
            failure: None,
            jobs: 0,
        }
    }

    fn spawn(name: &str, f: fn(&mut S, I) -> O) -> Option<Worker<S, I, O>> {
        let (job_tx, job_rx) = sync_channel::<(S, I)>(1);
        let (ans_tx, ans_rx) = sync_channel::<Answer<S, O>>(1);
        let handle = std::thread::Builder::new()
            .name(format!("offload-{name}"))
            .spawn(move || {
                while let Ok((mut state, input)) = job_rx.recv() {
                    let out = run(f, &mut state, input);
                    if ans_tx.send((state, out)).is_err() {
                        break;
                    }
                }
            })
            .ok()?;
        Some(Worker {
            jobs: Some(job_tx),
            answers: ans_rx,
            handle: Some(handle),
        })
    }
}

impl<S, I, O> Offload<S, I, O> {
    /// The offload's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Where the jobs run.
    pub fn mode(&self) -> OffloadMode {
        self.mode
    }

    /// Whether a job is in flight (submitted, not collected).
    pub fn is_busy(&self) -> bool {
        self.in_flight
    }

    /// Jobs submitted so far.
    pub fn jobs(&self) -> u64 {
        self.jobs
    }

    /// The state, between jobs (`None` while a job is in flight or after a failure).
    pub fn state(&self) -> Option<&S> {
        self.state.as_ref()
    }

    /// The state, mutably, between jobs.
    pub fn state_mut(&mut self) -> Option<&mut S> {
        self.state.as_mut()
    }

    fn failed(&self, message: String) -> OffloadError {
        OffloadError::Failed {
            name: self.name.clone(),
            message,
        }
    }

    /// Start a job on `input`: on the worker, or computed now (inline).
    pub fn submit(&mut self, input: I) -> Result<(), OffloadError> {
        if let Some(m) = &self.failure {
            return Err(self.failed(m.clone()));
        }
        if self.in_flight {
            return Err(OffloadError::Busy(self.name.clone()));
        }
        let Some(mut state) = self.state.take() else {
            return Err(self.failed("the state is gone".into()));
        };
        self.jobs += 1;
        self.in_flight = true;
        if let Some(tx) = self.worker.as_ref().and_then(|w| w.jobs.as_ref()) {
            return tx.send((state, input)).map_err(|_| {
                let m = "the worker thread is gone".to_owned();
                self.failure = Some(m.clone());
                self.failed(m)
            });
        }
        self.done = Some(run(self.f, &mut state, input));
        self.state = Some(state);
        Ok(())
    }

    /// The result of the job in flight, waiting for the worker if it is not done;
    /// `Ok(None)` when no job is in flight.
    pub fn collect(&mut self) -> Result<Option<O>, OffloadError> {
        if !self.in_flight {
            return match &self.failure {
                Some(m) => Err(self.failed(m.clone())),
                None => Ok(None),
            };
        }
        self.in_flight = false;
        let out = match self.done.take() {
            Some(out) => out,
            None => match self.worker.as_ref().map(|w| w.answers.recv()) {
                Some(Ok((state, out))) => {
                    self.state = Some(state);
                    out
                }
                _ => Err("the worker thread is gone".to_owned()),
            },
        };
        out.map(Some).map_err(|m| {
            self.state = None;
            self.failure = Some(m.clone());
            self.failed(m)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square_sum(s: &mut u64, x: u64) -> u64 {
        *s += x * x;
        *s
    }

    #[test]
    fn worker_and_inline_give_the_same_results_in_the_same_order() {
        for mode in [OffloadMode::Worker, OffloadMode::Inline] {
            let mut o = Offload::new("sq", 0u64, square_sum, mode);
            assert_eq!(o.mode(), mode);
            let mut got = Vec::new();
            for x in 1..=5 {
                o.submit(x).unwrap();
                assert!(o.is_busy());
                got.push(o.collect().unwrap().unwrap());
                assert!(!o.is_busy());
            }
            assert_eq!(got, [1, 5, 14, 30, 55], "{mode:?}");
            assert_eq!(o.state(), Some(&55));
            assert_eq!(o.jobs(), 5);
        }
    }

    #[test]
    fn one_job_at_a_time_and_nothing_to_collect_is_none() {
        let mut o = Offload::new("one", 0u64, square_sum, OffloadMode::Worker);
        assert_eq!(o.collect(), Ok(None));
        o.submit(2).unwrap();
        assert_eq!(o.state(), None, "the state is on the worker");
        assert_eq!(o.submit(3), Err(OffloadError::Busy("one".into())));
        assert_eq!(o.collect(), Ok(Some(4)));
        *o.state_mut().unwrap() = 100;
        o.submit(1).unwrap();
        assert_eq!(o.collect(), Ok(Some(101)));
    }

    fn explode(_: &mut u64, x: u64) -> u64 {
        assert!(x < 10, "input {x} out of range");
        x
    }

    #[test]
    fn a_panicking_job_is_reported_and_the_offload_refuses_more() {
        for mode in [OffloadMode::Worker, OffloadMode::Inline] {
            let mut o = Offload::new("boom", 0u64, explode, mode);
            o.submit(3).unwrap();
            assert_eq!(o.collect(), Ok(Some(3)));
            o.submit(12).unwrap();
            let err = o.collect().unwrap_err();
            assert!(
                matches!(&err, OffloadError::Failed { name, message }
                    if name == "boom" && message.contains("input 12 out of range")),
                "{mode:?}: {err}"
            );
            assert!(matches!(o.submit(1), Err(OffloadError::Failed { .. })));
            assert!(matches!(o.collect(), Err(OffloadError::Failed { .. })));
            assert_eq!(o.state(), None);
        }
    }

    #[test]
    fn dropping_an_offload_with_a_job_in_flight_joins_its_worker() {
        fn slow(_: &mut (), ms: u64) {
            std::thread::sleep(std::time::Duration::from_millis(ms));
        }
        let mut o = Offload::new("slow", (), slow, OffloadMode::Worker);
        o.submit(20).unwrap();
        drop(o); // must neither hang nor panic
    }

    #[test]
    fn the_mode_parses_from_its_name() {
        assert_eq!("worker".parse(), Ok(OffloadMode::Worker));
        assert_eq!("inline".parse(), Ok(OffloadMode::Inline));
        let unknown = "threads".parse::<OffloadMode>().unwrap_err();
        assert_eq!(unknown, UnknownOffloadMode("threads".into()));
        assert_eq!(
            unknown.to_string(),
            "unknown offload mode `threads` (worker, inline)"
        );
    }
}
