//! State estimators for `e11`, behind [`Estimator`]: the baseline extended Kalman
//! filter here; the moving-horizon estimator of the paper slots in the same way.

use std::collections::VecDeque;

use crate::model::{PlatformParams, Reduced, SlipParams, Torques};
use crate::mpc::{Mhe, MheError, MheSettings, Motion, Sample, TimedPose};
use crate::types::{Encoders, Imu, MapPose, State, Transform, WheelLoads};

/// What the estimator believes.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Estimate {
    /// Reduced state `(X, Y, φ, v, ω)`.
    pub x: [f64; 5],
    /// Slip parameters.
    pub p: SlipParams,
    /// Wheel angles (from the encoders).
    pub theta: [f64; 4],
    /// Wheel rates.
    pub theta_dot: [f64; 4],
    /// Whether a pose measurement has been fused (before, the pose is a guess).
    pub localised: bool,
}

impl Estimate {
    /// As the paper's state estimate `(q~, q~ dot)`.
    pub fn to_state(&self, x_icr: f64) -> State {
        let [x, y, phi, v, w] = self.x;
        let (s, c) = phi.sin_cos();
        State {
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
                v * c + x_icr * w * s,
                v * s - x_icr * w * c,
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
    /// Current time [s].
    pub now: f64,
}

/// A state estimator.
pub trait Estimator: Send + std::fmt::Debug {
    /// Name for reports.
    fn name(&self) -> &'static str;
    /// Advance by `dt` under the torques applied, `tau`, and fuse the measurements.
    fn update(&mut self, dt: f64, tau: &Torques, m: &Measurements) -> Estimate;
    /// Measurements rejected so far (non-finite, or failing the gate).
    fn rejected(&self) -> u64;
}

/// Which estimator.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum EstimatorKind {
    /// Extended Kalman filter on the reduced model.
    #[default]
    Ekf,
    /// Moving-horizon estimation of the state and the slip parameters (the paper's).
    Mhe,
}

impl std::str::FromStr for EstimatorKind {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "ekf" => Ok(EstimatorKind::Ekf),
            "mhe" => Ok(EstimatorKind::Mhe),
            _ => Err(format!("unknown estimator `{s}` (ekf, mhe)")),
        }
    }
}

impl EstimatorKind {
    /// An estimator of this kind for the platform `params` (nominal slip `p`), run
    /// every `dt` seconds.
    pub fn build(
        self,
        params: PlatformParams,
        p: SlipParams,
        dt: f64,
    ) -> Result<Box<dyn Estimator>, MheError> {
        Ok(match self {
            EstimatorKind::Ekf => Box::new(Ekf::new(params, p)),
            EstimatorKind::Mhe => Box::new(MheEstimator::new(params, p, dt)?),
        })
    }
}

/// Noise settings of the EKF.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct EkfNoise {
    /// Process noise densities of `(X, Y, φ, v, ω)` [unit/√s].
    pub process: [f64; 5],
    /// Map pose: position [m] and heading [rad].
    pub map_position: f64,
    /// Map heading [rad].
    pub map_heading: f64,
    /// Speed from the encoders [m/s].
    pub encoder_speed: f64,
    /// Gyroscope rate [rad/s].
    pub gyro: f64,
    /// IMU heading after alignment [rad].
    pub imu_heading: f64,
    /// Gate: innovations beyond this many standard deviations are rejected.
    pub gate: f64,
}

impl Default for EkfNoise {
    fn default() -> Self {
        EkfNoise {
            process: [0.02, 0.02, 0.05, 0.8, 1.5],
            map_position: 0.01,
            map_heading: 0.02,
            encoder_speed: 0.05,
            gyro: 0.03,
            imu_heading: 0.08,
            gate: 6.0,
        }
    }
}

/// An extended Kalman filter on the reduced skid-steer model (notes §1.3) with the
/// applied torques as inputs. It fuses the speed from the encoders, the gyroscope
/// rate, the IMU heading once aligned with the map, and the map pose, which arrives
/// late: it is compared with the estimate of the time it describes (kept for a
/// second) and the correction applied now. Non-finite measurements and innovations
/// beyond the gate are rejected and counted. It does not estimate the slip
/// parameters (the nominal ones are used) and does not use the visual odometry.
#[derive(Debug)]
pub struct Ekf {
    model: Reduced,
    p_nominal: SlipParams,
    x: [f64; 5],
    cov: [[f64; 5]; 5],
    noise: EkfNoise,
    history: VecDeque<(f64, [f64; 5])>,
    localised: bool,
    rejected: u64,
    theta: [f64; 4],
    theta_dot: [f64; 4],
}

