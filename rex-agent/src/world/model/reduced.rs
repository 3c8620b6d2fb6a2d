//! The reduced skid-steer model (notes §1.3, Kozłowski & Pazderski): the lateral-slip
//! constraint `v_y + x_0 ω = 0` and no longitudinal slip, so the state is
//! `x = (X, Y, φ, v, ω)` and the inputs are the four wheel torques. Used by
//! controllers and estimators; `peers/casadi_nmpc.py` implements the same equations.

use super::params::{PlatformParams, SlipParams};

/// Reduced state `(X, Y, φ, v, ω)`.
pub type State5 = [f64; 5];
/// Wheel torques `(τ_1, τ_2, τ_3, τ_4)` [N m], wheels 1 front-left, 2 rear-left,
/// 3 front-right, 4 rear-right.
pub type Torques = [f64; 4];

/// Jacobians of the model with respect to the state, the torques and the slip
/// parameters `p = (x_0, μ_s, μ_l)`, row-major (`x[i][j] = ∂f_i/∂x_j`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Jacobians {
    /// `∂/∂x` (5 × 5).
    pub x: [[f64; 5]; 5],
    /// `∂/∂u` (5 × 4).
    pub u: [[f64; 4]; 5],
    /// `∂/∂p` (5 × 3).
    pub p: [[f64; 3]; 5],
}

/// The smoothed sign `sg(s) = 2/π atan(k_s s)`.
#[inline]
pub fn sg(k_s: f64, s: f64) -> f64 {
    std::f64::consts::FRAC_2_PI * (k_s * s).atan()
}

/// Derivative of [`sg`].
#[inline]
pub fn sg_prime(k_s: f64, s: f64) -> f64 {
    std::f64::consts::FRAC_2_PI * k_s / (1.0 + (k_s * s).powi(2))
}

/// Precomputed constants of the reduced model.
#[derive(Clone, Debug, PartialEq)]
pub struct Reduced {
    /// The platform.
    pub params: PlatformParams,
    d: [[f64; 2]; 4],
    n: [f64; 4],
}

impl Reduced {
    /// The model of `params`.
    pub fn new(params: PlatformParams) -> Reduced {
        Reduced {
            d: params.contacts(),
            n: params.static_loads(),
            params,
        }
    }

    /// `ẋ = f(x, u, p)`.
    pub fn f(&self, x: &State5, u: &Torques, p: &SlipParams) -> State5 {
        let pr = &self.params;
        let [_, _, phi, v, w] = *x;
        let (x0, mu_s, mu_l) = (p.x_icr, p.mu_s, p.mu_l);
        let mut fx = 0.0;
        let mut mz = 0.0;
        for i in 0..4 {
            let [dx, dy] = self.d[i];
            let vix = v - dy * w;
            let viy = (dx - x0) * w;
            let fxi = u[i] / pr.wheel_radius - mu_s * self.n[i] * sg(pr.sign_smoothing, vix);
            let fyi = -mu_l * self.n[i] * sg(pr.sign_smoothing, viy);
            fx += fxi;
            mz += (dx - x0) * fyi - dy * fxi;
        }
        let m_eff = pr.effective_mass();
        let i_eff = pr.inertia
            + pr.mass * x0 * x0
            + 4.0 * pr.wheel_inertia * pr.half_track.powi(2) / pr.wheel_radius.powi(2);
        let (s, c) = phi.sin_cos();
        [
            v * c + x0 * w * s,
            v * s - x0 * w * c,
            w,
            (fx - pr.mass * x0 * w * w) / m_eff,
            (mz + pr.mass * x0 * v * w) / i_eff,
        ]
    }

