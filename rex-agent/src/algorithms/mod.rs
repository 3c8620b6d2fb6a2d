//! What a1 computes with, written without the framework: plain functions and types
//! over numbers, images and the platform model, so each can be tested and
//! benchmarked on its own.
//!
//! * [`mpc`]: nonlinear model predictive control and moving-horizon estimation on
//!   the reduced skid-steer model (the paper's section 3.2);
//! * [`planner`]: trajectory fragments between plan points, and the planning process
//!   behind the paper's `trajgen` API;
//! * [`estimation`]: the platform's state estimators behind one trait, the baseline
//!   EKF and the moving-horizon estimator (section 3.2);
//! * [`tracking`]: trajectory trackers behind one trait, the baseline
//!   (backstepping) and the NMPC (section 3.2);
//! * [`vo`]: stereo visual odometry and the KITTI drift metric (section 3.3);
//!
//! Of the crate they use only the layers below them: the platform model
//! ([`crate::model`]: parameters and the reduced model), the interface types
//! ([`crate::payload`]: poses, encoder and IMU readings), the numerics
//! ([`crate::math`]: linear solves, geometry, the seeded generator) and
//! [`crate::config`]; a test (`tests/layout.rs`) keeps it so.

pub mod estimation;
pub mod mpc;
pub mod planner;
pub mod tracking;
pub mod vo;
