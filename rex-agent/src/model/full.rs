//! The full skid-steer model (notes §1.4), the plant of the simulator: body pose and
//! velocities `(X, Y, φ, v_x, v_y, ω)`, wheel angles and rates, forces from slip.
//!
//! ```text
//! s_i   = r θ̇_i − v_ix,   v_ix = v_x − d_iy ω,   v_iy = v_y + d_ix ω
//! F_xi  = μ_x N_i sg(s_i),             F_yi = −μ_y N_i sg(v_iy)
//! m (v̇_x − v_y ω) = Σ F_xi,   m (v̇_y + v_x ω) = Σ F_yi,   I ω̇ = Σ (d_ix F_yi − d_iy F_xi)
//! J_w θ̈_i = τ_i − r F_xi − r μ_r N_i sg(r θ̇_i)
//! ```
//!
//! The instantaneous centre of rotation is not a parameter here: it emerges from the
//! force balance, and shifts with speed, turn rate and ground.
//!
//! # Integration
//!
//! The wheel-spin mode is stiff: its eigenvalue is about `−r² μ_x N (2/π) k_s / J_w`,
//! −10³ s⁻¹ for the 40 kg platform and −4·10³ s⁻¹ for a Jackal-like one, so explicit
//! RK4 at 1 kHz would be at or past its stability limit. The velocity vector
//! `w = (v_x, v_y, ω, θ̇_1..θ̇_4)` is therefore advanced by the **backward (implicit)
//! Euler** method, `M (w − w_n) − h G(w) = 0`, solved for `w` by **damped Newton
//! iterations** with the analytic 7×7 Jacobian `∂G/∂w` of the friction and Coriolis
//! terms: each iteration solves `(M − h ∂G/∂w) Δw = −F(w)` (nalgebra's LU with
//! partial pivoting, on the stack) and halves the update while the residual `F`
//! does not decrease (taking 1/64 of it at worst); at most 12 iterations, stopping
//! once the residual is below 10⁻¹⁰. The first undamped update
//! from `w_n` is the linearly implicit (Rosenbrock) Euler step; further iterations
//! are needed when a friction force crosses the steep part of its sign function
//! within the step. Backward Euler is L-stable for any stiffness (a test runs it with a
//! wheel inertia 100 times smaller and a near-Coulomb friction sign). Angles and
//! positions are then advanced with the new velocities (the pose with the mid-step
//! heading). Normal loads include the longitudinal and lateral load transfer of the
//! previous step's accelerations (what the force sensors measure).
//!
//! When the Newton system cannot be solved (singular or not finite, which only a
//! non-finite state causes in practice) the iterations stop and the step keeps the
//! last iterate: the velocities of the previous step if it happens in the first
//! iteration (they are frozen for that step). Such steps are counted in
//! [`IntegrationStats::singular`], and steps that end after the last iteration with
//! the residual still above the tolerance in [`IntegrationStats::unconverged`]; both
//! are read with [`Plant::integration_stats`].

use nalgebra::{Isometry2, Point2, SMatrix, SVector, UnitComplex, Vector2};

use super::dynamics::sg4;
use super::params::{PlatformParams, SurfaceMap};
use super::reduced::{sg, sg_prime};
use crate::config::{self, ConfigError, Invalid, Validate, finite};
use crate::math::linsolve;

/// A start pose `(x, y, φ)`, checked for finite values.
struct StartPose([f64; 3]);

impl Validate for StartPose {
    fn validate(&self) -> Result<(), Invalid> {
        finite("x", self.0[0])?;
        finite("y", self.0[1])?;
        finite("phi", self.0[2])
    }
}

/// State of the full model.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct FullState {
    /// World position of the centre of mass [m].
    pub x: f64,
    /// World position of the centre of mass [m].
    pub y: f64,
    /// Heading [rad] (not wrapped).
    pub phi: f64,
    /// Body-frame forward velocity [m/s].
    pub vx: f64,
    /// Body-frame lateral velocity [m/s].
    pub vy: f64,
    /// Yaw rate [rad/s].
    pub omega: f64,
    /// Wheel angles [rad].
    pub theta: [f64; 4],
    /// Wheel rates [rad/s].
    pub theta_dot: [f64; 4],
}

