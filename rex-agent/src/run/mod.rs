//! Running a Rex mission and collecting what happened, on the application
//! layer's loops ([`embodied::app::Watched`]): in the deterministic executor
//! ([`run_mission`]) or in real time ([`run_mission_realtime`]).
//!
//! Rex's probes report what e11 tracks after each of its activations and the
//! platform's true pose after each of the world's instants; a [`Sample`] pairs
//! e11's activation at `t` with the true pose at `t` (the platform integrates
//! at 1 kHz, so the world's step before `t` left its state at `t`): the
//! tracking error is measured without the one-period lag that sampling between
//! runs would add. The same reports, from every process of a deployment, are
//! what `rex launch` judges.

use std::path::Path;
use std::time::Duration;

mod collect;
pub mod judge;
#[cfg(test)]
mod tests;
pub use collect::Seen;
pub(crate) use collect::{MissionWatch, install_probes, install_probes_as};

use embodied::app::{AppError, Ran, Tally, Watched, figures};
use embodied::record::{RecordOptions, RecordSummary};
use embodied::{Finished, NoObserver, RtConfig, RtReport, System};

use crate::payload::{Ack, AckStatus, PlanOutcome};
use crate::system::{RexConfig, RobotHandles, build};
use judge::{PlanReport, Verdict};

/// One sample of a run, at every activation of `e11`.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Sample {
    /// Simulation time \[s\].
    pub t: f64,
    /// True pose `(X, Y, φ)`.
    pub truth: [f64; 3],
    /// Estimated pose.
    pub estimate: [f64; 3],
    /// Reference `(X, Y, φ, v, ω)`, when `e11` follows one.
    pub reference: Option<[f64; 5]>,
    /// Whether a fragment is being executed (not holding a point).
    pub executing: bool,
    /// Torques commanded.
    pub tau: [f64; 4],
    /// `c1`'s behaviour (0 = B1, 1 = B2, 2 = B3).
    pub behaviour: u8,
    /// The fragment being executed: `(plan, index)`.
    pub fragment: Option<(u32, u32)>,
    /// How long the motion capture has been delivering poses without a gap \[s\]
    /// (0 during a dropout).
    pub mocap_for: f64,
    /// Whether `e11` had lost the visual odometry it was receiving.
    pub vo_lost: bool,
    /// The estimator's friction of the ground `(μ_x, μ_y, μ_r)` (the MHE
    /// estimates it; NaN for an estimator that does not).
    pub friction: [f64; 3],
}

impl Sample {
    /// Distance between the true position and the reference position.
    pub fn error(&self) -> Option<f64> {
        self.reference
            .map(|r| (r[0] - self.truth[0]).hypot(r[1] - self.truth[1]))
    }

    /// Error of the estimated position.
    pub fn estimate_error(&self) -> f64 {
        (self.estimate[0] - self.truth[0]).hypot(self.estimate[1] - self.truth[1])
    }

    /// Whether the motion capture has been delivering for the last second: the
    /// estimate can be held to it (after a dropout it needs a moment to converge).
    pub fn with_mocap(&self) -> bool {
        self.mocap_for >= 1.0
    }
}

/// Counters gathered at the end of a run. The counters of another part of
/// the same run (another process of a deployment) add up with
/// [`Tally`]: each counter comes from one component.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize, Tally)]
pub struct Counters {
    /// Fragments received by `e11`.
    pub fragments_received: u32,
    /// Fragments executed to their end by `e11`.
    pub fragments_completed: u32,
    /// Fragments refused by `e11` (not finite).
    pub fragments_rejected: u32,
    /// Fragments refused by `e11` because they were handed over before a stop.
    pub fragments_stale: u32,
    /// Stops of the platform by `e11`'s safety monitor, with their time \[s\].
    pub stops: Vec<(f64, String)>,
    /// Command timeouts of the platform's watchdog (steps at zero torque).
    pub watchdog_steps: u64,
    /// What the estimator rejected, and its relocalisations.
    pub estimator: crate::algorithms::estimation::EstimatorHealth,
    /// Torque commands clamped or rejected by the platform.
    pub clamped_torques: u64,
    /// Fragments planned.
    pub planned: u64,
    /// Planner iterations, summed.
    pub planner_iterations: u64,
    /// Planner failures.
    pub planner_failures: u64,
    /// Errors recorded by the executor (`OnError::Continue`).
    pub executor_errors: u64,
    /// Motion-capture samples delivered and lost to dropouts.
    pub mocap: (u64, u64),
    /// Visual odometry: stereo pairs processed, motions sent, pairs without one.
    pub vo: (u64, u64, u64),
    /// What the tracker reports (solves, failures, fallbacks...).
    pub tracker: crate::algorithms::tracking::TrackerReport,
    /// Restarts of `c1` that `a2` heard of (its process crashed and was
    /// started again).
    pub c1_restarts: u32,
    /// Plans `a2` sent again after those restarts.
    pub plans_resent: u32,
    /// Fragments reported executed to their end a second time.
    pub fragments_repeated: u32,
    /// Times `e11` lost the visual odometry it was receiving.
    pub vo_outages: u32,
    /// Plans `c1` refused as numbered out of sequence (a plan lost on the
    /// way, or a sender that is not `a2`).
    pub plans_out_of_sequence: u32,
}

