//! The QP with its bounds by a primal-dual interior-point method whose Newton
//! steps are Riccati recursions over the stages (as HPIPM does), for the
//! samples where the equality-constrained solution violates a bound.
//!
//! The bounds are boxes on single components (each torque of `Δu_k`, the speed
//! and yaw rate of `Δx_{k+1}`), so each Newton step is the equality-constrained
//! QP again with the barrier's diagonal added to the stage weights and a
//! modified gradient: one backward recursion, one forward sweep, linear in
//! `N`. Mehrotra's predictor-corrector: two recursions per iteration.
//!
//! Every bounded component `z` has slacks `s_l = z − lb`, `s_u = ub − z` and
//! multipliers `λ_l`, `λ_u`. Starting from the equality-constrained solution
//! with `λ_l = λ_u`, the stationarity of the Lagrangian holds exactly at the
//! start, and every step (one step length for all) keeps it; the iteration
//! stops when the slacks' residuals and the complementarity are below the
//! tolerance. A Riccati pivot that is not positive, a step that stalls, or no
//! convergence in [`MAX_ITERATIONS`] returns `None`, and Clarabel solves the QP.

use super::{NU, NX, Nmpc};
use crate::algorithms::mpc::linalg::{Mat, cholesky, cholesky_solve};

/// Bounded components per stage: the torques of `Δu_k`, then the speed and
/// yaw rate of `Δx_{k+1}`.
const NB: usize = NU + 2;
/// The state components that have bounds.
const BOUNDED_X: [usize; 2] = [3, 4];
/// The multipliers' start. Measured on the peers' lap (`bench_nmpc`, mean
/// iterations at N = 20 / 50): 1.0 -> 8.0 / 7.8, 0.1 -> 6.8 / 6.5, 0.01 ->
/// 7.5 / 7.4, 0.001 -> 7.5 / 7.4.
const START_MULTIPLIER: f64 = 0.1;
/// Iterations before giving the QP to Clarabel.
pub(super) const MAX_ITERATIONS: usize = 40;

/// One component's box and its slacks and multipliers.
#[derive(Clone, Copy, Debug, Default)]
struct Bound {
    lb: f64,
    ub: f64,
    s_l: f64,
    s_u: f64,
    l_l: f64,
    l_u: f64,
}

/// A direction: the trajectory and the slacks' and multipliers' steps.
#[derive(Clone, Debug, Default)]
struct Direction {
    du: Vec<[f64; NU]>,
    dx: Vec<[f64; NX]>,
    s_l: Vec<f64>,
    s_u: Vec<f64>,
    l_l: Vec<f64>,
    l_u: Vec<f64>,
}

impl Direction {
    fn new(n: usize) -> Direction {
        Direction {
            du: vec![[0.0; NU]; n],
            dx: vec![[0.0; NX]; n + 1],
            s_l: vec![0.0; n * NB],
            s_u: vec![0.0; n * NB],
            l_l: vec![0.0; n * NB],
            l_u: vec![0.0; n * NB],
        }
    }
}

/// The method's memory, allocated once for the horizon.
#[derive(Clone, Debug, Default)]
pub(super) struct IpmWork {
    bounds: Vec<Bound>,
    du: Vec<[f64; NU]>,
    dx: Vec<[f64; NX]>,
    aff: Direction,
    dir: Direction,
    /// The cost's own gradient (the barrier's terms are added per solve).
    r_grad: Vec<[f64; NU]>,
    q_grad: Vec<[f64; NX]>,
    r_lin: Vec<[f64; NU]>,
    q_lin: Vec<[f64; NX]>,
    /// Per stage `k`: `P_{k+1}`, the Cholesky factor of `H_uu`, and `H_ux`:
    /// the factorisation both of an iteration's solves use.
    p_next: Vec<Mat<NX, NX>>,
    chol: Vec<Mat<NU, NU>>,
    hux: Vec<Mat<NU, NX>>,
}

