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
//! hold with zero multipliers on the bounds). Only when a bound would be violated
//! does Clarabel solve the full sparse QP, on a solver built once whose data are
//! updated in place (`update_q`, `update_A`, `update_b`; the sparsity never changes).
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

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};
use serde::{Deserialize, Serialize};

use super::linalg::{Mat, cholesky, cholesky_solve};
use super::sparse::Pattern;
use crate::world::model::{Reduced, SlipParams, State5, Torques};

const NX: usize = 5;
const NU: usize = 4;

/// How the QP of each SQP iteration is solved.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum QpStrategy {
    /// Riccati recursion on the equality-constrained QP; Clarabel when a bound
    /// would be violated. Same solutions, far less time.
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
    /// The QP was solved (`clarabel`: by Clarabel, because a bound was active).
    Solved {
        /// Whether Clarabel solved it.
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
            stages: vec![Stage::default(); n],
            prepared: false,
            warm: false,
            failures_in_a_row: 0,
            last_clarabel: false,
            du: vec![[0.0; NU]; n],
            dx: vec![[0.0; NX]; n + 1],
            qp: None,
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
        self.xs[n] = self.model.rk4(
            &self.xs[n - 1],
            &self.us[n - 1],
            &self.p,
            self.s.dt,
            self.s.rk4_steps,
        );
    }

    /// Linearise every stage and run the backward Riccati recursion.
    fn linearise(&mut self) {
        for k in 0..self.s.horizon {
            let (next, j) = self.model.rk4_sensitivities(
                &self.xs[k],
                &self.us[k],
                &self.p,
                self.s.dt,
                self.s.rk4_steps,
            );
            let st = &mut self.stages[k];
            st.a = Mat(j.x);
            st.b = Mat(j.u);
            st.d = std::array::from_fn(|i| next[i] - self.xs[k + 1][i]);
        }
    }

    /// Gradient of the cost at stage `k` (`2 Q (x_k − x_d,k)`, `Q_N` at the end).
    fn gradient_x(&self, k: usize) -> [f64; NX] {
        let w = if k == self.s.horizon {
            &self.s.q_terminal
        } else {
            &self.s.q
        };
        std::array::from_fn(|i| 2.0 * w[i] * (self.xs[k][i] - self.reference[k][i]))
    }

    /// Backward Riccati recursion of the equality-constrained QP; stores the gains.
    fn riccati(&mut self) -> Result<(), NmpcError> {
        let n = self.s.horizon;
        let mut p = Mat::<NX, NX>::diag(self.s.q_terminal.map(|w| 2.0 * w));
        let mut pv = self.gradient_x(n);
        for k in (0..n).rev() {
            let st = self.stages[k];
            let pa = p.mul(&st.a);
            let pb = p.mul(&st.b);
            let h: [f64; NX] = std::array::from_fn(|i| p.row_dot(i, &st.d) + pv[i]);
            let mut huu = st.b.tmul(&pb);
            for i in 0..NU {
                huu.0[i][i] += 2.0 * self.s.r[i];
            }
            let hux = st.b.tmul(&pa);
            let hu: [f64; NU] =
                std::array::from_fn(|i| 2.0 * self.s.r[i] * self.us[k][i] + st.b.col_dot(i, &h));
            let l = cholesky(&huu).ok_or_else(|| {
                NmpcError::Qp(format!(
                    "Riccati: the Hessian of stage {k} is not positive definite"
                ))
            })?;
            // K = −Huu⁻¹ Hux, k = −Huu⁻¹ hu.
            let mut kmat = Mat::<NU, NX>::zero();
            for c in 0..NX {
                let col = cholesky_solve(&l, &std::array::from_fn(|r| hux.0[r][c]));
                for r in 0..NU {
                    kmat.0[r][c] = -col[r];
                }
            }
            let kff = cholesky_solve(&l, &hu).map(|v| -v);
            self.stages[k].gain = kmat;
            self.stages[k].ff = kff;
            if k > 0 {
                // P ← 2Q + Aᵀ P A + Huxᵀ K,  p ← q + Aᵀ h + Huxᵀ k.
                let mut next = st.a.tmul(&pa).add(&hux.tmul(&kmat));
                for i in 0..NX {
                    next.0[i][i] += 2.0 * self.s.q[i];
                }
                p = next.symmetrised();
                let q = self.gradient_x(k);
                pv = std::array::from_fn(|i| q[i] + st.a.col_dot(i, &h) + hux.col_dot(i, &kff));
            }
        }
        Ok(())
    }

    /// Solve the QP at the current linearisation with `Δx_0 = x̂ − x_0`, apply the
    /// step; returns the largest step component.
    fn qp_step(&mut self, x_hat: &State5) -> Result<f64, NmpcError> {
        let dx0: [f64; NX] = std::array::from_fn(|i| x_hat[i] - self.xs[0][i]);
        self.last_clarabel = true;
        if self.s.qp == QpStrategy::Structured {
            self.riccati()?;
            if self.forward(&dx0) {
                self.last_clarabel = false;
                self.stats.qps += 1;
                self.stats.structured += 1;
                return Ok(self.apply_structured());
            }
        }
        self.clarabel_step(&dx0)
    }

    /// Forward sweep of the Riccati solution into `du`, `dx`; whether it is finite
    /// and satisfies every bound (then it solves the whole QP).
    fn forward(&mut self, dx0: &[f64; NX]) -> bool {
        let n = self.s.horizon;
        let (tau, vmax, wmax) = (self.s.torque_max, self.s.speed_max, self.s.yaw_rate_max);
        let tol = 1e-9;
        self.dx[0] = *dx0;
        let mut ok = dx0.iter().all(|v| v.is_finite());
        for k in 0..n {
            let st = &self.stages[k];
            let dx = self.dx[k];
            let du: [f64; NU] = std::array::from_fn(|i| st.gain.row_dot(i, &dx) + st.ff[i]);
            let next: [f64; NX] =
                std::array::from_fn(|i| st.a.row_dot(i, &dx) + st.b.row_dot(i, &du) + st.d[i]);
            ok &= (0..NU).all(|i| (self.us[k][i] + du[i]).abs() <= tau + tol);
            let x = &self.xs[k + 1];
            ok &= (x[3] + next[3]).abs() <= vmax + tol && (x[4] + next[4]).abs() <= wmax + tol;
            ok &= du.iter().chain(&next).all(|v| v.is_finite());
            self.du[k] = du;
            self.dx[k + 1] = next;
        }
        ok
    }

    /// Apply the structured step; returns its largest component.
    fn apply_structured(&mut self) -> f64 {
        let mut step = 0.0f64;
        for (u, du) in self.us.iter_mut().zip(&self.du) {
            for i in 0..NU {
                u[i] += du[i];
                step = step.max(du[i].abs());
            }
        }
        for (x, dx) in self.xs.iter_mut().zip(&self.dx) {
            for i in 0..NX {
                x[i] += dx[i];
                step = step.max(dx[i].abs());
            }
        }
        step
    }

    fn clarabel_step(&mut self, dx0: &[f64; NX]) -> Result<f64, NmpcError> {
        let n = self.s.horizon;
        if self.qp.is_none() {
            self.qp = Some(ClarabelQp::new(&self.s)?);
        }
        let data = self.qp_data(dx0);
        let Some(qp) = self.qp.as_mut() else {
            return Err(NmpcError::Qp("no QP solver".into()));
        };
        let (dw, iterations) = qp.solve(&data)?;
        self.stats.qps += 1;
        self.stats.clarabel += 1;
        self.stats.clarabel_iterations += u64::from(iterations);
        let mut step = 0.0f64;
        for i in 0..NX {
            self.xs[0][i] += dx0[i];
            step = step.max(dx0[i].abs());
        }
        for k in 0..n {
            for i in 0..NU {
                let d = dw[k * (NU + NX) + i];
                self.us[k][i] += d;
                step = step.max(d.abs());
            }
            for i in 0..NX {
                let d = dw[k * (NU + NX) + NU + i];
                self.xs[k + 1][i] += d;
                step = step.max(d.abs());
            }
        }
        Ok(step)
    }

    /// The QP's `q`, `A` values (declaration order of [`ClarabelQp`]) and `b`.
    fn qp_data(&self, dx0: &[f64; NX]) -> QpData {
        let n = self.s.horizon;
        let nz = NU + NX;
        let mut q = vec![0.0; n * nz];
        let mut a = Vec::with_capacity(n * (NX + NX * NX + NX * NU) + 2 * n * nz);
        let mut b = Vec::with_capacity(n * NX + 2 * n * (NU + 2));
        for k in 0..n {
            for i in 0..NU {
                q[k * nz + i] = 2.0 * self.s.r[i] * self.us[k][i];
            }
            let g = self.gradient_x(k + 1);
            q[k * nz + NU..(k + 1) * nz].copy_from_slice(&g);
        }
        // Equalities, block k: Δx_{k+1} − A_k Δx_k − B_k Δu_k = d_k (+ A_0 Δx_0).
        for k in 0..n {
            let st = &self.stages[k];
            for i in 0..NX {
                a.push(1.0);
                for c in 0..NU {
                    a.push(-st.b.0[i][c]);
                }
                if k > 0 {
                    for c in 0..NX {
                        a.push(-st.a.0[i][c]);
                    }
                }
            }
            for i in 0..NX {
                let extra = if k == 0 { st.a.row_dot(i, dx0) } else { 0.0 };
                b.push(st.d[i] + extra);
            }
        }
        // Bounds: ±Δu ≤ τ_max ∓ u, ±Δv ≤ v_max ∓ v, ±Δω ≤ ω_max ∓ ω.
        for k in 0..n {
            for i in 0..NU {
                a.push(1.0);
                b.push(self.s.torque_max - self.us[k][i]);
                a.push(-1.0);
                b.push(self.s.torque_max + self.us[k][i]);
            }
            let x = &self.xs[k + 1];
            for (i, bound) in [(3, self.s.speed_max), (4, self.s.yaw_rate_max)] {
                a.push(1.0);
                b.push(bound - x[i]);
                a.push(-1.0);
                b.push(bound + x[i]);
            }
        }
        QpData { q, a, b }
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

/// The values of one QP in the fixed layout of [`ClarabelQp`].
struct QpData {
    q: Vec<f64>,
    a: Vec<f64>,
    b: Vec<f64>,
}

/// Clarabel on the sparse multiple-shooting QP, built once. Variables per stage k:
/// `Δu_k` (4) then `Δx_{k+1}` (5); rows: 5 equalities per stage, then per stage
/// 8 torque-bound rows and 4 velocity-bound rows.
struct ClarabelQp {
    solver: DefaultSolver<f64>,
    a_pattern: Pattern,
    a_values: Vec<f64>,
}

impl std::fmt::Debug for ClarabelQp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "ClarabelQp({} nonzeros in A)", self.a_pattern.nnz())
    }
}

