#![doc = include_str!("../README.md")]
//!
//! ---
//!
//! This crate is the one dependency a user adds: it re-exports the formalism and the
//! executor of `agent-core`.

pub use agent_core::*;
