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
//! multipliers `λ_l`, `λ_u`. The start is the equality-constrained solution
//! with the previous solve's multipliers ([`IpmStart`]), or `λ_l = λ_u`
//! everywhere. The stationarity of the Lagrangian is then off by `λ_u − λ_l`
//! in each bounded component (nothing else: the equality-constrained solution
//! is stationary without bounds), and the Newton steps are linear in it, so a
//! step of length `α` (one for all) scales it by `1 − α`: it is tracked as that
//! product, and is zero all along from a cold start. The iteration stops when
//! it, the slacks' residuals and the complementarity are below the tolerance.
//! A Riccati pivot that is not positive, a step that stalls, or no convergence
//! in [`MAX_ITERATIONS`] returns `None`, and Clarabel solves the QP.

use super::{Nmpc, UuFactor, spd_cholesky};
use crate::model::{Dynamics, Matrix, NU, Vector};

/// Bounded components per stage: the torques of `Δu_k`, then the speed and
/// yaw rate of `Δx_{k+1}` (the model's [`Dynamics::SPEED`] and
/// [`Dynamics::YAW_RATE`]).
const NB: usize = NU + 2;
/// The multipliers' start: of the values tried, the one that took the fewest
/// iterations on the peers' lap at N = 20 and 50 (`bench_nmpc`; the sweep is in
/// docs/measurements.md, "The interior point's start").
const START_MULTIPLIER: f64 = 0.1;
/// Iterations before giving the QP to Clarabel.
pub(super) const MAX_ITERATIONS: usize = 40;
/// The least multiplier of a warm start (below, [`IpmStart`]): of the floors
/// tried, the one with the fewest iterations on the peers' lap, fewer than a
/// cold start's. The slacks keep a cold start's floor (a tenth of the box),
/// which was best for a warm start too. The sweeps: docs/measurements.md, "The
/// interior point's start".
const WARM_FLOOR: f64 = 0.01;

/// Where the next solve starts its multipliers: the last converged solve's,
/// shifted a stage with the trajectory (the real-time iteration's QPs follow
/// each other closely), each at least [`WARM_FLOOR`]; or, when the last QP
/// had no active bound or was not solved here, every multiplier at
/// [`START_MULTIPLIER`].
#[derive(Clone, Debug, Default)]
pub(super) struct IpmStart {
    /// `(λ_l, λ_u)` per bounded component, as [`IpmWork::bounds`].
    multipliers: Vec<(f64, f64)>,
    valid: bool,
}

impl IpmStart {
    pub(super) fn new(n: usize) -> IpmStart {
        IpmStart {
            multipliers: vec![(0.0, 0.0); n * NB],
            valid: false,
        }
    }

    /// Forget the multipliers (the next solve starts cold).
    pub(super) fn clear(&mut self) {
        self.valid = false;
    }

    /// Shift the multipliers one stage, as the trajectory; the last stage
    /// keeps its own.
    pub(super) fn shift(&mut self) {
        if self.multipliers.len() > NB {
            self.multipliers.copy_within(NB.., 0);
        }
    }

    /// The start of bound `j`'s multipliers.
    fn at(&self, j: usize) -> (f64, f64) {
        match self.multipliers.get(j) {
            Some(&(l, u)) if self.valid => (l.max(WARM_FLOOR), u.max(WARM_FLOOR)),
            _ => (START_MULTIPLIER, START_MULTIPLIER),
        }
    }
}

/// A bounded component's slacks and multipliers (or their steps): below
/// (`s_l = z − lb`, `λ_l`) and above (`s_u = ub − z`, `λ_u`).
#[derive(Clone, Copy, Debug, Default)]
struct Slacks {
    s_l: f64,
    s_u: f64,
    l_l: f64,
    l_u: f64,
}

/// One component's box and its slacks and multipliers.
#[derive(Clone, Copy, Debug, Default)]
struct Bound {
    lb: f64,
    ub: f64,
    at: Slacks,
    /// `1 / s_l`, `1 / s_u` of the iteration: each iteration's factorisation
    /// and its two directions divide by the slacks a dozen times a bound.
    inv_l: f64,
    inv_u: f64,
}

