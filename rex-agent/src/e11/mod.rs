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
//! * `ec` (to c1): the state estimate, and `ready` once at start and once per
//!   fragment after `notify` iterations;
//! * `ee_steps` (memory): counts `step` and `notify` down, queues fragments that
//!   arrive before the current one ends (because `notify < steps`), and holds the
//!   last point when no fragment follows.

pub mod estimator;
pub mod tracker;

use std::collections::VecDeque;

use embodied::{
    Action, Behaviour, Fsm, FsmBuildError, Group, In, NodeKind, Out, Subsystem, SubsystemKind,
};

pub use estimator::{Estimate, Estimator, EstimatorKind, Measurements};
pub use tracker::{Tracker, TrackerKind};

use crate::planner::Fragment;
use crate::types::{Encoders, Imu, ImuCommand, MapPose, State, Torques, Transform, WheelLoads};

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
#[derive(Debug)]
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
    /// The period [s].
    pub dt: f64,
    /// Iteration at which the IMU reset was sent.
    pub imu_reset_at: Option<u64>,
    /// ICR offset used to report velocities.
    pub x_icr: f64,
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
            dt,
            imu_reset_at: None,
            x_icr,
        }
    }
}

/// Inputs from `c1`.
#[derive(Clone, Debug, Default)]
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
impl Group for E11FromC1 {
    const PEER: NodeKind = NodeKind::Control;
}

/// Inputs from the platform.
#[derive(Clone, Debug, Default)]
pub struct E11FromE1 {
    /// IMU.
    pub imu: In<Imu>,
    /// Force sensors.
    pub forces: In<WheelLoads>,
    /// Encoders.
    pub encoders: In<Encoders>,
}
impl Group for E11FromE1 {
    const PEER: NodeKind = NodeKind::RealEffector;
}

/// `e11`'s input buffers (group names are the peers' names, as in the spec).
#[derive(Clone, Debug, Default)]
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
#[derive(Debug, Default)]
pub struct E11ToC1 {
    /// State estimate.
    pub q_est: Out<State>,
    /// Ready event.
    pub ready: Out<bool>,
}
impl Group for E11ToC1 {
    const PEER: NodeKind = NodeKind::Control;
}

/// Outputs to the platform.
#[derive(Debug, Default)]
#[expect(non_snake_case, reason = "the paper's buffer names")]
pub struct E11ToE1 {
    /// Torques.
    pub tau: Out<Torques>,
    /// IMU reset.
    pub cmd_E11: Out<ImuCommand>,
}
impl Group for E11ToE1 {
    const PEER: NodeKind = NodeKind::RealEffector;
}

/// `e11`'s output buffers.
#[derive(Debug, Default)]
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
pub struct E11;

impl Subsystem for E11 {
    const KIND: SubsystemKind = SubsystemKind::VirtualEffector;
    type Memory = E11Memory;
    type Input = E11Input;
    type Output = E11Output;
}

/// Whether `ready` goes out in this iteration.
fn report_ready(m: &E11Memory) -> bool {
    m.iteration == 0 || (m.track.running.is_some() && m.notify == 0 && !m.reported)
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
        now: m.iteration as f64 * m.dt,
    };
    let estimate = m.estym.estimator.update(m.dt, &m.tau, &meas);
    m.estym.estimate = estimate;
    m.track.following = None;
    if !estimate.localised {
        m.tau = [0.0; 4];
        m.track.reference = None;
        return;
    }
    if m.track.hold.is_none() {
        let [px, py, phi, _, _] = estimate.x;
        m.track.hold = Some([px, py, phi, 0.0, 0.0]);
    }
    m.track.following = m
        .track
        .running
        .as_ref()
        .map(|r| (r.fragment.plan, r.fragment.index));
    if fill_horizon(&mut m.track) {
        m.track.reference = m.track.horizon.first().copied();
        m.tau = m.track.tracker.control(&estimate, &m.track.horizon, m.dt);
    } else {
        m.track.reference = None;
        m.tau = [0.0; 4];
    }
}

/// `eE`: torques and the IMU reset to the platform.
pub fn ee_to_platform(m: &E11Memory, x: &E11Input, y: &mut E11ToE1) {
    y.tau.set(m.tau);
    if let Some(yaw) = reset_imu(m, x) {
        y.cmd_E11.set(ImuCommand::Reset { yaw });
    }
}

