//! The real effectors and receptors of the simulated world, as framework drivers:
//! the platform E1 (wheels, encoders, IMU, force sensors), the stereo camera R1 and
//! the motion-capture system R3 of the map agent.
//!
//! The three devices share the simulated ground truth ([`SharedTruth`]): the platform
//! writes it every step, the camera and the motion capture read it. Within an instant
//! the executor steps the platform first (it is added first), so both see the pose
//! of that instant.

use std::collections::VecDeque;
use std::sync::{Arc, Mutex};

use embodied::{
    Buffers, DeviceKind, Driver, DriverContext, DriverError, Group, In, Out, PortTable, Shape,
};
use serde::{Deserialize, Serialize};

use crate::a1::payload::{
    AcquireCommand, Encoders, Imu, ImuCommand, MapPose, Pose2, StereoPair, Torques, WheelLoads,
};
use crate::algorithms::geometry::wrap;
use crate::algorithms::rng::Rng;
use crate::config::{self, ConfigError, Invalid, Validate, non_negative, positive};
use crate::world::camera::Renderer;
use crate::world::camera::kitti::SequenceWriter;
use crate::world::model::{CommandStats, FullState, Plant};

/// What the simulation knows and the agents must estimate.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Truth {
    /// Simulation time [s].
    pub time: f64,
    /// The platform's full state.
    pub state: FullState,
}

/// The ground truth shared by the devices of the simulated world.
#[derive(Clone, Debug, Default)]
pub struct SharedTruth(Arc<Mutex<Truth>>);

impl SharedTruth {
    /// The current truth.
    pub fn get(&self) -> Result<Truth, DriverError> {
        self.0.lock().map(|t| *t).map_err(|_| {
            DriverError::new("the shared ground truth is poisoned (a device panicked)")
        })
    }

    fn set(&self, truth: Truth) -> Result<(), DriverError> {
        let mut t = self.0.lock().map_err(|_| {
            DriverError::new("the shared ground truth is poisoned (a device panicked)")
        })?;
        *t = truth;
        Ok(())
    }
}

// ---------------------------------------------------------------------------
// E1: the platform

/// Sensor characteristics of the platform.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorParams {
    /// Encoder counts per wheel revolution.
    pub encoder_ticks: u32,
    /// Samples over which the wheel rate is computed from the counts.
    pub speed_window: u32,
    /// Gyroscope white noise [rad/s].
    pub gyro_noise: f64,
    /// Gyroscope bias at start [rad/s].
    pub gyro_bias: f64,
    /// Random walk of the gyroscope bias [rad/s per √s].
    pub gyro_bias_walk: f64,
    /// Accelerometer noise [m/s²].
    pub accel_noise: f64,
    /// Force sensor noise [N].
    pub load_noise: f64,
    /// A torque command older than this is replaced by zero torque [s] (the motor
    /// controllers' watchdog).
    pub command_timeout: f64,
    /// Seed of all sensor noise.
    pub seed: u64,
}

impl Default for SensorParams {
    fn default() -> Self {
        SensorParams {
            encoder_ticks: 4096,
            speed_window: 10,
            gyro_noise: 0.01,
            gyro_bias: 0.003,
            gyro_bias_walk: 0.0005,
            accel_noise: 0.05,
            load_noise: 1.0,
            command_timeout: 0.25,
            seed: 1,
        }
    }
}

impl Validate for SensorParams {
    fn validate(&self) -> Result<(), Invalid> {
        if self.encoder_ticks == 0 {
            return Err(("encoder_ticks".into(), "0".into(), "must be at least 1"));
        }
        if !(1..=64).contains(&self.speed_window) {
            return Err((
                "speed_window".into(),
                self.speed_window.to_string(),
                "must be between 1 and 64 samples",
            ));
        }
        non_negative("gyro_noise", self.gyro_noise)?;
        non_negative("gyro_bias", self.gyro_bias.abs())?;
        non_negative("gyro_bias_walk", self.gyro_bias_walk)?;
        non_negative("accel_noise", self.accel_noise)?;
        non_negative("load_noise", self.load_noise)?;
        positive("command_timeout", self.command_timeout)
    }
}

