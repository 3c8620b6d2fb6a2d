//! The lateral-slip model: what Rex's NMPC predicts with and its MHE estimates
//! on. The plant ([`super::Plant`], notes §1.4) without its two stiffest parts
//! (the wheels' spin dynamics and the load transfer), and with the ground's
//! friction as the parameters to estimate instead of an ICR offset.
//!
//! State `x = (X, Y, φ, v_x, v_y, ω)`: the pose of the centre of mass and its
//! body-frame velocities; the lateral velocity `v_y` is free, so the sideslip of
//! a turn (the body drifts outwards until the wheels' lateral friction carries
//! the centripetal force) is predicted, where the reduced model's constraint
//! `v_y = −x_0 ω` ties it to the yaw rate. Parameters `p = (μ_x, μ_y, μ_r)`
//! ([`Friction`]). Per wheel, with static loads `N_i`:
//!
//! ```text
//! v_ix = v_x − d_iy ω,           v_iy = v_y + d_ix ω
//! g_i  = τ_i / r − μ_r N_i sg(r θ̇_i) − (J_w / r) θ̈_i                 (what the ground is asked for)
//! F_xi = μ_x N_i sat(g_i / (μ_x N_i)),     F_yi = −μ_y N_i sg(v_iy)
//! m (v̇_x − v_y ω) = Σ F_xi,    m (v̇_y + v_x ω) = Σ F_yi,    I ω̇ = Σ (d_ix F_yi − d_iy F_xi)
//! ```
//!
//! A wheel's torque does three things, as in the plant: it overcomes the
//! rolling resistance (a torque on the wheel), spins the wheel up (`J_w θ̈_i`),
//! and pushes on the ground. Where the wheel's acceleration is read (the MHE
//! gives each interval its encoders' two readings, [`super::SpinRead`]), `g_i`
//! is the plant's force on the ground but for the readings' noise and lag,
//! whether the wheel rolls, pulls or spins. Where it is not (the NMPC's
//! prediction), the wheels are taken to roll at the speed their torque and the
//! ground agree on (their spin mode, about −10³ s⁻¹, settles within a
//! millisecond, so it is eliminated) and spin up with the body:
//! `θ̈_i = (a⁰_x − d_iy α⁰) / r`, where `a⁰_x`, `α⁰` are the accelerations
//! of the motion unbounded by the ground, body and wheels' spin inertia together
//! (`m_e a⁰_x = Σ (τ_i / r − μ_r N_i sg(r θ̇_i)) + m v_y ω`, `I_e α⁰ = Σ (d_ix
//! F_yi − d_iy (τ_i / r − μ_r N_i sg(r θ̇_i)))`, `m_e = m + 4 J_w / r²`, `I_e = I +
//! 4 J_w c² / r²`): below the traction bound the body moves exactly so, and the
//! force on the ground is the torque's less the spin-up's share (a tenth of it
//! for this platform: taking the whole torque's force as the ground's, as this
//! model did before, biased the MHE's `μ_x` on ice high). The force is bounded
//! by what the ground can take, `μ_x N`: `sat` is the identity up to 0.9 and
//! bends smoothly onto ±1 by 1.1
//! (a wheel asked for more spins, as the plant's does, and gives the body its
//! bound whatever its torque). The longitudinal slip is then a quasi-static
//! function of the traction the wheel transmits, `μ_x N sg(s) = F_x`, which is
//! what the encoders show beside the body's motion ([`Dynamics::encoder_rate`]):
//! it lets the MHE tell `μ_x` from the encoders while a wheel pulls, long
//! before it spins. Near the bound the slip law is steep, so the prediction's
//! uncertainty grows with its slope (a few percent of the traction fraction,
//! what the left-out load transfer moves), and a wheel beyond 97 % of it is not
//! predicted at all. The slip takes time to settle after the torque changes
//! (the wheel's spin inertia against the ground's slope, 8-80 ms on ice), so
//! the MHE predicts each reading from the slip the one before showed
//! ([`super::settling`], [`Dynamics::encoder_rates_settling`]).
//!
//! The rolling resistance opposes the wheel's spin, `sg(r θ̇_i)`, as the
//! plant's does, and not the ground's motion under the wheel, `sg(v_ix)`:
//! the two part when a wheel slips (an inner wheel in a turn on ice; wheels
//! spun up at a start). Without the wheels' spin in its state, the model takes
//! it from their encoders where it is given them ([`super::WheelSpin`],
//! [`Dynamics::linearise_spinning`]; the MHE gives every interval its two
//! readings), and `sg(v_ix)` otherwise (the NMPC's prediction). On ice the
//! MHE's `μ_r` came out low with `sg(v_ix)`; reading the spin (and predicting
//! the encoders over their counting window, [`super::settling`]), then the
//! wheels' spin-up too, each took part of that bias away. The measurements of
//! this paragraph and the one before: docs/measurements.md, "The lateral-slip
//! model's friction".
//!
//! Stiffness: the lateral mode's eigenvalue is about `−Σ μ_y N (2/π) k_s / m`,
//! −75 s⁻¹ on concrete for the 40 kg platform; RK4 over 50 ms needs at least
//! two steps (three are used).