impl IpmWork {
    pub(super) fn new(n: usize) -> IpmWork {
        IpmWork {
            bounds: vec![Bound::default(); n * NB],
            du: vec![[0.0; NU]; n],
            dx: vec![[0.0; NX]; n + 1],
            aff: Direction::new(n),
            dir: Direction::new(n),
            r_grad: vec![[0.0; NU]; n],
            q_grad: vec![[0.0; NX]; n + 1],
            r_lin: vec![[0.0; NU]; n],
            q_lin: vec![[0.0; NX]; n + 1],
            p_next: vec![Mat::zero(); n],
            chol: vec![Mat::zero(); n],
            hux: vec![Mat::zero(); n],
        }
    }
}

/// The bounded component `b` of stage `k`'s variables.
fn value(du: &[[f64; NU]], dx: &[[f64; NX]], k: usize, b: usize) -> f64 {
    if b < NU {
        du[k][b]
    } else {
        dx[k + 1][BOUNDED_X[b - NU]]
    }
}

impl Nmpc {
    /// Solve the QP of the current linearisation with `Δx_0 = dx0` and its
    /// bounds into `self.du`, `self.dx`; the iterations, or `None` if it did
    /// not converge (then `self.du`, `self.dx` are not a solution). Expects
    /// `self.du`, `self.dx` to hold the equality-constrained solution.
    pub(super) fn ipm(&mut self, dx0: &[f64; NX]) -> Option<usize> {
        let mut w = std::mem::take(&mut self.work);
        if w.bounds.len() != self.s.horizon * NB {
            w = IpmWork::new(self.s.horizon);
        }
        let result = self.ipm_with(dx0, &mut w);
        self.work = w;
        result
    }

    fn ipm_with(&mut self, dx0: &[f64; NX], w: &mut IpmWork) -> Option<usize> {
        let n = self.s.horizon;
        let tol = self.s.qp_tolerance;
        for k in 0..n {
            w.r_grad[k] = std::array::from_fn(|i| 2.0 * self.s.r[i] * self.us[k][i]);
            w.q_grad[k + 1] = self.gradient_x(k + 1);
        }
        // The boxes, in deltas from the current iterate; the start: the
        // equality-constrained solution, slacks at least a tenth of the box
        // from zero, equal multipliers on both sides (so that stationarity
        // holds).
        w.du.copy_from_slice(&self.du);
        w.dx.copy_from_slice(&self.dx);
        for k in 0..n {
            for b in 0..NB {
                let (limit, at) = if b < NU {
                    (self.s.torque_max, self.us[k][b])
                } else if b == NU {
                    (self.s.speed_max, self.xs[k + 1][3])
                } else {
                    (self.s.yaw_rate_max, self.xs[k + 1][4])
                };
                let (lb, ub) = (-limit - at, limit - at);
                let z = value(&w.du, &w.dx, k, b);
                let floor = 0.1 * (ub - lb);
                w.bounds[k * NB + b] = Bound {
                    lb,
                    ub,
                    s_l: (z - lb).max(floor),
                    s_u: (ub - z).max(floor),
                    l_l: START_MULTIPLIER,
                    l_u: START_MULTIPLIER,
                };
            }
        }
        let m = (2 * n * NB) as f64;
        for iteration in 0..MAX_ITERATIONS {
            let mu = w
                .bounds
                .iter()
                .map(|b| b.s_l * b.l_l + b.s_u * b.l_u)
                .sum::<f64>()
                / m;
            let residual = (0..n * NB)
                .map(|j| {
                    let z = value(&w.du, &w.dx, j / NB, j % NB);
                    let b = &w.bounds[j];
                    (z - b.s_l - b.lb).abs().max((b.ub - z - b.s_u).abs())
                })
                .fold(0.0f64, f64::max);
            if !(mu.is_finite() && residual.is_finite()) {
                return None;
            }
            // The torques' multipliers are small (the torque weight is
            // 1e-3), so the complementarity must go far below the tolerance
            // for the solution to be within it (measured against Clarabel at
            // 1e-10: 2e-6 apart with `μ ≤ 1e-8`, within 1e-8 with `μ ≤ 1e-12`).
            if mu <= tol * 1e-6 && residual <= tol * 1e-2 {
                self.du.copy_from_slice(&w.du);
                self.dx.copy_from_slice(&w.dx);
                return Some(iteration);
            }
            self.factor(w)?;
            // Predictor: the affine direction (complementarity target 0).
            let mut aff = std::mem::take(&mut w.aff);
            self.direction(dx0, w, |_| (0.0, 0.0), &mut aff)?;
            let a_aff = step_length(&w.bounds, &aff, 1.0);
            let mu_aff = w
                .bounds
                .iter()
                .enumerate()
                .map(|(j, b)| {
                    (b.s_l + a_aff * aff.s_l[j]) * (b.l_l + a_aff * aff.l_l[j])
                        + (b.s_u + a_aff * aff.s_u[j]) * (b.l_u + a_aff * aff.l_u[j])
                })
                .sum::<f64>()
                / m;
            let sigma = (mu_aff / mu).clamp(0.0, 1.0).powi(3);
            // Corrector: centred, with the predictor's second-order term.
            let target = |j: usize| {
                (
                    sigma * mu - aff.s_l[j] * aff.l_l[j],
                    sigma * mu - aff.s_u[j] * aff.l_u[j],
                )
            };
            let mut dir = std::mem::take(&mut w.dir);
            let solved = self.direction(dx0, w, target, &mut dir);
            w.aff = aff;
            solved?;
            let alpha = step_length(&w.bounds, &dir, 0.995);
            if alpha < 1e-10 {
                w.dir = dir;
                return None;
            }
            for k in 0..n {
                for i in 0..NU {
                    w.du[k][i] += alpha * dir.du[k][i];
                }
                for i in 0..NX {
                    w.dx[k + 1][i] += alpha * dir.dx[k + 1][i];
                }
            }
            for (j, b) in w.bounds.iter_mut().enumerate() {
                b.s_l += alpha * dir.s_l[j];
                b.s_u += alpha * dir.s_u[j];
                b.l_l += alpha * dir.l_l[j];
                b.l_u += alpha * dir.l_u[j];
            }
            w.dir = dir;
        }
        None
    }