/// A direction: the trajectory and the slacks' and multipliers' steps.
#[derive(Clone, Debug, Default)]
struct Direction<const NX: usize> {
    du: Vec<Vector<NU>>,
    dx: Vec<Vector<NX>>,
    slacks: Vec<Slacks>,
}

impl<const NX: usize> Direction<NX> {
    fn new(n: usize) -> Direction<NX> {
        Direction {
            du: vec![Vector::zeros(); n],
            dx: vec![Vector::zeros(); n + 1],
            slacks: vec![Slacks::default(); n * NB],
        }
    }
}

/// The method's memory, allocated once for the horizon.
#[derive(Clone, Debug, Default)]
pub(super) struct IpmWork<const NX: usize> {
    bounds: Vec<Bound>,
    du: Vec<Vector<NU>>,
    dx: Vec<Vector<NX>>,
    aff: Direction<NX>,
    dir: Direction<NX>,
    /// The cost's own gradient (the barrier's terms are added per solve).
    r_grad: Vec<Vector<NU>>,
    q_grad: Vec<Vector<NX>>,
    r_lin: Vec<Vector<NU>>,
    q_lin: Vec<Vector<NX>>,
    /// Per stage `k`: `P_{k+1}` and the Cholesky factor of `H_uu`: the
    /// factorisation both of an iteration's solves use (with the gains `K`).
    p_next: Vec<Matrix<NX, NX>>,
    chol: Vec<UuFactor>,
}

impl<const NX: usize> IpmWork<NX> {
    pub(super) fn new(n: usize) -> IpmWork<NX> {
        IpmWork {
            bounds: vec![Bound::default(); n * NB],
            du: vec![Vector::zeros(); n],
            dx: vec![Vector::zeros(); n + 1],
            aff: Direction::new(n),
            dir: Direction::new(n),
            r_grad: vec![Vector::zeros(); n],
            q_grad: vec![Vector::zeros(); n + 1],
            r_lin: vec![Vector::zeros(); n],
            q_lin: vec![Vector::zeros(); n + 1],
            p_next: vec![Matrix::zeros(); n],
            chol: vec![UuFactor::pack_dirty(Matrix::identity()); n],
        }
    }

    /// Move the trajectory, the slacks and the multipliers `alpha` along
    /// `self.dir`.
    fn take_step(&mut self, alpha: f64) {
        let dir = &self.dir;
        for k in 0..self.du.len() {
            self.du[k] += dir.du[k] * alpha;
            self.dx[k + 1] += dir.dx[k + 1] * alpha;
        }
        for (b, d) in self.bounds.iter_mut().zip(&dir.slacks) {
            let b = &mut b.at;
            b.s_l += alpha * d.s_l;
            b.s_u += alpha * d.s_u;
            b.l_l += alpha * d.l_l;
            b.l_u += alpha * d.l_u;
        }
    }
}

/// The bounded components of stage `k`'s variables: the torques of `du[k]`,
/// then the components `bounded` of `dx[k + 1]`.
fn values<const NX: usize>(
    du: &[Vector<NU>],
    dx: &[Vector<NX>],
    bounded: [usize; 2],
    k: usize,
) -> [f64; NB] {
    let (u, x) = (&du[k], &dx[k + 1]);
    let mut z = [0.0; NB];
    z[..NU].copy_from_slice(u.as_slice());
    z[NU] = x[bounded[0]];
    z[NU + 1] = x[bounded[1]];
    z
}

impl<M: Dynamics<NX, NP>, const NX: usize, const NP: usize> Nmpc<M, NX, NP> {
    /// The state components with bounds: the speed and the yaw rate.
    const BOUNDED: [usize; 2] = [M::SPEED, M::YAW_RATE];