    /// `ẋ = f(x, u, p)` and its Jacobians `∂f/∂x`, `∂f/∂u`, `∂f/∂p` (with
    /// `p = (x_0, μ_s, μ_l)`), written out by hand from the equations of [`Reduced::f`].
    pub fn f_jacobians(&self, x: &State5, u: &Torques, p: &SlipParams) -> Jacobians {
        let pr = &self.params;
        let [_, _, phi, v, w] = *x;
        let (x0, mu_s, mu_l) = (p.x_icr, p.mu_s, p.mu_l);
        let (r, ks, m) = (pr.wheel_radius, pr.sign_smoothing, pr.mass);
        let m_eff = pr.effective_mass();
        let i_eff =
            pr.inertia + m * x0 * x0 + 4.0 * pr.wheel_inertia * pr.half_track.powi(2) / (r * r);
        // Sums of forces and moments, and their partial derivatives.
        let mut mz = 0.0;
        let (mut fx_v, mut fx_w, mut fx_mus) = (0.0, 0.0, 0.0);
        let (mut mz_v, mut mz_w, mut mz_x0, mut mz_mus, mut mz_mul) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let mut mz_u = [0.0; 4];
        for i in 0..4 {
            let [dx, dy] = self.d[i];
            let n = self.n[i];
            let vix = v - dy * w;
            let viy = (dx - x0) * w;
            let (sx, sx1) = (sg(ks, vix), sg_prime(ks, vix));
            let (sy, sy1) = (sg(ks, viy), sg_prime(ks, viy));
            let fxi = u[i] / r - mu_s * n * sx;
            let fyi = -mu_l * n * sy;
            // ∂F_xi/∂(v, w, μ_s); ∂F_yi/∂(w, x_0, μ_l).
            let (fxi_v, fxi_w, fxi_mus) = (-mu_s * n * sx1, mu_s * n * sx1 * dy, -n * sx);
            let (fyi_w, fyi_x0, fyi_mul) =
                (-mu_l * n * sy1 * (dx - x0), mu_l * n * sy1 * w, -n * sy);
            mz += (dx - x0) * fyi - dy * fxi;
            fx_v += fxi_v;
            fx_w += fxi_w;
            fx_mus += fxi_mus;
            mz_v -= dy * fxi_v;
            mz_w += (dx - x0) * fyi_w - dy * fxi_w;
            mz_x0 += -fyi + (dx - x0) * fyi_x0;
            mz_mus -= dy * fxi_mus;
            mz_mul += (dx - x0) * fyi_mul;
            mz_u[i] = -dy / r;
        }
        mz += m * x0 * v * w;
        mz_v += m * x0 * w;
        mz_w += m * x0 * v;
        mz_x0 += m * v * w;
        let (s, c) = phi.sin_cos();
        let mut j = Jacobians::default();
        // Ẋ, Ẏ, φ̇.
        j.x[0][2] = -v * s + x0 * w * c;
        j.x[0][3] = c;
        j.x[0][4] = x0 * s;
        j.p[0][0] = w * s;
        j.x[1][2] = v * c + x0 * w * s;
        j.x[1][3] = s;
        j.x[1][4] = -x0 * c;
        j.p[1][0] = -w * c;
        j.x[2][4] = 1.0;
        // v̇ = (F_x − m x_0 ω²) / m_eff.
        j.x[3][3] = fx_v / m_eff;
        j.x[3][4] = (fx_w - 2.0 * m * x0 * w) / m_eff;
        j.u[3] = [1.0 / (r * m_eff); 4];
        j.p[3][0] = -m * w * w / m_eff;
        j.p[3][1] = fx_mus / m_eff;
        // ω̇ = M_z / I_eff(x_0).
        j.x[4][3] = mz_v / i_eff;
        j.x[4][4] = mz_w / i_eff;
        j.u[4] = mz_u.map(|d| d / i_eff);
        j.p[4][0] = mz_x0 / i_eff - mz * 2.0 * m * x0 / (i_eff * i_eff);
        j.p[4][1] = mz_mus / i_eff;
        j.p[4][2] = mz_mul / i_eff;
        j
    }

