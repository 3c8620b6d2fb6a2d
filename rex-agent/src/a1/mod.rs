//! The locomotion agent `a1` of the paper's Fig. 3: the control subsystem [`c1`],
//! the virtual effector [`e11`] (e1,1) and the virtual receptor [`r11`] (r1,1),
//! the data their buffers carry ([`payload`]), the free space they check plans and
//! poses against ([`map`]), and the wiring that builds the whole Rex system from a
//! deployment of `specs/rex.ron` (re-exported here: [`build`], [`build_deployment`],
//! [`deployment`], [`RexConfig`], ...).

pub mod c1;
pub mod e11;
pub mod map;
pub mod payload;
pub mod r11;
mod wiring;

pub use wiring::{
    Limits, RexConfig, RexError, RexHandles, RunSettings, build, build_deployment, default_spec,
    deployment, load_spec,
};