    /// Solve the QP of the current linearisation with `Δx_0 = dx0` and its
    /// bounds into `self.du`, `self.dx`; the iterations, or `None` if it did
    /// not converge (then `self.du`, `self.dx` are not a solution). Expects
    /// `self.du`, `self.dx` to hold the equality-constrained solution. Starts
    /// from `self.ipm_start`, which it leaves as it is ([`Nmpc::keep_ipm_start`]).
    pub(super) fn ipm(&mut self, dx0: &Vector<NX>) -> Option<usize> {
        let mut w = std::mem::take(&mut self.work);
        if w.bounds.len() != self.s.horizon * NB {
            w = IpmWork::new(self.s.horizon);
        }
        let result = self.ipm_with(dx0, &mut w);
        self.work = w;
        result
    }

    /// The last converged solve's multipliers become the next solve's start.
    pub(super) fn keep_ipm_start(&mut self) {
        let start = &mut self.ipm_start;
        start.multipliers.clear();
        let kept = self.work.bounds.iter().map(|b| (b.at.l_l, b.at.l_u));
        start.multipliers.extend(kept);
        start.valid = true;
    }

    /// The iterations from the equality-constrained solution: each one the
    /// residuals and the convergence test, the factorisation, the predictor and
    /// corrector directions, and the step along the latter.
    fn ipm_with(&mut self, dx0: &Vector<NX>, w: &mut IpmWork<NX>) -> Option<usize> {
        let tol = self.s.qp_tolerance;
        self.cost_gradient(w);
        self.start(w);
        let m = (2 * self.s.horizon * NB) as f64;
        // The stationarity's residual (module docs).
        let mut stationarity = (w.bounds.iter())
            .map(|b| (b.at.l_u - b.at.l_l).abs())
            .fold(0.0f64, f64::max);
        for iteration in 0..MAX_ITERATIONS {
            let mu = mean_complementarity(&w.bounds, m);
            let residual = Self::slack_residual(w);
            if !(mu.is_finite() && residual.is_finite()) {
                return None;
            }
            // The torques' multipliers are small (the torque weight is
            // 1e-3), so the complementarity must go far below the tolerance
            // for the solution to be within it (measured against Clarabel at
            // 1e-10: 2e-6 apart with `μ ≤ 1e-8`, within 1e-8 with `μ ≤ 1e-12`).
            if mu <= tol * 1e-6 && residual <= tol * 1e-2 && stationarity <= tol * 1e-2 {
                self.du.copy_from_slice(&w.du);
                self.dx.copy_from_slice(&w.dx);
                return Some(iteration);
            }
            invert_slacks(&mut w.bounds);
            self.factor(w)?;
            let sigma = self.predictor(dx0, w, mu, m)?;
            let alpha = self.corrector(dx0, w, sigma * mu)?;
            stationarity *= 1.0 - alpha;
            w.take_step(alpha);
        }
        None
    }

    /// The cost's own gradient at the current iterate, into `w`.
    fn cost_gradient(&self, w: &mut IpmWork<NX>) {
        for k in 0..self.s.horizon {
            w.r_grad[k] = self.gradient_u(k);
            w.q_grad[k + 1] = self.gradient_x(k + 1);
        }
    }

    /// The boxes, in deltas from the current iterate, and the start: the
    /// equality-constrained solution, slacks at least a tenth of the box from
    /// zero, the multipliers of `self.ipm_start` (the stationarity is then off
    /// by `λ_u − λ_l`: module docs).
    fn start(&self, w: &mut IpmWork<NX>) {
        w.du.copy_from_slice(&self.du);
        w.dx.copy_from_slice(&self.dx);
        for (k, stage) in w.bounds.chunks_exact_mut(NB).enumerate() {
            let z = values(&w.du, &w.dx, Self::BOUNDED, k);
            for (b, bound) in stage.iter_mut().enumerate() {
                let (limit, at) = if b < NU {
                    (self.limits[b], self.us[k][b])
                } else if b == NU {
                    (self.s.speed_max, self.xs[k + 1][M::SPEED])
                } else {
                    (self.s.yaw_rate_max, self.xs[k + 1][M::YAW_RATE])
                };
                let (lb, ub) = (-limit - at, limit - at);
                let floor = 0.1 * (ub - lb);
                let (l_l, l_u) = self.ipm_start.at(k * NB + b);
                *bound = Bound {
                    lb,
                    ub,
                    at: Slacks {
                        s_l: (z[b] - lb).max(floor),
                        s_u: (ub - z[b]).max(floor),
                        l_l,
                        l_u,
                    },
                    inv_l: 0.0,
                    inv_u: 0.0,
                };
            }
        }
    }

