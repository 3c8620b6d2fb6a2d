//! Nonlinear model predictive tracking control (the paper's section 3.2; notes §3.1).
//!
//! The optimal control problem, exactly as `peers/casadi_nmpc.py` poses it:
//!
//! ```text
//! min  Σ_{k<N} (x_k − x_d,k)ᵀ Q (x_k − x_d,k) + u_kᵀ R u_k  +  (x_N − x_d,N)ᵀ Q_N (x_N − x_d,N)
//! s.t. x_0 = x̂,  x_{k+1} = F(x_k, u_k, p),  |τ_i| ≤ τ_max,i,  |v_k| ≤ v_max,  |ω_k| ≤ ω_max (k ≥ 1)
//! ```
//!
//! with `F` a prediction model ([`Dynamics`]) integrated by RK4 over each interval
//! (direct multiple shooting): the peers' reduced model ([`ReducedNmpc`]) for the
//! comparisons with them, the lateral-slip model ([`LateralNmpc`]) for Rex. It is
//! solved by Gauss–Newton SQP: linearise `F` around the current iterate with exact
//! sensitivities ([`Dynamics::rk4_sensitivities`]), solve the QP in `Δw`, take the
//! full step.
//!
//! * **Real-time iteration** ([`Nmpc::prepare`] then [`Nmpc::feedback`]): one QP per
//!   sample. The preparation shifts the previous solution one stage, linearises and
//!   runs the backward Riccati recursion before the measurement is known; the
//!   feedback only sets `Δx_0 = x̂ − x_0` and sweeps forward.
//! * **Converged SQP** ([`Nmpc::solve`]): QPs until the step is below a tolerance,
//!   for cold starts and tests.
//!
//! **How the QP is solved.** The QP has `N (NX + 4)` variables (`Δx_0` is fixed by
//! the measurement; 180 for the peers' problem), `N NX` equality rows and `12 N`
//! inequality rows. Solved by Clarabel (interior point, no warm start) it costs
//! about nine iterations whatever the starting point, more than the whole step's
//! budget. But the inequality rows are rarely active once the platform is on
//! its path. So [`QpStrategy::Structured`] first solves the equality-constrained QP
//! by a Riccati recursion over the stages (linear in `N`, a few microseconds); if
//! that solution satisfies every bound, it *is* the solution of the whole QP (the
//! KKT conditions hold with zero multipliers on the bounds). When a bound would be
//! violated, a primal-dual interior-point method whose Newton steps are the same
//! Riccati recursion with the barrier's diagonal added to the stage weights
//! (`ipm.rs`, as HPIPM does; Mehrotra's predictor-corrector, one factorisation for
//! both solves) solves the QP with its bounds in about seven iterations, in a
//! fraction of Clarabel's time. Clarabel stays the reference the tests compare it
//! with, and the fallback should it not converge: it solves the full sparse QP, on
//! a solver built once whose data are updated in place (`update_q`, `update_A`,
//! `update_b`; the sparsity never changes).
//! Clarabel's defaults are tuned for hard problems; this QP is small and well
//! scaled, so here it runs at tolerance 1e-6 without equilibration and iterative
//! refinement: about half the time of its defaults, with the same closed loop to
//! 1e-6. The measurements behind this paragraph: docs/measurements.md, "The NMPC's
//! QPs".
//! [`QpStrategy::Clarabel`] sends every QP to Clarabel, for comparison.
//!
//! The small dense algebra of the stages (products, the 4 × 4 Cholesky
//! factorisations of the Riccati recursion) is nalgebra's, on fixed-size types.
//!
//! **Faults.** A QP that Clarabel does not solve, a Riccati recursion that meets a
//! non-positive pivot, or non-finite data never panic: the controller applies the
//! shifted previous solution for at most `fallback_steps` samples, then brakes to a
//! stop ([`Status::SafeStop`]) until a QP succeeds again. Every case is counted in
//! [`NmpcStats`].
//!
//! This file holds the settings, the controller, its warm start and its fallbacks;
//! `qp.rs` the QP of one SQP iteration (linearisation, Riccati recursion, Clarabel).

use nalgebra::Cholesky;

use super::spd_cholesky;
use crate::model::{Dynamics, Lateral, Matrix, NU, PlatformParams, Reduced, Torques, Vector};

mod frozen;
mod ipm;
mod offset;
mod qp;

