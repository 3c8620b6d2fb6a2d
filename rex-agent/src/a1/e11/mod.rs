//! The virtual effector `e11` (the paper's section 3.2): executes trajectory fragments
//! with a tracker and a state estimator, both swappable ([`Tracker`], [`Estimator`]).
//!
//! One behaviour, `track`, that never ends; its transition functions (as in
//! `specs/rex.ron`):
//!
//! * `ee_estimate_track` (common part): the estimator fuses the new measurements,
//!   the tracker computes the torques for the current reference point;
//! * `eE` (to E1): the torques, and the IMU reset that aligns its heading with the
//!   map when the first map pose arrives;
//! * `ec` (to c1): the state estimate, `ready` once at start and once per
//!   fragment after `notify` iterations, and each plan's `outcome`;
//! * `ee_steps` (memory): counts `step` and `notify` down, queues fragments that
//!   arrive before the current one ends (because `notify < steps`), and holds the
//!   last point when no fragment follows.
//!
//! **Safety and outcomes.** While it executes a fragment, `e11` stops the
//! platform (brakes to the current estimated pose, drops the fragments queued,
//! reports `Execution::Stopped` with the reason, and `ready`) when the estimate or
//! the latest map pose leaves the free space of the map, when braking from the
//! current speed would end outside it, or when the estimate is farther than
//! `max_tracking_error` from the reference. Each stop starts a new *epoch*: `c1`
//! stamps the fragments it hands over with the epoch it knows, so fragments it
//! sent before it heard of the stop are refused, never executed. When a plan's
//! last fragment ends, `e11` reports whether the platform reached its end point
//! (its estimate within `final_tolerance` less `final_margin`, the estimate's own
//! error allowed for, and no farther than `final_margin` from the map poses of
//! the last half second; waiting up to `settle` seconds while holding it):
//! the early acknowledgement `Done` of `c1` says that the plan was handed over,
//! this says whether it was achieved.

use std::collections::{BTreeSet, VecDeque};

use embodied::{Buffers, Fsm, FsmBuildError, Group, In, Memory, Out, Subsystem, fsm};

pub use crate::algorithms::estimation::{Estimate, Estimator, EstimatorKind, Measurements};
pub use crate::algorithms::tracking::{Tracker, TrackerKind};

use crate::a1::map::Map;
use crate::algorithms::planner::Fragment;
use crate::payload::{
    Encoders, Execution, Imu, ImuCommand, MapPose, PlanOutcome, Progress, State, Torques,
    Transform, WheelLoads,
};

/// How `e11` keeps the platform safe and judges the end of a plan.
#[derive(Clone, Debug, PartialEq)]
pub struct Safety {
    /// The free space (its clearance: the platform's footprint).
    pub map: Map,
    /// The largest distance between the estimate and the reference \[m\]; beyond
    /// it `e11` stops the platform.
    pub max_tracking_error: f64,
    /// A plan's last point is reached within this distance \[m\].
    pub final_tolerance: f64,
    /// The estimate's own error allowed for: a plan is reported reached only
    /// when the estimate is within `final_tolerance − final_margin` of its
    /// last point, and within `final_margin` of the map poses of the last
    /// half second ([`Estimate::pose_disagreement`]) \[m\].
    pub final_margin: f64,
    /// How long `e11` waits, holding the last point, for the platform to come
    /// within the tolerance \[s\].
    pub settle: f64,
    /// The deceleration the platform is assumed to brake with \[m/s²\].
    pub brake_decel: f64,
    /// The torque the tracker commands at most per wheel \[N m\]; `None`: the
    /// platform's `torque_max` ([`Tracker::set_torque_bounds`]).
    pub torque_max: Option<f64>,
    /// The share of each wheel's traction the NMPC's torques may use.
    pub traction_margin: f64,
}

impl Default for Safety {
    fn default() -> Self {
        Safety {
            map: Map::default(),
            max_tracking_error: 0.3,
            final_tolerance: 0.1,
            final_margin: 0.03,
            settle: 3.0,
            brake_decel: 1.0,
            torque_max: None,
            traction_margin: crate::algorithms::tracking::TRACTION_MARGIN,
        }
    }
}

