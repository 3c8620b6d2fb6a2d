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
//! * `/predicates/<node>` (JSON, made with its first message): after each
//!   activation of a subsystem, the values of the predicates an observer
//!   beside the recorder asked the executor for
//!   ([`Observer::predicates_wanted`]: a contract monitor's invariants; the
//!   recorder asks for none itself, so a run without invariants records
//!   none), with the instant and the iteration: what the invariants are
//!   judged by over a recording;
//! * `/errors`: every error the executor met, with its time;
//! * `/timing`: a real-time run's timing statistics, one JSON message per
//!   process at its end ([`McapRecorder::timing`], [`crate::timing`]); a
//!   deterministic run has none (no wall clock).
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

use std::fs::File;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::sync::mpsc::sync_channel;
use std::thread::JoinHandle;

use agent_core::trace::{
    ActionEvent, ErasedPayload, Observer, ReadEvent, TransferEvent, TransitionEvent,
};
use agent_core::{ExecError, Stamp, System, Time, Valuation};

mod batch;
mod frames;
mod open;
mod options;
mod part;
mod writer;

pub use frames::{FRAMES_ENCODING, WIRE_ENCODING, raw_values};
pub use options::{Derive, DerivedChannel, RecordError, RecordOptions, RecordSummary, Values};

use open::Plan;
use part::{Backlog, Part, Record, WriterGone};
use writer::Output;
pub(crate) use writer::transition_json;

/// The metadata key of a CDR value channel (`/links/...`) that holds its
/// payload's shape: `serde-reflection`'s root format and registry as JSON,
/// what [`read_cdr`](crate::cdr::read_cdr) reads a value back by without the
/// Rust type ([`ChannelInfo::payload_shape`](crate::read::ChannelInfo::payload_shape)).
pub const SHAPE_KEY: &str = "shape";

/// The topic of a node's predicates after each activation:
/// `/predicates/<node>`.
pub const PREDICATES_PREFIX: &str = "/predicates/";

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

    /// Write the real-time executor's timing statistics on the `/timing`
    /// channel (made with its first message), stamped `time` (the run's last
    /// instant). Call it after the run's `join`, before [`McapRecorder::finish`].
    pub fn timing(&mut self, time: Time, stats: &crate::timing::TimingStats) {
        let json = stats.to_json();
        self.part.send(Record::Timing { time, json });
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
    fn predicates(&mut self, e: &ActionEvent, values: Valuation) {
        self.part.predicates(e, values);
    }
    fn error(&mut self, time: Time, error: &ExecError) {
        self.part.error(time, error);
    }
}

fn small(i: usize) -> u32 {
    u32::try_from(i).unwrap_or(u32::MAX)
}
