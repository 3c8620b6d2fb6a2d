//! The endogenous configuration space approach (Tchoń & Jakubiak; notes §2).
//!
//! The kinematic skid-steer model with the ICR offset `x_0`,
//! `q̇ = G(q) η`, `q = (X, Y, φ)`, `η = (v, ω)`, is driven by controls from a
//! truncated series; the end-point map `K(λ) = q(T)` is inverted by the (damped,
//! weighted) Jacobian pseudo-inverse, `λ ← λ − γ W Jᵀ (J W Jᵀ + α I)⁻¹ (K(λ) − q_d)`,
//! with `J` from the variational equation `ξ̇ = A ξ + B P(t)` integrated along the
//! trajectory (RK4, the same steps as the state). `W` measures each control channel
//! relative to its bound (`W = I` is the Moore–Penrose inverse of the notes).
//!
//! Basis: `b_k(t) = sin(k π t / T)`, `k = 1..M`, for each control channel, a complete
//! basis of L²(0, T) whose members vanish at both ends, so every fragment starts and
//! ends at rest and fragments chain without velocity jumps. The step length `γ` starts
//! at 1 (Newton) and is halved while the task error does not decrease; when no step
//! helps (a singular control), the controls are perturbed and the iteration restarts.

use std::f64::consts::{FRAC_PI_2, PI};

use nalgebra::{Const, DimMin, SMatrix, SVector};

use super::{Fragment, PlanError, PlanStats, Planner, PlannerSettings, Waypoint};
use crate::math::linsolve;
use crate::math::rng::Rng;

/// Harmonics per control channel.
pub const HARMONICS: usize = 3;
/// Parameters `λ`: [`HARMONICS`] per control channel `(v, ω)`.
pub const PARAMETERS: usize = 2 * HARMONICS;

/// ECSA settings beyond the shared ones.
#[derive(Clone, Debug, PartialEq)]
pub struct EcsaSettings {
    /// Stop when the task error is below this (m and rad).
    pub tolerance: f64,
    /// Iteration bound.
    pub max_iterations: usize,
    /// Damping `α` of the pseudo-inverse.
    pub damping: f64,
    /// Restarts from perturbed controls before giving up.
    pub max_restarts: usize,
}

impl Default for EcsaSettings {
    fn default() -> Self {
        EcsaSettings {
            tolerance: 1e-5,
            max_iterations: 60,
            damping: 1e-9,
            max_restarts: 4,
        }
    }
}

/// The ECSA planner.
#[derive(Clone, Debug)]
pub struct Ecsa {
    /// Shared settings.
    pub settings: PlannerSettings,
    /// ECSA settings.
    pub ecsa: EcsaSettings,
    rng: Rng,
}

/// The result of integrating the kinematics for controls `λ`.
struct Rollout {
    end: [f64; 3],
    /// ∂q(T)/∂λ.
    jac: [[f64; PARAMETERS]; 3],
}

impl Ecsa {
    /// A planner with default ECSA settings.
    pub fn new(settings: PlannerSettings) -> Ecsa {
        Ecsa {
            settings,
            ecsa: EcsaSettings::default(),
            rng: Rng::new(0xEC5A),
        }
    }

    fn basis(t: f64, period: f64) -> [f64; HARMONICS] {
        std::array::from_fn(|k| ((k + 1) as f64 * std::f64::consts::PI * t / period).sin())
    }

    fn controls(lambda: &[f64; PARAMETERS], b: &[f64; HARMONICS]) -> (f64, f64) {
        let mut v = 0.0;
        let mut w = 0.0;
        for k in 0..HARMONICS {
            v += lambda[k] * b[k];
            w += lambda[HARMONICS + k] * b[k];
        }
        (v, w)
    }

