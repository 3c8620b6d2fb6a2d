//! The executor's side of a recording: one `Part` per thread encodes what
//! its observer sees into batches and queues them, with the switches, errors
//! and counts, to the writer thread, within the `Backlog`'s bound.

use std::convert::Infallible;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::sync::mpsc::{Receiver, Sender, SyncSender, TrySendError, channel};

use agent_core::trace::{
    ActionEvent, ErasedPayload, Observer, ReadEvent, TransferEvent, TransitionEvent,
};
use agent_core::{ExecError, Step, Time, Valuation};

use super::batch::{self, BATCH_BYTES, BATCH_CAPACITY};
use super::small;

/// What a part queues to the writer thread.
pub(super) enum Record {
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
    /// The real-time executor's timing statistics of one process (JSON), at
    /// the run's last instant.
    Timing {
        time: Time,
        json: String,
    },
    /// The recording's owner finished it.
    End,
}

/// What one part counted.
#[derive(Default)]
pub(super) struct Counts {
    pub(super) iterations: Vec<u64>,
    /// Per node: the instant of its last activation.
    pub(super) last_of: Vec<Time>,
    /// Per node: the instant of its first activation (`None`: none yet).
    pub(super) first_of: Vec<Option<Time>>,
    pub(super) last: Time,
    pub(super) waits: u64,
    pub(super) encode_failures: u64,
}

impl Counts {
    pub(super) fn add(&mut self, other: &Counts) {
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

/// The bytes of batches queued to the writer and not yet written, shared by
/// the parts (which add) and the writer (which takes away, and says when it
/// has stopped).
#[derive(Debug)]
pub(super) struct Backlog {
    pub(super) bytes: AtomicUsize,
    pub(super) peak: AtomicUsize,
    pub(super) limit: usize,
    pub(super) writer_gone: AtomicBool,
}

impl Backlog {
    pub(super) fn new(limit: usize) -> Backlog {
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
    pub(super) fn written(&self, n: usize) {
        self.bytes.fetch_sub(n, Ordering::AcqRel);
    }
}

/// Tells the parts the writer has stopped, however it stops (an error, a
/// panic), so that none waits for room forever.
pub(super) struct WriterGone(pub(super) Arc<Backlog>);

impl Drop for WriterGone {
    fn drop(&mut self) {
        self.0.writer_gone.store(true, Ordering::Release);
    }
}

/// One thread's observer of a recording: it encodes what it sees and queues
/// it to the writer thread.
pub(super) struct Part {
    pub(super) id: u16,
    pub(super) tx: Option<SyncSender<Record>>,
    pub(super) backlog: Arc<Backlog>,
    pub(super) spare: Receiver<Vec<u8>>,
    /// Transfers and reads not yet sent (sent when [`BATCH_BYTES`] long, and
    /// before any other record, so the writer sees one part's events in order).
    pub(super) batch: Vec<u8>,
    pub(super) counts: Counts,
}

impl Part {
    pub(super) fn new(
        id: u16,
        tx: SyncSender<Record>,
        backlog: Arc<Backlog>,
        nodes: usize,
    ) -> Part {
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
    pub(super) fn send(&mut self, record: Record) {
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

    /// Append one entry to the batch with `push` (nothing without a writer),
    /// count it as an encode failure if `push` fails (it leaves the batch as it
    /// was), and send the batch once it is [`BATCH_BYTES`] long.
    fn push<E>(&mut self, push: impl FnOnce(&mut Vec<u8>) -> Result<(), E>) {
        if self.tx.is_none() {
            return;
        }
        if push(&mut self.batch).is_err() {
            self.counts.encode_failures += 1;
            return;
        }
        if self.batch.len() >= BATCH_BYTES {
            self.flush();
        }
    }

    /// Hand the counts to the writer (then, if `end`, say the run finished)
    /// and let the writer go.
    pub(super) fn close(&mut self, end: bool) {
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
        self.push(|out| batch::push_transfer(out, small(e.link), e.stamp, |b| value.encode(b)));
    }

    fn read(&mut self, e: &ReadEvent) {
        self.push(|out| {
            batch::push_read(out, small(e.link), e.time, e.stamp);
            Ok::<(), Infallible>(())
        });
    }

    fn received(&mut self, e: &ReadEvent, value: &dyn ErasedPayload) {
        self.push(|out| batch::push_received(out, small(e.link), e.stamp, |b| value.encode(b)));
    }

    fn predicates(&mut self, e: &ActionEvent, values: Valuation) {
        self.push(|out| {
            batch::push_predicates(out, small(e.node), e.time, e.iteration, values);
            Ok::<(), Infallible>(())
        });
    }

    fn error(&mut self, time: Time, error: &ExecError) {
        self.send(Record::Error {
            time,
            message: error.to_string(),
        });
    }
}
