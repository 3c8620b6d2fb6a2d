//! Solving the MHE's normal equations: exactly in `O(N)` by a block Cholesky
//! factorisation of the states' part and the 3 × 3 Schur complement of the slip
//! parameters, with Clarabel on the reduced box QP in `Δp` when a parameter bound
//! is hit ([`QpStrategy::Structured`](super::QpStrategy::Structured)); or the whole
//! QP in `(Δx, Δp)` by Clarabel ([`QpStrategy::Clarabel`](super::QpStrategy::Clarabel)).

use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};

use super::{Blocks, Mhe, MheError};
use crate::algorithms::mpc::sparse::Pattern;
use crate::algorithms::mpc::spd_cholesky;
use crate::model::{Dynamics, Matrix, Vector};

/// The states' steps and the parameters' step.
type Step<const NX: usize, const NP: usize> = (Vec<Vector<NX>>, Vector<NP>);

impl<M: Dynamics<NX, NP>, const NX: usize, const NP: usize> Mhe<M, NX, NP> {
    /// Solve the normal equations by block Cholesky (states) and the Schur
    /// complement (parameters); Clarabel on the reduced box QP when a bound is hit.
    pub(super) fn solve_structured(&mut self, n: usize) -> Result<Step<NX, NP>, MheError> {
        let not_pd = |i: usize| {
            MheError::Solve(format!(
                "the normal equations are not positive definite at stage {i}"
            ))
        };
        let singular = || MheError::Solve("a triangular solve met a zero pivot".into());
        // Factor T = L Lᵀ, L block bidiagonal: L_i on the diagonal, E_iᵀ below.
        let mut sdiag = self.blocks[0].d;
        for i in 0..=n {
            let l = spd_cholesky((sdiag + sdiag.transpose()) * 0.5)
                .ok_or_else(|| not_pd(i))?
                .unpack();
            if i < n {
                let e = l
                    .solve_lower_triangular(&self.blocks[i].o)
                    .ok_or_else(singular)?;
                sdiag = self.blocks[i + 1].d - e.tr_mul(&e);
                self.e[i] = e;
            }
            self.chol[i] = l;
        }
        // Right-hand sides [g_i | C_iᵀ]; forward then backward substitution.
        for i in 0..=n {
            let b = &self.blocks[i];
            let (mut g, mut c) = (b.g, b.c.transpose());
            if i > 0 {
                g -= self.e[i - 1].tr_mul(&self.sol_g[i - 1]);
                c -= self.e[i - 1].tr_mul(&self.sol_c[i - 1]);
            }
            let l = &self.chol[i];
            self.sol_g[i] = l.solve_lower_triangular(&g).ok_or_else(singular)?;
            self.sol_c[i] = l.solve_lower_triangular(&c).ok_or_else(singular)?;
        }
        for i in (0..=n).rev() {
            let (mut g, mut c) = (self.sol_g[i], self.sol_c[i]);
            if i < n {
                g -= self.e[i] * self.sol_g[i + 1];
                c -= self.e[i] * self.sol_c[i + 1];
            }
            let l = &self.chol[i];
            self.sol_g[i] = l.tr_solve_lower_triangular(&g).ok_or_else(singular)?;
            self.sol_c[i] = l.tr_solve_lower_triangular(&c).ok_or_else(singular)?;
        }
        // Schur complement S = Hpp − C T⁻¹ Cᵀ and b = g_p − C T⁻¹ g.
        let mut schur = self.hpp;
        let mut bp = self.gp;
        for i in 0..=n {
            let c = &self.blocks[i].c;
            bp -= c * self.sol_g[i];
            schur -= c * self.sol_c[i];
        }
        let schur = (schur + schur.transpose()) * 0.5;
        // What the window's data say of each parameter, the others and the
        // states given: the Schur complement without the arrival cost's part.
        self.information =
            Vector::from_fn(|k, _| (schur[(k, k)] - 1.0 / self.s.sigma_p[k].powi(2)).max(0.0));
        let l = spd_cholesky(schur).ok_or_else(|| {
            MheError::Solve("the parameters' Schur complement is not positive definite".into())
        })?;
        let mut dp = -l.solve(&bp);
        let inside = (0..NP).all(|k| {
            let q = self.p[k] + dp[k];
            q >= self.s.p_lb[k] - 1e-12 && q <= self.s.p_ub[k] + 1e-12
        });
        if !inside {
            if self.qp.is_none() {
                self.qp = Some(BoxQp::new(NP, self.s.qp_tolerance)?);
            }
            let lo = Vector::<NP>::from_fn(|k, _| self.s.p_lb[k] - self.p[k]);
            let hi = Vector::<NP>::from_fn(|k, _| self.s.p_ub[k] - self.p[k]);
            if let Some(qp) = self.qp.as_mut() {
                dp = Vector::from_column_slice(&qp.solve(
                    schur.as_slice(),
                    bp.as_slice(),
                    lo.as_slice(),
                    hi.as_slice(),
                )?);
            }
            self.stats.clarabel += 1;
        }
        let dx = (0..=n)
            .map(|i| -self.sol_g[i] - self.sol_c[i] * dp)
            .collect();
        Ok((dx, dp))
    }

