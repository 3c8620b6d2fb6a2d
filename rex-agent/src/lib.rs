//! Rex, the skid-steer mobile platform of Janiak & Zieliński, as an embodied agent.
//!
//! The folders follow the paper's Fig. 2/3:
//!
//! * [`a1`], the locomotion agent: its control subsystem `c1`, virtual effector
//!   `e1,1` and virtual receptor `r1,1`, the payloads of their buffers, the map they
//!   check plans and poses against, and the system built from `specs/rex.ron`;
//! * [`world`], the simulated world: the platform model, the real effector `E1` and
//!   receptors `R1` (stereo camera) and `R3` (motion capture) as drivers, the
//!   rendered scene, and the partner agents `a2` (ontology) and `a3` (map);
//! * [`algorithms`], what a1 computes with: model predictive control and
//!   moving-horizon estimation, trajectory planners, stereo visual odometry. They
//!   know nothing of the framework;
//! * [`report`], the verdict on a run and its report folder; [`config`],
//!   [`mission`], [`run`] and [`soak`], running missions for the `rex` binary,
//!   the tests and the examples; [`app`], what is Rex's own in the `rex`
//!   program (the rest is the application layer's, `embodied::app`).
//!
//! Everything is written against the public `embodied` API only, exactly as a
//! user's crate would be.

pub mod a1;
pub mod algorithms;
pub mod app;
pub mod config;
pub mod mission;
pub mod record;
pub mod report;
pub mod run;
pub mod soak;
pub mod world;
