//! What a recording is asked for and what it says: its options (the values'
//! form, derived channels, codecs, the queue's bounds), its errors and its
//! summary.

use std::collections::BTreeMap;
use std::path::PathBuf;
use std::sync::Arc;

use agent_core::Time;
use agent_core::trace::LinkInfo;

use crate::codec::Codec;

/// A channel derived from the values of some links, written beside their own:
/// what a robotics user expects to look at in Foxglove (an image, a pose, a
/// path) made from a buffer's value. Runs on the writer thread.
pub trait Derive: Send {
    /// The channel this adds for `link` (its index and description), or
    /// `None`. Called once per link when the recording is created.
    fn channel(&mut self, link: usize, info: &LinkInfo) -> Option<DerivedChannel>;
    /// The message for one value of a link it asked for (`body`: the value's
    /// postcard bytes; `time`: the sender's instant), written into `out`
    /// (empty); `false`: no message for this value.
    fn message(&mut self, link: usize, time: Time, body: &[u8], out: &mut Vec<u8>) -> bool;
    /// As [`Derive::message`], for a link recorded through a [`Codec`]: also
    /// given the codec's encoding of the value (`encoded`), which the message
    /// may reuse (an image the codec compressed already). By default,
    /// [`Derive::message`].
    fn message_encoded(
        &mut self,
        link: usize,
        time: Time,
        body: &[u8],
        encoded: &[u8],
        out: &mut Vec<u8>,
    ) -> bool {
        let _ = encoded;
        self.message(link, time, body, out)
    }
}

/// A channel a [`Derive`] adds.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DerivedChannel {
    /// The topic.
    pub topic: String,
    /// The schema's name (`foxglove.PoseInFrame`).
    pub schema_name: String,
    /// The schema's encoding (`jsonschema`).
    pub schema_encoding: String,
    /// The schema.
    pub schema: Vec<u8>,
    /// The messages' encoding (`json`).
    pub message_encoding: String,
}

/// The form of the values on a recording's `/links/...` channels: both are
/// read off the payload type's shape on the writer thread, and both are what
/// Foxglove plots any field of.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Values {
    /// ROS 2 CDR with a `ros2msg` schema made from the type
    /// ([`cdr`](crate::cdr)): a value's bytes, aligned, with no field names
    /// and no number formatting. A type with no ROS 2 message is recorded as
    /// [`Values::Json`]. Smaller and faster to write than JSON, so that the
    /// writer keeps up with the run (`bench_record`; docs/measurements.md, "The
    /// recorder's encodings").
    #[default]
    Cdr,
    /// JSON with the JSON schema of the type ([`json`](crate::json)): text
    /// any tool reads, at several times the bytes and the writer's time.
    Json,
}

/// How a recording is made.
pub struct RecordOptions {
    /// Queue records the writer may fall behind by before the executor
    /// waits: each either a batch of transfers and reads (about 64 KiB, or
    /// one value longer than that) or a behaviour switch or error.
    pub queue: usize,
    /// Bytes of batches the writer may fall behind by before the executor
    /// waits for it to catch up (a batch larger than this alone still goes
    /// once the writer has emptied the queue): the memory a slow disk or a
    /// starved writer can take. Default 128 MiB (about 200 of Rex's stereo
    /// pairs).
    pub queue_bytes: usize,
    /// Metadata records to add, by name: each a map of strings (the spec's
    /// text, the deployment, the run's settings, versions).
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
    /// The form of the values on the `/links/...` channels.
    pub values: Values,
    /// A value whose encoding is longer than this is recorded on its raw
    /// channel only (an image as a JSON array of numbers costs more than the
    /// run; a [`Derive`] can show it compressed). Counted in
    /// [`RecordSummary::raw_only`].
    pub value_max_bytes: usize,
    /// Derived channels.
    pub derived: Vec<Box<dyn Derive>>,
    /// Codecs for the raw channels of some payload types ([`Codec`]): each
    /// link whose payload a codec names is recorded in its encoding.
    pub codecs: Vec<Arc<dyn Codec>>,
    /// Run the writer thread in the background: at the lowest priority the
    /// system has (`SCHED_IDLE` on Linux), so that it takes only the CPU the
    /// run leaves and never delays a node, a worker or an offloaded
    /// computation. A run that leaves no CPU fills the queue, and the executor
    /// then waits for the writer ([`RecordSummary::waits`]): slower, never
    /// lossy. Default `true`; where the policy cannot be set the writer runs at
    /// normal priority ([`RecordSummary::background`] says which).
    pub background: bool,
}

impl std::fmt::Debug for RecordOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RecordOptions")
            .field("queue", &self.queue)
            .field("queue_bytes", &self.queue_bytes)
            .field("metadata", &self.metadata.keys().collect::<Vec<_>>())
            .field("values", &self.values)
            .field("value_max_bytes", &self.value_max_bytes)
            .field("derived", &self.derived.len())
            .field(
                "codecs",
                &self.codecs.iter().map(|c| c.name()).collect::<Vec<_>>(),
            )
            .field("background", &self.background)
            .finish()
    }
}

impl Default for RecordOptions {
    fn default() -> Self {
        RecordOptions {
            queue: 1024,
            queue_bytes: 128 << 20,
            metadata: BTreeMap::new(),
            values: Values::default(),
            value_max_bytes: 16 * 1024,
            derived: Vec::new(),
            codecs: Vec::new(),
            background: true,
        }
    }
}

/// Why a recording failed.
#[derive(Debug, thiserror::Error)]
pub enum RecordError {
    /// The file could not be created.
    #[error("recording {path}: {source}")]
    Create {
        /// The file.
        path: PathBuf,
        /// The OS's reason.
        source: std::io::Error,
    },
    /// The MCAP writer failed (the disk, most likely).
    #[error("recording {path}: {message}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
    /// The writer thread ended without saying why.
    #[error("recording {0}: the writer thread is gone")]
    WriterGone(PathBuf),
}

/// What a finished recording holds.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct RecordSummary {
    /// Messages written, all channels.
    pub messages: u64,
    /// Channels.
    pub channels: usize,
    /// Values whose bytes did not read as their shape says, or that could not
    /// be encoded (the former written raw only). A payload type without a
    /// shape ([`agent_core::reflect`]) is written raw only, and not counted.
    pub undecodable: u64,
    /// Values recorded on their raw channel only, being longer than
    /// [`RecordOptions::value_max_bytes`].
    pub raw_only: u64,
    /// The links whose values are JSON though [`Values::Cdr`] was asked for,
    /// their type having no ROS 2 message: each `<link>: <why>`.
    pub json_values: Vec<String>,
    /// Times the executor waited for the writer.
    pub waits: u64,
    /// The most bytes of batches the writer was behind by.
    pub backlog_peak_bytes: usize,
    /// Whether the writer ran in the background ([`RecordOptions::background`]).
    pub background: bool,
}
