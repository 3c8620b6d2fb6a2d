//! Recording runs of embodied agents so that standard tools read them.
//!
//! * [`json`]: buffer values as JSON with a JSON schema derived from the
//!   payload type ([`agent_core::reflect`]), the form Foxglove plots any field
//!   of, read from the postcard bytes the executors' observers produce
//!   ([`agent_core::trace::ErasedPayload::encode`]) without the Rust type, so a
//!   writer thread does it off the executor's thread;
//! * [`record`]: [`McapRecorder`], the observer that writes a run to MCAP.
//!
//! Replay, merging the files of a distributed run and Foxglove's well-known
//! schemas for poses and images build on these (see the README's roadmap).

pub mod json;
pub mod record;

/// The MCAP crate this one writes with (to read recordings back).
pub use mcap;
pub use record::{McapRecorder, RecordError, RecordOptions, RecordSummary};
