//! State estimators of the platform (used by `e11`), behind [`Estimator`]: the
//! baseline extended Kalman filter here; the moving-horizon estimator of the paper
//! ([`MheEstimator`], over [`crate::algorithms::mpc`]) slots in the same way.

use std::collections::VecDeque;

use crate::algorithms::mpc::MheError;
use crate::math::geometry::wrap;
use crate::model::{Dynamics, Friction, PlatformParams, Reduced, SlipParams, Torques, Vector};
use crate::payload::{Encoders, Ground, Imu, MapPose, State, Transform, WheelLoads};

mod mhe;
pub use mhe::MheEstimator;

/// What the estimator believes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Estimate {
    /// Pose, forward speed and yaw rate `(X, Y, φ, v, ω)`.
    pub x: [f64; 5],
    /// The lateral velocity `v_y` (body frame, left) when the estimator
    /// estimates it (the MHE on the lateral-slip model); `None`: the reduced
    /// model's, `−x_0 ω`.
    pub lateral: Option<f64>,
    /// The reduced model's slip parameters (the nominal ones unless estimated).
    pub p: SlipParams,
    /// The ground's friction, when the estimator estimates it (the MHE).
    pub friction: Option<Friction>,
    /// Whether that estimate has settled ([`Ground::settled`]).
    pub friction_settled: bool,
    /// Wheel angles (from the encoders).
    pub theta: [f64; 4],
    /// Wheel rates.
    pub theta_dot: [f64; 4],
    /// Whether a pose measurement has been fused (before, the pose is a guess).
    pub localised: bool,
    /// How far the estimate was from the map poses of the last
    /// [`DISAGREEMENT_SPAN_S`] \[m\], the largest distance: the MHE's fit at the
    /// poses' times, the EKF's estimate once corrected by each pose (a pose
    /// gated out: the whole innovation). Beyond the poses' own noise it says
    /// the estimate cannot follow them (a model the data contradict, a new
    /// ground): its error may then be larger than usual. `None` without a
    /// pose in that span.
    pub pose_disagreement: Option<f64>,
}

/// The span of map poses [`Estimate::pose_disagreement`] looks back over \[s\].
pub const DISAGREEMENT_SPAN_S: f64 = 0.5;

/// Drop the entries of a time-ordered queue stamped before `t`.
fn forget_before<T>(queue: &mut VecDeque<(f64, T)>, t: f64) {
    while queue.front().is_some_and(|(at, _)| *at < t) {
        queue.pop_front();
    }
}

impl Estimate {
    /// The lateral velocity: estimated, or the reduced model's `−x_0 ω` with
    /// the ICR offset `x_icr`.
    pub fn lateral_or(&self, x_icr: f64) -> f64 {
        self.lateral.unwrap_or(-x_icr * self.x[4])
    }

    /// As the paper's state estimate `(q~, q~ dot)`; the lateral velocity is
    /// the estimate's, or the reduced model's with the ICR offset `x_icr`.
    pub fn to_state(&self, x_icr: f64) -> State {
        let [x, y, phi, v, w] = self.x;
        let vy = self.lateral_or(x_icr);
        let (s, c) = phi.sin_cos();
        State {
            ground: self.friction.map(|friction| Ground {
                friction,
                settled: self.friction_settled,
            }),
            q: [
                x,
                y,
                phi,
                self.theta[0],
                self.theta[1],
                self.theta[2],
                self.theta[3],
            ],
            q_dot: [
                v * c - vy * s,
                v * s + vy * c,
                w,
                self.theta_dot[0],
                self.theta_dot[1],
                self.theta_dot[2],
                self.theta_dot[3],
            ],
        }
    }
}

/// The measurements of one iteration of `e11` (each `Some` only if new).
#[derive(Clone, Copy, Debug, Default)]
pub struct Measurements {
    /// Wheel encoders.
    pub encoders: Option<Encoders>,
    /// Inertial measurement unit.
    pub imu: Option<Imu>,
    /// Force sensors.
    pub loads: Option<WheelLoads>,
    /// Pose on the map, with the time it describes.
    pub map_pose: Option<MapPose>,
    /// Visual odometry.
    pub transform: Option<Transform>,
    /// Whether the IMU heading has been aligned with the map.
    pub imu_aligned: bool,
    /// Current time \[s\].
    pub now: f64,
}

