//! Nonlinear model predictive tracking control (the paper's section 3.2; notes §3.1).
//!
//! The optimal control problem, exactly as `peers/casadi_nmpc.py` poses it:
//!
//! ```text
//! min  Σ_{k<N} (x_k − x_d,k)ᵀ Q (x_k − x_d,k) + u_kᵀ R u_k  +  (x_N − x_d,N)ᵀ Q_N (x_N − x_d,N)
//! s.t. x_0 = x̂,  x_{k+1} = F(x_k, u_k, p),  |τ_i| ≤ τ_max,  |v_k| ≤ v_max,  |ω_k| ≤ ω_max (k ≥ 1)
//! ```
//!
//! with `F` the reduced model integrated by RK4 over each interval (direct multiple
//! shooting). It is solved by Gauss–Newton SQP: linearise `F` around the current
//! iterate with exact sensitivities ([`Reduced::rk4_sensitivities`]), solve the QP in
//! `Δw`, take the full step.
//!
//! * **Real-time iteration** ([`Nmpc::prepare`] then [`Nmpc::feedback`]): one QP per
//!   sample. The preparation shifts the previous solution one stage, linearises and
//!   runs the backward Riccati recursion before the measurement is known; the
//!   feedback only sets `Δx_0 = x̂ − x_0` and sweeps forward.
//! * **Converged SQP** ([`Nmpc::solve`]): QPs until the step is below a tolerance,
//!   for cold starts and tests.
//!
//! **How the QP is solved.** The QP has 180 variables (`Δx_0` is fixed by the
//! measurement), 100 equality rows and 240 inequality rows. Solved by Clarabel
//! (interior point, no warm start) it costs about nine iterations whatever the
//! starting point: 0.8–0.9 ms here, twice the whole budget. But the inequality rows
//! are rarely active once the platform is on its path. So
//! [`QpStrategy::Structured`] first solves the equality-constrained QP by a Riccati
//! recursion over the stages (linear in `N`, a few microseconds); if that solution
//! satisfies every bound, it *is* the solution of the whole QP (the KKT conditions
//! hold with zero multipliers on the bounds). When a bound would be violated, a
//! primal-dual interior-point method whose Newton steps are the same Riccati
//! recursion with the barrier's diagonal added to the stage weights (`ipm.rs`,
//! as HPIPM does; Mehrotra's predictor-corrector, one factorisation for both
//! solves) solves the QP with its bounds in about seven iterations: on the
//! peers' closed loop the step's p99 went from 0.52 ms (Clarabel for these QPs)
//! to 0.16 ms. Clarabel stays the reference the tests compare it with, and the
//! fallback should it not converge: it solves the full sparse QP, on a solver
//! built once whose data are updated in place (`update_q`, `update_A`,
//! `update_b`; the sparsity never changes).
//! Clarabel's defaults are tuned for hard problems; this QP is small and well
//! scaled, and measured on the peers' closed loop (`bench_nmpc`, Clarabel for every
//! QP) a solve took 0.77 ms with the defaults, 0.53 ms without iterative refinement,
//! 0.39 ms with tolerance 1e-6 and without equilibration and iterative refinement
//! as well, with the same closed loop to 1e-6: those are the defaults here.
//! [`QpStrategy::Clarabel`] sends every QP to Clarabel, for comparison.
//!
//! **Faults.** A QP that Clarabel does not solve, a Riccati recursion that meets a
//! non-positive pivot, or non-finite data never panic: the controller applies the
//! shifted previous solution for at most `fallback_steps` samples, then brakes to a
//! stop ([`Status::SafeStop`]) until a QP succeeds again. Every case is counted in
//! [`NmpcStats`].
//!
//! This file holds the settings, the controller, its warm start and its fallbacks;
//! `qp.rs` the QP of one SQP iteration (linearisation, Riccati recursion, Clarabel).

use serde::{Deserialize, Serialize};

use super::linalg::Mat;
use crate::world::model::{Reduced, SlipParams, State5, Torques};

mod ipm;
mod offset;
mod qp;

pub use offset::{DisturbanceObserver, DisturbanceSettings};

use ipm::IpmWork;
use qp::ClarabelQp;

const NX: usize = 5;
const NU: usize = 4;

/// How the QP of each SQP iteration is solved.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum QpStrategy {
    /// Riccati recursion on the equality-constrained QP; when a bound would be
    /// violated, the interior-point method on the stage structure (Clarabel if
    /// it does not converge). Same solutions, far less time.
    #[default]
    Structured,
    /// Every QP by Clarabel.
    Clarabel,
}