/// A plan whose last fragment ended: is the platform at its end point?
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Arrival {
    /// The plan.
    pub plan: u32,
    /// Its last point.
    pub end: [f64; 2],
    /// When the last fragment ended \[s\].
    pub since: f64,
}

/// Whether visual odometry comes in. Once the first motion has arrived, a1
/// expects them; when none comes for `patience` iterations (r11's process
/// crashed, the camera stopped, or r11 could not use the pairs: it sends no
/// motion then), visual odometry counts as lost: the estimator goes on without
/// it, as in a deployment without visual odometry, and the outage is counted
/// (and reported by the run).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VoWatch {
    /// Motions received.
    pub received: u64,
    /// The iteration of the latest.
    pub last: Option<u64>,
    /// Iterations without a motion after which visual odometry is lost.
    pub patience: u64,
    /// Whether it is lost now.
    pub lost: bool,
    /// Times it was lost.
    pub outages: u32,
}

impl VoWatch {
    /// A watch that declares visual odometry lost after `patience` iterations
    /// without a motion.
    pub fn new(patience: u64) -> VoWatch {
        VoWatch {
            received: 0,
            last: None,
            patience: patience.max(1),
            lost: false,
            outages: 0,
        }
    }

    /// Iteration `now`, with a motion or not.
    fn see(&mut self, now: u64, motion: bool) {
        if motion {
            self.received += 1;
            self.last = Some(now);
            self.lost = false;
        } else if let Some(last) = self.last
            && !self.lost
            && now.saturating_sub(last) >= self.patience
        {
            self.lost = true;
            self.outages += 1;
        }
    }
}

/// A fragment being executed.
#[derive(Clone, Debug)]
pub struct Running {
    /// The fragment.
    pub fragment: Fragment,
    /// Index of the current reference sample.
    pub k: usize,
}

/// The tracking side of the memory (`track`).
#[derive(Debug)]
pub struct TrackState {
    /// The tracker.
    pub tracker: Box<dyn Tracker>,
    /// The fragment being executed.
    pub running: Option<Running>,
    /// Fragments received before the running one ended, with their steps and notify.
    pub queue: VecDeque<(Fragment, u32, u32)>,
    /// The point held when no fragment runs.
    pub hold: Option<[f64; 5]>,
    /// The reference of this iteration (for reports).
    pub reference: Option<[f64; 5]>,
    /// The reference over the tracker's horizon (reused every iteration).
    pub horizon: Vec<[f64; 5]>,
    /// The fragment `(plan, index)` the reference of this iteration comes from
    /// (`None` when holding a point).
    pub following: Option<(u32, u32)>,
    /// Fragments received, completed and rejected (non-finite).
    pub received: u32,
    /// Fragments completed.
    pub completed: u32,
    /// Fragments rejected.
    pub rejected: u32,
    /// Fragments refused because they were handed over before a stop.
    pub stale: u32,
}

/// The estimation side of the memory (`estym`).
#[derive(Debug)]
pub struct EstimState {
    /// The estimator.
    pub estimator: Box<dyn Estimator>,
    /// The last estimate.
    pub estimate: Estimate,
}

/// `e11`'s internal memory.
#[derive(Debug, Memory)]
pub struct E11Memory {
    /// `track`.
    pub track: TrackState,
    /// `estym`.
    pub estym: EstimState,
    /// `step`: iterations left in the running fragment.
    pub step: u32,
    /// `notify`: iterations left before reporting ready.
    pub notify: u32,
    /// Whether ready was reported for the running fragment.
    pub reported: bool,
    /// `τ`: the torques of this iteration.
    pub tau: Torques,
    /// Iterations done.
    pub iteration: u64,
    /// The instant of iteration 0, in periods: taken from the platform's clock
    /// (the stamp of the first encoder reading), so that an `e11` started late
    /// (its process restarted) keeps the time of the map poses and visual
    /// odometry it fuses.
    pub start: Option<u64>,
    /// The period \[s\].
    pub dt: f64,
    /// Iteration at which the IMU reset was sent.
    pub imu_reset_at: Option<u64>,
    /// ICR offset used to report velocities.
    pub x_icr: f64,
    /// Limits of the safety monitor and the tolerance of arrivals.
    pub safety: Safety,
    /// Stops so far (see the module's documentation).
    pub epoch: u32,
    /// The plan whose end point is being waited for.
    pub arrival: Option<Arrival>,
    /// Plan outcomes not yet reported (one goes out per iteration).
    pub outbox: VecDeque<PlanOutcome>,
    /// Plans whose outcome was reported or queued.
    pub concluded: BTreeSet<u32>,
    /// The plan outcome reported in this iteration.
    pub event: Option<PlanOutcome>,
    /// Whether the platform was stopped in this iteration.
    pub stopped_now: bool,
    /// Why each stop happened, with its time \[s\].
    pub stops: Vec<(f64, String)>,
    /// The fragment completed in the last iteration (reported as `progress`).
    pub completed_now: Option<Progress>,
    /// Whether visual odometry comes in.
    pub vo: VoWatch,
}