/// How an estimator has coped with its measurements: what it threw away, and how
/// often it had to start again from the map.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct EstimatorHealth {
    /// Measurements rejected (non-finite, implausible, or failing the gate).
    pub rejected: u64,
    /// Of those, map poses failing the gate: the estimate disagreed with the
    /// trusted sensor.
    pub rejected_poses: u64,
    /// Times the estimate disagreed with the map poses for longer than the
    /// estimator's patience and was restarted from the latest pose.
    pub relocalisations: u64,
}

/// A state estimator.
pub trait Estimator: Send + std::fmt::Debug {
    /// Name for reports.
    fn name(&self) -> &'static str;
    /// Advance by `dt` under the torques applied, `tau`, and fuse the measurements.
    fn update(&mut self, dt: f64, tau: &Torques, m: &Measurements) -> Estimate;
    /// What was rejected so far, and the relocalisations.
    fn health(&self) -> EstimatorHealth;
}

/// Which estimator.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum EstimatorKind {
    /// Extended Kalman filter on the reduced model.
    #[default]
    Ekf,
    /// Moving-horizon estimation of the state and the ground's friction on the
    /// lateral-slip model (the paper's MHE).
    Mhe,
}

impl std::str::FromStr for EstimatorKind {
    type Err = crate::config::UnknownChoice;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "ekf" => Ok(EstimatorKind::Ekf),
            "mhe" => Ok(EstimatorKind::Mhe),
            _ => Err(crate::config::UnknownChoice::new(
                "estimator",
                s,
                "ekf, mhe",
            )),
        }
    }
}

impl EstimatorKind {
    /// An estimator of this kind for the platform `params` (nominal slip `p`; the
    /// ground assumed until it has seen it, `ground`), run every `dt` seconds,
    /// whose encoders count ticks over `encoder_window` seconds for a rate.
    pub fn build(
        self,
        params: PlatformParams,
        p: SlipParams,
        ground: Friction,
        dt: f64,
        encoder_window: f64,
    ) -> Result<Box<dyn Estimator>, MheError> {
        Ok(match self {
            EstimatorKind::Ekf => Box::new(Ekf::new(params, p)),
            EstimatorKind::Mhe => Box::new(MheEstimator::new(params, ground, dt, encoder_window)?),
        })
    }
}

/// Noise settings of the EKF.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EkfNoise {
    /// Process noise densities of `(X, Y, φ, v, ω)` \[unit/√s\].
    pub process: [f64; 5],
    /// Map pose: position \[m\] and heading \[rad\].
    pub map_position: f64,
    /// Map heading \[rad\].
    pub map_heading: f64,
    /// Speed from the encoders \[m/s\].
    pub encoder_speed: f64,
    /// Gyroscope rate \[rad/s\].
    pub gyro: f64,
    /// IMU heading reading \[rad\] (about its offset from the map heading).
    pub imu_heading: f64,
    /// Random walk of the IMU heading's offset from the map heading \[rad/√s\]: the
    /// IMU integrates a biased gyroscope.
    pub imu_offset_walk: f64,
    /// Gate: innovations beyond this many standard deviations are rejected.
    pub gate: f64,
    /// Map poses gated out for this long \[s\] restart the estimate from the latest
    /// one (a relocalisation).
    pub relocalise_after: f64,
}

impl Default for EkfNoise {
    fn default() -> Self {
        EkfNoise {
            process: [0.02, 0.02, 0.05, 0.8, 1.5],
            map_position: 0.01,
            map_heading: 0.02,
            encoder_speed: 0.05,
            gyro: 0.03,
            imu_heading: 0.01,
            imu_offset_walk: 0.02,
            gate: 6.0,
            relocalise_after: 1.0,
        }
    }
}

/// Indices of the EKF's state.
const X: usize = 0;
const Y: usize = 1;
const PHI: usize = 2;
const V: usize = 3;
const W: usize = 4;
/// The IMU heading's offset from the map heading.
const B: usize = 5;

type V6 = nalgebra::SVector<f64, 6>;
type M6 = nalgebra::SMatrix<f64, 6, 6>;

