//! Unit tests of the full model: the Newton system's solver, straight driving
//! and turning, stiff wheels, the step size against a fine reference, spinning
//! on ice, bad commands, invalid set-ups, a failed Newton solve, load transfer.

use super::*;
use crate::model::params::Surface;

fn p_half_track() -> f64 {
    PlatformParams::peer_default().half_track
}

fn plant() -> Plant {
    Plant::new(
        PlatformParams::peer_default(),
        SurfaceMap::concrete(),
        [0.0, 0.0, 0.0],
    )
    .unwrap()
}

fn run(p: &mut Plant, tau: [f64; 4], seconds: f64, h: f64) {
    for _ in 0..(seconds / h).round() as usize {
        let t = p.limit(tau);
        p.step(t, h);
    }
}

#[test]
fn solver_matches_a_known_system() {
    let mut a = [[0.0; 7]; 7];
    for i in 0..7 {
        a[i][i] = 2.0 + i as f64;
        a[i][(i + 3) % 7] = 1.0;
    }
    let x_true = [1.0, -2.0, 3.0, 0.5, 0.0, -1.0, 2.0];
    let mut b = [0.0; 7];
    for i in 0..7 {
        b[i] = (0..7).map(|k| a[i][k] * x_true[k]).sum();
    }
    let x = solve7(a, b).unwrap();
    for i in 0..7 {
        assert!((x[i] - x_true[i]).abs() < 1e-12);
    }
    assert!(solve7([[0.0; 7]; 7], b).is_none());
}

#[test]
fn straight_driving_reaches_the_speed_where_torque_balances_rolling_resistance() {
    let mut p = plant();
    run(&mut p, [1.0; 4], 5.0, 1e-3);
    let s = p.state;
    assert!(s.vx > 0.5, "drives forward: {s:?}");
    assert!(s.vy.abs() < 1e-9 && s.omega.abs() < 1e-9, "straight: {s:?}");
    // Steady state: τ = r F_x + r μ_r N sg(r θ̇) per wheel and Σ F_x = 0 ... at
    // steady speed the net force is small: the acceleration has died down.
    let before = s.vx;
    run(&mut p, [1.0; 4], 1.0, 1e-3);
    assert!(
        (p.state.vx - before).abs() < 0.3 * before,
        "approaching a steady speed"
    );
    // Wheels roll with small positive slip.
    let slip = p.params().wheel_radius * p.state.theta_dot[0] - p.state.vx;
    assert!(slip > 0.0 && slip < 0.05, "slip {slip}");
}

#[test]
fn turning_is_torque_hungry_and_the_icr_moves() {
    // Driving straight at a given speed needs little torque; spinning in place at
    // a comparable wheel speed needs much more (lateral friction).
    let turn = |tau: f64| {
        let mut p = plant();
        run(&mut p, [-tau, -tau, tau, tau], 3.0, 1e-3);
        p.state.omega
    };
    let drive = |tau: f64| {
        let mut p = plant();
        run(&mut p, [tau; 4], 3.0, 1e-3);
        p.state.vx / p.params().wheel_radius
    };
    let (slow, fast) = (turn(3.0), turn(8.0));
    eprintln!(
        "turn rate at 3 N m {slow}, at 8 N m {fast}; wheel rate driving at 3 N m {}",
        drive(3.0)
    );
    // Below the lateral friction moment (≈ 4 N m per wheel) the platform creeps
    // round in the smooth part of the friction sign; above it, it spins up.
    assert!(
        slow < 0.5 && fast > 4.0 * slow,
        "3 N m: {slow} rad/s, 8 N m: {fast} rad/s"
    );
    // The same 3 N m driving straight spins the wheels far faster than turning does.
    let wheel_when_turning = slow * p_half_track() / PlatformParams::peer_default().wheel_radius;
    assert!(drive(3.0) > 10.0 * wheel_when_turning);
    // A curve: the ICR is not at the centre of mass and depends on the speed.
    let icr = |tau: [f64; 4]| {
        let mut curve = plant();
        run(&mut curve, tau, 1.0, 1e-3);
        curve.icr_x().expect("turning")
    };
    let (gentle, hard) = (icr([1.0, 1.0, 4.0, 4.0]), icr([1.0, 1.0, 8.0, 8.0]));
    assert!(
        gentle.abs() > 1e-4,
        "the ICR is shifted from the COM: {gentle}"
    );
    assert!(
        (gentle - hard).abs() > 1e-4,
        "and moves with the manoeuvre: {gentle} vs {hard}"
    );
}

