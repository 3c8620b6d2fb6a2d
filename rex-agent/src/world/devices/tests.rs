//! Unit tests of the devices: the platform's commands and IMU resets, encoder
//! quantisation, gyro drift, reproducible noise, invalid sensor and motion-capture
//! parameters.

use super::*;
use crate::model::{CommandStats, Plant, PlatformParams, SurfaceMap};
use crate::payload::{Imu, ImuCommand, Torques};
use embodied::{Driver, DriverContext, Period, Stamp, Time};

fn platform(params: SensorParams) -> Platform {
    let plant = Plant::new(
        PlatformParams::peer_default(),
        SurfaceMap::concrete(),
        [0.0; 3],
    )
    .unwrap();
    Platform::new(plant, params).unwrap()
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
        let mut truth = Truth::default();
        let cx = DriverContext::new(
            Time::from_nanos(*k * 1_000_000),
            *k,
            Period::from_millis(1).unwrap(),
        )
        .with_environment(&mut truth);
        p.step(cx, &x, &mut y).unwrap();
        assert_eq!(
            truth.state,
            p.plant().state,
            "the platform writes the world"
        );
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
    let err = Platform::new(plant, bad).unwrap_err();
    assert!(err.to_string().contains("<sensors>: speed_window"), "{err}");
    let bad = MocapParams {
        dropout_rate: f64::NAN,
        ..MocapParams::default()
    };
    let err = MotionCapture::new(bad).unwrap_err();
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