/// An extended Kalman filter on the reduced skid-steer model (notes §1.3) with the
/// applied torques as inputs, and a sixth state: the offset `b` of the IMU heading
/// from the map heading. The IMU integrates a biased gyroscope, so its heading
/// drifts away from the map's (0.4 rad in a minute on Rex's simulated IMU); read
/// as `φ + b`, it keeps what it knows (how the heading changes) without pulling
/// the estimate off the map.
///
/// It fuses the speed from the encoders, the gyroscope rate, the IMU heading, and
/// the map pose, which arrives late: it is compared with the estimate of the time
/// it describes (kept for a second) and the correction applied now. Non-finite
/// measurements and innovations beyond the gate are rejected and counted; map
/// poses gated out for `relocalise_after` seconds mean the estimate is wrong, not
/// the map: the position and heading restart from the latest pose. It does not
/// estimate the slip parameters (the nominal ones are used) and does not use the
/// visual odometry.
#[derive(Debug)]
pub struct Ekf {
    model: Reduced,
    p_nominal: SlipParams,
    x: V6,
    cov: M6,
    noise: EkfNoise,
    history: VecDeque<(f64, V6)>,
    localised: bool,
    /// Whether `b` has been initialised from an IMU heading.
    offset_known: bool,
    /// When the current run of gated-out map poses began.
    rejecting_since: Option<f64>,
    /// How far the corrected estimate was from each map pose of the last
    /// [`DISAGREEMENT_SPAN_S`]: `(arrival time, distance)`.
    disagreements: VecDeque<(f64, f64)>,
    health: EstimatorHealth,
    theta: [f64; 4],
    theta_dot: [f64; 4],
}

impl Ekf {
    /// A filter for the platform `params` with nominal slip `p`, knowing nothing yet.
    pub fn new(params: PlatformParams, p: SlipParams) -> Ekf {
        Ekf::with_noise(params, p, EkfNoise::default())
    }

    /// The same with other noise settings.
    pub fn with_noise(params: PlatformParams, p: SlipParams, noise: EkfNoise) -> Ekf {
        Ekf {
            model: Reduced::new(params),
            p_nominal: p,
            x: V6::zeros(),
            cov: M6::from_diagonal(&V6::new(100.0, 100.0, 10.0, 1.0, 1.0, 10.0)),
            noise,
            history: VecDeque::with_capacity(64),
            localised: false,
            offset_known: false,
            rejecting_since: None,
            disagreements: VecDeque::with_capacity(32),
            health: EstimatorHealth::default(),
            theta: [0.0; 4],
            theta_dot: [0.0; 4],
        }
    }

    /// The state `(X, Y, φ, v, ω, b)`.
    pub fn state(&self) -> [f64; 6] {
        self.x.into()
    }

    /// Measurement update `z = h x + noise(σ)` with the innovation `z − h x` given
    /// (angle-aware where it must be); `false` if gated out.
    fn correct(&mut self, h: &V6, innovation: f64, sigma: f64, gate: bool) -> bool {
        if !innovation.is_finite() {
            self.health.rejected += 1;
            return false;
        }
        let ph = self.cov * h;
        let s = h.dot(&ph) + sigma * sigma;
        if gate && innovation * innovation > self.noise.gate * self.noise.gate * s {
            self.health.rejected += 1;
            return false;
        }
        let k = ph / s;
        self.x += k * innovation;
        // Joseph form: stays symmetric and positive.
        let i_kh = M6::identity() - k * h.transpose();
        self.cov = i_kh * self.cov * i_kh.transpose() + k * k.transpose() * (sigma * sigma);
        true
    }

    fn predict(&mut self, dt: f64, tau: &Torques) {
        let x5 = Vector::<5>::from_fn(|i, _| self.x[i]);
        let j = self.model.rk4_sensitivities(
            &x5,
            &Vector::from(*tau),
            &Vector::from(self.p_nominal.to_array()),
            dt,
            2,
        );
        let next = j.value;
        let mut f = M6::identity();
        f.fixed_view_mut::<5, 5>(0, 0).copy_from(&j.x);
        let n = &self.noise;
        let q = V6::new(
            n.process[0],
            n.process[1],
            n.process[2],
            n.process[3],
            n.process[4],
            n.imu_offset_walk,
        )
        .map(|d| d * d * dt);
        if next.iter().all(|v| v.is_finite()) && f.iter().all(|v| v.is_finite()) {
            for (i, v) in next.iter().enumerate() {
                self.x[i] = *v;
            }
            self.cov = f * self.cov * f.transpose();
        }
        self.cov += M6::from_diagonal(&q);
    }

