//! Model-based control and estimation for e1,1 (the paper's section 3.2): nonlinear
//! model predictive control ([`nmpc`]) and moving-horizon estimation ([`mhe`]) on a
//! skid-steer prediction model ([`crate::model::Dynamics`]: the peers'
//! reduced model, or the lateral-slip model Rex runs with), by Gauss–Newton SQP
//! with exact sensitivities, QPs solved by exploiting the stage structure and by
//! Clarabel when bounds are active. The small dense algebra is nalgebra's.

pub mod mhe;
pub mod nmpc;
pub mod sparse;

pub(crate) use crate::math::linsolve::spd_cholesky;

pub use mhe::{
    Innovation, LateralMhe, Mhe, MheError, MheEstimate, MheSettings, MheStats, Motion, ReducedMhe,
    Sample, TimedPose,
};
pub use nmpc::{
    ClarabelWorkspace, Control, FrozenQp, LateralNmpc, Nmpc, NmpcError, NmpcSettings, NmpcStats,
    QpSolution, QpStrategy, ReducedNmpc, SparseQp, Status,
};