impl E11Memory {
    /// A memory with this tracker and estimator, running every `dt` seconds.
    pub fn new(
        tracker: Box<dyn Tracker>,
        estimator: Box<dyn Estimator>,
        dt: f64,
        x_icr: f64,
    ) -> E11Memory {
        E11Memory {
            track: TrackState {
                tracker,
                running: None,
                queue: VecDeque::new(),
                hold: None,
                reference: None,
                horizon: Vec::new(),
                following: None,
                received: 0,
                completed: 0,
                rejected: 0,
                stale: 0,
            },
            estym: EstimState {
                estimator,
                estimate: Estimate::default(),
            },
            step: 0,
            notify: 0,
            reported: false,
            tau: [0.0; 4],
            iteration: 0,
            start: None,
            dt,
            imu_reset_at: None,
            x_icr,
            safety: Safety::default(),
            epoch: 0,
            arrival: None,
            outbox: VecDeque::new(),
            concluded: BTreeSet::new(),
            event: None,
            stopped_now: false,
            stops: Vec::new(),
            completed_now: None,
            // Half a second without a motion (they come about ten times a second).
            vo: VoWatch::new((0.5 / dt.max(1e-3)).ceil() as u64),
        }
    }

    /// The same with these safety limits (the tracker's torque bounds
    /// among them).
    pub fn with_safety(mut self, safety: Safety) -> E11Memory {
        self.track
            .tracker
            .set_torque_bounds(safety.torque_max, safety.traction_margin);
        self.safety = safety;
        self
    }

    /// Simulation time of this iteration \[s\].
    fn now(&self) -> f64 {
        (self.iteration + self.start.unwrap_or(0)) as f64 * self.dt
    }

    /// Take the instant of iteration 0 from the first plausible encoder
    /// reading (its stamp is within a millisecond of this instant).
    fn set_clock(&mut self, encoders: Option<&Encoders>) {
        if self.start.is_some() {
            return;
        }
        if let Some(t) = encoders
            .map(|e| e.time)
            .filter(|t| t.is_finite() && *t >= 0.0)
        {
            // An absurd stamp (beyond a century) is not a clock: keep counting.
            let periods = (t / self.dt).round();
            if periods < 3.2e9 / self.dt {
                self.start = Some((periods as u64).saturating_sub(self.iteration));
            }
        }
    }

    /// Queue the outcome of `plan`, once per plan.
    fn conclude(&mut self, plan: u32, result: Execution) {
        if self.concluded.insert(plan) {
            self.outbox.push_back(PlanOutcome {
                plan,
                epoch: self.epoch,
                result,
            });
        }
    }
}

/// Inputs from `c1`.
#[derive(Clone, Debug, Default, Group)]
#[group(peer = Control)]
#[expect(non_snake_case, reason = "the paper's buffer names")]
pub struct E11FromC1 {
    /// Map pose.
    pub pose: In<MapPose>,
    /// Visual odometry.
    pub A4x4: In<Transform>,
    /// A fragment.
    pub traj: In<Fragment>,
    /// Its steps.
    pub steps: In<u32>,
    /// Its notify step.
    pub notify: In<u32>,
}

/// Inputs from the platform.
#[derive(Clone, Debug, Default, Group)]
#[group(peer = RealEffector)]
pub struct E11FromE1 {
    /// IMU.
    pub imu: In<Imu>,
    /// Force sensors.
    pub forces: In<WheelLoads>,
    /// Encoders.
    pub encoders: In<Encoders>,
}

