//! Plane angles and rigid transforms, shared by the algorithms, the simulated world
//! and a1: [`wrap`] brings an angle into (−π, π]; [`Pose34`] is a 4×4 rigid
//! transform as its top 3×4 rows (KITTI's pose format), with [`compose`] and
//! [`invert`] (by nalgebra's [`IsometryMatrix3`]: [`isometry`], [`pose34`]).

use nalgebra::{IsometryMatrix3, Matrix3, Rotation3, Translation3};

/// An angle in (−π, π].
pub fn wrap(a: f64) -> f64 {
    let w = (a + std::f64::consts::PI).rem_euclid(std::f64::consts::TAU) - std::f64::consts::PI;
    if w <= -std::f64::consts::PI {
        w + std::f64::consts::TAU
    } else {
        w
    }
}

/// A 4×4 rigid transform as its top 3×4 rows.
pub type Pose34 = [[f64; 4]; 3];

/// `pose` as nalgebra's rigid transform (its rotation block taken as it is).
pub fn isometry(pose: &Pose34) -> IsometryMatrix3<f64> {
    IsometryMatrix3::from_parts(
        Translation3::new(pose[0][3], pose[1][3], pose[2][3]),
        Rotation3::from_matrix_unchecked(Matrix3::from_fn(|i, j| pose[i][j])),
    )
}

/// A rigid transform's top 3×4 rows.
pub fn pose34(t: &IsometryMatrix3<f64>) -> Pose34 {
    let (r, c) = (t.rotation.matrix(), &t.translation.vector);
    std::array::from_fn(|i| [r[(i, 0)], r[(i, 1)], r[(i, 2)], c[i]])
}

/// `a · b` for rigid transforms.
pub fn compose(a: &Pose34, b: &Pose34) -> Pose34 {
    pose34(&(isometry(a) * isometry(b)))
}

/// The inverse of a rigid transform.
pub fn invert(a: &Pose34) -> Pose34 {
    pose34(&isometry(a).inverse())
}

/// The identity transform.
pub const IDENTITY: Pose34 = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn wrap_keeps_angles_in_range() {
        for a in [
            -10.0,
            -std::f64::consts::PI,
            0.0,
            3.0,
            std::f64::consts::PI,
            7.0,
        ] {
            let w = wrap(a);
            assert!(
                w > -std::f64::consts::PI && w <= std::f64::consts::PI,
                "{a} -> {w}"
            );
            assert!(
                ((w - a) / std::f64::consts::TAU).fract().abs() < 1e-9
                    || ((w - a) / std::f64::consts::TAU).fract().abs() > 1.0 - 1e-9
            );
        }
    }
}
