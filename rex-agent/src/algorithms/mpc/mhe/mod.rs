//! Moving-horizon estimation of the state and the slip parameters (the paper's
//! section 3.2; notes §3.2), the problem of `peers/casadi_mhe.py`:
//!
//! ```text
//! min_{x_0..x_N, p}  ‖x_0 − x̄‖²_{P0} + ‖p − p̄‖²_{PP} + Σ_i ‖y_i − h(x_i)‖²_V
//!                    + Σ_i ‖x_{i+1} − F(x_i, u_i, p)‖²_W          p ∈ [p_lb, p_ub]
//! ```
//!
//! (the peer's process noise `w_i` with the constraint `x_{i+1} = F + w_i` is
//! eliminated: `w_i = x_{i+1} − F(x_i, u_i, p)`, the same problem). The window holds
//! the last `N + 1` samples (fewer at start); each stage has whichever measurements
//! arrived for it, so rates may differ and measurements may be missing:
//!
//! * map pose `(X, Y, φ)`, possibly late: attached to the stage nearest the time it
//!   describes;
//! * visual odometry: the motion between two earlier times, spread at constant
//!   velocity over the stages between them as relative motions of consecutive
//!   stages (which keeps the normal equations block-tridiagonal); unlike a pose
//!   composed onto the estimate, it adds no absolute evidence it does not have;
//! * gyroscope rate `ω`;
//! * IMU heading, through its increments between consecutive stages only: the IMU
//!   integrates its gyroscope, bias included, so its heading drifts away from the
//!   map's without bound (0.4 rad in a minute on Rex's simulated IMU). Taken as an
//!   absolute heading it pulled the estimate off the motion-capture poses until they
//!   were gated out for good; its increments are the integrated gyro over the
//!   interval, which the drift leaves intact;
//! * encoder rates `θ̇_i = (v − d_iy ω) / r`;
//! * wheel loads (force sensors): static loads plus the load transfer of the
//!   accelerations the model predicts.
//!
//! Exteroceptive measurements (poses) are gated: an innovation beyond
//! `gate · σ` (widened by `drift_rate` per second without an accepted pose) is
//! rejected; any non-finite or implausible measurement is rejected. All are counted.
//! An estimate that disagrees with the map poses for `relocalise_after` seconds is
//! wrong, not the poses: the window restarts from the latest pose (a relocalisation,
//! counted in [`MheStats::relocalisations`]), keeping the slip parameters.
//!
//! **Solution.** Gauss–Newton with exact sensitivities, one iteration per sample
//! (real-time iteration; more at start). The normal equations are block-tridiagonal
//! in the states with a border for `p`: a block Cholesky factorisation of the states'
//! part and the 3 × 3 Schur complement of `p` solve them exactly in `O(N)`. When the
//! step would leave the parameter bounds, the QP reduced to `Δp` (a 3-variable box
//! QP, exact after eliminating the states) is solved by Clarabel.
//! [`QpStrategy::Clarabel`] instead gives Clarabel the whole QP in `(Δx, Δp)`.

use std::collections::VecDeque;

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use serde::{Deserialize, Serialize};

use super::linalg::{Mat, cholesky, cholesky_solve};
use super::nmpc::QpStrategy;
use super::sparse::Pattern;
use crate::algorithms::geometry::wrap;
use crate::world::model::{Jacobians, Reduced, SlipParams, State5, Torques};

const NX: usize = 5;
const NP: usize = 3;

/// Settings of the MHE; the defaults are the peer's (`casadi_mhe.py`) where it has
/// them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct MheSettings {
    /// Window length `N` (intervals).
    pub horizon: usize,
    /// Interval [s].
    pub dt: f64,
    /// RK4 steps per interval.
    pub rk4_steps: usize,
    /// Process noise standard deviations per interval, `(X, Y, φ, v, ω)`.
    pub sigma_w: [f64; 5],
    /// Arrival cost on `x_0`.
    pub sigma_x0: [f64; 5],
    /// Arrival cost on `p`.
    pub sigma_p: [f64; 3],
    /// Initial parameter guess `(x_0, μ_s, μ_l)`.
    pub p_prior: [f64; 3],
    /// Lower parameter bounds.
    pub p_lb: [f64; 3],
    /// Upper parameter bounds.
    pub p_ub: [f64; 3],
    /// Map pose position noise [m].
    pub sigma_pos: f64,
    /// Map pose heading noise [rad].
    pub sigma_phi: f64,
    /// Gyroscope noise [rad/s].
    pub sigma_gyro: f64,
    /// Noise of the IMU heading's increment between two consecutive stages [rad]
    /// (its absolute value is not used: it drifts with the gyroscope's bias).
    pub sigma_heading_step: f64,
    /// Encoder rate noise [rad/s].
    pub sigma_encoder: f64,
    /// Force sensor noise [N] (0 leaves the loads out).
    pub sigma_load: f64,
    /// Visual odometry: noise of the displacement between consecutive stages [m].
    pub sigma_vo_step: f64,
    /// Visual odometry: noise of the turn between consecutive stages [rad].
    pub sigma_vo_turn: f64,
    /// Plausible speed [m/s] (measurements beyond 3 times are rejected).
    pub max_speed: f64,
    /// Plausible turn rate [rad/s] (the same).
    pub max_yaw_rate: f64,
    /// Gate on pose innovations, in standard deviations.
    pub gate: f64,
    /// Widening of the pose gate per second without an accepted pose [m/s].
    pub drift_rate: f64,
    /// Poses rejected by the gate for this long [s] restart the window from the
    /// latest one (a relocalisation).
    pub relocalise_after: f64,
    /// Gauss–Newton iterations per sample (1: real-time iteration).
    pub iterations: usize,
    /// Iterations while the window fills.
    pub start_iterations: usize,
    /// How QPs are solved.
    pub qp: QpStrategy,
    /// Clarabel's tolerances.
    pub qp_tolerance: f64,
}

impl Default for MheSettings {
    fn default() -> Self {
        MheSettings {
            horizon: 20,
            dt: 0.05,
            rk4_steps: 2,
            sigma_w: [0.002, 0.002, 0.002, 0.01, 0.02],
            sigma_x0: [0.05, 0.05, 0.05, 0.1, 0.1],
            sigma_p: [0.05, 0.05, 0.2],
            p_prior: [0.03, 0.05, 0.50],
            p_lb: [-0.15, 0.0, 0.05],
            p_ub: [0.15, 0.5, 1.5],
            sigma_pos: 0.02,
            sigma_phi: 0.01,
            sigma_gyro: 0.01,
            sigma_heading_step: 0.002,
            sigma_encoder: 0.05,
            sigma_load: 0.0,
            sigma_vo_step: 0.001,
            sigma_vo_turn: 0.002,
            max_speed: 1.5,
            max_yaw_rate: 2.0,
            gate: 6.0,
            drift_rate: 0.2,
            relocalise_after: 1.0,
            iterations: 1,
            start_iterations: 3,
            qp: QpStrategy::Structured,
            qp_tolerance: 1e-6,
        }
    }
}

impl MheSettings {
    /// Check the settings.
    pub fn validate(&self) -> Result<(), MheError> {
        let bad = |w: &str| Err(MheError::Settings(w.to_owned()));
        if self.horizon == 0 || self.rk4_steps == 0 || self.iterations == 0 {
            return bad("horizon, rk4_steps and iterations must be at least 1");
        }
        let scalars = [
            self.dt,
            self.sigma_pos,
            self.sigma_phi,
            self.sigma_gyro,
            self.sigma_heading_step,
            self.sigma_encoder,
            self.sigma_vo_step,
            self.sigma_vo_turn,
            self.max_speed,
            self.max_yaw_rate,
            self.gate,
            self.relocalise_after,
            self.qp_tolerance,
        ];
        let mut positive = self
            .sigma_w
            .iter()
            .chain(&self.sigma_x0)
            .chain(&self.sigma_p)
            .chain(&scalars);
        if positive.any(|v| !(v.is_finite() && *v > 0.0)) {
            return bad("dt, standard deviations, gate and tolerances must be positive");
        }
        let non_negative = |v: f64| v.is_finite() && v >= 0.0;
        if !(non_negative(self.sigma_load) && non_negative(self.drift_rate)) {
            return bad("sigma_load and drift_rate must be finite and non-negative");
        }
        for i in 0..NP {
            let (lb, ub, p0) = (self.p_lb[i], self.p_ub[i], self.p_prior[i]);
            if !(lb.is_finite() && ub.is_finite() && lb < ub && (lb..=ub).contains(&p0)) {
                return bad("each parameter needs finite bounds lb < ub around its prior");
            }
        }
        Ok(())
    }
}

