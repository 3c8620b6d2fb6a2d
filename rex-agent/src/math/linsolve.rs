//! The small dense linear solves of the algorithms and of the plant, on nalgebra's
//! fixed-size matrices (on the stack, no allocation): [`solve_lu`] for a general
//! system, [`solve_symmetric`] for normal equations (symmetric, positive definite
//! unless the data are degenerate), [`spd_cholesky`] for a factor to solve with
//! several times. Both refuse with `None`, and never panic on, a
//! system with a pivot of magnitude at most `pivot_min` or NaN, or a solution that
//! is not finite (as Gaussian elimination refuses them: a NaN anywhere in the
//! system reaches a pivot or the solution).

use nalgebra::allocator::Allocator;
use nalgebra::{Cholesky, Const, DefaultAllocator, DimMin, OMatrix, OVector, SMatrix};

/// Whether every number is finite (over the storage's slice: nalgebra's element
/// iterator costs several times as much in the plant's Newton loop).
fn finite(values: &[f64]) -> bool {
    values.iter().fold(true, |all, v| all & v.is_finite())
}

/// The Cholesky factorisation of a symmetric positive definite matrix, or
/// `None` if it is not (a pivot not positive) or not finite. (nalgebra's
/// `Cholesky::new` accepts an infinite pivot.)
pub(crate) fn spd_cholesky<const N: usize>(
    m: SMatrix<f64, N, N>,
) -> Option<Cholesky<f64, Const<N>>> {
    if !finite(m.as_slice()) {
        return None;
    }
    let l = Cholesky::new(m)?;
    l.l_dirty()
        .diagonal()
        .iter()
        .all(|d| d.is_finite() && *d > 0.0)
        .then_some(l)
}

/// Solve `a x = b` by LU with partial pivoting.
pub(crate) fn solve_lu<D>(
    a: OMatrix<f64, D, D>,
    b: &OVector<f64, D>,
    pivot_min: f64,
) -> Option<OVector<f64, D>>
where
    D: DimMin<D, Output = D>,
    DefaultAllocator: Allocator<D, D> + Allocator<D>,
{
    let lu = a.lu();
    // The pivots are U's diagonal (a NaN one is not above the least either).
    let packed = lu.lu_internal();
    if !(0..packed.nrows()).all(|i| packed[(i, i)].abs() > pivot_min) {
        return None;
    }
    let x = lu.solve(b)?;
    finite(x.as_slice()).then_some(x)
}

/// Solve `a x = b` for a symmetric `a`, of which only the lower triangle is read:
/// by Cholesky; when `a` is not positive definite with every pivot (the squares of
/// `L`'s diagonal) above `pivot_min`, by [`solve_lu`] (a singular matrix made
/// slightly indefinite by rounding is then treated as Gaussian elimination treats it).
pub(crate) fn solve_symmetric<D>(
    mut a: OMatrix<f64, D, D>,
    b: &OVector<f64, D>,
    pivot_min: f64,
) -> Option<OVector<f64, D>>
where
    D: DimMin<D, Output = D>,
    DefaultAllocator: Allocator<D, D> + Allocator<D>,
{
    a.fill_upper_triangle_with_lower_triangle();
    if let Some(chol) = Cholesky::new(a.clone())
        && (0..a.nrows()).all(|i| chol.l_dirty()[(i, i)].powi(2) > pivot_min)
    {
        let x = chol.solve(b);
        if finite(x.as_slice()) {
            return Some(x);
        }
    }
    solve_lu(a, b, pivot_min)
}

#[cfg(test)]
mod tests {
    use nalgebra::{Matrix3, Vector3};

    use super::*;

    #[test]
    fn solves_and_refuses() {
        let a = Matrix3::new(4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0);
        let x = Vector3::new(1.0, -2.0, 0.5);
        let b = a * x;
        for got in [solve_lu(a, &b, 1e-12), solve_symmetric(a, &b, 1e-12)] {
            let got = got.expect("a regular system");
            assert!((got - x).amax() < 1e-12, "{got} vs {x}");
        }
        // Only the lower triangle of a symmetric matrix is read.
        let mut lower = a;
        lower[(0, 2)] = f64::NAN;
        let got = solve_symmetric(lower, &b, 1e-12).expect("the lower triangle is regular");
        assert!((got - x).amax() < 1e-12);
        // Singular, indefinite (solved by LU), not finite.
        let singular = Matrix3::new(1.0, 2.0, 0.0, 2.0, 4.0, 0.0, 0.0, 0.0, 1.0);
        assert!(solve_lu(singular, &b, 1e-12).is_none());
        assert!(solve_symmetric(singular, &b, 1e-12).is_none());
        let indefinite = Matrix3::new(1.0, 0.0, 0.0, 0.0, -2.0, 0.0, 0.0, 0.0, 3.0);
        let got = solve_symmetric(indefinite, &b, 1e-12).expect("regular, not definite");
        assert!((indefinite * got - b).amax() < 1e-12);
        let mut nan = a;
        nan[(1, 1)] = f64::NAN;
        assert!(solve_lu(nan, &b, 1e-12).is_none());
        assert!(solve_symmetric(nan, &b, 1e-12).is_none());
        let mut nan_below = a;
        nan_below[(2, 0)] = f64::NAN;
        assert!(solve_lu(nan_below, &b, 1e-12).is_none());
        assert!(solve_symmetric(nan_below, &b, 1e-12).is_none());
        for bad in [f64::NAN, f64::INFINITY] {
            let b = Vector3::new(1.0, bad, 0.0);
            assert!(solve_lu(a, &b, 1e-12).is_none());
            assert!(solve_symmetric(a, &b, 1e-12).is_none());
        }
    }

    #[test]
    fn cholesky_solves_and_refuses_indefinite_or_non_finite_matrices() {
        let a = nalgebra::Matrix3::new(4.0, 2.0, 0.6, 2.0, 5.0, 1.0, 0.6, 1.0, 3.0);
        let b = Vector3::new(1.0, 2.0, 3.0);
        let x = spd_cholesky(a).expect("positive definite").solve(&b);
        assert!((a * x - b).amax() < 1e-12);
        assert!(spd_cholesky(nalgebra::Matrix2::new(1.0, 2.0, 2.0, 1.0)).is_none());
        assert!(spd_cholesky(nalgebra::Matrix1::new(f64::NAN)).is_none());
        assert!(spd_cholesky(nalgebra::Matrix1::new(f64::INFINITY)).is_none());
        assert!(spd_cholesky(nalgebra::Matrix2::new(1.0, 0.0, 0.0, 0.0)).is_none());
    }
}