    /// Position and heading from a map pose: exact for those three, uncorrelated
    /// with the rest; the IMU offset is learned again from the next IMU heading.
    fn adopt(&mut self, pose: [f64; 3]) {
        self.x[X] = pose[0];
        self.x[Y] = pose[1];
        self.x[PHI] = pose[2];
        for i in [X, Y, PHI, B] {
            self.cov.row_mut(i).fill(0.0);
            self.cov.column_mut(i).fill(0.0);
        }
        let n = self.noise;
        self.cov[(X, X)] = n.map_position.powi(2);
        self.cov[(Y, Y)] = n.map_position.powi(2);
        self.cov[(PHI, PHI)] = n.map_heading.powi(2);
        self.cov[(B, B)] = 10.0;
        self.offset_known = false;
        self.history.clear();
        self.disagreements.clear();
        self.rejecting_since = None;
    }

    fn map_pose(&mut self, pose: &MapPose, now: f64) {
        if !(pose.pose.is_finite() && pose.time.is_finite()) {
            self.health.rejected += 1;
            return;
        }
        // The estimate at the time the pose describes (or the oldest kept).
        let past = self
            .history
            .iter()
            .rev()
            .find(|(t, _)| *t <= pose.time + 1e-9)
            .map_or(self.x, |(_, x)| *x);
        let inn = [
            pose.pose.x - past[X],
            pose.pose.y - past[Y],
            wrap(pose.pose.phi - past[PHI]),
        ];
        if !self.localised {
            // The first pose: adopt it.
            self.adopt([pose.pose.x, pose.pose.y, pose.pose.phi]);
            self.localised = true;
            return;
        }
        let n = self.noise;
        let before = [self.x[X], self.x[Y]];
        let mut accepted = 0;
        for (i, sigma) in [
            (X, n.map_position),
            (Y, n.map_position),
            (PHI, n.map_heading),
        ] {
            let before = self.health.rejected;
            if self.correct(&V6::ith(i, 1.0), inn[i], sigma, true) {
                accepted += 1;
            } else if self.health.rejected > before {
                self.health.rejected_poses += 1;
            }
        }
        // The corrected estimate against the pose (the correction applies at
        // the pose's time as now): what the poses could not pull it to.
        let moved = [self.x[X] - before[0], self.x[Y] - before[1]];
        let residual = (inn[0] - moved[0]).hypot(inn[1] - moved[1]);
        self.disagreements.push_back((now, residual));
        if accepted == 3 {
            self.rejecting_since = None;
            return;
        }
        let since = *self.rejecting_since.get_or_insert(now);
        if now - since >= n.relocalise_after {
            // The pose moved to now by the estimate's own motion since its time.
            let moved = [self.x[X] + inn[0], self.x[Y] + inn[1], self.x[PHI] + inn[2]];
            self.adopt(moved);
            self.health.relocalisations += 1;
        }
    }
}

