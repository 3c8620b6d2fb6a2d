//! The platform E1 safe-stopped ([`Driver::safe_stop`]): it brakes and holds,
//! whatever `e11` keeps commanding. The driver is stepped alone at its period of
//! 1 ms, on concrete, with the same full forward torque delivered at every step.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use embodied::{Driver, DriverContext, Period, Stamp, Time};
use rex_agent::model::{Plant, PlatformParams, SurfaceMap};
use rex_agent::payload::{ImuCommand, Torques};
use rex_agent::world::devices::{Platform, PlatformInput, PlatformOutput, SensorParams, Truth};

/// Full forward torque on every wheel \[N m\] (the platform's `torque_max`).
const FULL: Torques = [10.0; 4];

/// The platform at rest at the origin, and its inputs and outputs.
struct Rig {
    platform: Platform,
    k: u64,
    x: PlatformInput,
    y: PlatformOutput,
}

/// What one step left: the time at its end \[s\], the speed \[m/s\], the
/// position \[m\], the wheel rates \[rad/s\] and the torques applied \[N m\].
#[derive(Clone, Copy, Debug)]
struct Sample {
    t: f64,
    speed: f64,
    pos: [f64; 2],
    rates: [f64; 4],
    torques: Torques,
}

fn distance(a: [f64; 2], b: [f64; 2]) -> f64 {
    (b[0] - a[0]).hypot(b[1] - a[1])
}

impl Rig {
    fn new() -> Rig {
        let plant = Plant::new(
            PlatformParams::peer_default(),
            SurfaceMap::concrete(),
            [0.0; 3],
        )
        .unwrap();
        Rig {
            platform: Platform::new(plant, SensorParams::default()).unwrap(),
            k: 0,
            x: PlatformInput::default(),
            y: PlatformOutput::default(),
        }
    }

    /// One step with `tau` delivered as a new command (and `reset`, if any).
    fn step_with(&mut self, tau: Torques, reset: Option<ImuCommand>) -> Sample {
        let now = Time::from_nanos(self.k * 1_000_000);
        let stamp = Stamp::new(self.k, now);
        self.x.e11.tau.deliver(tau, stamp);
        match reset {
            Some(cmd) => self.x.e11.cmd_E11.deliver(cmd, stamp),
            None => self.x.e11.cmd_E11.age(),
        }
        let mut truth = Truth::default();
        let cx = DriverContext::new(now, self.k, Period::from_millis(1).unwrap())
            .with_environment(&mut truth);
        self.platform.step(cx, &self.x, &mut self.y).unwrap();
        self.k += 1;
        let s = self.platform.plant().state;
        assert_eq!(truth.state, s, "the platform writes the world");
        Sample {
            t: truth.time,
            speed: s.vx.hypot(s.vy),
            pos: [s.x, s.y],
            rates: s.theta_dot,
            torques: self.platform.torques(),
        }
    }

    /// One step with `tau` delivered as a new command.
    fn step(&mut self, tau: Torques) -> Sample {
        self.step_with(tau, None)
    }

    /// `steps` steps with `tau` delivered at each.
    fn run(&mut self, tau: Torques, steps: u64) -> Vec<Sample> {
        (0..steps).map(|_| self.step(tau)).collect()
    }
}

/// Two seconds of full torque: the platform is at speed (2.93 m/s measured,
/// near the motors' limit of 3 m/s).
fn at_speed() -> (Rig, Vec<Sample>) {
    let mut rig = Rig::new();
    let drive = rig.run(FULL, 2000);
    let speed = drive.last().unwrap().speed;
    assert!(speed > 2.5, "at speed after 2 s: {speed} m/s");
    (rig, drive)
}