    /// The largest residual of the slacks' definitions `s_l = z − lb`,
    /// `s_u = ub − z` at `(w.du, w.dx)`.
    fn slack_residual(w: &IpmWork<NX>) -> f64 {
        let mut residual = 0.0f64;
        for (k, stage) in w.bounds.chunks_exact(NB).enumerate() {
            let z = values(&w.du, &w.dx, Self::BOUNDED, k);
            for (z, b) in z.iter().zip(stage) {
                residual = residual
                    .max((z - b.at.s_l - b.lb).abs())
                    .max((b.ub - z - b.at.s_u).abs());
            }
        }
        residual
    }

    /// The predictor: the affine direction (complementarity target 0) into
    /// `w.aff`, and the centring `σ` its complementarity suggests; `None` if
    /// it is not finite.
    fn predictor(&mut self, dx0: &Vector<NX>, w: &mut IpmWork<NX>, mu: f64, m: f64) -> Option<f64> {
        let mut aff = std::mem::take(&mut w.aff);
        let solved = self.direction(dx0, w, None, &mut aff);
        w.aff = aff;
        solved?;
        let a_aff = step_length(&w.bounds, &w.aff, 1.0);
        let mu_aff = w
            .bounds
            .iter()
            .zip(&w.aff.slacks)
            .map(|(b, d)| {
                let b = &b.at;
                (b.s_l + a_aff * d.s_l) * (b.l_l + a_aff * d.l_l)
                    + (b.s_u + a_aff * d.s_u) * (b.l_u + a_aff * d.l_u)
            })
            .sum::<f64>()
            / m;
        Some((mu_aff / mu).clamp(0.0, 1.0).powi(3))
    }

    /// The corrector: the direction centred on `target` (`σ μ`), with the
    /// predictor's second-order term, into `w.dir`, and the step along it;
    /// `None` if it is not finite or the step stalls.
    fn corrector(&mut self, dx0: &Vector<NX>, w: &mut IpmWork<NX>, target: f64) -> Option<f64> {
        let aff = std::mem::take(&mut w.aff);
        let mut dir = std::mem::take(&mut w.dir);
        let solved = self.direction(dx0, w, Some((&aff.slacks, target)), &mut dir);
        w.aff = aff;
        w.dir = dir;
        solved?;
        let alpha = step_length(&w.bounds, &w.dir, 0.995);
        if alpha < 1e-10 {
            return None;
        }
        Some(alpha)
    }

    /// The backward Riccati recursion's matrices for the stage weights with
    /// the barrier's diagonal: the gains into the stages, the rest into `w`;
    /// `None` if a pivot is not positive.
    fn factor(&mut self, w: &mut IpmWork<NX>) -> Option<()> {
        let n = self.s.horizon;
        let bounded = Self::BOUNDED;
        let barrier = |k: usize, b: usize| {
            let bound = &w.bounds[k * NB + b];
            bound.at.l_l * bound.inv_l + bound.at.l_u * bound.inv_u
        };
        let (q, q_terminal) = (&self.s.q, &self.s.q_terminal);
        let q_diag = |k: usize| {
            let weights = if k == n { q_terminal } else { q };
            let mut d = Vector::<NX>::from(weights.map(|v| 2.0 * v));
            for (b, &i) in bounded.iter().enumerate() {
                d[i] += barrier(k - 1, NU + b);
            }
            d
        };
        let mut p = Matrix::<NX, NX>::from_diagonal(&q_diag(n));
        for k in (0..n).rev() {
            let st = &self.stages[k];
            let pa = p * st.a;
            let pb = p * st.b;
            let mut huu = st.b.tr_mul(&pb);
            for i in 0..NU {
                huu[(i, i)] += 2.0 * self.s.r[i] + barrier(k, i);
            }
            let hux = st.b.tr_mul(&pa);
            let l = spd_cholesky(huu)?;
            // With `M = L⁻¹ H_ux`: `K = −L⁻ᵀ M` and `H_uxᵀ K = −Mᵀ M`. The
            // next stage waits for the forward substitution only, the back
            // substitution for `K` overlaps it.
            let m = l.l_dirty().solve_lower_triangular_unchecked(&hux);
            let kmat = -l.l_dirty().tr_solve_lower_triangular_unchecked(&m);
            w.p_next[k] = p;
            if k > 0 {
                let mut next = st.a.tr_mul(&pa) - m.tr_mul(&m);
                let q = q_diag(k);
                for i in 0..NX {
                    next[(i, i)] += q[i];
                }
                p = (next + next.transpose()) * 0.5;
            }
            w.chol[k] = l;
            self.stages[k].gain = kmat;
        }
        Some(())
    }

