//! The motion between two stereo pairs from matched features (notes `vo.md` §1.8):
//! points triangulated in the previous pair, Gauss–Newton on the reprojection error
//! in the current pair over `θ = (r_x, r_y, r_z, t_x, t_y, t_z)`
//! (`p_curr = R_x R_y R_z p_prev + t`), inside RANSAC on 3-point samples. The
//! normal equations of each step are solved by nalgebra's Cholesky
//! (`linsolve::solve_symmetric`).

use nalgebra::{
    IsometryMatrix3, Matrix3, Matrix3x6, Matrix4x3, Matrix6, Rotation3, Translation3, Vector3,
    Vector4, Vector6,
};

use crate::math::linsolve;
use crate::math::rng::Rng;

/// Rectified stereo intrinsics.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration {
    /// Focal length \[px\].
    pub f: f64,
    /// Principal point, column \[px\].
    pub cu: f64,
    /// Principal point, row \[px\].
    pub cv: f64,
    /// Baseline \[m\].
    pub baseline: f64,
}

/// One match: the point in the previous frame and its observations now.
#[derive(Clone, Copy, Debug)]
pub struct Observation {
    /// Triangulated in the previous left camera frame \[m\].
    pub p: [f64; 3],
    /// `(u_left, v_left, u_right, v_right)` in the current pair \[px\].
    pub obs: [f64; 4],
    /// Weight of its residuals.
    pub w: f64,
}

/// Triangulate matches `[prev_left, prev_right, curr_right, curr_left]` (pixel
/// positions) into `out` (replaced; no allocation once it has grown); the weight
/// favours the centre column when `reweighting`.
pub fn observations_into(
    c: &Calibration,
    matches: &[[(f64, f64); 4]],
    reweighting: bool,
    out: &mut Vec<Observation>,
) {
    out.clear();
    out.extend(matches.iter().map(|m| {
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
    }));
}

/// `R = R_x R_y R_z` of `θ` and its derivatives `∂R/∂r_x, ∂R/∂r_y, ∂R/∂r_z`
/// (`d R_a(α)/dα = R_a(α) [a]×` for a rotation about the axis `a`).
fn rotation(t: &[f64; 6]) -> (Matrix3<f64>, [Matrix3<f64>; 3]) {
    let rx = Rotation3::from_axis_angle(&Vector3::x_axis(), t[0]).into_inner();
    let ry = Rotation3::from_axis_angle(&Vector3::y_axis(), t[1]).into_inner();
    let rz = Rotation3::from_axis_angle(&Vector3::z_axis(), t[2]).into_inner();
    let drx = rx * Vector3::x().cross_matrix();
    let dry = ry * Vector3::y().cross_matrix();
    let drz = rz * Vector3::z().cross_matrix();
    (rx * ry * rz, [drx * ry * rz, rx * dry * rz, rx * ry * drz])
}

/// The translation of `θ`.
fn translation(t: &[f64; 6]) -> Vector3<f64> {
    Vector3::new(t[3], t[4], t[5])
}

