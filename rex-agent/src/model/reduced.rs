//! The reduced skid-steer model (notes §1.3, Kozłowski & Pazderski): the lateral-slip
//! constraint `v_y + x_0 ω = 0` and no longitudinal slip, so the state is
//! `x = (X, Y, φ, v, ω)` and the inputs are the four wheel torques. Used by
//! controllers and estimators; `peers/casadi_nmpc.py` implements the same equations.

use super::dynamics::{Dynamics, Linearised, Measured, NU, SpinRead, Vector, sg4};
use super::params::{PlatformParams, SlipParams};

/// Reduced state `(X, Y, φ, v, ω)`.
pub type State5 = [f64; 5];
/// Wheel torques `(τ_1, τ_2, τ_3, τ_4)` \[N m\], wheels 1 front-left, 2 rear-left,
/// 3 front-right, 4 rear-right.
pub type Torques = [f64; 4];

pub use super::dynamics::{sg, sg_prime};

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

    /// `ẋ = f(x, u, p)` on arrays (the baseline's and the peers' form).
    pub fn f5(&self, x: &State5, u: &Torques, p: &SlipParams) -> State5 {
        self.f(
            &Vector::from(*x),
            &Vector::from(*u),
            &Vector::from(p.to_array()),
        )
        .into()
    }

    /// One interval of length `dt` integrated with `steps` RK4 steps, on arrays
    /// (the peers' discrete model `F(x, u, p)`).
    pub fn rk4_5(&self, x: &State5, u: &Torques, p: &SlipParams, dt: f64, steps: usize) -> State5 {
        self.rk4(
            &Vector::from(*x),
            &Vector::from(*u),
            &Vector::from(p.to_array()),
            dt,
            steps,
        )
        .into()
    }

    /// Wheel rates `θ̇_i = (v - d_iy ω) / r` (no longitudinal slip).
    pub fn wheel_rates(&self, v: f64, w: f64) -> [f64; 4] {
        let r = self.params.wheel_radius;
        [0, 1, 2, 3].map(|i| (v - self.d[i][1] * w) / r)
    }

    /// `I + m x_0² + 4 J_w c² / r²`.
    fn i_eff(&self, x0: f64) -> f64 {
        let pr = &self.params;
        pr.inertia
            + pr.mass * x0 * x0
            + 4.0 * pr.wheel_inertia * pr.half_track.powi(2) / pr.wheel_radius.powi(2)
    }
}

impl Dynamics<5, 3> for Reduced {
    const SPEED: usize = 3;
    const YAW_RATE: usize = 4;
    const NAME: &'static str = "reduced";

    fn platform(&self) -> &PlatformParams {
        &self.params
    }

    fn f(&self, x: &Vector<5>, u: &Vector<NU>, p: &Vector<3>) -> Vector<5> {
        let pr = &self.params;
        let (phi, v, w) = (x[2], x[3], x[4]);
        let (x0, mu_s, mu_l) = (p[0], p[1], p[2]);
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
        let (s, c) = phi.sin_cos();
        Vector::from([
            v * c + x0 * w * s,
            v * s - x0 * w * c,
            w,
            (fx - pr.mass * x0 * w * w) / pr.effective_mass(),
            (mz + pr.mass * x0 * v * w) / self.i_eff(x0),
        ])
    }

