//! The motion between two stereo pairs from matched features (notes `vo.md` §1.8):
//! points triangulated in the previous pair, Gauss–Newton on the reprojection error
//! in the current pair over `θ = (r_x, r_y, r_z, t_x, t_y, t_z)`
//! (`p_curr = R_x R_y R_z p_prev + t`), inside RANSAC on 3-point samples.

use crate::algorithms::rng::Rng;

/// Rectified stereo intrinsics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration {
    /// Focal length [px].
    pub f: f64,
    /// Principal point, column [px].
    pub cu: f64,
    /// Principal point, row [px].
    pub cv: f64,
    /// Baseline [m].
    pub baseline: f64,
}

/// One match: the point in the previous frame and its observations now.
#[derive(Clone, Copy, Debug)]
pub struct Observation {
    /// Triangulated in the previous left camera frame [m].
    pub p: [f64; 3],
    /// `(u_left, v_left, u_right, v_right)` in the current pair [px].
    pub obs: [f64; 4],
    /// Weight of its residuals.
    pub w: f64,
}

/// Triangulate matches `[prev_left, prev_right, curr_right, curr_left]` (pixel
/// positions); the weight favours the centre column when `reweighting`.
pub fn observations(
    c: &Calibration,
    matches: &[[(f64, f64); 4]],
    reweighting: bool,
) -> Vec<Observation> {
    matches
        .iter()
        .map(|m| {
            let (pl, pr, cr, cl) = (m[0], m[1], m[2], m[3]);
            let d = (pl.0 - pr.0).max(1e-4);
            let z = c.f * c.baseline / d;
            let p = [(pl.0 - c.cu) * z / c.f, (pl.1 - c.cv) * z / c.f, z];
            let w = if reweighting {
                1.0 / ((cl.0 - c.cu).abs() / c.cu.abs().max(1.0) + 0.05)
            } else {
                1.0
            };
            Observation {
                p,
                obs: [cl.0, cl.1, cr.0, cr.1],
                w,
            }
        })
        .collect()
}

fn rotation(t: &[f64; 6]) -> ([[f64; 3]; 3], [[[f64; 3]; 3]; 3]) {
    let (sx, cx) = t[0].sin_cos();
    let (sy, cy) = t[1].sin_cos();
    let (sz, cz) = t[2].sin_cos();
    let rx = [[1.0, 0.0, 0.0], [0.0, cx, -sx], [0.0, sx, cx]];
    let ry = [[cy, 0.0, sy], [0.0, 1.0, 0.0], [-sy, 0.0, cy]];
    let rz = [[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]];
    let drx = [[0.0, 0.0, 0.0], [0.0, -sx, -cx], [0.0, cx, -sx]];
    let dry = [[-sy, 0.0, cy], [0.0, 0.0, 0.0], [-cy, 0.0, -sy]];
    let drz = [[-sz, -cz, 0.0], [cz, -sz, 0.0], [0.0, 0.0, 0.0]];
    let mul = |a: &[[f64; 3]; 3], b: &[[f64; 3]; 3]| -> [[f64; 3]; 3] {
        std::array::from_fn(|i| std::array::from_fn(|j| (0..3).map(|k| a[i][k] * b[k][j]).sum()))
    };
    (
        mul(&mul(&rx, &ry), &rz),
        [
            mul(&mul(&drx, &ry), &rz),
            mul(&mul(&rx, &dry), &rz),
            mul(&mul(&rx, &ry), &drz),
        ],
    )
}

fn apply(r: &[[f64; 3]; 3], p: &[f64; 3]) -> [f64; 3] {
    std::array::from_fn(|i| r[i][0] * p[0] + r[i][1] * p[1] + r[i][2] * p[2])
}

/// Predicted `(u_l, v_l, u_r, v_r)` of `p` moved by `θ`, or `None` behind the camera.
fn project(c: &Calibration, r: &[[f64; 3]; 3], t: &[f64; 6], p: &[f64; 3]) -> Option<[f64; 4]> {
    let q = apply(r, p);
    let (x, y, z) = (q[0] + t[3], q[1] + t[4], q[2] + t[5]);
    if z <= 1e-6 {
        return None;
    }
    Some([
        c.f * x / z + c.cu,
        c.f * y / z + c.cv,
        c.f * (x - c.baseline) / z + c.cu,
        c.f * y / z + c.cv,
    ])
}

/// Squared reprojection error (unweighted) of one observation, or infinity.
fn error2(c: &Calibration, r: &[[f64; 3]; 3], t: &[f64; 6], o: &Observation) -> f64 {
    project(c, r, t, &o.p).map_or(f64::INFINITY, |pr| {
        (0..4).map(|k| (o.obs[k] - pr[k]).powi(2)).sum()
    })
}