/// Why the MHE could not run.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MheError {
    /// Invalid settings.
    #[error("invalid MHE settings: {0}")]
    Settings(String),
    /// The step could not be computed.
    #[error("MHE step failed: {0}")]
    Solve(String),
}

/// A pose on the map and the time it describes [s].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TimedPose {
    /// Simulation time the pose describes.
    pub time: f64,
    /// `(X, Y, φ)`.
    pub pose: [f64; 3],
}

/// A motion measured by visual odometry: from the pose at `from` to the pose at
/// `to`, in the body frame at `from` (`dx` forward, `dy` left, `dphi`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Motion {
    /// Start time [s].
    pub from: f64,
    /// End time [s].
    pub to: f64,
    /// `(dx, dy, dφ)`.
    pub delta: [f64; 3],
}

/// The measurements of one sample (each `None` when absent).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    /// Map pose (possibly describing an earlier time).
    pub pose: Option<TimedPose>,
    /// Visual odometry.
    pub motion: Option<Motion>,
    /// Gyroscope yaw rate [rad/s].
    pub gyro: Option<f64>,
    /// IMU heading [rad]: only its change from the previous sample's is used.
    pub heading: Option<f64>,
    /// Encoder rates [rad/s].
    pub encoders: Option<[f64; 4]>,
    /// Wheel loads [N].
    pub loads: Option<[f64; 4]>,
}

/// Counters of the MHE.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct MheStats {
    /// Samples processed.
    pub samples: u64,
    /// Gauss–Newton steps.
    pub steps: u64,
    /// Steps whose QP went to Clarabel (a parameter bound active).
    pub clarabel: u64,
    /// Measurements rejected (not finite, implausible, or gated out).
    pub rejected: u64,
    /// Of those, map poses gated out.
    pub rejected_poses: u64,
    /// Restarts of the window from a map pose after `relocalise_after` seconds of
    /// rejected poses.
    pub relocalisations: u64,
    /// Samples before the first pose (nothing to anchor the estimate).
    pub waiting: u64,
    /// Failed steps (the previous estimate was propagated instead).
    pub failures: u64,
}

/// What the estimator believes now.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct MheEstimate {
    /// State `(X, Y, φ)` of the newest sample, and `(v, ω)`.
    pub x: State5,
    /// Slip parameters.
    pub p: SlipParams,
    /// Whether a pose anchored the estimate.
    pub localised: bool,
}

/// One stage of the window.
#[derive(Clone, Copy, Debug, Default)]
struct Stage {
    t: f64,
    x: State5,
    /// Torques applied from this stage to the next.
    u: Torques,
    pose: Option<[f64; 3]>,
    /// Standard deviations of `pose` (position, heading).
    pose_sigma: [f64; 2],
    gyro: Option<f64>,
    heading: Option<f64>,
    encoders: Option<[f64; 4]>,
    loads: Option<[f64; 4]>,
    /// The motion `(dx, dy, dφ)` to the next stage in this stage's frame, from
    /// visual odometry.
    rel: Option<[f64; 3]>,
}

/// Blocks of the normal equations.
#[derive(Clone, Copy, Debug, Default)]
struct Blocks {
    d: Mat<NX, NX>,
    /// Coupling with the next stage (block `(i, i+1)`).
    o: Mat<NX, NX>,
    /// Coupling with `p` (block `(p, i)`, 3 × 5).
    c: Mat<NP, NX>,
    g: [f64; NX],
}

/// The moving-horizon estimator.
#[derive(Debug)]
pub struct Mhe {
    model: Reduced,
    s: MheSettings,
    window: VecDeque<Stage>,
    p: [f64; NP],
    /// Arrival cost anchors.
    x_bar: State5,
    p_bar: [f64; NP],
    last_pose_time: Option<f64>,
    /// When the current run of gated-out poses began (`None` after an accepted one).
    rejecting_since: Option<f64>,
    blocks: Vec<Blocks>,
    hpp: Mat<NP, NP>,
    gp: [f64; NP],
    lin: Vec<Jacobians>,
    /// Block Cholesky factors of the states' part, and the solutions for the
    /// gradient and for the three coupling columns.
    chol: Vec<Mat<NX, NX>>,
    e: Vec<Mat<NX, NX>>,
    sol: Vec<Mat<NX, 4>>,
    qp: Option<BoxQp>,
    full: Option<FullQp>,
    stats: MheStats,
}

