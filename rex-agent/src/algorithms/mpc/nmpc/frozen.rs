//! The QP of one real-time iteration, frozen: to solve it again by each method
//! (the structured one, Clarabel) and to hand it to another solver in the
//! common sparse form, for comparisons such as `bench_qp`. Nothing here is on
//! the controller's path.

use super::qp::ClarabelQp;
use super::{Nmpc, NmpcError};
use crate::model::{Dynamics, NU, Vector};

/// The QP that [`Nmpc::feedback`] would solve after the last
/// [`Nmpc::prepare`], with its `Δx_0`; see [`Nmpc::freeze_qp`].
#[derive(Debug)]
pub struct FrozenQp<M: Dynamics<NX, NP>, const NX: usize, const NP: usize> {
    nmpc: Nmpc<M, NX, NP>,
    dx0: Vector<NX>,
}

/// A solution of a [`FrozenQp`].
#[derive(Clone, Debug, PartialEq)]
pub struct QpSolution {
    /// The step `Δw`: per stage `Δu_k` (4), then `Δx_{k+1}` (`NX`).
    pub step: Vec<f64>,
    /// The iterations (0: the Riccati solution met every bound).
    pub iterations: usize,
}

/// A QP in the form `min ½ zᵀ P z + qᵀ z` subject to `l ≤ A z ≤ u`, `P`
/// diagonal, `A` as triplets whose pattern is the same for every QP of one
/// controller (explicit zeros kept): the equalities of the dynamics first
/// (`l = u`), then one row per bounded variable.
#[derive(Clone, Debug, PartialEq)]
pub struct SparseQp {
    /// Variables.
    pub n: usize,
    /// Rows of `A`.
    pub m: usize,
    /// Rows that are equalities (the first ones).
    pub m_eq: usize,
    /// The diagonal of `P`.
    pub p_diag: Vec<f64>,
    /// The linear term.
    pub q: Vec<f64>,
    /// `A`'s rows, columns and values.
    pub a_rows: Vec<usize>,
    /// See `a_rows`.
    pub a_cols: Vec<usize>,
    /// See `a_rows`.
    pub a_values: Vec<f64>,
    /// Lower bounds of the rows.
    pub l: Vec<f64>,
    /// Upper bounds of the rows.
    pub u: Vec<f64>,
}

impl SparseQp {
    /// `½ zᵀ P z + qᵀ z`.
    pub fn objective(&self, z: &[f64]) -> f64 {
        z.iter()
            .zip(&self.p_diag)
            .zip(&self.q)
            .map(|((z, p), q)| 0.5 * p * z * z + q * z)
            .sum()
    }

    /// The largest violation of `l ≤ A z ≤ u`.
    pub fn violation(&self, z: &[f64]) -> f64 {
        let mut az = vec![0.0; self.m];
        for ((r, c), v) in self.a_rows.iter().zip(&self.a_cols).zip(&self.a_values) {
            az[*r] += v * z[*c];
        }
        az.iter()
            .zip(self.l.iter().zip(&self.u))
            .map(|(a, (l, u))| (l - a).max(a - u).max(0.0))
            .fold(0.0, f64::max)
    }
}

/// Clarabel set up once for the QPs of one controller; each solve updates its
/// data in place (as the controller's fallback does).
#[derive(Debug)]
pub struct ClarabelWorkspace(ClarabelQp);

impl<M: Dynamics<NX, NP>, const NX: usize, const NP: usize> Nmpc<M, NX, NP> {
    /// The QP the next [`Nmpc::feedback`] with `x_hat` solves (after
    /// [`Nmpc::prepare`]), frozen; the controller is not changed.
    pub fn freeze_qp(&self, x_hat: &[f64; NX]) -> Result<FrozenQp<M, NX, NP>, NmpcError> {
        if !self.prepared {
            return Err(NmpcError::NotPrepared);
        }
        super::check_finite(x_hat, "state estimate")?;
        // A fresh controller (no Clarabel set up, empty statistics) holding
        // this one's problem and linearisation.
        let mut nmpc = Nmpc::new(self.model.clone(), self.s.clone())?;
        nmpc.xs.clone_from(&self.xs);
        nmpc.us.clone_from(&self.us);
        nmpc.reference.clone_from(&self.reference);
        nmpc.stages.clone_from(&self.stages);
        nmpc.p = self.p;
        nmpc.limits = self.limits;
        nmpc.disturbance = self.disturbance;
        nmpc.prepared = true;
        nmpc.warm = self.warm;
        nmpc.ipm_start.clone_from(&self.ipm_start);
        Ok(FrozenQp {
            dx0: Vector::from(*x_hat) - self.xs[0],
            nmpc,
        })
    }
}