use super::dynamics::{
    Dynamics, EarlierReading, Linearised, Measured, NU, SpinRead, Vector, sg, sg_inverse, sg_prime,
    sg4,
};
use super::params::{Friction, PlatformParams};
use super::settling::settle_slip;

/// State of the lateral-slip model: `(X, Y, φ, v_x, v_y, ω)`.
pub type State6 = [f64; 6];

/// Components of the state.
const VX: usize = 3;
const VY: usize = 4;
const W: usize = 5;
/// Components of the parameters.
const MU_X: usize = 0;
const MU_Y: usize = 1;
const MU_R: usize = 2;

/// Where the traction bound starts to bend, and where it is reached.
const KNEE: f64 = 0.9;
const FULL: f64 = 1.1;
/// The largest fraction of the traction bound a wheel's encoder is predicted
/// at: beyond it the wheel spins (its slip grows without bound).
const ENCODER_FRACTION_MAX: f64 = 0.97;
/// How well the model knows a wheel's fraction of its traction bound: relative
/// (what it leaves out: the load transfer moves the loads by a few percent, and
/// the wheels' spin-up lags the torque, which near the bound moves the slip
/// much more) and absolute. Through the slip law's slope it is the encoder
/// prediction's own uncertainty, which grows steeply towards the bound. The
/// relative part was chosen on the figure eight on ice: of the values tried, the
/// largest biased the MHE's `μ_x` least (the sweep: docs/measurements.md, "The
/// lateral-slip model's friction").
const FRACTION_SIGMA: (f64, f64) = (0.3, 0.01);

/// A force fraction bounded smoothly by 1: the identity on `[−0.9, 0.9]`, a
/// quadratic blend onto ±1 on `0.9 < |z| < 1.1` (value and slope continuous),
/// ±1 beyond; with its derivative.
#[inline]
pub fn saturate(z: f64) -> (f64, f64) {
    let a = z.abs();
    if a <= KNEE {
        (z, 1.0)
    } else if a < FULL {
        let e = a - KNEE;
        let width = FULL - KNEE;
        (
            z.signum() * (KNEE + e - e * e / (2.0 * width)),
            1.0 - e / width,
        )
    } else {
        (z.signum(), 0.0)
    }
}

/// Precomputed constants of the lateral-slip model.
#[derive(Clone, Debug, PartialEq)]
pub struct Lateral {
    /// The platform.
    pub params: PlatformParams,
    d: [[f64; 2]; 4],
    n: [f64; 4],
    m_eff: f64,
    i_eff: f64,
    /// How long the encoders count ticks for a rate \[s\] (0: an instant).
    encoder_window: f64,
}

/// The smallest friction coefficient the model computes with (a bound `μ_x N`
/// of zero would make a wheel's force fraction infinite).
const MU_MIN: f64 = 1e-3;

/// Gradients by the body velocities, the torques and the parameters:
/// `(v_x, v_y, ω, τ_1..τ_4, μ_x, μ_y, μ_r)`.
type Grad = Vector<10>;
const G_VX: usize = 0;
const G_VY: usize = 1;
const G_W: usize = 2;
const G_TAU: usize = 3;
const G_P: usize = 7;

