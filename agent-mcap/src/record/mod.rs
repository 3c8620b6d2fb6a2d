//! [`McapRecorder`]: an observer that writes a run to an MCAP file.
//!
//! The executor's thread only encodes each value it sees (postcard) into a
//! batch, and queues the batch every 64 KiB (buffers the writer thread hands
//! back, so the steady state allocates nothing); the writer thread makes the
//! file's channels and schemas, adds each raw value's wire header, turns each
//! value into the form tools read (ROS 2 CDR, or JSON), writes the MCAP
//! records and compresses the chunks (zstd, on that thread).
//!
//! Channels:
//!
//! * `/links/<from>/<port>/to/<to>` for every link (`<port>` with `/` for `.`):
//!   the value in a form Foxglove decodes and plots any field of, read off the
//!   type's shape: by default ROS 2 CDR with the `ros2msg` schema of its type
//!   ([`cdr`](crate::cdr); schema `embodied/msg/<Type>`), or JSON with its
//!   JSON schema ([`json`](crate::json)) when [`RecordOptions::values`] asks
//!   for it or the type has no ROS 2 message (it contains itself, or a field
//!   name ROS 2 refuses); log time = the sender's instant, sequence = the
//!   link's count;
//! * the same topic under `/raw/...`: each value exactly as a link between
//!   processes carries it (the 41-byte header of [`agent_core::WireHeader`]
//!   with the type's fingerprint, the link's count and the sender's stamp,
//!   then the value's postcard bytes), several values of the link to a
//!   message, each behind its length (encoding [`FRAMES_ENCODING`];
//!   [`raw_values`] reads them): what a replay reads (the value channel is
//!   for tools; JSON cannot say NaN); a value larger than
//!   [`RecordOptions::value_max_bytes`] is recorded here only;
//! * channels derived from links ([`Derive`]): for example Foxglove's images
//!   and poses;
//! * `/received/links/...` for a link from another process, made when its
//!   first value arrives (encoding [`WIRE_ENCODING`], the link's codec as on
//!   its raw channel): each value this process took from it, as the raw
//!   channel would carry it: what a replay feeds when the sender's recording
//!   lacks it (a process killed before its recorder wrote it, or a value from
//!   outside the deployment);
//! * `/reads/links/...` for every link (encoding `embodied-read/1`): each
//!   value its receiver took, at the receiver's instant (log time), as the
//!   value's stamp (sender's iteration, then instant, each a little-endian
//!   `u64`): which value an activation read, which in a real-time run depends
//!   on the threads' timing; what a replay feeds;
//! * `/fsm/<node>`: each behaviour switch, with the arc and the value of every
//!   predicate at the decision, and the end of a final behaviour;
//! * `/errors`: every error the executor met, with its time.
//!
//! Metadata `system`: the nodes, behaviours and links; `end`: when the run
//! ended, how many iterations each node made and the instants of its first
//! and last (`first/<node>`, `last/<node>`, ns) (written by
//! [`McapRecorder::finish`]: a file without it was not finished); and whatever
//! the caller adds ([`RecordOptions::metadata`]: the spec, the deployment, the
//! settings).
//!
//! The deterministic executor takes the recorder itself as its observer; the
//! real-time executor one part per thread ([`McapRecorder::threads`]), each
//! queuing to the same writer.
//!
//! Queuing is lossless and bounded: when the writer falls behind by
//! [`RecordOptions::queue`] records or [`RecordOptions::queue_bytes`] bytes,
//! the executor waits (counted). A writer
//! that fails (disk full) stops the recording; the run goes on, and
//! [`McapRecorder::finish`] returns the error.

use std::collections::BTreeMap;
use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, Sender, SyncSender, TrySendError, channel, sync_channel};
use std::thread::JoinHandle;

use agent_core::trace::{
    ActionEvent, ErasedPayload, LinkInfo, Observer, ReadEvent, TransferEvent, TransitionEvent,
};
use agent_core::{ExecError, Stamp, Step, System, Time};

use crate::codec::Codec;

mod batch;
mod frames;
mod writer;

use batch::{BATCH_BYTES, BATCH_CAPACITY};
pub use frames::{FRAMES_ENCODING, WIRE_ENCODING, raw_values};

pub(crate) use writer::transition_json;
use writer::{Output, Plan};

/// The message encoding of the reads channels: the stamp of the value read
/// (the sender's iteration, then its instant in ns; little-endian `u64`s).
pub const READ_ENCODING: &str = "embodied-read/1";

