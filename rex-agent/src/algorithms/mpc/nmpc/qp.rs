//! The QP of one SQP iteration of the NMPC: the linearisation of every stage, the
//! equality-constrained QP by a backward Riccati recursion and a forward sweep (the
//! structured solution, kept when it satisfies every bound), and the full sparse QP
//! by Clarabel when it does not (see the module docs of `nmpc`).

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};

use super::{Nmpc, NmpcError, NmpcSettings, QpStrategy, spd_cholesky};
use crate::algorithms::mpc::sparse::Pattern;
use crate::model::{Dynamics, Matrix, NU, Vector};

impl<M: Dynamics<NX, NP>, const NX: usize, const NP: usize> Nmpc<M, NX, NP> {
    /// Linearise every stage.
    pub(super) fn linearise(&mut self) {
        for k in 0..self.s.horizon {
            let j = self.model.rk4_sensitivities(
                &self.xs[k],
                &self.us[k],
                &self.p,
                self.s.dt,
                self.s.rk4_steps,
            );
            let st = &mut self.stages[k];
            st.a = j.x;
            st.b = j.u;
            st.d = j.value + self.disturbance - self.xs[k + 1];
        }
    }

    /// The state weights of stage `k` (`Q`, `Q_N` at the end).
    pub(super) fn weights(&self, k: usize) -> &[f64; NX] {
        if k == self.s.horizon {
            &self.s.q_terminal
        } else {
            &self.s.q
        }
    }

    /// Gradient of the cost at stage `k` (`2 Q (x_k − x_d,k)`, `Q_N` at the end).
    pub(super) fn gradient_x(&self, k: usize) -> Vector<NX> {
        let w = self.weights(k);
        let e = self.xs[k] - self.reference[k];
        Vector::from_fn(|i, _| 2.0 * w[i] * e[i])
    }

    /// The torques' gradient at stage `k`, `2 R u_k`.
    pub(super) fn gradient_u(&self, k: usize) -> Vector<NU> {
        Vector::from_fn(|i, _| 2.0 * self.s.r[i] * self.us[k][i])
    }

    /// Backward Riccati recursion of the equality-constrained QP; stores the gains.
    pub(super) fn riccati(&mut self) -> Result<(), NmpcError> {
        let n = self.s.horizon;
        let mut p =
            Matrix::<NX, NX>::from_diagonal(&Vector::from(self.s.q_terminal.map(|w| 2.0 * w)));
        let mut pv = self.gradient_x(n);
        for k in (0..n).rev() {
            let st = self.stages[k];
            let pa = p * st.a;
            let pb = p * st.b;
            let h = p * st.d + pv;
            let mut huu = st.b.tr_mul(&pb);
            for i in 0..NU {
                huu[(i, i)] += 2.0 * self.s.r[i];
            }
            let hux = st.b.tr_mul(&pa);
            let hu = self.gradient_u(k) + st.b.tr_mul(&h);
            let l = spd_cholesky(huu).ok_or_else(|| {
                NmpcError::Qp(format!(
                    "Riccati: the Hessian of stage {k} is not positive definite"
                ))
            })?;
            // K = −Huu⁻¹ Hux, k = −Huu⁻¹ hu.
            let kmat = -l.solve(&hux);
            let kff = -l.solve(&hu);
            self.stages[k].gain = kmat;
            self.stages[k].ff = kff;
            if k > 0 {
                // P ← 2Q + Aᵀ P A + Huxᵀ K,  p ← q + Aᵀ h + Huxᵀ k.
                let mut next = st.a.tr_mul(&pa) + hux.tr_mul(&kmat);
                for i in 0..NX {
                    next[(i, i)] += 2.0 * self.s.q[i];
                }
                p = (next + next.transpose()) * 0.5;
                pv = self.gradient_x(k) + st.a.tr_mul(&h) + hux.tr_mul(&kff);
            }
        }
        Ok(())
    }

    /// Solve the QP at the current linearisation with `Δx_0 = x̂ − x_0`, apply the
    /// step; returns the largest step component.
    pub(super) fn qp_step(&mut self, x_hat: &Vector<NX>) -> Result<f64, NmpcError> {
        let dx0 = x_hat - self.xs[0];
        self.last_clarabel = true;
        if self.s.qp == QpStrategy::Structured {
            self.riccati()?;
            if self.forward(&dx0) {
                self.last_clarabel = false;
                self.stats.qps += 1;
                self.stats.structured += 1;
                // No bound active: every multiplier is zero.
                self.ipm_start.clear();
                return Ok(self.apply_structured());
            }
            if let Some(iterations) = self.ipm(&dx0) {
                self.last_clarabel = false;
                self.stats.qps += 1;
                self.stats.ipm += 1;
                self.stats.ipm_iterations += iterations as u64;
                self.keep_ipm_start();
                return Ok(self.apply_structured());
            }
            self.stats.ipm_fallbacks += 1;
        }
        self.ipm_start.clear();
        self.clarabel_step(&dx0)
    }