#[test]
fn stable_for_stiff_wheels() {
    // Wheel inertia 100× smaller and a near-Coulomb friction sign: eigenvalues
    // of 10⁵–10⁶ s⁻¹, way beyond any explicit method at 1 kHz.
    let params = PlatformParams {
        wheel_inertia: 1e-4,
        sign_smoothing: 500.0,
        ..PlatformParams::peer_default()
    };
    let mut p = Plant::new(params, SurfaceMap::concrete(), [0.0; 3]).unwrap();
    run(&mut p, [5.0, 5.0, 6.0, 6.0], 2.0, 1e-3);
    let s = p.state;
    let all = [s.x, s.y, s.vx, s.vy, s.omega];
    assert!(
        all.iter().all(|v| v.is_finite() && v.abs() < 100.0),
        "{s:?}"
    );
    assert!(
        s.theta_dot.iter().all(|w| w.is_finite() && w.abs() < 100.0),
        "{s:?}"
    );
}

#[test]
fn one_millisecond_agrees_with_a_fine_reference() {
    // The same manoeuvre at h = 1 ms and h = 0.01 ms: positions within 1 cm after 2 s.
    let tau = [3.0, 3.0, 5.0, 5.0];
    let mut coarse = plant();
    run(&mut coarse, tau, 2.0, 1e-3);
    let mut fine = plant();
    run(&mut fine, tau, 2.0, 1e-5);
    let dx = coarse.state.x - fine.state.x;
    let dy = coarse.state.y - fine.state.y;
    assert!(
        (dx * dx + dy * dy).sqrt() < 0.01,
        "{:?} vs {:?}",
        coarse.state,
        fine.state
    );
    assert!((coarse.state.phi - fine.state.phi).abs() < 0.01);
}

#[test]
fn ice_under_the_wheels_makes_them_spin() {
    let mut map = SurfaceMap::concrete();
    map.surfaces.push(Surface {
        name: "ice".into(),
        mu_long: 0.08,
        mu_lat: 0.05,
        rolling: 0.01,
    });
    map.default = "ice".into();
    let mut ice = Plant::new(PlatformParams::peer_default(), map, [0.0; 3]).unwrap();
    let mut concrete = plant();
    run(&mut ice, [4.0; 4], 1.0, 1e-3);
    run(&mut concrete, [4.0; 4], 1.0, 1e-3);
    let slip = |p: &Plant| p.params().wheel_radius * p.state.theta_dot[0] - p.state.vx;
    assert!(
        slip(&ice) > 10.0 * slip(&concrete).max(1e-3),
        "ice {} concrete {}",
        slip(&ice),
        slip(&concrete)
    );
    assert!(ice.state.vx < concrete.state.vx);
}

