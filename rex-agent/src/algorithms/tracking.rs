//! Trajectory trackers of the platform (used by `e11`), behind [`Tracker`]: a baseline (Kanayama's law over
//! a computed-torque loop) and the paper's NMPC ([`NmpcTracker`]).

use super::estimation::Estimate;
use crate::algorithms::mpc::nmpc::{DisturbanceObserver, DisturbanceSettings};
use crate::algorithms::mpc::{LateralNmpc, NmpcError, NmpcSettings};
use crate::algorithms::planner::nearest_angle;
use crate::model::{Friction, Lateral, PlatformParams, Reduced, Torques};

/// A trajectory tracker: wheel torques from the estimate and the reference.
pub trait Tracker: Send + std::fmt::Debug {
    /// Name for reports.
    fn name(&self) -> &'static str;

    /// How many samples of reference beyond the current one the tracker looks at
    /// (a predictive controller's horizon); e1,1 hands it `horizon() + 1` samples.
    fn horizon(&self) -> usize {
        1
    }

    /// Torques that make the platform follow the reference `(X, Y, φ, v, ω)`:
    /// `reference[k]` is the reference `k · dt` from now (`horizon() + 1` samples).
    fn control(&mut self, estimate: &Estimate, reference: &[[f64; 5]], dt: f64) -> Torques;

    /// A sample without control (no reference to follow, or not localised):
    /// the torques are zero, and the next [`Tracker::control`] does not follow
    /// the last one.
    fn idle(&mut self) {}

    /// Counters for reports (solver failures, fallbacks...).
    fn report(&self) -> TrackerReport {
        TrackerReport::default()
    }

    /// Bound each wheel's torque by `torque_max` \[N m\] (`None`: the
    /// platform's, as built) and, for a tracker that keeps within the ground's
    /// traction (the NMPC), by `traction_margin` times that traction. A bound
    /// above the platform's limit lets the commands exceed it (the platform
    /// clamps them). The values are checked by the run file's validation;
    /// one not positive and finite changes nothing.
    fn set_torque_bounds(&mut self, torque_max: Option<f64>, traction_margin: f64);
}

/// The share of each wheel's traction the NMPC's torques may use by default
/// ([`Tracker::set_torque_bounds`]).
pub const TRACTION_MARGIN: f64 = 0.85;

/// What a tracker reports about its work.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct TrackerReport {
    /// Optimisation problems solved.
    pub solves: u64,
    /// Of which with a bound active (solved by the interior-point method on
    /// the stages, or by Clarabel).
    pub constrained: u64,
    /// Of which by Clarabel (the interior-point method did not converge, or
    /// `QpStrategy::Clarabel`).
    pub clarabel: u64,
    /// Failed solves.
    pub failures: u64,
    /// Samples on the shifted previous solution.
    pub fallbacks: u64,
    /// Samples braking to a stop.
    pub safe_stops: u64,
    /// Samples whose inputs were refused (a non-finite estimate or reference).
    pub refused: u64,
}

/// Which tracker.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum TrackerKind {
    /// Kinematic tracking law with a computed-torque velocity loop.
    #[default]
    Backstepping,
    /// Nonlinear model predictive control (the paper's).
    Nmpc,
}

impl std::str::FromStr for TrackerKind {
    type Err = crate::config::UnknownChoice;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "backstepping" | "baseline" => Ok(TrackerKind::Backstepping),
            "nmpc" => Ok(TrackerKind::Nmpc),
            _ => Err(crate::config::UnknownChoice::new(
                "tracker",
                s,
                "backstepping, nmpc",
            )),
        }
    }
}

impl TrackerKind {
    /// A tracker of this kind for the platform `params`, run every `dt` seconds.
    pub fn build(self, params: PlatformParams, dt: f64) -> Result<Box<dyn Tracker>, NmpcError> {
        Ok(match self {
            TrackerKind::Backstepping => Box::new(Backstepping::new(params)),
            TrackerKind::Nmpc => Box::new(NmpcTracker::new(params, dt)?),
        })
    }
}

/// Below this speed along the path \[m/s\] its direction is the planner's
/// heading (finite differences of positions a few millimetres apart say little).
const MOVING: f64 = 0.02;

