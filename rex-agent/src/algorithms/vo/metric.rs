//! The KITTI odometry metric (devkit `evaluate_odometry.cpp`, notes `vo.md` §3.2):
//! for every first frame `f = 0, 10, 20, …` and segment length `L`, the last frame
//! `l` is the first one whose ground-truth path from `f` exceeds `L`; the error of
//! the estimated relative motion `inv(inv(E_f) E_l) · inv(G_f) G_l` gives
//! `t = |translation| / L` and `r = angle / L`; the figures are the means over all
//! segments (`t` in percent, `r` in degrees per metre).
//!
//! Segment lengths are KITTI's 100, 200, …, 800 m for paths of at least 900 m;
//! shorter paths use `k · s`, `k = 1..8`, `s = max(1, round(path / 9))` metres, as
//! the peer's `kitti_eval.py` does (so the two can be compared on the simulator's
//! sequences). Lengths that no segment reaches are dropped.

use crate::math::geometry::{Pose34, compose, invert};

/// KITTI's segment lengths \[m\].
pub const KITTI_LENGTHS: [f64; 8] = [100.0, 200.0, 300.0, 400.0, 500.0, 600.0, 700.0, 800.0];

/// The drift of an estimated trajectory.
#[derive(Clone, Debug, PartialEq)]
pub struct Drift {
    /// Mean translational error \[%\].
    pub t_err_pct: f64,
    /// Mean rotational error \[deg/m\].
    pub r_err_deg_per_m: f64,
    /// Segments evaluated.
    pub segments: usize,
    /// The segment lengths that some segment reached \[m\].
    pub lengths: Vec<f64>,
    /// Length of the ground-truth path \[m\].
    pub path_length: f64,
}

/// Why the metric could not be computed.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum MetricError {
    /// Different numbers of poses.
    #[error("the ground truth has {gt} poses, the estimate {est}")]
    Length {
        /// Ground-truth poses.
        gt: usize,
        /// Estimated poses.
        est: usize,
    },
    /// A segment length that is not a length.
    #[error("segment length {0} m: lengths are finite, at least {MIN_LENGTH} m")]
    BadLength(f64),
    /// No segment fits.
    #[error("no segment of the lengths {lengths:?} m fits in a {path:.1} m path")]
    NoSegment {
        /// Lengths tried.
        lengths: Vec<f64>,
        /// Path length \[m\].
        path: f64,
    },
}

/// The shortest segment length \[m\] (shorter ones measure noise, and divide by
/// almost nothing).
pub const MIN_LENGTH: f64 = 0.1;

/// The segment lengths for a path of `path` metres.
pub fn auto_lengths(path: f64) -> Vec<f64> {
    if path >= 900.0 {
        return KITTI_LENGTHS.to_vec();
    }
    let s = (path / 9.0).round_ties_even().max(1.0);
    (1..=8).map(|k| f64::from(k) * s).collect()
}

fn distances(poses: &[Pose34]) -> Vec<f64> {
    let mut d = Vec::with_capacity(poses.len());
    let mut acc = 0.0;
    for (i, p) in poses.iter().enumerate() {
        if i > 0 {
            let q = &poses[i - 1];
            acc += ((p[0][3] - q[0][3]).powi(2)
                + (p[1][3] - q[1][3]).powi(2)
                + (p[2][3] - q[2][3]).powi(2))
            .sqrt();
        }
        d.push(acc);
    }
    d
}

