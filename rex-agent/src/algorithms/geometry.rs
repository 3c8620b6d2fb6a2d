//! Plane angles and rigid transforms, shared by the algorithms, the simulated world
//! and a1: [`wrap`] brings an angle into (−π, π]; [`Pose34`] is a 4×4 rigid
//! transform as its top 3×4 rows (KITTI's pose format), with [`compose`] and
//! [`invert`].

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

/// `a · b` for rigid transforms.
pub fn compose(a: &Pose34, b: &Pose34) -> Pose34 {
    let mut r = [[0.0; 4]; 3];
    for i in 0..3 {
        for j in 0..4 {
            r[i][j] =
                (0..3).map(|k| a[i][k] * b[k][j]).sum::<f64>() + if j == 3 { a[i][3] } else { 0.0 };
        }
    }
    r
}

/// The inverse of a rigid transform.
pub fn invert(a: &Pose34) -> Pose34 {
    let mut r = [[0.0; 4]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = a[j][i];
        }
        r[i][3] = -(0..3).map(|k| a[k][i] * a[k][3]).sum::<f64>();
    }
    r
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