/// Put the calling thread at the lowest priority the system has
/// (`SCHED_IDLE` on Linux, which needs no privilege); `true` when the OS then
/// reports that policy for the thread.
fn lowest_priority() -> bool {
    #[cfg(any(target_os = "linux", target_os = "android"))]
    {
        use thread_priority::{
            NormalThreadSchedulePolicy, ThreadPriority, ThreadSchedulePolicy,
            set_thread_priority_and_policy, thread_native_id, thread_schedule_policy,
        };
        let idle = ThreadSchedulePolicy::Normal(NormalThreadSchedulePolicy::Idle);
        set_thread_priority_and_policy(thread_native_id(), ThreadPriority::Min, idle).is_ok()
            && thread_schedule_policy().is_ok_and(|p| p == idle)
    }
    #[cfg(not(any(target_os = "linux", target_os = "android")))]
    {
        false
    }
}

/// One read as its channel carries it.
pub(crate) fn encode_read(stamp: Stamp) -> [u8; 16] {
    let mut b = [0u8; 16];
    b[..8].copy_from_slice(&stamp.iteration.to_le_bytes());
    b[8..].copy_from_slice(&stamp.time.as_nanos().to_le_bytes());
    b
}

/// A read's stamp, from its channel's bytes.
pub(crate) fn decode_read(data: &[u8]) -> Option<Stamp> {
    let iteration = u64::from_le_bytes(data.get(..8)?.try_into().ok()?);
    let time = u64::from_le_bytes(data.get(8..16)?.try_into().ok()?);
    (data.len() == 16).then(|| Stamp::new(iteration, Time::from_nanos(time)))
}

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
    /// [`Values::Json`]. Measured recording Rex's figure-eight without images
    /// (`bench_record`): 9.0 MB instead of 13.0, and the recorded run 1.06x
    /// the plain one's wall time instead of 1.35x (the writer now keeps up).
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

enum Record {
    /// Transfers and reads, in the order one part saw them (see the `batch` module).
    Batch {
        part: u16,
        bytes: Vec<u8>,
    },
    Transition {
        node: u32,
        time: Time,
        iteration: u64,
        step: Step,
    },
    Error {
        time: Time,
        message: String,
    },
    /// A part (one thread's observer) starts: where its buffers go back.
    Part {
        part: u16,
        give_back: Sender<Vec<u8>>,
    },
    /// A part ends: what it counted.
    Counted(Counts),
    /// The recording's owner finished it.
    End,
}

/// What one part counted.
#[derive(Default)]
struct Counts {
    iterations: Vec<u64>,
    /// Per node: the instant of its last activation.
    last_of: Vec<Time>,
    /// Per node: the instant of its first activation (`None`: none yet).
    first_of: Vec<Option<Time>>,
    last: Time,
    waits: u64,
    encode_failures: u64,
}

impl Counts {
    fn add(&mut self, other: &Counts) {
        if self.iterations.len() < other.iterations.len() {
            self.iterations.resize(other.iterations.len(), 0);
        }
        for (a, b) in self.iterations.iter_mut().zip(&other.iterations) {
            *a += b;
        }
        if self.last_of.len() < other.last_of.len() {
            self.last_of.resize(other.last_of.len(), Time::ZERO);
        }
        for (a, b) in self.last_of.iter_mut().zip(&other.last_of) {
            *a = (*a).max(*b);
        }
        if self.first_of.len() < other.first_of.len() {
            self.first_of.resize(other.first_of.len(), None);
        }
        for (a, b) in self.first_of.iter_mut().zip(&other.first_of) {
            *a = match (*a, *b) {
                (Some(x), Some(y)) => Some(x.min(y)),
                (x, y) => x.or(y),
            };
        }
        self.last = self.last.max(other.last);
        self.waits += other.waits;
        self.encode_failures += other.encode_failures;
    }
}

/// An [`Observer`] that writes the run to an MCAP file (see the module's
/// documentation). Give it to `Executor::with_observer`; after the run, take
/// it back (`Executor::into_observer`) and [`McapRecorder::finish`] it. For a
/// real-time run, give `RealTime::observe` its [`McapRecorder::threads`] and
/// finish it after `Running::join`.
pub struct McapRecorder {
    part: Part,
    writer: Option<JoinHandle<Result<RecordSummary, RecordError>>>,
    path: PathBuf,
    /// The number of nodes, and the writer's backlog, for parts.
    nodes: usize,
    backlog: Arc<Backlog>,
    parts: std::sync::Arc<std::sync::atomic::AtomicU16>,
}

impl std::fmt::Debug for McapRecorder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("McapRecorder")
            .field("path", &self.path)
            .finish()
    }
}

