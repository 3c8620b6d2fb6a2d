//! Publishing off the node's thread.
//!
//! A node's thread may be a real-time one (`SCHED_FIFO`), and Zenoh's `put` may
//! block it: on the locks its transmission pipeline shares with Zenoh's own
//! threads (which run at normal priority, so a busy machine preempts them while
//! they hold one: a priority inversion), and, for a reliable publisher, until
//! the pipeline has room: on a loaded machine Rex's 1 kHz plant blocked in
//! `put` for many of its periods (docs/measurements.md, "Publishing off the
//! node's thread"). So a publisher hands each message
//! to a wait-free bounded ring (`rtrb`) and wakes the transport's one publishing
//! thread (`Thread::unpark`: an atomic swap, a futex wake only when the thread
//! sleeps), which hands the messages to Zenoh in the order each ring received
//! them.
//!
//! A ring that is full (the publishing thread [`CAPACITY`] messages behind, or
//! [`SAMPLE_BYTES`] on a sample link) refuses: a queue link's message is an
//! error the node reports (never dropped silently); a sample link's newest
//! message is dropped and counted, as Zenoh's own congestion control would. What Zenoh refuses on the publishing thread is
//! reported by the publisher's next `put`. [`Outbox::flush`] waits until every
//! message put so far is in Zenoh's hands (before a session closes). The thread
//! ends once the outbox and all its publishers are gone and their rings drained.

use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::{JoinHandle, Thread};
use std::time::{Duration, Instant};

use agent_core::{Publisher, TransportError};

/// Where the publishing thread sends one key's messages.
pub(crate) trait Sink: Send + 'static {
    /// Send one message; an error is reported by the publisher's next `put`.
    fn send(&mut self, message: Vec<u8>) -> Result<(), String>;
}

/// What a full ring does with a message.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum WhenFull {
    /// Refuse it with an error (queue links: reliable).
    Refuse,
    /// Drop it and count it (sample links: the latest value matters).
    Drop,
}

/// The messages a ring holds, at most.
pub(crate) const CAPACITY: usize = 1024;

/// The bytes a sample link's ring holds, at most: its values may be images, of
/// which only the latest matters (16 stereo VGA pairs; a queue link's values are
/// small, and none may be lost, so only their number is bounded).
pub(crate) const SAMPLE_BYTES: usize = 10 << 20;

/// What a publisher and the publishing thread share about one key.
#[derive(Default)]
struct Health {
    /// Whether `error` holds an error not yet reported.
    failed: AtomicBool,
    error: Mutex<Option<String>>,
    /// The bytes in the ring.
    pending: AtomicUsize,
}

struct Outlet {
    ring: rtrb::Consumer<Vec<u8>>,
    sink: Box<dyn Sink>,
    health: Arc<Health>,
}

#[derive(Default)]
struct Shared {
    /// Outlets made since the thread last looked (setup time only).
    new: Mutex<Vec<Outlet>>,
    /// The outbox is gone: the thread ends when its outlets are.
    owner_gone: AtomicBool,
    /// Messages pushed into a ring, and handed from a ring to a sink.
    pushed: AtomicU64,
    handed: AtomicU64,
    /// Sample messages dropped by a full ring.
    dropped: AtomicU64,
}

struct Started {
    shared: Arc<Shared>,
    thread: Thread,
    #[cfg_attr(
        not(test),
        expect(dead_code, reason = "the tests ask it whether the thread ended")
    )]
    handle: JoinHandle<()>,
}

/// One transport's publishing thread (started with its first publisher) and
/// its rings.
pub(crate) struct Outbox {
    name: String,
    started: Mutex<Option<Started>>,
}

impl Outbox {
    /// An outbox whose thread, once started, is called `name`.
    pub(crate) fn new(name: &str) -> Outbox {
        Outbox {
            name: name.to_owned(),
            started: Mutex::new(None),
        }
    }

    /// A publisher whose messages the thread sends to `sink`.
    pub(crate) fn publisher(
        &self,
        sink: Box<dyn Sink>,
        when_full: WhenFull,
    ) -> std::io::Result<OutboxPublisher> {
        let mut started = self.started.lock().unwrap_or_else(PoisonError::into_inner);
        let started = match &mut *started {
            Some(s) => s,
            None => {
                let shared = Arc::new(Shared::default());
                let theirs = shared.clone();
                let handle = std::thread::Builder::new()
                    .name(self.name.clone())
                    .spawn(move || publish(&theirs))?;
                started.insert(Started {
                    shared,
                    thread: handle.thread().clone(),
                    handle,
                })
            }
        };
        let (tx, rx) = rtrb::RingBuffer::new(CAPACITY);
        let health = Arc::new(Health::default());
        started
            .shared
            .new
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(Outlet {
                ring: rx,
                sink,
                health: health.clone(),
            });
        started.thread.unpark();
        Ok(OutboxPublisher {
            ring: Some(tx),
            when_full,
            health,
            shared: started.shared.clone(),
            thread: started.thread.clone(),
        })
    }

