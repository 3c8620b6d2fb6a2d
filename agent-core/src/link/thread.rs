//! Links between threads, for the real-time executor: the same semantics as the
//! in-process channels, without a lock.
//!
//! * Sample: a wait-free triple buffer (`triple_buffer`). The writer publishes
//!   the latest value with its stamp; the reader takes it if it is new. A value
//!   published before the previous one was read is counted as overwritten.
//! * Queue: a wait-free bounded single-producer single-consumer ring (`rtrb`),
//!   allocated once with the link's bound. A value sent into a full ring is
//!   refused and reported, as in-process.
//!
//! Values move: the writer's storage goes into the link, and the reader's previous
//! storage goes back into the triple buffer, so `Vec`-like payloads recycle their
//! storage and `Copy` payloads never allocate after the link is made.
//!
//! Reads are causal: an activation of instant `t` takes only a value stamped at
//! or before `t`. A thread that runs late (woken after its instant, or catching
//! up after an overrun) may find a value its sender stamped after the instant it
//! is running; that value stays in the link (sample: held, and replaced if a newer
//! one arrives, which counts as overwritten; queue: at the front of the ring) until
//! an activation whose instant reaches its stamp. A node therefore never sees a
//! value from its own future, as in the deterministic executor.

use std::sync::Arc;
use std::sync::atomic::Ordering;

use crate::buffer::{In, Out, Payload};
use crate::kinds::Policy;
use crate::time::{Stamp, Time};
use crate::trace::{ReadEvent, TransferEvent};

use super::remote::{RemoteRx, RemoteTx};
pub(crate) use super::stats::SharedStats;
use super::{Access, Cause, InPort, LinkCx, OutPort, Port, Refused, observe_read};
use crate::error::LinkError;

/// What a sample link's triple buffer holds.
#[derive(Clone)]
pub(crate) struct Slot<T> {
    value: Option<T>,
    stamp: Stamp,
}

/// The sending half of a link between threads.
pub(crate) enum ThreadTx<T: Send> {
    Sample(triple_buffer::Input<Slot<T>>, Arc<SharedStats>),
    Queue(rtrb::Producer<(T, Stamp)>, usize, Arc<SharedStats>),
    /// To another process.
    Remote(RemoteTx),
}

/// The receiving half of a link between threads.
pub(crate) enum ThreadRx<T: Send> {
    /// The flag: the output buffer holds a value taken from the triple buffer
    /// and not yet delivered (stamped after the instant that took it).
    Sample(triple_buffer::Output<Slot<T>>, Arc<SharedStats>, bool),
    Queue(rtrb::Consumer<(T, Stamp)>, Arc<SharedStats>),
    /// From another process.
    Remote(RemoteRx),
    /// The link's own half, and a feed from outside the system (another
    /// middleware: [`RealTime::feed`](crate::RealTime::feed)), read in turn
    /// when both hold a value.
    Fed(Box<Fed<T>>),
}

/// A link's receiving half with a feed beside it.
pub(crate) struct Fed<T: Send> {
    pub(crate) link: ThreadRx<T>,
    pub(crate) feed: RemoteRx,
    /// The feed is tried first at the next read (it was not taken last).
    pub(crate) feed_first: bool,
    /// The last read's value came from the feed.
    pub(crate) from_feed: bool,
}

/// The two halves and the counters of a new link between threads.
pub(crate) fn channel<T: Payload>(policy: Policy) -> (ThreadTx<T>, ThreadRx<T>, Arc<SharedStats>) {
    let stats = Arc::new(SharedStats::default());
    match policy {
        Policy::Sample => {
            let (tx, rx) = triple_buffer::triple_buffer(&Slot {
                value: None,
                stamp: Stamp::new(0, Time::ZERO),
            });
            (
                ThreadTx::Sample(tx, stats.clone()),
                ThreadRx::Sample(rx, stats.clone(), false),
                stats,
            )
        }
        Policy::Queue { bound } => {
            let bound = bound.max(1);
            let (tx, rx) = rtrb::RingBuffer::new(bound);
            (
                ThreadTx::Queue(tx, bound, stats.clone()),
                ThreadRx::Queue(rx, stats.clone()),
                stats,
            )
        }
    }
}