/// The bytes of batches queued to the writer and not yet written, shared by
/// the parts (which add) and the writer (which takes away, and says when it
/// has stopped).
#[derive(Debug)]
struct Backlog {
    bytes: AtomicUsize,
    peak: AtomicUsize,
    limit: usize,
    writer_gone: AtomicBool,
}

impl Backlog {
    fn new(limit: usize) -> Backlog {
        Backlog {
            bytes: AtomicUsize::new(0),
            peak: AtomicUsize::new(0),
            limit,
            writer_gone: AtomicBool::new(false),
        }
    }

    /// Wait until `n` more bytes fit (or the queue is empty, or the writer
    /// gone), then count them in; `true` if it had to wait. The writer is
    /// polled every 200 µs: waiting is the rare case of a writer that cannot
    /// keep up, not the steady state.
    fn wait_for_room(&self, n: usize) -> bool {
        let mut waited = false;
        loop {
            let queued = self.bytes.load(Ordering::Acquire);
            if queued == 0
                || queued.saturating_add(n) <= self.limit
                || self.writer_gone.load(Ordering::Acquire)
            {
                break;
            }
            waited = true;
            std::thread::sleep(std::time::Duration::from_micros(200));
        }
        let now = self.bytes.fetch_add(n, Ordering::AcqRel) + n;
        self.peak.fetch_max(now, Ordering::Relaxed);
        waited
    }

    /// The writer wrote a batch of `n` bytes.
    fn written(&self, n: usize) {
        self.bytes.fetch_sub(n, Ordering::AcqRel);
    }
}

/// Tells the parts the writer has stopped, however it stops (an error, a
/// panic), so that none waits for room forever.
struct WriterGone(Arc<Backlog>);

impl Drop for WriterGone {
    fn drop(&mut self) {
        self.0.writer_gone.store(true, Ordering::Release);
    }
}

/// One thread's observer of a recording: it encodes what it sees and queues
/// it to the writer thread.
struct Part {
    id: u16,
    tx: Option<SyncSender<Record>>,
    backlog: Arc<Backlog>,
    spare: Receiver<Vec<u8>>,
    /// Transfers and reads not yet sent (sent when [`BATCH_BYTES`] long, and
    /// before any other record, so the writer sees one part's events in order).
    batch: Vec<u8>,
    counts: Counts,
}

impl Part {
    fn new(id: u16, tx: SyncSender<Record>, backlog: Arc<Backlog>, nodes: usize) -> Part {
        let (give_back, spare) = channel::<Vec<u8>>();
        let mut part = Part {
            id,
            tx: Some(tx),
            backlog,
            spare,
            batch: Vec::with_capacity(BATCH_CAPACITY),
            counts: Counts {
                iterations: vec![0; nodes],
                last_of: vec![Time::ZERO; nodes],
                first_of: vec![None; nodes],
                ..Counts::default()
            },
        };
        part.send(Record::Part {
            part: id,
            give_back,
        });
        part
    }

    /// Send the batch (if not empty), then `record`.
    fn send(&mut self, record: Record) {
        self.flush();
        self.send_now(record);
    }

    /// Send the batch of transfers and reads, if not empty.
    fn flush(&mut self) {
        if self.batch.is_empty() || self.tx.is_none() {
            return;
        }
        if self.backlog.wait_for_room(self.batch.len()) {
            self.counts.waits += 1;
        }
        // A buffer the writer gave back, else a new one of a batch's size (one
        // allocation, not the dozen of a vector grown value by value).
        let mut next = self
            .spare
            .try_recv()
            .unwrap_or_else(|_| Vec::with_capacity(BATCH_CAPACITY));
        next.clear();
        let bytes = std::mem::replace(&mut self.batch, next);
        self.send_now(Record::Batch {
            part: self.id,
            bytes,
        });
    }

    fn send_now(&mut self, record: Record) {
        let Some(tx) = &self.tx else {
            return;
        };
        let sent = match tx.try_send(record) {
            Ok(()) => Ok(()),
            Err(TrySendError::Full(record)) => {
                self.counts.waits += 1;
                tx.send(record).map_err(|_| ())
            }
            Err(TrySendError::Disconnected(_)) => Err(()),
        };
        if sent.is_err() {
            // The writer failed: `finish` says why; the run goes on.
            self.tx = None;
        }
    }

    /// Hand the counts to the writer (then, if `end`, say the run finished)
    /// and let the writer go.
    fn close(&mut self, end: bool) {
        let counts = std::mem::take(&mut self.counts);
        self.send(Record::Counted(counts));
        if end {
            self.send(Record::End);
        }
        self.tx = None;
    }
}