pub use frozen::{ClarabelWorkspace, FrozenQp, QpSolution, SparseQp};
pub use offset::{DisturbanceObserver, DisturbanceSettings};

use ipm::{IpmStart, IpmWork};
use qp::ClarabelQp;

/// The most iterations the structured interior-point method takes on one QP
/// ([`FrozenQp::solve_structured`] too); without convergence by then, Clarabel
/// solves the QP.
pub const IPM_MAX_ITERATIONS: usize = ipm::MAX_ITERATIONS;

/// The NMPC on the peers' reduced model `(X, Y, φ, v, ω)`.
pub type ReducedNmpc = Nmpc<Reduced, 5, 3>;
/// The NMPC on the lateral-slip model `(X, Y, φ, v_x, v_y, ω)`.
pub type LateralNmpc = Nmpc<Lateral, 6, 3>;

/// How the QP of each SQP iteration is solved.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum QpStrategy {
    /// Riccati recursion on the equality-constrained QP; when a bound would be
    /// violated, the interior-point method on the stage structure (Clarabel if
    /// it does not converge). Same solutions, far less time.
    #[default]
    Structured,
    /// Every QP by Clarabel.
    Clarabel,
}

/// Settings of the NMPC for a model of `NX` states; the defaults of the reduced
/// model are the peers' (`casadi_nmpc.py`).
#[derive(Clone, Debug, PartialEq)]
pub struct NmpcSettings<const NX: usize> {
    /// Horizon `N` (shooting intervals).
    pub horizon: usize,
    /// Interval length \[s\].
    pub dt: f64,
    /// RK4 steps per interval.
    pub rk4_steps: usize,
    /// State weights `Q`.
    pub q: [f64; NX],
    /// Terminal weights `Q_N`.
    pub q_terminal: [f64; NX],
    /// Torque weights `R`.
    pub r: [f64; 4],
    /// Torque bound per wheel \[N m\].
    pub torque_max: f64,
    /// Speed bound \[m/s\].
    pub speed_max: f64,
    /// Yaw-rate bound \[rad/s\].
    pub yaw_rate_max: f64,
    /// How QPs are solved.
    pub qp: QpStrategy,
    /// Converged SQP: the most iterations.
    pub sqp_max_iterations: usize,
    /// Converged SQP: stop when `max |Δw|` is below this.
    pub sqp_tolerance: f64,
    /// Clarabel's gap and feasibility tolerances.
    pub qp_tolerance: f64,
    /// Clarabel's equilibration of the data (off: the QP is well scaled).
    pub qp_equilibrate: bool,
    /// Clarabel's iterative refinement of each KKT solve (off: this QP does not
    /// need it, and it costs a large share of a solve).
    pub qp_iterative_refinement: bool,
    /// Clarabel's iteration bound.
    pub qp_max_iterations: u32,
    /// Samples on the shifted previous solution after a failed QP, before braking.
    pub fallback_steps: usize,
    /// Time constant of the safe stop \[s\].
    pub brake_time: f64,
}

impl<const NX: usize> NmpcSettings<NX> {
    /// The settings common to every model, with the state weights `q` (also
    /// terminal).
    pub fn with_weights(q: [f64; NX]) -> NmpcSettings<NX> {
        NmpcSettings {
            horizon: 20,
            dt: 0.05,
            rk4_steps: 2,
            q,
            q_terminal: q,
            r: [1e-3; 4],
            torque_max: 10.0,
            speed_max: 1.5,
            yaw_rate_max: 2.0,
            qp: QpStrategy::Structured,
            sqp_max_iterations: 50,
            sqp_tolerance: 1e-6,
            qp_tolerance: 1e-6,
            qp_equilibrate: false,
            qp_iterative_refinement: false,
            qp_max_iterations: 50,
            fallback_steps: 5,
            brake_time: 0.3,
        }
    }