/// The ground's forces on the wheels, with their gradients ([`Lateral::forces`]).
#[derive(Clone, Copy, Debug)]
struct Forces {
    /// Longitudinal force of each wheel on the body, `F_xi`.
    fx: [f64; 4],
    gx: [Grad; 4],
    /// Lateral force of each wheel, `F_yi`.
    fy: [f64; 4],
    gy: [Grad; 4],
}

impl Lateral {
    /// The model of `params`.
    pub fn new(params: PlatformParams) -> Lateral {
        let r = params.wheel_radius;
        Lateral {
            d: params.contacts(),
            n: params.static_loads(),
            m_eff: params.effective_mass(),
            i_eff: params.inertia
                + 4.0 * params.wheel_inertia * params.half_track.powi(2) / (r * r),
            params,
            encoder_window: 0.0,
        }
    }

    /// The model of encoders that give a wheel's rate as its ticks over the
    /// last `window` seconds: the settling prediction is then the slip's mean
    /// over that window ([`settle_slip`]). `None` unless `window` is finite
    /// and not negative.
    pub fn with_encoder_window(self, window: f64) -> Option<Lateral> {
        (window.is_finite() && window >= 0.0).then_some(Lateral {
            encoder_window: window,
            ..self
        })
    }

    /// The traction bound of wheel `i` on a ground of longitudinal friction
    /// `mu_long`, as a torque: `r μ_x N_i` \[N m\].
    pub fn traction_torque(&self, i: usize, mu_long: f64) -> f64 {
        self.params.wheel_radius * mu_long.max(MU_MIN) * self.n[i]
    }

    /// The ground's forces on the wheels at `x` under torques `u`. A wheel's
    /// torque drives its own spin as well as the ground: what the ground is
    /// asked for is `g_i = τ_i / r − μ_r N_i sg(r θ̇_i) − (J_w / r) θ̈_i`, the
    /// rolling resistance and the spin-up taken off; the ground gives
    /// `F_xi = μ_x N_i sat(g_i / (μ_x N_i))`.
    ///
    /// The spin-up is the wheel's acceleration read where `spin` has it (data,
    /// without gradient), else the one of a wheel rolling with the unbounded
    /// motion, `r θ̈_i = v̇_ix = v̇_x − d_iy ω̇` (the body and the wheels' spin
    /// inertia together: `m_e`, `I_e`): below the bound the body then
    /// accelerates exactly as the unbounded motion says; a wheel at its bound
    /// gives the body `μ_x N_i` whatever its torque (the rest spins it up).
    ///
    /// The rolling resistance opposes each wheel's spin: `sg(r θ̇_i)` where
    /// `spin` gives the rate (data), else the ground's motion under the
    /// wheel, `sg(v_ix)` (what the spin is when the wheel does not slip).
    fn forces(&self, x: &Vector<6>, u: &Vector<NU>, p: &Vector<3>, spin: &SpinRead) -> Forces {
        let (m, r, ks) = (
            self.params.mass,
            self.params.wheel_radius,
            self.params.sign_smoothing,
        );
        let kappa = self.params.wheel_inertia / (r * r);
        let (vx, vy, w) = (x[VX], x[VY], x[W]);
        let mut drive = [0.0; 4];
        let mut gdrive = [Grad::zeros(); 4];
        let mut fy = [0.0; 4];
        let mut gy = [Grad::zeros(); 4];
        // The unbounded accelerations' numerators: Σ drive + m v_y ω, and the
        // yaw moment Σ (d_ix F_yi − d_iy drive_i).
        let mut sum = m * vy * w;
        let mut gsum = Grad::zeros();
        gsum[G_VY] = m * w;
        gsum[G_W] = m * vy;
        let mut moment = 0.0;
        let mut gmoment = Grad::zeros();
        // The rolling resistance's direction, and its slope in `v_ix` (none
        // where the spin was read).
        let read = spin.rates.map(f64::is_finite);
        let mut sgx = sg4(
            ks,
            std::array::from_fn(|i| {
                if read[i] {
                    r * spin.rates[i]
                } else {
                    vx - self.d[i][1] * w
                }
            }),
        );
        for (i, (_, slope)) in sgx.iter_mut().enumerate() {
            if read[i] {
                *slope = 0.0;
            }
        }
        let sgy = sg4(ks, std::array::from_fn(|i| vy + self.d[i][0] * w));
        for i in 0..4 {
            let [dx, dy] = self.d[i];
            let n = self.n[i];
            let ((sx, sx1), (sy, sy1)) = (sgx[i], sgy[i]);
            drive[i] = u[i] / r - p[MU_R] * n * sx;
            let g = &mut gdrive[i];
            g[G_VX] = -p[MU_R] * n * sx1;
            g[G_W] = dy * p[MU_R] * n * sx1;
            g[G_TAU + i] = 1.0 / r;
            g[G_P + MU_R] = -n * sx;
            fy[i] = -p[MU_Y] * n * sy;
            let g = &mut gy[i];
            g[G_VY] = -p[MU_Y] * n * sy1;
            g[G_W] = -dx * p[MU_Y] * n * sy1;
            g[G_P + MU_Y] = -n * sy;
            sum += drive[i];
            gsum += gdrive[i];
            moment += dx * fy[i] - dy * drive[i];
            gmoment += gy[i] * dx - gdrive[i] * dy;
        }
        let (a0, ga0) = (sum / self.m_eff, gsum / self.m_eff);
        let (b0, gb0) = (moment / self.i_eff, gmoment / self.i_eff);
        let mux = p[MU_X].max(MU_MIN);
        let mut out = Forces {
            fx: [0.0; 4],
            gx: [Grad::zeros(); 4],
            fy,
            gy,
        };
        for i in 0..4 {
            let dy = self.d[i][1];
            let cap = mux * self.n[i];
            let (g, gg) = if spin.accelerations[i].is_finite() {
                (drive[i] - kappa * r * spin.accelerations[i], gdrive[i])
            } else {
                (
                    drive[i] - kappa * (a0 - dy * b0),
                    gdrive[i] - (ga0 - gb0 * dy) * kappa,
                )
            };
            let z = g / cap;
            let (sat, sat1) = saturate(z);
            out.fx[i] = cap * sat;
            out.gx[i] = gg * sat1;
            // ∂(μ N sat(g / (μ N)))/∂μ = N (sat − z sat'); zero below the knee.
            if p[MU_X] > MU_MIN {
                out.gx[i][G_P + MU_X] = self.n[i] * (sat - z * sat1);
            }
        }
        out
    }