impl Mhe {
    /// An estimator for `model`.
    pub fn new(model: Reduced, settings: MheSettings) -> Result<Mhe, MheError> {
        settings.validate()?;
        let n = settings.horizon;
        Ok(Mhe {
            model,
            window: VecDeque::with_capacity(n + 2),
            p: settings.p_prior,
            x_bar: [0.0; NX],
            p_bar: settings.p_prior,
            last_pose_time: None,
            rejecting_since: None,
            blocks: vec![Blocks::default(); n + 1],
            hpp: Mat::zero(),
            gp: [0.0; NP],
            lin: vec![Jacobians::default(); n],
            chol: vec![Mat::zero(); n + 1],
            e: vec![Mat::zero(); n + 1],
            sol: vec![Mat::zero(); n + 1],
            qp: None,
            full: None,
            stats: MheStats::default(),
            s: settings,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &MheSettings {
        &self.s
    }

    /// The counters.
    pub fn stats(&self) -> MheStats {
        self.stats
    }

    /// The current estimate.
    pub fn estimate(&self) -> MheEstimate {
        MheEstimate {
            x: self.window.back().map_or([0.0; NX], |s| s.x),
            p: slip(&self.p),
            localised: !self.window.is_empty(),
        }
    }

    /// The estimate of the state at time `t` inside the window (nearest stage).
    pub fn state_at(&self, t: f64) -> Option<State5> {
        self.nearest(t)
            .map(|i| self.shifted(&self.window[i].x, t - self.window[i].t))
    }

    /// The state `x` moved along its own velocity by `dt` seconds (first order):
    /// measurements are rarely taken at a stage's instant, and 25 ms at 0.5 m/s
    /// are 12 mm.
    fn shifted(&self, x: &State5, dt: f64) -> State5 {
        let (s, c) = x[2].sin_cos();
        let (v, w, x0) = (x[3], x[4], self.p[0]);
        [
            x[0] + dt * (v * c + x0 * w * s),
            x[1] + dt * (v * s - x0 * w * c),
            x[2] + dt * w,
            v,
            w,
        ]
    }

    fn nearest(&self, t: f64) -> Option<usize> {
        if !t.is_finite() {
            return None;
        }
        let (i, s) = self
            .window
            .iter()
            .enumerate()
            .min_by(|a, b| (a.1.t - t).abs().total_cmp(&(b.1.t - t).abs()))?;
        ((s.t - t).abs() <= 0.5 * self.s.dt + 1e-9).then_some(i)
    }

    /// A new sample at time `t`: `u` is the torque applied since the previous
    /// sample, `m` the measurements. Returns the estimate after the update.
    pub fn update(&mut self, t: f64, u: &Torques, m: &Sample) -> MheEstimate {
        self.stats.samples += 1;
        let u = u.map(|v| if v.is_finite() { v } else { 0.0 });
        if self.window.is_empty() {
            return self.start(t, m);
        }
        // Predict the new stage and shift the window.
        let (mut prev, p) = (
            self.window.back().copied().unwrap_or_default(),
            slip(&self.p),
        );
        prev.u = u;
        if let Some(last) = self.window.back_mut() {
            last.u = u;
        }
        let x_new = self.model.rk4(&prev.x, &u, &p, self.s.dt, self.s.rk4_steps);
        let x_new = if x_new.iter().all(|v| v.is_finite()) {
            x_new
        } else {
            prev.x
        };
        self.window.push_back(Stage {
            t,
            x: x_new,
            ..Stage::default()
        });
        if self.window.len() > self.s.horizon + 1 {
            self.window.pop_front();
            // Arrival cost: the current estimate of the new first stage.
            if let Some(first) = self.window.front() {
                self.x_bar = first.x;
            }
            self.p_bar = self.p;
        }
        self.attach(m);
        let iterations = if self.window.len() <= self.s.horizon {
            self.s.start_iterations.max(self.s.iterations)
        } else {
            self.s.iterations
        };
        for _ in 0..iterations {
            if let Err(_e) = self.gauss_newton() {
                self.stats.failures += 1;
                break;
            }
        }
        self.estimate()
    }

    /// The first sample with a pose starts the window; before it, samples wait.
    fn start(&mut self, t: f64, m: &Sample) -> MheEstimate {
        let pose = m
            .pose
            .filter(|p| p.pose.iter().all(|v| v.is_finite()) && p.time.is_finite());
        let Some(pose) = pose else {
            if m.pose.is_some() {
                self.stats.rejected += 1;
            }
            self.stats.waiting += 1;
            return self.estimate();
        };
        let w = m.gyro.filter(|w| w.is_finite()).unwrap_or(0.0);
        let v = m
            .encoders
            .filter(|e| e.iter().all(|v| v.is_finite()))
            .map_or(0.0, |e| {
                self.model.params.wheel_radius * e.iter().sum::<f64>() / 4.0
            });
        let [x, y, phi] = pose.pose;
        // The pose describes an earlier time (it is late): moved to now, it is
        // the first stage's measurement.
        self.x_bar = self.shifted(&[x, y, phi, v, w], t - pose.time);
        self.p_bar = self.p;
        self.window.push_back(Stage {
            t,
            x: self.x_bar,
            pose: Some([self.x_bar[0], self.x_bar[1], self.x_bar[2]]),
            pose_sigma: [self.s.sigma_pos, self.s.sigma_phi],
            ..Stage::default()
        });
        self.last_pose_time = Some(pose.time);
        self.attach(&Sample { pose: None, ..*m });
        for _ in 0..self.s.start_iterations.max(1) {
            if self.gauss_newton().is_err() {
                self.stats.failures += 1;
                break;
            }
        }
        self.estimate()
    }

    /// Attach the measurements of a sample to their stages, rejecting bad ones.
    fn attach(&mut self, m: &Sample) {
        let n = self.window.len() - 1;
        let plausible_rate = 4.0 * self.model.params.wheel_speed_max.max(1.0);
        let now = self.window[n].t;
        if let Some(g) = m.gyro {
            if g.is_finite() && g.abs() <= 20.0 {
                self.window[n].gyro = Some(g);
            } else {
                self.stats.rejected += 1;
            }
        }
        if let Some(h) = m.heading {
            // A jump no turn makes (a reset of the IMU between the samples, or
            // garbage) breaks the chain of increments.
            let previous = n.checked_sub(1).and_then(|i| {
                self.window[i]
                    .heading
                    .map(|h0| (h0, now - self.window[i].t))
            });
            let plausible = previous.is_none_or(|(h0, dt)| {
                wrap(h - h0).abs() <= 3.0 * self.s.max_yaw_rate * dt.abs() + 0.05
            });
            if h.is_finite() && plausible {
                self.window[n].heading = Some(h);
            } else {
                self.stats.rejected += 1;
            }
        }
        if let Some(e) = m.encoders {
            if e.iter().all(|v| v.is_finite() && v.abs() <= plausible_rate) {
                self.window[n].encoders = Some(e);
            } else {
                self.stats.rejected += 1;
            }
        }
        if let Some(l) = m.loads
            && self.s.sigma_load > 0.0
        {
            let weight = self.model.params.mass * self.model.params.gravity;
            if l.iter()
                .all(|v| v.is_finite() && *v >= -0.1 * weight && *v <= weight)
            {
                self.window[n].loads = Some(l);
            } else {
                self.stats.rejected += 1;
            }
        }
        if let Some(p) = m.pose {
            let sigma = [self.s.sigma_pos, self.s.sigma_phi];
            self.attach_pose(p.time, p.pose, sigma, now);
        }
        let first = self.window.front().map_or(now, |s| s.t);
        let filling = self.window.len() <= self.s.horizon;
        if let Some(mo) = m
            .motion
            .filter(|mo| !(filling && mo.from < first - 0.5 * self.s.dt))
        {
            // (A motion that began before a window still filling is of no use,
            // and nothing wrong.) Visual odometry measures a relative motion: the average velocity
            // over the interval, attached to the stage nearest its middle. (Composed
            // onto the estimate at `from` as a pose, it would repeat the estimate's
            // own error as if it were new evidence.)
            let span = mo.to - mo.from;
            let (a, b) = (self.nearest(mo.from), self.nearest(mo.to));
            // The displacement in the frame at the interval's middle: the chord of
            // an arc points along the heading half-way (in the frame at `from` it
            // would show a lateral v ω Δt / 2 that is no slip).
            let [dx, dy, dphi] = mo.delta;
            let (sh, ch) = (0.5 * dphi).sin_cos();
            let (mx, my) = (ch * dx + sh * dy, -sh * dx + ch * dy);
            let speed = [mx / span, my / span, dphi / span];
            let plausible = speed[0].abs() <= 3.0 * self.s.max_speed
                && speed[1].abs() <= 3.0 * self.s.max_speed
                && speed[2].abs() <= 3.0 * self.s.max_yaw_rate;
            match (a, b) {
                (Some(a), Some(b))
                    if span > 1e-3 && speed.iter().all(|v| v.is_finite()) && plausible =>
                {
                    // The motion between consecutive stages at that velocity (chords).
                    for k in a..b {
                        let tau = self.window[k + 1].t - self.window[k].t;
                        let turn = speed[2] * tau;
                        let (sh, ch) = (0.5 * turn).sin_cos();
                        let (ex, ey) = (speed[0] * tau, speed[1] * tau);
                        self.window[k].rel = Some([ch * ex - sh * ey, sh * ex + ch * ey, turn]);
                    }
                    if a == b {
                        // Shorter than a stage: nothing to tie together.
                        self.stats.rejected += 1;
                    }
                }
                _ => self.stats.rejected += 1,
            }
        }
    }

    fn attach_pose(&mut self, time: f64, pose: [f64; 3], sigma: [f64; 2], now: f64) {
        let first = self.window.front().map_or(now, |s| s.t);
        if time < first - 0.5 * self.s.dt && self.window.len() <= self.s.horizon {
            // Older than a window that is still filling: the first stage was
            // anchored on a newer pose.
            return;
        }
        let Some(i) = self
            .nearest(time)
            .filter(|_| pose.iter().all(|v| v.is_finite()))
        else {
            self.stats.rejected += 1;
            return;
        };
        // The measurement moved to the stage's instant along the estimated velocity.
        let x = self.window[i].x;
        let dt = self.window[i].t - time;
        let moved = self.shifted(&[pose[0], pose[1], pose[2], x[3], x[4]], dt);
        let pose = [moved[0], moved[1], moved[2]];
        let since = self.last_pose_time.map_or(0.0, |t| (now - t).max(0.0));
        let radius = self.s.gate * sigma[0] + self.s.drift_rate * since;
        let dphi = wrap(pose[2] - x[2]);
        let heading_gate = self.s.gate * sigma[1] + 0.5 * self.s.drift_rate * since;
        if (pose[0] - x[0]).hypot(pose[1] - x[1]) > radius || dphi.abs() > heading_gate {
            self.stats.rejected += 1;
            self.stats.rejected_poses += 1;
            let since = *self.rejecting_since.get_or_insert(time);
            if now - since >= self.s.relocalise_after {
                let t = self.window[i].t;
                self.relocalise(t, [pose[0], pose[1], x[2] + dphi], now);
            }
            return;
        }
        self.rejecting_since = None;
        self.window[i].pose = Some([pose[0], pose[1], x[2] + dphi]);
        self.window[i].pose_sigma = sigma;
        self.last_pose_time = Some(self.last_pose_time.map_or(time, |t| t.max(time)));
    }

    /// Restart the window from a map pose that describes the time `t`: the newest
    /// stage keeps its measurements and velocities, takes the pose moved to its
    /// instant, and becomes the whole window (the arrival cost anchors on it).
    fn relocalise(&mut self, t: f64, pose: [f64; 3], now: f64) {
        let Some(last) = self.window.back().copied() else {
            return;
        };
        let x = self.shifted(&[pose[0], pose[1], pose[2], last.x[3], last.x[4]], now - t);
        self.window.clear();
        self.window.push_back(Stage {
            x,
            pose: None,
            rel: None,
            ..last
        });
        self.x_bar = x;
        self.p_bar = self.p;
        self.last_pose_time = Some(t);
        self.rejecting_since = None;
        self.stats.relocalisations += 1;
    }

    /// One Gauss–Newton step on the whole window.
    fn gauss_newton(&mut self) -> Result<(), MheError> {
        let n = self.window.len() - 1;
        self.assemble()?;
        let (dx, dp) = match self.s.qp {
            QpStrategy::Structured => self.solve_structured(n)?,
            QpStrategy::Clarabel => self.solve_full(n)?,
        };
        if dx.iter().flatten().chain(&dp).any(|v| !v.is_finite()) {
            return Err(MheError::Solve("the step is not finite".into()));
        }
        for (stage, d) in self.window.iter_mut().zip(&dx) {
            for k in 0..NX {
                stage.x[k] += d[k];
            }
        }
        for k in 0..NP {
            self.p[k] = (self.p[k] + dp[k]).clamp(self.s.p_lb[k], self.s.p_ub[k]);
        }
        self.stats.steps += 1;
        Ok(())
    }

    /// Build the blocks of `JᵀJ` and `Jᵀr` at the current window.
    fn assemble(&mut self) -> Result<(), MheError> {
        let n = self.window.len() - 1;
        let s = &self.s;
        let p = slip(&self.p);
        for b in &mut self.blocks[..=n] {
            *b = Blocks::default();
        }
        let mut hpp = Mat::<NP, NP>::zero();
        let mut gp = [0.0; NP];
        // Arrival cost.
        let x0 = self.window[0].x;
        for k in 0..NX {
            let w = 1.0 / s.sigma_x0[k].powi(2);
            self.blocks[0].d.0[k][k] += w;
            let e = if k == 2 {
                wrap(x0[k] - self.x_bar[k])
            } else {
                x0[k] - self.x_bar[k]
            };
            self.blocks[0].g[k] += w * e;
        }
        for k in 0..NP {
            let w = 1.0 / s.sigma_p[k].powi(2);
            hpp.0[k][k] += w;
            gp[k] += w * (self.p[k] - self.p_bar[k]);
        }
        // Measurements.
        let wheel_r = self.model.params.wheel_radius;
        let contacts = self.model.params.contacts();
        for i in 0..=n {
            let st = self.window[i];
            let loads = st.loads.map(|l| (l, self.load_model(&st.x, &st.u, &p)));
            let b = &mut self.blocks[i];
            let mut scalar = |h: &[f64; NX], hp: &[f64; NP], r: f64, sigma: f64| {
                let w = 1.0 / (sigma * sigma);
                for a in 0..NX {
                    b.g[a] += w * h[a] * r;
                    for c in 0..NX {
                        b.d.0[a][c] += w * h[a] * h[c];
                    }
                    for c in 0..NP {
                        b.c.0[c][a] += w * hp[c] * h[a];
                    }
                }
                for a in 0..NP {
                    gp[a] += w * hp[a] * r;
                    for c in 0..NP {
                        hpp.0[a][c] += w * hp[a] * hp[c];
                    }
                }
            };
            let unit =
                |k: usize| -> [f64; NX] { std::array::from_fn(|j| f64::from(u8::from(j == k))) };
            let no_p = [0.0; NP];
            if let Some(pose) = st.pose {
                scalar(&unit(0), &no_p, st.x[0] - pose[0], st.pose_sigma[0]);
                scalar(&unit(1), &no_p, st.x[1] - pose[1], st.pose_sigma[0]);
                scalar(&unit(2), &no_p, st.x[2] - pose[2], st.pose_sigma[1]);
            }
            if let Some(g) = st.gyro {
                scalar(&unit(4), &no_p, st.x[4] - g, s.sigma_gyro);
            }
            if let Some(e) = st.encoders {
                let r = wheel_r;
                for k in 0..4 {
                    let dy = contacts[k][1];
                    let mut h = [0.0; NX];
                    h[3] = 1.0 / r;
                    h[4] = -dy / r;
                    scalar(
                        &h,
                        &no_p,
                        (st.x[3] - dy * st.x[4]) / r - e[k],
                        s.sigma_encoder,
                    );
                }
            }
            if let Some((l, (pred, jx, jp))) = loads {
                for k in 0..4 {
                    scalar(&jx[k], &jp[k], pred[k] - l[k], s.sigma_load);
                }
            }
        }
        // Visual odometry: r = motion from x_i to x_{i+1} in the frame of x_i − measured.
        for i in 0..n {
            let Some(rel) = self.window[i].rel else {
                continue;
            };
            let (a, b) = (self.window[i].x, self.window[i + 1].x);
            let (sn, c) = a[2].sin_cos();
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let r = [
                c * dx + sn * dy - rel[0],
                -sn * dx + c * dy - rel[1],
                b[2] - a[2] - rel[2],
            ];
            // Rows of ∂r/∂x_i and ∂r/∂x_{i+1}.
            let ja = [
                [-c, -sn, -sn * dx + c * dy, 0.0, 0.0],
                [sn, -c, -c * dx - sn * dy, 0.0, 0.0],
                [0.0, 0.0, -1.0, 0.0, 0.0],
            ];
            let jb = [
                [c, sn, 0.0, 0.0, 0.0],
                [-sn, c, 0.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0, 0.0],
            ];
            let w = [
                1.0 / s.sigma_vo_step.powi(2),
                1.0 / s.sigma_vo_step.powi(2),
                1.0 / s.sigma_vo_turn.powi(2),
            ];
            for k in 0..3 {
                for m in 0..NX {
                    self.blocks[i].g[m] += w[k] * ja[k][m] * r[k];
                    self.blocks[i + 1].g[m] += w[k] * jb[k][m] * r[k];
                    for q in 0..NX {
                        self.blocks[i].d.0[m][q] += w[k] * ja[k][m] * ja[k][q];
                        self.blocks[i + 1].d.0[m][q] += w[k] * jb[k][m] * jb[k][q];
                        self.blocks[i].o.0[m][q] += w[k] * ja[k][m] * jb[k][q];
                    }
                }
            }
        }
        // IMU heading: r = (φ_{i+1} − φ_i) − (h_{i+1} − h_i), the integrated gyro.
        let w = 1.0 / s.sigma_heading_step.powi(2);
        for i in 0..n {
            let (Some(h0), Some(h1)) = (self.window[i].heading, self.window[i + 1].heading) else {
                continue;
            };
            let r = (self.window[i + 1].x[2] - self.window[i].x[2]) - wrap(h1 - h0);
            self.blocks[i].d.0[2][2] += w;
            self.blocks[i + 1].d.0[2][2] += w;
            self.blocks[i].o.0[2][2] -= w;
            self.blocks[i].g[2] -= w * r;
            self.blocks[i + 1].g[2] += w * r;
        }
        // Dynamics: r = x_{i+1} − F(x_i, u_i, p), weights 1/σ_w².
        for i in 0..n {
            let st = self.window[i];
            let (next, j) = self
                .model
                .rk4_sensitivities(&st.x, &st.u, &p, s.dt, s.rk4_steps);
            if next.iter().any(|v| !v.is_finite()) {
                return Err(MheError::Solve("the model prediction is not finite".into()));
            }
            self.lin[i] = j;
            let x1 = self.window[i + 1].x;
            let r: [f64; NX] = std::array::from_fn(|k| x1[k] - next[k]);
            let w: [f64; NX] = s.sigma_w.map(|v| 1.0 / (v * v));
            let a = Mat(j.x);
            let pm = Mat(j.p);
            // W A and W P (rows scaled).
            let wa = Mat(std::array::from_fn(|k| a.0[k].map(|v| v * w[k])));
            let wp = Mat(std::array::from_fn(|k| pm.0[k].map(|v| v * w[k])));
            let wr: [f64; NX] = std::array::from_fn(|k| w[k] * r[k]);
            {
                let b = &mut self.blocks[i];
                b.d = b.d.add(&a.tmul(&wa));
                for c in 0..NX {
                    for k in 0..NX {
                        b.o.0[c][k] -= wa.0[k][c];
                    }
                    b.g[c] -= a.col_dot(c, &wr);
                }
                b.c = b.c.add(&pm.tmul(&wa));
            }
            {
                let b = &mut self.blocks[i + 1];
                for k in 0..NX {
                    b.d.0[k][k] += w[k];
                    b.g[k] += wr[k];
                    for c in 0..NP {
                        b.c.0[c][k] -= wp.0[k][c];
                    }
                }
            }
            hpp = hpp.add(&pm.tmul(&wp));
            for c in 0..NP {
                gp[c] -= pm.col_dot(c, &wr);
            }
        }
        self.hpp = hpp;
        self.gp = gp;
        Ok(())
    }
}

impl Mhe {
    /// Predicted wheel loads of the force sensors and their Jacobians: static loads
    /// plus the transfer of the body accelerations `a_x = v̇ + x₀ω²`,
    /// `a_y = vω − x₀ω̇` (as the plant computes them).
    fn load_model(
        &self,
        x: &State5,
        u: &Torques,
        p: &SlipParams,
    ) -> ([f64; 4], [[f64; NX]; 4], [[f64; NP]; 4]) {
        let pr = &self.model.params;
        let f = self.model.f(x, u, p);
        let j = self.model.f_jacobians(x, u, p);
        let (v, w, x0) = (x[3], x[4], p.x_icr);
        let ax = f[3] + x0 * w * w;
        let ay = v * w - x0 * f[4];
        let mut ax_x = j.x[3];
        ax_x[4] += 2.0 * x0 * w;
        let mut ax_p = j.p[3];
        ax_p[0] += w * w;
        let mut ay_x: [f64; NX] = std::array::from_fn(|k| -x0 * j.x[4][k]);
        ay_x[3] += w;
        ay_x[4] += v;
        let mut ay_p: [f64; NP] = std::array::from_fn(|k| -x0 * j.p[4][k]);
        ay_p[0] -= f[4];
        let long = pr.mass * pr.cog_height / (2.0 * (pr.front + pr.rear));
        let lat = pr.mass * pr.cog_height / (4.0 * pr.half_track);
        let n0 = pr.static_loads();
        let d = pr.contacts();
        let mut loads = [0.0; 4];
        let mut jx = [[0.0; NX]; 4];
        let mut jp = [[0.0; NP]; 4];
        for i in 0..4 {
            let front = if d[i][0] > 0.0 { -1.0 } else { 1.0 };
            let left = if d[i][1] > 0.0 { -1.0 } else { 1.0 };
            loads[i] = n0[i] + front * long * ax + left * lat * ay;
            jx[i] = std::array::from_fn(|k| front * long * ax_x[k] + left * lat * ay_x[k]);
            jp[i] = std::array::from_fn(|k| front * long * ax_p[k] + left * lat * ay_p[k]);
        }
        (loads, jx, jp)
    }

    /// Solve the normal equations by block Cholesky (states) and the Schur
    /// complement (parameters); Clarabel on the reduced box QP when a bound is hit.
    fn solve_structured(&mut self, n: usize) -> Result<(Vec<[f64; NX]>, [f64; NP]), MheError> {
        let not_pd = |i: usize| {
            MheError::Solve(format!(
                "the normal equations are not positive definite at stage {i}"
            ))
        };
        // Factor T = L Lᵀ, L block bidiagonal: L_i on the diagonal, E_iᵀ below.
        let mut sdiag = self.blocks[0].d;
        for i in 0..=n {
            let l = cholesky(&sdiag.symmetrised()).ok_or_else(|| not_pd(i))?;
            self.chol[i] = l;
            if i < n {
                let o = self.blocks[i].o;
                let mut e = Mat::<NX, NX>::zero();
                for c in 0..NX {
                    let col = lower_solve(&l, &std::array::from_fn(|r| o.0[r][c]));
                    for r in 0..NX {
                        e.0[r][c] = col[r];
                    }
                }
                self.e[i] = e;
                sdiag = self.blocks[i + 1].d.add(&neg(&e.tmul(&e)));
            }
        }
        // Right-hand sides B_i = [g_i | C_iᵀ]; forward then backward substitution.
        let rhs = |b: &Blocks| -> Mat<NX, 4> {
            Mat(std::array::from_fn(|r| {
                [b.g[r], b.c.0[0][r], b.c.0[1][r], b.c.0[2][r]]
            }))
        };
        for i in 0..=n {
            let mut b = rhs(&self.blocks[i]);
            if i > 0 {
                b = b.add(&neg(&self.e[i - 1].tmul(&self.sol[i - 1])));
            }
            self.sol[i] = columns(&b, |col| lower_solve(&self.chol[i], col));
        }
        for i in (0..=n).rev() {
            let mut y = self.sol[i];
            if i < n {
                y = y.add(&neg(&self.e[i].mul(&self.sol[i + 1])));
            }
            self.sol[i] = columns(&y, |col| upper_solve(&self.chol[i], col));
        }
        // Schur complement S = Hpp − C T⁻¹ Cᵀ and b = g_p − C T⁻¹ g.
        let mut schur = self.hpp;
        let mut bp = self.gp;
        for i in 0..=n {
            let c = self.blocks[i].c;
            let x = self.sol[i];
            for a in 0..NP {
                bp[a] -= (0..NX).map(|k| c.0[a][k] * x.0[k][0]).sum::<f64>();
                for b in 0..NP {
                    schur.0[a][b] -= (0..NX).map(|k| c.0[a][k] * x.0[k][b + 1]).sum::<f64>();
                }
            }
        }
        let schur = schur.symmetrised();
        let l = cholesky(&schur).ok_or_else(|| {
            MheError::Solve("the parameters' Schur complement is not positive definite".into())
        })?;
        let mut dp = cholesky_solve(&l, &bp).map(|v| -v);
        let inside = (0..NP).all(|k| {
            let q = self.p[k] + dp[k];
            q >= self.s.p_lb[k] - 1e-12 && q <= self.s.p_ub[k] + 1e-12
        });
        if !inside {
            if self.qp.is_none() {
                self.qp = Some(BoxQp::new(self.s.qp_tolerance)?);
            }
            let lo: [f64; NP] = std::array::from_fn(|k| self.s.p_lb[k] - self.p[k]);
            let hi: [f64; NP] = std::array::from_fn(|k| self.s.p_ub[k] - self.p[k]);
            if let Some(qp) = self.qp.as_mut() {
                dp = qp.solve(&schur, &bp, &lo, &hi)?;
            }
            self.stats.clarabel += 1;
        }
        let dx = (0..=n)
            .map(|i| {
                let x = &self.sol[i];
                std::array::from_fn(|k| {
                    -x.0[k][0] - (0..NP).map(|a| x.0[k][a + 1] * dp[a]).sum::<f64>()
                })
            })
            .collect();
        Ok((dx, dp))
    }

    /// The whole QP in `(Δx_0..Δx_n, Δp)` by Clarabel (for comparison).
    fn solve_full(&mut self, n: usize) -> Result<(Vec<[f64; NX]>, [f64; NP]), MheError> {
        if self.full.as_ref().is_none_or(|f| f.stages != n + 1) {
            self.full = Some(FullQp::new(n + 1, self.s.qp_tolerance)?);
        }
        let lo: [f64; NP] = std::array::from_fn(|k| self.s.p_lb[k] - self.p[k]);
        let hi: [f64; NP] = std::array::from_fn(|k| self.s.p_ub[k] - self.p[k]);
        let Some(full) = self.full.as_mut() else {
            return Err(MheError::Solve("no QP".into()));
        };
        let w = full.solve(&self.blocks[..=n], &self.hpp, &self.gp, &lo, &hi)?;
        self.stats.clarabel += 1;
        let dx = (0..=n)
            .map(|i| std::array::from_fn(|k| w[i * NX + k]))
            .collect();
        let dp = std::array::from_fn(|k| w[(n + 1) * NX + k]);
        Ok((dx, dp))
    }
}

fn neg<const R: usize, const C: usize>(m: &Mat<R, C>) -> Mat<R, C> {
    Mat(m.0.map(|row| row.map(|v| -v)))
}

/// Apply `f` to each column of `m`.
fn columns<const K: usize>(m: &Mat<NX, K>, f: impl Fn(&[f64; NX]) -> [f64; NX]) -> Mat<NX, K> {
    let mut out = Mat::<NX, K>::zero();
    for c in 0..K {
        let col = f(&std::array::from_fn(|r| m.0[r][c]));
        for r in 0..NX {
            out.0[r][c] = col[r];
        }
    }
    out
}

/// `L y = b` for lower-triangular `L`.
fn lower_solve<const N: usize>(l: &Mat<N, N>, b: &[f64; N]) -> [f64; N] {
    let mut y = *b;
    for i in 0..N {
        for k in 0..i {
            y[i] -= l.0[i][k] * y[k];
        }
        y[i] /= l.0[i][i];
    }
    y
}

/// `Lᵀ x = y` for lower-triangular `L`.
fn upper_solve<const N: usize>(l: &Mat<N, N>, y: &[f64; N]) -> [f64; N] {
    let mut x = *y;
    for i in (0..N).rev() {
        for k in i + 1..N {
            x[i] -= l.0[k][i] * x[k];
        }
        x[i] /= l.0[i][i];
    }
    x
}

fn clarabel_settings(tol: f64) -> Result<DefaultSettings<f64>, MheError> {
    DefaultSettingsBuilder::default()
        .verbose(false)
        .presolve_enable(false)
        .tol_gap_abs(tol)
        .tol_gap_rel(tol)
        .tol_feas(tol)
        // As for the NMPC: a small, well-scaled QP (see `nmpc`).
        .equilibrate_enable(false)
        .iterative_refinement_enable(false)
        .build()
        .map_err(|e| MheError::Solve(format!("Clarabel settings: {e}")))
}

fn clarabel_result(solver: &DefaultSolver<f64>) -> Result<Vec<f64>, MheError> {
    let sol = &solver.solution;
    match sol.status {
        SolverStatus::Solved | SolverStatus::AlmostSolved
            if sol.x.iter().all(|v| v.is_finite()) =>
        {
            Ok(sol.x.clone())
        }
        other => Err(MheError::Solve(format!("Clarabel: {other:?}"))),
    }
}

/// `min ½ Δpᵀ S Δp + bᵀ Δp` over `lo ≤ Δp ≤ hi`, by Clarabel (3 variables).
struct BoxQp {
    solver: DefaultSolver<f64>,
    /// Buffers for the data updates (Clarabel takes `Vec`s).
    p: Vec<f64>,
    q: Vec<f64>,
    b: Vec<f64>,
}

impl std::fmt::Debug for BoxQp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("BoxQp")
    }
}

impl BoxQp {
    fn new(tol: f64) -> Result<BoxQp, MheError> {
        // P: upper triangle of a dense 3 × 3; A = [I; −I].
        let p = CscMatrix::new(
            3,
            3,
            vec![0, 1, 3, 6],
            vec![0, 0, 1, 0, 1, 2],
            vec![1.0, 0.0, 1.0, 0.0, 0.0, 1.0],
        );
        let a = CscMatrix::new(
            6,
            3,
            vec![0, 2, 4, 6],
            vec![0, 3, 1, 4, 2, 5],
            vec![1.0, -1.0, 1.0, -1.0, 1.0, -1.0],
        );
        let solver = DefaultSolver::new(
            &p,
            &[0.0; 3],
            &a,
            &[1.0; 6],
            &[SupportedConeT::NonnegativeConeT(6)],
            clarabel_settings(tol)?,
        )
        .map_err(|e| MheError::Solve(format!("Clarabel setup: {e}")))?;
        Ok(BoxQp {
            solver,
            p: vec![0.0; 6],
            q: vec![0.0; 3],
            b: vec![0.0; 6],
        })
    }