    fn shared(&self) -> Option<Arc<Shared>> {
        let started = self.started.lock().unwrap_or_else(PoisonError::into_inner);
        started.as_ref().map(|s| s.shared.clone())
    }

    /// Sample messages dropped so far because their ring was full.
    pub(crate) fn dropped(&self) -> u64 {
        self.shared()
            .map_or(0, |s| s.dropped.load(Ordering::Relaxed))
    }

    /// Wait until every message put so far has been handed to its sink, for
    /// at most `timeout`; whether it was.
    pub(crate) fn flush(&self, timeout: Duration) -> bool {
        let Some(shared) = self.shared() else {
            return true;
        };
        let target = shared.pushed.load(Ordering::Acquire);
        let deadline = Instant::now() + timeout;
        while shared.handed.load(Ordering::Acquire) < target {
            if Instant::now() >= deadline {
                return false;
            }
            std::thread::sleep(Duration::from_micros(200));
        }
        true
    }

    /// Whether the publishing thread has ended (tests).
    #[cfg(test)]
    fn ended(&self) -> bool {
        let started = self.started.lock().unwrap_or_else(PoisonError::into_inner);
        started.as_ref().is_none_or(|s| s.handle.is_finished())
    }
}

impl Drop for Outbox {
    fn drop(&mut self) {
        let started = self.started.lock().unwrap_or_else(PoisonError::into_inner);
        if let Some(s) = started.as_ref() {
            s.shared.owner_gone.store(true, Ordering::Release);
            s.thread.unpark();
        }
    }
}

/// The publishing thread: drain every ring, sleep until woken (by a put, a new
/// publisher, a publisher's or the outbox's end).
fn publish(shared: &Shared) {
    let mut outlets: Vec<Outlet> = Vec::new();
    loop {
        // Read first: an owner gone before the draining below is seen gone.
        let owner_gone = shared.owner_gone.load(Ordering::Acquire);
        outlets.append(&mut shared.new.lock().unwrap_or_else(PoisonError::into_inner));
        for outlet in &mut outlets {
            while let Ok(message) = outlet.ring.pop() {
                outlet
                    .health
                    .pending
                    .fetch_sub(message.len(), Ordering::Relaxed);
                let sent = outlet.sink.send(message);
                if let Err(e) = sent {
                    *outlet
                        .health
                        .error
                        .lock()
                        .unwrap_or_else(PoisonError::into_inner) = Some(e);
                    outlet.health.failed.store(true, Ordering::Release);
                }
                shared.handed.fetch_add(1, Ordering::Release);
            }
        }
        // A publisher gone with its ring drained has nothing more to send (its
        // last push came before it was dropped, so `is_empty` sees it).
        outlets.retain(|o| !(o.ring.is_abandoned() && o.ring.is_empty()));
        // Nobody can make a publisher any more: end with the last outlet.
        if owner_gone && outlets.is_empty() {
            return;
        }
        std::thread::park();
    }
}

/// The node's end: `put` never blocks and never enters Zenoh.
pub(crate) struct OutboxPublisher {
    /// `None` only while dropping: the ring is dropped before the thread is woken.
    ring: Option<rtrb::Producer<Vec<u8>>>,
    when_full: WhenFull,
    health: Arc<Health>,
    shared: Arc<Shared>,
    thread: Thread,
}

impl Publisher for OutboxPublisher {
    fn put(&mut self, message: &[u8]) -> Result<(), TransportError> {
        if self.health.failed.swap(false, Ordering::Acquire) {
            let error = self
                .health
                .error
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .take();
            if let Some(e) = error {
                return Err(TransportError(format!("an earlier message: {e}")));
            }
        }
        let len = message.len();
        // An empty ring takes a sample of any size.
        let pending = self.health.pending.load(Ordering::Relaxed);
        let room =
            self.when_full == WhenFull::Refuse || pending == 0 || pending + len <= SAMPLE_BYTES;
        // Counted before the push, so that the thread's count after its pop
        // never goes below zero.
        let pushed = room && {
            self.health.pending.fetch_add(len, Ordering::Relaxed);
            let pushed = self
                .ring
                .as_mut()
                .is_some_and(|ring| ring.push(message.to_vec()).is_ok());
            if !pushed {
                self.health.pending.fetch_sub(len, Ordering::Relaxed);
            }
            pushed
        };
        self.thread.unpark();
        match (pushed, self.when_full) {
            (true, _) => {
                self.shared.pushed.fetch_add(1, Ordering::Release);
                Ok(())
            }
            (false, WhenFull::Drop) => {
                self.shared.dropped.fetch_add(1, Ordering::Relaxed);
                Ok(())
            }
            (false, WhenFull::Refuse) => Err(TransportError(format!(
                "{CAPACITY} messages wait for the publishing thread"
            ))),
        }
    }
}

impl Drop for OutboxPublisher {
    fn drop(&mut self) {
        // The thread drops this ring's outlet once it is drained.
        drop(self.ring.take());
        self.thread.unpark();
    }
}

#[cfg(test)]
#[path = "outbox_tests.rs"]
mod tests;
