//! The platform E1, the real effector of a1: the full model driven by `e1,1`'s
//! torques, with its sensors (wheel encoders, IMU, force sensors) and their noise.
//! It writes the ground truth every step.
//!
//! When the run safe-stops ([`Driver::safe_stop`]) the platform brakes and holds:
//! from its next step on, each wheel gets a braking torque against its own rate,
//! whatever `e11` commands, until the end of the run.

use embodied::{Buffers, DeviceKind, Driver, DriverContext, DriverError, Group, In, Out};
use serde::{Deserialize, Serialize};

use super::Truth;
use crate::config::{self, ConfigError, Invalid, Validate, non_negative, positive};
use crate::math::geometry::wrap;
use crate::math::rng::Rng;
use crate::model::{CommandStats, Plant};
use crate::payload::{Encoders, Imu, ImuCommand, Torques, WheelLoads};

/// Sensor characteristics of the platform.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SensorParams {
    /// Encoder counts per wheel revolution.
    pub encoder_ticks: u32,
    /// Samples over which the wheel rate is computed from the counts.
    pub speed_window: u32,
    /// Gyroscope white noise \[rad/s\].
    pub gyro_noise: f64,
    /// Gyroscope bias at start \[rad/s\].
    pub gyro_bias: f64,
    /// Random walk of the gyroscope bias \[rad/s per √s\].
    pub gyro_bias_walk: f64,
    /// Accelerometer noise \[m/s²\].
    pub accel_noise: f64,
    /// Force sensor noise \[N\].
    pub load_noise: f64,
    /// A torque command older than this is replaced by zero torque \[s\] (the motor
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

impl SensorParams {
    /// How long the encoders count ticks for a rate \[s\], sampled every
    /// `step` seconds (the platform's period).
    pub fn encoder_window(&self, step: f64) -> f64 {
        f64::from(self.speed_window) * step
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
    rng: Rng,
    counts: [[i64; 4]; 64],
    samples: u64,
    bias: f64,
    /// The IMU's integrated heading (the devices' tests set it).
    pub(super) yaw: f64,
    last_command: Option<(Torques, f64)>,
    timeouts: u64,
    resets: u64,
    rejected_resets: u64,
    /// The torques the motors delivered in the last step.
    applied: Torques,
    /// [`Driver::safe_stop`] was called: the brake holds from the next step on.
    held: bool,
    /// When the brake first acted \[s\].
    safe_stopped: Option<f64>,
    /// The robot of a fleet it is ([`super::FleetTruth`]); `None`: the single Rex.
    robot: Option<usize>,
}

impl Platform {
    /// The platform `plant` with sensors `params` (validated). It writes the
    /// system's environment, [`Truth`], every step.
    pub fn new(plant: Plant, params: SensorParams) -> Result<Platform, ConfigError> {
        config::check("sensors", &params)?;
        let rng = Rng::stream(params.seed, "platform");
        Ok(Platform {
            yaw: plant.state.phi,
            bias: params.gyro_bias,
            plant,
            params,
            rng,
            counts: [[0; 4]; 64],
            samples: 0,
            last_command: None,
            timeouts: 0,
            resets: 0,
            rejected_resets: 0,
            applied: [0.0; 4],
            held: false,
            safe_stopped: None,
            robot: None,
        })
    }