// The algorithms' reports know nothing of the framework (tests/layout.rs):
// their counts add up here.
embodied::app::tally_fields!(crate::algorithms::tracking::TrackerReport:
    solves, constrained, clarabel, failures, fallbacks, safe_stops, refused);
embodied::app::tally_fields!(crate::algorithms::estimation::EstimatorHealth:
    rejected, rejected_poses, relocalisations);

/// What a run produced.
#[derive(Clone, Debug, Default)]
pub struct Outcome {
    /// The mission's name.
    pub mission: String,
    /// Plans in the mission, and those `c1` took from another sender
    /// ([`Outcome::foreign`]).
    pub plans: usize,
    /// Plans `c1` took that `a2` did not send (numbered after the mission's:
    /// from the ROS 2 topic `/rex/plan`, say), in the order taken, with their
    /// last point (`None`: refused as taken). Judged with the mission's.
    pub foreign: Vec<(u32, Option<crate::payload::Point2>)>,
    /// Final acknowledgements received by `a2`, with their arrival time \[s\].
    pub acks: Vec<(f64, Ack)>,
    /// Plan outcomes reported by `e11`, with the time it reported them \[s\].
    pub outcomes: Vec<(f64, PlanOutcome)>,
    /// Each plan of the mission, then each plan from another sender, judged
    /// against the simulation's truth.
    pub reports: Vec<PlanReport>,
    /// Samples at every activation of `e11`.
    pub samples: Vec<Sample>,
    /// Simulated time \[s\].
    pub sim_s: f64,
    /// Wall-clock time \[s\].
    pub wall_s: f64,
    /// Counters.
    pub counters: Counters,
    /// Whether the mission ended (every plan sent, its outcome reported to `a2`,
    /// the last fragment executed) before the time limit. For a mission that
    /// listens ([`crate::mission::Mission::listens`]), which runs to its
    /// limit: whether, when the run ended, every plan `c1` took had its final
    /// acknowledgement and nothing was left executing.
    pub completed: bool,
    /// The names of the planner, tracker and estimator.
    pub parts: [String; 3],
}

impl Outcome {
    /// Plans acknowledged as done (the paper's early acknowledgement: every
    /// fragment handed over), each counted once (a plan sent again after a
    /// restart of `c1` is acknowledged again).
    pub fn plans_done(&self) -> usize {
        let mut done: Vec<u32> = self
            .acks
            .iter()
            .filter(|(_, a)| a.status == AckStatus::Done)
            .map(|(_, a)| a.plan)
            .collect();
        done.sort_unstable();
        done.dedup();
        done.len()
    }

    /// When `e11` lost the visual odometry it was receiving, and when it came
    /// back (`None`: not before the end) \[s\].
    pub fn vo_outages(&self) -> Vec<(f64, Option<f64>)> {
        let lost = self.samples.iter().map(|s| (s.t, s.vo_lost));
        let runs = embodied::app::plot::runs(lost).into_iter().filter(|r| r.2);
        runs.map(|(from, to, _)| (from, to)).collect()
    }

    /// The estimator's friction of the ground `(μ_x, μ_y, μ_r)` at the run's last
    /// sample.
    pub fn friction_estimate(&self) -> Option<[f64; 3]> {
        self.samples
            .last()
            .map(|s| s.friction)
            .filter(|f| f.iter().all(|v| v.is_finite()))
    }

    /// Plans achieved: acknowledged, reported reached by `e11`, and confirmed by
    /// the simulation's truth (end point, tracking error, estimate, clearance).
    pub fn plans_achieved(&self) -> usize {
        self.reports
            .iter()
            .filter(|r| r.verdict == Verdict::Achieved)
            .count()
    }