/// What the plant did with the torque commands it was given ([`Plant::clean`]).
/// Each counts commands, not wheels: a command with several bad torques counts once
/// in each kind it has.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CommandStats {
    /// Commands with a NaN or infinite torque (that torque replaced by zero).
    pub not_finite: u64,
    /// Commands with a finite torque outside `±torque_max` (that torque clamped).
    pub out_of_bounds: u64,
}

/// How the implicit integration went (see the module docs).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct IntegrationStats {
    /// Steps whose Newton system could not be solved: they kept the last iterate
    /// (the previous velocities if it failed in the first iteration).
    pub singular: u64,
    /// Steps that used every Newton iteration and still had a residual above the
    /// tolerance (the last iterate is used).
    pub unconverged: u64,
}

/// The simulated platform.
#[derive(Clone, Debug)]
pub struct Plant {
    params: PlatformParams,
    surfaces: SurfaceMap,
    d: [[f64; 2]; 4],
    n_static: [f64; 4],
    /// Current state.
    pub state: FullState,
    loads: [f64; 4],
    /// Body-frame acceleration `(a_x, a_y)` of the last step [m/s²].
    accel: [f64; 2],
    stats: CommandStats,
    integration: IntegrationStats,
}

impl Plant {
    /// A plant at rest at `(x, y, φ)`; the parameters, the ground and the pose are
    /// validated (a negative mass, a map without surfaces or with two surfaces of
    /// the same name, a NaN pose... are errors).
    pub fn new(
        params: PlatformParams,
        surfaces: SurfaceMap,
        pose: [f64; 3],
    ) -> Result<Plant, ConfigError> {
        config::check("platform", &params)?;
        config::check("surfaces", &surfaces)?;
        config::check("start pose", &StartPose(pose))?;
        let n_static = params.static_loads();
        Ok(Plant {
            d: params.contacts(),
            n_static,
            loads: n_static,
            params,
            surfaces,
            state: FullState {
                x: pose[0],
                y: pose[1],
                phi: pose[2],
                ..FullState::default()
            },
            accel: [0.0; 2],
            stats: CommandStats::default(),
            integration: IntegrationStats::default(),
        })
    }

    /// The platform parameters.
    pub fn params(&self) -> &PlatformParams {
        &self.params
    }

    /// The ground.
    pub fn surfaces(&self) -> &SurfaceMap {
        &self.surfaces
    }

    /// Normal load of each wheel in the last step [N].
    pub fn loads(&self) -> [f64; 4] {
        self.loads
    }

    /// Body-frame acceleration `(a_x, a_y)` in the last step [m/s²].
    pub fn accel(&self) -> [f64; 2] {
        self.accel
    }

    /// How many torque commands were rejected or clamped so far ([`Plant::clean`]).
    pub fn command_stats(&self) -> CommandStats {
        self.stats
    }

    /// Steps whose implicit solve failed or did not converge so far.
    pub fn integration_stats(&self) -> IntegrationStats {
        self.integration
    }

    /// Check a new torque command, once when it arrives: a NaN or infinite torque
    /// becomes zero, a torque beyond `±torque_max` is clamped, and the command is
    /// counted in [`CommandStats`] (once per kind of fault, however many wheels have
    /// it). The motors then deliver [`Plant::available`] of the cleaned command at
    /// every step.
    pub fn clean(&mut self, command: [f64; 4]) -> [f64; 4] {
        let max = self.params.torque_max;
        let not_finite = command.iter().any(|c| !c.is_finite());
        let out_of_bounds = command.iter().any(|c| c.is_finite() && c.abs() > max);
        self.stats.not_finite += u64::from(not_finite);
        self.stats.out_of_bounds += u64::from(out_of_bounds);
        command.map(|c| {
            if c.is_finite() {
                c.clamp(-max, max)
            } else {
                0.0
            }
        })
    }

    /// The torques the motors deliver for a (cleaned) command at the current wheel
    /// speeds: a torque driving a wheel is limited by the motor curve, falling
    /// linearly from `torque_max` to zero at `wheel_speed_max` (braking torque is not
    /// limited by speed). Nothing is counted; a torque that is still NaN or beyond
    /// the bounds (a command that did not go through [`Plant::clean`]) gives zero or
    /// is clamped, so the plant never integrates one.
    pub fn available(&self, command: [f64; 4]) -> [f64; 4] {
        let p = &self.params;
        let mut tau = [0.0; 4];
        for i in 0..4 {
            let c = command[i];
            if !c.is_finite() {
                continue;
            }
            let w = self.state.theta_dot[i];
            let available = if c * w > 0.0 {
                p.torque_max * (1.0 - w.abs() / p.wheel_speed_max).max(0.0)
            } else {
                p.torque_max
            };
            tau[i] = c.clamp(-available, available);
        }
        tau
    }

