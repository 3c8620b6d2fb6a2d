//! The trajectory planner as c1 uses it: a planning process running concurrently with
//! the execution process, behind the paper's API (`trajgenInit`, `trajgenStart`,
//! `trajgenStop`, `trajgenIsReady`, `trajgenGetTraj`, `trajgenGetStat`).
//!
//! Two runtimes: [`Runtime::Thread`] plans on a worker thread (the concurrent planning
//! process of the paper); [`Runtime::Inline`] plans inside `trajgenStart`. Both report
//! a result as ready only after `latency` calls of `trajgenGetStat` (the planning time
//! in c1's iterations), and the threaded one then waits for the worker if it is not
//! done yet, so a run is deterministic in virtual time whichever runtime plans.

use std::sync::mpsc::{Receiver, Sender, channel};
use std::thread::JoinHandle;

use super::{Fragment, PlanError, PlanStats, Planner, PlannerKind, PlannerSettings, Waypoint};

/// Where planning runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Runtime {
    /// On a worker thread, concurrently with the execution process.
    #[default]
    Thread,
    /// Inside `start` (for property tests and single-threaded runs).
    Inline,
}

/// The planner's state as `trajgenGetStat` reports it.
#[derive(Clone, Debug, PartialEq)]
pub enum Status {
    /// Initialised, nothing being planned.
    Idle,
    /// Planning the fragment towards the last point started.
    Planning,
    /// A fragment is ready to be taken.
    Ready,
    /// Stopped: the plan has no more points.
    Stopped,
    /// Planning failed; the platform holds its position.
    Failed(String),
}

type Job = ([f64; 3], Waypoint);
type Answer = Result<(Fragment, PlanStats), PlanError>;

struct Worker {
    jobs: Option<Sender<Job>>,
    answers: Receiver<Answer>,
    handle: Option<JoinHandle<()>>,
}

impl Drop for Worker {
    fn drop(&mut self) {
        // Closing the job channel ends the worker's loop.
        self.jobs.take();
        if let Some(h) = self.handle.take() {
            let _ = h.join();
        }
    }
}

