//! The NMPC on the peers' problem (were its unit tests in rex-agent): the peer's
//! figure eight, structured and Clarabel QPs alike, converged SQP on the dynamics
//! and bounds, fallbacks and braking, bad input.

use rex_agent::algorithms::mpc::nmpc::{
    Control, FrozenQp, IPM_MAX_ITERATIONS, Nmpc, NmpcError, NmpcSettings, NmpcStats, QpStrategy,
    Status,
};
use rex_agent::model::{Dynamics, NU, Reduced, SlipParams, State5, Vector};
use rex_bench::peer::{self, DT, INIT_OFFSET, N_SIM, PLANT_RK4_STEPS};

const NX: usize = 5;

/// The nominal slip parameters as the NMPC takes them.
const P: [f64; 3] = [0.03, 0.05, 0.5];

/// The peers' closed loop for `steps` samples from their initial offset:
/// `control` gives sample `k`'s torques from the controller, `k`, the true state
/// and the reference over the horizon. The true states (the first included) and
/// the controller.
fn drive(
    settings: NmpcSettings<5>,
    steps: usize,
    mut control: impl FnMut(&mut Nmpc<Reduced, 5, 3>, usize, &State5, &[State5]) -> Control,
) -> (Vec<State5>, Nmpc<Reduced, 5, 3>) {
    let model = peer::model();
    let n = settings.horizon;
    let r = peer::reference_run(N_SIM + n + 1);
    let mut nmpc = Nmpc::new(model.clone(), settings).unwrap();
    let mut x = r[0];
    for i in 0..5 {
        x[i] += INIT_OFFSET[i];
    }
    let mut xs = vec![x];
    for k in 0..steps {
        let c = control(&mut nmpc, k, &x, &r[k..=k + n]);
        x = model.rk4_5(&x, &c.torques, &SlipParams::NOMINAL, DT, PLANT_RK4_STEPS);
        xs.push(x);
    }
    (xs, nmpc)
}

/// The peers' closed loop for `steps` samples; the true positions and the
/// statuses.
fn closed_loop(settings: NmpcSettings<5>, steps: usize) -> (Vec<State5>, Vec<Status>, NmpcStats) {
    let mut status = Vec::new();
    let (xs, nmpc) = drive(settings, steps, |nmpc, _, x, r| {
        let c = nmpc.control(x, r, &P).unwrap();
        status.push(c.status.clone());
        c
    });
    (xs, status, nmpc.stats())
}

/// The peers' closed loop (one lap, default settings): `each` gets every QP
/// with an active bound, frozen before the controller solves it and goes on.
/// The number of such QPs.
fn each_active_qp_of_the_lap(mut each: impl FnMut(FrozenQp<Reduced, 5, 3>)) -> usize {
    let mut active = 0;
    drive(NmpcSettings::default(), N_SIM, |nmpc, k, x, r| {
        if k == 0 {
            return nmpc.control(x, r, &P).unwrap();
        }
        nmpc.prepare(r, &P).unwrap();
        let mut qp = nmpc.freeze_qp(x).unwrap();
        if qp.active().unwrap() {
            active += 1;
            each(qp);
        }
        nmpc.feedback(x).unwrap()
    });
    active
}