    fn solve(
        &mut self,
        s: &Mat<NP, NP>,
        b: &[f64; NP],
        lo: &[f64; NP],
        hi: &[f64; NP],
    ) -> Result<[f64; NP], MheError> {
        let update =
            |e: clarabel::solver::DataUpdateError| MheError::Solve(format!("Clarabel update: {e}"));
        // Upper triangle in CSC order; rows of A: Δp_0, Δp_1, Δp_2, −Δp_0, −Δp_1, −Δp_2.
        self.p.copy_from_slice(&[
            s.0[0][0], s.0[0][1], s.0[1][1], s.0[0][2], s.0[1][2], s.0[2][2],
        ]);
        self.q.copy_from_slice(b);
        self.b
            .copy_from_slice(&[hi[0], hi[1], hi[2], -lo[0], -lo[1], -lo[2]]);
        self.solver.update_P(&self.p).map_err(update)?;
        self.solver.update_q(&self.q).map_err(update)?;
        self.solver.update_b(&self.b).map_err(update)?;
        self.solver.solve();
        let x = clarabel_result(&self.solver)?;
        Ok([x[0], x[1], x[2]])
    }
}

impl std::fmt::Debug for FullQp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "FullQp({} stages)", self.stages)
    }
}

/// The whole MHE QP for Clarabel: variables `(Δx_0..Δx_{n}, Δp)`, `P = JᵀJ` (upper
/// triangle of the block-tridiagonal-with-border pattern), bounds on `Δp`.
struct FullQp {
    stages: usize,
    solver: DefaultSolver<f64>,
    pattern: Pattern,
    values: Vec<f64>,
    nzval: Vec<f64>,
    q: Vec<f64>,
    b: Vec<f64>,
}

