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

/// No wheel's rate read at an instant.
pub const NOT_READ: [f64; 4] = [f64::NAN; 4];

/// What the wheels' encoders tell a model at an instant of an interval
/// ([`WheelSpin`]): each wheel's rate \[rad/s\] and its acceleration over the
/// interval \[rad/s²\], NaN where not read. A model whose state does not hold
/// the wheels' spin (the lateral model) takes from the rates the direction of
/// the rolling resistance, and from the accelerations the share of a wheel's
/// torque that spins the wheel up.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SpinRead {
    /// The rates.
    pub rates: [f64; 4],
    /// The accelerations.
    pub accelerations: [f64; 4],
}

impl SpinRead {
    /// Nothing read.
    pub const NONE: SpinRead = SpinRead {
        rates: NOT_READ,
        accelerations: NOT_READ,
    };

    /// The rates `rates` read, no acceleration (an instant without the
    /// interval around it).
    pub const fn rates(rates: [f64; 4]) -> SpinRead {
        SpinRead {
            rates,
            accelerations: NOT_READ,
        }
    }
}

/// The wheels' rates over one interval as their encoders read them \[rad/s\]:
/// at its start and at its end, NaN where a wheel was not read. A model whose
/// state does not hold the wheels' spin (the lateral model) takes from them the
/// direction of the rolling resistance, which opposes the wheel's spin and not
/// the ground's motion under it (the two part when a wheel slips, as an inner
/// wheel does in a turn on ice), and the wheels' acceleration
/// ([`SpinRead`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WheelSpin {
    /// At the interval's start.
    pub start: [f64; 4],
    /// At its end.
    pub end: [f64; 4],
}

impl WheelSpin {
    /// Nothing read: the models take the ground's motion under each wheel.
    pub const UNKNOWN: WheelSpin = WheelSpin {
        start: NOT_READ,
        end: NOT_READ,
    };

    /// The rates at the fraction `s` (in `[0, 1]`) of the interval: linear
    /// between two readings, the one reading of a wheel read once, NaN for a
    /// wheel not read.
    pub fn at(&self, s: f64) -> [f64; 4] {
        std::array::from_fn(|i| {
            let (a, b) = (self.start[i], self.end[i]);
            match (a.is_finite(), b.is_finite()) {
                (true, true) => a + (b - a) * s,
                (true, false) => a,
                (false, true) => b,
                (false, false) => f64::NAN,
            }
        })
    }

    /// Each wheel's mean acceleration over an interval of `dt` seconds \[rad/s²\]:
    /// its two readings' difference over `dt`; NaN for a wheel not read at
    /// both ends, and for every wheel unless `dt` is positive and finite.
    pub fn accelerations(&self, dt: f64) -> [f64; 4] {
        std::array::from_fn(|i| {
            let a = (self.end[i] - self.start[i]) / dt;
            if dt > 0.0 && dt.is_finite() && a.is_finite() {
                a
            } else {
                f64::NAN
            }
        })
    }

    /// What a model is told at the fraction `s` of an interval of `dt`
    /// seconds: the rates there ([`WheelSpin::at`]) and the interval's
    /// accelerations ([`WheelSpin::accelerations`]).
    pub fn read_at(&self, s: f64, dt: f64) -> SpinRead {
        SpinRead {
            rates: self.at(s),
            accelerations: self.accelerations(dt),
        }
    }
}

