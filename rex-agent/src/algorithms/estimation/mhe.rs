//! Rex's moving-horizon estimator behind [`Estimator`], with the friction's
//! random walk that follows a change of ground.

use std::collections::VecDeque;

use super::{
    DISAGREEMENT_SPAN_S, Estimate, Estimator, EstimatorHealth, Measurements, forget_before,
};
use crate::algorithms::mpc::{
    Innovation, LateralMhe, MheError, MheSettings, Motion, Sample, TimedPose,
};
use crate::model::{Friction, Lateral, PlatformParams, SlipParams, Torques};
use crate::payload::Transform;

/// The MHE of [`crate::algorithms::mpc::mhe`] on the lateral-slip model as e1,1's
/// estimator. Every iteration of e1,1 is a sample: the encoder rates, the
/// gyroscope rate, the IMU heading once it is aligned with the map, the wheel
/// loads, the map pose when one arrives (attached to the time it describes: the
/// map agent's poses are late), and the visual odometry's motion between two
/// pairs (`A4x4`, relayed by c1). It estimates the lateral velocity and the
/// ground's friction `(μ_x, μ_y, μ_r)` with the state; the NMPC uses them.
#[derive(Debug)]
pub struct MheEstimator {
    mhe: LateralMhe,
    theta: [f64; 4],
    theta_dot: [f64; 4],
    settling: Settling,
    walk: FrictionWalk,
}

/// Whether the friction estimate has settled: the platform has been moving for
/// [`Settling::MOVING_S`] and over the last [`Settling::WINDOW_S`] the estimated
/// `μ_x` and `μ_y` stayed within [`Settling::BAND`] of their mean. Not latched:
/// on a new ground the estimate moves again, and is unsettled until it stops.
#[derive(Clone, Debug, Default)]
struct Settling {
    moving: f64,
    recent: VecDeque<(f64, [f64; 2])>,
}

/// The friction's random walk: how far each sample may move the estimate of
/// `(μ_x, μ_y, μ_r)` (the MHE's arrival cost of the parameters).
///
/// * Loose at start ([`FrictionWalk::START`]: nothing is known of the ground),
///   tightening with the time the platform has moved (time constant
///   [`FrictionWalk::SETTLE_S`]; standing still teaches nothing of the ground).
/// * Then relative, [`FrictionWalk::RELATIVE`] of the estimate a sample (not
///   below [`FrictionWalk::FLOOR`]): an absolute step right for concrete is
///   too large for ice, whose coefficients are ten times smaller.
/// * Widened while the encoders disagree with the model: by `1 + GAIN · s`,
///   where `s` is the mean square of the encoders' normalised innovation
///   ([`Innovation`]; a wheel spinning beyond any friction counts as
///   [`FrictionWalk::SPINNING`]) smoothed over [`FrictionWalk::SURPRISE_S`]:
///   `s` stays below 1 on a uniform ground and rises when the ground changes,
///   which a purely relative walk followed too slowly. (The measurements
///   behind these choices: docs/measurements.md, "The friction's walk".)
#[derive(Clone, Copy, Debug, Default)]
struct FrictionWalk {
    /// The smoothed mean square innovation `s`.
    surprise: f64,
}

impl FrictionWalk {
    const START: [f64; 3] = [0.3, 0.3, 0.05];
    /// \[s\]
    const SETTLE_S: f64 = 1.0;
    const RELATIVE: f64 = 0.01;
    /// Half a percent of ice's friction, one percent of its rolling
    /// resistance (whose lower bound is 0).
    const FLOOR: [f64; 3] = [5e-4, 5e-4, 1e-4];
    const GAIN: f64 = 2.0;
    /// \[s\]
    const SURPRISE_S: f64 = 0.25;
    /// A reading left out as a spinning wheel counts as a residual of 5 σ
    /// (squared): the ground takes less than the model thought.
    const SPINNING: f64 = 25.0;

    /// Take the newest sample's innovation, `dt` seconds after the previous.
    fn observe(&mut self, dt: f64, innovation: Option<Innovation>) {
        if let Some(i) = innovation.filter(|i| i.mean_square.is_finite() && dt > 0.0) {
            let a = 1.0 - (-dt / Self::SURPRISE_S).exp();
            let (compared, spinning) = (i.readings as f64, i.spinning as f64);
            let square = (i.mean_square * compared + Self::SPINNING * spinning)
                / (compared + spinning).max(1.0);
            self.surprise += a * (square - self.surprise);
        }
    }

