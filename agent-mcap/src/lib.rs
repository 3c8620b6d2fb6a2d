//! Recording runs of embodied agents so that standard tools read them, and
//! replaying a subsystem against a recording.
//!
//! * [`json`]: buffer values as JSON with a JSON schema derived from the
//!   payload type ([`agent_core::reflect`]), the form Foxglove plots any field
//!   of, read from the postcard bytes the executors' observers produce
//!   ([`agent_core::trace::ErasedPayload::encode`]) without the Rust type, so a
//!   writer thread does it off the executor's thread;
//! * [`cdr`]: the same values as ROS 2 CDR with a `ros2msg` schema made from
//!   the type, the recorder's default (no field names, no number formatting
//!   per value; Foxglove and every ROS 2 tool decode it);
//! * [`record`]: [`McapRecorder`], the observer that writes a run to MCAP, and
//!   [`Derive`], channels derived from buffers (Foxglove's images and poses);
//! * [`codec`]: [`Codec`], a lossless encoding of one payload type's values on
//!   their raw channels (a camera's images as PNG);
//! * [`read`]: [`Recording`], a file read back, with errors that name the
//!   offset of a truncated or damaged part;
//! * [`export`](mod@export): a recording as an MCAP file of profile `ros2`
//!   with its ROS 2 channels only, for ROS 2 tools (rosbags reads it);
//! * [`merge`](mod@merge): the recordings of the processes of a distributed run
//!   made one, in time order;
//! * [`timing`](mod@timing): the real-time executor's timing statistics
//!   (the `/timing` channel) and the WCETs they measured;
//! * [`replay`](mod@replay): one subsystem fed its recorded inputs, its outputs
//!   and behaviour switches compared bit for bit with the recording.

pub mod cdr;
mod close;
pub mod codec;
pub mod export;
pub mod json;
pub mod merge;
mod postcard;
pub mod read;
pub mod record;
pub mod replay;
pub mod timing;

/// The MCAP crate this one writes with (to read recordings back).
pub use codec::{Codec, DecodeError};
pub use export::{ExportError, ExportOptions, ExportSummary, LeftOut, LeftOutReason, export_ros2};
pub use mcap;
pub use merge::{MergeError, MergeSummary, merge, merge_launch};
pub use read::{ReadError, Recording};
pub use record::{
    Derive, DerivedChannel, McapRecorder, RecordError, RecordOptions, RecordSummary, Values,
    raw_values,
};
pub use replay::{
    Difference, Divergence, ReplayError, ReplayOptions, Replayed, Window, replay, replay_file,
};
pub use timing::{TimingStats, measured_lateness, measured_wcets, read_timing};
