//! Moving-horizon estimation of the state and the model's parameters (the paper's
//! section 3.2; notes §3.2), the problem of `peers/casadi_mhe.py` on any
//! prediction model ([`Dynamics`]): the peers' reduced model with its slip
//! parameters `(x_0, μ_s, μ_l)` ([`ReducedMhe`]), or the lateral-slip model with
//! the ground's friction `(μ_x, μ_y, μ_r)` ([`LateralMhe`], Rex's):
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
//! * encoder rates as the model predicts them ([`Dynamics::encoder_rate`]):
//!   `θ̇_i = (v − d_iy ω) / r` on the reduced model; with the longitudinal slip
//!   of the traction each wheel transmits on the lateral-slip model, which is
//!   how the encoders tell the ground's `μ_x` (a wheel whose torque the model
//!   says the ground cannot take is left out, and so is a reading whose slip
//!   no `μ_x` explains: [`Dynamics::encoder_usable`]);
//! * wheel loads (force sensors): static loads plus the load transfer of the
//!   accelerations the model predicts under the torques of the interval before.
//!
//! Exteroceptive measurements (poses) are gated: an innovation beyond
//! `gate · σ` (widened by `drift_rate` per second without an accepted pose) is
//! rejected; any non-finite or implausible measurement is rejected. All are counted.
//! An estimate that disagrees with the map poses for `relocalise_after` seconds is
//! wrong, not the poses: the window restarts from the latest pose (a relocalisation,
//! counted in [`MheStats::relocalisations`]), keeping the parameters.
//!
//! **Solution.** Gauss–Newton with exact sensitivities, one iteration per sample
//! (real-time iteration; more at start). The normal equations are block-tridiagonal
//! in the states with a border for `p`: a block Cholesky factorisation of the states'
//! part and the `NP × NP` Schur complement of `p` solve them exactly in `O(N)` (on
//! nalgebra's fixed-size types). When the step would leave the parameter bounds,
//! the QP reduced to `Δp` (a box QP in `NP` variables, exact after eliminating the
//! states) is solved by Clarabel.
//! [`QpStrategy::Clarabel`] instead gives Clarabel the whole QP in `(Δx, Δp)`.
//!
//! This file holds the settings, the window and how measurements join it;
//! `assemble.rs` one Gauss–Newton step (the normal equations); `solve.rs` their
//! solution (block Cholesky and Schur complement, Clarabel's QPs).

use std::collections::VecDeque;

use super::nmpc::QpStrategy;
use crate::model::{
    Dynamics, EarlierReading, Friction, Lateral, Matrix, Measured, NOT_READ, NU, Reduced,
    SlipParams, Torques, Vector, WheelSpin,
};

mod assemble;
mod attach;
mod solve;

use solve::{BoxQp, FullQp};

/// The MHE on the peers' reduced model.
pub type ReducedMhe = Mhe<Reduced, 5, 3>;
/// The MHE on the lateral-slip model.
pub type LateralMhe = Mhe<Lateral, 6, 3>;

