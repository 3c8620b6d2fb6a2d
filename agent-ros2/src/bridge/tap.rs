//! The node's end of the bridge: an [`Observer`] that copies each published
//! value's bytes into a slot of a bounded, wait-free ring and wakes the
//! publishing thread. It never blocks and never enters Zenoh.
//!
//! A tap owns two rings with the publishing thread: `full` carries slots to
//! it, `free` brings their byte buffers back. The buffers circulate, so once
//! each has grown to the size of the values it carries, a value costs no
//! allocation on the node's thread (the first values into a fresh buffer, or a
//! value larger than any before, do grow it). When no buffer is free (the
//! publishing thread is a whole ring behind) the value is dropped and counted,
//! or, for a run that is not real time ([`Shared::wait`]), waited for: the
//! node's thread wakes the publishing thread and yields until a buffer comes
//! back, for at most the time given (then it drops, and counts).

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::thread::Thread;
use std::time::{SystemTime, UNIX_EPOCH};

use agent_core::Stamp;
use agent_core::trace::{ErasedPayload, Observer, TransferEvent};

/// One value on its way to the publishing thread.
pub(crate) struct Slot {
    /// The topic (index into the plan's topics).
    pub(crate) topic: usize,
    /// The value's stamp: its sender's iteration and instant.
    pub(crate) stamp: Stamp,
    /// When it was sent \[ns since the UNIX epoch\].
    pub(crate) wall_ns: i64,
    /// Its postcard bytes.
    pub(crate) bytes: Vec<u8>,
}

/// The publishing thread's end of a tap's rings.
pub(crate) struct Outlet {
    pub(crate) full: rtrb::Consumer<Slot>,
    pub(crate) free: rtrb::Producer<Vec<u8>>,
}

/// A topic's counts, shared by the taps and the publishing thread.
#[derive(Debug, Default)]
pub(crate) struct Counts {
    pub(crate) published: AtomicU64,
    pub(crate) dropped: AtomicU64,
    pub(crate) encode_failures: AtomicU64,
    pub(crate) put_failures: AtomicU64,
}

/// What the taps and the publishing thread share.
pub(crate) struct Shared {
    /// The topics each link's values go to (index: link).
    pub(crate) by_link: Vec<Vec<usize>>,
    /// The counts, per topic.
    pub(crate) counts: Vec<Counts>,
    /// Outlets of taps made since the publishing thread last looked.
    pub(crate) new: Mutex<Vec<Outlet>>,
    /// The bridge is finishing: drain once more and end.
    pub(crate) stop: std::sync::atomic::AtomicBool,
    /// The byte buffers of each new tap's ring.
    pub(crate) slots: usize,
    /// How long a tap waits for a free buffer before it drops a value
    /// (`None`: not at all).
    pub(crate) wait: Option<std::time::Duration>,
}

/// An [`Observer`] that hands the values of published links to the bridge's
/// publishing thread (see the module's documentation).
pub(crate) struct Tap {
    full: rtrb::Producer<Slot>,
    free: rtrb::Consumer<Vec<u8>>,
    /// A buffer taken and not sent (its value failed to encode).
    spare: Option<Vec<u8>>,
    shared: Arc<Shared>,
    thread: Thread,
}

/// The first capacity of a slot's buffer \[bytes\].
const FIRST_CAPACITY: usize = 256;

impl Tap {
    /// A tap whose rings the publishing thread `thread` drains.
    pub(crate) fn new(shared: Arc<Shared>, thread: Thread) -> Tap {
        let slots = shared.slots.max(1);
        let (full, full_rx) = rtrb::RingBuffer::new(slots);
        let (mut free_tx, free) = rtrb::RingBuffer::new(slots);
        for _ in 0..slots {
            // The ring has room for exactly these.
            let _ = free_tx.push(Vec::with_capacity(FIRST_CAPACITY));
        }
        shared
            .new
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .push(Outlet {
                full: full_rx,
                free: free_tx,
            });
        thread.unpark();
        Tap {
            full,
            free,
            spare: None,
            shared,
            thread,
        }
    }

    /// Hand one value to the publishing thread for `topic`.
    fn hand(&mut self, topic: usize, stamp: Stamp, value: &dyn ErasedPayload) {
        let bytes = self
            .spare
            .take()
            .or_else(|| self.free.pop().ok())
            .or_else(|| self.wait_for_buffer());
        let counts = &self.shared.counts[topic];
        let Some(mut bytes) = bytes else {
            counts.dropped.fetch_add(1, Ordering::Relaxed);
            return;
        };
        bytes.clear();
        if value.encode(&mut bytes).is_err() {
            counts.encode_failures.fetch_add(1, Ordering::Relaxed);
            self.spare = Some(bytes);
            return;
        }
        let slot = Slot {
            topic,
            stamp,
            wall_ns: now_ns(),
            bytes,
        };
        match self.full.push(slot) {
            Ok(()) => self.thread.unpark(),
            // Never: there are no more buffers than the ring holds.
            Err(rtrb::PushError::Full(slot)) => {
                counts.dropped.fetch_add(1, Ordering::Relaxed);
                self.spare = Some(slot.bytes);
            }
        }
    }
}