/// Commands from the virtual effector `e11` to the platform.
#[derive(Debug, Default, Group)]
#[group(peer = VirtualEffector)]
#[expect(non_snake_case, reason = "the paper's buffer names")]
pub struct PlatformFromE11 {
    /// Wheel torques (`τ`).
    pub tau: In<Torques>,
    /// IMU reset (`cmd_E1,1`).
    pub cmd_E11: In<ImuCommand>,
}

/// The platform's inputs.
#[derive(Debug, Default, Buffers)]
pub struct PlatformInput {
    /// From `e11`.
    pub e11: PlatformFromE11,
}

/// Readings for `e11`.
#[derive(Debug, Default, Group)]
#[group(peer = VirtualEffector)]
pub struct PlatformToE11 {
    /// Inertial measurement unit.
    pub imu: Out<Imu>,
    /// Force sensors.
    pub forces: Out<WheelLoads>,
    /// Wheel encoders.
    pub encoders: Out<Encoders>,
}

/// The platform's outputs.
#[derive(Debug, Default, Buffers)]
pub struct PlatformOutput {
    /// To `e11`.
    pub e11: PlatformToE11,
}

/// The simulated platform E1: the full model and its sensors.
#[derive(Debug)]
pub struct Platform {
    plant: Plant,
    params: SensorParams,
    truth: SharedTruth,
    rng: Rng,
    counts: [[i64; 4]; 64],
    samples: u64,
    bias: f64,
    yaw: f64,
    last_command: Option<(Torques, f64)>,
    timeouts: u64,
    resets: u64,
    rejected_resets: u64,
}

impl Platform {
    /// The platform `plant` with sensors `params` (validated), publishing to `truth`.
    pub fn new(
        plant: Plant,
        params: SensorParams,
        truth: SharedTruth,
    ) -> Result<Platform, ConfigError> {
        config::check("sensors", &params)?;
        let rng = Rng::stream(params.seed, "platform");
        Ok(Platform {
            yaw: plant.state.phi,
            bias: params.gyro_bias,
            plant,
            params,
            truth,
            rng,
            counts: [[0; 4]; 64],
            samples: 0,
            last_command: None,
            timeouts: 0,
            resets: 0,
            rejected_resets: 0,
        })
    }

    /// The plant (ground truth).
    pub fn plant(&self) -> &Plant {
        &self.plant
    }

    /// The plant, to disturb it: a push, a collision, a kidnapping (what the
    /// platform's model does not know happens to robots; tests of the safety
    /// monitor use it). The sensors and the shared truth follow at the next step.
    pub fn plant_mut(&mut self) -> &mut Plant {
        &mut self.plant
    }

    /// Torque commands that were NaN or out of bounds so far: each command from
    /// `e11` is checked and counted once, when it arrives (see [`Plant::clean`]).
    pub fn command_stats(&self) -> CommandStats {
        self.plant.command_stats()
    }

    /// The torque command in force: the last one received, cleaned (NaN torques
    /// zeroed, the others clamped to `±torque_max`), and when it arrived [s].
    pub fn command(&self) -> Option<(Torques, f64)> {
        self.last_command
    }

    /// Steps run with zero torque because the last command was too old.
    pub fn timeouts(&self) -> u64 {
        self.timeouts
    }

    /// IMU resets obeyed.
    pub fn resets(&self) -> u64 {
        self.resets
    }

    /// IMU resets ignored because their heading was NaN or infinite.
    pub fn rejected_resets(&self) -> u64 {
        self.rejected_resets
    }

