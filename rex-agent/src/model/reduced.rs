//! The reduced skid-steer model (notes §1.3, Kozłowski & Pazderski): the lateral-slip
//! constraint `v_y + x_0 ω = 0` and no longitudinal slip, so the state is
//! `x = (X, Y, φ, v, ω)` and the inputs are the four wheel torques. Used by
//! controllers and estimators; `peers/casadi_nmpc.py` implements the same equations.

use super::params::{PlatformParams, SlipParams};

/// Reduced state `(X, Y, φ, v, ω)`.
pub type State5 = [f64; 5];
/// Wheel torques `(τ_1, τ_2, τ_3, τ_4)` [N m].
pub type Torques = [f64; 4];

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