    /// [`Plant::clean`] then [`Plant::available`]: for a command applied for one
    /// step only (it is counted at each call).
    pub fn limit(&mut self, command: [f64; 4]) -> [f64; 4] {
        let clean = self.clean(command);
        self.available(clean)
    }

    /// Advance by `h` seconds with wheel torques `tau` (already limited).
    pub fn step(&mut self, tau: [f64; 4], h: f64) {
        let p = &self.params;
        let s = self.state;
        let (k, r) = (p.sign_smoothing, p.wheel_radius);
        // Normal loads with the load transfer of the last accelerations.
        let long = p.mass * self.accel[0] * p.cog_height / (2.0 * (p.front + p.rear));
        let lat = p.mass * self.accel[1] * p.cog_height / (4.0 * p.half_track);
        let mut n = self.n_static;
        for i in 0..4 {
            let front = if self.d[i][0] > 0.0 { -1.0 } else { 1.0 };
            let left = if self.d[i][1] > 0.0 { -1.0 } else { 1.0 };
            n[i] = (n[i] + front * long + left * lat).max(0.0);
        }
        self.loads = n;
        // Ground under each wheel.
        let body = Isometry2::new(Vector2::new(s.x, s.y), s.phi);
        let mut mu = [[0.0; 3]; 4];
        for i in 0..4 {
            let contact = body * Point2::from(self.d[i]);
            // A validated map always has a surface; no ground means no friction.
            mu[i] = self
                .surfaces
                .at(contact.x, contact.y)
                .map_or([0.0; 3], |g| [g.mu_long, g.mu_lat, g.rolling]);
        }
        // Backward Euler on the velocities, w = (vx, vy, ω, θ̇1..4):
        //   M (w − w_n) − h G(w) = 0,
        // solved by Newton's method with the analytic Jacobian, damped by halving
        // the step while the residual does not decrease. The first iteration is the
        // linearly implicit (Rosenbrock) Euler step; more are needed only when a
        // friction force crosses its steep region within the step. A singular system
        // stops the iterations with the last iterate (counted; see the module docs).
        let m = [
            p.mass,
            p.mass,
            p.inertia,
            p.wheel_inertia,
            p.wheel_inertia,
            p.wheel_inertia,
            p.wheel_inertia,
        ];
        let w_n = [
            s.vx,
            s.vy,
            s.omega,
            s.theta_dot[0],
            s.theta_dot[1],
            s.theta_dot[2],
            s.theta_dot[3],
        ];
        let forces = Forces {
            d: self.d,
            n,
            mu,
            mass: p.mass,
            r,
            k,
            tau,
        };
        let residual = |w: &[f64; 7], g: &[f64; 7]| -> [f64; 7] {
            let mut f = [0.0; 7];
            for i in 0..7 {
                f[i] = m[i] * (w[i] - w_n[i]) - h * g[i];
            }
            f
        };
        let norm = |f: &[f64; 7]| (0..7).map(|i| (f[i] / m[i]).powi(2)).sum::<f64>().sqrt();
        let mut w = w_n;
        let (g0, mut jac) = forces.eval(&w);
        let mut f = residual(&w, &g0);
        let mut fnorm = norm(&f);
        // Whether the iterations ended before the last one (converged, or singular).
        let mut ended = false;
        for _ in 0..MAX_NEWTON {
            let mut a = [[0.0; 7]; 7];
            let mut rhs = [0.0; 7];
            for row in 0..7 {
                for col in 0..7 {
                    a[row][col] = -h * jac[row][col];
                }
                a[row][row] += m[row];
                rhs[row] = -f[row];
            }
            let Some(dw) = solve7(a, rhs) else {
                self.integration.singular += 1;
                ended = true;
                break;
            };
            let mut lambda = 1.0;
            loop {
                let mut trial = w;
                for i in 0..7 {
                    trial[i] += lambda * dw[i];
                }
                let (gt, jt) = forces.eval(&trial);
                let ft = residual(&trial, &gt);
                let nt = norm(&ft);
                if nt < fnorm || lambda < 1.0 / 64.0 {
                    w = trial;
                    jac = jt;
                    f = ft;
                    fnorm = nt;
                    break;
                }
                lambda *= 0.5;
            }
            if fnorm < NEWTON_TOL {
                ended = true;
                break;
            }
        }
        if !ended {
            self.integration.unconverged += 1;
        }
        let delta: [f64; 7] = std::array::from_fn(|i| w[i] - w_n[i]);
        let mut next = s;
        next.vx += delta[0];
        next.vy += delta[1];
        next.omega += delta[2];
        for i in 0..4 {
            next.theta_dot[i] += delta[3 + i];
            next.theta[i] += h * next.theta_dot[i];
        }
        let phi_mid = s.phi + 0.5 * h * next.omega;
        let velocity = UnitComplex::new(phi_mid) * Vector2::new(next.vx, next.vy);
        next.x += h * velocity.x;
        next.y += h * velocity.y;
        next.phi += h * next.omega;
        // Physical body-frame acceleration: v̇ + ω × v.
        self.accel = [
            delta[0] / h - next.vy * next.omega,
            delta[1] / h + next.vx * next.omega,
        ];
        self.state = next;
    }

