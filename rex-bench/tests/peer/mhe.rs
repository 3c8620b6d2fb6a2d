//! The MHE on the peer's problem (were its unit tests in rex-agent): structured and
//! Clarabel solutions alike, dropouts, garbage, late poses, parameter bounds,
//! visual odometry and IMU heading increments, relocalisation.

use rex_agent::algorithms::mpc::mhe::{
    Innovation, Mhe, MheError, MheSettings, Motion, ReducedMhe, Sample, TimedPose,
};
use rex_agent::algorithms::mpc::nmpc::QpStrategy;
use rex_agent::math::geometry::wrap;
use rex_bench::peer::{self, DT, MheData, N_SIM, P_TRUE_MHE};

type Settings = MheSettings<5, 3>;

fn data() -> MheData {
    peer::mhe_data(1).unwrap()
}

/// Run the MHE over the data set; `edit` may change each sample. Returns the
/// position errors from `k = N` on (as the peer) and the estimator.
fn run(
    settings: Settings,
    d: &MheData,
    edit: impl Fn(usize, &mut Sample),
) -> (Vec<f64>, ReducedMhe) {
    let n = settings.horizon;
    let mut mhe = Mhe::new(peer::model(), settings).unwrap();
    let mut err = Vec::new();
    for k in 0..=N_SIM {
        let mut s = d.sample(k);
        edit(k, &mut s);
        let u = if k > 0 { d.us[k - 1] } else { [0.0; 4] };
        let e = mhe.update(k as f64 * DT, &u, &s);
        if k >= n {
            err.push((e.x[0] - d.xs[k][0]).hypot(e.x[1] - d.xs[k][1]));
        }
    }
    (err, mhe)
}