/// `e11`'s input buffers (group names are the peers' names, as in the spec).
#[derive(Clone, Debug, Default, Buffers)]
#[expect(
    non_snake_case,
    reason = "groups are named after their peer component, E1"
)]
pub struct E11Input {
    /// From `c1`.
    pub c1: E11FromC1,
    /// From `E1`.
    pub E1: E11FromE1,
}

/// Outputs to `c1`.
#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub struct E11ToC1 {
    /// State estimate.
    pub q_est: Out<State>,
    /// Ready event.
    pub ready: Out<bool>,
    /// How a plan's execution ended.
    pub outcome: Out<PlanOutcome>,
    /// A fragment executed to its end.
    pub progress: Out<Progress>,
}

/// Outputs to the platform.
#[derive(Debug, Default, Group)]
#[group(peer = RealEffector)]
#[expect(non_snake_case, reason = "the paper's buffer names")]
pub struct E11ToE1 {
    /// Torques.
    pub tau: Out<Torques>,
    /// IMU reset.
    pub cmd_E11: Out<ImuCommand>,
}

/// `e11`'s output buffers.
#[derive(Debug, Default, Buffers)]
#[expect(
    non_snake_case,
    reason = "groups are named after their peer component, E1"
)]
pub struct E11Output {
    /// To `c1`.
    pub c1: E11ToC1,
    /// To `E1`.
    pub E1: E11ToE1,
}

/// The virtual effector `e11`.
#[derive(Subsystem)]
#[subsystem(kind = VirtualEffector, memory = E11Memory, input = E11Input, output = E11Output)]
pub struct E11;

/// Whether `ready` goes out in this iteration: at start, `notify` iterations into
/// each fragment, and when a stop leaves `e11` idle.
fn report_ready(m: &E11Memory) -> bool {
    m.iteration == 0 || (m.track.running.is_some() && m.notify == 0 && !m.reported) || m.stopped_now
}

/// Why the platform must stop now, if it must: checked while a fragment runs.
fn hazard(m: &E11Memory, x: &E11Input, e: &Estimate) -> Option<String> {
    let running = m.track.running.as_ref()?;
    let s = &m.safety;
    let [px, py, phi, v, _] = e.x;
    if let Err(why) = s.map.explain(px, py) {
        return Some(format!("the estimated position {why}"));
    }
    if let Some(p) = x.c1.pose.fresh().filter(|p| p.pose.is_finite())
        && let Err(why) = s.map.explain(p.pose.x, p.pose.y)
    {
        return Some(format!("motion capture puts the platform at {why}"));
    }
    if v.abs() > 0.05 {
        // Where braking from this speed along the heading ends.
        let d = v * v.abs() / (2.0 * s.brake_decel);
        let (bx, by) = (px + d * phi.cos(), py + d * phi.sin());
        if let Err(why) = s.map.explain(bx, by) {
            return Some(format!(
                "heading out of the free space at {v:.2} m/s: braking would end at {why}"
            ));
        }
    }
    let states = &running.fragment.states;
    let r = states.get(running.k.min(states.len().saturating_sub(1)))?;
    let error = (px - r[0]).hypot(py - r[1]);
    (error > s.max_tracking_error).then(|| {
        format!(
            "the platform is {error:.2} m from its reference (at most {:.2} m)",
            s.max_tracking_error
        )
    })
}

/// Stop: brake to the estimated pose and hold it, drop every fragment, start a new
/// epoch, report why for every plan whose fragments ran or waited.
fn stop(m: &mut E11Memory, e: &Estimate, reason: String) {
    let mut plans: Vec<u32> = m.track.running.iter().map(|r| r.fragment.plan).collect();
    plans.extend(m.track.queue.iter().map(|(f, _, _)| f.plan));
    plans.dedup();
    m.epoch += 1;
    m.track.running = None;
    m.track.queue.clear();
    m.arrival = None;
    m.step = 0;
    m.notify = 0;
    m.stopped_now = true;
    let [px, py, phi, _, _] = e.x;
    m.track.hold = Some([px, py, phi, 0.0, 0.0]);
    m.stops.push((m.now(), reason.clone()));
    for plan in plans {
        m.conclude(plan, Execution::Stopped(reason.clone()));
    }
}