fn spawn(kind: PlannerKind, settings: PlannerSettings) -> Option<Worker> {
    let (job_tx, job_rx) = channel::<Job>();
    let (ans_tx, ans_rx) = channel::<Answer>();
    let handle = std::thread::Builder::new()
        .name("trajgen".into())
        .spawn(move || {
            let mut planner = kind.build(settings);
            while let Ok((from, to)) = job_rx.recv() {
                if ans_tx.send(planner.plan(from, &to)).is_err() {
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

/// Figures of the planning so far.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct PlannerTotals {
    /// Fragments planned.
    pub fragments: u64,
    /// Newton iterations, summed.
    pub iterations: u64,
    /// Failures.
    pub failures: u64,
}

/// The trajectory planner structure of c1's memory (`trajgen`).
pub struct TrajGen {
    kind: PlannerKind,
    settings: PlannerSettings,
    runtime: Runtime,
    latency: u32,
    worker: Option<Worker>,
    inline: Option<Box<dyn Planner>>,
    from: [f64; 3],
    plan: u32,
    index: u32,
    status: Status,
    waited: u32,
    job: Option<Job>,
    answer: Option<Answer>,
    totals: PlannerTotals,
}

impl std::fmt::Debug for TrajGen {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TrajGen")
            .field("planner", &self.kind)
            .field("status", &self.status)
            .field("from", &self.from)
            .field("plan", &self.plan)
            .field("index", &self.index)
            .finish()
    }
}

impl Clone for TrajGen {
    /// A clone plans inline (threads are not cloned); a job in flight is planned again.
    fn clone(&self) -> Self {
        let mut t = TrajGen::new(
            self.kind,
            self.settings.clone(),
            Runtime::Inline,
            self.latency,
        );
        t.from = self.from;
        t.plan = self.plan;
        t.index = self.index;
        t.status = self.status.clone();
        t.waited = self.waited;
        t.job = self.job;
        t.totals = self.totals;
        t.answer = match (&self.answer, self.job) {
            (Some(a), _) => Some(a.clone()),
            (None, Some((from, to))) if self.status == Status::Planning => {
                t.inline.as_mut().map(|p| p.plan(from, &to))
            }
            _ => None,
        };
        t
    }
}

impl std::str::FromStr for Runtime {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "thread" => Ok(Runtime::Thread),
            "inline" => Ok(Runtime::Inline),
            _ => Err(format!("unknown planning runtime `{s}` (thread, inline)")),
        }
    }
}

impl TrajGen {
    /// A planner of `kind`; a result is ready `latency` calls of `stat` after `start`.
    pub fn new(
        kind: PlannerKind,
        settings: PlannerSettings,
        runtime: Runtime,
        latency: u32,
    ) -> TrajGen {
        let (worker, inline) = match runtime {
            Runtime::Thread => match spawn(kind, settings.clone()) {
                Some(w) => (Some(w), None),
                // No thread available: plan inline rather than not at all.
                None => (None, Some(kind.build(settings.clone()))),
            },
            Runtime::Inline => (None, Some(kind.build(settings.clone()))),
        };
        TrajGen {
            kind,
            settings,
            runtime,
            latency,
            worker,
            inline,
            from: [0.0; 3],
            plan: 0,
            index: 0,
            status: Status::Idle,
            waited: 0,
            job: None,
            answer: None,
            totals: PlannerTotals::default(),
        }
    }

    /// Which planner.
    pub fn kind(&self) -> PlannerKind {
        self.kind
    }

    /// Which runtime.
    pub fn runtime(&self) -> Runtime {
        self.runtime
    }

    /// The shared planner settings.
    pub fn settings(&self) -> &PlannerSettings {
        &self.settings
    }

    /// `trajgenInit(trajgen, state)`: prepare for plan `plan`; `pose` is the
    /// platform's `(X, Y, φ)` in the state (c1 passes its state estimate's).
    ///
    /// The first plan starts from `pose`. A later plan starts where the last
    /// fragment planned ends: because `c1` acknowledges a plan as soon as its last
    /// fragment is handed over (the paper's early `ack`), the next plan arrives
    /// while `e11` still executes that fragment, and the platform will be at its end
    /// (or holding it) when the next plan's first fragment begins. Starting from the
    /// current state instead would make the platform jump back along the path.
    ///
    /// `first` is the number of the plan's first fragment: 0, or the point a
    /// resumed plan starts from (see [`crate::a1::payload::Plan::first`]).
    pub fn init(&mut self, pose: [f64; 3], plan: u32, first: u32) {
        self.abandon();
        if self.totals.fragments == 0 {
            self.from = pose;
        }
        self.plan = plan;
        self.index = first;
        self.status = Status::Idle;
    }

    /// Plan the next fragment from `pose` `(X, Y, φ)` instead of the end of the last
    /// fragment planned: after a plan that did not end where it was planned to
    /// (stopped, failed), the platform is not there.
    pub fn restart_from(&mut self, pose: [f64; 3]) {
        self.from = pose;
    }

    /// Where the next fragment starts `(X, Y, φ)`.
    pub fn from(&self) -> [f64; 3] {
        self.from
    }

    /// Forget a job in flight (its answer is drained when it comes).
    fn abandon(&mut self) {
        if self.status == Status::Planning
            && self.answer.is_none()
            && let Some(w) = &self.worker
        {
            // Keep the worker's queue in step: wait for the stale answer.
            let _ = w.answers.recv();
        }
        self.job = None;
        self.answer = None;
    }

    /// `trajgenStart(trajgen, point)`: plan from the last processed configuration to
    /// `point`.
    pub fn start(&mut self, point: Waypoint) {
        self.abandon();
        let job = (self.from, point);
        self.job = Some(job);
        self.waited = 0;
        self.status = Status::Planning;
        if let Some(w) = &self.worker {
            if w.jobs.as_ref().is_some_and(|tx| tx.send(job).is_ok()) {
                return;
            }
            self.worker = None;
            self.inline = Some(self.kind.build(self.settings.clone()));
        }
        if let Some(p) = &mut self.inline {
            self.answer = Some(p.plan(job.0, &job.1));
        }
    }

    /// `trajgenStop(trajgen)`: no more points.
    pub fn stop(&mut self) {
        self.abandon();
        self.status = Status::Stopped;
    }

    /// The current status (without advancing it, unlike [`TrajGen::stat`]).
    pub fn status(&self) -> &Status {
        &self.status
    }

    /// `trajgenIsReady(trajgen)`: a fragment can be taken.
    pub fn is_ready(&self) -> bool {
        self.status == Status::Ready
    }

    /// Whether planning failed.
    pub fn failed(&self) -> Option<&str> {
        match &self.status {
            Status::Failed(m) => Some(m),
            _ => None,
        }
    }

    /// `trajgenGetStat(trajgen)`: one more of c1's iterations spent planning; after
    /// `latency` of them the result is collected (waiting for the worker if needed).
    pub fn stat(&mut self) -> &Status {
        if self.status == Status::Planning {
            self.waited += 1;
            if self.waited >= self.latency {
                if self.answer.is_none() {
                    self.answer = self
                        .worker
                        .as_ref()
                        .map(|w| w.answers.recv().unwrap_or(Err(PlanError::ProcessGone)));
                }
                match self.answer.as_ref() {
                    Some(Ok(_)) => self.status = Status::Ready,
                    Some(Err(e)) => {
                        self.totals.failures += 1;
                        self.status = Status::Failed(e.to_string());
                    }
                    None => self.status = Status::Failed("the planning process is gone".into()),
                }
            }
        }
        &self.status
    }

    /// `trajgenGetTraj(trajgen)`: take the ready fragment; the next one starts at its
    /// end.
    pub fn get_traj(&mut self) -> Option<Fragment> {
        if self.status != Status::Ready {
            return None;
        }
        let (mut fragment, stats) = self.answer.take()?.ok()?;
        self.job = None;
        fragment.plan = self.plan;
        fragment.index = self.index;
        self.index = self.index.saturating_add(1);
        if let Some(end) = fragment.end() {
            self.from = [end[0], end[1], end[2]];
        }
        self.totals.fragments += 1;
        self.totals.iterations += stats.iterations as u64;
        self.status = Status::Idle;
        Some(fragment)
    }

    /// Figures so far.
    pub fn totals(&self) -> PlannerTotals {
        self.totals
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(runtime: Runtime) -> Vec<Fragment> {
        let mut t = TrajGen::new(PlannerKind::Ecsa, PlannerSettings::default(), runtime, 3);
        t.init([0.0, 0.0, 0.0], 7, 0);
        let mut out = Vec::new();
        for p in [(1.0, 0.0), (1.0, 1.0)] {
            t.start(Waypoint {
                x: p.0,
                y: p.1,
                phi: None,
            });
            assert!(!t.is_ready());
            let mut calls = 0;
            while !t.is_ready() {
                t.stat();
                calls += 1;
                assert!(calls <= 3, "ready after the latency");
            }
            assert_eq!(calls, 3);
            out.push(t.get_traj().unwrap());
        }
        t.stop();
        assert_eq!(t.stat(), &Status::Stopped);
        out
    }

    #[test]
    fn threaded_and_inline_planning_agree() {
        let a = run(Runtime::Thread);
        let b = run(Runtime::Inline);
        assert_eq!(a, b);
        assert_eq!((a[0].plan, a[0].index, a[1].index), (7, 0, 1));
        // The second fragment starts where the first ends.
        assert_eq!(a[1].states[0][..3], a[0].end().unwrap()[..3]);
    }

    #[test]
    fn failures_are_reported() {
        let mut t = TrajGen::new(
            PlannerKind::Ecsa,
            PlannerSettings::default(),
            Runtime::Inline,
            1,
        );
        t.init([0.0, 0.0, 0.0], 1, 0);
        t.start(Waypoint {
            x: f64::INFINITY,
            y: 0.0,
            phi: None,
        });
        t.stat();
        assert!(t.failed().is_some_and(|m| m.contains("finite")));
        assert!(t.get_traj().is_none());
        let c = t.clone();
        assert_eq!(c.failed(), t.failed());
    }
}