    /// Advance the plant by `dt` with `command` (as the motors deliver it at the
    /// current wheel speeds, [`Plant::available`]; the command is not counted here:
    /// the driver cleans and counts each command once when it arrives) and sample
    /// the sensors.
    pub fn advance(&mut self, command: Torques, dt: f64) -> (Imu, WheelLoads, Encoders) {
        let tau = self.plant.available(command);
        self.plant.step(tau, dt);
        let s = self.plant.state;
        let p = &self.params;
        // Encoders: quantised angles; rates from the counts over the speed window.
        let q = std::f64::consts::TAU / f64::from(p.encoder_ticks);
        let now_counts = s.theta.map(|t| (t / q).floor() as i64);
        let window = p.speed_window as u64;
        let slot = (self.samples % 64) as usize;
        self.counts[slot] = now_counts;
        self.samples += 1;
        let span = window.min(self.samples - 1);
        let old = self.counts[((self.samples - 1 - span) % 64) as usize];
        let rate = if span == 0 {
            [0.0; 4]
        } else {
            [0, 1, 2, 3].map(|i| (now_counts[i] - old[i]) as f64 * q / (span as f64 * dt))
        };
        let encoders = Encoders {
            theta: now_counts.map(|c| c as f64 * q),
            rate,
        };
        // IMU: biased, noisy gyroscope integrated into a drifting heading.
        self.bias += self.rng.gauss(p.gyro_bias_walk * dt.sqrt());
        let gyro = s.omega + self.bias + self.rng.gauss(p.gyro_noise);
        self.yaw += gyro * dt;
        let accel = self.plant.accel();
        let imu = Imu {
            yaw: wrap(self.yaw),
            yaw_rate: gyro,
            accel: [
                accel[0] + self.rng.gauss(p.accel_noise),
                accel[1] + self.rng.gauss(p.accel_noise),
            ],
        };
        let loads = self.plant.loads();
        let forces = WheelLoads {
            load: [0, 1, 2, 3].map(|i| loads[i] + self.rng.gauss(p.load_noise)),
        };
        (imu, forces, encoders)
    }
}

impl Driver for Platform {
    const KIND: DeviceKind = DeviceKind::Effector;
    type Input = PlatformInput;
    type Output = PlatformOutput;

    fn shape() -> Option<Shape> {
        Some(Shape::of_driver::<Self>())
    }

    fn ports() -> Option<PortTable> {
        Some(PortTable::of::<Self::Input, Self::Output>())
    }

    fn step(
        &mut self,
        cx: DriverContext,
        x: &PlatformInput,
        y: &mut PlatformOutput,
    ) -> Result<(), DriverError> {
        let dt = cx.period.as_secs_f64();
        let now = cx.now.as_secs_f64();
        // A new command is checked (and a bad one counted) once, when it arrives;
        // the cleaned command stays in force until the next one or the timeout.
        if let Some(&tau) = x.e11.tau.fresh() {
            self.last_command = Some((self.plant.clean(tau), now));
        }
        if let Some(ImuCommand::Reset { yaw }) = x.e11.cmd_E11.fresh().copied() {
            if yaw.is_finite() {
                self.yaw = yaw;
                self.resets += 1;
            } else {
                self.rejected_resets += 1;
            }
        }
        let command = match self.last_command {
            Some((tau, at)) if now - at <= self.params.command_timeout => tau,
            Some(_) => {
                self.timeouts += 1;
                [0.0; 4]
            }
            None => [0.0; 4],
        };
        let (imu, forces, encoders) = self.advance(command, dt);
        self.truth.set(Truth {
            time: now + dt,
            state: self.plant.state,
        })?;
        y.e11.imu.set(imu);
        y.e11.forces.set(forces);
        y.e11.encoders.set(encoders);
        Ok(())
    }
}

// ---------------------------------------------------------------------------
// R1: the stereo camera

/// The acquisition command from `r11`.
#[derive(Debug, Default, Group)]
#[group(peer = VirtualReceptor)]
#[expect(non_snake_case, reason = "the paper's buffer names")]
pub struct CameraFromR11 {
    /// `cmd_R1,1`.
    pub cmd_R11: In<AcquireCommand>,
}

/// The camera's inputs.
#[derive(Debug, Default, Buffers)]
pub struct CameraInput {
    /// From `r11`.
    pub r11: CameraFromR11,
}

/// Images for `r11`.
#[derive(Debug, Default, Group)]
#[group(peer = VirtualReceptor)]
pub struct CameraToR11 {
    /// The stereo pair (`img_lr`).
    pub img_lr: Out<StereoPair>,
}

/// The camera's outputs.
#[derive(Debug, Default, Buffers)]
pub struct CameraOutput {
    /// To `r11`.
    pub r11: CameraToR11,
}