impl<T: Payload> ThreadTx<T> {
    /// As the in-process channel's `put`: with `last` the value moves (the storage
    /// it replaces is left in `value`), otherwise it is cloned.
    #[inline]
    pub(crate) fn put(
        &mut self,
        value: &mut Option<T>,
        last: bool,
        stamp: Stamp,
    ) -> Result<(), Cause> {
        match self {
            ThreadTx::Sample(tx, stats) => {
                let slot = tx.input_buffer_mut();
                if last {
                    std::mem::swap(&mut slot.value, value);
                } else {
                    slot.value.clone_from(value);
                }
                slot.stamp = stamp;
                if tx.publish() {
                    stats.overwritten.fetch_add(1, Ordering::Relaxed);
                }
                stats.sent.fetch_add(1, Ordering::Relaxed);
                Ok(())
            }
            ThreadTx::Queue(tx, bound, stats) => {
                if tx.is_full() {
                    stats.overflowed.fetch_add(1, Ordering::Relaxed);
                    return Err(Cause::Full(*bound));
                }
                let v = if last { value.take() } else { value.clone() };
                if let Some(v) = v {
                    // Only this thread pushes, and the ring had room.
                    if tx.push((v, stamp)).is_err() {
                        stats.overflowed.fetch_add(1, Ordering::Relaxed);
                        return Err(Cause::Full(*bound));
                    }
                }
                let pending = *bound - tx.slots();
                stats.max_pending.fetch_max(pending, Ordering::Relaxed);
                stats.sent.fetch_add(1, Ordering::Relaxed);
                Ok(())
            }
            ThreadTx::Remote(tx) => match value.as_ref() {
                Some(v) => tx
                    .put(v, stamp)
                    .map_err(|p| Cause::Remote(tx.key().clone(), p)),
                None => Ok(()),
            },
        }
    }
}

impl<T: Payload> ThreadRx<T> {
    /// Take what the link holds for an activation of instant `now` (only a value
    /// stamped at or before it; [`Time::NEVER`] takes anything); a link from
    /// another process may report a problem instead (key, problem).
    #[inline]
    pub(crate) fn take_into(
        &mut self,
        x: &mut In<T>,
        now: Time,
    ) -> Result<(), (Arc<str>, crate::error::RemoteProblem)> {
        match self {
            ThreadRx::Sample(rx, stats, held) => {
                // A value held for a later instant and replaced by a newer one
                // before any activation could take it was overwritten.
                if rx.update() && std::mem::replace(held, true) {
                    stats.overwritten.fetch_add(1, Ordering::Relaxed);
                }
                let slot = rx.output_buffer_mut();
                if *held && slot.stamp.time <= now {
                    *held = false;
                    x.swap_in(&mut slot.value, slot.stamp);
                    stats.delivered.fetch_add(1, Ordering::Relaxed);
                } else {
                    x.age();
                }
            }
            ThreadRx::Queue(rx, stats) => match rx.peek() {
                Ok((_, stamp)) if stamp.time <= now => {
                    if let Ok((v, stamp)) = rx.pop() {
                        x.swap_in(&mut Some(v), stamp);
                        stats.delivered.fetch_add(1, Ordering::Relaxed);
                    }
                }
                _ => x.age(),
            },
            ThreadRx::Remote(rx) => {
                return rx
                    .inbox
                    .take_into(x, now)
                    .map_err(|p| (rx.inbox.key_arc(), p));
            }
            ThreadRx::Fed(fed) => return fed.take_into(x, now),
        }
        Ok(())
    }

    /// Whether the value the last read brought came from another process or
    /// from outside the system (the observer keeps such values: a replay
    /// needs them).
    pub(crate) fn took_from_away(&self) -> bool {
        match self {
            ThreadRx::Remote(_) => true,
            ThreadRx::Fed(fed) => fed.from_feed || fed.link.took_from_away(),
            ThreadRx::Sample(..) | ThreadRx::Queue(..) => false,
        }
    }
}

impl<T: Payload> Fed<T> {
    /// One value from the link or the feed: the one whose turn it is if it
    /// holds a value due at `now`, else the other's. Neither starves the
    /// other: after a value from one, the other is tried first.
    fn take_into(
        &mut self,
        x: &mut In<T>,
        now: Time,
    ) -> Result<(), (Arc<str>, crate::error::RemoteProblem)> {
        let inbox = &self.feed.inbox;
        let from_feed = |x: &mut In<T>| inbox.take_into(x, now).map_err(|p| (inbox.key_arc(), p));
        self.from_feed = false;
        if self.feed_first {
            from_feed(x)?;
            if x.took() {
                self.feed_first = false;
                self.from_feed = true;
                return Ok(());
            }
            self.link.take_into(x, now)?;
        } else {
            self.link.take_into(x, now)?;
            if x.took() {
                self.feed_first = true;
                return Ok(());
            }
            from_feed(x)?;
            self.from_feed = x.took();
        }
        if x.took() {
            self.feed_first = !self.from_feed;
        }
        Ok(())
    }
}