    /// The state `(X, Y, φ, v_x, v_y, ω)` as an array.
    pub fn state(x: &Vector<6>) -> State6 {
        std::array::from_fn(|i| x[i])
    }

    /// The lateral velocity of a steady turn at forward speed `v` and yaw rate
    /// `w` on the ground `p`: the `v_y` at which the wheels' lateral forces
    /// carry the centripetal force, `Σ F_yi(v_y, ω) = m v ω` (the heading then
    /// points `atan2(v_y, v)` off the path's tangent). Newton's method on a
    /// monotone function; `None` when the ground cannot carry the turn (the
    /// lateral friction bound `μ_y m g` is below `m v ω`).
    pub fn steady_lateral(&self, v: f64, w: f64, p: &Friction) -> Option<f64> {
        let (m, ks) = (self.params.mass, self.params.sign_smoothing);
        let muy = p.mu_lat.max(MU_MIN);
        let need = m * v * w;
        let bound: f64 = self.n.iter().map(|n| muy * n).sum();
        if !(need.is_finite() && need.abs() < 0.98 * bound) {
            return None;
        }
        // g(v_y) = m v ω − Σ F_yi = m v ω + Σ μ_y N_i sg(v_iy), increasing in v_y.
        let g = |vy: f64| -> (f64, f64) {
            let mut f = need;
            let mut df = 0.0;
            for i in 0..4 {
                let viy = vy + self.d[i][0] * w;
                f += muy * self.n[i] * sg(ks, viy);
                df += muy * self.n[i] * sg_prime(ks, viy);
            }
            (f, df)
        };
        let mut vy = 0.0;
        for _ in 0..60 {
            let (f, df) = g(vy);
            if f.abs() < 1e-12 * bound.max(1.0) {
                return Some(vy);
            }
            if !(df > 0.0 && df.is_finite()) {
                return None;
            }
            // Damped: the friction law is flat far from zero slip.
            let step = (-f / df).clamp(-0.2, 0.2);
            vy += step;
        }
        let (f, _) = g(vy);
        (f.abs() < 1e-6 * bound.max(1.0)).then_some(vy)
    }