    /// Forward sweep of the Riccati solution into `du`, `dx`; whether it is finite
    /// and satisfies every bound (then it solves the whole QP).
    pub(super) fn forward(&mut self, dx0: &Vector<NX>) -> bool {
        let n = self.s.horizon;
        let (vmax, wmax) = (self.s.speed_max, self.s.yaw_rate_max);
        let tol = 1e-9;
        self.dx[0] = *dx0;
        let mut ok = dx0.iter().all(|v| v.is_finite());
        for k in 0..n {
            let st = &self.stages[k];
            let du = st.gain * self.dx[k] + st.ff;
            let next = st.a * self.dx[k] + st.b * du + st.d;
            ok &= (0..NU).all(|i| (self.us[k][i] + du[i]).abs() <= self.limits[i] + tol);
            let x = &self.xs[k + 1];
            ok &= (x[M::SPEED] + next[M::SPEED]).abs() <= vmax + tol
                && (x[M::YAW_RATE] + next[M::YAW_RATE]).abs() <= wmax + tol;
            ok &= du.iter().chain(next.iter()).all(|v| v.is_finite());
            self.du[k] = du;
            self.dx[k + 1] = next;
        }
        ok
    }

    /// Apply the structured step; returns its largest component.
    fn apply_structured(&mut self) -> f64 {
        let mut step = 0.0f64;
        for (u, du) in self.us.iter_mut().zip(&self.du) {
            *u += du;
            step = step.max(du.amax());
        }
        for (x, dx) in self.xs.iter_mut().zip(&self.dx) {
            *x += dx;
            step = step.max(dx.amax());
        }
        step
    }

    fn clarabel_step(&mut self, dx0: &Vector<NX>) -> Result<f64, NmpcError> {
        let n = self.s.horizon;
        if self.qp.is_none() {
            self.qp = Some(ClarabelQp::new(&self.s, [M::SPEED, M::YAW_RATE])?);
        }
        let data = self.qp_data(dx0);
        let Some(qp) = self.qp.as_mut() else {
            return Err(NmpcError::Qp("no QP solver".into()));
        };
        let (dw, iterations) = qp.solve(&data)?;
        self.stats.qps += 1;
        self.stats.clarabel += 1;
        self.stats.clarabel_iterations += u64::from(iterations);
        self.xs[0] += dx0;
        let mut step = dx0.amax();
        for k in 0..n {
            let at = k * (NU + NX);
            for i in 0..NU {
                let d = dw[at + i];
                self.us[k][i] += d;
                step = step.max(d.abs());
            }
            for i in 0..NX {
                let d = dw[at + NU + i];
                self.xs[k + 1][i] += d;
                step = step.max(d.abs());
            }
        }
        Ok(step)
    }

    /// The QP's `q`, `A` values (declaration order of [`ClarabelQp`]) and `b`.
    pub(super) fn qp_data(&self, dx0: &Vector<NX>) -> QpData {
        let n = self.s.horizon;
        let nz = NU + NX;
        let mut q = vec![0.0; n * nz];
        let mut a = Vec::with_capacity(n * (NX + NX * NX + NX * NU) + 2 * n * nz);
        let mut b = Vec::with_capacity(n * NX + 2 * n * (NU + 2));
        for k in 0..n {
            q[k * nz..k * nz + NU].copy_from_slice(self.gradient_u(k).as_slice());
            q[k * nz + NU..(k + 1) * nz].copy_from_slice(self.gradient_x(k + 1).as_slice());
        }
        // Equalities, block k: Δx_{k+1} − A_k Δx_k − B_k Δu_k = d_k (+ A_0 Δx_0).
        for k in 0..n {
            let st = &self.stages[k];
            for i in 0..NX {
                a.push(1.0);
                for c in 0..NU {
                    a.push(-st.b[(i, c)]);
                }
                if k > 0 {
                    for c in 0..NX {
                        a.push(-st.a[(i, c)]);
                    }
                }
            }
            let extra = if k == 0 { st.a * dx0 } else { Vector::zeros() };
            b.extend((st.d + extra).iter());
        }
        // Bounds: ±Δu ≤ τ_max ∓ u, ±Δv ≤ v_max ∓ v, ±Δω ≤ ω_max ∓ ω.
        for k in 0..n {
            for i in 0..NU {
                a.push(1.0);
                b.push(self.limits[i] - self.us[k][i]);
                a.push(-1.0);
                b.push(self.limits[i] + self.us[k][i]);
            }
            let x = &self.xs[k + 1];
            for (i, bound) in [
                (M::SPEED, self.s.speed_max),
                (M::YAW_RATE, self.s.yaw_rate_max),
            ] {
                a.push(1.0);
                b.push(bound - x[i]);
                a.push(-1.0);
                b.push(bound + x[i]);
            }
        }
        QpData { q, a, b }
    }
}

/// The values of one QP in the fixed layout of [`ClarabelQp`].
pub(super) struct QpData {
    pub(super) q: Vec<f64>,
    pub(super) a: Vec<f64>,
    pub(super) b: Vec<f64>,
}

/// Clarabel on the sparse multiple-shooting QP, built once. Variables per stage k:
/// `Δu_k` (4) then `Δx_{k+1}` (`NX`); rows: `NX` equalities per stage, then per
/// stage 8 torque-bound rows and 4 velocity-bound rows.
pub(super) struct ClarabelQp {
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
    /// The QP of a model whose speed and yaw rate are the state components
    /// `bounded`.
    pub(super) fn new<const NX: usize>(
        s: &NmpcSettings<NX>,
        bounded: [usize; 2],
    ) -> Result<ClarabelQp, NmpcError> {
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
            for i in bounded {
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
    pub(super) fn solve(&mut self, data: &QpData) -> Result<(Vec<f64>, u32), NmpcError> {
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