/// The simulated stereo camera R1: on an acquisition command it renders a pair at
/// the platform's pose of that instant, and delivers it at its next step (never in
/// the same step, as the paper says). Without a command it sends nothing.
pub struct StereoCamera {
    renderer: Renderer,
    truth: SharedTruth,
    pending: StereoPair,
    has_pending: bool,
    frames: u64,
    recorder: Option<SequenceWriter>,
}

impl std::fmt::Debug for StereoCamera {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("StereoCamera")
            .field("frames", &self.frames)
            .field("recording", &self.recorder.is_some())
            .finish()
    }
}

impl StereoCamera {
    /// A camera rendering with `renderer`, looking from the pose in `truth`.
    pub fn new(renderer: Renderer, truth: SharedTruth) -> StereoCamera {
        StereoCamera {
            renderer,
            truth,
            pending: StereoPair::default(),
            has_pending: false,
            frames: 0,
            recorder: None,
        }
    }

    /// Also write every rendered pair, with its true pose, to a KITTI sequence.
    pub fn record_to(&mut self, writer: SequenceWriter) {
        self.recorder = Some(writer);
    }

    /// Stop recording; returns the writer (call `finish` on it).
    pub fn take_recorder(&mut self) -> Option<SequenceWriter> {
        self.recorder.take()
    }

    /// The renderer (camera parameters and scene).
    pub fn renderer(&self) -> &Renderer {
        &self.renderer
    }

    /// Pairs rendered so far.
    pub fn frames(&self) -> u64 {
        self.frames
    }
}

impl Driver for StereoCamera {
    const KIND: DeviceKind = DeviceKind::Receptor;
    type Input = CameraInput;
    type Output = CameraOutput;

    fn shape() -> Option<Shape> {
        Some(Shape::of_driver::<Self>())
    }

    fn ports() -> Option<PortTable> {
        Some(PortTable::of::<Self::Input, Self::Output>())
    }

    fn step(
        &mut self,
        _: DriverContext,
        x: &CameraInput,
        y: &mut CameraOutput,
    ) -> Result<(), DriverError> {
        if self.has_pending {
            // Hand over the pair; its storage comes back recycled through the link.
            std::mem::swap(y.r11.img_lr.write_recycled(), &mut self.pending);
            self.has_pending = false;
        }
        if let Some(cmd) = x.r11.cmd_R11.fresh() {
            let truth = self.truth.get()?;
            let s = truth.state;
            let pair = &mut self.pending;
            let body = [s.x, s.y, s.phi];
            self.renderer
                .render_pair(body, &mut pair.left, &mut pair.right);
            if let Some(w) = &mut self.recorder {
                let pose = self.renderer.camera().left_pose(body);
                w.push(truth.time, &pose, &pair.left, &pair.right)
                    .map_err(|e| DriverError::new(format!("recording the KITTI sequence: {e}")))?;
            }
            pair.seq = cmd.seq;
            pair.time = truth.time;
            pair.width = self.renderer.camera().width;
            pair.height = self.renderer.camera().height;
            self.has_pending = true;
            self.frames += 1;
        }
        Ok(())
    }
}

// ---------------------------------------------------------------------------
// R3: motion capture (a device of the map agent a3)

/// Characteristics of the motion-capture system.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MocapParams {
    /// Position noise [m].
    pub position_noise: f64,
    /// Heading noise [rad].
    pub heading_noise: f64,
    /// How old a pose is when it is delivered [s].
    pub latency: f64,
    /// Probability per sample that a dropout starts.
    pub dropout_rate: f64,
    /// Length of a dropout [s].
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
    truth: SharedTruth,
    rng: Rng,
    history: VecDeque<(f64, Pose2)>,
    silent_until: f64,
    delivered: u64,
    dropped: u64,
    last: Option<(f64, MapPose)>,
}

impl MotionCapture {
    /// A motion-capture system (`params` validated) observing `truth`.
    pub fn new(params: MocapParams, truth: SharedTruth) -> Result<MotionCapture, ConfigError> {
        config::check("mocap", &params)?;
        Ok(MotionCapture {
            rng: Rng::stream(params.seed, "mocap"),
            params,
            truth,
            history: VecDeque::with_capacity(256),
            silent_until: f64::NEG_INFINITY,
            delivered: 0,
            dropped: 0,
            last: None,
        })
    }