    /// The largest fraction of a wheel's traction bound `μ_x N` that a motion
    /// needs: forward speed `v`, yaw rate `w`, their rates `v_dot`, `w_dot`, in
    /// the steady sideslip of that turn ([`Lateral::steady_lateral`]), each side's
    /// two wheels pulling alike. `None` when the ground cannot carry the turn.
    ///
    /// From the model's equations, as torques (over `r`): the wheels' drives must
    /// give `Σ = m_e v̇ − m v_y ω` and `Σ d_iy · = Σ d_ix F_yi − I_e ω̇` (the yaw
    /// moment the lateral friction resists with; `m_e`, `I_e` count the wheels'
    /// spin-up), and each wheel's drive is that plus its rolling resistance: the
    /// fraction the NMPC's torque bound (`r μ_x N` times its margin) limits.
    pub fn traction_demand(
        &self,
        v: f64,
        w: f64,
        v_dot: f64,
        w_dot: f64,
        ground: &Friction,
    ) -> Option<f64> {
        let (m, ks, c) = (
            self.params.mass,
            self.params.sign_smoothing,
            self.params.half_track,
        );
        let vy = self.steady_lateral(v, w, ground)?;
        let muy = ground.mu_lat.max(MU_MIN);
        let lateral_moment: f64 = (0..4)
            .map(|i| {
                let dx = self.d[i][0];
                -dx * muy * self.n[i] * sg(ks, vy + dx * w)
            })
            .sum();
        let sum = self.m_eff * v_dot - m * vy * w;
        let moment = lateral_moment - self.i_eff * w_dot;
        // Left wheels (d_iy = c) each F_L, right ones F_R: 2 (F_L + F_R) = Σ F_x,
        // 2 c (F_L − F_R) = Σ d_iy F_x.
        let (left, right) = (
            sum / 4.0 + moment / (4.0 * c),
            sum / 4.0 - moment / (4.0 * c),
        );
        let mux = ground.mu_long.max(MU_MIN);
        let demand = (0..4)
            .map(|i| {
                let dy = self.d[i][1];
                let force = if dy > 0.0 { left } else { right };
                let rolling = ground.rolling * self.n[i] * sg(ks, v - dy * w);
                (force + rolling).abs() / (mux * self.n[i])
            })
            .fold(0.0, f64::max);
        demand.is_finite().then_some(demand)
    }
}

impl Dynamics<6, 3> for Lateral {
    const SPEED: usize = VX;
    const YAW_RATE: usize = W;
    const NAME: &'static str = "lateral";

    fn platform(&self) -> &PlatformParams {
        &self.params
    }

    fn linearise(&self, x: &Vector<6>, u: &Vector<NU>, p: &Vector<3>) -> Linearised<6, 3> {
        self.linearise_spinning(x, u, p, &SpinRead::NONE)
    }