    /// Plans `e11` reported reached whose end point the platform did not in truth
    /// reach (a success reported that was not achieved).
    pub fn false_done(&self) -> usize {
        self.reports
            .iter()
            .filter(|r| matches!(r.verdict, Verdict::FalseSuccess(_)))
            .count()
    }

    /// Whether the run succeeded: it completed and achieved every plan (a
    /// listening run that took none succeeds: it executed every plan it got).
    pub fn succeeded(&self) -> bool {
        self.completed && self.plans_achieved() == self.plans
    }

    fn tracking_errors(&self) -> impl Iterator<Item = f64> + '_ {
        self.samples
            .iter()
            .filter(|s| s.executing)
            .filter_map(Sample::error)
    }

    /// RMS of the tracking error over the samples that follow a fragment \[m\].
    pub fn rms(&self) -> f64 {
        figures::rms(self.tracking_errors())
    }

    /// Largest tracking error while following fragments \[m\].
    pub fn max_error(&self) -> f64 {
        figures::largest(self.tracking_errors())
    }

    /// RMS of the estimator's position error over the whole run \[m\].
    pub fn estimate_rms(&self) -> f64 {
        figures::rms(self.samples.iter().map(Sample::estimate_error))
    }

    /// Simulated seconds per wall-clock second.
    pub fn realtime_factor(&self) -> f64 {
        self.sim_s / self.wall_s.max(1e-9)
    }

    /// The summary line of the main job (`plans_acked`: the plans achieved, of
    /// the mission's and those taken from another sender).
    pub fn summary_line(&self) -> String {
        format!(
            "mission={} plans_acked={}/{} rms_m={:.4} max_m={:.4} realtime_factor={:.1}",
            self.mission,
            self.plans_achieved(),
            self.plans,
            self.rms(),
            self.max_error(),
            self.realtime_factor()
        )
    }
}

/// Why a run failed: the application layer's error, as for every run of
/// the layer (Rex could not be built, [`AppError::Build`]; the executor
/// stopped on an error; the recording could not be made).
pub type RunError = AppError;

/// What a run reports while it goes.
#[derive(Clone, Debug)]
pub enum Progress<'a> {
    /// `a2` received the final acknowledgement of a plan.
    Ack {
        /// Simulation time \[s\].
        t: f64,
        /// The acknowledgement.
        ack: &'a Ack,
    },
    /// Another `every` seconds of simulated time passed.
    Tick {
        /// Simulation time \[s\].
        t: f64,
        /// The latest sample.
        sample: &'a Sample,
    },
}

/// Run `config`'s mission until every plan is acknowledged and the platform has
/// executed the last fragment, or until `limit` of simulated time; `progress` sees
/// each acknowledgement as it arrives and a tick every `tick` of simulated time.
pub fn run_mission(
    config: &RexConfig,
    limit: Duration,
    tick: Duration,
    progress: impl FnMut(Progress<'_>),
) -> Result<Outcome, RunError> {
    run_mission_observed(config, limit, tick, |_| Ok(NoObserver), progress).map(|(out, _)| out)
}

/// [`run_mission`] with an observer of the executor, made by `observer` from
/// the built system (a recorder, for example: [`embodied::record::McapRecorder`]);
/// returns it with the outcome.
pub fn run_mission_observed<O: embodied::Observer + 'static>(
    config: &RexConfig,
    limit: Duration,
    tick: Duration,
    observer: impl FnOnce(&System) -> Result<O, RunError>,
    progress: impl FnMut(Progress<'_>),
) -> Result<(Outcome, O), RunError> {
    let run = |run: Watched<'_, Seen>, system: System| {
        let observer = observer(&system)?;
        run.simulate(system, config.exec, observer)
    };
    watched(config, (limit, tick), progress, run).map(|(out, _, observer)| (out, observer))
}