/// Settings of the MHE for a model of `NX` states and `NP` parameters; the
/// reduced model's defaults are the peer's (`casadi_mhe.py`) where it has them.
#[derive(Clone, Debug, PartialEq)]
pub struct MheSettings<const NX: usize, const NP: usize> {
    /// Window length `N` (intervals).
    pub horizon: usize,
    /// Interval \[s\].
    pub dt: f64,
    /// RK4 steps per interval.
    pub rk4_steps: usize,
    /// Process noise standard deviations per interval, per state component.
    pub sigma_w: [f64; NX],
    /// Arrival cost on `x_0`.
    pub sigma_x0: [f64; NX],
    /// Arrival cost on `p`.
    pub sigma_p: [f64; NP],
    /// Initial parameter guess.
    pub p_prior: [f64; NP],
    /// Lower parameter bounds.
    pub p_lb: [f64; NP],
    /// Upper parameter bounds.
    pub p_ub: [f64; NP],
    /// Map pose position noise \[m\].
    pub sigma_pos: f64,
    /// Map pose heading noise \[rad\].
    pub sigma_phi: f64,
    /// Gyroscope noise \[rad/s\].
    pub sigma_gyro: f64,
    /// Noise of the IMU heading's increment between two consecutive stages \[rad\]
    /// (its absolute value is not used: it drifts with the gyroscope's bias).
    pub sigma_heading_step: f64,
    /// Encoder rate noise \[rad/s\].
    pub sigma_encoder: f64,
    /// Force sensor noise \[N\] (0 leaves the loads out).
    pub sigma_load: f64,
    /// Visual odometry: noise of the displacement between consecutive stages \[m\].
    pub sigma_vo_step: f64,
    /// Visual odometry: noise of the turn between consecutive stages \[rad\].
    pub sigma_vo_turn: f64,
    /// Plausible speed \[m/s\] (measurements beyond 3 times are rejected).
    pub max_speed: f64,
    /// Plausible turn rate \[rad/s\] (the same).
    pub max_yaw_rate: f64,
    /// Gate on pose innovations, in standard deviations.
    pub gate: f64,
    /// Widening of the pose gate per second without an accepted pose \[m/s\].
    pub drift_rate: f64,
    /// Poses rejected by the gate for this long \[s\] restart the window from the
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

impl<const NX: usize, const NP: usize> MheSettings<NX, NP> {
    /// The settings that do not depend on the model, with its noise, arrival
    /// cost and parameter set.
    pub fn with_model(
        sigma_w: [f64; NX],
        sigma_x0: [f64; NX],
        sigma_p: [f64; NP],
        p_prior: [f64; NP],
        p_lb: [f64; NP],
        p_ub: [f64; NP],
    ) -> MheSettings<NX, NP> {
        MheSettings {
            horizon: 20,
            dt: 0.05,
            rk4_steps: 2,
            sigma_w,
            sigma_x0,
            sigma_p,
            p_prior,
            p_lb,
            p_ub,
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

impl Default for MheSettings<5, 3> {
    /// The peer's, on the reduced model: parameters `(x_0, μ_s, μ_l)` from
    /// `(0.03, 0.05, 0.5)`.
    fn default() -> Self {
        MheSettings::with_model(
            [0.002, 0.002, 0.002, 0.01, 0.02],
            [0.05, 0.05, 0.05, 0.1, 0.1],
            [0.05, 0.05, 0.2],
            SlipParams::NOMINAL.to_array(),
            [-0.15, 0.0, 0.05],
            [0.15, 0.5, 1.5],
        )
    }
}

impl Default for MheSettings<6, 3> {
    /// On the lateral-slip model: the ground's `(μ_x, μ_y, μ_r)` from concrete's,
    /// within `[0.02, 1.5] × [0.02, 1.5] × [0, 0.3]`; the lateral velocity's
    /// process noise as the forward speed's; three RK4 steps per interval.
    fn default() -> Self {
        MheSettings {
            rk4_steps: 3,
            ..MheSettings::with_model(
                [0.002, 0.002, 0.002, 0.01, 0.01, 0.02],
                [0.05, 0.05, 0.05, 0.1, 0.1, 0.1],
                [0.2, 0.2, 0.05],
                Friction::CONCRETE.to_array(),
                [0.02, 0.02, 0.0],
                [1.5, 1.5, 0.3],
            )
        }
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

/// A pose on the map and the time it describes \[s\].
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
    /// Start time \[s\].
    pub from: f64,
    /// End time \[s\].
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
    /// Gyroscope yaw rate \[rad/s\].
    pub gyro: Option<f64>,
    /// IMU heading \[rad\]: only its change from the previous sample's is used.
    pub heading: Option<f64>,
    /// Encoder rates \[rad/s\].
    pub encoders: Option<[f64; 4]>,
    /// Wheel loads \[N\].
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
    /// Of those, encoder readings gated out (a wheel spinning far beyond what
    /// the model predicts for it; counted per wheel).
    pub rejected_encoders: u64,
    /// Restarts of the window from a map pose after `relocalise_after` seconds of
    /// rejected poses.
    pub relocalisations: u64,
    /// Samples before the first pose (nothing to anchor the estimate).
    pub waiting: u64,
    /// Windows dropped because their newest state was implausible (counted in
    /// `failures` too); each restarts from the next pose.
    pub restarts: u64,
    /// Failed steps (the previous estimate was propagated instead).
    pub failures: u64,
}

/// What the estimator believes now.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MheEstimate<const NX: usize, const NP: usize> {
    /// The state of the newest sample.
    pub x: [f64; NX],
    /// The parameters.
    pub p: [f64; NP],
    /// Whether a pose anchored the estimate.
    pub localised: bool,
}

/// One stage of the window.
#[derive(Clone, Copy, Debug)]
struct Stage<const NX: usize> {
    t: f64,
    x: Vector<NX>,
    /// Torques applied from this stage to the next.
    u: Vector<NU>,
    pose: Option<[f64; 3]>,
    /// Standard deviations of `pose` (position, heading).
    pose_sigma: [f64; 2],
    gyro: Option<f64>,
    heading: Option<f64>,
    encoders: Option<[f64; 4]>,
    /// The wheels' rates read, gated or not (NaN where not read): the
    /// direction of their rolling resistance and, with a neighbour stage's,
    /// their acceleration ([`Dynamics::linearise_spinning`]).
    spin: [f64; 4],
    loads: Option<[f64; 4]>,
    /// The motion `(dx, dy, dφ)` to the next stage in this stage's frame, from
    /// visual odometry.
    rel: Option<[f64; 3]>,
}

impl<const NX: usize> Default for Stage<NX> {
    fn default() -> Self {
        Stage {
            t: 0.0,
            x: Vector::zeros(),
            u: Vector::zeros(),
            pose: None,
            pose_sigma: [0.0; 2],
            gyro: None,
            heading: None,
            encoders: None,
            spin: NOT_READ,
            loads: None,
            rel: None,
        }
    }
}

/// Blocks of the normal equations.
#[derive(Clone, Copy, Debug)]
struct Blocks<const NX: usize, const NP: usize> {
    d: Matrix<NX, NX>,
    /// Coupling with the next stage (block `(i, i+1)`).
    o: Matrix<NX, NX>,
    /// Coupling with `p` (block `(p, i)`, `NP × NX`).
    c: Matrix<NP, NX>,
    g: Vector<NX>,
}

impl<const NX: usize, const NP: usize> Default for Blocks<NX, NP> {
    fn default() -> Self {
        Blocks {
            d: Matrix::zeros(),
            o: Matrix::zeros(),
            c: Matrix::zeros(),
            g: Vector::zeros(),
        }
    }
}

/// The moving-horizon estimator on the prediction model `M`.
#[derive(Debug)]
pub struct Mhe<M: Dynamics<NX, NP>, const NX: usize, const NP: usize> {
    model: M,
    s: MheSettings<NX, NP>,
    window: VecDeque<Stage<NX>>,
    p: Vector<NP>,
    /// Arrival cost anchors.
    x_bar: Vector<NX>,
    p_bar: Vector<NP>,
    last_pose_time: Option<f64>,
    /// When the current run of gated-out poses began (`None` after an accepted one).
    rejecting_since: Option<f64>,
    blocks: Vec<Blocks<NX, NP>>,
    hpp: Matrix<NP, NP>,
    gp: Vector<NP>,
    /// Block Cholesky factors of the states' part (`L_i`, lower), the blocks
    /// `E_i = L_i⁻¹ O_i`, and the solutions for the gradient and for the
    /// coupling columns.
    chol: Vec<Matrix<NX, NX>>,
    e: Vec<Matrix<NX, NX>>,
    sol_g: Vec<Vector<NX>>,
    sol_c: Vec<Matrix<NX, NP>>,
    qp: Option<BoxQp>,
    full: Option<FullQp>,
    /// The information on each parameter from the window's data at the last
    /// structured step ([`Mhe::information`]).
    information: Vector<NP>,
    /// The newest sample's encoder innovation ([`Mhe::innovation`]).
    innovation: Option<Innovation>,
    stats: MheStats,
}

/// How far the newest sample's encoder readings were from what the model
/// predicted before they were fitted (the prediction from the previous
/// estimate), in units of their standard deviation; and how many were left out
/// as spinning. (A reading of a wheel the model itself predicts beyond its
/// bound is in neither count.)
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Innovation {
    /// The mean of the normalised residuals (predicted − read); 0 without
    /// a reading compared.
    pub mean: f64,
    /// The mean of their squares; 0 without a reading compared.
    pub mean_square: f64,
    /// The readings compared.
    pub readings: usize,
    /// The readings left out as a wheel spinning beyond what any friction
    /// explains (gated when they arrived).
    pub spinning: usize,
}

impl<M: Dynamics<NX, NP>, const NX: usize, const NP: usize> Mhe<M, NX, NP> {
    /// An estimator for `model`.
    pub fn new(model: M, settings: MheSettings<NX, NP>) -> Result<Self, MheError> {
        settings.validate()?;
        let n = settings.horizon;
        Ok(Mhe {
            model,
            window: VecDeque::with_capacity(n + 2),
            p: Vector::from(settings.p_prior),
            x_bar: Vector::zeros(),
            p_bar: Vector::from(settings.p_prior),
            last_pose_time: None,
            rejecting_since: None,
            blocks: vec![Blocks::default(); n + 1],
            hpp: Matrix::zeros(),
            gp: Vector::zeros(),
            chol: vec![Matrix::zeros(); n + 1],
            e: vec![Matrix::zeros(); n + 1],
            sol_g: vec![Vector::zeros(); n + 1],
            sol_c: vec![Matrix::zeros(); n + 1],
            qp: None,
            full: None,
            information: Vector::zeros(),
            innovation: None,
            stats: MheStats::default(),
            s: settings,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &MheSettings<NX, NP> {
        &self.s
    }

    /// The prediction model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The counters.
    pub fn stats(&self) -> MheStats {
        self.stats
    }

    /// Change the arrival cost's standard deviations of the parameters (how far
    /// each sample may move them: loose while nothing is known of them, tight
    /// once they are). Refused unless each is positive and finite.
    pub fn set_sigma_p(&mut self, sigma_p: [f64; NP]) -> Result<(), MheError> {
        if sigma_p.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(MheError::Settings(
                "sigma_p must be positive and finite".into(),
            ));
        }
        self.s.sigma_p = sigma_p;
        Ok(())
    }

    /// How much the window's data say about each parameter: the diagonal of
    /// the Gauss–Newton information of `p` with the states eliminated (the
    /// Schur complement of the normal equations) less the arrival cost's part,
    /// `1/σ²` of what the data alone would pin each parameter to, the others
    /// held. Zero while the platform stands still (nothing is learnt of the
    /// ground then); from the last [`QpStrategy::Structured`] step.
    pub fn information(&self) -> [f64; NP] {
        self.information.into()
    }

    /// How far the fitted states are from the map poses attached in the last
    /// `span` seconds of the window: the largest distance \[m\] (position only).
    /// The poses' own noise aside, a fit that cannot follow them (a model the
    /// data contradict) shows here. `None` without such a pose.
    pub fn pose_residual(&self, span: f64) -> Option<f64> {
        let newest = self.window.back()?.t;
        self.window
            .iter()
            .filter(|s| s.t >= newest - span)
            .filter_map(|s| s.pose.map(|p| (p[0] - s.x[0]).hypot(p[1] - s.x[1])))
            .reduce(f64::max)
    }

    /// The newest sample's encoder readings against the model's prediction
    /// before the fit: a change of the parameters (a new ground) shows here as
    /// residuals the noise does not explain. `None` before a second sample or
    /// without encoder readings.
    pub fn innovation(&self) -> Option<Innovation> {
        self.innovation
    }

    /// What stage `i`'s encoders should read with the parameters `p`: under
    /// the torques of the interval that ends there, from the slips the
    /// readings of the stage before showed ([`Dynamics::encoder_rates_settling`];
    /// the first stage's as settled, without an earlier reading), the
    /// rolling resistance opposing the spin read at the stage.
    fn encoder_prediction(&self, i: usize, p: &Vector<NP>) -> [Option<Measured<NX, NP>>; 4] {
        let st = &self.window[i];
        let (before, u) = match i.checked_sub(1).map(|k| &self.window[k]) {
            Some(b) => (
                EarlierReading {
                    x: b.x,
                    rates: b.encoders.unwrap_or(NOT_READ),
                    h: st.t - b.t,
                },
                b.u,
            ),
            None => (
                EarlierReading {
                    x: st.x,
                    rates: NOT_READ,
                    h: 0.0,
                },
                st.u,
            ),
        };
        self.model
            .encoder_rates_settling(&before, &st.x, &u, p, &st.spin)
    }

    fn encoder_innovation(&self) -> Option<Innovation> {
        let n = self.window.len().checked_sub(2)?;
        let last = &self.window[n + 1];
        let e = last.encoders?;
        let (mut sum, mut square, mut readings, mut spinning) = (0.0, 0.0, 0, 0);
        let predicted = self.encoder_prediction(n + 1, &self.p);
        for (reading, m) in e.iter().zip(predicted) {
            if !reading.is_finite() {
                spinning += 1;
                continue;
            }
            if let Some(m) = m {
                let r = (m.value - reading) / self.s.sigma_encoder.hypot(m.sigma);
                sum += r;
                square += r * r;
                readings += 1;
            }
        }
        let n = readings.max(1) as f64;
        (readings + spinning > 0).then_some(Innovation {
            mean: sum / n,
            mean_square: square / n,
            readings,
            spinning,
        })
    }

    /// The current estimate.
    pub fn estimate(&self) -> MheEstimate<NX, NP> {
        MheEstimate {
            x: self.window.back().map_or([0.0; NX], |s| s.x.into()),
            p: self.p.into(),
            localised: !self.window.is_empty(),
        }
    }

    /// The estimate of the state at time `t` inside the window (nearest stage).
    pub fn state_at(&self, t: f64) -> Option<[f64; NX]> {
        self.nearest(t)
            .map(|i| self.shifted(&self.window[i].x, t - self.window[i].t).into())
    }

    /// The state `x` moved along its own velocity by `dt` seconds (first order):
    /// measurements are rarely taken at a stage's instant, and 25 ms at 0.5 m/s
    /// are 12 mm.
    fn shifted(&self, x: &Vector<NX>, dt: f64) -> Vector<NX> {
        let [vx, vy] = self.model.world_velocity(x, &self.p);
        let mut out = *x;
        out[0] += dt * vx;
        out[1] += dt * vy;
        out[2] += dt * x[M::YAW_RATE];
        out
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
    pub fn update(&mut self, t: f64, u: &Torques, m: &Sample) -> MheEstimate<NX, NP> {
        self.stats.samples += 1;
        self.innovation = None;
        let u = Vector::from(u.map(|v| if v.is_finite() { v } else { 0.0 }));
        if self.window.is_empty() {
            return self.start(t, m);
        }
        // Predict the new stage and shift the window.
        let Some(last) = self.window.back_mut() else {
            return self.estimate();
        };
        last.u = u;
        let prev = last.x;
        let spin = WheelSpin {
            start: last.spin,
            end: NOT_READ,
        };
        let x_new = self
            .model
            .rk4_spinning(&prev, &u, &self.p, self.s.dt, self.s.rk4_steps, &spin);
        let x_new = if x_new.iter().all(|v| v.is_finite()) {
            x_new
        } else {
            prev
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
        self.innovation = self.encoder_innovation();
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
        if !self.plausible() {
            // The window explains its measurements with a motion no platform
            // makes (wheels spinning in place read as a spin of the body, on a
            // platform too heavy to move): a failure, and the window restarts
            // from the next pose rather than drifting on.
            self.stats.failures += 1;
            self.stats.restarts += 1;
            self.window.clear();
            self.rejecting_since = None;
        }
        self.estimate()
    }

    /// Whether the newest stage's velocities are ones a platform within the
    /// settings' limits could have (three times `max_speed`, `max_yaw_rate`, as
    /// for the measurements) and its pose is finite.
    fn plausible(&self) -> bool {
        let Some(last) = self.window.back() else {
            return true;
        };
        let [vx, vy] = self.model.world_velocity(&last.x, &self.p);
        last.x.iter().all(|v| v.is_finite())
            && vx.hypot(vy) <= 3.0 * self.s.max_speed
            && last.x[M::YAW_RATE].abs() <= 3.0 * self.s.max_yaw_rate
    }

    /// The first sample with a pose starts the window; before it, samples wait.
    fn start(&mut self, t: f64, m: &Sample) -> MheEstimate<NX, NP> {
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
                self.model.platform().wheel_radius * e.iter().sum::<f64>() / 4.0
            });
        // The pose describes an earlier time (it is late): moved to now, it is
        // the first stage's measurement.
        let x = self.model.state_at_pose(pose.pose, v, w, &self.p);
        self.x_bar = self.shifted(&x, t - pose.time);
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
}
