//! Recording runs of embodied agents so that standard tools read them.
//!
//! Today: [`json`], buffer values as JSON with a JSON schema derived from the
//! payload type ([`agent_core::reflect`]), the form Foxglove plots any field of.
//! The values are read from the postcard bytes the executors' observers already
//! produce ([`agent_core::trace::ErasedPayload::encode`]), without the Rust type,
//! so a writer thread can do it off the executor's thread. The MCAP writer, the
//! channels of a run and replay build on it (see the README's roadmap).

pub mod json;
