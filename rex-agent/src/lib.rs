//! Rex, the skid-steer mobile platform of Janiak & Zieliński, as an embodied agent.
//!
//! The locomotion agent `a1` (control subsystem `c1`, virtual effector `e1,1`, virtual
//! receptor `r1,1`), its simulated world (platform `E1`, stereo camera `R1`) and its
//! partner agents `a2` (ontology) and `a3` (map) are built here against the public
//! `embodied` API only, exactly as a user's crate would be.

pub mod c1;
pub mod camera;
pub mod config;
pub mod devices;
pub mod e11;
pub mod judge;
pub mod map;
pub mod mission;
pub mod model;
pub mod mpc;
pub mod noise;
pub mod partners;
pub mod planner;
pub mod r11;
pub mod report;
pub mod rex;
pub mod run;
pub mod soak;
pub mod types;
pub mod vo;
pub mod world;