    /// Check the settings: every number finite, weights non-negative, `R` and the
    /// bounds positive, a horizon and a step.
    pub fn validate(&self) -> Result<(), NmpcError> {
        let bad = |what: &str| Err(NmpcError::Settings(what.to_owned()));
        if self.horizon == 0 || self.rk4_steps == 0 {
            return bad("horizon and rk4_steps must be at least 1");
        }
        let positive = [
            self.dt,
            self.torque_max,
            self.speed_max,
            self.yaw_rate_max,
            self.qp_tolerance,
            self.brake_time,
        ];
        if positive.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return bad("dt, bounds, qp_tolerance and brake_time must be positive and finite");
        }
        if self.r.iter().any(|v| !(v.is_finite() && *v > 0.0)) {
            return bad("the torque weights R must be positive (the QP must be strictly convex)");
        }
        if self
            .q
            .iter()
            .chain(&self.q_terminal)
            .any(|v| !(v.is_finite() && *v >= 0.0))
        {
            return bad("the state weights Q and Q_N must be non-negative and finite");
        }
        if !(self.sqp_tolerance.is_finite() && self.sqp_tolerance > 0.0) {
            return bad("sqp_tolerance must be positive");
        }
        Ok(())
    }
}

impl Default for NmpcSettings<5> {
    /// The peers': `Q = Q_N = diag(200, 200, 20, 1, 1)` on `(X, Y, φ, v, ω)`,
    /// `R = 10⁻³ I`, N = 20 × 50 ms, two RK4 steps per interval.
    fn default() -> Self {
        NmpcSettings::with_weights([200.0, 200.0, 20.0, 1.0, 1.0])
    }
}

impl Default for NmpcSettings<6> {
    /// The peers' weights on `(X, Y, φ, v_x, v_y, ω)`, the lateral velocity
    /// weighted as the forward speed; three RK4 steps per interval (the
    /// lateral mode is stiff on a grippy ground, see [`Lateral`]).
    fn default() -> Self {
        NmpcSettings {
            rk4_steps: 3,
            ..NmpcSettings::with_weights([200.0, 200.0, 20.0, 1.0, 1.0, 1.0])
        }
    }
}

/// Why the NMPC could not compute a control.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum NmpcError {
    /// Invalid settings.
    #[error("invalid NMPC settings: {0}")]
    Settings(String),
    /// A measurement, reference or parameter is not finite.
    #[error("the {0} is not finite")]
    NotFinite(&'static str),
    /// The reference has fewer than `N + 1` samples.
    #[error("the reference has {got} samples, the horizon needs {need}")]
    ShortReference {
        /// Samples given.
        got: usize,
        /// Samples needed.
        need: usize,
    },
    /// `feedback` was called without a `prepare` before it.
    #[error("feedback without a prepared QP")]
    NotPrepared,
    /// The QP could not be solved.
    #[error("QP not solved: {0}")]
    Qp(String),
}

/// How the torques of a sample were obtained.
#[derive(Clone, Debug, PartialEq)]
pub enum Status {
    /// The QP was solved (by the Riccati recursion, the interior-point method
    /// on the stages when a bound was active, or Clarabel).
    Solved {
        /// Whether Clarabel solved it (the interior-point method did not
        /// converge, or [`QpStrategy::Clarabel`]).
        clarabel: bool,
    },
    /// The QP failed; the shifted previous solution is applied.
    Fallback {
        /// Why.
        reason: String,
    },
    /// Too many failures in a row: braking to a stop.
    SafeStop {
        /// Why.
        reason: String,
    },
}

/// The control of one sample.
#[derive(Clone, Debug, PartialEq)]
pub struct Control {
    /// Wheel torques to apply, within the bounds.
    pub torques: Torques,
    /// How they were obtained.
    pub status: Status,
}

/// Counters of the NMPC.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct NmpcStats {
    /// QPs solved.
    pub qps: u64,
    /// QPs solved by the Riccati recursion alone (no bound active).
    pub structured: u64,
    /// QPs with an active bound solved by the structured interior-point
    /// method.
    pub ipm: u64,
    /// Its iterations, summed.
    pub ipm_iterations: u64,
    /// QPs the structured interior-point method did not solve, given to
    /// Clarabel.
    pub ipm_fallbacks: u64,
    /// QPs solved by Clarabel.
    pub clarabel: u64,
    /// Clarabel's interior-point iterations, summed.
    pub clarabel_iterations: u64,
    /// Failed QPs.
    pub failures: u64,
    /// Samples on the shifted previous solution.
    pub fallbacks: u64,
    /// Samples braking.
    pub safe_stops: u64,
}

/// One linearised stage: `Δx_{k+1} = A Δx_k + B Δu_k + d`.
#[derive(Clone, Copy, Debug)]
struct Stage<const NX: usize> {
    a: Matrix<NX, NX>,
    b: Matrix<NX, NU>,
    d: Vector<NX>,
    /// Feedback gain and feed-forward of the Riccati solution: `Δu = K Δx + k`.
    gain: Matrix<NU, NX>,
    ff: Vector<NU>,
}

