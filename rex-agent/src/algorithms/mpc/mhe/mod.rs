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
//!
//! This file holds the settings, the window and how measurements join it;
//! `assemble.rs` one Gauss–Newton step (the normal equations); `solve.rs` their
//! solution (block Cholesky and Schur complement, Clarabel's QPs).

use std::collections::VecDeque;

use serde::{Deserialize, Serialize};

use super::linalg::Mat;
use super::nmpc::QpStrategy;
use crate::algorithms::geometry::wrap;
use crate::world::model::{Jacobians, Reduced, SlipParams, State5, Torques};

mod assemble;
mod solve;

use solve::{BoxQp, FullQp};

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
}

fn slip(p: &[f64; NP]) -> SlipParams {
    SlipParams {
        x_icr: p[0],
        mu_s: p[1],
        mu_l: p[2],
    }
}

#[cfg(test)]
mod tests;