impl FullQp {
    fn new(stages: usize, tol: f64) -> Result<FullQp, MheError> {
        let nv = stages * NX + NP;
        let mut pattern = Pattern::new(nv, nv);
        for i in 0..stages {
            for r in 0..NX {
                for c in r..NX {
                    pattern.push(i * NX + r, i * NX + c);
                }
            }
            if i + 1 < stages {
                for r in 0..NX {
                    for c in 0..NX {
                        pattern.push(i * NX + r, (i + 1) * NX + c);
                    }
                }
            }
            for r in 0..NX {
                for c in 0..NP {
                    pattern.push(i * NX + r, stages * NX + c);
                }
            }
        }
        for r in 0..NP {
            for c in r..NP {
                pattern.push(stages * NX + r, stages * NX + c);
            }
        }
        pattern.compile();
        let values = vec![0.0; pattern.len()];
        let mut a = Pattern::new(2 * NP, nv);
        for k in 0..NP {
            a.push(2 * k, stages * NX + k);
            a.push(2 * k + 1, stages * NX + k);
        }
        a.compile();
        let a_csc = a.csc(&[1.0, -1.0, 1.0, -1.0, 1.0, -1.0]);
        let mut diag = vec![0.0; pattern.len()];
        // A positive diagonal for the set-up; the values change before every solve.
        let mut idx = 0;
        for i in 0..stages {
            for r in 0..NX {
                for c in r..NX {
                    if r == c {
                        diag[idx] = 1.0;
                    }
                    idx += 1;
                }
            }
            idx += if i + 1 < stages { NX * NX } else { 0 } + NX * NP;
        }
        for r in 0..NP {
            for c in r..NP {
                if r == c {
                    diag[idx] = 1.0;
                }
                idx += 1;
            }
        }
        let p_csc = pattern.csc(&diag);
        let solver = DefaultSolver::new(
            &p_csc,
            &vec![0.0; nv],
            &a_csc,
            &[1.0; 2 * NP],
            &[SupportedConeT::NonnegativeConeT(2 * NP)],
            clarabel_settings(tol)?,
        )
        .map_err(|e| MheError::Solve(format!("Clarabel setup: {e}")))?;
        Ok(FullQp {
            stages,
            solver,
            nzval: vec![0.0; p_csc.nzval.len()],
            pattern,
            values,
            q: vec![0.0; nv],
            b: vec![0.0; 2 * NP],
        })
    }