    /// The backward Riccati recursion's matrices for the stage weights with
    /// the barrier's diagonal: the gains into the stages, the rest into `w`;
    /// `None` if a pivot is not positive.
    fn factor(&mut self, w: &mut IpmWork) -> Option<()> {
        let n = self.s.horizon;
        let barrier = |k: usize, b: usize| {
            let bd = &w.bounds[k * NB + b];
            bd.l_l / bd.s_l + bd.l_u / bd.s_u
        };
        let q_diag = |k: usize| {
            let q = if k == n {
                &self.s.q_terminal
            } else {
                &self.s.q
            };
            let mut d = q.map(|v| 2.0 * v);
            for (b, &i) in BOUNDED_X.iter().enumerate() {
                d[i] += barrier(k - 1, NU + b);
            }
            d
        };
        let mut p = Mat::<NX, NX>::diag(q_diag(n));
        for k in (0..n).rev() {
            let st = &self.stages[k];
            let pa = p.mul(&st.a);
            let pb = p.mul(&st.b);
            let mut huu = st.b.tmul(&pb);
            for i in 0..NU {
                huu.0[i][i] += 2.0 * self.s.r[i] + barrier(k, i);
            }
            let hux = st.b.tmul(&pa);
            let l = cholesky(&huu)?;
            let mut kmat = Mat::<NU, NX>::zero();
            for c in 0..NX {
                let col = cholesky_solve(&l, &std::array::from_fn(|r| hux.0[r][c]));
                for r in 0..NU {
                    kmat.0[r][c] = -col[r];
                }
            }
            w.p_next[k] = p;
            w.chol[k] = l;
            w.hux[k] = hux;
            if k > 0 {
                let mut next = st.a.tmul(&pa).add(&hux.tmul(&kmat));
                let q = q_diag(k);
                for i in 0..NX {
                    next.0[i][i] += q[i];
                }
                p = next.symmetrised();
            }
            self.stages[k].gain = kmat;
        }
        Some(())
    }