/// Predicted `(u_l, v_l, u_r, v_r)` of `p` moved by `θ` (its rotation `r`), or
/// `None` behind the camera.
fn project(c: &Calibration, r: &Matrix3<f64>, t: &[f64; 6], p: &[f64; 3]) -> Option<[f64; 4]> {
    let q = r * Vector3::from(*p) + translation(t);
    let (x, y, z) = (q.x, q.y, q.z);
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
fn error2(c: &Calibration, r: &Matrix3<f64>, t: &[f64; 6], o: &Observation) -> f64 {
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
        let shift = translation(&t);
        // The normal equations `JᵀJ δ = Jᵀ res` (the lower triangle of JᵀJ).
        let mut jtj = Matrix6::zeros();
        let mut jtr = Vector6::zeros();
        for &i in active {
            let o = &obs[i];
            let p = Vector3::from(o.p);
            let q = r * p + shift;
            let (x, y, z) = (q.x, q.y, q.z);
            if z <= 1e-6 {
                continue;
            }
            // ∂q/∂θ: rotations through dR, translations the identity.
            let dq = Matrix3x6::from_columns(&[
                dr[0] * p,
                dr[1] * p,
                dr[2] * p,
                Vector3::x(),
                Vector3::y(),
                Vector3::z(),
            ]);
            let (f, iz) = (c.f, 1.0 / z);
            let pred = Vector4::new(
                f * x * iz + c.cu,
                f * y * iz + c.cv,
                f * (x - c.baseline) * iz + c.cu,
                f * y * iz + c.cv,
            );
            // ∂(u_l, v_l, u_r, v_r)/∂q.
            #[rustfmt::skip]
            let dpred = Matrix4x3::new(
                f * iz, 0.0, -f * x * iz * iz,
                0.0, f * iz, -f * y * iz * iz,
                f * iz, 0.0, -f * (x - c.baseline) * iz * iz,
                0.0, f * iz, -f * y * iz * iz,
            );
            let jac = o.w * (dpred * dq);
            let res = o.w * (Vector4::from(o.obs) - pred);
            for k in 0..4 {
                let row = jac.row(k).transpose();
                jtr.axpy(res[k], &row, 1.0);
                jtj.syger(1.0, &row, &row, 1.0);
            }
        }
        // Pivots at or below 1e-12 are singular (as they were for the Gaussian
        // elimination this replaces).
        let delta = linsolve::solve_symmetric(jtj, &jtr, 1e-12)?;
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

/// Reusable buffers of [`estimate`]: the inlier sets of a hypothesis and of the
/// best one (no allocation once they have grown).
#[derive(Clone, Debug, Default)]
pub struct RansacScratch {
    inliers: Vec<usize>,
    best: Vec<usize>,
}

/// RANSAC and the final fit.
pub fn estimate(
    c: &Calibration,
    obs: &[Observation],
    iterations: usize,
    threshold: f64,
    min_inliers: usize,
    rng: &mut Rng,
    scratch: &mut RansacScratch,
) -> Result<Estimate, EgomotionError> {
    let n = obs.len();
    let needed = min_inliers.max(6);
    if n < needed {
        return Err(EgomotionError::TooFewMatches { found: n, needed });
    }
    let thr2 = threshold * threshold;
    let RansacScratch {
        inliers,
        best: best_set,
    } = scratch;
    best_set.clear();
    let mut best = (best_set, [0.0; 6]);
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
        // Only a set larger than the best is kept: the count stops as soon as
        // the observations left could no longer make it larger.
        let beat = best.0.len();
        inliers.clear();
        for (i, o) in obs.iter().enumerate() {
            if inliers.len() + (n - i) <= beat {
                break;
            }
            if error2(c, &r, &theta, o) < thr2 {
                inliers.push(i);
            }
        }
        if inliers.len() > beat {
            std::mem::swap(best.0, inliers);
            best.1 = theta;
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
        gauss_newton(c, obs, best.0, best.1, 100, 1e-8).ok_or(EgomotionError::NoConvergence {
            inliers: best.0.len(),
        })?;
    Ok(Estimate {
        theta,
        inliers: best.0.len(),
    })
}

/// The 4 × 4 transform `[R t; 0 1]` of `θ` (row-major).
pub fn transform(theta: &[f64; 6]) -> [[f64; 4]; 4] {
    let (r, _) = rotation(theta);
    let pose = IsometryMatrix3::from_parts(
        Translation3::from(translation(theta)),
        Rotation3::from_matrix_unchecked(r),
    );
    pose.to_homogeneous().transpose().into()
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

    /// RANSAC as the odometry runs it (200 hypotheses, 2 px, 6 inliers), seeded.
    fn ransac(obs: &[Observation]) -> Result<Estimate, EgomotionError> {
        estimate(
            &calib(),
            obs,
            200,
            2.0,
            6,
            &mut Rng::new(0),
            &mut RansacScratch::default(),
        )
    }

    #[test]
    fn recovers_a_motion_despite_outliers() {
        let truth = [0.01, -0.08, 0.005, 0.05, -0.01, 0.4];
        let obs = scene(truth, 40);
        let e = ransac(&obs).unwrap();
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
        let err = ransac(&obs).unwrap_err();
        assert!(matches!(err, EgomotionError::TooFewInliers { .. }), "{err}");
        let err = ransac(&obs[..4]).unwrap_err();
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