impl<M: Dynamics<NX, NP>, const NX: usize, const NP: usize> FrozenQp<M, NX, NP> {
    /// The step of the last solve, in the layout of [`QpSolution::step`].
    fn step(&self) -> Vec<f64> {
        let c = &self.nmpc;
        let mut w = Vec::with_capacity(c.s.horizon * (NU + NX));
        for k in 0..c.s.horizon {
            w.extend(c.du[k].iter());
            w.extend(c.dx[k + 1].iter());
        }
        w
    }

    /// Solved as the controller solves it: the Riccati recursion, kept when it
    /// meets every bound, else the interior-point method on the stages, from
    /// the controller's start when frozen (each solve from the same one).
    pub fn solve_structured(&mut self) -> Result<QpSolution, NmpcError> {
        let dx0 = self.dx0;
        self.nmpc.riccati()?;
        let iterations = if self.nmpc.forward(&dx0) {
            0
        } else {
            self.nmpc
                .ipm(&dx0)
                .ok_or_else(|| NmpcError::Qp("the interior-point method did not converge".into()))?
        };
        Ok(QpSolution {
            step: self.step(),
            iterations,
        })
    }

    /// The same QP, its interior-point solves starting cold (every multiplier
    /// at the same value) instead of from the controller's last solution.
    pub fn cold(mut self) -> FrozenQp<M, NX, NP> {
        self.nmpc.ipm_start.clear();
        self
    }

    /// Whether a bound is active (the Riccati solution violates one).
    pub fn active(&mut self) -> Result<bool, NmpcError> {
        let dx0 = self.dx0;
        self.nmpc.riccati()?;
        Ok(!self.nmpc.forward(&dx0))
    }

    /// Clarabel set up for this QP's controller, at tolerance `tol`.
    pub fn clarabel(&self, tol: f64) -> Result<ClarabelWorkspace, NmpcError> {
        let s = super::NmpcSettings {
            qp_tolerance: tol,
            ..self.nmpc.s.clone()
        };
        Ok(ClarabelWorkspace(ClarabelQp::new(
            &s,
            [M::SPEED, M::YAW_RATE],
        )?))
    }

    /// Solved by Clarabel in `workspace` (its data updated in place).
    pub fn solve_clarabel(
        &self,
        workspace: &mut ClarabelWorkspace,
    ) -> Result<QpSolution, NmpcError> {
        let data = self.nmpc.qp_data(&self.dx0);
        let (step, iterations) = workspace.0.solve(&data)?;
        Ok(QpSolution {
            step,
            iterations: iterations as usize,
        })
    }

    /// The QP in the common sparse form (the same problem Clarabel solves,
    /// each pair of opposite inequalities as one row with two bounds).
    pub fn sparse(&self) -> SparseQp {
        let c = &self.nmpc;
        let n = c.s.horizon;
        let nz = NU + NX;
        let data = c.qp_data(&self.dx0);
        let mut p_diag = Vec::with_capacity(n * nz);
        for k in 0..n {
            p_diag.extend(c.s.r.iter().map(|r| 2.0 * r));
            p_diag.extend(c.weights(k + 1).iter().map(|w| 2.0 * w));
        }
        let (mut rows, mut cols, mut values) = (Vec::new(), Vec::new(), Vec::new());
        let mut a = data.a.iter();
        let mut next = || a.next().copied().unwrap_or(0.0);
        // Equalities, in `qp_data`'s order: Δx_{k+1}, then −B_k, then −A_k.
        for k in 0..n {
            for i in 0..NX {
                let row = k * NX + i;
                rows.push(row);
                cols.push(k * nz + NU + i);
                values.push(next());
                for j in 0..NU {
                    rows.push(row);
                    cols.push(k * nz + j);
                    values.push(next());
                }
                if k > 0 {
                    for j in 0..NX {
                        rows.push(row);
                        cols.push((k - 1) * nz + NU + j);
                        values.push(next());
                    }
                }
            }
        }
        let m_eq = n * NX;
        let mut l = data.b[..m_eq].to_vec();
        let mut u = l.clone();
        // Boxes: `qp_data` gives `z ≤ b⁺` and `−z ≤ b⁻` for each.
        let mut row = m_eq;
        let mut b = data.b[m_eq..].chunks_exact(2);
        for k in 0..n {
            let bounded = (0..NU).chain([NU + M::SPEED, NU + M::YAW_RATE]);
            for j in bounded {
                let (plus, minus) = b.next().map_or((0.0, 0.0), |p| (p[0], p[1]));
                rows.push(row);
                cols.push(k * nz + j);
                values.push(1.0);
                l.push(-minus);
                u.push(plus);
                row += 1;
            }
        }
        SparseQp {
            n: n * nz,
            m: row,
            m_eq,
            p_diag,
            q: data.q,
            a_rows: rows,
            a_cols: cols,
            a_values: values,
            l,
            u,
        }
    }
}