/// The end of a plan: reached when the estimate comes within the tolerance of its
/// last point less the margin for the estimate's own error, while the estimate
/// keeps to the map poses within that margin ([`Estimate::pose_disagreement`]:
/// when it does not, as on a ground the estimator has not caught up with, its
/// error may exceed the margin, and `e11` waits); missed if it is not reached
/// within `settle` seconds, or when the next plan's fragments take over first.
fn judge_arrival(m: &mut E11Memory, e: &Estimate) {
    let Some(a) = m.arrival else {
        return;
    };
    let error = (e.x[0] - a.end[0]).hypot(e.x[1] - a.end[1]);
    // The margin holds while the estimate keeps to the map poses within it.
    let trusted = e
        .pose_disagreement
        .is_none_or(|d| d <= m.safety.final_margin);
    let result = if trusted && error <= m.safety.final_tolerance - m.safety.final_margin {
        Execution::Reached { error_m: error }
    } else if m.track.running.is_some() || m.now() - a.since >= m.safety.settle {
        Execution::Missed { error_m: error }
    } else {
        return;
    };
    m.arrival = None;
    m.conclude(a.plan, result);
}

/// Whether the IMU reset goes out in this iteration: with the first map pose.
fn reset_imu(m: &E11Memory, x: &E11Input) -> Option<f64> {
    if m.imu_reset_at.is_some() {
        return None;
    }
    x.c1.pose
        .fresh()
        .filter(|p| p.pose.is_finite())
        .map(|p| p.pose.phi)
}

/// Fill `track.horizon` with the reference of the next `tracker.horizon() + 1`
/// samples: the running fragment from its current sample, then the fragments
/// queued after it, then the last point held at rest. `false` if there is nothing
/// to follow (no fragment and no point to hold).
fn fill_horizon(t: &mut TrackState) -> bool {
    let len = t.tracker.horizon() + 1;
    t.horizon.clear();
    if let Some(r) = &t.running {
        let k = r.k.min(r.fragment.states.len().saturating_sub(1));
        t.horizon.extend(r.fragment.states[k..].iter().take(len));
        // The next fragments start where the previous one ends: skip their first sample.
        for (f, _, _) in &t.queue {
            if t.horizon.len() >= len {
                break;
            }
            let room = len - t.horizon.len();
            t.horizon.extend(f.states.iter().skip(1).take(room));
        }
    }
    let rest = t
        .horizon
        .last()
        .map(|e| [e[0], e[1], e[2], 0.0, 0.0])
        .or(t.hold);
    let Some(rest) = rest else {
        return false;
    };
    t.horizon.resize(len, rest);
    true
}

/// `ee_estimate_track` (common part): estimate, then the torques.
pub fn ee_estimate_track(m: &mut E11Memory, x: &E11Input) {
    let meas = Measurements {
        encoders: x.E1.encoders.fresh().copied(),
        imu: x.E1.imu.fresh().copied(),
        loads: x.E1.forces.fresh().copied(),
        map_pose: x.c1.pose.fresh().copied(),
        transform: x.c1.A4x4.fresh().copied(),
        imu_aligned: m.imu_reset_at.is_some_and(|at| m.iteration >= at + 2),
        now: 0.0,
    };
    m.set_clock(meas.encoders.as_ref());
    let meas = Measurements {
        now: m.now(),
        ..meas
    };
    m.vo.see(m.iteration, meas.transform.is_some());
    let estimate = m.estym.estimator.update(m.dt, &m.tau, &meas);
    m.estym.estimate = estimate;
    m.track.following = None;
    m.stopped_now = false;
    if !estimate.localised {
        m.event = m.outbox.pop_front();
        m.track.tracker.idle();
        m.tau = [0.0; 4];
        m.track.reference = None;
        return;
    }
    if m.track.hold.is_none() {
        let [px, py, phi, _, _] = estimate.x;
        m.track.hold = Some([px, py, phi, 0.0, 0.0]);
    }
    match hazard(m, x, &estimate) {
        Some(reason) => stop(m, &estimate, reason),
        None => judge_arrival(m, &estimate),
    }
    m.event = m.outbox.pop_front();
    m.track.following = m
        .track
        .running
        .as_ref()
        .map(|r| (r.fragment.plan, r.fragment.index));
    if fill_horizon(&mut m.track) {
        m.track.reference = m.track.horizon.first().copied();
        m.tau = m.track.tracker.control(&estimate, &m.track.horizon, m.dt);
    } else {
        m.track.tracker.idle();
        m.track.reference = None;
        m.tau = [0.0; 4];
    }
}