    /// The whole QP in `(Δx_0..Δx_n, Δp)` by Clarabel (for comparison).
    pub(super) fn solve_full(&mut self, n: usize) -> Result<Step<NX, NP>, MheError> {
        if self.full.as_ref().is_none_or(|f| f.stages != n + 1) {
            self.full = Some(FullQp::new(n + 1, NX, NP, self.s.qp_tolerance)?);
        }
        let lo = Vector::<NP>::from_fn(|k, _| self.s.p_lb[k] - self.p[k]);
        let hi = Vector::<NP>::from_fn(|k, _| self.s.p_ub[k] - self.p[k]);
        let Some(full) = self.full.as_mut() else {
            return Err(MheError::Solve("no QP".into()));
        };
        let w = full.solve(&self.blocks[..=n], &self.hpp, &self.gp, &lo, &hi)?;
        self.stats.clarabel += 1;
        let dx = (0..=n)
            .map(|i| Vector::from_column_slice(&w[i * NX..(i + 1) * NX]))
            .collect();
        let dp = Vector::from_column_slice(&w[(n + 1) * NX..(n + 1) * NX + NP]);
        Ok((dx, dp))
    }
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

/// `min ½ Δpᵀ S Δp + bᵀ Δp` over `lo ≤ Δp ≤ hi`, by Clarabel (`m` variables).
pub(super) struct BoxQp {
    m: usize,
    solver: DefaultSolver<f64>,
    /// Buffers for the data updates (Clarabel takes `Vec`s).
    p: Vec<f64>,
    q: Vec<f64>,
    b: Vec<f64>,
}

impl std::fmt::Debug for BoxQp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "BoxQp({})", self.m)
    }
}

impl BoxQp {
    fn new(m: usize, tol: f64) -> Result<BoxQp, MheError> {
        // P: the upper triangle of a dense m × m, column by column; A = [I; −I].
        let mut p = Pattern::new(m, m);
        for c in 0..m {
            for r in 0..=c {
                p.push(r, c);
            }
        }
        p.compile();
        let mut a = Pattern::new(2 * m, m);
        for k in 0..m {
            a.push(k, k);
            a.push(m + k, k);
        }
        a.compile();
        let identity: Vec<f64> = (0..m)
            .flat_map(|c| (0..=c).map(move |r| if r == c { 1.0 } else { 0.0 }))
            .collect();
        let signs: Vec<f64> = (0..m).flat_map(|_| [1.0, -1.0]).collect();
        let solver = DefaultSolver::new(
            &p.csc(&identity),
            &vec![0.0; m],
            &a.csc(&signs),
            &vec![1.0; 2 * m],
            &[SupportedConeT::NonnegativeConeT(2 * m)],
            clarabel_settings(tol)?,
        )
        .map_err(|e| MheError::Solve(format!("Clarabel setup: {e}")))?;
        Ok(BoxQp {
            m,
            solver,
            p: vec![0.0; m * (m + 1) / 2],
            q: vec![0.0; m],
            b: vec![0.0; 2 * m],
        })
    }

    /// `s` column-major `m × m`; `b`, `lo`, `hi` of length `m`.
    fn solve(
        &mut self,
        s: &[f64],
        b: &[f64],
        lo: &[f64],
        hi: &[f64],
    ) -> Result<Vec<f64>, MheError> {
        let m = self.m;
        let update =
            |e: clarabel::solver::DataUpdateError| MheError::Solve(format!("Clarabel update: {e}"));
        // The upper triangle in CSC order; rows of A: Δp, then −Δp.
        let mut v = 0;
        for c in 0..m {
            for r in 0..=c {
                self.p[v] = s[c * m + r];
                v += 1;
            }
        }
        self.q.copy_from_slice(b);
        for k in 0..m {
            self.b[k] = hi[k];
            self.b[m + k] = -lo[k];
        }
        self.solver.update_P(&self.p).map_err(update)?;
        self.solver.update_q(&self.q).map_err(update)?;
        self.solver.update_b(&self.b).map_err(update)?;
        self.solver.solve();
        clarabel_result(&self.solver)
    }
}

impl std::fmt::Debug for FullQp {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "FullQp({} stages)", self.stages)
    }
}

