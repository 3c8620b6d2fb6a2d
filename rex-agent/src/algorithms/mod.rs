//! What a1 computes with, written without the framework: plain functions and types
//! over numbers, images and the platform model, so each can be tested and
//! benchmarked on its own.
//!
//! * [`mpc`]: nonlinear model predictive control and moving-horizon estimation on
//!   the reduced skid-steer model (the paper's section 3.2);
//! * [`planner`]: trajectory fragments between plan points, and the planning process
//!   behind the paper's `trajgen` API;
//! * [`vo`]: stereo visual odometry and the KITTI drift metric (section 3.3);
//! * [`geometry`]: plane angles and rigid transforms; [`rng`]: seeded random
//!   numbers (RANSAC, ECSA, and the simulated sensors' noise); `linsolve`: the
//!   small linear solves (nalgebra's LU and Cholesky, with the refusals they share).
//!
//! The only module of the crate they use is the platform model
//! ([`crate::world::model`]: parameters and the reduced model, pure math); a test
//! (`tests/layout.rs`) keeps it so.

pub mod geometry;
pub(crate) mod linsolve;
pub mod mpc;
pub mod planner;
pub mod rng;
pub mod vo;