impl ClarabelQp {
    fn new(s: &NmpcSettings) -> Result<ClarabelQp, NmpcError> {
        let n = s.horizon;
        let nz = NU + NX;
        let nv = n * nz;
        let n_eq = n * NX;
        let n_ineq = n * (2 * NU + 4);
        // P: the constant Gauss–Newton Hessian, diagonal.
        let mut p_pattern = Pattern::new(nv, nv);
        let mut p_values = Vec::with_capacity(nv);
        for k in 0..n {
            for i in 0..NU {
                p_pattern.push(k * nz + i, k * nz + i);
                p_values.push(2.0 * s.r[i]);
            }
            let w = if k + 1 == n { &s.q_terminal } else { &s.q };
            for i in 0..NX {
                p_pattern.push(k * nz + NU + i, k * nz + NU + i);
                p_values.push(2.0 * w[i]);
            }
        }
        p_pattern.compile();
        // A, in the order `qp_data` fills it.
        let mut a = Pattern::new(n_eq + n_ineq, nv);
        for k in 0..n {
            for i in 0..NX {
                let row = k * NX + i;
                a.push(row, k * nz + NU + i);
                for c in 0..NU {
                    a.push(row, k * nz + c);
                }
                if k > 0 {
                    for c in 0..NX {
                        a.push(row, (k - 1) * nz + NU + c);
                    }
                }
            }
        }
        let mut row = n_eq;
        for k in 0..n {
            for i in 0..NU {
                a.push(row, k * nz + i);
                a.push(row + 1, k * nz + i);
                row += 2;
            }
            for i in [3, 4] {
                a.push(row, k * nz + NU + i);
                a.push(row + 1, k * nz + NU + i);
                row += 2;
            }
        }
        a.compile();
        let a_values = vec![0.0; a.len()];
        let settings: DefaultSettings<f64> = DefaultSettingsBuilder::default()
            .verbose(false)
            .presolve_enable(false)
            .max_iter(s.qp_max_iterations)
            .tol_gap_abs(s.qp_tolerance)
            .tol_gap_rel(s.qp_tolerance)
            .tol_feas(s.qp_tolerance)
            .equilibrate_enable(s.qp_equilibrate)
            .iterative_refinement_enable(s.qp_iterative_refinement)
            .build()
            .map_err(|e| NmpcError::Qp(format!("Clarabel settings: {e}")))?;
        let cones = [
            SupportedConeT::ZeroConeT(n_eq),
            SupportedConeT::NonnegativeConeT(n_ineq),
        ];
        // Placeholder values with the final sparsity (explicit zeros are kept).
        let a_csc: CscMatrix<f64> = a.csc(&a_values);
        let solver = DefaultSolver::new(
            &p_pattern.csc(&p_values),
            &vec![0.0; nv],
            &a_csc,
            &vec![1.0; n_eq + n_ineq],
            &cones,
            settings,
        )
        .map_err(|e| NmpcError::Qp(format!("Clarabel setup: {e}")))?;
        Ok(ClarabelQp {
            solver,
            a_pattern: a,
            a_values: vec![0.0; a_csc.nzval.len()],
        })
    }