impl Drop for Part {
    fn drop(&mut self) {
        if self.tx.is_some() {
            self.close(false);
        }
    }
}

impl Observer for Part {
    fn transition(&mut self, e: &TransitionEvent) {
        // A final behaviour's end is an activation without an action.
        if let Some(t) = self.counts.last_of.get_mut(e.node) {
            *t = (*t).max(e.time);
        }
        if let Some(t) = self.counts.first_of.get_mut(e.node) {
            t.get_or_insert(e.time);
        }
        self.send(Record::Transition {
            node: small(e.node),
            time: e.time,
            iteration: e.iteration,
            step: e.step,
        });
    }

    fn action(&mut self, e: &ActionEvent) {
        if let Some(n) = self.counts.iterations.get_mut(e.node) {
            *n += 1;
        }
        if let Some(t) = self.counts.last_of.get_mut(e.node) {
            *t = (*t).max(e.time);
        }
        if let Some(t) = self.counts.first_of.get_mut(e.node) {
            t.get_or_insert(e.time);
        }
        self.counts.last = self.counts.last.max(e.time);
    }

    fn transfer(&mut self, e: &TransferEvent, value: &dyn ErasedPayload) {
        if self.tx.is_none() {
            return;
        }
        let pushed = batch::push_transfer(&mut self.batch, small(e.link), e.stamp, |out| {
            value.encode(out)
        });
        if pushed.is_err() {
            self.counts.encode_failures += 1;
            return;
        }
        if self.batch.len() >= BATCH_BYTES {
            self.flush();
        }
    }

    fn read(&mut self, e: &ReadEvent) {
        if self.tx.is_none() {
            return;
        }
        batch::push_read(&mut self.batch, small(e.link), e.time, e.stamp);
        if self.batch.len() >= BATCH_BYTES {
            self.flush();
        }
    }

    fn received(&mut self, e: &ReadEvent, value: &dyn ErasedPayload) {
        if self.tx.is_none() {
            return;
        }
        let pushed = batch::push_received(&mut self.batch, small(e.link), e.stamp, |out| {
            value.encode(out)
        });
        if pushed.is_err() {
            self.counts.encode_failures += 1;
            return;
        }
        if self.batch.len() >= BATCH_BYTES {
            self.flush();
        }
    }

    fn error(&mut self, time: Time, error: &ExecError) {
        self.send(Record::Error {
            time,
            message: error.to_string(),
        });
    }
}

/// A link's channels and how to read its values.
struct LinkChannels {
    /// The link's topic (`/links/...`), and its raw channel's metadata.
    topic: String,
    raw_meta: BTreeMap<String, String>,
    /// The value's channel, and whether it is CDR (else JSON).
    value: u16,
    cdr: bool,
    raw: u16,
    reads: u16,
    read_sequence: u32,
    /// The payload's fingerprint, for the raw messages' wire header.
    fingerprint: u64,
    /// Values recorded: the MCAP sequence (wrapping) and, from 1, the wire
    /// header's.
    count: u64,
    /// Derived channels: (the derive, its channel).
    derived: Vec<(usize, u16)>,
    /// The codec of the raw channel.
    codec: Option<Arc<dyn Codec>>,
    /// Values not yet written to the raw channel ([`FRAMES_ENCODING`]), and
    /// the first one's instant.
    pending: Vec<u8>,
    pending_since: Time,
    /// Raw messages written: their MCAP sequence (wrapping).
    raw_messages: u32,
    /// The channel of values received from another process (made with the
    /// first), and how many.
    received: Option<u16>,
    received_count: u64,
}

