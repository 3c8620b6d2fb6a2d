//! What a prediction model gives the NMPC and the MHE: `ẋ = f(x, u, p)` with its
//! Jacobians, integrated over an interval by RK4 with exact sensitivities, and the
//! few measurement functions the estimator needs. Two models implement it: the
//! reduced model of the peers ([`super::Reduced`], `(X, Y, φ, v, ω)`, ICR offset)
//! and the lateral-slip model Rex runs with ([`super::Lateral`],
//! `(X, Y, φ, v_x, v_y, ω)`, the ground's friction as parameters).
//!
//! Vectors and matrices are nalgebra's fixed-size types (no heap): `NX` states,
//! [`NU`] wheel torques, `NP` parameters.

use nalgebra::{SMatrix, SVector};

use super::params::PlatformParams;

/// Wheel torques per sample.
pub const NU: usize = 4;

/// A column vector of `N` components.
pub type Vector<const N: usize> = SVector<f64, N>;
/// An `R × C` matrix.
pub type Matrix<const R: usize, const C: usize> = SMatrix<f64, R, C>;

/// A value with its Jacobians with respect to the state, the torques and the
/// parameters: of `f` (continuous) or of one interval `F` (discrete).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Linearised<const NX: usize, const NP: usize> {
    /// The value.
    pub value: Vector<NX>,
    /// `∂/∂x`.
    pub x: Matrix<NX, NX>,
    /// `∂/∂u`.
    pub u: Matrix<NX, NU>,
    /// `∂/∂p`.
    pub p: Matrix<NX, NP>,
}

impl<const NX: usize, const NP: usize> Default for Linearised<NX, NP> {
    fn default() -> Self {
        Linearised {
            value: Vector::zeros(),
            x: Matrix::zeros(),
            u: Matrix::zeros(),
            p: Matrix::zeros(),
        }
    }
}

/// A scalar function of `(x, p)` (a measurement) with its gradients.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Measured<const NX: usize, const NP: usize> {
    /// The value.
    pub value: f64,
    /// The model's own uncertainty of the value (a standard deviation, added
    /// to the sensor's in quadrature): what it leaves out shows more in some
    /// measurements than in others.
    pub sigma: f64,
    /// `∂/∂x`.
    pub x: Vector<NX>,
    /// `∂/∂p`.
    pub p: Vector<NP>,
}