    /// Update the data in place and solve; the step `Δw` and the iterations.
    fn solve(&mut self, data: &QpData) -> Result<(Vec<f64>, u32), NmpcError> {
        if data
            .q
            .iter()
            .chain(&data.a)
            .chain(&data.b)
            .any(|v| !v.is_finite())
        {
            return Err(NmpcError::NotFinite("QP data"));
        }
        self.a_pattern.scatter(&data.a, &mut self.a_values);
        let update = |e: clarabel::solver::DataUpdateError| {
            NmpcError::Qp(format!("Clarabel data update: {e}"))
        };
        self.solver.update_q(&data.q).map_err(update)?;
        self.solver.update_A(&self.a_values).map_err(update)?;
        self.solver.update_b(&data.b).map_err(update)?;
        self.solver.solve();
        let sol = &self.solver.solution;
        match sol.status {
            SolverStatus::Solved | SolverStatus::AlmostSolved => {
                if sol.x.iter().all(|v| v.is_finite()) {
                    Ok((sol.x.clone(), sol.iterations))
                } else {
                    Err(NmpcError::Qp(
                        "Clarabel returned a non-finite solution".into(),
                    ))
                }
            }
            other => Err(NmpcError::Qp(format!("Clarabel: {other:?}"))),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::mpc::peer::{self, DT, INIT_OFFSET, N_SIM, PLANT_RK4_STEPS};

    /// The peers' closed loop for `steps` samples; the true positions and the
    /// statuses.
    fn closed_loop(settings: NmpcSettings, steps: usize) -> (Vec<State5>, Vec<Status>, NmpcStats) {
        let model = peer::model();
        let n = settings.horizon;
        let r = peer::reference_run(N_SIM + n + 1);
        let mut nmpc = Nmpc::new(model.clone(), settings).unwrap();
        let p = SlipParams::NOMINAL;
        let mut x = r[0];
        for i in 0..5 {
            x[i] += INIT_OFFSET[i];
        }
        let (mut xs, mut status) = (vec![x], Vec::new());
        for k in 0..steps {
            let c = nmpc.control(&x, &r[k..=k + n], &p).unwrap();
            status.push(c.status);
            x = model.rk4(&x, &c.torques, &p, DT, PLANT_RK4_STEPS);
            xs.push(x);
        }
        (xs, status, nmpc.stats())
    }

    #[test]
    fn tracks_the_figure_eight_like_the_peer() {
        let (xs, _, stats) = closed_loop(NmpcSettings::default(), N_SIM);
        let r = peer::reference_run(N_SIM + 1);
        let err: Vec<f64> = xs
            .iter()
            .zip(&r)
            .map(|(x, r)| (x[0] - r[0]).hypot(x[1] - r[1]))
            .collect();
        let rms = |e: &[f64]| (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt();
        // The peer: rms 0.0296 m over the lap, 0.0016 m after 2 s.
        assert!((rms(&err) - 0.0296).abs() < 0.0005, "rms {}", rms(&err));
        assert!(rms(&err[40..]) < 0.002, "steady rms {}", rms(&err[40..]));
        assert_eq!(stats.failures, 0);
        assert!(stats.structured > 0 && stats.clarabel > 0, "{stats:?}");
    }

    #[test]
    fn structured_and_clarabel_qps_give_the_same_closed_loop() {
        let steps = 60;
        let (a, sa, _) = closed_loop(NmpcSettings::default(), steps);
        let clarabel = NmpcSettings {
            qp: QpStrategy::Clarabel,
            ..NmpcSettings::default()
        };
        let (b, _, stats) = closed_loop(clarabel, steps);
        assert_eq!(stats.structured, 0);
        for (x, y) in a.iter().zip(&b) {
            for i in 0..5 {
                assert!((x[i] - y[i]).abs() < 1e-6, "{x:?} vs {y:?}");
            }
        }
        assert!(sa.contains(&Status::Solved { clarabel: false }));
        assert!(sa.contains(&Status::Solved { clarabel: true }));
    }

    #[test]
    fn converged_sqp_satisfies_the_dynamics_and_the_bounds() {
        let model = peer::model();
        let s = NmpcSettings::default();
        let r = peer::reference_run(s.horizon + 1);
        let mut nmpc = Nmpc::new(model.clone(), s.clone()).unwrap();
        let mut x0 = r[0];
        x0[0] += 0.3;
        let p = SlipParams::NOMINAL;
        let iterations = nmpc.solve(&x0, &r, &p).unwrap();
        assert!(iterations < s.sqp_max_iterations, "{iterations} iterations");
        let (xs, us) = (nmpc.predicted(), nmpc.torques());
        assert_eq!(xs[0], x0);
        for k in 0..s.horizon {
            let next = model.rk4(&xs[k], &us[k], &p, s.dt, s.rk4_steps);
            for i in 0..5 {
                assert!((next[i] - xs[k + 1][i]).abs() < 1e-7, "defect at stage {k}");
            }
            assert!(us[k].iter().all(|u| u.abs() <= s.torque_max + 1e-6));
            assert!(xs[k + 1][4].abs() <= s.yaw_rate_max + 1e-6);
        }
        // 30 cm off: the torques saturate at the start.
        assert!(
            us[0].iter().any(|u| (u.abs() - s.torque_max).abs() < 1e-6),
            "{:?}",
            us[0]
        );
    }

    #[test]
    fn qp_failures_fall_back_then_brake() {
        // Clarabel cannot finish in one iteration: every QP fails.
        let settings = NmpcSettings {
            qp: QpStrategy::Clarabel,
            qp_max_iterations: 1,
            fallback_steps: 3,
            ..NmpcSettings::default()
        };
        let model = peer::model();
        let r = peer::reference_run(40);
        let mut nmpc = Nmpc::new(model, settings).unwrap();
        let p = SlipParams::NOMINAL;
        let moving = [0.0, 0.0, 0.0, 0.6, 0.5];
        let mut kinds = Vec::new();
        for k in 0..6 {
            let c = nmpc.control(&moving, &r[k..=k + 20], &p).unwrap();
            kinds.push(match &c.status {
                Status::Solved { .. } => "solved",
                Status::Fallback { reason } => {
                    assert!(reason.contains("MaxIterations"), "{reason}");
                    "fallback"
                }
                Status::SafeStop { .. } => {
                    // Braking: forward speed and turn are opposed.
                    let (left, right) = (c.torques[0], c.torques[2]);
                    assert!(left + right < 0.0 && right - left < 0.0, "{:?}", c.torques);
                    "stop"
                }
            });
        }
        assert_eq!(
            kinds,
            ["fallback", "fallback", "fallback", "stop", "stop", "stop"]
        );
        let stats = nmpc.stats();
        assert_eq!(
            (stats.failures, stats.fallbacks, stats.safe_stops),
            (6, 3, 3)
        );
    }

    #[test]
    fn bad_input_is_an_error_not_a_panic() {
        let mut nmpc = Nmpc::new(peer::model(), NmpcSettings::default()).unwrap();
        let r = peer::reference_run(21);
        let p = SlipParams::NOMINAL;
        let nan = [f64::NAN, 0.0, 0.0, 0.0, 0.0];
        assert_eq!(
            nmpc.control(&nan, &r, &p),
            Err(NmpcError::NotFinite("state estimate"))
        );
        assert!(matches!(
            nmpc.control(&r[0], &r[..5], &p),
            Err(NmpcError::ShortReference { got: 5, need: 21 })
        ));
        let bad_p = SlipParams {
            mu_l: f64::INFINITY,
            ..p
        };
        assert!(nmpc.control(&r[0], &r, &bad_p).is_err());
        assert_eq!(nmpc.feedback(&r[0]), Err(NmpcError::NotPrepared));
        for bad in [
            NmpcSettings {
                horizon: 0,
                ..NmpcSettings::default()
            },
            NmpcSettings {
                r: [0.0; 4],
                ..NmpcSettings::default()
            },
            NmpcSettings {
                dt: f64::NAN,
                ..NmpcSettings::default()
            },
            NmpcSettings {
                q: [-1.0; 5],
                ..NmpcSettings::default()
            },
        ] {
            assert!(matches!(
                Nmpc::new(peer::model(), bad),
                Err(NmpcError::Settings(_))
            ));
        }
    }
}