impl Estimator for Ekf {
    fn name(&self) -> &'static str {
        "ekf"
    }

    fn update(&mut self, dt: f64, tau: &Torques, m: &Measurements) -> Estimate {
        self.predict(dt, tau);
        let n = self.noise;
        if let Some(e) = m.encoders {
            if e.rate.iter().chain(&e.theta).all(|v| v.is_finite()) {
                self.theta = e.theta;
                self.theta_dot = e.rate;
                let v = self.model.params.wheel_radius * e.rate.iter().sum::<f64>() / 4.0;
                let inn = v - self.x[V];
                self.correct(&V6::ith(V, 1.0), inn, n.encoder_speed, true);
            } else {
                self.health.rejected += 1;
            }
        }
        if let Some(imu) = m.imu {
            let inn = imu.yaw_rate - self.x[W];
            self.correct(&V6::ith(W, 1.0), inn, n.gyro, true);
            if m.imu_aligned && self.localised && imu.yaw.is_finite() {
                if self.offset_known {
                    let inn = wrap(imu.yaw - self.x[PHI] - self.x[B]);
                    let h = V6::ith(PHI, 1.0) + V6::ith(B, 1.0);
                    self.correct(&h, inn, n.imu_heading, true);
                } else {
                    // The offset is whatever it is now; its uncertainty is the heading's.
                    self.x[B] = wrap(imu.yaw - self.x[PHI]);
                    self.cov.row_mut(B).fill(0.0);
                    self.cov.column_mut(B).fill(0.0);
                    self.cov[(B, B)] = self.cov[(PHI, PHI)] + n.imu_heading.powi(2);
                    self.cov[(B, PHI)] = -self.cov[(PHI, PHI)];
                    self.cov[(PHI, B)] = -self.cov[(PHI, PHI)];
                    self.offset_known = true;
                }
            }
        }
        if let Some(pose) = m.map_pose {
            self.map_pose(&pose, m.now);
        }
        self.history.push_back((m.now, self.x));
        forget_before(&mut self.history, m.now - 1.0);
        forget_before(&mut self.disagreements, m.now - DISAGREEMENT_SPAN_S);
        Estimate {
            x: std::array::from_fn(|i| self.x[i]),
            lateral: None,
            p: self.p_nominal,
            friction: None,
            friction_settled: false,
            theta: self.theta,
            theta_dot: self.theta_dot,
            localised: self.localised,
            pose_disagreement: self.disagreements.iter().map(|(_, d)| *d).reduce(f64::max),
        }
    }

    fn health(&self) -> EstimatorHealth {
        self.health
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::Pose2;

    #[test]
    fn localises_on_the_first_pose_and_rejects_garbage() {
        let mut ekf = Ekf::new(PlatformParams::peer_default(), SlipParams::NOMINAL);
        let at = |x: f64, t: f64| MapPose {
            pose: Pose2 {
                x,
                y: 2.0,
                phi: 0.5,
            },
            time: t,
        };
        let e = ekf.update(
            0.05,
            &[0.0; 4],
            &Measurements {
                map_pose: Some(at(1.0, 0.0)),
                now: 0.05,
                ..Measurements::default()
            },
        );
        assert!(e.localised && (e.x[0] - 1.0).abs() < 1e-9 && (e.x[2] - 0.5).abs() < 1e-9);
        let before = ekf.health().rejected;
        ekf.update(
            0.05,
            &[0.0; 4],
            &Measurements {
                map_pose: Some(at(f64::NAN, 0.05)),
                now: 0.1,
                ..Measurements::default()
            },
        );
        ekf.update(
            0.05,
            &[0.0; 4],
            &Measurements {
                map_pose: Some(at(50.0, 0.1)),
                now: 0.15,
                ..Measurements::default()
            },
        );
        assert_eq!(
            ekf.health().rejected,
            before + 2,
            "NaN and a 49 m jump are rejected"
        );
        assert!((ekf.state()[0] - 1.0).abs() < 0.01);
    }

    #[test]
    fn reports_how_far_the_map_poses_of_the_last_half_second_were() {
        fn step(ekf: &mut Ekf, k: u32, x: Option<f64>) -> Option<f64> {
            let t = f64::from(k) * 0.05;
            let pose = x.map(|x| MapPose {
                pose: Pose2 {
                    x,
                    y: 0.0,
                    phi: 0.0,
                },
                time: t,
            });
            let m = Measurements {
                map_pose: pose,
                now: t,
                ..Measurements::default()
            };
            ekf.update(0.05, &[0.0; 4], &m).pose_disagreement
        }
        let mut ekf = Ekf::new(PlatformParams::peer_default(), SlipParams::NOMINAL);
        assert_eq!(step(&mut ekf, 0, None), None, "no pose yet");
        assert_eq!(step(&mut ekf, 1, Some(1.0)), None, "the first is adopted");
        // 5 cm off: the correction takes the estimate part of the way.
        let d = step(&mut ekf, 2, Some(1.05)).unwrap_or(f64::NAN);
        let x = ekf.state()[X];
        assert!(d > 0.005 && d < 0.045, "{d}");
        assert!((d - (1.05 - x)).abs() < 1e-9, "{d} vs {x}");
        // 2 m off: gated out, the whole of it.
        let d = step(&mut ekf, 3, Some(x + 2.0)).unwrap_or(f64::NAN);
        assert!((d - 2.0).abs() < 0.01, "{d}");
        // Then poses where the estimate is: the 2 m (at 0.15 s) is the
        // largest for half a second, then leaves the span.
        for k in 4..=15 {
            let x = ekf.state()[X];
            let d = step(&mut ekf, k, Some(x));
            // (At 0.65 s exactly, either: the instants are sums of 0.05.)
            if k <= 12 {
                assert!(d.is_some_and(|d| d > 1.9), "{k}: {d:?}");
            } else if k >= 14 {
                assert!(d.is_some_and(|d| d < 0.005), "{k}: {d:?}");
            }
        }
        // Half a second without a pose: nothing to say.
        for k in 16..=26 {
            let d = step(&mut ekf, k, None);
            if k != 25 {
                assert_eq!(d.is_some(), k < 25, "{k}: {d:?}");
            }
        }
    }
}