    /// Integrate state and variational equation with RK4, `steps` steps over `period`;
    /// `on_sample(i, q, v, ω)` sees the state at every step boundary.
    fn rollout(
        &self,
        from: [f64; 3],
        lambda: &[f64; PARAMETERS],
        period: f64,
        steps: usize,
        mut on_sample: impl FnMut(usize, [f64; 3], f64, f64),
    ) -> Rollout {
        let x0 = self.settings.slip.x_icr;
        let h = period / steps as f64;
        // Combined state: q (3) and ξ (3×PARAMETERS), row-major.
        type Z = ([f64; 3], [[f64; PARAMETERS]; 3]);
        let deriv = |z: &Z, t: f64| -> Z {
            let (q, xi) = z;
            let b = Self::basis(t, period);
            let (v, w) = Self::controls(lambda, &b);
            let (s, c) = q[2].sin_cos();
            let dq = [v * c + x0 * w * s, v * s - x0 * w * c, w];
            // A = ∂f/∂q (only the φ column is non-zero); B = G(q).
            let a0 = -v * s + x0 * w * c;
            let a1 = v * c + x0 * w * s;
            let g = [[c, x0 * s], [s, -x0 * c], [0.0, 1.0]];
            let mut dxi = [[0.0; PARAMETERS]; 3];
            for j in 0..PARAMETERS {
                let (pv, pw) = if j < HARMONICS {
                    (b[j], 0.0)
                } else {
                    (0.0, b[j - HARMONICS])
                };
                let xphi = xi[2][j];
                dxi[0][j] = a0 * xphi + g[0][0] * pv + g[0][1] * pw;
                dxi[1][j] = a1 * xphi + g[1][0] * pv + g[1][1] * pw;
                dxi[2][j] = pw;
            }
            (dq, dxi)
        };
        let add = |z: &Z, k: &Z, f: f64| -> Z {
            let mut r = *z;
            for i in 0..3 {
                r.0[i] += f * k.0[i];
                for j in 0..PARAMETERS {
                    r.1[i][j] += f * k.1[i][j];
                }
            }
            r
        };
        let mut z: Z = (from, [[0.0; PARAMETERS]; 3]);
        let b0 = Self::basis(0.0, period);
        let (v0, w0) = Self::controls(lambda, &b0);
        on_sample(0, z.0, v0, w0);
        for i in 0..steps {
            let t = i as f64 * h;
            let k1 = deriv(&z, t);
            let k2 = deriv(&add(&z, &k1, h / 2.0), t + h / 2.0);
            let k3 = deriv(&add(&z, &k2, h / 2.0), t + h / 2.0);
            let k4 = deriv(&add(&z, &k3, h), t + h);
            for r in 0..3 {
                z.0[r] += h / 6.0 * (k1.0[r] + 2.0 * k2.0[r] + 2.0 * k3.0[r] + k4.0[r]);
                for j in 0..PARAMETERS {
                    z.1[r][j] +=
                        h / 6.0 * (k1.1[r][j] + 2.0 * k2.1[r][j] + 2.0 * k3.1[r][j] + k4.1[r][j]);
                }
            }
            let b = Self::basis(t + h, period);
            let (v, w) = Self::controls(lambda, &b);
            on_sample(i + 1, z.0, v, w);
        }
        Rollout { end: z.0, jac: z.1 }
    }

    /// Task error `K(λ) − q_d` (2 components when the heading is free).
    fn error(end: &[f64; 3], goal: &[f64; 3], with_heading: bool) -> ([f64; 3], usize) {
        let e = [end[0] - goal[0], end[1] - goal[1], end[2] - goal[2]];
        (e, if with_heading { 3 } else { 2 })
    }

    fn norm(e: &[f64; 3], m: usize) -> f64 {
        e[..m].iter().map(|x| x * x).sum::<f64>().sqrt()
    }