    /// The platform of robot `robot` of a fleet: it writes the robot's entry of
    /// the fleet's [`super::FleetTruth`] instead of the system's [`Truth`].
    pub fn in_fleet(mut self, robot: usize) -> Platform {
        self.robot = Some(robot);
        self
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
    /// zeroed, the others clamped to `±torque_max`), and when it arrived \[s\].
    /// Once the platform is safe-stopped, the commands are still received,
    /// cleaned and counted, but the wheels do not obey them.
    pub fn command(&self) -> Option<(Torques, f64)> {
        self.last_command
    }

    /// The wheel torques the motors delivered in the last step \[N m\]: the
    /// command in force, or the brake's once safe-stopped, as [`Plant::available`]
    /// limits them (never beyond `±torque_max`). Zero before the first step.
    pub fn torques(&self) -> Torques {
        self.applied
    }

    /// When the platform safe-stopped: the simulation time of its first step
    /// after [`Driver::safe_stop`] \[s\], the first step it braked. `None` if it
    /// was not safe-stopped, or has not stepped since.
    pub fn safe_stopped(&self) -> Option<f64> {
        self.safe_stopped
    }

    /// The braking torques for a step of `dt` seconds: `τ_i = −k θ̇_i` on each
    /// wheel, saturated at `±torque_max`, with `k = J_w / (2 dt)`.
    ///
    /// The brake torque is held over the step (computed from the rates at its
    /// start), so a wheel without grip (in the air, or skidding where the slip
    /// force is flat) follows `θ̇ ← (1 − k dt / J_w) θ̇`: monotone for `k < J_w /
    /// dt`, and `J_w / (2 dt)` halves the rate every step. A rolling wheel has
    /// more margin (the slip stiffness, `r² μ_x N (2/π) k_s` ≈ 10 N m s/rad,
    /// integrated implicitly, adds to `J_w / dt`), but 3 `J_w / dt` no longer
    /// settles within the bounds of `tests/safe_stop.rs`.
    ///
    /// For the 40 kg platform (`J_w` = 0.01 kg m², r = 0.1 m) at its period of
    /// 1 ms, `k` = 5 N m s/rad: saturated at 10 N m above 2 rad/s (0.2 m/s at
    /// the rim), where the wheels skid and the ground's friction
    /// (μ_x = 0.8 on concrete, at most 7.8 m/s² smoothed by the slip sign)
    /// decelerates the platform (6.7 m/s² measured); below, the wheels roll and
    /// the speed decays with the time constant `m_eff r² / (4 k)` = 44 × 0.01 / 20
    /// = 22 ms (30 ms measured, the tyres' slip adding to it). From 2.93 m/s, after
    /// 2 s of full torque, the platform is below 1 cm/s 0.51 s later, 0.65 m
    /// further, without reversing (`tests/safe_stop.rs`); then it is at rest: the
    /// brake's torque vanishes with the rates, and on flat ground no force moves
    /// it (3·10⁻¹¹ m in 2 s).
    fn brake(&self, dt: f64) -> Torques {
        let p = self.plant.params();
        let k = p.wheel_inertia / (2.0 * dt);
        let max = p.torque_max;
        self.plant
            .state
            .theta_dot
            .map(|w| (-k * w).clamp(-max, max))
    }

    /// Steps run with zero torque because the last command was too old (not
    /// counted once safe-stopped: no command is obeyed then).
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
        self.applied = tau;
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
            time: 0.0,
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

    fn step(
        &mut self,
        mut cx: DriverContext<'_>,
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
        let command = if self.held {
            self.safe_stopped.get_or_insert(now);
            self.brake(dt)
        } else {
            match self.last_command {
                Some((tau, at)) if now - at <= self.params.command_timeout => tau,
                Some(_) => {
                    self.timeouts += 1;
                    [0.0; 4]
                }
                None => [0.0; 4],
            }
        };
        let (imu, forces, mut encoders) = self.advance(command, dt);
        encoders.time = now + dt;
        *super::truth(&mut cx, self.robot)? = Truth {
            time: now + dt,
            state: self.plant.state,
        };
        y.e11.imu.set(imu);
        y.e11.forces.set(forces);
        y.e11.encoders.set(encoders);
        Ok(())
    }

    /// Brake and hold: from the next step on, the wheels get the brake's torques
    /// (`Platform::brake`) whatever `e11` commands, until the end of the run; the
    /// IMU resets are still obeyed. Latched: a second call changes nothing.
    fn safe_stop(&mut self) {
        self.held = true;
    }
}