/// The NMPC of [`crate::algorithms::mpc::nmpc`] as e1,1's tracker, on the
/// lateral-slip model with the ground's friction of the estimate (the MHE's; the
/// concrete's when the estimator has none), the bounds of the platform, one
/// real-time iteration per sample.
///
/// Two things it takes from what it knows of the ground:
///
/// * **The reference, made consistent with the model.** The planner's reference
///   `(X, Y, φ, v, ω)` describes a path and a speed along it; on a slippery
///   ground the body must turn its nose into each bend by the sideslip angle
///   `β = atan2(v_y, v_x)` of the steady turn ([`Lateral::steady_lateral`]),
///   and its lateral velocity is `v_y`, not zero. The tracker recomputes the
///   heading, forward and lateral velocities of each sample from the path's
///   tangent and speed (finite differences of its positions) and that steady
///   turn: tracking the planner's heading would make the NMPC trade position for
///   a heading the ground does not allow.
/// * **The traction bound.** Each wheel's torque stays below `traction_margin`
///   times what the ground can take, `r μ_x N` (the rest of the model's force
///   law bends onto that bound): above it the wheel spins and the model no
///   longer holds.
///
/// A refused input (a non-finite estimate or reference) keeps the last torques
/// for the fallback steps the NMPC allows, then brakes.
#[derive(Debug)]
pub struct NmpcTracker {
    nmpc: LateralNmpc,
    /// What the model leaves out (offset-free tracking).
    observer: DisturbanceObserver<6>,
    /// The fraction of the traction bound the torques may use.
    traction_margin: f64,
    /// The model's reference over the horizon (reused every sample).
    reference: Vec<[f64; 6]>,
    last: Torques,
    refused: u64,
    refused_in_a_row: usize,
}

impl NmpcTracker {
    /// An NMPC for the platform `params` with the peers' weights and horizon, at
    /// interval `dt`.
    pub fn new(params: PlatformParams, dt: f64) -> Result<NmpcTracker, NmpcError> {
        let settings = NmpcSettings {
            dt,
            torque_max: params.torque_max,
            speed_max: params.speed_max,
            yaw_rate_max: params.yaw_rate_max,
            ..NmpcSettings::<6>::default()
        };
        Ok(NmpcTracker {
            nmpc: LateralNmpc::new(Lateral::new(params), settings)?,
            observer: DisturbanceObserver::new(DisturbanceSettings::<6>::default()),
            traction_margin: TRACTION_MARGIN,
            reference: Vec::new(),
            last: [0.0; 4],
            refused: 0,
            refused_in_a_row: 0,
        })
    }

    /// The controller.
    pub fn nmpc(&self) -> &LateralNmpc {
        &self.nmpc
    }

    /// The model's reference `(X, Y, φ, v_x, v_y, ω)` for the planner's
    /// `(X, Y, φ, v, ω)` samples `dt` apart on the ground `friction`, headings
    /// unwrapped from `heading`.
    pub fn model_reference(
        model: &Lateral,
        reference: &[[f64; 5]],
        dt: f64,
        friction: &Friction,
        heading: f64,
        out: &mut Vec<[f64; 6]>,
    ) {
        out.clear();
        let n = reference.len();
        let mut last_phi = heading;
        for k in 0..n {
            let r = reference[k];
            // The path's velocity by central differences (one-sided at the ends).
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
            let span = (b - a) as f64 * dt;
            let (dx, dy) = (
                reference[b][0] - reference[a][0],
                reference[b][1] - reference[a][1],
            );
            let speed = if span > 0.0 { dx.hypot(dy) / span } else { 0.0 };
            // Where the path goes, and whether the body goes forwards or
            // backwards along it (its heading against the path's direction);
            // hardly moving, the direction is not defined: the planner's
            // heading.
            let moving = speed > MOVING;
            let psi = dy.atan2(dx);
            let forwards = !moving || (psi - r[2]).cos() >= 0.0;
            let tangent = match (moving, forwards) {
                (false, _) => r[2],
                (true, true) => psi,
                (true, false) => psi + std::f64::consts::PI,
            };
            let w = r[4];
            let v_signed = if forwards { speed } else { -speed };
            let vy = if moving {
                model.steady_lateral(v_signed, w, friction).unwrap_or(0.0)
            } else {
                0.0
            };
            let vx = v_signed.signum() * (speed * speed - vy * vy).max(0.0).sqrt();
            // The velocity points along the tangent: φ = ψ − atan2(v_y, v_x)
            // (for v_x < 0, the tangent already turned by π above).
            let beta = if moving {
                (vy / speed).clamp(-1.0, 1.0).asin() * v_signed.signum()
            } else {
                0.0
            };
            let phi = nearest_angle(tangent - beta, last_phi);
            last_phi = phi;
            out.push([r[0], r[1], phi, vx, vy, w]);
        }
    }
}

