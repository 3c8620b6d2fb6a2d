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
    /// World position of the centre of mass \[m\].
    pub x: f64,
    /// World position of the centre of mass \[m\].
    pub y: f64,
    /// Heading \[rad\] (not wrapped).
    pub phi: f64,
    /// Body-frame forward velocity \[m/s\].
    pub vx: f64,
    /// Body-frame lateral velocity \[m/s\].
    pub vy: f64,
    /// Yaw rate \[rad/s\].
    pub omega: f64,
    /// Wheel angles \[rad\].
    pub theta: [f64; 4],
    /// Wheel rates \[rad/s\].
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
    /// Body-frame acceleration `(a_x, a_y)` of the last step \[m/s²\].
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

    /// Normal load of each wheel in the last step \[N\].
    pub fn loads(&self) -> [f64; 4] {
        self.loads
    }

    /// Body-frame acceleration `(a_x, a_y)` in the last step \[m/s²\].
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

    /// Advance by `h` seconds with wheel torques `tau` (already limited): the
    /// normal loads and the ground under the wheels, the velocities by backward
    /// Euler (module docs), then the angles and the pose with them.
    pub fn step(&mut self, tau: [f64; 4], h: f64) {
        let n = self.normal_loads();
        self.loads = n;
        let mu = self.ground();
        let euler = self.backward_euler(tau, n, mu, h);
        let (w, end) = euler.solve();
        match end {
            NewtonEnd::Converged => {}
            NewtonEnd::Singular => self.integration.singular += 1,
            NewtonEnd::Unconverged => self.integration.unconverged += 1,
        }
        self.advance(&w, &euler.w_n, h);
    }

    /// The normal loads with the load transfer of the last accelerations.
    fn normal_loads(&self) -> [f64; 4] {
        let p = &self.params;
        let long = p.mass * self.accel[0] * p.cog_height / (2.0 * (p.front + p.rear));
        let lat = p.mass * self.accel[1] * p.cog_height / (4.0 * p.half_track);
        let mut n = self.n_static;
        for i in 0..4 {
            let front = if self.d[i][0] > 0.0 { -1.0 } else { 1.0 };
            let left = if self.d[i][1] > 0.0 { -1.0 } else { 1.0 };
            n[i] = (n[i] + front * long + left * lat).max(0.0);
        }
        n
    }

    /// The friction `(μ_x, μ_y, μ_r)` of the ground under each wheel.
    fn ground(&self) -> [[f64; 3]; 4] {
        let s = &self.state;
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
        mu
    }

    /// The velocities' implicit step from the current state, with the normal
    /// loads `n`, the ground `mu` and the torques `tau`.
    fn backward_euler(
        &self,
        tau: [f64; 4],
        n: [f64; 4],
        mu: [[f64; 3]; 4],
        h: f64,
    ) -> BackwardEuler {
        let p = &self.params;
        let s = &self.state;
        BackwardEuler {
            m: [
                p.mass,
                p.mass,
                p.inertia,
                p.wheel_inertia,
                p.wheel_inertia,
                p.wheel_inertia,
                p.wheel_inertia,
            ],
            w_n: [
                s.vx,
                s.vy,
                s.omega,
                s.theta_dot[0],
                s.theta_dot[1],
                s.theta_dot[2],
                s.theta_dot[3],
            ],
            h,
            forces: Forces {
                d: self.d,
                n,
                mu,
                mass: p.mass,
                r: p.wheel_radius,
                k: p.sign_smoothing,
                tau,
            },
        }
    }

    /// The state after the step from the new velocities `w` (the old ones
    /// `w_n`): the wheel angles and the pose advanced with them (the pose with
    /// the mid-step heading), and the body-frame acceleration.
    fn advance(&mut self, w: &[f64; 7], w_n: &[f64; 7], h: f64) {
        let s = self.state;
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

/// Backward Euler on the velocities `w = (vx, vy, ω, θ̇1..4)`:
/// `M (w − w_n) − h G(w) = 0`, solved by Newton's method with the analytic
/// Jacobian, damped by halving the update while the residual does not
/// decrease. The first iteration is the linearly implicit (Rosenbrock) Euler
/// step; more are needed only when a friction force crosses its steep region
/// within the step.
struct BackwardEuler {
    /// The diagonal of `M`.
    m: [f64; 7],
    w_n: [f64; 7],
    h: f64,
    forces: Forces,
}

/// How the Newton iterations of a step ended.
enum NewtonEnd {
    /// The residual is below [`NEWTON_TOL`].
    Converged,
    /// The Newton system could not be solved: the last iterate is kept.
    Singular,
    /// Every iteration used, the residual still above the tolerance.
    Unconverged,
}

/// A Newton iterate: the velocities, `∂G/∂w` there, the residual and its norm.
struct Iterate {
    w: [f64; 7],
    jac: [[f64; 7]; 7],
    f: [f64; 7],
    norm: f64,
}

impl BackwardEuler {
    /// The new velocities, and how the iterations ended (the last iterate when
    /// the system is singular or the iterations run out).
    fn solve(&self) -> ([f64; 7], NewtonEnd) {
        let mut it = self.at(self.w_n);
        for _ in 0..MAX_NEWTON {
            let Some(dw) = self.newton_update(&it) else {
                return (it.w, NewtonEnd::Singular);
            };
            it = self.damped(&it, &dw);
            if it.norm < NEWTON_TOL {
                return (it.w, NewtonEnd::Converged);
            }
        }
        (it.w, NewtonEnd::Unconverged)
    }

    /// The iterate at `w`.
    fn at(&self, w: [f64; 7]) -> Iterate {
        let (g, jac) = self.forces.eval(&w);
        let f = self.residual(&w, &g);
        let norm = self.norm(&f);
        Iterate { w, jac, f, norm }
    }

    /// The residual `F(w) = M (w − w_n) − h G(w)`.
    fn residual(&self, w: &[f64; 7], g: &[f64; 7]) -> [f64; 7] {
        let mut f = [0.0; 7];
        for i in 0..7 {
            f[i] = self.m[i] * (w[i] - self.w_n[i]) - self.h * g[i];
        }
        f
    }

    /// The residual's norm in velocity units.
    fn norm(&self, f: &[f64; 7]) -> f64 {
        (0..7)
            .map(|i| (f[i] / self.m[i]).powi(2))
            .sum::<f64>()
            .sqrt()
    }

    /// Newton's update `Δw` from `(M − h ∂G/∂w) Δw = −F(w)`; `None` if the
    /// system is singular.
    fn newton_update(&self, it: &Iterate) -> Option<[f64; 7]> {
        let mut a = [[0.0; 7]; 7];
        let mut rhs = [0.0; 7];
        for row in 0..7 {
            for col in 0..7 {
                a[row][col] = -self.h * it.jac[row][col];
            }
            a[row][row] += self.m[row];
            rhs[row] = -it.f[row];
        }
        solve7(a, rhs)
    }

    /// The iterate along `dw`, the step halved while the residual does not
    /// decrease; a step of 1/128 of `dw` is taken whatever its residual.
    fn damped(&self, it: &Iterate, dw: &[f64; 7]) -> Iterate {
        let mut lambda = 1.0;
        loop {
            let mut trial = it.w;
            for i in 0..7 {
                trial[i] += lambda * dw[i];
            }
            let next = self.at(trial);
            if next.norm < it.norm || lambda < 1.0 / 64.0 {
                return next;
            }
            lambda *= 0.5;
        }
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
mod tests;