/// A skid-steer prediction model: state `x ∈ R^NX` whose first three components
/// are the pose `(X, Y, φ)`, the four wheel torques as inputs, parameters
/// `p ∈ R^NP` (estimated by the MHE, used by the NMPC).
pub trait Dynamics<const NX: usize, const NP: usize>:
    Clone + std::fmt::Debug + Send + Sync + 'static
{
    /// Index of the forward speed `v_x` in the state.
    const SPEED: usize;
    /// Index of the yaw rate `ω` in the state.
    const YAW_RATE: usize;
    /// Short name for reports.
    const NAME: &'static str;

    /// The platform.
    fn platform(&self) -> &PlatformParams;

    /// `ẋ = f(x, u, p)` and its Jacobians.
    fn linearise(&self, x: &Vector<NX>, u: &Vector<NU>, p: &Vector<NP>) -> Linearised<NX, NP>;

    /// `ẋ = f(x, u, p)` (the default evaluates [`Dynamics::linearise`]; a model
    /// gives a cheaper one when it has it).
    fn f(&self, x: &Vector<NX>, u: &Vector<NU>, p: &Vector<NP>) -> Vector<NX> {
        self.linearise(x, u, p).value
    }

    /// The state at pose `(X, Y, φ)` moving with forward speed `v` and yaw rate
    /// `w`, as the model represents it (for starting an estimate).
    fn state_at_pose(&self, pose: [f64; 3], v: f64, w: f64, p: &Vector<NP>) -> Vector<NX>;

    /// The velocity of the point whose pose the state holds, in the world frame
    /// `(Ẋ, Ẏ)` (for moving a measurement to a stage's instant).
    fn world_velocity(&self, x: &Vector<NX>, p: &Vector<NP>) -> [f64; 2];

    /// The body-frame accelerations `(a_x, a_y)` of the centre of mass (what
    /// the wheel loads' transfer follows), with their gradients.
    fn body_accelerations(
        &self,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
    ) -> [Measured<NX, NP>; 2];

    /// The rate wheel `i`'s encoder should read, with its gradients; `None`
    /// when the model cannot predict it (a wheel spinning on a surface that
    /// cannot take its torque).
    fn encoder_rate(
        &self,
        i: usize,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
    ) -> Option<Measured<NX, NP>>;

    /// The four encoders' rates, [`Dynamics::encoder_rate`] of each wheel in
    /// turn unless a model shares work between the wheels (the lateral model
    /// computes the ground's forces once for all four).
    fn encoder_rates(
        &self,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
    ) -> [Option<Measured<NX, NP>>; 4] {
        std::array::from_fn(|i| self.encoder_rate(i, x, u, p))
    }

    /// [`Dynamics::encoder_rates`] for a model that knows how a wheel's slip
    /// settles after its torque changes: each wheel's rate at `x` under `u`
    /// reached from the slip its encoder showed `h` seconds before
    /// (`previous[i]` [rad/s], read at the state `x_previous`; NaN where there
    /// was no reading). `x_previous` and `previous` enter as data (no gradient
    /// by them). The default: the slip settles at once, as
    /// [`Dynamics::encoder_rates`] has it.
    fn encoder_rates_settling(
        &self,
        _x_previous: &Vector<NX>,
        _previous: [f64; 4],
        _h: f64,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
    ) -> [Option<Measured<NX, NP>>; 4] {
        self.encoder_rates(x, u, p)
    }

    /// Whether wheel `i`'s encoder `reading` [rad/s] is one the model can
    /// represent at state `x` with some parameters (a wheel spinning far faster
    /// than the ground moves under it is not: its slip has no bound the model
    /// knows). The default: every reading.
    fn encoder_usable(&self, _i: usize, _x: &Vector<NX>, _reading: f64) -> bool {
        true
    }

    /// One interval of length `dt` integrated with `steps` RK4 steps: the
    /// discrete model `F(x, u, p)`.
    fn rk4(
        &self,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
        dt: f64,
        steps: usize,
    ) -> Vector<NX> {
        let h = dt / steps.max(1) as f64;
        let mut xk = *x;
        for _ in 0..steps.max(1) {
            let k1 = self.f(&xk, u, p);
            let k2 = self.f(&(xk + k1 * (h / 2.0)), u, p);
            let k3 = self.f(&(xk + k2 * (h / 2.0)), u, p);
            let k4 = self.f(&(xk + k3 * h), u, p);
            xk += (k1 + (k2 + k3) * 2.0 + k4) * (h / 6.0);
        }
        xk
    }

    /// [`Dynamics::rk4`] and its exact Jacobians, by differentiating every RK4
    /// stage (the discrete variational equation): the sensitivities `S = ∂x/∂(x₀,
    /// u, p)` are carried through the stages, `dk = f_x · (S + c·dk_prev) + [0 f_u
    /// f_p]`.
    fn rk4_sensitivities(
        &self,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
        dt: f64,
        steps: usize,
    ) -> Linearised<NX, NP> {
        let h = dt / steps.max(1) as f64;
        let mut s = Linearised {
            value: *x,
            x: Matrix::identity(),
            u: Matrix::zeros(),
            p: Matrix::zeros(),
        };
        // The derivative of a stage point `y` with sensitivities `dy`.
        let stage = |y: &Linearised<NX, NP>| -> Linearised<NX, NP> {
            let j = self.linearise(&y.value, u, p);
            Linearised {
                value: j.value,
                x: j.x * y.x,
                u: j.x * y.u + j.u,
                p: j.x * y.p + j.p,
            }
        };
        let shift = |a: &Linearised<NX, NP>, k: &Linearised<NX, NP>, c: f64| Linearised {
            value: a.value + k.value * c,
            x: a.x + k.x * c,
            u: a.u + k.u * c,
            p: a.p + k.p * c,
        };
        for _ in 0..steps.max(1) {
            let k1 = stage(&s);
            let k2 = stage(&shift(&s, &k1, h / 2.0));
            let k3 = stage(&shift(&s, &k2, h / 2.0));
            let k4 = stage(&shift(&s, &k3, h));
            let w = h / 6.0;
            s.value += (k1.value + (k2.value + k3.value) * 2.0 + k4.value) * w;
            s.x += (k1.x + (k2.x + k3.x) * 2.0 + k4.x) * w;
            s.u += (k1.u + (k2.u + k3.u) * 2.0 + k4.u) * w;
            s.p += (k1.p + (k2.p + k3.p) * 2.0 + k4.p) * w;
        }
        s
    }
}