    /// Poses delivered and samples lost to dropouts.
    pub fn counts(&self) -> (u64, u64) {
        (self.delivered, self.dropped)
    }

    /// The last pose delivered, with the time it was sent [s].
    pub fn last_delivered(&self) -> Option<(f64, MapPose)> {
        self.last
    }
}

impl Driver for MotionCapture {
    const KIND: DeviceKind = DeviceKind::Receptor;
    type Input = ();
    type Output = MocapOutput;

    fn shape() -> Option<Shape> {
        Some(Shape::of_driver::<Self>())
    }

    fn ports() -> Option<PortTable> {
        Some(PortTable::of::<Self::Input, Self::Output>())
    }

    fn step(&mut self, cx: DriverContext, _: &(), y: &mut MocapOutput) -> Result<(), DriverError> {
        let truth = self.truth.get()?;
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::world::model::{PlatformParams, SurfaceMap};
    use embodied::{Period, Stamp, Time};

    fn platform(params: SensorParams) -> Platform {
        let plant = Plant::new(
            PlatformParams::peer_default(),
            SurfaceMap::concrete(),
            [0.0; 3],
        )
        .unwrap();
        Platform::new(plant, params, SharedTruth::default()).unwrap()
    }

    /// Step `driver` at 1 kHz from `*k`, with `tau` and `cmd` delivered as new in
    /// the first of `steps` steps (and aged in the others); returns the last IMU
    /// reading.
    fn drive(
        p: &mut Platform,
        k: &mut u64,
        tau: Option<Torques>,
        cmd: Option<ImuCommand>,
        steps: u64,
    ) -> Imu {
        let mut x = PlatformInput::default();
        let mut y = PlatformOutput::default();
        for n in 0..steps {
            let stamp = Stamp::new(*k, Time::from_nanos(*k * 1_000_000));
            match tau {
                Some(t) if n == 0 => x.e11.tau.deliver(t, stamp),
                _ => x.e11.tau.age(),
            }
            match cmd {
                Some(c) if n == 0 => x.e11.cmd_E11.deliver(c, stamp),
                _ => x.e11.cmd_E11.age(),
            }
            let cx = DriverContext {
                now: Time::from_nanos(*k * 1_000_000),
                iteration: *k,
                period: Period::from_millis(1).unwrap(),
            };
            p.step(cx, &x, &mut y).unwrap();
            *k += 1;
        }
        *y.e11.imu.written().unwrap()
    }

    #[test]
    fn a_bad_command_is_cleaned_and_counted_once_however_long_it_stays_in_force() {
        let mut p = platform(SensorParams::default());
        let mut k = 0;
        // A good command, then one NaN command held for 50 plant steps (e11's period).
        drive(&mut p, &mut k, Some([1.0; 4]), None, 50);
        assert_eq!(p.command_stats(), CommandStats::default());
        drive(&mut p, &mut k, Some([f64::NAN, 1.0, 1.0, 1.0]), None, 50);
        assert_eq!(
            p.command_stats(),
            CommandStats {
                not_finite: 1,
                out_of_bounds: 0
            }
        );
        assert_eq!(p.command().unwrap().0, [0.0, 1.0, 1.0, 1.0], "NaN -> 0");
        assert!(p.plant().state.theta_dot.iter().all(|w| w.is_finite()));
        // One out-of-bounds command: counted once, and clamped.
        drive(&mut p, &mut k, Some([25.0, -30.0, 2.0, 10.0]), None, 50);
        assert_eq!(
            p.command_stats(),
            CommandStats {
                not_finite: 1,
                out_of_bounds: 1
            }
        );
        assert_eq!(p.command().unwrap().0, [10.0, -10.0, 2.0, 10.0]);
        assert_eq!(p.command().unwrap().1, 0.1, "arrived at 100 ms");
        // Good commands afterwards count nothing.
        for _ in 0..3 {
            drive(&mut p, &mut k, Some([2.0; 4]), None, 50);
        }
        assert_eq!(
            p.command_stats(),
            CommandStats {
                not_finite: 1,
                out_of_bounds: 1
            }
        );
        assert_eq!(p.timeouts(), 0);
    }

    #[test]
    fn a_reset_to_a_non_finite_heading_is_rejected_and_counted() {
        let mut p = platform(SensorParams {
            gyro_bias: 0.5,
            gyro_noise: 0.0,
            gyro_bias_walk: 0.0,
            ..SensorParams::default()
        });
        let mut k = 0;
        let imu = drive(&mut p, &mut k, None, None, 100);
        assert!(imu.yaw > 0.04, "drifted: {}", imu.yaw);
        let reset = |yaw| Some(ImuCommand::Reset { yaw });
        let imu = drive(&mut p, &mut k, None, reset(f64::NAN), 20);
        assert_eq!((p.resets(), p.rejected_resets()), (0, 1));
        assert!(imu.yaw > 0.05 && imu.yaw.is_finite(), "kept: {}", imu.yaw);
        drive(&mut p, &mut k, None, reset(f64::INFINITY), 20);
        drive(&mut p, &mut k, None, reset(f64::NEG_INFINITY), 20);
        assert_eq!((p.resets(), p.rejected_resets()), (0, 3));
        let imu = drive(&mut p, &mut k, None, reset(-1.0), 1);
        assert_eq!((p.resets(), p.rejected_resets()), (1, 3));
        assert!(
            (imu.yaw - (-1.0 + 0.5e-3)).abs() < 1e-9,
            "reset: {}",
            imu.yaw
        );
    }

    #[test]
    fn invalid_sensor_or_mocap_parameters_are_errors() {
        let plant = Plant::new(
            PlatformParams::peer_default(),
            SurfaceMap::concrete(),
            [0.0; 3],
        )
        .unwrap();
        let bad = SensorParams {
            speed_window: 0,
            ..SensorParams::default()
        };
        let err = Platform::new(plant, bad, SharedTruth::default()).unwrap_err();
        assert!(err.to_string().contains("<sensors>: speed_window"), "{err}");
        let bad = MocapParams {
            dropout_rate: f64::NAN,
            ..MocapParams::default()
        };
        let err = MotionCapture::new(bad, SharedTruth::default()).unwrap_err();
        assert!(err.to_string().contains("<mocap>: dropout_rate"), "{err}");
    }

    #[test]
    fn encoders_are_quantised_and_rates_follow_the_wheels() {
        let mut p = platform(SensorParams::default());
        let mut last = None;
        for _ in 0..2000 {
            last = Some(p.advance([2.0; 4], 1e-3));
        }
        let (_, _, enc) = last.unwrap();
        let q = std::f64::consts::TAU / 4096.0;
        for i in 0..4 {
            let ticks = enc.theta[i] / q;
            assert!((ticks - ticks.round()).abs() < 1e-9, "quantised");
            let truth = p.plant().state.theta_dot[i];
            assert!(
                (enc.rate[i] - truth).abs() < 0.2,
                "rate {} vs {truth}",
                enc.rate[i]
            );
            assert!((enc.theta[i] - p.plant().state.theta[i]).abs() <= q);
        }
    }

    #[test]
    fn the_gyro_drifts_and_a_reset_realigns_it() {
        let mut p = platform(SensorParams {
            gyro_bias: 0.02,
            ..SensorParams::default()
        });
        for _ in 0..5000 {
            p.advance([0.0; 4], 1e-3);
        }
        let (imu, _, _) = p.advance([0.0; 4], 1e-3);
        assert!(
            imu.yaw > 0.05,
            "a 0.02 rad/s bias drifts about 0.1 rad in 5 s: {}",
            imu.yaw
        );
        assert!(
            p.plant().state.phi.abs() < 1e-9,
            "while the platform stood still"
        );
        p.yaw = 0.0;
        let (imu, _, _) = p.advance([0.0; 4], 1e-3);
        assert!(imu.yaw.abs() < 1e-3);
    }

    #[test]
    fn noise_is_reproducible_from_the_seed() {
        let run = |seed| {
            let mut p = platform(SensorParams {
                seed,
                ..SensorParams::default()
            });
            (0..100)
                .map(|_| p.advance([1.0; 4], 1e-3).0.yaw_rate)
                .collect::<Vec<_>>()
        };
        assert_eq!(run(5), run(5));
        assert_ne!(run(5), run(6));
    }
}