    /// Pose `(X, Y, φ)`.
    pub fn pose(&self) -> [f64; 3] {
        [self.state.x, self.state.y, self.state.phi]
    }

    /// The x-coordinate of the instantaneous centre of rotation in the body frame,
    /// `x_ICR = −v_y / ω` (`None` when hardly turning).
    pub fn icr_x(&self) -> Option<f64> {
        (self.state.omega.abs() > 1e-3).then(|| -self.state.vy / self.state.omega)
    }
}

/// Newton iterations per step, at most.
const MAX_NEWTON: usize = 12;
/// Newton stops when the residual (in velocity units) is below this.
const NEWTON_TOL: f64 = 1e-10;

/// What the velocity dynamics `M ẇ = G(w)` need, frozen over one step.
struct Forces {
    d: [[f64; 2]; 4],
    n: [f64; 4],
    mu: [[f64; 3]; 4],
    mass: f64,
    r: f64,
    k: f64,
    tau: [f64; 4],
}

impl Forces {
    /// `G(w)` and `∂G/∂w` for `w = (vx, vy, ω, θ̇1..4)`.
    fn eval(&self, w: &[f64; 7]) -> ([f64; 7], [[f64; 7]; 7]) {
        let (vx, vy, om) = (w[0], w[1], w[2]);
        let (k, r, mass) = (self.k, self.r, self.mass);
        let mut g = [0.0; 7];
        let mut jac = [[0.0; 7]; 7];
        g[0] = mass * vy * om;
        g[1] = -mass * vx * om;
        jac[0][1] = mass * om;
        jac[0][2] = mass * vy;
        jac[1][0] = -mass * om;
        jac[1][2] = -mass * vx;
        let sgy = sg4(k, std::array::from_fn(|i| vy + self.d[i][0] * om));
        for i in 0..4 {
            let [dx, dy] = self.d[i];
            let [mux, muy, mur] = self.mu[i];
            let n = self.n[i];
            let spin = w[3 + i];
            let slip = r * spin - (vx - dy * om);
            let fx = mux * n * sg(k, slip);
            let dfx = mux * n * sg_prime(k, slip); // ∂F_x/∂slip
            let (sy, sy1) = sgy[i];
            let fy = -muy * n * sy;
            let dfy = -muy * n * sy1; // ∂F_y/∂v_iy
            // ∂slip/∂(vx, ω, θ̇_i) = (−1, d_iy, r); ∂v_iy/∂(vy, ω) = (1, d_ix).
            g[0] += fx;
            jac[0][0] -= dfx;
            jac[0][2] += dfx * dy;
            jac[0][3 + i] += dfx * r;
            g[1] += fy;
            jac[1][1] += dfy;
            jac[1][2] += dfy * dx;
            g[2] += dx * fy - dy * fx;
            jac[2][0] += dy * dfx;
            jac[2][1] += dx * dfy;
            jac[2][2] += dx * dfy * dx - dy * dfx * dy;
            jac[2][3 + i] -= dy * dfx * r;
            let roll = mur * n * sg(k, r * spin);
            let droll = mur * n * sg_prime(k, r * spin) * r;
            g[3 + i] = self.tau[i] - r * fx - r * roll;
            jac[3 + i][0] = r * dfx;
            jac[3 + i][2] = -r * dfx * dy;
            jac[3 + i][3 + i] = -r * dfx * r - r * droll;
        }
        (g, jac)
    }
}