impl McapRecorder {
    /// Record a run of `system` to `path` (created or truncated). The channels
    /// are made now, from the system's links and their payload shapes.
    pub fn create(
        path: &Path,
        system: &System,
        options: RecordOptions,
    ) -> Result<McapRecorder, RecordError> {
        let file = File::create(path).map_err(|source| RecordError::Create {
            path: path.to_owned(),
            source,
        })?;
        // Only what needs the system is taken here; the channels, schemas
        // and metadata are made on the writer thread (measured: 0.8 ms of a
        // 100 ms run of Rex's figure-eight when they were made here).
        let info = system.info().clone();
        let links = info.links.len();
        let plan = Plan {
            file,
            path: path.to_owned(),
            shapes: (0..links)
                .map(|k| {
                    let s = system.payload_shape(k)?;
                    serde_json::to_string(&(s.root, s.registry)).ok()
                })
                .collect(),
            fingerprints: (0..links)
                .map(|k| system.payload_fingerprint(k).unwrap_or(0))
                .collect(),
            info,
            options,
        };
        let nodes = plan.info.nodes.len();
        let (tx, rx) = sync_channel::<Record>(plan.options.queue.max(1));
        let background = plan.options.background;
        let backlog = Arc::new(Backlog::new(plan.options.queue_bytes));
        let gone = WriterGone(backlog.clone());
        let writer = std::thread::Builder::new()
            .name("mcap-writer".into())
            .spawn(move || {
                let gone = gone;
                let background = background && lowest_priority();
                let (mut out, shapes) = match Output::open(plan) {
                    Ok(opened) => opened,
                    Err(e) => {
                        drop(rx);
                        return Err(e);
                    }
                };
                out.summary.background = background;
                out.run(&rx, &shapes, &gone.0)
            })
            .map_err(|source| RecordError::Create {
                path: path.to_owned(),
                source,
            })?;
        Ok(McapRecorder {
            part: Part::new(0, tx, backlog.clone(), nodes),
            backlog,
            writer: Some(writer),
            path: path.to_owned(),
            nodes,
            parts: std::sync::Arc::new(std::sync::atomic::AtomicU16::new(1)),
        })
    }

    /// The observers of a real-time run, one per thread, for
    /// `RealTime::observe`: each queues to this recording's writer. Call
    /// [`McapRecorder::finish`] after the run's `join` (it waits until every
    /// thread's part is gone, so it must not be called while a `RealTime` that
    /// holds these is neither started nor dropped).
    pub fn threads(&self) -> impl FnMut(&str, &[usize]) -> Box<dyn Observer> + Send + 'static {
        let tx = self.part.tx.clone();
        let backlog = self.backlog.clone();
        let nodes = self.nodes;
        let ids = self.parts.clone();
        move |_thread: &str, _nodes: &[usize]| -> Box<dyn Observer> {
            let id = ids.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            match &tx {
                Some(tx) => Box::new(Part::new(id, tx.clone(), backlog.clone(), nodes)),
                // The writer already failed: `finish` says why.
                None => Box::new(agent_core::NoObserver),
            }
        }
    }

    /// The bytes of values queued to the writer thread and not yet written:
    /// how far behind the run the writer is now (the summary's
    /// `backlog_peak_bytes` is the most it was). Values not yet in a batch
    /// (under 64 KiB a thread) are not counted.
    pub fn backlog_bytes(&self) -> usize {
        self.backlog.bytes.load(Ordering::Acquire)
    }

    /// Whether the writer thread has stopped before the recording was
    /// finished: it failed (a full disk, most likely), and the run goes on
    /// unrecorded; [`McapRecorder::finish`] says why.
    pub fn has_failed(&self) -> bool {
        self.writer.is_some() && self.backlog.writer_gone.load(Ordering::Acquire)
    }

    /// The file being written.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Close the file (its summary and index) and say what it holds, or why
    /// the recording failed.
    pub fn finish(mut self) -> Result<RecordSummary, RecordError> {
        self.part.close(true);
        let writer = self
            .writer
            .take()
            .ok_or_else(|| RecordError::WriterGone(self.path.clone()))?;
        // The run is over: no need to wait for the writer's nap to end.
        writer.thread().unpark();
        writer
            .join()
            .map_err(|_| RecordError::WriterGone(self.path.clone()))?
    }
}

impl Drop for McapRecorder {
    fn drop(&mut self) {
        // Not finished: close the file anyway (errors are lost; `finish` says
        // them), without the `end` record that says the run was finished.
        self.part.close(false);
        if let Some(w) = self.writer.take() {
            w.thread().unpark();
            let _ = w.join();
        }
    }
}

impl Observer for McapRecorder {
    fn transition(&mut self, e: &TransitionEvent) {
        self.part.transition(e);
    }
    fn action(&mut self, e: &ActionEvent) {
        self.part.action(e);
    }
    fn transfer(&mut self, e: &TransferEvent, value: &dyn ErasedPayload) {
        self.part.transfer(e, value);
    }
    fn read(&mut self, e: &ReadEvent) {
        self.part.read(e);
    }
    fn received(&mut self, e: &ReadEvent, value: &dyn ErasedPayload) {
        self.part.received(e, value);
    }
    fn error(&mut self, time: Time, error: &ExecError) {
        self.part.error(time, error);
    }
}

fn small(i: usize) -> u32 {
    u32::try_from(i).unwrap_or(u32::MAX)
}