impl Tap {
    /// A buffer given back by the publishing thread within the tap's wait, if
    /// it waits (see the module's documentation); `None` when it does not,
    /// when the time is up, or when the bridge is finishing.
    fn wait_for_buffer(&mut self) -> Option<Vec<u8>> {
        let wait = self.shared.wait?;
        let until = std::time::Instant::now() + wait;
        loop {
            self.thread.unpark();
            std::thread::yield_now();
            if let Ok(bytes) = self.free.pop() {
                return Some(bytes);
            }
            if self.shared.stop.load(Ordering::Relaxed) || std::time::Instant::now() >= until {
                return None;
            }
            std::thread::sleep(std::time::Duration::from_micros(50));
        }
    }
}

/// The wall clock \[ns since the UNIX epoch\] (0 before it, saturating).
pub(crate) fn now_ns() -> i64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| i64::try_from(d.as_nanos()).unwrap_or(i64::MAX))
}

impl Observer for Tap {
    fn transfer(&mut self, event: &TransferEvent, value: &dyn ErasedPayload) {
        let n = self.shared.by_link.get(event.link).map_or(0, Vec::len);
        for k in 0..n {
            let topic = self.shared.by_link[event.link][k];
            self.hand(topic, event.stamp, value);
        }
    }
}

impl Drop for Tap {
    fn drop(&mut self) {
        // The publishing thread drops the outlet once it is abandoned and drained.
        self.thread.unpark();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use agent_core::Time;
    use std::sync::atomic::AtomicBool;

    fn shared(slots: usize) -> Arc<Shared> {
        Arc::new(Shared {
            // Link 1 is published as topic 0; link 0 is not.
            by_link: vec![vec![], vec![0]],
            counts: vec![Counts::default()],
            new: Mutex::new(Vec::new()),
            stop: AtomicBool::new(false),
            slots,
            wait: None,
        })
    }

    fn send(tap: &mut Tap, link: usize, k: u32) {
        let stamp = Stamp::new(u64::from(k), Time::from_nanos(u64::from(k) * 10));
        tap.transfer(&TransferEvent { link, stamp }, &k);
    }

    /// No publishing thread drains the rings (this thread stands for it): a
    /// ring of 2 slots takes 2 values and drops the next ones, counting
    /// them; a buffer given back takes a value again.
    #[test]
    fn a_full_ring_drops_and_counts_and_never_blocks() {
        let shared = shared(2);
        let mut tap = Tap::new(shared.clone(), std::thread::current());
        for k in 0..5 {
            send(&mut tap, 1, k);
        }
        send(&mut tap, 0, 9);
        let counts = &shared.counts[0];
        assert_eq!(counts.dropped.load(Ordering::Relaxed), 3);
        assert_eq!(counts.encode_failures.load(Ordering::Relaxed), 0);
        let mut outlet = shared
            .new
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .remove(0);
        let Ok(first) = outlet.full.pop() else {
            panic!("no slot")
        };
        assert_eq!((first.topic, first.stamp.iteration), (0, 0));
        // postcard's varint of 0.
        assert_eq!(first.bytes, [0]);
        assert!(first.wall_ns > 0);
        assert!(outlet.free.push(first.bytes).is_ok());
        send(&mut tap, 1, 300);
        assert_eq!(counts.dropped.load(Ordering::Relaxed), 3);
        let values: Vec<Vec<u8>> = std::iter::from_fn(|| outlet.full.pop().ok())
            .map(|s| s.bytes)
            .collect();
        assert_eq!(values, [vec![1], vec![0xac, 0x02]]);
    }

    /// A tap that waits: a full ring holds the node's thread until the
    /// publishing thread (here another thread) gives a buffer back, and no
    /// value is dropped; with nobody draining, it drops after its wait.
    #[test]
    fn a_waiting_tap_loses_nothing_while_the_publisher_drains() {
        let mut waiting = shared(2);
        if let Some(s) = Arc::get_mut(&mut waiting) {
            s.wait = Some(std::time::Duration::from_secs(10));
        }
        let drainer = {
            let shared = waiting.clone();
            std::thread::spawn(move || {
                let mut got = Vec::new();
                while got.len() < 50 {
                    let outlet = shared
                        .new
                        .lock()
                        .unwrap_or_else(PoisonError::into_inner)
                        .pop();
                    let Some(mut outlet) = outlet else {
                        std::thread::park_timeout(std::time::Duration::from_millis(1));
                        continue;
                    };
                    while got.len() < 50 {
                        match outlet.full.pop() {
                            Ok(slot) => {
                                got.push(slot.stamp.iteration);
                                let _ = outlet.free.push(slot.bytes);
                            }
                            Err(_) => {
                                std::thread::park_timeout(std::time::Duration::from_millis(1))
                            }
                        }
                    }
                }
                got
            })
        };
        let mut tap = Tap::new(waiting.clone(), drainer.thread().clone());
        for k in 0..50 {
            send(&mut tap, 1, k);
        }
        let got = drainer.join().unwrap_or_default();
        assert_eq!(got, (0..50).collect::<Vec<u64>>());
        assert_eq!(waiting.counts[0].dropped.load(Ordering::Relaxed), 0);

        let mut brief = shared(1);
        if let Some(s) = Arc::get_mut(&mut brief) {
            s.wait = Some(std::time::Duration::from_millis(20));
        }
        let mut tap = Tap::new(brief.clone(), std::thread::current());
        send(&mut tap, 1, 0);
        send(&mut tap, 1, 1);
        assert_eq!(brief.counts[0].dropped.load(Ordering::Relaxed), 1);
    }
}