/// Settings of the NMPC; the defaults are the peers' (`casadi_nmpc.py`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NmpcSettings {
    /// Horizon `N` (shooting intervals).
    pub horizon: usize,
    /// Interval length [s].
    pub dt: f64,
    /// RK4 steps per interval.
    pub rk4_steps: usize,
    /// State weights `Q` on `(X, Y, φ, v, ω)` errors.
    pub q: [f64; 5],
    /// Terminal weights `Q_N`.
    pub q_terminal: [f64; 5],
    /// Torque weights `R`.
    pub r: [f64; 4],
    /// Torque bound per wheel [N m].
    pub torque_max: f64,
    /// Speed bound [m/s].
    pub speed_max: f64,
    /// Yaw-rate bound [rad/s].
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
    /// need it, and it costs 40 % of a solve).
    pub qp_iterative_refinement: bool,
    /// Clarabel's iteration bound.
    pub qp_max_iterations: u32,
    /// Samples on the shifted previous solution after a failed QP, before braking.
    pub fallback_steps: usize,
    /// Time constant of the safe stop [s].
    pub brake_time: f64,
}

impl Default for NmpcSettings {
    fn default() -> Self {
        NmpcSettings {
            horizon: 20,
            dt: 0.05,
            rk4_steps: 2,
            q: [200.0, 200.0, 20.0, 1.0, 1.0],
            q_terminal: [200.0, 200.0, 20.0, 1.0, 1.0],
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
}

impl NmpcSettings {
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
#[derive(Clone, Copy, Debug, Default)]
struct Stage {
    a: Mat<NX, NX>,
    b: Mat<NX, NU>,
    d: [f64; NX],
    /// Feedback gain and feed-forward of the Riccati solution: `Δu = K Δx + k`.
    gain: Mat<NU, NX>,
    ff: [f64; NU],
}

/// The NMPC tracker.
#[derive(Debug)]
pub struct Nmpc {
    model: Reduced,
    s: NmpcSettings,
    /// Current iterate: states `x_0..x_N` and torques `u_0..u_{N−1}`.
    xs: Vec<State5>,
    us: Vec<Torques>,
    reference: Vec<State5>,
    p: SlipParams,
    /// Added to every predicted interval: `x_{k+1} = F(x_k, u_k, p) + d`
    /// ([`Nmpc::set_disturbance`]).
    disturbance: State5,
    stages: Vec<Stage>,
    /// Whether `stages` holds a linearisation of the current iterate.
    prepared: bool,
    /// Whether the iterate comes from a previous solution (else: cold start).
    warm: bool,
    failures_in_a_row: usize,
    /// Whether the last QP went to Clarabel.
    last_clarabel: bool,
    /// The step of the structured solution, checked against the bounds first.
    du: Vec<[f64; NU]>,
    dx: Vec<[f64; NX]>,
    qp: Option<ClarabelQp>,
    /// The structured interior-point method's memory.
    work: IpmWork,
    stats: NmpcStats,
}

impl Nmpc {
    /// A controller for `model`.
    pub fn new(model: Reduced, settings: NmpcSettings) -> Result<Nmpc, NmpcError> {
        settings.validate()?;
        let n = settings.horizon;
        Ok(Nmpc {
            model,
            xs: vec![[0.0; NX]; n + 1],
            us: vec![[0.0; NU]; n],
            reference: vec![[0.0; NX]; n + 1],
            p: SlipParams::NOMINAL,
            disturbance: [0.0; NX],
            stages: vec![Stage::default(); n],
            prepared: false,
            warm: false,
            failures_in_a_row: 0,
            last_clarabel: false,
            du: vec![[0.0; NU]; n],
            dx: vec![[0.0; NX]; n + 1],
            qp: None,
            work: IpmWork::new(n),
            stats: NmpcStats::default(),
            s: settings,
        })
    }

    /// The settings.
    pub fn settings(&self) -> &NmpcSettings {
        &self.s
    }

    /// The counters.
    pub fn stats(&self) -> NmpcStats {
        self.stats
    }

    /// The predicted states `x_0..x_N` of the current solution.
    pub fn predicted(&self) -> &[State5] {
        &self.xs
    }

    /// The torques `u_0..u_{N−1}` of the current solution.
    pub fn torques(&self) -> &[Torques] {
        &self.us
    }

    /// The disturbance the predictions add to each interval's end state, `x_{k+1}
    /// = F(x_k, u_k, p) + d` (offset-free MPC: what the model leaves out, as an
    /// observer of the one-step prediction errors estimates it;
    /// [`DisturbanceObserver`]). Zero unless set; a non-finite `d` is refused.
    pub fn set_disturbance(&mut self, d: &State5) -> Result<(), NmpcError> {
        check_finite(d, "disturbance")?;
        self.disturbance = *d;
        Ok(())
    }

    /// The disturbance in use.
    pub fn disturbance(&self) -> &State5 {
        &self.disturbance
    }

    /// The model's prediction of one interval with the current parameters and
    /// disturbance: where `x` goes under `u`.
    pub fn predict(&self, x: &State5, u: &Torques) -> State5 {
        let next = self.model.rk4(x, u, &self.p, self.s.dt, self.s.rk4_steps);
        std::array::from_fn(|i| next[i] + self.disturbance[i])
    }

    /// Forget the previous solution (the next sample starts cold).
    pub fn reset(&mut self) {
        self.warm = false;
        self.prepared = false;
    }

    /// One sample of the real-time iteration: [`Nmpc::prepare`], then
    /// [`Nmpc::feedback`]. The first sample (and the first after [`Nmpc::reset`])
    /// runs the converged SQP instead.
    pub fn control(
        &mut self,
        x_hat: &State5,
        reference: &[State5],
        p: &SlipParams,
    ) -> Result<Control, NmpcError> {
        check_finite(x_hat, "state estimate")?;
        if !self.warm {
            self.set_problem(reference, p)?;
            self.cold_start(x_hat);
            return Ok(match self.iterate(x_hat, self.s.sqp_max_iterations) {
                Ok(_) => {
                    self.warm = true;
                    self.solved()
                }
                Err(e) => self.failed(x_hat, e),
            });
        }
        self.prepare(reference, p)?;
        self.feedback(x_hat)
    }

    /// Preparation: shift the previous solution one stage, take the new reference
    /// window `x_d,0..x_d,N` and parameters, linearise and run the backward Riccati
    /// recursion. Everything that does not need the measurement.
    pub fn prepare(&mut self, reference: &[State5], p: &SlipParams) -> Result<(), NmpcError> {
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
    pub fn feedback(&mut self, x_hat: &State5) -> Result<Control, NmpcError> {
        check_finite(x_hat, "state estimate")?;
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
        x_hat: &State5,
        reference: &[State5],
        p: &SlipParams,
    ) -> Result<usize, NmpcError> {
        check_finite(x_hat, "state estimate")?;
        self.set_problem(reference, p)?;
        if !self.warm {
            self.cold_start(x_hat);
        }
        let n = self.iterate(x_hat, self.s.sqp_max_iterations)?;
        self.warm = true;
        Ok(n)
    }

    fn set_problem(&mut self, reference: &[State5], p: &SlipParams) -> Result<(), NmpcError> {
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
        if ![p.x_icr, p.mu_s, p.mu_l].iter().all(|v| v.is_finite()) {
            return Err(NmpcError::NotFinite("slip parameter estimate"));
        }
        self.reference.copy_from_slice(&reference[..need]);
        self.p = *p;
        Ok(())
    }

    fn cold_start(&mut self, x_hat: &State5) {
        self.xs[0] = *x_hat;
        for k in 1..=self.s.horizon {
            self.xs[k] = self.reference[k];
        }
        self.us.iter_mut().for_each(|u| *u = [0.0; NU]);
    }

    fn iterate(&mut self, x_hat: &State5, max: usize) -> Result<usize, NmpcError> {
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
        self.xs[n] = self.predict(&self.xs[n - 1], &self.us[n - 1]);
    }

    fn solved(&mut self) -> Control {
        self.failures_in_a_row = 0;
        Control {
            torques: self.clamped(self.us[0]),
            status: Status::Solved {
                clarabel: self.last_clarabel,
            },
        }
    }

    fn failed(&mut self, x_hat: &State5, error: NmpcError) -> Control {
        self.stats.failures += 1;
        self.failures_in_a_row += 1;
        let reason = error.to_string();
        if self.failures_in_a_row <= self.s.fallback_steps {
            self.stats.fallbacks += 1;
            // The iterate is the shifted previous solution: its first torques.
            Control {
                torques: self.clamped(self.us[0]),
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

    /// Torques that stop the platform within `brake_time`, from the reduced model's
    /// effective mass and inertia.
    fn brake(&self, x: &State5) -> Torques {
        let pr = &self.model.params;
        let (v, w) = (x[3], x[4]);
        let m_eff = pr.effective_mass();
        let i_eff = pr.inertia
            + pr.mass * self.p.x_icr.powi(2)
            + 4.0 * pr.wheel_inertia * pr.half_track.powi(2) / pr.wheel_radius.powi(2);
        let sum = -m_eff * v / self.s.brake_time * pr.wheel_radius / 2.0;
        let diff = -i_eff * w / self.s.brake_time * pr.wheel_radius / (2.0 * pr.half_track);
        let (l, r) = ((sum - diff) / 2.0, (sum + diff) / 2.0);
        self.clamped([l, l, r, r])
    }

    fn clamped(&self, u: Torques) -> Torques {
        let t = self.s.torque_max;
        u.map(|v| if v.is_finite() { v.clamp(-t, t) } else { 0.0 })
    }
}

fn check_finite(x: &State5, what: &'static str) -> Result<(), NmpcError> {
    if x.iter().all(|v| v.is_finite()) {
        Ok(())
    } else {
        Err(NmpcError::NotFinite(what))
    }
}

#[cfg(test)]
mod tests;