/// Gauss–Newton on the observations `active`, from `θ`: `Some(θ)` when every step
/// component falls below `eps` within `max_iter` iterations.
pub fn gauss_newton(
    c: &Calibration,
    obs: &[Observation],
    active: &[usize],
    theta: [f64; 6],
    max_iter: usize,
    eps: f64,
) -> Option<[f64; 6]> {
    if active.len() < 3 {
        return None;
    }
    let mut t = theta;
    for _ in 0..max_iter {
        let (r, dr) = rotation(&t);
        let mut a = [[0.0; 6]; 6];
        let mut g = [0.0; 6];
        for &i in active {
            let o = &obs[i];
            let q = apply(&r, &o.p);
            let (x, y, z) = (q[0] + t[3], q[1] + t[4], q[2] + t[5]);
            if z <= 1e-6 {
                continue;
            }
            // ∂(x, y, z)/∂θ: rotations through dR, translations the identity.
            let mut dp = [[0.0; 6]; 3];
            for k in 0..3 {
                let d = apply(&dr[k], &o.p);
                for row in 0..3 {
                    dp[row][k] = d[row];
                }
                dp[k][3 + k] = 1.0;
            }
            let (f, iz) = (c.f, 1.0 / z);
            let pred = [
                f * x * iz + c.cu,
                f * y * iz + c.cv,
                f * (x - c.baseline) * iz + c.cu,
                f * y * iz + c.cv,
            ];
            let rows: [[f64; 3]; 4] = [
                [f * iz, 0.0, -f * x * iz * iz],
                [0.0, f * iz, -f * y * iz * iz],
                [f * iz, 0.0, -f * (x - c.baseline) * iz * iz],
                [0.0, f * iz, -f * y * iz * iz],
            ];
            for k in 0..4 {
                let jrow: [f64; 6] = std::array::from_fn(|m| {
                    o.w * (rows[k][0] * dp[0][m] + rows[k][1] * dp[1][m] + rows[k][2] * dp[2][m])
                });
                let res = o.w * (o.obs[k] - pred[k]);
                for m in 0..6 {
                    g[m] += jrow[m] * res;
                    for n in m..6 {
                        a[m][n] += jrow[m] * jrow[n];
                    }
                }
            }
        }
        for m in 0..6 {
            for n in 0..m {
                a[m][n] = a[n][m];
            }
        }
        let delta = solve6(a, g)?;
        for m in 0..6 {
            t[m] += delta[m];
        }
        if !t.iter().all(|v| v.is_finite()) {
            return None;
        }
        if delta.iter().all(|d| d.abs() < eps) {
            return Some(t);
        }
    }
    None
}

/// Solve `a x = b` (6 × 6) by Gaussian elimination with partial pivoting.
fn solve6(mut a: [[f64; 6]; 6], mut b: [f64; 6]) -> Option<[f64; 6]> {
    for col in 0..6 {
        let p = (col..6).max_by(|&i, &j| a[i][col].abs().total_cmp(&a[j][col].abs()))?;
        // Also refuses a NaN pivot.
        if a[p][col].abs().is_nan() || a[p][col].abs() <= 1e-12 {
            return None;
        }
        a.swap(col, p);
        b.swap(col, p);
        for row in col + 1..6 {
            let f = a[row][col] / a[col][col];
            for k in col..6 {
                a[row][k] -= f * a[col][k];
            }
            b[row] -= f * b[col];
        }
    }
    let mut x = [0.0; 6];
    for row in (0..6).rev() {
        let s: f64 = (row + 1..6).map(|k| a[row][k] * x[k]).sum();
        x[row] = (b[row] - s) / a[row][row];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

/// Why no motion could be estimated from the matches.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum EgomotionError {
    /// Fewer matches than the estimation needs.
    #[error("{found} matches, at least {needed} needed")]
    TooFewMatches {
        /// Matches found.
        found: usize,
        /// Matches needed.
        needed: usize,
    },
    /// No RANSAC hypothesis had enough support.
    #[error("RANSAC found {inliers} inliers among {matches} matches, at least {needed} needed")]
    TooFewInliers {
        /// Best support.
        inliers: usize,
        /// Matches.
        matches: usize,
        /// Needed.
        needed: usize,
    },
    /// The final fit did not converge.
    #[error("the final Gauss-Newton fit on {inliers} inliers did not converge")]
    NoConvergence {
        /// Inliers fitted.
        inliers: usize,
    },
}

/// The estimated motion.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    /// `θ = (r_x, r_y, r_z, t_x, t_y, t_z)`.
    pub theta: [f64; 6],
    /// Inliers.
    pub inliers: usize,
}