impl Ekf {
    /// A filter for the platform `params` with nominal slip `p`, knowing nothing yet.
    pub fn new(params: PlatformParams, p: SlipParams) -> Ekf {
        let mut cov = [[0.0; 5]; 5];
        for (i, s) in [100.0, 100.0, 10.0, 1.0, 1.0].into_iter().enumerate() {
            cov[i][i] = s;
        }
        Ekf {
            model: Reduced::new(params),
            p_nominal: p,
            x: [0.0; 5],
            cov,
            noise: EkfNoise::default(),
            history: VecDeque::with_capacity(64),
            localised: false,
            rejected: 0,
            theta: [0.0; 4],
            theta_dot: [0.0; 4],
        }
    }

    /// Scalar measurement update `z = x[i] + noise(σ)`, angle-aware for the heading.
    /// Returns false if gated out.
    fn update_scalar(&mut self, i: usize, innovation: f64, sigma: f64, gate: bool) -> bool {
        if !innovation.is_finite() {
            self.rejected += 1;
            return false;
        }
        let s = self.cov[i][i] + sigma * sigma;
        if gate && innovation * innovation > self.noise.gate * self.noise.gate * s {
            self.rejected += 1;
            return false;
        }
        let k: [f64; 5] = std::array::from_fn(|r| self.cov[r][i] / s);
        for r in 0..5 {
            self.x[r] += k[r] * innovation;
        }
        let row = self.cov[i];
        for r in 0..5 {
            for c in 0..5 {
                self.cov[r][c] -= k[r] * row[c];
            }
        }
        true
    }

    fn predict(&mut self, dt: f64, tau: &Torques) {
        let f = |x: &[f64; 5]| self.model.rk4(x, tau, &self.p_nominal, dt, 2);
        let x1 = f(&self.x);
        // Jacobian by central differences (5 states).
        let mut a = [[0.0; 5]; 5];
        for j in 0..5 {
            let h = 1e-6 * (1.0 + self.x[j].abs());
            let (mut xp, mut xm) = (self.x, self.x);
            xp[j] += h;
            xm[j] -= h;
            let (fp, fm) = (f(&xp), f(&xm));
            for i in 0..5 {
                a[i][j] = (fp[i] - fm[i]) / (2.0 * h);
            }
        }
        let mut ap = [[0.0; 5]; 5];
        for i in 0..5 {
            for j in 0..5 {
                ap[i][j] = (0..5).map(|k| a[i][k] * self.cov[k][j]).sum();
            }
        }
        for i in 0..5 {
            for j in 0..5 {
                self.cov[i][j] = (0..5).map(|k| ap[i][k] * a[j][k]).sum();
            }
            self.cov[i][i] += self.noise.process[i].powi(2) * dt;
        }
        if x1.iter().all(|v| v.is_finite()) {
            self.x = x1;
        }
    }
}