impl Tracker for NmpcTracker {
    fn name(&self) -> &'static str {
        "nmpc"
    }

    fn horizon(&self) -> usize {
        self.nmpc.settings().horizon
    }

    fn control(&mut self, e: &Estimate, reference: &[[f64; 5]], dt: f64) -> Torques {
        let friction = e.friction.unwrap_or(Friction::CONCRETE);
        // The estimate's heading, unwrapped next to the reference's.
        let [x, y, phi, v, w] = e.x;
        let phi = reference.first().map_or(phi, |r| nearest_angle(phi, r[2]));
        let vy = e.lateral.unwrap_or_else(|| {
            self.nmpc
                .model()
                .steady_lateral(v, w, &friction)
                .unwrap_or(0.0)
        });
        let state = [x, y, phi, v, vy, w];
        let mut model_reference = std::mem::take(&mut self.reference);
        Self::model_reference(
            self.nmpc.model(),
            reference,
            dt,
            &friction,
            phi,
            &mut model_reference,
        );
        // The traction bound of each wheel on this ground (refused only if not
        // finite: then the previous limits stay).
        let model = self.nmpc.model();
        let limits: [f64; 4] = std::array::from_fn(|i| {
            self.traction_margin * model.traction_torque(i, friction.mu_long)
        });
        let _ = self.nmpc.set_torque_limits(limits);
        let d = self.observer.update(&self.nmpc, &state);
        // The observer's disturbance is finite (bounded, non-finite errors
        // skipped): accepted.
        let _ = self.nmpc.set_disturbance(&d);
        let result = self
            .nmpc
            .control(&state, &model_reference, &friction.to_array());
        self.reference = model_reference;
        match result {
            Ok(c) => {
                self.observer.applied(&state, &c.torques);
                self.refused_in_a_row = 0;
                self.last = c.torques;
                c.torques
            }
            Err(_) => {
                // Inputs the NMPC refuses: hold the last torques briefly, then stop.
                self.observer.gap();
                self.refused += 1;
                self.refused_in_a_row += 1;
                if self.refused_in_a_row > self.nmpc.settings().fallback_steps {
                    self.nmpc.reset();
                    self.last = [0.0; 4];
                }
                self.last
            }
        }
    }

    fn idle(&mut self) {
        self.observer.gap();
    }

    fn set_torque_bounds(&mut self, torque_max: Option<f64>, traction_margin: f64) {
        if let Some(t) = torque_max {
            let _ = self.nmpc.set_torque_max(t);
        }
        if traction_margin.is_finite() && traction_margin > 0.0 {
            self.traction_margin = traction_margin;
        }
    }

    fn report(&self) -> TrackerReport {
        let s = self.nmpc.stats();
        TrackerReport {
            solves: s.qps,
            constrained: s.ipm + s.clarabel,
            clarabel: s.clarabel,
            failures: s.failures,
            fallbacks: s.fallbacks,
            safe_stops: s.safe_stops,
            refused: self.refused,
        }
    }
}

/// Gains of [`Backstepping`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gains {
    /// Along-track position gain \[1/s\].
    pub kx: f64,
    /// Cross-track gain \[1/m²\].
    pub ky: f64,
    /// Heading gain \[1/m\].
    pub kphi: f64,
    /// Heading gain at standstill \[1/s\].
    pub kphi_rest: f64,
    /// Speed loop gain \[1/s\].
    pub kv: f64,
    /// Turn-rate loop gain \[1/s\].
    pub kw: f64,
    /// Integral gain of the speed loop \[1/s²\].
    pub ki_v: f64,
    /// Integral gain of the turn-rate loop \[1/s²\].
    pub ki_w: f64,
    /// Bound of each integral term (as an acceleration) \[m/s², rad/s²\].
    pub i_max: f64,
}