    /// `F(x, u, p)` ([`Reduced::rk4`]) and its exact Jacobians, by differentiating
    /// every RK4 stage (the discrete variational equation): `S ← ∂x/∂(x₀, u, p)` is
    /// carried through the stages with `dk = f_x · (S + c·dk_prev) + [0 f_u f_p]`.
    pub fn rk4_sensitivities(
        &self,
        x: &State5,
        u: &Torques,
        p: &SlipParams,
        dt: f64,
        steps: usize,
    ) -> (State5, Jacobians) {
        const NZ: usize = 12; // x (5), u (4), p (3)
        type Sens = [[f64; NZ]; 5];
        let h = dt / steps.max(1) as f64;
        let mut xk = *x;
        let mut sk: Sens = [[0.0; NZ]; 5];
        for (i, row) in sk.iter_mut().enumerate() {
            row[i] = 1.0;
        }
        // dk = f_x · dy + E, with dy the sensitivity of the stage point.
        let stage = |y: &State5, dy: &Sens| -> (State5, Sens) {
            let j = self.f_jacobians(y, u, p);
            let k = self.f(y, u, p);
            let mut dk: Sens = [[0.0; NZ]; 5];
            for r in 0..5 {
                for c in 0..NZ {
                    let mut acc = 0.0;
                    for m in 0..5 {
                        acc += j.x[r][m] * dy[m][c];
                    }
                    dk[r][c] = acc;
                }
                for c in 0..4 {
                    dk[r][5 + c] += j.u[r][c];
                }
                for c in 0..3 {
                    dk[r][9 + c] += j.p[r][c];
                }
            }
            (k, dk)
        };
        let shift = |x: &State5, s: &Sens, k: &State5, dk: &Sens, a: f64| -> (State5, Sens) {
            let mut y = *x;
            let mut dy = *s;
            for r in 0..5 {
                y[r] += a * k[r];
                for c in 0..NZ {
                    dy[r][c] += a * dk[r][c];
                }
            }
            (y, dy)
        };
        for _ in 0..steps.max(1) {
            let (k1, d1) = stage(&xk, &sk);
            let (y2, s2) = shift(&xk, &sk, &k1, &d1, h / 2.0);
            let (k2, d2) = stage(&y2, &s2);
            let (y3, s3) = shift(&xk, &sk, &k2, &d2, h / 2.0);
            let (k3, d3) = stage(&y3, &s3);
            let (y4, s4) = shift(&xk, &sk, &k3, &d3, h);
            let (k4, d4) = stage(&y4, &s4);
            for r in 0..5 {
                xk[r] += h / 6.0 * (k1[r] + 2.0 * k2[r] + 2.0 * k3[r] + k4[r]);
                for c in 0..NZ {
                    sk[r][c] += h / 6.0 * (d1[r][c] + 2.0 * d2[r][c] + 2.0 * d3[r][c] + d4[r][c]);
                }
            }
        }
        let mut j = Jacobians::default();
        for r in 0..5 {
            j.x[r].copy_from_slice(&sk[r][..5]);
            j.u[r].copy_from_slice(&sk[r][5..9]);
            j.p[r].copy_from_slice(&sk[r][9..]);
        }
        (xk, j)
    }

    /// One interval of length `dt` integrated with `steps` RK4 steps (the peers'
    /// discrete model `F(x, u, p)`).
    pub fn rk4(&self, x: &State5, u: &Torques, p: &SlipParams, dt: f64, steps: usize) -> State5 {
        let h = dt / steps.max(1) as f64;
        let add = |a: &State5, b: &State5, k: f64| -> State5 {
            let mut r = *a;
            for i in 0..5 {
                r[i] += k * b[i];
            }
            r
        };
        let mut xk = *x;
        for _ in 0..steps.max(1) {
            let k1 = self.f(&xk, u, p);
            let k2 = self.f(&add(&xk, &k1, h / 2.0), u, p);
            let k3 = self.f(&add(&xk, &k2, h / 2.0), u, p);
            let k4 = self.f(&add(&xk, &k3, h), u, p);
            for i in 0..5 {
                xk[i] += h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
            }
        }
        xk
    }