fn wrap(a: f64) -> f64 {
    let w = (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    if w <= -std::f64::consts::PI {
        w + std::f64::consts::TAU
    } else {
        w
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
                let inn = v - self.x[3];
                self.update_scalar(3, inn, n.encoder_speed, true);
            } else {
                self.rejected += 1;
            }
        }
        if let Some(imu) = m.imu {
            let inn = imu.yaw_rate - self.x[4];
            self.update_scalar(4, inn, n.gyro, true);
            if m.imu_aligned && self.localised {
                let inn = wrap(imu.yaw - self.x[2]);
                self.update_scalar(2, inn, n.imu_heading, true);
            }
        }
        if let Some(pose) = m.map_pose {
            if pose.pose.is_finite() && pose.time.is_finite() {
                // The estimate at the time the pose describes (or the oldest kept).
                let past = self
                    .history
                    .iter()
                    .rev()
                    .find(|(t, _)| *t <= pose.time + 1e-9)
                    .map_or(self.x, |(_, x)| *x);
                let inn = [
                    pose.pose.x - past[0],
                    pose.pose.y - past[1],
                    wrap(pose.pose.phi - past[2]),
                ];
                if !self.localised {
                    // The first pose: adopt it.
                    self.x[0] = pose.pose.x;
                    self.x[1] = pose.pose.y;
                    self.x[2] = pose.pose.phi;
                    for i in 0..3 {
                        for j in 0..5 {
                            self.cov[i][j] = 0.0;
                            self.cov[j][i] = 0.0;
                        }
                    }
                    self.cov[0][0] = n.map_position.powi(2);
                    self.cov[1][1] = n.map_position.powi(2);
                    self.cov[2][2] = n.map_heading.powi(2);
                    self.localised = true;
                    self.history.clear();
                } else {
                    self.update_scalar(0, inn[0], n.map_position, true);
                    self.update_scalar(1, inn[1], n.map_position, true);
                    self.update_scalar(2, inn[2], n.map_heading, true);
                }
            } else {
                self.rejected += 1;
            }
        }
        self.history.push_back((m.now, self.x));
        while self.history.len() > 1 && self.history.front().is_some_and(|(t, _)| *t < m.now - 1.0)
        {
            self.history.pop_front();
        }
        Estimate {
            x: self.x,
            p: self.p_nominal,
            theta: self.theta,
            theta_dot: self.theta_dot,
            localised: self.localised,
        }
    }

    fn rejected(&self) -> u64 {
        self.rejected
    }
}

/// The MHE of [`crate::mpc::mhe`] as e1,1's estimator. Every iteration of e1,1 is a
/// sample: the encoder rates, the gyroscope rate, the IMU heading once it is
/// aligned with the map, the wheel loads, the map pose when one arrives (attached to
/// the time it describes: the map agent's poses are late), and the visual
/// odometry's motion between two pairs (`A4x4`, relayed by c1). It
/// estimates the slip parameters `(x_0, μ_s, μ_l)` with the state; the NMPC uses
/// them.
#[derive(Debug)]
pub struct MheEstimator {
    mhe: Mhe,
    theta: [f64; 4],
    theta_dot: [f64; 4],
}

impl MheEstimator {
    /// Settings for Rex: the peer's weights, with noise levels for what the
    /// simulated platform does that the reduced model does not (longitudinal wheel
    /// slip shows in the encoder rates; the gyroscope drifts, so its integrated
    /// heading is weak), and a slower random walk of the parameters (the peer's
    /// arrival cost lets them move 0.05 per sample, which suits a 10 s lap but
    /// makes the NMPC's model jitter over a long mission).
    pub fn settings(p: SlipParams, dt: f64) -> MheSettings {
        MheSettings {
            dt,
            p_prior: p.to_array(),
            sigma_w: [0.003, 0.003, 0.003, 0.03, 0.05],
            sigma_encoder: 0.3,
            sigma_heading: 0.05,
            sigma_load: 5.0,
            sigma_p: [0.002, 0.002, 0.01],
            ..MheSettings::default()
        }
    }

    /// An estimator for the platform `params`, starting from the slip `p`.
    pub fn new(params: PlatformParams, p: SlipParams, dt: f64) -> Result<MheEstimator, MheError> {
        Ok(MheEstimator {
            mhe: Mhe::new(Reduced::new(params), Self::settings(p, dt))?,
            theta: [0.0; 4],
            theta_dot: [0.0; 4],
        })
    }

    /// The estimator.
    pub fn mhe(&self) -> &Mhe {
        &self.mhe
    }
}

impl Estimator for MheEstimator {
    fn name(&self) -> &'static str {
        "mhe"
    }

    fn update(&mut self, _dt: f64, tau: &Torques, m: &Measurements) -> Estimate {
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
        Estimate {
            x: e.x,
            p: e.p,
            theta: self.theta,
            theta_dot: self.theta_dot,
            localised: e.localised,
        }
    }

    fn rejected(&self) -> u64 {
        self.mhe.stats().rejected
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::Pose2;

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
        let before = ekf.rejected();
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
            ekf.rejected(),
            before + 2,
            "NaN and a 49 m jump are rejected"
        );
        assert!((ekf.x[0] - 1.0).abs() < 0.01);
    }
}