/// The sending port of an output buffer whose links go to other threads.
pub(crate) struct ThreadOut<O, T: Send, A> {
    pub(crate) port: Port<O, Out<T>, A>,
    /// (link index, sending half), one per destination.
    pub(crate) links: Vec<(usize, ThreadTx<T>)>,
    /// Whether a destination is in another process: its half hears of the
    /// activations without a write (a held value may be due).
    pub(crate) away: bool,
}

impl<O, T: Payload, A> ThreadOut<O, T, A> {
    /// Every half to another process, told of the activation at `now`
    /// ([`RemoteTx::idle`]), or told to publish what it holds (`now`: `None`).
    fn remote_halves(&mut self, now: Option<Time>) -> Result<(), Refused> {
        let mut result = Ok(());
        for (link, tx) in &mut self.links {
            if let ThreadTx::Remote(tx) = tx {
                let r = match now {
                    Some(now) => tx.idle(now),
                    None => tx.flush(),
                };
                if let (Err(problem), true) = (r, result.is_ok()) {
                    result = Err(Refused {
                        link: *link,
                        cause: Cause::Remote(tx.key().clone(), problem),
                    });
                }
            }
        }
        result
    }
}

impl<O: 'static, T: Payload, A: Access<O, Out<T>>> OutPort<O> for ThreadOut<O, T, A> {
    #[inline]
    fn send(&mut self, y: &mut O, stamp: Stamp, cx: &mut LinkCx<'_>) -> Result<(), Refused> {
        let Some(value) = self.port.get(y).pending() else {
            return if self.away {
                self.remote_halves(Some(stamp.time))
            } else {
                Ok(())
            };
        };
        let n = self.links.len();
        let mut result = Ok(());
        for (k, (link, tx)) in self.links.iter_mut().enumerate() {
            if let (Some(obs), Some(v)) = (cx.observer.as_deref_mut(), value.as_ref()) {
                obs.transfer(&TransferEvent { link: *link, stamp }, v);
            }
            let r = tx
                .put(value, k + 1 == n, stamp)
                .map_err(|cause| Refused { link: *link, cause });
            if result.is_ok() {
                result = r;
            }
        }
        result
    }

    fn discard(&mut self, y: &mut O) {
        self.port.get(y).discard();
    }

    fn flush(&mut self) -> Result<(), Refused> {
        if self.away {
            self.remote_halves(None)
        } else {
            Ok(())
        }
    }
}

/// The receiving port of an input buffer fed from another thread.
pub(crate) struct ThreadIn<I, T: Send, A> {
    pub(crate) port: Port<I, In<T>, A>,
    pub(crate) rx: ThreadRx<T>,
    pub(crate) name: std::borrow::Cow<'static, str>,
    pub(crate) link: usize,
}

