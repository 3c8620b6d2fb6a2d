//! Model-based control and estimation for e1,1 (the paper's section 3.2): nonlinear
//! model predictive control ([`nmpc`]) and moving-horizon estimation ([`mhe`]) on a
//! skid-steer prediction model ([`crate::world::model::Dynamics`]: the peers'
//! reduced model, or the lateral-slip model Rex runs with), by Gauss–Newton SQP
//! with exact sensitivities, QPs solved by exploiting the stage structure and by
//! Clarabel when bounds are active. The small dense algebra is nalgebra's.

use nalgebra::{Cholesky, Const};

use crate::world::model::Matrix;

pub mod mhe;
pub mod nmpc;
pub mod peer;
pub mod sparse;

pub use mhe::{
    LateralMhe, Mhe, MheError, MheEstimate, MheSettings, MheStats, Motion, ReducedMhe, Sample,
    TimedPose,
};
pub use nmpc::{
    ClarabelWorkspace, Control, FrozenQp, LateralNmpc, Nmpc, NmpcError, NmpcSettings, NmpcStats,
    QpSolution, QpStrategy, ReducedNmpc, SparseQp, Status,
};

/// The Cholesky factorisation of a symmetric positive definite matrix, or
/// `None` if it is not (a pivot not positive) or not finite. (nalgebra's
/// `Cholesky::new` accepts an infinite pivot.)
pub(crate) fn spd_cholesky<const N: usize>(m: Matrix<N, N>) -> Option<Cholesky<f64, Const<N>>> {
    if !m.iter().all(|v| v.is_finite()) {
        return None;
    }
    let l = Cholesky::new(m)?;
    l.l_dirty()
        .diagonal()
        .iter()
        .all(|d| d.is_finite() && *d > 0.0)
        .then_some(l)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cholesky_solves_and_refuses_indefinite_or_non_finite_matrices() {
        let a = Matrix::<3, 3>::new(4.0, 2.0, 0.6, 2.0, 5.0, 1.0, 0.6, 1.0, 3.0);
        let b = crate::world::model::Vector::<3>::new(1.0, 2.0, 3.0);
        let x = spd_cholesky(a).expect("positive definite").solve(&b);
        assert!((a * x - b).amax() < 1e-12);
        assert!(spd_cholesky(Matrix::<2, 2>::new(1.0, 2.0, 2.0, 1.0)).is_none());
        assert!(spd_cholesky(Matrix::<1, 1>::new(f64::NAN)).is_none());
        assert!(spd_cholesky(Matrix::<1, 1>::new(f64::INFINITY)).is_none());
        assert!(spd_cholesky(Matrix::<2, 2>::new(1.0, 0.0, 0.0, 0.0)).is_none());
    }
}