/// Run `config`'s mission in real time (the same system on threads against
/// the wall clock, [`embodied::RealTime`]: the world on one thread, the
/// subsystems on the executor's workers), for at most `limit` of wall-clock
/// time, ended and judged as the deterministic run is. Returns the outcome
/// and what the executor measured.
pub fn run_mission_realtime(
    config: &RexConfig,
    limit: Duration,
    tick: Duration,
    rt: RtConfig,
    progress: impl FnMut(Progress<'_>),
) -> Result<(Outcome, RtReport), RunError> {
    realtime(config, (limit, tick), rt, None, progress).map(|(out, report, _)| (out, report))
}

/// [`run_mission_realtime`], recorded to `path` (every thread's part of the
/// run: what each node sent and read, its behaviour switches, the errors).
pub fn run_mission_realtime_recorded(
    config: &RexConfig,
    limit: Duration,
    tick: Duration,
    rt: RtConfig,
    (path, options): (&Path, RecordOptions),
    progress: impl FnMut(Progress<'_>),
) -> Result<(Outcome, RtReport, RecordSummary), RunError> {
    let (out, report, summary) =
        realtime(config, (limit, tick), rt, Some((path, options)), progress)?;
    // A recording was asked for: the run returns its summary.
    Ok((out, report, summary.unwrap_or_default()))
}

fn realtime(
    config: &RexConfig,
    times: (Duration, Duration),
    rt: RtConfig,
    record: Option<(&Path, RecordOptions)>,
    progress: impl FnMut(Progress<'_>),
) -> Result<(Outcome, RtReport, Option<RecordSummary>), RunError> {
    let rt = RtConfig {
        exec: config.exec,
        ..rt
    };
    let run = |run: Watched<'_, Seen>, system| run.realtime_recorded(system, rt, record);
    let (out, ran, summary) = watched(config, times, progress, run)?;
    Ok((out, ran.finished.into_report(), summary))
}

/// Build `config`'s Rex, put its probes on it (every component: the whole
/// system runs here), run it with `run` to `limit` (a tick of progress every
/// `tick`), and judge it. The library's mission runs judge the mission; the
/// spec's contracts are watched in the program's runs (`rex`, through the
/// layer).
fn watched<R>(
    config: &RexConfig,
    (limit, tick): (Duration, Duration),
    progress: impl FnMut(Progress<'_>),
    run: impl FnOnce(Watched<'_, Seen>, System) -> Result<(Ran, R), RunError>,
) -> Result<(Outcome, Ran, R), RunError> {
    let (system, h) = build(config).map_err(|e| AppError::Build(Box::new(e)))?;
    let mut watch = MissionWatch::new(config, tick, progress);
    let mut watched = Watched::new(&mut watch, limit);
    install_probes(&mut watched.probes, &h, &|_| true);
    let (ran, r) = run(watched, system)?;
    Ok((watch.conclude(&ran, &h), ran, r))
}

/// What a run's nodes say at its end (those this process ran): the counters,
/// and the names of the planner, tracker and estimator.
pub(crate) fn last_reports(run: &Finished, h: impl Into<RobotHandles>) -> Vec<Seen> {
    let h = &h.into();
    let mut counters = Counters::default();
    finish_counters(run, h, &mut counters);
    counters.executor_errors = run.report().error_count;
    let parts = [
        run.memory(&h.c1)
            .map(|c1| c1.trajgen.kind().name().to_owned()),
        run.memory(&h.e11)
            .map(|e11| e11.track.tracker.name().to_owned()),
        run.memory(&h.e11)
            .map(|e11| e11.estym.estimator.name().to_owned()),
    ];
    vec![Seen::Counters(Box::new(counters)), Seen::Parts(parts)]
}

/// The counters of a run, read at its end; returns how many plans `a2` sent.
pub(crate) fn finish_counters(x: &Finished, h: &RobotHandles, c: &mut Counters) -> usize {
    if let Some(m) = x.memory(&h.e11) {
        c.fragments_received = m.track.received;
        c.fragments_completed = m.track.completed;
        c.fragments_rejected = m.track.rejected;
        c.fragments_stale = m.track.stale;
        c.stops = m.stops.clone();
        c.estimator = m.estym.estimator.health();
        c.tracker = m.track.tracker.report();
        c.vo_outages = m.vo.outages;
    }
    if let Some(p) = x.driver(&h.platform) {
        let s = p.command_stats();
        c.clamped_torques = s.not_finite + s.out_of_bounds;
        c.watchdog_steps = p.timeouts();
    }
    if let Some(m) = x.memory(&h.c1) {
        let t = m.trajgen.totals();
        c.planned = t.fragments;
        c.planner_iterations = t.iterations;
        c.planner_failures = t.failures;
        c.plans_out_of_sequence = m.out_of_sequence;
    }
    if let Some(m) = x.driver(&h.map.mocap) {
        c.mocap = m.counts();
    }
    if let Some(m) = h.vision.and_then(|(r11, _)| x.memory(&r11)) {
        c.vo = (m.odom.pairs, m.odom.motions, m.odom.no_estimates);
    }
    h.c2.and_then(|c2| x.memory(&c2)).map_or(0, |m| {
        c.c1_restarts = m.restarts;
        c.plans_resent = m.resent;
        c.fragments_repeated = m.repeated;
        m.next
    })
}