    /// The rolling resistance opposes the spin read, else the ground's motion
    /// under the wheel; the spin-up is the acceleration read, else the
    /// unbounded motion's (the readings are data: no gradient by them).
    fn linearise_spinning(
        &self,
        x: &Vector<6>,
        u: &Vector<NU>,
        p: &Vector<3>,
        spin: &SpinRead,
    ) -> Linearised<6, 3> {
        let (m, inertia) = (self.params.mass, self.params.inertia);
        let (phi, vx, vy, w) = (x[2], x[VX], x[VY], x[W]);
        let f = self.forces(x, u, p, spin);
        // The body under the ground's forces (the wheels' spin inertia is in
        // them): m (v̇_x − v_y ω) = Σ F_xi, m (v̇_y + v_x ω) = Σ F_yi,
        // I ω̇ = Σ (d_ix F_yi − d_iy F_xi).
        let mut ax = m * vy * w;
        let mut gax = Grad::zeros();
        gax[G_VY] = m * w;
        gax[G_W] = m * vy;
        let mut ay = -m * vx * w;
        let mut gay = Grad::zeros();
        gay[G_VX] = -m * w;
        gay[G_W] = -m * vx;
        let (mut mz, mut gmz) = (0.0, Grad::zeros());
        for i in 0..4 {
            let [dx, dy] = self.d[i];
            ax += f.fx[i];
            gax += f.gx[i];
            ay += f.fy[i];
            gay += f.gy[i];
            mz += dx * f.fy[i] - dy * f.fx[i];
            gmz += f.gy[i] * dx - f.gx[i] * dy;
        }
        let rows = [
            (VX, ax / m, gax / m),
            (VY, ay / m, gay / m),
            (W, mz / inertia, gmz / inertia),
        ];
        let (s, c) = phi.sin_cos();
        let mut out = Linearised::<6, 3> {
            value: Vector::<6>::from([vx * c - vy * s, vx * s + vy * c, w, 0.0, 0.0, 0.0]),
            ..Linearised::default()
        };
        for (row, value, g) in rows {
            out.value[row] = value;
            for (col, k) in [(VX, G_VX), (VY, G_VY), (W, G_W)] {
                out.x[(row, col)] = g[k];
            }
            for k in 0..NU {
                out.u[(row, k)] = g[G_TAU + k];
            }
            for k in 0..3 {
                out.p[(row, k)] = g[G_P + k];
            }
        }
        let j = &mut out.x;
        j[(0, 2)] = -vx * s - vy * c;
        j[(0, VX)] = c;
        j[(0, VY)] = -s;
        j[(1, 2)] = vx * c - vy * s;
        j[(1, VX)] = s;
        j[(1, VY)] = c;
        j[(2, W)] = 1.0;
        out
    }

    fn f_spinning(
        &self,
        x: &Vector<6>,
        u: &Vector<NU>,
        p: &Vector<3>,
        spin: &SpinRead,
    ) -> Vector<6> {
        self.linearise_spinning(x, u, p, spin).value
    }

    fn state_at_pose(&self, pose: [f64; 3], v: f64, w: f64, _p: &Vector<3>) -> Vector<6> {
        Vector::<6>::from([pose[0], pose[1], pose[2], v, 0.0, w])
    }

    fn world_velocity(&self, x: &Vector<6>, _p: &Vector<3>) -> [f64; 2] {
        let (s, c) = x[2].sin_cos();
        [x[VX] * c - x[VY] * s, x[VX] * s + x[VY] * c]
    }

    fn body_accelerations(
        &self,
        x: &Vector<6>,
        u: &Vector<NU>,
        p: &Vector<3>,
        spin: &SpinRead,
    ) -> [Measured<6, 3>; 2] {
        // a_x = v̇_x − v_y ω, a_y = v̇_y + v_x ω (what the plant's load transfer
        // follows).
        let j = self.linearise_spinning(x, u, p, spin);
        let (vx, vy, w) = (x[VX], x[VY], x[W]);
        let mut ax = Measured {
            value: j.value[VX] - vy * w,
            sigma: 0.0,
            x: j.x.row(VX).transpose(),
            p: j.p.row(VX).transpose(),
        };
        ax.x[VY] -= w;
        ax.x[W] -= vy;
        let mut ay = Measured {
            value: j.value[VY] + vx * w,
            sigma: 0.0,
            x: j.x.row(VY).transpose(),
            p: j.p.row(VY).transpose(),
        };
        ay.x[VX] += w;
        ay.x[W] += vx;
        [ax, ay]
    }

    /// Usable while the slip it shows, `r θ̇ − v_ix`, is one the friction law
    /// maps below 97 % of the traction bound: then some `μ_x` explains it.
    fn encoder_usable(&self, i: usize, x: &Vector<6>, reading: f64) -> bool {
        let Some([_, dy]) = self.d.get(i).copied() else {
            return false;
        };
        let slip = self.params.wheel_radius * reading - (x[VX] - dy * x[W]);
        sg(self.params.sign_smoothing, slip).abs() <= ENCODER_FRACTION_MAX
    }

    fn encoder_rate(
        &self,
        i: usize,
        x: &Vector<6>,
        u: &Vector<NU>,
        p: &Vector<3>,
    ) -> Option<Measured<6, 3>> {
        let f = self.forces(x, u, p, &SpinRead::NONE);
        self.encoder_rate_with(i, x, p, &f, None)
    }