    /// The walk for the estimate `p` after `moving` seconds of motion.
    fn sigma(&self, p: [f64; 3], moving: f64) -> [f64; 3] {
        let widen = 1.0 + Self::GAIN * self.surprise;
        let loose = (-moving / Self::SETTLE_S).exp();
        std::array::from_fn(|k| {
            let base = (Self::RELATIVE * p[k].abs()).max(Self::FLOOR[k]);
            let walk = (base * widen).min(Self::START[k]);
            walk + (Self::START[k] - walk) * loose
        })
    }
}

impl Settling {
    const MOVING_S: f64 = 1.0;
    const WINDOW_S: f64 = 1.0;
    const BAND: f64 = 0.1;

    /// One sample at time `now`, after `dt` seconds; forward speed `v`, yaw rate `w`.
    fn update(&mut self, now: f64, dt: f64, v: f64, w: f64, f: &Friction) -> bool {
        if v.abs() > 0.05 || w.abs() > 0.1 {
            self.moving += dt;
        }
        self.recent.push_back((now, [f.mu_long, f.mu_lat]));
        forget_before(&mut self.recent, now - Self::WINDOW_S);
        let n = self.recent.len() as f64;
        let steady = (0..2).all(|k| {
            let mean = self.recent.iter().map(|(_, p)| p[k]).sum::<f64>() / n;
            self.recent
                .iter()
                .all(|(_, p)| (p[k] - mean).abs() <= Self::BAND * mean.abs())
        });
        self.moving >= Self::MOVING_S && steady
    }
}

impl MheEstimator {
    /// Settings for Rex: the lateral-slip model's defaults with noise levels
    /// for what the simulated platform does that the model does not (the load
    /// transfer, the wheels' spin-up) and for its sensors (the encoders' rate
    /// over a short window of ticks), the IMU heading's increments (its
    /// absolute value drifts with the gyroscope's bias), and a random walk of
    /// the friction that lets it follow a change of ground within a second or
    /// two; starting from the ground `prior` (the bounds widened to hold it).
    pub fn settings(prior: Friction, dt: f64) -> MheSettings<6, 3> {
        let d = MheSettings::<6, 3>::default();
        let p = prior.to_array();
        MheSettings {
            dt,
            p_prior: p,
            p_lb: std::array::from_fn(|i| d.p_lb[i].min(p[i])),
            p_ub: std::array::from_fn(|i| d.p_ub[i].max(p[i])),
            sigma_w: [0.003, 0.003, 0.003, 0.03, 0.03, 0.05],
            sigma_encoder: 0.15,
            sigma_heading_step: 0.002,
            sigma_load: 5.0,
            // (Rex's estimator replaces these with [`FrictionWalk`]'s each
            // sample.)
            sigma_p: [0.01, 0.01, 0.002],
            ..d
        }
    }

    /// An estimator for the platform `params`, starting from the ground `prior`
    /// (Rex starts from the slipperiest it expects: its NMPC then uses little
    /// torque until the estimator has seen that the ground takes more, rather
    /// than spinning its wheels on ice it took for concrete). Its encoders
    /// count ticks over `encoder_window` seconds for a rate
    /// ([`Lateral::with_encoder_window`]; finite and not negative).
    pub fn new(
        params: PlatformParams,
        prior: Friction,
        dt: f64,
        encoder_window: f64,
    ) -> Result<MheEstimator, MheError> {
        let settings = Self::settings(prior, dt);
        let model = Lateral::new(params)
            .with_encoder_window(encoder_window)
            .ok_or_else(|| {
                MheError::Settings(format!(
                    "the encoders' window must be finite and not negative, not {encoder_window}"
                ))
            })?;
        let mut mhe = LateralMhe::new(model, settings)?;
        mhe.set_sigma_p(FrictionWalk::START)?;
        Ok(MheEstimator {
            mhe,
            theta: [0.0; 4],
            theta_dot: [0.0; 4],
            settling: Settling::default(),
            walk: FrictionWalk::default(),
        })
    }

    /// The estimator.
    pub fn mhe(&self) -> &LateralMhe {
        &self.mhe
    }
}