/// The smoothed sign `sg(s) = 2/π atan(k_s s)` of the friction laws.
#[inline]
pub fn sg(k_s: f64, s: f64) -> f64 {
    std::f64::consts::FRAC_2_PI * (k_s * s).atan()
}

/// [`sg`] and [`sg_prime`] of four slip velocities, each distinct velocity
/// once: a side's two wheels share their longitudinal velocity and an axle's
/// two their lateral one, and `atan` is the models' dearest operation (a fifth
/// of the main job's time without vision). The same bits as four separate
/// calls (velocities compared bit for bit).
#[inline]
pub fn sg4(k_s: f64, s: [f64; 4]) -> [(f64, f64); 4] {
    let mut out = [(0.0, 0.0); 4];
    for i in 0..4 {
        out[i] = match (0..i).find(|&j| s[j].to_bits() == s[i].to_bits()) {
            Some(j) => out[j],
            None => (sg(k_s, s[i]), sg_prime(k_s, s[i])),
        };
    }
    out
}

/// Derivative of [`sg`].
#[inline]
pub fn sg_prime(k_s: f64, s: f64) -> f64 {
    std::f64::consts::FRAC_2_PI * k_s / (1.0 + (k_s * s).powi(2))
}

/// The inverse of [`sg`] for `|z| < 1`, with its derivative: the slip velocity
/// at which the friction law gives the fraction `z` of its bound.
#[inline]
pub fn sg_inverse(k_s: f64, z: f64) -> (f64, f64) {
    let t = (std::f64::consts::FRAC_PI_2 * z).tan();
    (t / k_s, std::f64::consts::FRAC_PI_2 * (1.0 + t * t) / k_s)
}

/// Test helpers shared by the models' tests: central differences against the
/// hand-written Jacobians.
#[cfg(test)]
pub(crate) mod check {
    use super::*;

