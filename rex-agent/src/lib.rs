//! Rex, the skid-steer mobile platform of Janiak & Zieliński, as an embodied agent.
//!
//! The folders follow the paper's Fig. 2/3, in layers that import downward only (`tests/layout.rs` checks it):
//!
//! 1. [`math`] (linear solves, geometry, the seeded generator) and [`config`] (RON
//!    files);
//! 2. [`model`], the skid-steer platform (parameters, the reduced model of the
//!    controllers, the full model of the plant); [`payload`], what the buffers
//!    carry; [`mission`], a2's plans;
//! 3. [`algorithms`], what a1 computes with: model predictive control and
//!    moving-horizon estimation, state estimators and trajectory trackers,
//!    trajectory planners, stereo visual odometry. They know nothing of the
//!    framework;
//! 4. [`a1`], the locomotion agent (its control subsystem `c1`, virtual effector
//!    `e1,1`, virtual receptor `r1,1`, the map they check plans and poses
//!    against), and [`world`], the simulated world (the real effector `E1` and
//!    receptors `R1` and `R3` as drivers, the rendered scene, the partner agents
//!    `a2` and `a3`), neither knowing the other;
//! 5. the composition root: [`system`] (a1 in the world, built from
//!    `specs/rex.ron`), [`run`] (missions in either executor, judged), [`report`],
//!    [`record`], [`soak`], and [`app`], what is Rex's own in the `rex` program (the
//!    rest is the application layer's, `embodied::app`).
//!
//! Everything is written against the public `embodied` API only, exactly as a
//! user's crate would be.

pub mod a1;
pub mod algorithms;
pub mod app;
pub mod config;
pub mod fleet;
pub mod math;
pub mod mission;
pub mod model;
pub mod payload;
pub mod record;
pub mod report;
#[cfg(feature = "ros2")]
pub mod ros2;
pub mod run;
pub mod soak;
pub mod system;
pub mod world;