    fn solve(
        &mut self,
        blocks: &[Blocks],
        hpp: &Mat<NP, NP>,
        gp: &[f64; NP],
        lo: &[f64; NP],
        hi: &[f64; NP],
    ) -> Result<Vec<f64>, MheError> {
        let mut v = 0;
        for (i, b) in blocks.iter().enumerate() {
            for r in 0..NX {
                for c in r..NX {
                    self.values[v] = 0.5 * (b.d.0[r][c] + b.d.0[c][r]);
                    v += 1;
                }
            }
            if i + 1 < self.stages {
                for r in 0..NX {
                    for c in 0..NX {
                        self.values[v] = b.o.0[r][c];
                        v += 1;
                    }
                }
            }
            for r in 0..NX {
                for c in 0..NP {
                    self.values[v] = b.c.0[c][r];
                    v += 1;
                }
            }
            self.q[i * NX..(i + 1) * NX].copy_from_slice(&b.g);
        }
        for r in 0..NP {
            for c in r..NP {
                self.values[v] = 0.5 * (hpp.0[r][c] + hpp.0[c][r]);
                v += 1;
            }
        }
        self.q[self.stages * NX..].copy_from_slice(gp);
        self.pattern.scatter(&self.values, &mut self.nzval);
        let update =
            |e: clarabel::solver::DataUpdateError| MheError::Solve(format!("Clarabel update: {e}"));
        self.b
            .copy_from_slice(&[hi[0], -lo[0], hi[1], -lo[1], hi[2], -lo[2]]);
        self.solver.update_P(&self.nzval).map_err(update)?;
        self.solver.update_q(&self.q).map_err(update)?;
        self.solver.update_b(&self.b).map_err(update)?;
        self.solver.solve();
        clarabel_result(&self.solver)
    }
}