    /// Wheel rates `θ̇_i = (v - d_iy ω) / r` (no longitudinal slip).
    pub fn wheel_rates(&self, v: f64, w: f64) -> [f64; 4] {
        let r = self.params.wheel_radius;
        [0, 1, 2, 3].map(|i| (v - self.d[i][1] * w) / r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Golden values of notes §1.6 (`python3 peers/casadi_nmpc.py --check-model`).
    #[test]
    fn golden_values() {
        let m = Reduced::new(PlatformParams::peer_default());
        let x = [0.3, -0.2, 0.7, 0.5, 0.4];
        let u = [2.0, 1.5, 4.0, 3.5];
        let p = SlipParams::NOMINAL;
        let f = m.f(&x, &u, &p);
        let f_golden = [
            0.390151705889,
            0.312930737371,
            0.4,
            2.079178721053,
            -6.641400164438,
        ];
        for i in 0..5 {
            assert!(
                (f[i] - f_golden[i]).abs() < 1e-9,
                "f[{i}] = {} vs {}",
                f[i],
                f_golden[i]
            );
        }
        let xn = m.rk4(&x, &u, &p, 0.05, 2);
        let xn_golden = [
            0.321230082956,
            -0.182362817614,
            0.713505801905,
            0.603907653554,
            0.177112448654,
        ];
        for i in 0..5 {
            assert!(
                (xn[i] - xn_golden[i]).abs() < 1e-9,
                "F[{i}] = {} vs {}",
                xn[i],
                xn_golden[i]
            );
        }
    }

    /// The hand-written Jacobians and the RK4 sensitivities agree with central
    /// differences at the golden point and at a point of fast turning.
    #[test]
    fn jacobians_match_finite_differences() {
        let m = Reduced::new(PlatformParams::peer_default());
        let points = [
            (
                [0.3, -0.2, 0.7, 0.5, 0.4],
                [2.0, 1.5, 4.0, 3.5],
                [0.03, 0.05, 0.5],
            ),
            (
                [-1.0, 2.0, -2.5, -0.3, 1.7],
                [-6.0, -5.0, 7.0, 8.0],
                [0.06, 0.07, 0.6],
            ),
            ([0.0, 0.0, 0.0, 0.0, 0.0], [0.0; 4], [-0.02, 0.1, 0.9]),
        ];
        for (x, u, pv) in points {
            let p = SlipParams {
                x_icr: pv[0],
                mu_s: pv[1],
                mu_l: pv[2],
            };
            let z0: Vec<f64> = x.iter().chain(&u).chain(&pv).copied().collect();
            let split = |z: &[f64]| -> (State5, Torques, SlipParams) {
                (
                    [z[0], z[1], z[2], z[3], z[4]],
                    [z[5], z[6], z[7], z[8]],
                    SlipParams {
                        x_icr: z[9],
                        mu_s: z[10],
                        mu_l: z[11],
                    },
                )
            };
            let cont = |z: &[f64]| {
                let (x, u, p) = split(z);
                m.f(&x, &u, &p)
            };
            let disc = |z: &[f64]| {
                let (x, u, p) = split(z);
                m.rk4(&x, &u, &p, 0.05, 2)
            };
            let jf = m.f_jacobians(&x, &u, &p);
            let (xn, jd) = m.rk4_sensitivities(&x, &u, &p, 0.05, 2);
            assert_eq!(xn, m.rk4(&x, &u, &p, 0.05, 2));
            for c in 0..12 {
                let h = 1e-6;
                let (mut zp, mut zm) = (z0.clone(), z0.clone());
                zp[c] += h;
                zm[c] -= h;
                let (fp, fm) = (cont(&zp), cont(&zm));
                let (dp, dm) = (disc(&zp), disc(&zm));
                for r in 0..5 {
                    let pick = |j: &Jacobians| match c {
                        0..=4 => j.x[r][c],
                        5..=8 => j.u[r][c - 5],
                        _ => j.p[r][c - 9],
                    };
                    let fd = (fp[r] - fm[r]) / (2.0 * h);
                    let dd = (dp[r] - dm[r]) / (2.0 * h);
                    assert!(
                        (pick(&jf) - fd).abs() < 1e-5 * (1.0 + fd.abs()),
                        "∂f{r}/∂z{c}: {} vs {fd}",
                        pick(&jf)
                    );
                    assert!(
                        (pick(&jd) - dd).abs() < 1e-6 * (1.0 + dd.abs()),
                        "∂F{r}/∂z{c}: {} vs {dd}",
                        pick(&jd)
                    );
                }
            }
        }
    }

    #[test]
    fn turning_in_place_needs_torque() {
        // The lateral friction moment (≈ 39 N m for the 40 kg set, notes §1.3): with
        // ±4 N m per wheel the platform barely keeps turning, with ±2 N m it stops.
        let m = Reduced::new(PlatformParams::peer_default());
        let p = SlipParams::NOMINAL;
        let spin = |tau: f64| {
            let mut x = [0.0, 0.0, 0.0, 0.0, 1.0];
            for _ in 0..100 {
                x = m.rk4(&x, &[-tau, -tau, tau, tau], &p, 0.01, 2);
            }
            x[4]
        };
        let (slow, fast) = (spin(2.0), spin(6.0));
        // Below the saturated lateral friction moment the turn settles at a slow rate
        // (the smooth part of the friction sign); above it, it speeds up.
        assert!(slow < 0.5, "2 N m per wheel: {slow} rad/s");
        assert!(fast > 4.0 * slow, "6 N m per wheel: {fast} rad/s vs {slow}");
    }
}