    /// The Newton direction from `(w.du, w.dx, w.bounds)` on the
    /// factorisation of [`Nmpc::factor`], into `out`; `None` if it is not
    /// finite. The complementarity targets: none (the predictor), or
    /// `corrector = (aff, c)`: `c − Δs Δλ` with the predictor's steps `aff`
    /// on each side.
    fn direction(
        &mut self,
        dx0: &Vector<NX>,
        w: &mut IpmWork<NX>,
        corrector: Option<(&[Slacks], f64)>,
        out: &mut Direction<NX>,
    ) -> Option<()> {
        let n = self.s.horizon;
        let bounded = Self::BOUNDED;
        let target = |j: usize| match corrector {
            Some((aff, c)) => {
                let d = &aff[j];
                (c - d.s_l * d.l_l, c - d.s_u * d.l_u)
            }
            None => (0.0, 0.0),
        };
        // The gradient: the cost's, and the barrier's terms.
        w.r_lin.copy_from_slice(&w.r_grad);
        w.q_lin.copy_from_slice(&w.q_grad);
        for (k, stage) in w.bounds.chunks_exact(NB).enumerate() {
            let mut g = [0.0; NB];
            for (b, (bound, g)) in stage.iter().zip(&mut g).enumerate() {
                let (t_l, t_u) = target(k * NB + b);
                let (lb, ub, bd) = (bound.lb, bound.ub, &bound.at);
                let (i_l, i_u) = (bound.inv_l, bound.inv_u);
                let (d_l, d_u) = (bd.l_l * i_l, bd.l_u * i_u);
                *g = -t_l * i_l + t_u * i_u - bd.l_l + bd.l_u - d_l * lb - d_u * ub;
            }
            for i in 0..NU {
                w.r_lin[k][i] += g[i];
            }
            w.q_lin[k + 1][bounded[0]] += g[NU];
            w.q_lin[k + 1][bounded[1]] += g[NU + 1];
        }
        // The backward pass of the vectors. `H_uxᵀ k = −H_uxᵀ H_uu⁻¹ h_u = Kᵀ
        // h_u` (`H_uu` is symmetric): the recursion goes on without waiting
        // for the solve, whose chained divisions then overlap the next
        // stages' work.
        let mut pv = w.q_lin[n];
        for k in (0..n).rev() {
            let st = &self.stages[k];
            let h = w.p_next[k] * st.d + pv;
            let hu = w.r_lin[k] + st.b.tr_mul(&h);
            if k > 0 {
                pv = w.q_lin[k] + st.a.tr_mul(&h) + st.gain.tr_mul(&hu);
            }
            self.stages[k].ff = -w.chol[k].solve(&hu);
        }
        // The new trajectory, then the direction to it.
        out.dx[0] = *dx0;
        for k in 0..n {
            let st = &self.stages[k];
            let x = out.dx[k];
            let u = st.gain * x + st.ff;
            out.du[k] = u;
            out.dx[k + 1] = st.a * x + st.b * u + st.d;
        }
        for k in 0..n {
            out.du[k] -= w.du[k];
            out.dx[k + 1] -= w.dx[k + 1];
        }
        let stages = w
            .bounds
            .chunks_exact(NB)
            .zip(out.slacks.chunks_exact_mut(NB));
        for (k, (stage, steps)) in stages.enumerate() {
            let z = values(&w.du, &w.dx, bounded, k);
            let dz = values(&out.du, &out.dx, bounded, k);
            for (b, (bound, step)) in stage.iter().zip(steps).enumerate() {
                let (t_l, t_u) = target(k * NB + b);
                let bd = &bound.at;
                let ds_l = dz[b] + (z[b] - bd.s_l - bound.lb);
                let ds_u = -dz[b] + (bound.ub - z[b] - bd.s_u);
                *step = Slacks {
                    s_l: ds_l,
                    s_u: ds_u,
                    l_l: (t_l - bd.s_l * bd.l_l - bd.l_l * ds_l) * bound.inv_l,
                    l_u: (t_u - bd.s_u * bd.l_u - bd.l_u * ds_u) * bound.inv_u,
                };
            }
        }
        let finite = out.du.iter().flat_map(|v| v.iter().copied());
        let finite = finite
            .chain(out.dx.iter().flat_map(|v| v.iter().copied()))
            .chain(out.slacks.iter().flat_map(|d| [d.s_l, d.s_u, d.l_l, d.l_u]))
            .all(f64::is_finite);
        finite.then_some(())
    }
}