/// The whole MHE QP for Clarabel: variables `(Δx_0..Δx_{n}, Δp)`, `P = JᵀJ` (upper
/// triangle of the block-tridiagonal-with-border pattern), bounds on `Δp`.
pub(super) struct FullQp {
    stages: usize,
    nx: usize,
    np: usize,
    solver: DefaultSolver<f64>,
    pattern: Pattern,
    values: Vec<f64>,
    nzval: Vec<f64>,
    q: Vec<f64>,
    b: Vec<f64>,
}

impl FullQp {
    fn new(stages: usize, nx: usize, np: usize, tol: f64) -> Result<FullQp, MheError> {
        let nv = stages * nx + np;
        let mut pattern = Pattern::new(nv, nv);
        // Declared in the order `solve` fills the values; a positive diagonal
        // for the set-up (the values change before every solve).
        let mut diag = Vec::new();
        for i in 0..stages {
            for r in 0..nx {
                for c in r..nx {
                    pattern.push(i * nx + r, i * nx + c);
                    diag.push(if r == c { 1.0 } else { 0.0 });
                }
            }
            if i + 1 < stages {
                for r in 0..nx {
                    for c in 0..nx {
                        pattern.push(i * nx + r, (i + 1) * nx + c);
                        diag.push(0.0);
                    }
                }
            }
            for r in 0..nx {
                for c in 0..np {
                    pattern.push(i * nx + r, stages * nx + c);
                    diag.push(0.0);
                }
            }
        }
        for r in 0..np {
            for c in r..np {
                pattern.push(stages * nx + r, stages * nx + c);
                diag.push(if r == c { 1.0 } else { 0.0 });
            }
        }
        pattern.compile();
        let values = vec![0.0; pattern.len()];
        let mut a = Pattern::new(2 * np, nv);
        for k in 0..np {
            a.push(2 * k, stages * nx + k);
            a.push(2 * k + 1, stages * nx + k);
        }
        a.compile();
        let signs: Vec<f64> = (0..np).flat_map(|_| [1.0, -1.0]).collect();
        let a_csc = a.csc(&signs);
        let p_csc = pattern.csc(&diag);
        let solver = DefaultSolver::new(
            &p_csc,
            &vec![0.0; nv],
            &a_csc,
            &vec![1.0; 2 * np],
            &[SupportedConeT::NonnegativeConeT(2 * np)],
            clarabel_settings(tol)?,
        )
        .map_err(|e| MheError::Solve(format!("Clarabel setup: {e}")))?;
        Ok(FullQp {
            stages,
            nx,
            np,
            solver,
            nzval: vec![0.0; p_csc.nzval.len()],
            pattern,
            values,
            q: vec![0.0; nv],
            b: vec![0.0; 2 * np],
        })
    }

    fn solve<const NX: usize, const NP: usize>(
        &mut self,
        blocks: &[Blocks<NX, NP>],
        hpp: &Matrix<NP, NP>,
        gp: &Vector<NP>,
        lo: &Vector<NP>,
        hi: &Vector<NP>,
    ) -> Result<Vec<f64>, MheError> {
        if (self.nx, self.np) != (NX, NP) || blocks.len() != self.stages {
            return Err(MheError::Solve("the QP was built for another size".into()));
        }
        let mut v = 0;
        let mut put = |value: f64| {
            self.values[v] = value;
            v += 1;
        };
        for (i, b) in blocks.iter().enumerate() {
            for r in 0..NX {
                for c in r..NX {
                    put(0.5 * (b.d[(r, c)] + b.d[(c, r)]));
                }
            }
            if i + 1 < self.stages {
                for r in 0..NX {
                    for c in 0..NX {
                        put(b.o[(r, c)]);
                    }
                }
            }
            for r in 0..NX {
                for c in 0..NP {
                    put(b.c[(c, r)]);
                }
            }
        }
        for r in 0..NP {
            for c in r..NP {
                put(0.5 * (hpp[(r, c)] + hpp[(c, r)]));
            }
        }
        for (i, b) in blocks.iter().enumerate() {
            self.q[i * NX..(i + 1) * NX].copy_from_slice(b.g.as_slice());
        }
        self.q[self.stages * NX..].copy_from_slice(gp.as_slice());
        self.pattern.scatter(&self.values, &mut self.nzval);
        let update =
            |e: clarabel::solver::DataUpdateError| MheError::Solve(format!("Clarabel update: {e}"));
        for k in 0..NP {
            self.b[2 * k] = hi[k];
            self.b[2 * k + 1] = -lo[k];
        }
        self.solver.update_P(&self.nzval).map_err(update)?;
        self.solver.update_q(&self.q).map_err(update)?;
        self.solver.update_b(&self.b).map_err(update)?;
        self.solver.solve();
        clarabel_result(&self.solver)
    }
}