impl<const NX: usize> Default for Stage<NX> {
    fn default() -> Self {
        Stage {
            a: Matrix::zeros(),
            b: Matrix::zeros(),
            d: Vector::zeros(),
            gain: Matrix::zeros(),
            ff: Vector::zeros(),
        }
    }
}

/// The NMPC tracker on the prediction model `M`.
#[derive(Debug)]
pub struct Nmpc<M: Dynamics<NX, NP>, const NX: usize, const NP: usize> {
    model: M,
    s: NmpcSettings<NX>,
    /// Current iterate: states `x_0..x_N` and torques `u_0..u_{N−1}`.
    xs: Vec<Vector<NX>>,
    us: Vec<Vector<NU>>,
    reference: Vec<Vector<NX>>,
    p: Vector<NP>,
    /// The torque bound of each wheel in use (`torque_max` unless lowered by
    /// [`Nmpc::set_torque_limits`]).
    limits: [f64; NU],
    /// Added to every predicted interval: `x_{k+1} = F(x_k, u_k, p) + d`
    /// ([`Nmpc::set_disturbance`]).
    disturbance: Vector<NX>,
    stages: Vec<Stage<NX>>,
    /// Whether `stages` holds a linearisation of the current iterate.
    prepared: bool,
    /// Whether the iterate comes from a previous solution (else: cold start).
    warm: bool,
    failures_in_a_row: usize,
    /// Whether the last QP went to Clarabel.
    last_clarabel: bool,
    /// The step of the structured solution, checked against the bounds first.
    du: Vec<Vector<NU>>,
    dx: Vec<Vector<NX>>,
    qp: Option<ClarabelQp>,
    /// The structured interior-point method's memory, and where its next
    /// solve starts.
    work: IpmWork<NX>,
    ipm_start: IpmStart,
    stats: NmpcStats,
}