/// The encoders' rates read `h` seconds before the instant a model predicts
/// them at ([`Dynamics::encoder_rates_settling`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EarlierReading<const NX: usize> {
    /// The state then.
    pub x: Vector<NX>,
    /// The rates read then \[rad/s\] (NaN where a wheel was not read).
    pub rates: [f64; 4],
    /// How long before \[s\].
    pub h: f64,
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

    /// [`Dynamics::linearise`] with the wheels' rates and accelerations
    /// `spin` known from outside the model (NaN where not; [`SpinRead`]).
    /// The default: a model whose state holds what it needs ignores them.
    fn linearise_spinning(
        &self,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
        _spin: &SpinRead,
    ) -> Linearised<NX, NP> {
        self.linearise(x, u, p)
    }

    /// [`Dynamics::f`] with the wheels' spin known, as
    /// [`Dynamics::linearise_spinning`] (the default ignores it).
    fn f_spinning(
        &self,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
        _spin: &SpinRead,
    ) -> Vector<NX> {
        self.f(x, u, p)
    }

    /// The state at pose `(X, Y, φ)` moving with forward speed `v` and yaw rate
    /// `w`, as the model represents it (for starting an estimate).
    fn state_at_pose(&self, pose: [f64; 3], v: f64, w: f64, p: &Vector<NP>) -> Vector<NX>;

    /// The velocity of the point whose pose the state holds, in the world frame
    /// `(Ẋ, Ẏ)` (for moving a measurement to a stage's instant).
    fn world_velocity(&self, x: &Vector<NX>, p: &Vector<NP>) -> [f64; 2];

    /// The body-frame accelerations `(a_x, a_y)` of the centre of mass (what
    /// the wheel loads' transfer follows), with their gradients; `spin` the
    /// wheels' spin read at `x` as in [`Dynamics::linearise_spinning`].
    fn body_accelerations(
        &self,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
        spin: &SpinRead,
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
    /// reached from the slip its encoder showed `before.h` seconds before,
    /// and `spin` the rates read at `x` (the direction of the rolling
    /// resistance, as in [`Dynamics::linearise_spinning`]; not the wheels'
    /// accelerations: the readings predicted are what they would come from).
    /// `before` and `spin` enter as data (no gradient by them). The default:
    /// the slip settles at once, as [`Dynamics::encoder_rates`] has it.
    fn encoder_rates_settling(
        &self,
        _before: &EarlierReading<NX>,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
        _spin: &[f64; 4],
    ) -> [Option<Measured<NX, NP>>; 4] {
        self.encoder_rates(x, u, p)
    }

    /// Whether wheel `i`'s encoder `reading` \[rad/s\] is one the model can
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
        rk4_with(x, dt, steps, |y, _| self.f(y, u, p))
    }

    /// [`Dynamics::rk4`] with the wheels' readings over the interval known
    /// ([`Dynamics::f_spinning`] at each RK4 stage's instant,
    /// [`WheelSpin::read_at`]).
    fn rk4_spinning(
        &self,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
        dt: f64,
        steps: usize,
        spin: &WheelSpin,
    ) -> Vector<NX> {
        rk4_with(x, dt, steps, |y, s| {
            self.f_spinning(y, u, p, &spin.read_at(s, dt))
        })
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
        rk4_sensitivities_with(x, dt, steps, |y, _| self.linearise(y, u, p))
    }

    /// [`Dynamics::rk4_sensitivities`] with the wheels' readings over the
    /// interval known ([`Dynamics::linearise_spinning`] at each RK4 stage's
    /// instant, [`WheelSpin::read_at`]).
    fn rk4_sensitivities_spinning(
        &self,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
        dt: f64,
        steps: usize,
        spin: &WheelSpin,
    ) -> Linearised<NX, NP> {
        rk4_sensitivities_with(x, dt, steps, |y, s| {
            self.linearise_spinning(y, u, p, &spin.read_at(s, dt))
        })
    }
}

/// `steps` classical RK4 steps over `dt` of `ẋ = f(x, s)`, `s` the fraction of
/// the interval at each stage.
fn rk4_with<const NX: usize>(
    x: &Vector<NX>,
    dt: f64,
    steps: usize,
    f: impl Fn(&Vector<NX>, f64) -> Vector<NX>,
) -> Vector<NX> {
    let n = steps.max(1);
    let h = dt / n as f64;
    let mut xk = *x;
    for j in 0..n {
        let (s, mid, end) = stage_instants(j, n);
        let k1 = f(&xk, s);
        let k2 = f(&(xk + k1 * (h / 2.0)), mid);
        let k3 = f(&(xk + k2 * (h / 2.0)), mid);
        let k4 = f(&(xk + k3 * h), end);
        xk += (k1 + (k2 + k3) * 2.0 + k4) * (h / 6.0);
    }
    xk
}