impl<I: 'static, T: Payload, A: Access<I, In<T>>> InPort<I> for ThreadIn<I, T, A> {
    #[inline]
    fn read(&mut self, x: &mut I, cx: &mut LinkCx<'_>) -> Result<(), LinkError> {
        let x = self.port.get(x);
        let taken = self.rx.take_into(x, cx.time);
        observe_read(x, self.link, cx);
        // A value from another process (or fed from outside the system):
        // the observer keeps it too.
        if let (true, Some(obs), Some(v), Some(stamp)) = (
            self.rx.took_from_away(),
            cx.observer.as_deref_mut(),
            x.fresh(),
            x.stamp(),
        ) {
            obs.received(
                &ReadEvent {
                    time: cx.time,
                    link: self.link,
                    stamp,
                },
                v,
            );
        }
        taken.map_err(|(key, problem)| LinkError::Remote {
            link: cx
                .links
                .get(self.link)
                .map(|l| l.name.clone())
                .unwrap_or_default(),
            key: key.to_string(),
            problem,
        })
    }

    fn attach(&self, x: &mut I) {
        self.port.get(x).set_name(self.name.clone());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stamp(i: u64) -> Stamp {
        Stamp::new(i, Time::from_nanos(i))
    }

    #[test]
    fn sample_between_threads_keeps_the_latest_and_counts_overwrites() {
        let (mut tx, mut rx, stats) = channel::<u32>(Policy::Sample);
        let mut x = In::default();
        rx.take_into(&mut x, Time::NEVER).unwrap();
        assert!(!x.is_new() && !x.has_data());
        tx.put(&mut Some(1), true, stamp(1)).unwrap();
        tx.put(&mut Some(2), true, stamp(2)).unwrap();
        rx.take_into(&mut x, Time::NEVER).unwrap();
        assert_eq!((x.fresh(), x.stamp()), (Some(&2), Some(stamp(2))));
        rx.take_into(&mut x, Time::NEVER).unwrap();
        assert!(!x.is_new());
        assert_eq!(x.get(), Some(&2));
        let s = stats.snapshot();
        assert_eq!((s.sent, s.delivered, s.overwritten), (2, 1, 1));
    }

    #[test]
    fn queue_between_threads_is_lossless_ordered_and_bounded() {
        let (mut tx, mut rx, stats) = channel::<u32>(Policy::queue(2));
        tx.put(&mut Some(1), true, stamp(1)).unwrap();
        tx.put(&mut Some(2), false, stamp(2)).unwrap();
        assert_eq!(tx.put(&mut Some(3), true, stamp(3)), Err(Cause::Full(2)));
        let mut x = In::default();
        for expect in [Some(1), Some(2)] {
            rx.take_into(&mut x, Time::NEVER).unwrap();
            assert_eq!(x.fresh().copied(), expect);
        }
        rx.take_into(&mut x, Time::NEVER).unwrap();
        assert!(!x.is_new());
        let s = stats.snapshot();
        assert_eq!(
            (s.sent, s.delivered, s.overflowed, s.max_pending),
            (2, 2, 1, 2)
        );
    }

    #[test]
    fn a_late_activation_never_takes_a_value_from_its_future() {
        let at = Time::from_nanos;
        // Sample: the value stamped 5 waits for the activation of instant 5; one
        // replaced while it waits counts as overwritten.
        let (mut tx, mut rx, stats) = channel::<u32>(Policy::Sample);
        let mut x = In::default();
        tx.put(&mut Some(5), true, stamp(5)).unwrap();
        rx.take_into(&mut x, at(3)).unwrap();
        assert!(!x.is_new() && !x.has_data());
        rx.take_into(&mut x, at(4)).unwrap();
        assert!(!x.is_new());
        rx.take_into(&mut x, at(5)).unwrap();
        assert_eq!((x.fresh(), x.stamp()), (Some(&5), Some(stamp(5))));
        tx.put(&mut Some(8), true, stamp(8)).unwrap();
        rx.take_into(&mut x, at(6)).unwrap();
        tx.put(&mut Some(9), true, stamp(9)).unwrap();
        rx.take_into(&mut x, at(7)).unwrap();
        assert!(!x.is_new());
        assert_eq!(x.get(), Some(&5));
        rx.take_into(&mut x, at(9)).unwrap();
        assert_eq!(x.fresh(), Some(&9));
        let s = stats.snapshot();
        assert_eq!((s.sent, s.delivered, s.overwritten), (3, 2, 1));
        // Queue: the front waits, and what is behind it waits in order.
        let (mut tx, mut rx, stats) = channel::<u32>(Policy::queue(4));
        for i in [2, 6, 7] {
            tx.put(&mut Some(i), true, stamp(u64::from(i))).unwrap();
        }
        let mut got = Vec::new();
        for now in 0..10 {
            rx.take_into(&mut x, at(now)).unwrap();
            got.push(x.fresh().copied());
        }
        let none = None;
        assert_eq!(
            got,
            [
                none,
                none,
                Some(2),
                none,
                none,
                none,
                Some(6),
                Some(7),
                none,
                none
            ]
        );
        assert_eq!(stats.snapshot().delivered, 3);
    }

    #[test]
    fn a_queue_carries_every_value_in_order_across_real_threads() {
        let (mut tx, mut rx, stats) = channel::<u64>(Policy::queue(16));
        const N: u64 = 20_000;
        let producer = std::thread::spawn(move || {
            let mut i = 0;
            while i < N {
                if tx.put(&mut Some(i), true, stamp(i)).is_ok() {
                    i += 1;
                } else {
                    std::thread::yield_now();
                }
            }
        });
        let mut x = In::default();
        let mut expect = 0;
        while expect < N {
            rx.take_into(&mut x, Time::NEVER).unwrap();
            if let Some(v) = x.fresh() {
                assert_eq!(*v, expect);
                expect += 1;
            } else {
                std::thread::yield_now();
            }
        }
        producer.join().unwrap();
        assert_eq!(stats.snapshot().delivered, N);
    }
}