impl Default for Gains {
    fn default() -> Self {
        Gains {
            kx: 2.0,
            ky: 40.0,
            kphi: 5.0,
            kphi_rest: 2.5,
            kv: 8.0,
            kw: 15.0,
            ki_v: 10.0,
            ki_w: 30.0,
            i_max: 3.0,
        }
    }
}

/// The classic two-level tracker of mobile robotics, adapted to the skid-steer's
/// torque inputs: Kanayama's kinematic tracking law gives the wanted speed and turn
/// rate from the pose error in the body frame,
///
/// ```text
/// v_c = v_r cos e_φ + k_x e_x,      ω_c = ω_r + v_r k_y e_y + (|v_r| k_φ + k_φ0) sin e_φ
/// ```
///
/// (Kanayama writes `v_r k_φ`: his Lyapunov function decreases only for `v_r > 0`,
/// and reversing, which ECSA plans when a fragment must end at a heading it cannot
/// reach forwards, turned the heading away from the reference until the platform
/// was 0.35 m off; with `|v_r|` it decreases either way.)
///
/// and a computed-torque loop inverts the reduced dynamics (§1.3) for the wanted
/// accelerations `v̇_c + k_v (v_c − v) + k_iv ∫(v_c − v)`, `ω̇_c + k_ω (ω_c − ω) + k_iω ∫(ω_c − ω)`,
/// giving one torque per side (the same on the front and rear wheel). Torques are
/// clamped to the bounds. The integral terms take up what the model gets wrong
/// (above all the lateral friction that resists turning, which depends on the
/// ground): without them a turn-rate deficit remains, and the kinematic law can only
/// cancel it with a standing cross-track error `e_y ≈ Δω / (k_y v)`. They are
/// bounded, and frozen while a torque saturates (anti-windup).
#[derive(Debug)]
pub struct Backstepping {
    model: Reduced,
    /// Gains.
    pub gains: Gains,
    /// Integrals of the speed and turn-rate errors.
    integral: [f64; 2],
}

impl Backstepping {
    /// A tracker for the platform `params`.
    pub fn new(params: PlatformParams) -> Backstepping {
        Backstepping {
            model: Reduced::new(params),
            gains: Gains::default(),
            integral: [0.0; 2],
        }
    }

    fn command(&self, e: &Estimate, r: &[f64; 5]) -> (f64, f64) {
        let g = &self.gains;
        let [x, y, phi, _, _] = e.x;
        let (s, c) = phi.sin_cos();
        let (dx, dy) = (r[0] - x, r[1] - y);
        let ex = c * dx + s * dy;
        let ey = -s * dx + c * dy;
        let ephi = (r[2] - phi + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU)
            - std::f64::consts::PI;
        let v = r[3] * ephi.cos() + g.kx * ex;
        let w = r[4] + r[3] * g.ky * ey + (r[3].abs() * g.kphi + g.kphi_rest) * ephi.sin();
        (v, w)
    }
}