    /// Check `linearise` and `rk4_sensitivities` of `m` against central
    /// differences at `(x, u, p)`.
    pub(crate) fn jacobians<M: Dynamics<NX, NP>, const NX: usize, const NP: usize>(
        m: &M,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
        dt: f64,
        steps: usize,
    ) {
        let jf = m.linearise(x, u, p);
        let jd = m.rk4_sensitivities(x, u, p, dt, steps);
        assert!((jf.value - m.f(x, u, p)).norm() < 1e-12);
        assert!((jd.value - m.rk4(x, u, p, dt, steps)).norm() < 1e-12);
        let h = 1e-6;
        let compare = |what: &str, analytic: f64, fd: f64, tol: f64| {
            assert!(
                (analytic - fd).abs() < tol * (1.0 + fd.abs()),
                "{what}: {analytic} vs {fd} (finite differences) at x {x:?} u {u:?} p {p:?}"
            );
        };
        for c in 0..NX {
            let (mut xp, mut xm) = (*x, *x);
            xp[c] += h;
            xm[c] -= h;
            let fd = (m.f(&xp, u, p) - m.f(&xm, u, p)) / (2.0 * h);
            let dd = (m.rk4(&xp, u, p, dt, steps) - m.rk4(&xm, u, p, dt, steps)) / (2.0 * h);
            for r in 0..NX {
                compare(&format!("∂f{r}/∂x{c}"), jf.x[(r, c)], fd[r], 1e-5);
                compare(&format!("∂F{r}/∂x{c}"), jd.x[(r, c)], dd[r], 1e-6);
            }
        }
        for c in 0..NU {
            let (mut up, mut um) = (*u, *u);
            up[c] += h;
            um[c] -= h;
            let fd = (m.f(x, &up, p) - m.f(x, &um, p)) / (2.0 * h);
            let dd = (m.rk4(x, &up, p, dt, steps) - m.rk4(x, &um, p, dt, steps)) / (2.0 * h);
            for r in 0..NX {
                compare(&format!("∂f{r}/∂u{c}"), jf.u[(r, c)], fd[r], 1e-5);
                compare(&format!("∂F{r}/∂u{c}"), jd.u[(r, c)], dd[r], 1e-6);
            }
        }
        for c in 0..NP {
            let (mut pp, mut pm) = (*p, *p);
            pp[c] += h;
            pm[c] -= h;
            let fd = (m.f(x, u, &pp) - m.f(x, u, &pm)) / (2.0 * h);
            let dd = (m.rk4(x, u, &pp, dt, steps) - m.rk4(x, u, &pm, dt, steps)) / (2.0 * h);
            for r in 0..NX {
                compare(&format!("∂f{r}/∂p{c}"), jf.p[(r, c)], fd[r], 1e-5);
                compare(&format!("∂F{r}/∂p{c}"), jd.p[(r, c)], dd[r], 1e-6);
            }
        }
    }

    /// Check a measurement's gradients against central differences.
    pub(crate) fn measured<const NX: usize, const NP: usize>(
        what: &str,
        f: impl Fn(&Vector<NX>, &Vector<NP>) -> Measured<NX, NP>,
        x: &Vector<NX>,
        p: &Vector<NP>,
    ) {
        let at = f(x, p);
        let h = 1e-6;
        for c in 0..NX {
            let (mut xp, mut xm) = (*x, *x);
            xp[c] += h;
            xm[c] -= h;
            let fd = (f(&xp, p).value - f(&xm, p).value) / (2.0 * h);
            assert!(
                (at.x[c] - fd).abs() < 1e-5 * (1.0 + fd.abs()),
                "∂{what}/∂x{c}: {} vs {fd}",
                at.x[c]
            );
        }
        for c in 0..NP {
            let (mut pp, mut pm) = (*p, *p);
            pp[c] += h;
            pm[c] -= h;
            let fd = (f(x, &pp).value - f(x, &pm).value) / (2.0 * h);
            assert!(
                (at.p[c] - fd).abs() < 1e-5 * (1.0 + fd.abs()),
                "∂{what}/∂p{c}: {} vs {fd}",
                at.p[c]
            );
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sg4_gives_the_bits_of_four_separate_calls() {
        // Shared velocities (a side's pair, an axle's pair), all distinct, all
        // equal, signed zeros (equal as numbers, not as bits) and a NaN.
        let cases = [
            [0.3, 0.3, -0.2, -0.2],
            [0.3, -0.2, 0.3, -0.2],
            [1e-3, 2e-3, -4e-3, 8.0],
            [0.7; 4],
            [0.0, -0.0, 0.0, -0.0],
            [f64::NAN, 0.1, f64::NAN, 0.1],
        ];
        for s in cases {
            let got = sg4(20.0, s);
            for i in 0..4 {
                let want = (sg(20.0, s[i]), sg_prime(20.0, s[i]));
                assert_eq!(
                    (got[i].0.to_bits(), got[i].1.to_bits()),
                    (want.0.to_bits(), want.1.to_bits()),
                    "{s:?}, wheel {i}"
                );
            }
        }
    }
}