impl<M: Dynamics<NX, NP>, const NX: usize, const NP: usize> Nmpc<M, NX, NP> {
    /// A controller for `model`.
    pub fn new(model: M, settings: NmpcSettings<NX>) -> Result<Self, NmpcError> {
        settings.validate()?;
        let n = settings.horizon;
        Ok(Nmpc {
            model,
            xs: vec![Vector::zeros(); n + 1],
            us: vec![Vector::zeros(); n],
            reference: vec![Vector::zeros(); n + 1],
            p: Vector::zeros(),
            limits: [settings.torque_max; NU],
            disturbance: Vector::zeros(),
            stages: vec![Stage::default(); n],
            prepared: false,
            warm: false,
            failures_in_a_row: 0,
            last_clarabel: false,
            du: vec![Vector::zeros(); n],
            dx: vec![Vector::zeros(); n + 1],
            qp: None,
            work: IpmWork::new(n),
            ipm_start: IpmStart::new(n),
            stats: NmpcStats::default(),
            s: settings,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &NmpcSettings<NX> {
        &self.s
    }

    /// The prediction model.
    pub fn model(&self) -> &M {
        &self.model
    }

    /// The counters.
    pub fn stats(&self) -> NmpcStats {
        self.stats
    }

    /// The predicted states `x_0..x_N` of the current solution.
    pub fn predicted(&self) -> &[Vector<NX>] {
        &self.xs
    }

    /// The torques `u_0..u_{N−1}` of the current solution.
    pub fn torques(&self) -> &[Vector<NU>] {
        &self.us
    }

    /// Lower the torque bound of each wheel below `torque_max` (what the ground
    /// can take, say); a limit above `torque_max` is `torque_max`. Refused
    /// (nothing changes) unless every limit is positive and finite.
    pub fn set_torque_limits(&mut self, limits: [f64; NU]) -> Result<(), NmpcError> {
        if limits.iter().any(|l| !(l.is_finite() && *l > 0.0)) {
            return Err(NmpcError::NotFinite("torque limit"));
        }
        self.limits = limits.map(|l| l.min(self.s.torque_max));
        Ok(())
    }

    /// Set the torque bound of each wheel, `torque_max` (the limits
    /// [`Nmpc::set_torque_limits`] lowers it to start from it too). Refused
    /// (nothing changes) unless it is positive and finite.
    pub fn set_torque_max(&mut self, torque_max: f64) -> Result<(), NmpcError> {
        if !(torque_max.is_finite() && torque_max > 0.0) {
            return Err(NmpcError::NotFinite("torque bound"));
        }
        self.s.torque_max = torque_max;
        self.limits = [torque_max; NU];
        Ok(())
    }

    /// The torque bounds in use.
    pub fn torque_limits(&self) -> [f64; NU] {
        self.limits
    }

    /// The disturbance the predictions add to each interval's end state, `x_{k+1}
    /// = F(x_k, u_k, p) + d` (offset-free MPC: what the model leaves out, as an
    /// observer of the one-step prediction errors estimates it;
    /// [`DisturbanceObserver`]). Zero unless set; a non-finite `d` is refused.
    pub fn set_disturbance(&mut self, d: &[f64; NX]) -> Result<(), NmpcError> {
        check_finite(d, "disturbance")?;
        self.disturbance = Vector::from(*d);
        Ok(())
    }

    /// The disturbance in use.
    pub fn disturbance(&self) -> [f64; NX] {
        self.disturbance.into()
    }

    /// The model's prediction of one interval with the current parameters and
    /// disturbance: where `x` goes under `u`.
    pub fn predict(&self, x: &[f64; NX], u: &Torques) -> [f64; NX] {
        let next = self.model.rk4(
            &Vector::from(*x),
            &Vector::from(*u),
            &self.p,
            self.s.dt,
            self.s.rk4_steps,
        );
        (next + self.disturbance).into()
    }

    /// Forget the previous solution (the next sample starts cold).
    pub fn reset(&mut self) {
        self.warm = false;
        self.prepared = false;
        self.ipm_start.clear();
    }

    /// One sample of the real-time iteration: [`Nmpc::prepare`], then
    /// [`Nmpc::feedback`]. The first sample (and the first after [`Nmpc::reset`])
    /// runs the converged SQP instead.
    pub fn control(
        &mut self,
        x_hat: &[f64; NX],
        reference: &[[f64; NX]],
        p: &[f64; NP],
    ) -> Result<Control, NmpcError> {
        check_finite(x_hat, "state estimate")?;
        let x_hat = Vector::from(*x_hat);
        if !self.warm {
            self.set_problem(reference, p)?;
            self.cold_start(&x_hat);
            return Ok(match self.iterate(&x_hat, self.s.sqp_max_iterations) {
                Ok(_) => {
                    self.warm = true;
                    self.solved()
                }
                Err(e) => self.failed(&x_hat, e),
            });
        }
        self.prepare(reference, p)?;
        self.feedback_vector(&x_hat)
    }

    /// Preparation: shift the previous solution one stage, take the new reference
    /// window `x_d,0..x_d,N` and parameters, linearise and run the backward Riccati
    /// recursion. Everything that does not need the measurement.
    pub fn prepare(&mut self, reference: &[[f64; NX]], p: &[f64; NP]) -> Result<(), NmpcError> {
        self.set_problem(reference, p)?;
        if self.warm {
            self.shift();
        }
        self.linearise();
        self.prepared = true;
        Ok(())
    }

    /// Feedback: the QP with `Δx_0 = x̂ − x_0`, solved (see the module docs), the
    /// step applied, the first torques returned.
    pub fn feedback(&mut self, x_hat: &[f64; NX]) -> Result<Control, NmpcError> {
        check_finite(x_hat, "state estimate")?;
        self.feedback_vector(&Vector::from(*x_hat))
    }

    fn feedback_vector(&mut self, x_hat: &Vector<NX>) -> Result<Control, NmpcError> {
        if !self.prepared {
            return Err(NmpcError::NotPrepared);
        }
        self.prepared = false;
        match self.qp_step(x_hat) {
            Ok(_) => {
                self.warm = true;
                Ok(self.solved())
            }
            Err(e) => Ok(self.failed(x_hat, e)),
        }
    }

    /// Converged SQP from the current iterate (cold: from the reference): QPs until
    /// the largest step component is below `sqp_tolerance`; returns the iterations.
    pub fn solve(
        &mut self,
        x_hat: &[f64; NX],
        reference: &[[f64; NX]],
        p: &[f64; NP],
    ) -> Result<usize, NmpcError> {
        check_finite(x_hat, "state estimate")?;
        let x_hat = Vector::from(*x_hat);
        self.set_problem(reference, p)?;
        if !self.warm {
            self.cold_start(&x_hat);
        }
        let n = self.iterate(&x_hat, self.s.sqp_max_iterations)?;
        self.warm = true;
        Ok(n)
    }

    fn set_problem(&mut self, reference: &[[f64; NX]], p: &[f64; NP]) -> Result<(), NmpcError> {
        let need = self.s.horizon + 1;
        if reference.len() < need {
            return Err(NmpcError::ShortReference {
                got: reference.len(),
                need,
            });
        }
        if reference[..need]
            .iter()
            .any(|r| r.iter().any(|v| !v.is_finite()))
        {
            return Err(NmpcError::NotFinite("reference"));
        }
        check_finite(p, "parameter estimate")?;
        for (to, from) in self.reference.iter_mut().zip(reference) {
            *to = Vector::from(*from);
        }
        self.p = Vector::from(*p);
        Ok(())
    }

    fn cold_start(&mut self, x_hat: &Vector<NX>) {
        self.xs[0] = *x_hat;
        for k in 1..=self.s.horizon {
            self.xs[k] = self.reference[k];
        }
        self.us.iter_mut().for_each(|u| *u = Vector::zeros());
    }

    fn iterate(&mut self, x_hat: &Vector<NX>, max: usize) -> Result<usize, NmpcError> {
        for i in 1..=max.max(1) {
            self.linearise();
            let step = self.qp_step(x_hat)?;
            if step < self.s.sqp_tolerance {
                return Ok(i);
            }
        }
        Ok(max.max(1))
    }

    /// Shift the solution one stage; the last stage repeats the last torques.
    fn shift(&mut self) {
        let n = self.s.horizon;
        self.xs.copy_within(1.., 0);
        self.us.copy_within(1.., 0);
        self.ipm_start.shift();
        let next = self.model.rk4(
            &self.xs[n - 1],
            &self.us[n - 1],
            &self.p,
            self.s.dt,
            self.s.rk4_steps,
        );
        self.xs[n] = next + self.disturbance;
    }

    fn solved(&mut self) -> Control {
        self.failures_in_a_row = 0;
        Control {
            torques: self.clamped(&self.us[0]),
            status: Status::Solved {
                clarabel: self.last_clarabel,
            },
        }
    }

    fn failed(&mut self, x_hat: &Vector<NX>, error: NmpcError) -> Control {
        self.stats.failures += 1;
        self.failures_in_a_row += 1;
        let reason = error.to_string();
        if self.failures_in_a_row <= self.s.fallback_steps {
            self.stats.fallbacks += 1;
            // The iterate is the shifted previous solution: its first torques.
            Control {
                torques: self.clamped(&self.us[0]),
                status: Status::Fallback { reason },
            }
        } else {
            self.stats.safe_stops += 1;
            self.warm = false;
            Control {
                torques: self.brake(x_hat),
                status: Status::SafeStop { reason },
            }
        }
    }

    /// Torques that stop the platform within `brake_time`, from its effective
    /// mass and inertia.
    fn brake(&self, x: &Vector<NX>) -> Torques {
        let pr: &PlatformParams = self.model.platform();
        let (v, w) = (x[M::SPEED], x[M::YAW_RATE]);
        let m_eff = pr.effective_mass();
        let i_eff =
            pr.inertia + 4.0 * pr.wheel_inertia * pr.half_track.powi(2) / pr.wheel_radius.powi(2);
        let sum = -m_eff * v / self.s.brake_time * pr.wheel_radius / 2.0;
        let diff = -i_eff * w / self.s.brake_time * pr.wheel_radius / (2.0 * pr.half_track);
        let (l, r) = ((sum - diff) / 2.0, (sum + diff) / 2.0);
        self.clamped(&Vector::from([l, l, r, r]))
    }

    fn clamped(&self, u: &Vector<NU>) -> Torques {
        std::array::from_fn(|i| {
            let t = self.limits[i];
            if u[i].is_finite() {
                u[i].clamp(-t, t)
            } else {
                0.0
            }
        })
    }
}

fn check_finite<const N: usize>(x: &[f64; N], what: &'static str) -> Result<(), NmpcError> {
    if x.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(NmpcError::NotFinite(what))
    }
}

/// The Cholesky factor of a stage's `H_uu` (see [`spd_cholesky`]).
type UuFactor = Cholesky<f64, nalgebra::Const<NU>>;