/// RANSAC and the final fit.
pub fn estimate(
    c: &Calibration,
    obs: &[Observation],
    iterations: usize,
    threshold: f64,
    min_inliers: usize,
    rng: &mut Rng,
) -> Result<Estimate, EgomotionError> {
    let n = obs.len();
    let needed = min_inliers.max(6);
    if n < needed {
        return Err(EgomotionError::TooFewMatches { found: n, needed });
    }
    let thr2 = threshold * threshold;
    let mut best: (Vec<usize>, [f64; 6]) = (Vec::new(), [0.0; 6]);
    let mut inliers = Vec::with_capacity(n);
    for _ in 0..iterations {
        // Three distinct matches.
        let a = (rng.next_u64() % n as u64) as usize;
        let mut b = (rng.next_u64() % n as u64) as usize;
        while b == a {
            b = (rng.next_u64() % n as u64) as usize;
        }
        let mut d = (rng.next_u64() % n as u64) as usize;
        while d == a || d == b {
            d = (rng.next_u64() % n as u64) as usize;
        }
        let Some(theta) = gauss_newton(c, obs, &[a, b, d], [0.0; 6], 20, 1e-6) else {
            continue;
        };
        let (r, _) = rotation(&theta);
        inliers.clear();
        inliers.extend((0..n).filter(|&i| error2(c, &r, &theta, &obs[i]) < thr2));
        if inliers.len() > best.0.len() {
            best = (inliers.clone(), theta);
        }
    }
    if best.0.len() < needed {
        return Err(EgomotionError::TooFewInliers {
            inliers: best.0.len(),
            matches: n,
            needed,
        });
    }
    let theta =
        gauss_newton(c, obs, &best.0, best.1, 100, 1e-8).ok_or(EgomotionError::NoConvergence {
            inliers: best.0.len(),
        })?;
    Ok(Estimate {
        theta,
        inliers: best.0.len(),
    })
}

/// The 4 × 4 transform `[R t; 0 1]` of `θ`.
pub fn transform(theta: &[f64; 6]) -> [[f64; 4]; 4] {
    let (r, _) = rotation(theta);
    [
        [r[0][0], r[0][1], r[0][2], theta[3]],
        [r[1][0], r[1][1], r[1][2], theta[4]],
        [r[2][0], r[2][1], r[2][2], theta[5]],
        [0.0, 0.0, 0.0, 1.0],
    ]
}

#[cfg(test)]
mod tests {
    use super::*;

    fn calib() -> Calibration {
        Calibration {
            f: 400.0,
            cu: 319.5,
            cv: 239.5,
            baseline: 0.3,
        }
    }

    /// Points in front of the camera, moved by `truth`, observed exactly; some
    /// observations replaced by garbage.
    fn scene(truth: [f64; 6], outliers: usize) -> Vec<Observation> {
        let c = calib();
        let (r, _) = rotation(&truth);
        let mut rng = Rng::new(5);
        (0..120)
            .map(|i| {
                let p = [rng.gauss(2.0), rng.gauss(1.0), 3.0 + 10.0 * rng.uniform()];
                let obs = if i < outliers {
                    [
                        rng.uniform() * 640.0,
                        rng.uniform() * 480.0,
                        rng.uniform() * 640.0,
                        rng.uniform() * 480.0,
                    ]
                } else {
                    project(&c, &r, &truth, &p).unwrap_or([0.0; 4])
                };
                Observation { p, obs, w: 1.0 }
            })
            .collect()
    }

    #[test]
    fn recovers_a_motion_despite_outliers() {
        let truth = [0.01, -0.08, 0.005, 0.05, -0.01, 0.4];
        let obs = scene(truth, 40);
        let e = estimate(&calib(), &obs, 200, 2.0, 6, &mut Rng::new(0)).unwrap();
        assert_eq!(e.inliers, 80);
        for k in 0..6 {
            assert!(
                (e.theta[k] - truth[k]).abs() < 1e-6,
                "{:?} vs {truth:?}",
                e.theta
            );
        }
    }

    #[test]
    fn too_little_support_is_an_error_not_a_guess() {
        let obs = scene([0.0, 0.1, 0.0, 0.0, 0.0, 0.3], 118);
        let err = estimate(&calib(), &obs, 200, 2.0, 6, &mut Rng::new(0)).unwrap_err();
        assert!(matches!(err, EgomotionError::TooFewInliers { .. }), "{err}");
        let err = estimate(&calib(), &obs[..4], 200, 2.0, 6, &mut Rng::new(0)).unwrap_err();
        assert_eq!(
            err,
            EgomotionError::TooFewMatches {
                found: 4,
                needed: 6
            }
        );
    }

    #[test]
    fn the_jacobian_is_the_derivative_of_the_projection() {
        // One Gauss–Newton step from the truth stays at the truth; from a nearby
        // start it converges in a few steps (quadratically).
        let truth = [0.02, 0.05, -0.01, 0.1, 0.02, 0.3];
        let obs = scene(truth, 0);
        let all: Vec<usize> = (0..obs.len()).collect();
        let t = gauss_newton(&calib(), &obs, &all, [0.0; 6], 8, 1e-10).unwrap();
        for k in 0..6 {
            assert!((t[k] - truth[k]).abs() < 1e-9);
        }
    }
}