#[test]
fn bad_commands_are_clamped_and_counted_once_per_command() {
    let mut p = plant();
    let t = p.clean([f64::NAN, 100.0, -100.0, 1.0]);
    assert_eq!(t, [0.0, 10.0, -10.0, 1.0]);
    assert_eq!(
        p.command_stats(),
        CommandStats {
            not_finite: 1,
            out_of_bounds: 1
        },
        "one command with a NaN and two torques beyond the bounds"
    );
    assert_eq!(p.clean([f64::INFINITY; 4]), [0.0; 4]);
    assert_eq!(p.clean([f64::NEG_INFINITY, 0.0, 0.0, 0.0]), [0.0; 4]);
    assert_eq!(p.clean([10.0, -10.0, 0.0, 3.0]), [10.0, -10.0, 0.0, 3.0]);
    assert_eq!(
        p.command_stats(),
        CommandStats {
            not_finite: 3,
            out_of_bounds: 1
        },
        "infinities are not finite; ±torque_max is within bounds"
    );
    // The motor curve applies at every step and counts nothing.
    p.state.theta_dot = [30.0; 4];
    assert_eq!(
        p.available([5.0; 4]),
        [0.0; 4],
        "no drive torque at the no-load speed"
    );
    assert_eq!(p.available([-5.0; 4]), [-5.0; 4], "braking is not limited");
    p.state.theta_dot = [15.0; 4];
    assert_eq!(
        p.available([8.0, -8.0, f64::NAN, 50.0]),
        [5.0, -8.0, 0.0, 5.0]
    );
    assert_eq!(
        p.command_stats().not_finite,
        3,
        "available() counts nothing"
    );
    assert_eq!(p.command_stats().out_of_bounds, 1);
    assert_eq!(p.limit([f64::NAN; 4]), [0.0; 4]);
    assert_eq!(
        p.command_stats().not_finite,
        4,
        "limit() cleans, and counts"
    );
}

#[test]
fn invalid_parameters_ground_or_pose_are_errors() {
    let bad = PlatformParams {
        mass: -1.0,
        ..PlatformParams::peer_default()
    };
    let err = Plant::new(bad, SurfaceMap::concrete(), [0.0; 3]).unwrap_err();
    assert!(err.to_string().contains("<platform>: mass = -1"), "{err}");
    // A centre of mass over an axle leaves the other axle's wheels without
    // load, which the prediction models divide by.
    let over_the_axle = PlatformParams {
        rear: 0.0,
        ..PlatformParams::peer_default()
    };
    let err = Plant::new(over_the_axle, SurfaceMap::concrete(), [0.0; 3]).unwrap_err();
    assert!(err.to_string().contains("<platform>: rear = 0"), "{err}");
    let empty = SurfaceMap {
        surfaces: Vec::new(),
        ..SurfaceMap::concrete()
    };
    let err = Plant::new(PlatformParams::peer_default(), empty, [0.0; 3]).unwrap_err();
    assert!(err.to_string().contains("<surfaces>: surfaces"), "{err}");
    let mut twice = SurfaceMap::concrete();
    twice.surfaces.push(twice.surfaces[0].clone());
    let err = Plant::new(PlatformParams::peer_default(), twice, [0.0; 3]).unwrap_err();
    assert!(err.to_string().contains("surfaces[1].name"), "{err}");
    let err = Plant::new(
        PlatformParams::peer_default(),
        SurfaceMap::concrete(),
        [0.0, f64::NAN, 0.0],
    )
    .unwrap_err();
    assert!(err.to_string().contains("<start pose>: y = NaN"), "{err}");
}

#[test]
fn a_failed_newton_solve_is_counted() {
    // A normal run: every step converges.
    let mut p = plant();
    run(&mut p, [3.0, 3.0, 6.0, 6.0], 2.0, 1e-3);
    assert_eq!(p.integration_stats(), IntegrationStats::default());
    // A NaN velocity makes the Newton system unsolvable: the step keeps the
    // velocities it started with, and is counted.
    p.state.vy = f64::NAN;
    let before = p.state;
    p.step([1.0; 4], 1e-3);
    assert_eq!(
        p.integration_stats(),
        IntegrationStats {
            singular: 1,
            unconverged: 0
        }
    );
    assert_eq!(p.state.vx, before.vx, "frozen");
    assert_eq!(p.state.theta_dot, before.theta_dot, "frozen");
    p.step([1.0; 4], 1e-3);
    assert_eq!(p.integration_stats().singular, 2);
}

#[test]
fn load_transfer_shows_on_the_wheels() {
    let mut p = plant();
    run(&mut p, [6.0; 4], 0.1, 1e-3);
    let n = p.loads();
    assert!(
        n[1] > n[0] && n[3] > n[2],
        "accelerating forward loads the rear wheels: {n:?}"
    );
    let total: f64 = n.iter().sum();
    let weight = p.params().mass * p.params().gravity;
    assert!((total - weight).abs() < 1e-6);
}