fn slip(p: &[f64; NP]) -> SlipParams {
    SlipParams {
        x_icr: p[0],
        mu_s: p[1],
        mu_l: p[2],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::mpc::peer::{self, DT, MheData, N_SIM, P_TRUE_MHE};

    fn data() -> MheData {
        peer::mhe_data(1).unwrap()
    }

    /// A sample of the peer's data set: pose, gyro and encoders at `k`.
    fn sample(d: &MheData, k: usize) -> Sample {
        let y = d.ys[k];
        Sample {
            pose: Some(TimedPose {
                time: k as f64 * DT,
                pose: [y[0], y[1], y[2]],
            }),
            gyro: Some(y[3]),
            encoders: Some([y[4], y[5], y[6], y[7]]),
            ..Sample::default()
        }
    }

    /// Run the MHE over the data set; `edit` may change each sample. Returns the
    /// position errors from `k = N` on (as the peer) and the estimator.
    fn run(
        settings: MheSettings,
        d: &MheData,
        edit: impl Fn(usize, &mut Sample),
    ) -> (Vec<f64>, Mhe) {
        let n = settings.horizon;
        let mut mhe = Mhe::new(peer::model(), settings).unwrap();
        let mut err = Vec::new();
        for k in 0..=N_SIM {
            let mut s = sample(d, k);
            edit(k, &mut s);
            let u = if k > 0 { d.us[k - 1] } else { [0.0; 4] };
            let e = mhe.update(k as f64 * DT, &u, &s);
            if k >= n {
                err.push((e.x[0] - d.xs[k][0]).hypot(e.x[1] - d.xs[k][1]));
            }
        }
        (err, mhe)
    }

    fn rms(e: &[f64]) -> f64 {
        (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt()
    }

    #[test]
    fn estimates_the_state_and_the_slip_parameters_like_the_peer() {
        // The peer (one noise draw): position RMS 0.0084 m (raw measurements
        // 0.0285 m), final |p − p_true| = (0.0079, 0.0000, 0.0033). The parameter
        // errors depend on the draw: compare their mean over four draws.
        let mut mean = [0.0; 3];
        for seed in 1..=4 {
            let d = peer::mhe_data(seed).unwrap();
            let (err, mhe) = run(MheSettings::default(), &d, |_, _| {});
            assert!(rms(&err) < 0.01, "seed {seed}: position rms {}", rms(&err));
            assert_eq!(mhe.stats().rejected, 0);
            assert_eq!(mhe.stats().failures, 0);
            let p = mhe.estimate().p;
            mean[0] += (p.x_icr - P_TRUE_MHE.x_icr).abs() / 4.0;
            mean[1] += (p.mu_s - P_TRUE_MHE.mu_s).abs() / 4.0;
            mean[2] += (p.mu_l - P_TRUE_MHE.mu_l).abs() / 4.0;
        }
        assert!(
            mean[0] < 0.01 && mean[1] < 0.005 && mean[2] < 0.01,
            "{mean:?}"
        );
    }

    #[test]
    fn the_structured_solution_is_clarabels() {
        let d = data();
        let (a, ma) = run(MheSettings::default(), &d, |_, _| {});
        let full = MheSettings {
            qp: QpStrategy::Clarabel,
            ..MheSettings::default()
        };
        let (b, mb) = run(full, &d, |_, _| {});
        assert!(mb.stats().clarabel > 0);
        for (x, y) in a.iter().zip(&b) {
            assert!((x - y).abs() < 1e-6, "{x} vs {y}");
        }
        let (pa, pb) = (ma.estimate().p, mb.estimate().p);
        assert!((pa.x_icr - pb.x_icr).abs() < 1e-6 && (pa.mu_l - pb.mu_l).abs() < 1e-6);
    }

    #[test]
    fn a_dropout_of_several_seconds_is_bridged_and_poses_are_taken_back() {
        let d = data();
        // No pose from 3 s to 6 s.
        let (err, mhe) = run(MheSettings::default(), &d, |k, s| {
            if (60..120).contains(&k) {
                s.pose = None;
            }
        });
        let during = &err[60 - 20..120 - 20];
        let after = &err[140 - 20..];
        assert!(
            during.iter().all(|e| *e < 0.15),
            "dead reckoning drifts: {:.3}",
            during.iter().fold(0.0f64, |m, v| m.max(*v))
        );
        assert!(rms(after) < 0.012, "recovers: {}", rms(after));
        assert_eq!(mhe.stats().rejected, 0, "the returning poses are accepted");
    }

    #[test]
    fn garbage_is_rejected_and_counted() {
        let d = data();
        let (clean, _) = run(MheSettings::default(), &d, |_, _| {});
        let (err, mhe) = run(MheSettings::default(), &d, |k, s| match k % 10 {
            3 => s.gyro = Some(f64::NAN),
            5 => {
                if let Some(p) = &mut s.pose {
                    p.pose[0] += 5.0; // a 5 m jump
                }
            }
            7 => s.encoders = Some([1e9, 0.0, 0.0, 0.0]),
            9 => {
                if let Some(p) = &mut s.pose {
                    p.time = f64::NAN;
                }
            }
            _ => {}
        });
        assert_eq!(mhe.stats().rejected, 4 * 20, "{:?}", mhe.stats());
        assert!(
            rms(&err) < rms(&clean) * 1.3,
            "{} vs {}",
            rms(&err),
            rms(&clean)
        );
    }

    #[test]
    fn late_and_intermittent_poses_go_to_the_stage_they_describe() {
        let d = data();
        // The pose of sample k arrives 2 samples late, and only every 4th one.
        let (err, mhe) = run(MheSettings::default(), &d, |k, s| {
            s.pose = (k >= 2 && (k - 2) % 4 == 0).then(|| {
                let y = d.ys[k - 2];
                TimedPose {
                    time: (k - 2) as f64 * DT,
                    pose: [y[0], y[1], y[2]],
                }
            });
            if k < 2 {
                s.pose = Some(TimedPose {
                    time: 0.0,
                    pose: [d.ys[0][0], d.ys[0][1], d.ys[0][2]],
                });
            }
        });
        assert!(rms(&err) < 0.015, "rms {}", rms(&err));
        assert_eq!(mhe.stats().rejected, 0);
    }

    #[test]
    fn parameter_bounds_hold_with_clarabel_when_active() {
        let d = data();
        // x_0 is truly 0.06: bound it at 0.04.
        let settings = MheSettings {
            p_ub: [0.04, 0.5, 1.5],
            ..MheSettings::default()
        };
        let (_, mhe) = run(settings, &d, |_, _| {});
        let p = mhe.estimate().p;
        assert!(p.x_icr <= 0.04 + 1e-9 && p.x_icr > 0.039, "{p:?}");
        assert!(
            mhe.stats().clarabel > 0,
            "the bound was active: {:?}",
            mhe.stats()
        );
    }

    #[test]
    fn visual_odometry_narrows_the_drift_of_a_dropout() {
        let d = data();
        // No pose from 3 s to 6 s, and a model that is wrong: the slip parameters
        // held at the nominal (0.03, 0.05, 0.5) while the plant has (0.06, 0.07,
        // 0.6). With visual odometry: the motion over the last two samples (from the
        // true states, as a perfect odometry would measure it).
        let wrong = MheSettings {
            sigma_p: [1e-5; 3],
            ..MheSettings::default()
        };
        let drop = |k: usize| (60..120).contains(&k);
        let (without, _) = run(wrong.clone(), &d, |k, s| {
            if drop(k) {
                s.pose = None;
            }
        });
        let (with, mhe) = run(wrong, &d, |k, s| {
            if drop(k) {
                s.pose = None;
            }
            if k >= 2 && k % 2 == 0 {
                let (a, b) = (d.xs[k - 2], d.xs[k]);
                let (sn, c) = a[2].sin_cos();
                let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                s.motion = Some(Motion {
                    from: (k - 2) as f64 * DT,
                    to: k as f64 * DT,
                    delta: [c * dx + sn * dy, -sn * dx + c * dy, b[2] - a[2]],
                });
            }
        });
        let gap = |e: &[f64]| rms(&e[60 - 20..120 - 20]);
        assert!(
            gap(&with) < 0.5 * gap(&without),
            "{} vs {}",
            gap(&with),
            gap(&without)
        );
        assert_eq!(mhe.stats().rejected, 0);
        // A motion with a non-finite part or an absurd speed is rejected.
        let mut m = Mhe::new(peer::model(), MheSettings::default()).unwrap();
        let mut s0 = sample(&d, 0);
        m.update(0.0, &[0.0; 4], &s0);
        s0.motion = Some(Motion {
            from: 0.0,
            to: 0.05,
            delta: [f64::NAN, 0.0, 0.0],
        });
        m.update(0.05, &[0.0; 4], &s0);
        s0.motion = Some(Motion {
            from: 0.05,
            to: 0.1,
            delta: [5.0, 0.0, 0.0],
        });
        m.update(0.1, &[0.0; 4], &s0);
        assert_eq!(m.stats().rejected, 2);
    }

    /// An IMU heading that drifts away from the map's (an offset of 0.5 rad growing
    /// by 0.02 rad/s, as an integrated gyroscope with a bias does) must not pull
    /// the estimate: only its increments count. Taken as an absolute heading (the
    /// cause of Rex's long-mission divergence) it pulled the heading estimate by
    /// about a tenth of the offset, and gated the poses out once it grew.
    #[test]
    fn a_drifting_imu_heading_does_not_pull_the_estimate() {
        let d = data();
        let offset = |k: usize| 0.5 + 0.02 * k as f64 * DT;
        // Half of the poses lost: the IMU matters more.
        let (without, _) = run(MheSettings::default(), &d, |k, s| {
            if k % 2 == 1 {
                s.pose = None;
            }
        });
        let (err, mhe) = run(MheSettings::default(), &d, |k, s| {
            s.heading = Some(wrap(d.xs[k][2] + offset(k)));
            if k % 2 == 1 {
                s.pose = None;
            }
        });
        let phi_err = wrap(mhe.estimate().x[2] - d.xs[N_SIM][2]).abs();
        assert!(phi_err < 0.02, "heading error {phi_err}");
        assert!(
            rms(&err) < 1.1 * rms(&without),
            "position rms {} vs {} without the IMU heading",
            rms(&err),
            rms(&without)
        );
        assert_eq!(mhe.stats().rejected, 0, "{:?}", mhe.stats());
    }

    /// The increments are what the IMU heading knows: with them the estimate rides
    /// out a dropout better than with the gyroscope's samples alone.
    #[test]
    fn imu_heading_increments_narrow_the_drift_of_a_dropout() {
        let d = data();
        let drop = |k: usize| (60..120).contains(&k);
        let (without, _) = run(MheSettings::default(), &d, |k, s| {
            if drop(k) {
                s.pose = None;
            }
        });
        let (with, mhe) = run(MheSettings::default(), &d, |k, s| {
            // Offset from the map heading, and exact increments.
            s.heading = Some(wrap(d.xs[k][2] + 1.0));
            if drop(k) {
                s.pose = None;
            }
        });
        let gap = |e: &[f64]| rms(&e[60 - 20..120 - 20]);
        assert!(
            gap(&with) < gap(&without),
            "{} vs {}",
            gap(&with),
            gap(&without)
        );
        assert_eq!(mhe.stats().rejected, 0);
    }

    /// A robot carried 1.5 m away (or an estimate gone wrong): the poses are gated
    /// out, and after `relocalise_after` seconds the window restarts from them.
    #[test]
    fn an_estimate_the_poses_contradict_for_long_is_relocalised() {
        let d = data();
        let kidnap = |k: usize| if k >= 100 { 1.5 } else { 0.0 };
        let (_, mhe) = run(MheSettings::default(), &d, |k, s| {
            if let Some(p) = &mut s.pose {
                p.pose[0] += kidnap(k);
            }
        });
        let stats = mhe.stats();
        assert_eq!(stats.relocalisations, 1, "{stats:?}");
        // Rejected for one second (20 samples), then believed again.
        assert!((19..=22).contains(&stats.rejected_poses), "{stats:?}");
        let x = mhe.estimate().x;
        let truth = d.xs[N_SIM];
        let e = (x[0] - truth[0] - 1.5).hypot(x[1] - truth[1]);
        assert!(e < 0.03, "{e}");
    }

    #[test]
    fn nothing_is_estimated_before_the_first_pose() {
        let mut mhe = Mhe::new(peer::model(), MheSettings::default()).unwrap();
        let e = mhe.update(
            0.0,
            &[0.0; 4],
            &Sample {
                gyro: Some(0.1),
                ..Sample::default()
            },
        );
        assert!(!e.localised);
        assert_eq!(mhe.stats().waiting, 1);
        let bad = MheSettings {
            p_prior: [0.3, 0.05, 0.5],
            ..MheSettings::default()
        };
        assert!(matches!(
            Mhe::new(peer::model(), bad),
            Err(MheError::Settings(_))
        ));
    }
}
