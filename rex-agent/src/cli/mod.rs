//! The `rex` binary's commands beyond a single mission, one module each:
//! [`deploy`] runs a deployment's processes and launches them, [`replay`]
//! replays a subsystem against a recording.

#[cfg(feature = "distributed")]
pub(crate) mod deploy;
pub(crate) mod replay;