    /// `f` and its Jacobians, written out by hand from the equations of `f`.
    fn linearise(&self, x: &Vector<5>, u: &Vector<NU>, p: &Vector<3>) -> Linearised<5, 3> {
        let pr = &self.params;
        let (phi, v, w) = (x[2], x[3], x[4]);
        let (x0, mu_s, mu_l) = (p[0], p[1], p[2]);
        let (r, ks, m) = (pr.wheel_radius, pr.sign_smoothing, pr.mass);
        let m_eff = pr.effective_mass();
        let i_eff = self.i_eff(x0);
        // Sums of forces and moments, and their partial derivatives.
        let (mut fx, mut mz) = (0.0, 0.0);
        let (mut fx_v, mut fx_w, mut fx_mus) = (0.0, 0.0, 0.0);
        let (mut mz_v, mut mz_w, mut mz_x0, mut mz_mus, mut mz_mul) = (0.0, 0.0, 0.0, 0.0, 0.0);
        let mut mz_u = [0.0; 4];
        let sgx = sg4(ks, std::array::from_fn(|i| v - self.d[i][1] * w));
        let sgy = sg4(ks, std::array::from_fn(|i| (self.d[i][0] - x0) * w));
        for i in 0..4 {
            let [dx, dy] = self.d[i];
            let n = self.n[i];
            let ((sx, sx1), (sy, sy1)) = (sgx[i], sgy[i]);
            let fxi = u[i] / r - mu_s * n * sx;
            let fyi = -mu_l * n * sy;
            // ∂F_xi/∂(v, w, μ_s); ∂F_yi/∂(w, x_0, μ_l).
            let (fxi_v, fxi_w, fxi_mus) = (-mu_s * n * sx1, mu_s * n * sx1 * dy, -n * sx);
            let (fyi_w, fyi_x0, fyi_mul) =
                (-mu_l * n * sy1 * (dx - x0), mu_l * n * sy1 * w, -n * sy);
            fx += fxi;
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
        let mut j = Linearised::<5, 3> {
            value: Vector::from([
                v * c + x0 * w * s,
                v * s - x0 * w * c,
                w,
                (fx - m * x0 * w * w) / m_eff,
                mz / i_eff,
            ]),
            ..Linearised::default()
        };
        // Ẋ, Ẏ, φ̇.
        j.x[(0, 2)] = -v * s + x0 * w * c;
        j.x[(0, 3)] = c;
        j.x[(0, 4)] = x0 * s;
        j.p[(0, 0)] = w * s;
        j.x[(1, 2)] = v * c + x0 * w * s;
        j.x[(1, 3)] = s;
        j.x[(1, 4)] = -x0 * c;
        j.p[(1, 0)] = -w * c;
        j.x[(2, 4)] = 1.0;
        // v̇ = (F_x − m x_0 ω²) / m_eff.
        j.x[(3, 3)] = fx_v / m_eff;
        j.x[(3, 4)] = (fx_w - 2.0 * m * x0 * w) / m_eff;
        for i in 0..4 {
            j.u[(3, i)] = 1.0 / (r * m_eff);
            j.u[(4, i)] = mz_u[i] / i_eff;
        }
        j.p[(3, 0)] = -m * w * w / m_eff;
        j.p[(3, 1)] = fx_mus / m_eff;
        // ω̇ = M_z / I_eff(x_0).
        j.x[(4, 3)] = mz_v / i_eff;
        j.x[(4, 4)] = mz_w / i_eff;
        j.p[(4, 0)] = mz_x0 / i_eff - mz * 2.0 * m * x0 / (i_eff * i_eff);
        j.p[(4, 1)] = mz_mus / i_eff;
        j.p[(4, 2)] = mz_mul / i_eff;
        j
    }

    fn state_at_pose(&self, pose: [f64; 3], v: f64, w: f64, _p: &Vector<3>) -> Vector<5> {
        Vector::from([pose[0], pose[1], pose[2], v, w])
    }

    fn world_velocity(&self, x: &Vector<5>, p: &Vector<3>) -> [f64; 2] {
        let (s, c) = x[2].sin_cos();
        let (v, w, x0) = (x[3], x[4], p[0]);
        [v * c + x0 * w * s, v * s - x0 * w * c]
    }

    /// `a_x = v̇ + x₀ω²`, `a_y = vω − x₀ω̇` (the centre of mass's, as the plant
    /// computes them).
    fn body_accelerations(
        &self,
        x: &Vector<5>,
        u: &Vector<NU>,
        p: &Vector<3>,
        _spin: &SpinRead,
    ) -> [Measured<5, 3>; 2] {
        let j = self.linearise(x, u, p);
        let (v, w, x0) = (x[3], x[4], p[0]);
        let mut ax = Measured {
            value: j.value[3] + x0 * w * w,
            sigma: 0.0,
            x: j.x.row(3).transpose(),
            p: j.p.row(3).transpose(),
        };
        ax.x[4] += 2.0 * x0 * w;
        ax.p[0] += w * w;
        let mut ay = Measured {
            value: v * w - x0 * j.value[4],
            sigma: 0.0,
            x: -j.x.row(4).transpose() * x0,
            p: -j.p.row(4).transpose() * x0,
        };
        ay.x[3] += w;
        ay.x[4] += v;
        ay.p[0] -= j.value[4];
        [ax, ay]
    }

    /// `θ̇_i = (v − d_iy ω) / r`: no longitudinal slip.
    fn encoder_rate(
        &self,
        i: usize,
        x: &Vector<5>,
        _u: &Vector<NU>,
        _p: &Vector<3>,
    ) -> Option<Measured<5, 3>> {
        let r = self.params.wheel_radius;
        let dy = self.d.get(i)?[1];
        let mut m = Measured {
            value: (x[3] - dy * x[4]) / r,
            sigma: 0.0,
            x: Vector::zeros(),
            p: Vector::zeros(),
        };
        m.x[3] = 1.0 / r;
        m.x[4] = -dy / r;
        Some(m)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::dynamics::check;

    /// Golden values of notes §1.6 (`python3 peers/casadi_nmpc.py --check-model`).
    #[test]
    fn golden_values() {
        let m = Reduced::new(PlatformParams::peer_default());
        let x = [0.3, -0.2, 0.7, 0.5, 0.4];
        let u = [2.0, 1.5, 4.0, 3.5];
        let p = SlipParams::NOMINAL;
        let f = m.f5(&x, &u, &p);
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
        let xn = m.rk4_5(&x, &u, &p, 0.05, 2);
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
        for (x, u, p) in points {
            let (x, u, p) = (Vector::from(x), Vector::from(u), Vector::from(p));
            check::jacobians(&m, &x, &u, &p, 0.05, 2);
            assert_eq!(m.linearise(&x, &u, &p).value, m.f(&x, &u, &p));
            for k in 0..2 {
                check::measured(
                    &format!("a{k}"),
                    |x, p| m.body_accelerations(x, &u, p, &SpinRead::NONE)[k],
                    &x,
                    &p,
                );
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
                x = m.rk4_5(&x, &[-tau, -tau, tau, tau], &p, 0.01, 2);
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