/// The complementarity `μ`: the mean of the `m` products of a slack and its
/// multiplier.
fn mean_complementarity(bounds: &[Bound], m: f64) -> f64 {
    bounds
        .iter()
        .map(|b| b.at.s_l * b.at.l_l + b.at.s_u * b.at.l_u)
        .sum::<f64>()
        / m
}

/// The slacks' inverses of the iteration, which its factorisation and both
/// its directions use.
fn invert_slacks(bounds: &mut [Bound]) {
    for b in bounds {
        b.inv_l = 1.0 / b.at.s_l;
        b.inv_u = 1.0 / b.at.s_u;
    }
}

/// The longest step `≤ 1`, times `fraction`, that keeps every slack and
/// multiplier positive. The least ratio `v / −dv` over the decreasing ones is
/// tracked as a fraction (compared by cross-multiplying: both denominators are
/// positive) and divided once, instead of once per decreasing value (divisions
/// are slow; `bench_nmpc` measured in docs/measurements.md).
fn step_length<const NX: usize>(bounds: &[Bound], d: &Direction<NX>, fraction: f64) -> f64 {
    // The least ratio `num / den`, starting at `1 / fraction` (the step 1).
    let (mut num, mut den) = (1.0f64, fraction);
    for (b, d) in bounds.iter().zip(&d.slacks) {
        let b = &b.at;
        for (v, dv) in [
            (b.s_l, d.s_l),
            (b.s_u, d.s_u),
            (b.l_l, d.l_l),
            (b.l_u, d.l_u),
        ] {
            if dv < 0.0 && v * den < num * -dv {
                (num, den) = (v, -dv);
            }
        }
    }
    (fraction * num / den).min(1.0)
}

#[cfg(test)]
mod tests {
    use crate::algorithms::mpc::NmpcSettings;
    use crate::algorithms::mpc::nmpc::ReducedNmpc;
    use crate::model::{PlatformParams, Reduced, SlipParams, Vector};

    #[test]
    fn a_direction_that_is_not_finite_leaves_the_memory_usable() {
        let model = Reduced::new(PlatformParams::peer_default());
        let mut nmpc = ReducedNmpc::new(model, NmpcSettings::default()).expect("valid settings");
        let reference = vec![[0.0; 5]; 21];
        nmpc.prepare(&reference, &SlipParams::NOMINAL.to_array())
            .expect("valid problem");
        // A start that is not finite: its direction is not either.
        assert_eq!(nmpc.ipm(&Vector::from([f64::NAN; 5])), None);
        // The next solve finds its direction buffers (it indexed empty ones
        // when they were dropped with the failed direction).
        nmpc.ipm(&Vector::zeros());
    }
}
