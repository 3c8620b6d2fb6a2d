//! Reading postcard without the Rust type: agent-core's cursor
//! ([`agent_core::untyped`]), which the JSON and CDR writers walk a
//! [`TypeShape`](agent_core::TypeShape)'s formats with.

pub use agent_core::untyped::DecodeError;
pub(crate) use agent_core::untyped::{Cursor, MAX_DEPTH};
