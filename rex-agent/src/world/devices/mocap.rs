//! The motion-capture system R3, a real receptor of the map agent a3: the true pose
//! with noise, latency and dropouts.

use std::collections::VecDeque;

use embodied::{Buffers, DeviceKind, Driver, DriverContext, DriverError, Group, Out};
use serde::{Deserialize, Serialize};

use crate::config::{self, ConfigError, Invalid, Validate, non_negative};
use crate::math::geometry::wrap;
use crate::math::rng::Rng;
use crate::payload::{MapPose, Pose2};

/// Characteristics of the motion-capture system.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MocapParams {
    /// Position noise \[m\].
    pub position_noise: f64,
    /// Heading noise \[rad\].
    pub heading_noise: f64,
    /// How old a pose is when it is delivered \[s\].
    pub latency: f64,
    /// Probability per sample that a dropout starts.
    pub dropout_rate: f64,
    /// Length of a dropout \[s\].
    pub dropout_length: f64,
    /// Noise seed.
    pub seed: u64,
}

impl Default for MocapParams {
    fn default() -> Self {
        MocapParams {
            position_noise: 0.005,
            heading_noise: 0.005,
            latency: 0.04,
            dropout_rate: 0.002,
            dropout_length: 0.5,
            seed: 3,
        }
    }
}

impl Validate for MocapParams {
    fn validate(&self) -> Result<(), Invalid> {
        non_negative("position_noise", self.position_noise)?;
        non_negative("heading_noise", self.heading_noise)?;
        non_negative("latency", self.latency)?;
        if !(0.0..=1.0).contains(&self.dropout_rate) {
            return Err((
                "dropout_rate".into(),
                self.dropout_rate.to_string(),
                "must be a probability in [0, 1]",
            ));
        }
        non_negative("dropout_length", self.dropout_length)
    }
}

/// Poses for the map agent's virtual receptor `r31`.
#[derive(Debug, Default, Group)]
#[group(peer = VirtualReceptor)]
pub struct MocapToR31 {
    /// The measured pose and the time it describes.
    pub pose: Out<MapPose>,
}

/// The motion capture's outputs.
#[derive(Debug, Default, Buffers)]
pub struct MocapOutput {
    /// To `r31`.
    pub r31: MocapToR31,
}

/// The simulated motion-capture system R3: noisy poses, delivered `latency` late,
/// with dropouts during which it sends nothing.
#[derive(Debug)]
pub struct MotionCapture {
    params: MocapParams,
    rng: Rng,
    history: VecDeque<(f64, Pose2)>,
    silent_until: f64,
    delivered: u64,
    dropped: u64,
    last: Option<(f64, MapPose)>,
    /// The robot of a fleet it observes ([`super::FleetTruth`]); `None`: the single Rex.
    robot: Option<usize>,
}

impl MotionCapture {
    /// A motion-capture system (`params` validated) observing the system's
    /// environment, [`Truth`](super::Truth).
    pub fn new(params: MocapParams) -> Result<MotionCapture, ConfigError> {
        config::check("mocap", &params)?;
        Ok(MotionCapture {
            rng: Rng::stream(params.seed, "mocap"),
            params,
            history: VecDeque::with_capacity(256),
            silent_until: f64::NEG_INFINITY,
            delivered: 0,
            dropped: 0,
            last: None,
            robot: None,
        })
    }

    /// The motion capture of robot `robot` of a fleet: it observes the robot's
    /// entry of the fleet's [`super::FleetTruth`].
    pub fn in_fleet(mut self, robot: usize) -> MotionCapture {
        self.robot = Some(robot);
        self
    }

    /// Poses delivered and samples lost to dropouts.
    pub fn counts(&self) -> (u64, u64) {
        (self.delivered, self.dropped)
    }

    /// The last pose delivered, with the time it was sent \[s\].
    pub fn last_delivered(&self) -> Option<(f64, MapPose)> {
        self.last
    }
}

impl Driver for MotionCapture {
    const KIND: DeviceKind = DeviceKind::Receptor;
    type Input = ();
    type Output = MocapOutput;

    fn step(
        &mut self,
        mut cx: DriverContext<'_>,
        _: &(),
        y: &mut MocapOutput,
    ) -> Result<(), DriverError> {
        let truth = *super::truth(&mut cx, self.robot)?;
        let now = cx.now.as_secs_f64();
        let s = truth.state;
        self.history.push_back((
            truth.time,
            Pose2 {
                x: s.x,
                y: s.y,
                phi: s.phi,
            },
        ));
        // The newest sample at least `latency` old is the one delivered now; older
        // ones are no longer needed.
        let due = now - self.params.latency;
        while self.history.len() > 1 && self.history[1].0 <= due + 1e-12 {
            self.history.pop_front();
        }
        let Some(&(time, pose)) = self.history.front().filter(|(t, _)| *t <= due + 1e-12) else {
            return Ok(());
        };
        if now < self.silent_until {
            self.dropped += 1;
            return Ok(());
        }
        if self.rng.uniform() < self.params.dropout_rate {
            self.silent_until = now + self.params.dropout_length;
            self.dropped += 1;
            return Ok(());
        }
        let p = &self.params;
        let noisy = Pose2 {
            x: pose.x + self.rng.gauss(p.position_noise),
            y: pose.y + self.rng.gauss(p.position_noise),
            phi: wrap(pose.phi + self.rng.gauss(p.heading_noise)),
        };
        let sent = MapPose { pose: noisy, time };
        y.r31.pose.set(sent);
        self.last = Some((now, sent));
        self.delivered += 1;
        Ok(())
    }
}
