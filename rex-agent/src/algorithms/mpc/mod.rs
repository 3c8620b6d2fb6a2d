//! Model-based control and estimation for e1,1 (the paper's section 3.2): nonlinear
//! model predictive control ([`nmpc`]) and moving-horizon estimation ([`mhe`]) on the
//! reduced skid-steer model, by Gauss–Newton SQP with exact sensitivities, QPs solved
//! by exploiting the stage structure and by Clarabel when bounds are active.

pub mod linalg;
pub mod mhe;
pub mod nmpc;
pub mod peer;
pub mod sparse;

pub use mhe::{Mhe, MheError, MheEstimate, MheSettings, MheStats, Motion, Sample, TimedPose};
pub use nmpc::{Control, Nmpc, NmpcError, NmpcSettings, NmpcStats, QpStrategy, Status};