impl Estimator for MheEstimator {
    fn name(&self) -> &'static str {
        "mhe"
    }

    fn update(&mut self, dt: f64, tau: &Torques, m: &Measurements) -> Estimate {
        if let Some(e) = m
            .encoders
            .filter(|e| e.theta.iter().chain(&e.rate).all(|v| v.is_finite()))
        {
            self.theta = e.theta;
            self.theta_dot = e.rate;
        }
        let sample = Sample {
            pose: m.map_pose.map(|p| TimedPose {
                time: p.time,
                pose: [p.pose.x, p.pose.y, p.pose.phi],
            }),
            motion: m.transform.filter(Transform::is_finite).map(|t| Motion {
                from: t.from,
                to: t.to,
                delta: t.planar(),
            }),
            gyro: m.imu.map(|i| i.yaw_rate),
            heading: m.imu.filter(|_| m.imu_aligned).map(|i| i.yaw),
            encoders: m.encoders.map(|e| e.rate),
            loads: m.loads.map(|l| l.load),
        };
        let e = self.mhe.update(m.now, tau, &sample);
        let [x, y, phi, vx, vy, w] = e.x;
        self.walk.observe(dt, self.mhe.innovation());
        let sigma_p = self.walk.sigma(e.p, self.settling.moving);
        // Positive and finite: accepted.
        let _ = self.mhe.set_sigma_p(sigma_p);
        let friction = Friction::from_array(e.p);
        let steady = self.settling.update(m.now, dt, vx, w, &friction);
        let settled = e.localised && steady;
        Estimate {
            x: [x, y, phi, vx, w],
            lateral: Some(vy),
            p: SlipParams::NOMINAL,
            friction: Some(friction),
            friction_settled: settled,
            theta: self.theta,
            theta_dot: self.theta_dot,
            localised: e.localised,
            pose_disagreement: self.mhe.pose_residual(DISAGREEMENT_SPAN_S),
        }
    }

    fn health(&self) -> EstimatorHealth {
        let s = self.mhe.stats();
        EstimatorHealth {
            rejected: s.rejected,
            rejected_poses: s.rejected_poses,
            relocalisations: s.relocalisations,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn innovation(mean_square: f64) -> Option<Innovation> {
        Some(Innovation {
            mean: 0.0,
            mean_square,
            readings: 4,
            spinning: 0,
        })
    }

    #[test]
    fn the_walk_is_loose_at_start_then_relative_and_widens_with_surprise() {
        let mut walk = FrictionWalk::default();
        let ice = [0.1, 0.07, 0.01];
        assert_eq!(walk.sigma(ice, 0.0), FrictionWalk::START);
        let steady = walk.sigma(ice, 60.0);
        let expect = [0.001, 0.0007, 0.0001];
        for (s, e) in steady.iter().zip(expect) {
            assert!((s - e).abs() < 1e-12, "{steady:?}");
        }
        // Ten times the ground, ten times the walk; never below the floor.
        let concrete = walk.sigma([1.0, 0.7, 0.1], 60.0);
        for (c, s) in concrete.iter().zip(steady) {
            assert!((c - 10.0 * s).abs() < 1e-12, "{concrete:?}");
        }
        assert_eq!(walk.sigma([0.0, -1e-9, 0.0], 60.0), FrictionWalk::FLOOR);
        // Encoders that keep disagreeing (a mean square of 50) widen it about
        // a hundredfold within a second; the start's bound caps it.
        for _ in 0..20 {
            walk.observe(0.05, innovation(50.0));
        }
        assert!((48.0..50.0).contains(&walk.surprise), "{}", walk.surprise);
        let wide = walk.sigma(ice, 60.0);
        assert!(wide[0] > 0.09 && wide[1] > 0.06, "{wide:?}");
        assert!(wide.iter().zip(FrictionWalk::START).all(|(w, s)| *w <= s));
        // Agreement brings it back; nothing to compare and garbage change nothing.
        for _ in 0..40 {
            walk.observe(0.05, innovation(0.2));
        }
        let calm = walk.surprise;
        assert!((calm - 0.2).abs() < 0.05, "{calm}");
        walk.observe(0.05, None);
        walk.observe(0.05, innovation(f64::NAN));
        walk.observe(f64::NAN, innovation(1e6));
        walk.observe(0.0, innovation(1e6));
        assert_eq!(walk.surprise, calm);
        // Wheels spinning beyond any friction count as surprises of 25, the
        // other readings as they are: here (2 · 25 + 2 · 1) / 4 = 13.
        let spinning = Innovation {
            mean: 0.0,
            mean_square: 1.0,
            readings: 2,
            spinning: 2,
        };
        for _ in 0..100 {
            walk.observe(0.05, Some(spinning));
        }
        assert!((walk.surprise - 13.0).abs() < 1e-3, "{}", walk.surprise);
        let all = Innovation {
            readings: 0,
            spinning: 4,
            ..spinning
        };
        for _ in 0..100 {
            walk.observe(0.05, Some(all));
        }
        assert!((walk.surprise - 25.0).abs() < 1e-3, "{}", walk.surprise);
    }
}