/// Evaluate `est` against `gt` with segment starts every `step` frames; `lengths`
/// `None` chooses them from the path length.
pub fn evaluate(
    gt: &[Pose34],
    est: &[Pose34],
    lengths: Option<&[f64]>,
    step: usize,
) -> Result<Drift, MetricError> {
    if gt.len() != est.len() {
        return Err(MetricError::Length {
            gt: gt.len(),
            est: est.len(),
        });
    }
    let dist = distances(gt);
    let path = dist.last().copied().unwrap_or(0.0);
    let lengths: Vec<f64> = lengths.map_or_else(|| auto_lengths(path), <[f64]>::to_vec);
    if let Some(&bad) = lengths
        .iter()
        .find(|l| !(l.is_finite() && **l >= MIN_LENGTH))
    {
        return Err(MetricError::BadLength(bad));
    }
    let (mut t_sum, mut r_sum, mut n) = (0.0, 0.0, 0usize);
    let mut reached: Vec<f64> = Vec::new();
    for f in (0..gt.len()).step_by(step.max(1)) {
        for &len in &lengths {
            let Some(l) = (f..dist.len()).find(|&i| dist[i] > dist[f] + len) else {
                continue;
            };
            let dg = compose(&invert(&gt[f]), &gt[l]);
            let de = compose(&invert(&est[f]), &est[l]);
            let e = compose(&invert(&de), &dg);
            let c = 0.5 * (e[0][0] + e[1][1] + e[2][2] - 1.0);
            let r = c.clamp(-1.0, 1.0).acos();
            let t = (e[0][3].powi(2) + e[1][3].powi(2) + e[2][3].powi(2)).sqrt();
            r_sum += r / len;
            t_sum += t / len;
            n += 1;
            if !reached.contains(&len) {
                reached.push(len);
            }
        }
    }
    if n == 0 {
        return Err(MetricError::NoSegment { lengths, path });
    }
    reached.sort_by(f64::total_cmp);
    Ok(Drift {
        t_err_pct: 100.0 * t_sum / n as f64,
        r_err_deg_per_m: (r_sum / n as f64).to_degrees(),
        segments: n,
        lengths: reached,
        path_length: path,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A camera moving forward (z) `step` metres per frame and turning about the
    /// vertical axis (y) by `yaw` per frame.
    fn path(frames: usize, step: f64, yaw: f64) -> Vec<Pose34> {
        let mut pose = [
            [1.0, 0.0, 0.0, 0.0],
            [0.0, 1.0, 0.0, 0.0],
            [0.0, 0.0, 1.0, 0.0],
        ];
        let (s, c) = yaw.sin_cos();
        let motion = [[c, 0.0, s, 0.0], [0.0, 1.0, 0.0, 0.0], [-s, 0.0, c, step]];
        (0..frames)
            .map(|i| {
                if i > 0 {
                    pose = compose(&pose, &motion);
                }
                pose
            })
            .collect()
    }

    #[test]
    fn a_perfect_estimate_has_no_drift() {
        let gt = path(200, 0.5, 0.01);
        let d = evaluate(&gt, &gt, None, 10).unwrap();
        // acos near 1 turns round-off of 1e-16 into 1e-8 (as in the devkit).
        assert!(
            d.t_err_pct.abs() < 1e-9 && d.r_err_deg_per_m.abs() < 1e-6,
            "{d:?}"
        );
        assert!(d.segments > 0);
        // 99.5 m of path: segments of 11, 22, ..., 88 m.
        assert_eq!(d.lengths, [11.0, 22.0, 33.0, 44.0, 55.0, 66.0, 77.0, 88.0]);
    }

    #[test]
    fn a_pure_scale_error_is_the_translational_error() {
        // Straight path, 1 m per frame, the estimate 10 % too long. A 10 m segment
        // ends at the first frame beyond 10 m, 11 m on: the error is 1.1 m, 11 %.
        let gt = path(101, 1.0, 0.0);
        let est = path(101, 1.1, 0.0);
        let d = evaluate(&gt, &est, Some(&[10.0]), 10).unwrap();
        assert!((d.t_err_pct - 11.0).abs() < 1e-9, "{d:?}");
        assert!(d.r_err_deg_per_m.abs() < 1e-6);
        assert_eq!(d.segments, 9);
    }

    #[test]
    fn a_constant_yaw_drift_is_the_rotational_error() {
        // 0.01 rad of yaw per 1 m frame that the ground truth does not have: over a
        // segment of L metres (L + 1 frames in this discretisation, since the last
        // frame is the first beyond L), the angle is 0.01 (L + 1), so r = 0.01 (L+1)/L.
        let gt = path(101, 1.0, 0.0);
        let est = path(101, 1.0, 0.01);
        let d = evaluate(&gt, &est, Some(&[10.0]), 10).unwrap();
        let expected = (0.01_f64 * 11.0 / 10.0).to_degrees();
        assert!(
            (d.r_err_deg_per_m - expected).abs() < 1e-9,
            "{} vs {expected}",
            d.r_err_deg_per_m
        );
        assert!(d.t_err_pct > 0.0);
    }

    #[test]
    fn mismatched_or_short_sequences_are_errors() {
        let gt = path(10, 0.1, 0.0);
        assert_eq!(
            evaluate(&gt, &gt[..5], None, 10),
            Err(MetricError::Length { gt: 10, est: 5 })
        );
        assert!(matches!(
            evaluate(&gt, &gt, Some(&[100.0]), 10),
            Err(MetricError::NoSegment { .. })
        ));
        // Lengths that are not lengths: before, `--lengths 0` gave infinite errors.
        for bad in [0.0, -1.0, 1e-9, f64::NAN, f64::INFINITY] {
            assert!(
                matches!(
                    evaluate(&gt, &gt, Some(&[0.5, bad]), 10),
                    Err(MetricError::BadLength(_))
                ),
                "{bad}"
            );
        }
    }
}