fn rms(e: &[f64]) -> f64 {
    (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt()
}

#[test]
fn estimates_the_state_and_the_slip_parameters_like_the_peer() {
    // The peer (one noise draw): position RMS 0.0084 m (raw measurements
    // 0.0285 m), final |p − p_true| = (0.0079, 0.0000, 0.0033). The parameter
    // errors depend on the draw: compare their mean over four draws.
    let mut mean = [0.0; 3];
    for seed in 1..=4 {
        let d = peer::mhe_data(seed).unwrap();
        let (err, mhe) = run(Settings::default(), &d, |_, _| {});
        assert!(rms(&err) < 0.01, "seed {seed}: position rms {}", rms(&err));
        assert_eq!(mhe.stats().rejected, 0);
        assert_eq!(mhe.stats().failures, 0);
        let p = mhe.estimate().p;
        for (m, (e, t)) in mean.iter_mut().zip(p.iter().zip(P_TRUE_MHE.to_array())) {
            *m += (e - t).abs() / 4.0;
        }
    }
    assert!(
        mean[0] < 0.01 && mean[1] < 0.005 && mean[2] < 0.01,
        "{mean:?}"
    );
}

#[test]
fn the_structured_solution_is_clarabels() {
    let d = data();
    let (a, ma) = run(Settings::default(), &d, |_, _| {});
    let full = Settings {
        qp: QpStrategy::Clarabel,
        ..Settings::default()
    };
    let (b, mb) = run(full, &d, |_, _| {});
    assert!(mb.stats().clarabel > 0);
    for (x, y) in a.iter().zip(&b) {
        assert!((x - y).abs() < 1e-6, "{x} vs {y}");
    }
    let (pa, pb) = (ma.estimate().p, mb.estimate().p);
    assert!((pa[0] - pb[0]).abs() < 1e-6 && (pa[2] - pb[2]).abs() < 1e-6);
}

#[test]
fn a_dropout_of_several_seconds_is_bridged_and_poses_are_taken_back() {
    let d = data();
    // No pose from 3 s to 6 s.
    let (err, mhe) = run(Settings::default(), &d, |k, s| {
        if (60..120).contains(&k) {
            s.pose = None;
        }
    });
    let during = &err[60 - 20..120 - 20];
    let after = &err[140 - 20..];
    assert!(
        during.iter().all(|e| *e < 0.15),
        "dead reckoning drifts: {:.3}",
        during.iter().fold(0.0f64, |m, v| m.max(*v))
    );
    assert!(rms(after) < 0.012, "recovers: {}", rms(after));
    assert_eq!(mhe.stats().rejected, 0, "the returning poses are accepted");
}

#[test]
fn garbage_is_rejected_and_counted() {
    let d = data();
    let (clean, _) = run(Settings::default(), &d, |_, _| {});
    let (err, mhe) = run(Settings::default(), &d, |k, s| match k % 10 {
        3 => s.gyro = Some(f64::NAN),
        5 => {
            if let Some(p) = &mut s.pose {
                p.pose[0] += 5.0; // a 5 m jump
            }
        }
        7 => s.encoders = Some([1e9, 0.0, 0.0, 0.0]),
        9 => {
            if let Some(p) = &mut s.pose {
                p.time = f64::NAN;
            }
        }
        _ => {}
    });
    assert_eq!(mhe.stats().rejected, 4 * 20, "{:?}", mhe.stats());
    assert!(
        rms(&err) < rms(&clean) * 1.3,
        "{} vs {}",
        rms(&err),
        rms(&clean)
    );
}

#[test]
fn late_and_intermittent_poses_go_to_the_stage_they_describe() {
    let d = data();
    // The pose of sample k arrives 2 samples late, and only every 4th one.
    let (err, mhe) = run(Settings::default(), &d, |k, s| {
        s.pose = (k >= 2 && (k - 2) % 4 == 0).then(|| {
            let y = d.ys[k - 2];
            TimedPose {
                time: (k - 2) as f64 * DT,
                pose: [y[0], y[1], y[2]],
            }
        });
        if k < 2 {
            s.pose = Some(TimedPose {
                time: 0.0,
                pose: [d.ys[0][0], d.ys[0][1], d.ys[0][2]],
            });
        }
    });
    assert!(rms(&err) < 0.015, "rms {}", rms(&err));
    assert_eq!(mhe.stats().rejected, 0);
}

#[test]
fn parameter_bounds_hold_with_clarabel_when_active() {
    let d = data();
    // x_0 is truly 0.06: bound it at 0.04.
    let settings = Settings {
        p_ub: [0.04, 0.5, 1.5],
        ..Settings::default()
    };
    let (_, mhe) = run(settings, &d, |_, _| {});
    let p = mhe.estimate().p;
    assert!(p[0] <= 0.04 + 1e-9 && p[0] > 0.039, "{p:?}");
    assert!(
        mhe.stats().clarabel > 0,
        "the bound was active: {:?}",
        mhe.stats()
    );
}

#[test]
fn visual_odometry_narrows_the_drift_of_a_dropout() {
    let d = data();
    // No pose from 3 s to 6 s, and a model that is wrong: the slip parameters
    // held at the nominal (0.03, 0.05, 0.5) while the plant has (0.06, 0.07,
    // 0.6). With visual odometry: the motion over the last two samples (from the
    // true states, as a perfect odometry would measure it).
    let wrong = Settings {
        sigma_p: [1e-5; 3],
        ..Settings::default()
    };
    let drop = |k: usize| (60..120).contains(&k);
    let (without, _) = run(wrong.clone(), &d, |k, s| {
        if drop(k) {
            s.pose = None;
        }
    });
    let (with, mhe) = run(wrong, &d, |k, s| {
        if drop(k) {
            s.pose = None;
        }
        if k >= 2 && k % 2 == 0 {
            let (a, b) = (d.xs[k - 2], d.xs[k]);
            let (sn, c) = a[2].sin_cos();
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            s.motion = Some(Motion {
                from: (k - 2) as f64 * DT,
                to: k as f64 * DT,
                delta: [c * dx + sn * dy, -sn * dx + c * dy, b[2] - a[2]],
            });
        }
    });
    let gap = |e: &[f64]| rms(&e[60 - 20..120 - 20]);
    assert!(
        gap(&with) < 0.5 * gap(&without),
        "{} vs {}",
        gap(&with),
        gap(&without)
    );
    assert_eq!(mhe.stats().rejected, 0);
    // A motion with a non-finite part or an absurd speed is rejected.
    let mut m = Mhe::new(peer::model(), Settings::default()).unwrap();
    let mut s0 = d.sample(0);
    m.update(0.0, &[0.0; 4], &s0);
    s0.motion = Some(Motion {
        from: 0.0,
        to: 0.05,
        delta: [f64::NAN, 0.0, 0.0],
    });
    m.update(0.05, &[0.0; 4], &s0);
    s0.motion = Some(Motion {
        from: 0.05,
        to: 0.1,
        delta: [5.0, 0.0, 0.0],
    });
    m.update(0.1, &[0.0; 4], &s0);
    assert_eq!(m.stats().rejected, 2);
}

/// An IMU heading that drifts away from the map's (an offset of 0.5 rad growing
/// by 0.02 rad/s, as an integrated gyroscope with a bias does) must not pull
/// the estimate: only its increments count. Taken as an absolute heading (the
/// cause of Rex's long-mission divergence) it pulled the heading estimate by
/// about a tenth of the offset, and gated the poses out once it grew.
#[test]
fn a_drifting_imu_heading_does_not_pull_the_estimate() {
    let d = data();
    let offset = |k: usize| 0.5 + 0.02 * k as f64 * DT;
    // Half of the poses lost: the IMU matters more.
    let (without, _) = run(Settings::default(), &d, |k, s| {
        if k % 2 == 1 {
            s.pose = None;
        }
    });
    let (err, mhe) = run(Settings::default(), &d, |k, s| {
        s.heading = Some(wrap(d.xs[k][2] + offset(k)));
        if k % 2 == 1 {
            s.pose = None;
        }
    });
    let phi_err = wrap(mhe.estimate().x[2] - d.xs[N_SIM][2]).abs();
    assert!(phi_err < 0.02, "heading error {phi_err}");
    assert!(
        rms(&err) < 1.1 * rms(&without),
        "position rms {} vs {} without the IMU heading",
        rms(&err),
        rms(&without)
    );
    assert_eq!(mhe.stats().rejected, 0, "{:?}", mhe.stats());
}

/// The increments are what the IMU heading knows: with them the estimate rides
/// out a dropout better than with the gyroscope's samples alone.
#[test]
fn imu_heading_increments_narrow_the_drift_of_a_dropout() {
    let d = data();
    let drop = |k: usize| (60..120).contains(&k);
    let (without, _) = run(Settings::default(), &d, |k, s| {
        if drop(k) {
            s.pose = None;
        }
    });
    let (with, mhe) = run(Settings::default(), &d, |k, s| {
        // Offset from the map heading, and exact increments.
        s.heading = Some(wrap(d.xs[k][2] + 1.0));
        if drop(k) {
            s.pose = None;
        }
    });
    let gap = |e: &[f64]| rms(&e[60 - 20..120 - 20]);
    assert!(
        gap(&with) < gap(&without),
        "{} vs {}",
        gap(&with),
        gap(&without)
    );
    assert_eq!(mhe.stats().rejected, 0);
}

/// A robot carried 1.5 m away (or an estimate gone wrong): the poses are gated
/// out, and after `relocalise_after` seconds the window restarts from them.
#[test]
fn an_estimate_the_poses_contradict_for_long_is_relocalised() {
    let d = data();
    let kidnap = |k: usize| if k >= 100 { 1.5 } else { 0.0 };
    let (_, mhe) = run(Settings::default(), &d, |k, s| {
        if let Some(p) = &mut s.pose {
            p.pose[0] += kidnap(k);
        }
    });
    let stats = mhe.stats();
    assert_eq!(stats.relocalisations, 1, "{stats:?}");
    // Rejected for one second (20 samples), then believed again.
    assert!((19..=22).contains(&stats.rejected_poses), "{stats:?}");
    let x = mhe.estimate().x;
    let truth = d.xs[N_SIM];
    let e = (x[0] - truth[0] - 1.5).hypot(x[1] - truth[1]);
    assert!(e < 0.03, "{e}");
}

#[test]
fn nothing_is_estimated_before_the_first_pose() {
    let mut mhe = Mhe::new(peer::model(), Settings::default()).unwrap();
    let e = mhe.update(
        0.0,
        &[0.0; 4],
        &Sample {
            gyro: Some(0.1),
            ..Sample::default()
        },
    );
    assert!(!e.localised);
    assert_eq!(mhe.stats().waiting, 1);
    let bad = Settings {
        p_prior: [0.3, 0.05, 0.5],
        ..Settings::default()
    };
    assert!(matches!(
        Mhe::new(peer::model(), bad),
        Err(MheError::Settings(_))
    ));
}

/// Run the MHE over the data set with the encoders' readings scaled by
/// `scale` from sample 100 on (as on a ground that suddenly slips more), the
/// poses exact (the truth) if `exact_poses`; `read` what is wanted of the
/// estimator after each sample.
fn with_encoders_scaled<T>(
    d: &MheData,
    scale: f64,
    exact_poses: bool,
    read: impl Fn(&ReducedMhe) -> T,
) -> Vec<T> {
    let mut mhe = Mhe::new(peer::model(), Settings::default()).unwrap();
    let mut out = Vec::new();
    for k in 0..=N_SIM {
        let mut s = d.sample(k);
        if exact_poses {
            let x = d.xs[k];
            s.pose = s.pose.map(|p| TimedPose {
                pose: [x[0], x[1], x[2]],
                ..p
            });
        }
        if k >= 100 {
            s.encoders = s.encoders.map(|e| e.map(|v| v * scale));
        }
        let u = if k > 0 { d.us[k - 1] } else { [0.0; 4] };
        mhe.update(k as f64 * DT, &u, &s);
        out.push(read(&mhe));
    }
    out
}

#[test]
fn the_encoder_innovation_shows_a_change_the_noise_does_not_explain() {
    // The peer's data, whose encoders the model explains up to their noise,
    // and the same data with the wheels turning 20 % faster from sample 100 on
    // (as on a ground that suddenly slips more): the innovation is the residual
    // before the fit, so it shows the change at once.
    let d = data();
    let innovations = |scale: f64| with_encoders_scaled(&d, scale, false, Mhe::innovation);
    let clean = innovations(1.0);
    let changed = innovations(1.2);
    assert!(clean[0].is_none(), "no innovation before a second sample");
    let mean = |v: &[Option<Innovation>]| {
        v.iter().map(|i| i.unwrap().mean_square).sum::<f64>() / v.len() as f64
    };
    let (before, after) = (mean(&clean[40..]), mean(&changed[100..105]));
    assert!(
        clean[1..]
            .iter()
            .all(|i| i.is_some_and(|i| i.readings == 4 && i.spinning == 0))
    );
    // Measured 1.17: the encoders' noise as the settings say (a mean square
    // near 1 is what normalised residuals of a right model have).
    assert!(
        (0.5..2.0).contains(&before),
        "the model explains the clean data: {before}"
    );
    assert!(after > 10.0 * before, "{after} vs {before}");
    // The sign says which way: the wheels turn faster than predicted.
    assert!(changed[100].unwrap().mean < -3.0, "{:?}", changed[100]);
    assert_eq!(clean[..100], changed[..100]);
}

/// The poses exact (the truth), so that what is left is the fit's own.
#[test]
fn the_pose_residual_shows_a_fit_the_model_keeps_from_the_poses() {
    // The peer's data with exact poses, and the same with the wheels turning
    // 30 % faster from sample 100 on (as on a ground that suddenly slips
    // more): the encoders and the model then carry the fit ahead of the
    // poses, which stay where the robot is.
    let d = data();
    let residuals = |scale: f64| with_encoders_scaled(&d, scale, true, |m| m.pose_residual(0.5));
    let clean = residuals(1.0);
    let changed = residuals(1.3);
    let max = |v: &[Option<f64>]| v.iter().map(|r| r.unwrap()).fold(0.0, f64::max);
    // Measured: at most 0.96 mm on the clean data, 83 mm within a second
    // of the change (0.5 mm just before it).
    let (before, after) = (max(&clean[40..]), max(&changed[100..120]));
    assert!(before < 0.002, "the fit keeps to exact poses: {before}");
    assert!(after > 0.05, "a model the encoders contradict: {after}");
    assert_eq!(clean[..100], changed[..100]);
    assert!(clean[0].is_some(), "a pose from the first sample");
    let mhe = Mhe::new(peer::model(), Settings::default()).unwrap();
    assert_eq!(mhe.pose_residual(0.5), None, "no pose yet");
}