/// `eE`: torques and the IMU reset to the platform.
#[expect(
    non_snake_case,
    reason = "the paper's name: the target is a real device"
)]
pub fn eE(m: &E11Memory, x: &E11Input, y: &mut E11ToE1) {
    y.tau.set(m.tau);
    if let Some(yaw) = reset_imu(m, x) {
        y.cmd_E11.set(ImuCommand::Reset { yaw });
    }
}

/// `ec`: the state estimate, the ready event, plan outcomes and the fragment
/// completed in the last iteration to `c1`.
pub fn ec(m: &E11Memory, _: &E11Input, y: &mut E11ToC1) {
    if let Some(p) = m.completed_now {
        y.progress.set(p);
    }
    if m.estym.estimate.localised {
        y.q_est.set(m.estym.estimate.to_state(m.x_icr));
    }
    if report_ready(m) {
        y.ready.set(true);
    }
    if let Some(o) = &m.event {
        y.outcome.set(o.clone());
    }
}

fn valid(f: &Fragment) -> bool {
    !f.states.is_empty() && f.dt > 0.0 && f.states.iter().flatten().all(|v| v.is_finite())
}

/// `ee_steps`: count down, take new fragments, hold the last point.
pub fn ee_steps(m: &mut E11Memory, x: &E11Input) {
    if reset_imu(m, x).is_some() {
        m.imu_reset_at = Some(m.iteration);
    }
    if report_ready(m) && m.iteration > 0 {
        m.reported = true;
    }
    m.completed_now = None;
    let now = m.now();
    if let Some(r) = &mut m.track.running {
        r.k += 1;
        m.step = m.step.saturating_sub(1);
        m.notify = m.notify.saturating_sub(1);
        if m.step == 0 {
            let end = r.fragment.end();
            m.track.hold = end.map(|e| [e[0], e[1], e[2], 0.0, 0.0]);
            if r.fragment.last
                && let Some(e) = end
            {
                m.arrival = Some(Arrival {
                    plan: r.fragment.plan,
                    end: [e[0], e[1]],
                    since: now,
                });
            }
            m.completed_now = Some(Progress {
                plan: r.fragment.plan,
                done: r.fragment.index.saturating_add(1),
            });
            m.track.running = None;
            m.track.completed += 1;
        }
    }
    if let Some(f) = x.c1.traj.fresh() {
        m.track.received += 1;
        if f.epoch < m.epoch {
            // Handed over before c1 heard of the last stop: its plan ended there.
            m.track.stale += 1;
            let why = format!(
                "fragment {} was handed over before c1 heard of stop {}",
                f.index, m.epoch
            );
            m.conclude(f.plan, Execution::Stopped(why));
        } else if valid(f) {
            // `steps` and `notify` travel with the fragment; keep `notify < steps`.
            let steps =
                x.c1.steps
                    .fresh()
                    .copied()
                    .unwrap_or(f.steps() as u32)
                    .max(1);
            let notify = x.c1.notify.fresh().copied().unwrap_or(0).min(steps - 1);
            m.track.queue.push_back((f.clone(), steps, notify));
        } else {
            m.track.rejected += 1;
            let why = format!("fragment {} is empty or not finite", f.index);
            m.conclude(f.plan, Execution::Stopped(why));
        }
    }
    if m.track.running.is_none()
        && let Some((fragment, steps, notify)) = m.track.queue.pop_front()
    {
        m.step = steps;
        m.notify = notify;
        m.reported = false;
        m.track.running = Some(Running { fragment, k: 0 });
    }
    m.iteration += 1;
}

/// `e11`'s FSM: the single behaviour `track`.
pub fn e11_fsm() -> Result<Fsm<E11>, FsmBuildError> {
    fsm! {
        subsystem E11;
        while track until false {
            common <- ee_estimate_track, E1 <- eE, c1 <- ec, memory <- ee_steps
        }
        initial track;
    }
}

#[cfg(test)]
mod tests;