    /// The Newton direction from `(w.du, w.dx, w.bounds)` towards the
    /// complementarity targets `target(j) = (t_l, t_u)`, on the factorisation
    /// of [`Nmpc::factor`], into `out`; `None` if it is not finite.
    fn direction(
        &mut self,
        dx0: &[f64; NX],
        w: &mut IpmWork,
        target: impl Fn(usize) -> (f64, f64),
        out: &mut Direction,
    ) -> Option<()> {
        let n = self.s.horizon;
        // The gradient: the cost's, and the barrier's terms.
        w.r_lin.copy_from_slice(&w.r_grad);
        w.q_lin.copy_from_slice(&w.q_grad);
        for j in 0..n * NB {
            let (k, b) = (j / NB, j % NB);
            let bd = &w.bounds[j];
            let (t_l, t_u) = target(j);
            let (d_l, d_u) = (bd.l_l / bd.s_l, bd.l_u / bd.s_u);
            let g = -t_l / bd.s_l + t_u / bd.s_u - bd.l_l + bd.l_u - d_l * bd.lb - d_u * bd.ub;
            if b < NU {
                w.r_lin[k][b] += g;
            } else {
                w.q_lin[k + 1][BOUNDED_X[b - NU]] += g;
            }
        }
        // The backward pass of the vectors.
        let mut pv = w.q_lin[n];
        for k in (0..n).rev() {
            let st = &self.stages[k];
            let h: [f64; NX] = std::array::from_fn(|i| w.p_next[k].row_dot(i, &st.d) + pv[i]);
            let hu: [f64; NU] = std::array::from_fn(|i| w.r_lin[k][i] + st.b.col_dot(i, &h));
            let kff = cholesky_solve(&w.chol[k], &hu).map(|v| -v);
            if k > 0 {
                pv = std::array::from_fn(|i| {
                    w.q_lin[k][i] + st.a.col_dot(i, &h) + w.hux[k].col_dot(i, &kff)
                });
            }
            self.stages[k].ff = kff;
        }
        // The new trajectory, then the direction to it.
        out.dx[0] = *dx0;
        for k in 0..n {
            let st = &self.stages[k];
            let x = out.dx[k];
            out.du[k] = std::array::from_fn(|i| st.gain.row_dot(i, &x) + st.ff[i]);
            let u = out.du[k];
            out.dx[k + 1] =
                std::array::from_fn(|i| st.a.row_dot(i, &x) + st.b.row_dot(i, &u) + st.d[i]);
        }
        for k in 0..n {
            for i in 0..NU {
                out.du[k][i] -= w.du[k][i];
            }
            for i in 0..NX {
                out.dx[k + 1][i] -= w.dx[k + 1][i];
            }
        }
        for j in 0..n * NB {
            let (k, b) = (j / NB, j % NB);
            let bd = &w.bounds[j];
            let (t_l, t_u) = target(j);
            let z = value(&w.du, &w.dx, k, b);
            let dz = value(&out.du, &out.dx, k, b);
            let ds_l = dz + (z - bd.s_l - bd.lb);
            let ds_u = -dz + (bd.ub - z - bd.s_u);
            out.s_l[j] = ds_l;
            out.s_u[j] = ds_u;
            out.l_l[j] = (t_l - bd.s_l * bd.l_l - bd.l_l * ds_l) / bd.s_l;
            out.l_u[j] = (t_u - bd.s_u * bd.l_u - bd.l_u * ds_u) / bd.s_u;
        }
        let finite = out.du.iter().flatten().chain(out.dx.iter().flatten());
        let finite = finite
            .chain(&out.s_l)
            .chain(&out.s_u)
            .chain(&out.l_l)
            .chain(&out.l_u)
            .all(|v| v.is_finite());
        finite.then_some(())
    }
}

/// The longest step `≤ 1`, times `fraction`, that keeps every slack and
/// multiplier positive.
fn step_length(bounds: &[Bound], d: &Direction, fraction: f64) -> f64 {
    let mut alpha = 1.0f64;
    for (j, b) in bounds.iter().enumerate() {
        for (v, dv) in [
            (b.s_l, d.s_l[j]),
            (b.s_u, d.s_u[j]),
            (b.l_l, d.l_l[j]),
            (b.l_u, d.l_u[j]),
        ] {
            if dv < 0.0 {
                alpha = alpha.min(-fraction * v / dv);
            }
        }
    }
    alpha.min(1.0)
}