/// Solve the 7×7 Newton system `a x = b` (`a` row-major) by nalgebra's LU with
/// partial pivoting: `None` when it is singular (a pivot of magnitude at most
/// 1e-300) or not finite.
fn solve7(a: [[f64; 7]; 7], b: [f64; 7]) -> Option<[f64; 7]> {
    let a = SMatrix::<f64, 7, 7>::from_fn(|row, col| a[row][col]);
    linsolve::solve_lu(a, &SVector::from(b), 1e-300).map(Into::into)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::params::Surface;

    fn p_half_track() -> f64 {
        PlatformParams::peer_default().half_track
    }

    fn plant() -> Plant {
        Plant::new(
            PlatformParams::peer_default(),
            SurfaceMap::concrete(),
            [0.0, 0.0, 0.0],
        )
        .unwrap()
    }

    fn run(p: &mut Plant, tau: [f64; 4], seconds: f64, h: f64) {
        for _ in 0..(seconds / h).round() as usize {
            let t = p.limit(tau);
            p.step(t, h);
        }
    }

    #[test]
    fn solver_matches_a_known_system() {
        let mut a = [[0.0; 7]; 7];
        for i in 0..7 {
            a[i][i] = 2.0 + i as f64;
            a[i][(i + 3) % 7] = 1.0;
        }
        let x_true = [1.0, -2.0, 3.0, 0.5, 0.0, -1.0, 2.0];
        let mut b = [0.0; 7];
        for i in 0..7 {
            b[i] = (0..7).map(|k| a[i][k] * x_true[k]).sum();
        }
        let x = solve7(a, b).unwrap();
        for i in 0..7 {
            assert!((x[i] - x_true[i]).abs() < 1e-12);
        }
        assert!(solve7([[0.0; 7]; 7], b).is_none());
    }

    #[test]
    fn straight_driving_reaches_the_speed_where_torque_balances_rolling_resistance() {
        let mut p = plant();
        run(&mut p, [1.0; 4], 5.0, 1e-3);
        let s = p.state;
        assert!(s.vx > 0.5, "drives forward: {s:?}");
        assert!(s.vy.abs() < 1e-9 && s.omega.abs() < 1e-9, "straight: {s:?}");
        // Steady state: τ = r F_x + r μ_r N sg(r θ̇) per wheel and Σ F_x = 0 ... at
        // steady speed the net force is small: the acceleration has died down.
        let before = s.vx;
        run(&mut p, [1.0; 4], 1.0, 1e-3);
        assert!(
            (p.state.vx - before).abs() < 0.3 * before,
            "approaching a steady speed"
        );
        // Wheels roll with small positive slip.
        let slip = p.params().wheel_radius * p.state.theta_dot[0] - p.state.vx;
        assert!(slip > 0.0 && slip < 0.05, "slip {slip}");
    }

    #[test]
    fn turning_is_torque_hungry_and_the_icr_moves() {
        // Driving straight at a given speed needs little torque; spinning in place at
        // a comparable wheel speed needs much more (lateral friction).
        let turn = |tau: f64| {
            let mut p = plant();
            run(&mut p, [-tau, -tau, tau, tau], 3.0, 1e-3);
            p.state.omega
        };
        let drive = |tau: f64| {
            let mut p = plant();
            run(&mut p, [tau; 4], 3.0, 1e-3);
            p.state.vx / p.params().wheel_radius
        };
        let (slow, fast) = (turn(3.0), turn(8.0));
        eprintln!(
            "turn rate at 3 N m {slow}, at 8 N m {fast}; wheel rate driving at 3 N m {}",
            drive(3.0)
        );
        // Below the lateral friction moment (≈ 4 N m per wheel) the platform creeps
        // round in the smooth part of the friction sign; above it, it spins up.
        assert!(
            slow < 0.5 && fast > 4.0 * slow,
            "3 N m: {slow} rad/s, 8 N m: {fast} rad/s"
        );
        // The same 3 N m driving straight spins the wheels far faster than turning does.
        let wheel_when_turning =
            slow * p_half_track() / PlatformParams::peer_default().wheel_radius;
        assert!(drive(3.0) > 10.0 * wheel_when_turning);
        // A curve: the ICR is not at the centre of mass and depends on the speed.
        let icr = |tau: [f64; 4]| {
            let mut curve = plant();
            run(&mut curve, tau, 1.0, 1e-3);
            curve.icr_x().expect("turning")
        };
        let (gentle, hard) = (icr([1.0, 1.0, 4.0, 4.0]), icr([1.0, 1.0, 8.0, 8.0]));
        assert!(
            gentle.abs() > 1e-4,
            "the ICR is shifted from the COM: {gentle}"
        );
        assert!(
            (gentle - hard).abs() > 1e-4,
            "and moves with the manoeuvre: {gentle} vs {hard}"
        );
    }

    #[test]
    fn stable_for_stiff_wheels() {
        // Wheel inertia 100× smaller and a near-Coulomb friction sign: eigenvalues
        // of 10⁵–10⁶ s⁻¹, way beyond any explicit method at 1 kHz.
        let params = PlatformParams {
            wheel_inertia: 1e-4,
            sign_smoothing: 500.0,
            ..PlatformParams::peer_default()
        };
        let mut p = Plant::new(params, SurfaceMap::concrete(), [0.0; 3]).unwrap();
        run(&mut p, [5.0, 5.0, 6.0, 6.0], 2.0, 1e-3);
        let s = p.state;
        let all = [s.x, s.y, s.vx, s.vy, s.omega];
        assert!(
            all.iter().all(|v| v.is_finite() && v.abs() < 100.0),
            "{s:?}"
        );
        assert!(
            s.theta_dot.iter().all(|w| w.is_finite() && w.abs() < 100.0),
            "{s:?}"
        );
    }

    #[test]
    fn one_millisecond_agrees_with_a_fine_reference() {
        // The same manoeuvre at h = 1 ms and h = 0.01 ms: positions within 1 cm after 2 s.
        let tau = [3.0, 3.0, 5.0, 5.0];
        let mut coarse = plant();
        run(&mut coarse, tau, 2.0, 1e-3);
        let mut fine = plant();
        run(&mut fine, tau, 2.0, 1e-5);
        let dx = coarse.state.x - fine.state.x;
        let dy = coarse.state.y - fine.state.y;
        assert!(
            (dx * dx + dy * dy).sqrt() < 0.01,
            "{:?} vs {:?}",
            coarse.state,
            fine.state
        );
        assert!((coarse.state.phi - fine.state.phi).abs() < 0.01);
    }

    #[test]
    fn ice_under_the_wheels_makes_them_spin() {
        let mut map = SurfaceMap::concrete();
        map.surfaces.push(Surface {
            name: "ice".into(),
            mu_long: 0.08,
            mu_lat: 0.05,
            rolling: 0.01,
        });
        map.default = "ice".into();
        let mut ice = Plant::new(PlatformParams::peer_default(), map, [0.0; 3]).unwrap();
        let mut concrete = plant();
        run(&mut ice, [4.0; 4], 1.0, 1e-3);
        run(&mut concrete, [4.0; 4], 1.0, 1e-3);
        let slip = |p: &Plant| p.params().wheel_radius * p.state.theta_dot[0] - p.state.vx;
        assert!(
            slip(&ice) > 10.0 * slip(&concrete).max(1e-3),
            "ice {} concrete {}",
            slip(&ice),
            slip(&concrete)
        );
        assert!(ice.state.vx < concrete.state.vx);
    }

    #[test]
    fn bad_commands_are_clamped_and_counted_once_per_command() {
        let mut p = plant();
        let t = p.clean([f64::NAN, 100.0, -100.0, 1.0]);
        assert_eq!(t, [0.0, 10.0, -10.0, 1.0]);
        assert_eq!(
            p.command_stats(),
            CommandStats {
                not_finite: 1,
                out_of_bounds: 1
            },
            "one command with a NaN and two torques beyond the bounds"
        );
        assert_eq!(p.clean([f64::INFINITY; 4]), [0.0; 4]);
        assert_eq!(p.clean([f64::NEG_INFINITY, 0.0, 0.0, 0.0]), [0.0; 4]);
        assert_eq!(p.clean([10.0, -10.0, 0.0, 3.0]), [10.0, -10.0, 0.0, 3.0]);
        assert_eq!(
            p.command_stats(),
            CommandStats {
                not_finite: 3,
                out_of_bounds: 1
            },
            "infinities are not finite; ±torque_max is within bounds"
        );
        // The motor curve applies at every step and counts nothing.
        p.state.theta_dot = [30.0; 4];
        assert_eq!(
            p.available([5.0; 4]),
            [0.0; 4],
            "no drive torque at the no-load speed"
        );
        assert_eq!(p.available([-5.0; 4]), [-5.0; 4], "braking is not limited");
        p.state.theta_dot = [15.0; 4];
        assert_eq!(
            p.available([8.0, -8.0, f64::NAN, 50.0]),
            [5.0, -8.0, 0.0, 5.0]
        );
        assert_eq!(
            p.command_stats().not_finite,
            3,
            "available() counts nothing"
        );
        assert_eq!(p.command_stats().out_of_bounds, 1);
        assert_eq!(p.limit([f64::NAN; 4]), [0.0; 4]);
        assert_eq!(
            p.command_stats().not_finite,
            4,
            "limit() cleans, and counts"
        );
    }

    #[test]
    fn invalid_parameters_ground_or_pose_are_errors() {
        let bad = PlatformParams {
            mass: -1.0,
            ..PlatformParams::peer_default()
        };
        let err = Plant::new(bad, SurfaceMap::concrete(), [0.0; 3]).unwrap_err();
        assert!(err.to_string().contains("<platform>: mass = -1"), "{err}");
        // A centre of mass over an axle leaves the other axle's wheels without
        // load, which the prediction models divide by.
        let over_the_axle = PlatformParams {
            rear: 0.0,
            ..PlatformParams::peer_default()
        };
        let err = Plant::new(over_the_axle, SurfaceMap::concrete(), [0.0; 3]).unwrap_err();
        assert!(err.to_string().contains("<platform>: rear = 0"), "{err}");
        let empty = SurfaceMap {
            surfaces: Vec::new(),
            ..SurfaceMap::concrete()
        };
        let err = Plant::new(PlatformParams::peer_default(), empty, [0.0; 3]).unwrap_err();
        assert!(err.to_string().contains("<surfaces>: surfaces"), "{err}");
        let mut twice = SurfaceMap::concrete();
        twice.surfaces.push(twice.surfaces[0].clone());
        let err = Plant::new(PlatformParams::peer_default(), twice, [0.0; 3]).unwrap_err();
        assert!(err.to_string().contains("surfaces[1].name"), "{err}");
        let err = Plant::new(
            PlatformParams::peer_default(),
            SurfaceMap::concrete(),
            [0.0, f64::NAN, 0.0],
        )
        .unwrap_err();
        assert!(err.to_string().contains("<start pose>: y = NaN"), "{err}");
    }

    #[test]
    fn a_failed_newton_solve_is_counted() {
        // A normal run: every step converges.
        let mut p = plant();
        run(&mut p, [3.0, 3.0, 6.0, 6.0], 2.0, 1e-3);
        assert_eq!(p.integration_stats(), IntegrationStats::default());
        // A NaN velocity makes the Newton system unsolvable: the step keeps the
        // velocities it started with, and is counted.
        p.state.vy = f64::NAN;
        let before = p.state;
        p.step([1.0; 4], 1e-3);
        assert_eq!(
            p.integration_stats(),
            IntegrationStats {
                singular: 1,
                unconverged: 0
            }
        );
        assert_eq!(p.state.vx, before.vx, "frozen");
        assert_eq!(p.state.theta_dot, before.theta_dot, "frozen");
        p.step([1.0; 4], 1e-3);
        assert_eq!(p.integration_stats().singular, 2);
    }

    #[test]
    fn load_transfer_shows_on_the_wheels() {
        let mut p = plant();
        run(&mut p, [6.0; 4], 0.1, 1e-3);
        let n = p.loads();
        assert!(
            n[1] > n[0] && n[3] > n[2],
            "accelerating forward loads the rear wheels: {n:?}"
        );
        let total: f64 = n.iter().sum();
        let weight = p.params().mass * p.params().gravity;
        assert!((total - weight).abs() < 1e-6);
    }
}
