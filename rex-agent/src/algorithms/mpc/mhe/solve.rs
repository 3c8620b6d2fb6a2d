//! Solving the MHE's normal equations: exactly in `O(N)` by a block Cholesky
//! factorisation of the states' part and the 3 × 3 Schur complement of the slip
//! parameters, with Clarabel on the reduced box QP in `Δp` when a parameter bound
//! is hit ([`QpStrategy::Structured`](super::QpStrategy::Structured)); or the whole
//! QP in `(Δx, Δp)` by Clarabel ([`QpStrategy::Clarabel`](super::QpStrategy::Clarabel)).

use clarabel::algebra::CscMatrix;
use clarabel::solver::{
    DefaultSettings, DefaultSettingsBuilder, DefaultSolver, IPSolver, SolverStatus, SupportedConeT,
};

use super::{Blocks, Mhe, MheError, NP, NX};
use crate::algorithms::mpc::linalg::{Mat, cholesky, cholesky_solve};
use crate::algorithms::mpc::sparse::Pattern;

impl Mhe {
    /// Solve the normal equations by block Cholesky (states) and the Schur
    /// complement (parameters); Clarabel on the reduced box QP when a bound is hit.
    pub(super) fn solve_structured(
        &mut self,
        n: usize,
    ) -> Result<(Vec<[f64; NX]>, [f64; NP]), MheError> {
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
    pub(super) fn solve_full(&mut self, n: usize) -> Result<(Vec<[f64; NX]>, [f64; NP]), MheError> {
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
pub(super) struct BoxQp {
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
pub(super) struct FullQp {
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