    /// Solve the task `K(λ) = goal` (the heading counts only `with_heading`) for
    /// a motion of `period` seconds integrated in `steps` RK4 steps: the Newton
    /// iteration on the end-point map, with its statistics. The controls `λ` are
    /// the coefficients of [`HARMONICS`] sine harmonics per channel `(v, ω)`.
    pub fn solve(
        &mut self,
        from: [f64; 3],
        goal: [f64; 3],
        with_heading: bool,
        period: f64,
        steps: usize,
    ) -> Result<([f64; PARAMETERS], PlanStats), PlanError> {
        let e_cfg = self.ecsa.clone();
        // The metric of the control space: each channel relative to its bound (a
        // weighted pseudo-inverse), so that a metre per second and a radian per
        // second are not priced alike.
        let wv = self.settings.speed_max.powi(2);
        let ww = self.settings.turn_rate_max.powi(2);
        let weights: [f64; PARAMETERS] =
            std::array::from_fn(|j| if j < HARMONICS { wv } else { ww });
        // Initial controls, "turn towards the goal, drive, turn to the goal heading":
        // the first harmonic of v covers the distance (∫ sin(πt/T) = 2T/π), forwards
        // or backwards, whichever faces the goal with less turning; the first
        // harmonic of ω makes the net turn, the second (which integrates to zero)
        // turns the platform towards the goal half-way. A straight-line guess would
        // be a singular control for goals beside the platform: it moves sideways
        // only through the ICR offset, and Newton ends on a solution that shuffles
        // back and forth at absurd speeds.
        let (dx, dy) = (goal[0] - from[0], goal[1] - from[1]);
        let distance = dx.hypot(dy);
        let wrap = |a: f64| (a + PI).rem_euclid(2.0 * PI) - PI;
        let (towards, sign) = if distance > 1e-9 {
            let rel = wrap(dy.atan2(dx) - from[2]);
            if rel.abs() <= FRAC_PI_2 {
                (rel, 1.0)
            } else {
                (wrap(rel - PI), -1.0)
            }
        } else {
            (0.0, 0.0)
        };
        let turn = if with_heading {
            goal[2] - from[2]
        } else {
            towards
        };
        let k = PI / (2.0 * period);
        let mut lambda = [0.0; PARAMETERS];
        lambda[0] = k * sign * distance;
        lambda[HARMONICS] = k * turn;
        lambda[HARMONICS + 1] = (towards - turn / 2.0) * PI / period;
        let mut stats = PlanStats::default();
        let mut r = self.rollout(from, &lambda, period, steps, |_, _, _, _| {});
        let (mut e, m) = Self::error(&r.end, &goal, with_heading);
        let mut err = Self::norm(&e, m);
        while stats.iterations < e_cfg.max_iterations {
            if err < e_cfg.tolerance {
                stats.error = err;
                return Ok((lambda, stats));
            }
            stats.iterations += 1;
            // Δλ = −Jᵀ (J Jᵀ + α I)⁻¹ e over the first m rows.
            // Weighted: Δλ = −W Jᵀ (J W Jᵀ + α I)⁻¹ e, W = diag(w_j²).
            let mut d = [[0.0; 3]; 3];
            for a in 0..m {
                for b in 0..m {
                    d[a][b] = (0..PARAMETERS)
                        .map(|j| r.jac[a][j] * r.jac[b][j] * weights[j])
                        .sum::<f64>();
                }
                d[a][a] += e_cfg.damping;
            }
            let y = solve_small(&d, &e, m);
            let step: [f64; PARAMETERS] = std::array::from_fn(|j| match &y {
                Some(y) => -weights[j] * (0..m).map(|a| r.jac[a][j] * y[a]).sum::<f64>(),
                None => 0.0,
            });
            let mut gamma = 1.0;
            let mut improved = false;
            if y.is_some() {
                for _ in 0..8 {
                    let trial: [f64; PARAMETERS] =
                        std::array::from_fn(|j| lambda[j] + gamma * step[j]);
                    let rt = self.rollout(from, &trial, period, steps, |_, _, _, _| {});
                    let (et, _) = Self::error(&rt.end, &goal, with_heading);
                    let nt = Self::norm(&et, m);
                    if nt.is_finite() && nt < err {
                        lambda = trial;
                        r = rt;
                        e = et;
                        err = nt;
                        improved = true;
                        break;
                    }
                    gamma *= 0.5;
                }
            }
            if !improved {
                // A singular control (or a stalled step): perturb and go on.
                if stats.restarts >= e_cfg.max_restarts {
                    return Err(PlanError::Singular {
                        restarts: stats.restarts,
                    });
                }
                stats.restarts += 1;
                let scale = 0.1 * (1.0 + lambda.iter().map(|x| x.abs()).fold(0.0, f64::max));
                for l in &mut lambda {
                    *l += scale * self.rng.normal();
                }
                r = self.rollout(from, &lambda, period, steps, |_, _, _, _| {});
                let (e2, _) = Self::error(&r.end, &goal, with_heading);
                e = e2;
                err = Self::norm(&e, m);
            }
        }
        if err < e_cfg.tolerance {
            stats.error = err;
            return Ok((lambda, stats));
        }
        Err(PlanError::NoConvergence {
            iterations: stats.iterations,
            error: err,
        })
    }
}

