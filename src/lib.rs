//! # embodied
//!
//! Specify, check and run robot control systems as *embodied agents*, the formalism of
//! Zieliński used by Janiak & Zieliński for the Rex mobile platform.
//!
//! This crate is the one dependency a user adds: it re-exports the formalism and the
//! executor of [`agent_core`]. See the README for a walk-through.

pub use agent_core::*;