impl Tracker for Backstepping {
    fn name(&self) -> &'static str {
        "backstepping"
    }

    fn set_torque_bounds(&mut self, torque_max: Option<f64>, _: f64) {
        if let Some(t) = torque_max.filter(|t| t.is_finite() && *t > 0.0) {
            self.model.params.torque_max = t;
        }
    }

    fn control(&mut self, e: &Estimate, horizon: &[[f64; 5]], dt: f64) -> Torques {
        let Some(reference) = horizon.first() else {
            return [0.0; 4];
        };
        let next = horizon.get(1).unwrap_or(reference);
        let g = self.gains;
        let p = &self.model.params;
        let (vc, wc) = self.command(e, reference);
        let (ev, ew) = (vc - e.x[3], wc - e.x[4]);
        let iv = (g.ki_v * self.integral[0]).clamp(-g.i_max, g.i_max);
        let iw = (g.ki_w * self.integral[1]).clamp(-g.i_max, g.i_max);
        // Feed-forward: the reference's accelerations; feedback on the velocities.
        let vdot = (next[3] - reference[3]) / dt + g.kv * ev + iv;
        let wdot = (next[4] - reference[4]) / dt + g.kw * ew + iw;
        // Accelerations with zero torque, then the torques that add what is missing.
        let free = self.model.f5(&e.x, &[0.0; 4], &e.p);
        let m_eff = p.effective_mass();
        let i_eff = p.inertia
            + p.mass * e.p.x_icr.powi(2)
            + 4.0 * p.wheel_inertia * p.half_track.powi(2) / p.wheel_radius.powi(2);
        let sum = (vdot - free[3]) * p.wheel_radius * m_eff / 2.0;
        let diff = (wdot - free[4]) * p.wheel_radius * i_eff / (2.0 * p.half_track);
        let (left, right) = ((sum - diff) / 2.0, (sum + diff) / 2.0);
        let saturated = left.abs() > p.torque_max || right.abs() > p.torque_max;
        if !saturated && ev.is_finite() && ew.is_finite() {
            self.integral[0] += ev * dt;
            self.integral[1] += ew * dt;
        }
        let clamp = |t: f64| {
            if t.is_finite() {
                t.clamp(-p.torque_max, p.torque_max)
            } else {
                0.0
            }
        };
        [clamp(left), clamp(left), clamp(right), clamp(right)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::SlipParams;

    #[test]
    fn a_tracker_is_chosen_by_name_and_an_unknown_name_lists_the_options() {
        assert_eq!("nmpc".parse(), Ok(TrackerKind::Nmpc));
        assert_eq!("baseline".parse(), Ok(TrackerKind::Backstepping));
        let e = "pid".parse::<TrackerKind>().unwrap_err();
        assert_eq!(e.given, "pid");
        assert_eq!(e.to_string(), "unknown tracker `pid` (backstepping, nmpc)");
    }

    #[test]
    fn drives_the_reduced_model_onto_a_reference_forwards_and_backwards() {
        for speed in [0.7, -0.7] {
            // Closed loop on the reduced model: start 10 cm off a straight
            // reference, 0.2 rad off its heading.
            let params = PlatformParams::peer_default();
            let model = Reduced::new(params.clone());
            let mut t = Backstepping::new(params);
            let p = SlipParams::NOMINAL;
            let mut x = [0.0, 0.1, 0.2, 0.0, 0.0];
            let dt = 0.05;
            let reference = |k: usize| [speed * k as f64 * dt, 0.0, 0.0, speed, 0.0];
            let mut worst: f64 = 0.0;
            for k in 0..200 {
                let e = Estimate {
                    x,
                    p,
                    ..Estimate::default()
                };
                let tau = t.control(&e, &[reference(k), reference(k + 1)], dt);
                x = model.rk4_5(&x, &tau, &p, dt, 4);
                let r = reference(k + 1);
                worst = worst.max((x[0] - r[0]).hypot(x[1] - r[1]));
            }
            let r = reference(200);
            assert!(
                (x[0] - r[0]).hypot(x[1] - r[1]) < 0.01,
                "v = {speed}: {x:?} vs {r:?}"
            );
            assert!(worst < 0.2, "v = {speed}: worst {worst}");
        }
    }

    #[test]
    fn drives_the_reduced_model_onto_a_reference() {
        // Closed loop on the reduced model: start 10 cm off a straight reference.
        let params = PlatformParams::peer_default();
        let model = Reduced::new(params.clone());
        let mut t = Backstepping::new(params);
        let p = SlipParams::NOMINAL;
        let mut x = [0.0, 0.1, 0.0, 0.0, 0.0];
        let dt = 0.05;
        let reference = |k: usize| [0.3 * k as f64 * dt, 0.0, 0.0, 0.3, 0.0];
        for k in 0..200 {
            let e = Estimate {
                x,
                p,
                ..Estimate::default()
            };
            let tau = t.control(&e, &[reference(k), reference(k + 1)], dt);
            x = model.rk4_5(&x, &tau, &p, dt, 4);
        }
        let r = reference(200);
        assert!((x[0] - r[0]).hypot(x[1] - r[1]) < 0.01, "{x:?} vs {r:?}");
    }
}