/// Solve the leading `m`×`m` block (m ≤ 3) of `d y = e`, `d = J W Jᵀ + α I`
/// symmetric, by nalgebra's Cholesky (LU should rounding make it indefinite):
/// `None` when it is singular or not finite.
fn solve_small(d: &[[f64; 3]; 3], e: &[f64; 3], m: usize) -> Option<[f64; 3]> {
    fn block<const M: usize>(d: &[[f64; 3]; 3], e: &[f64; 3]) -> Option<[f64; 3]>
    where
        Const<M>: DimMin<Const<M>, Output = Const<M>>,
    {
        let a = SMatrix::<f64, M, M>::from_fn(|row, col| d[row][col]);
        let b = SVector::<f64, M>::from_fn(|row, _| e[row]);
        let y = linsolve::solve_symmetric(a, &b, 1e-300)?;
        Some(std::array::from_fn(|k| if k < M { y[k] } else { 0.0 }))
    }
    match m {
        1 => block::<1>(d, e),
        2 => block::<2>(d, e),
        3 => block::<3>(d, e),
        _ => None,
    }
}

impl Planner for Ecsa {
    fn name(&self) -> &'static str {
        "ecsa"
    }

    fn plan(&mut self, from: [f64; 3], to: &Waypoint) -> Result<(Fragment, PlanStats), PlanError> {
        super::check_finite(&from, to)?;
        let s = self.settings.clone();
        let goal_phi = to.phi.map(|p| super::nearest_angle(p, from[2]));
        let goal = [to.x, to.y, goal_phi.unwrap_or(0.0)];
        let mut period = s.duration(
            from,
            &Waypoint {
                phi: goal_phi,
                ..*to
            },
        );
        if period > s.max_duration {
            return Err(PlanError::TooLong {
                duration: period,
                max: s.max_duration,
            });
        }
        let mut total = PlanStats::default();
        for attempt in 0..4 {
            let samples = (period / s.dt).round().max(1.0) as usize;
            // Two RK4 steps per sample interval.
            let steps = 2 * samples;
            let (lambda, stats) = self.solve(from, goal, goal_phi.is_some(), period, steps)?;
            total.iterations += stats.iterations;
            total.restarts += stats.restarts;
            total.error = stats.error;
            let mut states = Vec::with_capacity(samples + 1);
            let (mut peak_v, mut peak_w) = (0.0f64, 0.0f64);
            self.rollout(from, &lambda, period, steps, |i, q, v, w| {
                peak_v = peak_v.max(v.abs());
                peak_w = peak_w.max(w.abs());
                if i % 2 == 0 {
                    states.push([q[0], q[1], q[2], v, w]);
                }
            });
            match s.retime(period, peak_v, peak_w, attempt)? {
                None => {
                    return Ok((
                        Fragment {
                            plan: 0,
                            index: 0,
                            dt: s.dt,
                            states,
                            ..Fragment::default()
                        },
                        total,
                    ));
                }
                // Too fast: slow down proportionally and plan again.
                Some(longer) => period = longer,
            }
        }
        Err(PlanError::TooLong {
            duration: period,
            max: s.max_duration,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn planner() -> Ecsa {
        Ecsa::new(PlannerSettings::default())
    }

    #[test]
    fn the_peer_tasks_converge() {
        // The tasks of peers/ecsa_demo.py, from the origin.
        let tasks = [
            (2.0, 1.0, 0.0),
            (0.0, 1.0, 0.0),
            (-1.0, 0.5, std::f64::consts::FRAC_PI_2),
            (1.0, 0.0, std::f64::consts::PI),
        ];
        for (x, y, phi) in tasks {
            let (f, stats) = planner()
                .plan(
                    [0.0; 3],
                    &Waypoint {
                        x,
                        y,
                        phi: Some(phi),
                    },
                )
                .unwrap();
            let end = f.end().unwrap();
            assert!(
                (end[0] - x).hypot(end[1] - y) < 1e-3,
                "{end:?} vs ({x}, {y})"
            );
            assert!((end[2] - crate::algorithms::planner::nearest_angle(phi, 0.0)).abs() < 1e-3);
            assert!(stats.iterations <= 30, "{stats:?}");
            assert!(
                f.states[0][3].abs() < 1e-12 && end[3].abs() < 1e-9,
                "rest to rest"
            );
            assert!(
                f.states
                    .iter()
                    .all(|s| s[3].abs() <= 1.0 + 1e-9 && s[4].abs() <= 1.8 + 1e-9)
            );
        }
    }

    #[test]
    fn staying_put_is_a_zero_fragment() {
        let (f, stats) = planner()
            .plan(
                [1.0, 2.0, 0.3],
                &Waypoint {
                    x: 1.0,
                    y: 2.0,
                    phi: Some(0.3),
                },
            )
            .unwrap();
        assert_eq!(stats.iterations, 0);
        assert!(f.states.iter().all(|s| s[3] == 0.0 && s[4] == 0.0));
    }

    #[test]
    fn free_heading_and_bad_input() {
        let (f, _) = planner()
            .plan(
                [0.0; 3],
                &Waypoint {
                    x: 1.0,
                    y: 1.0,
                    phi: None,
                },
            )
            .unwrap();
        let end = f.end().unwrap();
        assert!((end[0] - 1.0).hypot(end[1] - 1.0) < 1e-3);
        assert_eq!(
            planner()
                .plan(
                    [0.0; 3],
                    &Waypoint {
                        x: f64::NAN,
                        y: 0.0,
                        phi: None
                    }
                )
                .unwrap_err(),
            PlanError::NotFinite
        );
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 48, failure_persistence: None, ..ProptestConfig::default() })]
        /// Random point pairs: the terminal error is below 1 mm within the iteration
        /// bound, or the planner reports a documented failure (never a hang or NaN).
        #[test]
        fn random_pairs_reach_the_goal_or_fail_cleanly(
            x in -3.0f64..3.0, y in -3.0f64..3.0, phi0 in -3.0f64..3.0,
            gx in -3.0f64..3.0, gy in -3.0f64..3.0, gphi in proptest::option::of(-3.0f64..3.0),
        ) {
            let goal = Waypoint { x: gx, y: gy, phi: gphi };
            match planner().plan([x, y, phi0], &goal) {
                Ok((f, stats)) => {
                    let end = f.end().unwrap();
                    prop_assert!((end[0] - gx).hypot(end[1] - gy) < 1e-3, "{:?} {:?}", end, stats);
                    if let Some(p) = gphi {
                        prop_assert!((end[2] - crate::algorithms::planner::nearest_angle(p, phi0)).abs() < 1e-3);
                    }
                    prop_assert!(stats.iterations <= EcsaSettings::default().max_iterations);
                    prop_assert!(f.states.iter().flatten().all(|v| v.is_finite()));
                }
                Err(e) => prop_assert!(matches!(e, PlanError::NoConvergence { .. } | PlanError::Singular { .. } | PlanError::TooFast { .. } | PlanError::TooLong { .. }), "{e}"),
            }
        }
    }
}