    fn encoder_rates(
        &self,
        x: &Vector<6>,
        u: &Vector<NU>,
        p: &Vector<3>,
    ) -> [Option<Measured<6, 3>>; 4] {
        let f = self.forces(x, u, p, &SpinRead::NONE);
        std::array::from_fn(|i| self.encoder_rate_with(i, x, p, &f, None))
    }

    /// Each wheel's slip from the one its encoder showed `h` seconds before
    /// ([`settle_slip`]); a wheel without a finite reading then, or with no
    /// time since, as [`Dynamics::encoder_rates`] has it.
    fn encoder_rates_settling(
        &self,
        before: &EarlierReading<6>,
        x: &Vector<6>,
        u: &Vector<NU>,
        p: &Vector<3>,
        spin: &[f64; 4],
    ) -> [Option<Measured<6, 3>>; 4] {
        let f = self.forces(x, u, p, &SpinRead::rates(*spin));
        let r = self.params.wheel_radius;
        std::array::from_fn(|i| {
            let dy = self.d[i][1];
            let start = r * before.rates[i] - (before.x[VX] - dy * before.x[W]);
            let settle = (start.is_finite() && before.h > 0.0).then_some((start, before.h));
            self.encoder_rate_with(i, x, p, &f, settle)
        })
    }
}

impl Lateral {
    /// [`Dynamics::encoder_rate`] of wheel `i` with the ground's forces `f`
    /// at `(x, u, p)`; with `settle`, `(s₀, h)`, the slip reached `h` seconds
    /// after the slip `s₀` ([`settle_slip`]) instead of the settled one.
    fn encoder_rate_with(
        &self,
        i: usize,
        x: &Vector<6>,
        p: &Vector<3>,
        f: &Forces,
        settle: Option<(f64, f64)>,
    ) -> Option<Measured<6, 3>> {
        // θ̇_i = (v_ix + s_i) / r with the slip s_i at which the ground takes the
        // wheel's traction: μ_x N sg(s) = F_x, i.e. s = sg⁻¹(F_x / (μ_x N)).
        let [_, dy] = *self.d.get(i)?;
        let (r, ks) = (self.params.wheel_radius, self.params.sign_smoothing);
        // The wheel's fraction of its traction bound, `ζ = F_x / (μ_x N)`, and
        // its gradient: `F_x`'s over the bound, and for `μ_x` also `−ζ / μ_x`
        // (the bound moves with it; not below the floor, where it is fixed).
        let mux = p[MU_X].max(MU_MIN);
        let cap = mux * self.n[i];
        let zeta = f.fx[i] / cap;
        let mut gzeta = f.gx[i] / cap;
        if p[MU_X] > MU_MIN {
            gzeta[G_P + MU_X] -= zeta / mux;
        }
        if zeta.is_nan() || zeta.abs() > ENCODER_FRACTION_MAX {
            return None;
        }
        // The slip, its slope in ζ, and its derivative by the bound `μ_x N`
        // itself (how fast the slip settles depends on it).
        let kappa = self.params.wheel_inertia / (r * r);
        let (slip, slip_zeta, slip_cap) = settle
            .and_then(|(start, h)| settle_slip(ks, kappa, cap, zeta, start, h, self.encoder_window))
            .unwrap_or_else(|| {
                let (s, ds) = sg_inverse(ks, zeta);
                (s, ds, 0.0)
            });
        let vix = x[VX] - dy * x[W];
        let (rel, abs) = FRACTION_SIGMA;
        let g = gzeta * (slip_zeta / r);
        let mut m = Measured {
            value: (vix + slip) / r,
            sigma: slip_zeta * (rel * zeta.abs() + abs) / r,
            x: Vector::zeros(),
            p: Vector::zeros(),
        };
        m.x[VX] = 1.0 / r + g[G_VX];
        m.x[VY] = g[G_VY];
        m.x[W] = -dy / r + g[G_W];
        for k in 0..3 {
            m.p[k] = g[G_P + k];
        }
        if p[MU_X] > MU_MIN {
            m.p[MU_X] += slip_cap * self.n[i] / r;
        }
        Some(m)
    }
}

#[cfg(test)]
mod tests;