/// `ec`: the state estimate and the ready event to `c1`.
pub fn ec(m: &E11Memory, _: &E11Input, y: &mut E11ToC1) {
    if m.estym.estimate.localised {
        y.q_est.set(m.estym.estimate.to_state(m.x_icr));
    }
    if report_ready(m) {
        y.ready.set(true);
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
    if let Some(r) = &mut m.track.running {
        r.k += 1;
        m.step = m.step.saturating_sub(1);
        m.notify = m.notify.saturating_sub(1);
        if m.step == 0 {
            m.track.hold = r.fragment.end().map(|e| [e[0], e[1], e[2], 0.0, 0.0]);
            m.track.running = None;
            m.track.completed += 1;
        }
    }
    if let Some(f) = x.c1.traj.fresh() {
        m.track.received += 1;
        if valid(f) {
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
    Fsm::single(Behaviour::while_loop(
        "track",
        Action::<E11>::new()
            .common(ee_estimate_track)
            .output(|y| &mut y.E1, ee_to_platform)
            .output(|y| &mut y.c1, ec)
            .memory(ee_steps),
        "false",
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{PlatformParams, SlipParams};
    use embodied::{Stamp, Time};

    fn fragment(index: u32, x0: f64, n: usize) -> Fragment {
        Fragment {
            plan: 1,
            index,
            dt: 0.05,
            states: (0..=n)
                .map(|k| [x0 + 0.01 * k as f64, 0.0, 0.0, 0.2, 0.0])
                .collect(),
        }
    }

    /// What e11 did at each iteration (ready sent, the fragment whose reference it
    /// followed), and the fragments it rejected.
    fn run(
        deliveries: &[(u64, Fragment, u32, u32)],
        iterations: u64,
    ) -> (Vec<(bool, Option<u32>)>, u32) {
        let params = PlatformParams::peer_default();
        let mut m = E11Memory::new(
            TrackerKind::Backstepping
                .build(params.clone(), 0.05)
                .unwrap(),
            EstimatorKind::Ekf
                .build(params, SlipParams::NOMINAL, 0.05)
                .unwrap(),
            0.05,
            0.03,
        );
        let fsm = e11_fsm().unwrap();
        let mut state = fsm.start();
        let mut x = E11Input::default();
        let stamp = Stamp::new(0, Time::ZERO);
        let mut out = Vec::new();
        for it in 0..iterations {
            x.c1.traj.age();
            x.c1.steps.age();
            x.c1.notify.age();
            x.c1.pose.age();
            if it == 0 {
                // Localise the estimator at the origin.
                let pose = MapPose {
                    pose: crate::types::Pose2::default(),
                    time: 0.0,
                };
                x.c1.pose.deliver(pose, stamp);
            }
            for (at, f, steps, notify) in deliveries {
                if *at == it {
                    x.c1.traj.deliver(f.clone(), stamp);
                    x.c1.steps.deliver(*steps, stamp);
                    x.c1.notify.deliver(*notify, stamp);
                }
            }
            let mut y = E11Output::default();
            fsm.activate(&mut state, &mut m, &x, &mut y, |_| {})
                .unwrap();
            out.push((y.c1.ready.is_written(), m.track.following.map(|(_, i)| i)));
        }
        (out, m.track.rejected)
    }

    #[test]
    fn fragments_run_steps_iterations_ready_after_notify_then_hold() {
        let (out, rejected) = run(
            &[
                (1, fragment(0, 0.0, 10), 10, 6),
                (4, fragment(1, 0.1, 4), 4, 2),
            ],
            24,
        );
        assert_eq!(rejected, 0);
        let ready: Vec<usize> = (0..out.len()).filter(|&i| out[i].0).collect();
        let following: Vec<Option<u32>> = out.iter().map(|o| o.1).collect();
        // Ready once at start, then once per fragment after `notify` iterations of it.
        // Fragment 0 arrives at 1 and runs 2..=11; fragment 1 arrives early (at 4),
        // waits, and runs 12..=15; then e11 holds the last point.
        assert_eq!(ready, [0, 8, 14], "{out:?}");
        assert_eq!(&following[2..12], &[Some(0); 10]);
        assert_eq!(&following[12..16], &[Some(1); 4]);
        assert!(following[16..].iter().all(Option::is_none), "holding");
        assert_eq!(following[..2], [None, None]);
    }

    #[test]
    fn bad_fragments_are_rejected_and_counted() {
        let mut bad = fragment(0, 0.0, 5);
        bad.states[3][1] = f64::NAN;
        let (out, rejected) = run(&[(1, bad, 5, 2)], 10);
        assert_eq!(rejected, 1);
        assert!(out.iter().all(|o| o.1.is_none()), "never followed: {out:?}");
    }
}