#[test]
fn tracks_the_figure_eight_like_the_peer() {
    let (xs, _, stats) = closed_loop(NmpcSettings::default(), N_SIM);
    let r = peer::reference_run(N_SIM + 1);
    let err: Vec<f64> = xs
        .iter()
        .zip(&r)
        .map(|(x, r)| (x[0] - r[0]).hypot(x[1] - r[1]))
        .collect();
    let rms = |e: &[f64]| (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt();
    // The peer: rms 0.0296 m over the lap, 0.0016 m after 2 s.
    assert!((rms(&err) - 0.0296).abs() < 0.0005, "rms {}", rms(&err));
    assert!(rms(&err[40..]) < 0.002, "steady rms {}", rms(&err[40..]));
    assert_eq!(stats.failures, 0);
    // Bounds are active in a third of the samples: the structured
    // interior-point method solves those, Clarabel none.
    assert!(stats.structured > 0 && stats.ipm > 0, "{stats:?}");
    assert_eq!((stats.ipm_fallbacks, stats.clarabel), (0, 0), "{stats:?}");
}

#[test]
fn structured_and_clarabel_qps_give_the_same_closed_loop() {
    let steps = 60;
    let (a, sa, structured) = closed_loop(NmpcSettings::default(), steps);
    // The reference: Clarabel on every QP, to a tolerance far below the
    // structured solver's.
    let clarabel = NmpcSettings {
        qp: QpStrategy::Clarabel,
        qp_tolerance: 1e-10,
        ..NmpcSettings::default()
    };
    let (b, _, stats) = closed_loop(clarabel, steps);
    assert_eq!(stats.structured, 0);
    for (x, y) in a.iter().zip(&b) {
        for i in 0..5 {
            assert!((x[i] - y[i]).abs() < 1e-6, "{x:?} vs {y:?}");
        }
    }
    assert!(
        structured.ipm > 0 && structured.structured > 0,
        "{structured:?}"
    );
    assert!(sa.iter().all(|s| *s == Status::Solved { clarabel: false }));
}

#[test]
fn the_structured_interior_point_method_solves_each_qp_as_clarabel_does() {
    // The QPs of the peers' closed loop (one lap) with an active bound, each
    // solved by both before the controller goes on.
    let mut iterations = 0;
    // Largest differences: states, torques, objective (its values are 1e-3 to
    // 0.2).
    let mut worst = [0.0f64; 3];
    let mut violation = 0.0f64;
    let compared = each_active_qp_of_the_lap(|mut qp| {
        let ipm = qp.solve_structured().unwrap();
        let mut tight = qp.clarabel(1e-10).unwrap();
        let clarabel = qp.solve_clarabel(&mut tight).unwrap();
        iterations = iterations.max(ipm.iterations);
        for (j, (a, b)) in ipm.step.iter().zip(&clarabel.step).enumerate() {
            let torque = usize::from(j % (NU + NX) < NU);
            worst[torque] = worst[torque].max((a - b).abs());
        }
        // The same QP in the common sparse form: both feasible, the same
        // objective.
        let sparse = qp.sparse();
        let f = [
            sparse.objective(&ipm.step),
            sparse.objective(&clarabel.step),
        ];
        worst[2] = worst[2].max((f[0] - f[1]).abs());
        violation = violation
            .max(sparse.violation(&ipm.step))
            .max(sparse.violation(&clarabel.step));
    });
    assert!(compared > 50, "{compared} QPs with an active bound");
    assert!(violation < 1e-8, "constraint violation {violation}");
    assert!(iterations < IPM_MAX_ITERATIONS, "{iterations}");
    // The same optimum: the objectives agree to 1e-9, the state trajectories
    // to 1e-6 (measured: 3.5e-7). The torques, which the cost weighs by 1e-3
    // only, sit in a valley of the objective so flat that two solutions 1e-10
    // apart in it differ by up to 1e-4 in the torques (measured: 1.9e-5):
    // both solvers are there within their tolerances.
    assert!(worst[0] < 1e-6, "states {worst:?}");
    assert!(worst[1] < 1e-4, "torques {worst:?}");
    assert!(worst[2] < 1e-9, "objective {worst:?}");
}

#[test]
fn warm_started_interior_point_solves_are_the_cold_ones_in_fewer_iterations() {
    // Every QP with an active bound of the peers' lap, solved from the
    // controller's start (the last solution's multipliers, shifted) and cold.
    let (mut warm, mut cold) = (0, 0);
    let mut worst = 0.0f64;
    let compared = each_active_qp_of_the_lap(|mut qp| {
        let a = qp.solve_structured().unwrap();
        // Solving again starts from the same multipliers.
        assert_eq!(qp.solve_structured().unwrap().step, a.step);
        let b = qp.cold().solve_structured().unwrap();
        for (j, (a, b)) in a.step.iter().zip(&b.step).enumerate() {
            if j % (NU + NX) >= NU {
                worst = worst.max((a - b).abs());
            }
        }
        (warm, cold) = (warm + a.iterations, cold + b.iterations);
    });
    assert!(compared > 50, "{compared} QPs with an active bound");
    // The same solution (states to 1e-6, as against Clarabel), measured
    // 5.6 against 6.8 iterations on average.
    assert!(worst < 1e-6, "states {worst}");
    assert!(
        10 * warm < 9 * cold,
        "{warm} warm vs {cold} cold iterations"
    );
}

#[test]
fn converged_sqp_satisfies_the_dynamics_and_the_bounds() {
    let model = peer::model();
    let s = NmpcSettings::default();
    let r = peer::reference_run(s.horizon + 1);
    let mut nmpc = Nmpc::new(model.clone(), s.clone()).unwrap();
    let mut x0 = r[0];
    x0[0] += 0.3;
    let p = P;
    let iterations = nmpc.solve(&x0, &r, &p).unwrap();
    assert!(iterations < s.sqp_max_iterations, "{iterations} iterations");
    let (xs, us) = (nmpc.predicted(), nmpc.torques());
    assert_eq!(xs[0], Vector::from(x0));
    for k in 0..s.horizon {
        let next = model.rk4(&xs[k], &us[k], &Vector::from(p), s.dt, s.rk4_steps);
        for i in 0..5 {
            assert!((next[i] - xs[k + 1][i]).abs() < 1e-7, "defect at stage {k}");
        }
        assert!(us[k].iter().all(|u| u.abs() <= s.torque_max + 1e-6));
        assert!(xs[k + 1][4].abs() <= s.yaw_rate_max + 1e-6);
    }
    // 30 cm off: the torques saturate at the start.
    assert!(
        us[0].iter().any(|u| (u.abs() - s.torque_max).abs() < 1e-6),
        "{:?}",
        us[0]
    );
}

#[test]
fn an_infeasible_qp_is_refused_by_both_solvers_never_solved_wrongly() {
    // Far above the speed bound (1.5 m/s): no torque brings the next state
    // within it, so the QP has no solution. The interior-point method must
    // not return one; Clarabel then refuses it too, and the controller falls
    // back.
    let model = peer::model();
    let s = NmpcSettings::default();
    let r = peer::reference_run(s.horizon + 1);
    let mut nmpc = Nmpc::new(model, s).unwrap();
    let p = P;
    let fast = [0.0, 0.0, 0.0, 6.0, 0.0];
    let c = nmpc.control(&fast, &r, &p).unwrap();
    assert!(
        matches!(c.status, Status::Fallback { .. } | Status::SafeStop { .. }),
        "{:?}",
        c.status
    );
    let stats = nmpc.stats();
    assert_eq!((stats.ipm, stats.clarabel), (0, 0), "{stats:?}");
    assert!(stats.ipm_fallbacks >= 1 && stats.failures >= 1, "{stats:?}");
    assert!(c.torques.iter().all(|t| t.is_finite() && t.abs() <= 10.0));
}

#[test]
fn qp_failures_fall_back_then_brake() {
    // Clarabel cannot finish in one iteration: every QP fails.
    let settings = NmpcSettings {
        qp: QpStrategy::Clarabel,
        qp_max_iterations: 1,
        fallback_steps: 3,
        ..NmpcSettings::default()
    };
    let model = peer::model();
    let r = peer::reference_run(40);
    let mut nmpc = Nmpc::new(model, settings).unwrap();
    let p = P;
    let moving = [0.0, 0.0, 0.0, 0.6, 0.5];
    let mut kinds = Vec::new();
    for k in 0..6 {
        let c = nmpc.control(&moving, &r[k..=k + 20], &p).unwrap();
        kinds.push(match &c.status {
            Status::Solved { .. } => "solved",
            Status::Fallback { reason } => {
                assert!(reason.contains("MaxIterations"), "{reason}");
                "fallback"
            }
            Status::SafeStop { .. } => {
                // Braking: forward speed and turn are opposed.
                let (left, right) = (c.torques[0], c.torques[2]);
                assert!(left + right < 0.0 && right - left < 0.0, "{:?}", c.torques);
                "stop"
            }
        });
    }
    assert_eq!(
        kinds,
        ["fallback", "fallback", "fallback", "stop", "stop", "stop"]
    );
    let stats = nmpc.stats();
    assert_eq!(
        (stats.failures, stats.fallbacks, stats.safe_stops),
        (6, 3, 3)
    );
}

#[test]
fn bad_input_is_an_error_not_a_panic() {
    let mut nmpc = Nmpc::new(peer::model(), NmpcSettings::default()).unwrap();
    let r = peer::reference_run(21);
    let p = P;
    let nan = [f64::NAN, 0.0, 0.0, 0.0, 0.0];
    assert_eq!(
        nmpc.control(&nan, &r, &p),
        Err(NmpcError::NotFinite("state estimate"))
    );
    assert!(matches!(
        nmpc.control(&r[0], &r[..5], &p),
        Err(NmpcError::ShortReference { got: 5, need: 21 })
    ));
    let bad_p = [0.03, 0.05, f64::INFINITY];
    assert!(nmpc.control(&r[0], &r, &bad_p).is_err());
    assert_eq!(nmpc.feedback(&r[0]), Err(NmpcError::NotPrepared));
    for bad in [
        NmpcSettings {
            horizon: 0,
            ..NmpcSettings::default()
        },
        NmpcSettings {
            r: [0.0; 4],
            ..NmpcSettings::default()
        },
        NmpcSettings {
            dt: f64::NAN,
            ..NmpcSettings::default()
        },
        NmpcSettings {
            q: [-1.0; 5],
            ..NmpcSettings::default()
        },
    ] {
        assert!(matches!(
            Nmpc::new(peer::model(), bad),
            Err(NmpcError::Settings(_))
        ));
    }
}