/// Where RK4 step `j` of `n` evaluates its stages, as fractions of the
/// interval: its start, its middle, its end.
fn stage_instants(j: usize, n: usize) -> (f64, f64, f64) {
    let (j, n) = (j as f64, n as f64);
    (j / n, (j + 0.5) / n, (j + 1.0) / n)
}

/// [`rk4_with`] with the sensitivities of the result to `(x, u, p)`, from the
/// linearisation `f` of the right-hand side at each stage.
fn rk4_sensitivities_with<const NX: usize, const NP: usize>(
    x: &Vector<NX>,
    dt: f64,
    steps: usize,
    f: impl Fn(&Vector<NX>, f64) -> Linearised<NX, NP>,
) -> Linearised<NX, NP> {
    let n = steps.max(1);
    let h = dt / n as f64;
    let mut s = Linearised {
        value: *x,
        x: Matrix::identity(),
        u: Matrix::zeros(),
        p: Matrix::zeros(),
    };
    // The derivative of a stage point `y` with sensitivities `dy`.
    let stage = |y: &Linearised<NX, NP>, at: f64| -> Linearised<NX, NP> {
        let j = f(&y.value, at);
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
    for j in 0..n {
        let (at, mid, end) = stage_instants(j, n);
        let k1 = stage(&s, at);
        let k2 = stage(&shift(&s, &k1, h / 2.0), mid);
        let k3 = stage(&shift(&s, &k2, h / 2.0), mid);
        let k4 = stage(&shift(&s, &k3, h), end);
        let w = h / 6.0;
        s.value += (k1.value + (k2.value + k3.value) * 2.0 + k4.value) * w;
        s.x += (k1.x + (k2.x + k3.x) * 2.0 + k4.x) * w;
        s.u += (k1.u + (k2.u + k3.u) * 2.0 + k4.u) * w;
        s.p += (k1.p + (k2.p + k3.p) * 2.0 + k4.p) * w;
    }
    s
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
    /// differences at `(x, u, p)`, and that the spinning variants without
    /// a wheel read are the same bits.
    pub(crate) fn jacobians<M: Dynamics<NX, NP>, const NX: usize, const NP: usize>(
        m: &M,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
        dt: f64,
        steps: usize,
    ) {
        let unknown = WheelSpin::UNKNOWN;
        assert_eq!(
            m.linearise(x, u, p),
            m.linearise_spinning(x, u, p, &SpinRead::NONE)
        );
        assert_eq!(m.f(x, u, p), m.f_spinning(x, u, p, &SpinRead::NONE));
        assert_eq!(
            m.rk4_sensitivities(x, u, p, dt, steps),
            m.rk4_sensitivities_spinning(x, u, p, dt, steps, &unknown)
        );
        assert_eq!(
            m.rk4(x, u, p, dt, steps),
            m.rk4_spinning(x, u, p, dt, steps, &unknown)
        );
        jacobians_spinning(m, x, u, p, dt, steps, &unknown);
    }

    /// Check `linearise_spinning` (at the interval's start) and
    /// `rk4_sensitivities_spinning` of `m` against central differences at
    /// `(x, u, p)` with the wheels' readings `spin`.
    pub(crate) fn jacobians_spinning<M: Dynamics<NX, NP>, const NX: usize, const NP: usize>(
        m: &M,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
        dt: f64,
        steps: usize,
        spin: &WheelSpin,
    ) {
        let now = spin.read_at(0.0, dt);
        let jf = m.linearise_spinning(x, u, p, &now);
        let jd = m.rk4_sensitivities_spinning(x, u, p, dt, steps, spin);
        let f = |x: &Vector<NX>, u: &Vector<NU>, p: &Vector<NP>| m.f_spinning(x, u, p, &now);
        let rk4 = |x: &Vector<NX>, u: &Vector<NU>, p: &Vector<NP>, dt: f64, steps: usize| {
            m.rk4_spinning(x, u, p, dt, steps, spin)
        };
        assert!((jf.value - f(x, u, p)).norm() < 1e-12);
        assert!((jd.value - rk4(x, u, p, dt, steps)).norm() < 1e-12);
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
            let fd = (f(&xp, u, p) - f(&xm, u, p)) / (2.0 * h);
            let dd = (rk4(&xp, u, p, dt, steps) - rk4(&xm, u, p, dt, steps)) / (2.0 * h);
            for r in 0..NX {
                compare(&format!("∂f{r}/∂x{c}"), jf.x[(r, c)], fd[r], 1e-5);
                compare(&format!("∂F{r}/∂x{c}"), jd.x[(r, c)], dd[r], 1e-6);
            }
        }
        for c in 0..NU {
            let (mut up, mut um) = (*u, *u);
            up[c] += h;
            um[c] -= h;
            let fd = (f(x, &up, p) - f(x, &um, p)) / (2.0 * h);
            let dd = (rk4(x, &up, p, dt, steps) - rk4(x, &um, p, dt, steps)) / (2.0 * h);
            for r in 0..NX {
                compare(&format!("∂f{r}/∂u{c}"), jf.u[(r, c)], fd[r], 1e-5);
                compare(&format!("∂F{r}/∂u{c}"), jd.u[(r, c)], dd[r], 1e-6);
            }
        }
        for c in 0..NP {
            let (mut pp, mut pm) = (*p, *p);
            pp[c] += h;
            pm[c] -= h;
            let fd = (f(x, u, &pp) - f(x, u, &pm)) / (2.0 * h);
            let dd = (rk4(x, u, &pp, dt, steps) - rk4(x, u, &pm, dt, steps)) / (2.0 * h);
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
    fn wheel_spin_is_linear_between_two_readings_else_the_one_there_is() {
        let spin = WheelSpin {
            start: [1.0, f64::NAN, 2.0, f64::NAN],
            end: [3.0, 4.0, f64::NAN, f64::INFINITY],
        };
        let at = |s: f64| spin.at(s);
        assert_eq!(at(0.0)[..3], [1.0, 4.0, 2.0]);
        assert_eq!(at(0.25)[..3], [1.5, 4.0, 2.0]);
        assert_eq!(at(1.0)[..3], [3.0, 4.0, 2.0]);
        assert!((0..=4).all(|k| at(f64::from(k) / 4.0)[3].is_nan()));
        assert!(WheelSpin::UNKNOWN.at(0.5).iter().all(|v| v.is_nan()));
    }

    #[test]
    fn wheel_spin_accelerations_need_both_readings_and_a_real_interval() {
        let spin = WheelSpin {
            start: [1.0, f64::NAN, 2.0, f64::INFINITY],
            end: [3.0, 4.0, f64::NAN, 1.0],
        };
        let a = spin.accelerations(0.5);
        assert_eq!(a[0], 4.0);
        assert!(a[1..].iter().all(|v| v.is_nan()), "{a:?}");
        for dt in [0.0, -0.5, f64::NAN, f64::INFINITY] {
            assert!(spin.accelerations(dt).iter().all(|v| v.is_nan()), "{dt}");
        }
        // What a model is told inside the interval: the rates there and the
        // interval's accelerations.
        let read = spin.read_at(0.25, 0.5);
        assert_eq!(read.rates[..3], spin.at(0.25)[..3]);
        assert_eq!(read.accelerations[0], 4.0);
        assert_eq!(SpinRead::rates([1.0; 4]).rates, [1.0; 4]);
        assert!(
            SpinRead::rates([1.0; 4])
                .accelerations
                .iter()
                .all(|v| v.is_nan())
        );
        let nothing = WheelSpin::UNKNOWN.read_at(0.5, 0.05);
        assert!(
            nothing
                .rates
                .iter()
                .chain(&nothing.accelerations)
                .all(|v| v.is_nan())
        );
    }

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