/// Measured (the simulation is deterministic): from
/// 2.93 m/s, below 1 cm/s 0.509 s after the safe stop and below 1 mm/s after
/// 0.579 s, 0.65 m further; the position then moves by 3e-11 m over the last
/// 2 s. The bounds below leave a margin over these figures.
#[test]
fn a_safe_stopped_platform_brakes_to_rest_and_holds_against_full_torque() {
    let (mut rig, drive) = at_speed();
    assert_eq!(rig.platform.safe_stopped(), None, "not before");
    rig.platform.safe_stop();
    assert_eq!(
        rig.platform.safe_stopped(),
        None,
        "not before its next step"
    );
    let hold = rig.run(FULL, 3000);
    assert_eq!(
        rig.platform.safe_stopped(),
        Some(2.0),
        "the first step after the safe stop, at 2 s"
    );
    assert_eq!(rig.platform.command().unwrap().0, FULL, "still received");

    // Below 1 cm/s within 0.6 s (measured 0.509 s), and below 1 mm/s for good
    // within 0.7 s (measured 0.579 s).
    let stopped = hold.iter().position(|s| s.speed < 0.01).unwrap();
    let stop_time = hold[stopped].t - 2.0;
    assert!(stop_time < 0.6, "below 1 cm/s after {stop_time} s");
    let still = hold.iter().rposition(|s| s.speed >= 1e-3).unwrap() + 1;
    let still_time = hold.get(still).map_or(f64::INFINITY, |s| s.t - 2.0);
    assert!(
        still_time < 0.7,
        "below 1 mm/s for good after {still_time} s"
    );
    // Braking, not reversing: the speed never grows and the wheels never turn
    // backwards (a brake gain too high for the period would make them oscillate
    // about zero).
    assert!(
        hold.windows(2).all(|w| w[1].speed <= w[0].speed),
        "the speed only falls"
    );
    for s in &hold {
        assert!(s.rates.iter().all(|&w| w >= 0.0), "{s:?}");
    }
    // Held: less than 1 mm over the last 2 s (measured 3e-11 m), at rest at the end.
    let drift = distance(hold[999].pos, hold[2999].pos);
    assert!(drift < 1e-3, "moved {drift} m while held");
    let end = hold.last().unwrap();
    assert!(end.speed < 1e-6, "{end:?}");
    let braked = distance(drive.last().unwrap().pos, end.pos);
    assert!((0.3..1.0).contains(&braked), "stopped {braked} m further");
    // No torque ever beyond the platform's limit; the brake used all of it
    // (the first step: the wheels at speed).
    let max = PlatformParams::peer_default().torque_max;
    for s in drive.iter().chain(&hold) {
        assert!(s.torques.iter().all(|t| t.abs() <= max), "{s:?}");
    }
    assert_eq!(hold[0].torques, [-max; 4], "full braking at speed");
    assert!(hold.iter().all(|s| s.torques.iter().all(|&t| t <= 0.0)));
    assert_eq!(rig.platform.timeouts(), 0);
}

/// The same command without the safe stop keeps the platform moving: what the
/// brake is measured against.
#[test]
fn without_safe_stop_the_same_command_keeps_it_moving() {
    let (mut rig, drive) = at_speed();
    let on = rig.run(FULL, 3000);
    assert_eq!(rig.platform.safe_stopped(), None);
    assert!(on.iter().all(|s| s.speed > 2.5), "still at speed");
    let moved = distance(on[999].pos, on[2999].pos);
    assert!(moved > 5.0, "moved {moved} m in the last 2 s");
    assert!(distance(drive.last().unwrap().pos, on[2999].pos) > 8.0);
    let max = PlatformParams::peer_default().torque_max;
    for s in drive.iter().chain(&on) {
        assert!(s.torques.iter().all(|&t| t > 0.0 && t <= max), "{s:?}");
    }
}

/// The safe stop is latched: a second call does not move its time, the wheels
/// stay held whatever the commands, and the IMU resets are still obeyed.
#[test]
fn the_safe_stop_is_latched_and_imu_resets_are_still_obeyed() {
    let (mut rig, _) = at_speed();
    rig.platform.safe_stop();
    rig.run(FULL, 1000);
    rig.platform.safe_stop();
    let reverse = rig.run([-10.0, 10.0, -10.0, 10.0], 1000);
    assert_eq!(rig.platform.safe_stopped(), Some(2.0));
    assert!(
        reverse.iter().all(|s| s.speed < 1e-3),
        "{:?}",
        reverse.last()
    );
    let omega = rig.platform.plant().state.omega;
    assert!(omega.abs() < 1e-6, "no turn on the spot: {omega} rad/s");
    rig.step_with(FULL, Some(ImuCommand::Reset { yaw: 0.5 }));
    assert_eq!(rig.platform.resets(), 1);
    let yaw = rig.y.e11.imu.written().unwrap().yaw;
    assert!((yaw - 0.5).abs() < 0.01, "reset to 0.5: {yaw}");
}
