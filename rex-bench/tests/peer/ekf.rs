//! The baseline EKF (`algorithms::estimation`, which e11 runs) on the peer's MHE
//! data set (were unit tests of `a1::e11::estimator`): an IMU heading that drifts, poses that contradict the
//! estimate for long.

use rex_agent::a1::e11::Measurements;
use rex_agent::algorithms::estimation::{Ekf, Estimator};
use rex_agent::math::geometry::wrap;
use rex_agent::model::SlipParams;
use rex_agent::payload::{Encoders, Imu, MapPose, Pose2};
use rex_bench::peer::{self, DT, MheData, N_SIM};

/// Indices of [`Ekf::state`], `(X, Y, φ, v, ω, b)`: the position, the heading,
/// and `b`, the IMU heading's offset from the map heading.
const X: usize = 0;
const Y: usize = 1;
const PHI: usize = 2;
const B: usize = 5;

/// Run the EKF over the peer's data set (poses, gyro, encoders, and an IMU
/// heading `φ + offset(k)`); `edit` may change each sample. Returns the
/// position errors from 1 s on and the filter.
fn run_peer(
    d: &MheData,
    offset: impl Fn(usize) -> f64,
    edit: impl Fn(usize, &mut Measurements),
) -> (Vec<f64>, Ekf) {
    let mut ekf = Ekf::new(peer::model().params, SlipParams::NOMINAL);
    let mut err = Vec::new();
    for k in 0..=N_SIM {
        let y = d.ys[k];
        let t = k as f64 * DT;
        let mut m = Measurements {
            encoders: Some(Encoders {
                theta: [0.0; 4],
                rate: [y[4], y[5], y[6], y[7]],
                time: t,
            }),
            imu: Some(Imu {
                yaw: wrap(d.xs[k][2] + offset(k)),
                yaw_rate: y[3],
                accel: [0.0; 2],
            }),
            map_pose: Some(MapPose {
                pose: Pose2 {
                    x: y[0],
                    y: y[1],
                    phi: wrap(y[2]),
                },
                time: t,
            }),
            imu_aligned: true,
            now: t,
            ..Measurements::default()
        };
        edit(k, &mut m);
        let u = if k > 0 { d.us[k - 1] } else { [0.0; 4] };
        let e = ekf.update(DT, &u, &m);
        if k >= 20 {
            err.push((e.x[0] - d.xs[k][0]).hypot(e.x[1] - d.xs[k][1]));
        }
    }
    (err, ekf)
}

fn max(e: &[f64]) -> f64 {
    e.iter().fold(0.0, |m, v| m.max(*v))
}

/// The IMU heading drifts away from the map's (0.5 rad, growing by 0.02 rad/s):
/// the filter follows the offset and the map. Taken as the map heading (as
/// before the offset state), it pulled the estimate until the poses were gated
/// out for good.
#[test]
fn a_drifting_imu_heading_does_not_pull_the_estimate() {
    let d = peer::mhe_data(1).unwrap();
    // The peer's plant slips unlike the nominal model the EKF predicts with:
    // compare with the same filter not reading the IMU heading at all.
    let (without, _) = run_peer(&d, |_| 0.0, |_, m| m.imu_aligned = false);
    let (err, ekf) = run_peer(&d, |k| 0.5 + 0.02 * k as f64 * DT, |_, _| {});
    let x = ekf.state();
    assert!(
        max(&err) < 1.2 * max(&without),
        "position error {} vs {} without the IMU heading",
        max(&err),
        max(&without)
    );
    assert!(wrap(x[PHI] - d.xs[N_SIM][2]).abs() < 0.03, "{x:?}");
    let offset = 0.5 + 0.02 * N_SIM as f64 * DT;
    assert!(
        wrap(x[B] - offset).abs() < 0.03,
        "offset {} vs {offset}",
        x[B]
    );
    assert_eq!(ekf.health().relocalisations, 0);
}

/// Poses that contradict the estimate for longer than `relocalise_after` (a
/// robot carried away, or an estimate gone wrong) are believed again.
#[test]
fn an_estimate_the_poses_contradict_for_long_is_relocalised() {
    let d = peer::mhe_data(1).unwrap();
    let (_, ekf) = run_peer(
        &d,
        |_| 0.3,
        |k, m| {
            if k >= 100
                && let Some(p) = &mut m.map_pose
            {
                p.pose.x += 1.5;
            }
        },
    );
    let h = ekf.health();
    assert_eq!(h.relocalisations, 1, "{h:?}");
    assert!((20..=23).contains(&h.rejected_poses), "{h:?}");
    // As good as the filter that was never contradicted, within a centimetre.
    let (plain, _) = run_peer(&d, |_| 0.3, |_, _| {});
    let x = ekf.state();
    let e = (x[X] - d.xs[N_SIM][0] - 1.5).hypot(x[Y] - d.xs[N_SIM][1]);
    let last = plain.last().copied().unwrap_or(0.0);
    assert!(e < last + 0.01, "{e} vs {last}");
}
