//! The trajectory planner as c1 uses it: a planning process running concurrently with
//! the execution process, behind the paper's API (`trajgenInit`, `trajgenStart`,
//! `trajgenStop`, `trajgenIsReady`, `trajgenGetTraj`, `trajgenGetStat`).
//!
//! Two runtimes: [`Runtime::Thread`] plans on a worker thread (the concurrent planning
//! process of the paper); [`Runtime::Inline`] plans inside `trajgenStart`. Both report
//! a result as ready only after `latency` calls of `trajgenGetStat` (the planning time
//! in c1's iterations), and the threaded one then waits for the worker if it is not
//! done yet, so a run is deterministic in virtual time whichever runtime plans. Both are
//! an [`embodied::Offload`] of the planner.

use embodied::{Offload, OffloadError, OffloadMode};

use crate::algorithms::planner::{
    Fragment, PlanError, PlanStats, Planner, PlannerKind, PlannerSettings, Waypoint,
};

/// Where planning runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Runtime {
    /// On a worker thread, concurrently with the execution process.
    #[default]
    Thread,
    /// Inside `start` (for property tests and single-threaded runs).
    Inline,
}

impl Runtime {
    /// The [`Offload`] mode that plans this way.
    pub fn mode(self) -> OffloadMode {
        match self {
            Runtime::Thread => OffloadMode::Worker,
            Runtime::Inline => OffloadMode::Inline,
        }
    }
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
type Planning = Offload<Box<dyn Planner>, Job, Answer>;

fn plan(planner: &mut Box<dyn Planner>, (from, to): Job) -> Answer {
    planner.plan(from, &to)
}

fn planning(kind: PlannerKind, settings: &PlannerSettings, mode: OffloadMode) -> Planning {
    Offload::new("trajgen", kind.build(settings.clone()), plan, mode)
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
    latency: u32,
    planning: Planning,
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
        t.answer = self.answer.clone();
        if let (None, Some(job), Status::Planning) = (&self.answer, self.job, &self.status) {
            // Planned inline, so at once: the clone collects it when `stat` says.
            t.submit(job);
        }
        t
    }
}

impl std::str::FromStr for Runtime {
    type Err = crate::config::UnknownChoice;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "thread" => Ok(Runtime::Thread),
            "inline" => Ok(Runtime::Inline),
            _ => Err(crate::config::UnknownChoice::new(
                "planning runtime",
                s,
                "thread, inline",
            )),
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
        // With no thread available, the offload plans inline rather than not at all.
        let planning = planning(kind, &settings, runtime.mode());
        TrajGen {
            kind,
            settings,
            latency,
            planning,
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

    /// Which runtime plans now: `Inline` once a failed worker was replaced, or
    /// when no thread could be had.
    pub fn runtime(&self) -> Runtime {
        match self.planning.mode() {
            OffloadMode::Worker => Runtime::Thread,
            OffloadMode::Inline => Runtime::Inline,
        }
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
    /// resumed plan starts from (see [`crate::payload::Plan::first`]).
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

    /// Forget a job in flight (waiting for the worker to finish it: one job at a
    /// time).
    fn abandon(&mut self) {
        let _ = self.planning.collect();
        self.job = None;
        self.answer = None;
    }

    /// Hand `job` to the planning process. A planning process that failed (a
    /// planner that panicked) is replaced by a fresh planner that plans inline:
    /// the failure was reported with the job that caused it.
    fn submit(&mut self, job: Job) {
        if let Err(e) = self.planning.submit(job) {
            if !matches!(e, OffloadError::Failed { .. }) {
                // Busy cannot happen (`abandon` collected); stay safe anyway.
                let _ = self.planning.collect();
            }
            self.planning = planning(self.kind, &self.settings, OffloadMode::Inline);
            let _ = self.planning.submit(job);
        }
    }

    /// `trajgenStart(trajgen, point)`: plan from the last processed configuration to
    /// `point`.
    pub fn start(&mut self, point: Waypoint) {
        self.abandon();
        let job = (self.from, point);
        self.job = Some(job);
        self.waited = 0;
        self.status = Status::Planning;
        self.submit(job);
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
                    self.answer = match self.planning.collect() {
                        Ok(answer) => answer,
                        Err(e) => Some(Err(PlanError::ProcessGone(e.to_string()))),
                    };
                }
                match self.answer.as_ref() {
                    Some(Ok(_)) => self.status = Status::Ready,
                    Some(Err(e)) => {
                        self.totals.failures += 1;
                        self.status = Status::Failed(e.to_string());
                    }
                    None => self.status = Status::Failed("nothing was being planned".into()),
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
    fn a_clone_taken_while_planning_plans_the_same_fragment() {
        let mut t = TrajGen::new(
            PlannerKind::Ecsa,
            PlannerSettings::default(),
            Runtime::Thread,
            2,
        );
        t.init([0.0, 0.0, 0.0], 1, 0);
        t.start(Waypoint {
            x: 1.0,
            y: 0.5,
            phi: None,
        });
        let mut c = t.clone();
        assert_eq!(c.runtime(), Runtime::Inline, "a clone plans inline");
        for g in [&mut t, &mut c] {
            assert_eq!(g.stat(), &Status::Planning);
            assert_eq!(g.stat(), &Status::Ready);
        }
        assert_eq!(t.get_traj(), c.get_traj());
        // A job abandoned by a new start: its answer is not taken for the new one.
        t.start(Waypoint {
            x: 5.0,
            y: 5.0,
            phi: None,
        });
        t.start(Waypoint {
            x: 1.5,
            y: 0.5,
            phi: None,
        });
        c.start(Waypoint {
            x: 1.5,
            y: 0.5,
            phi: None,
        });
        t.stat();
        c.stat();
        assert_eq!(t.get_traj(), c.get_traj());
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
