//! The bridge's inbound side: Zenoh's callbacks hand each sample of a
//! subscribed topic to the inbound thread through a bounded channel; the
//! thread checks it (its key's type and hash, its attachment, its
//! publisher's numbering), decodes its CDR into the input buffer type's
//! postcard bytes (by the type's shape, which is not `Send`, so it lives on
//! this thread) and delivers it to the input's inbox as a message of the wire
//! format between processes. Nothing here panics on what arrives: every
//! refusal is counted, with the last reason kept.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError};
use std::sync::{Arc, Mutex, PoisonError};

use agent_core::link::remote::WireHeader;
use agent_core::{Inbox, Stamp, Time};
use zenoh::sample::Sample;

use super::adapter::{Decode, Decoder, Prepared, Refusal};
use super::tap::now_ns;
use crate::wire::{Attachment, Gid};

/// How many samples may wait for the inbound thread, over every subscribed
/// topic, before more are dropped (and counted).
pub(crate) const BACKLOG: usize = 1024;

/// How many publishers of one topic have their numbering tracked: past
/// this, the tracks are forgotten (a flood of made-up GIDs must not grow
/// memory), and each publisher's next sample starts its track again.
const MAX_PUBLISHERS: usize = 256;

/// What the inbound thread is told.
pub(crate) enum Inbound {
    /// Subscription `index` feeds `inbox` (sent before its subscriber is
    /// declared, so before any of its samples).
    Subscribe {
        /// The subscription (index into the plan's).
        index: usize,
        /// The input's inbox.
        inbox: Arc<Inbox>,
    },
    /// A sample of subscription `index`.
    Sample {
        /// The subscription.
        index: usize,
        /// The sample, as Zenoh delivered it.
        sample: Sample,
    },
    /// Every subscriber is undeclared: end after what is queued.
    Stop,
}

/// A subscribed topic's counts, shared by Zenoh's callbacks and the inbound
/// thread.
#[derive(Debug, Default)]
pub(crate) struct InCounts {
    pub(crate) received: AtomicU64,
    pub(crate) delivered: AtomicU64,
    pub(crate) dropped: AtomicU64,
    pub(crate) wrong_type: AtomicU64,
    pub(crate) bad_attachment: AtomicU64,
    pub(crate) duplicate: AtomicU64,
    pub(crate) undecodable: AtomicU64,
    pub(crate) rejected: AtomicU64,
    pub(crate) lost: AtomicU64,
    /// Why the last refused sample was refused.
    pub(crate) last_refusal: Mutex<Option<String>>,
}

impl InCounts {
    /// A sample refused: `count` counts it, `why` says why.
    fn refuse(&self, count: &AtomicU64, why: String) {
        count.fetch_add(1, Ordering::Relaxed);
        *self
            .last_refusal
            .lock()
            .unwrap_or_else(PoisonError::into_inner) = Some(why);
    }
}

/// The callback of subscription `index`'s Zenoh subscriber: count the
/// sample and hand it to the inbound thread, or drop it (counted) when
/// the thread is [`BACKLOG`] samples behind.
pub(crate) fn callback(
    index: usize,
    to_thread: SyncSender<Inbound>,
    counts: Arc<[InCounts]>,
) -> impl Fn(Sample) + Send + Sync + 'static {
    move |sample: Sample| {
        let Some(counts) = counts.get(index) else {
            return;
        };
        counts.received.fetch_add(1, Ordering::Relaxed);
        match to_thread.try_send(Inbound::Sample { index, sample }) {
            Ok(()) => {}
            Err(TrySendError::Full(_) | TrySendError::Disconnected(_)) => {
                counts.dropped.fetch_add(1, Ordering::Relaxed);
            }
        }
    }
}

/// One subscribed topic as the inbound thread takes it.
pub(crate) struct Incoming {
    /// Its data key: a sample on another (the topic's, of another type or
    /// hash) is refused.
    pub(crate) key: String,
    /// Its CDR to the buffer type's postcard bytes (made ready on the
    /// thread).
    pub(crate) decoder: Decoder,
    /// The buffer type's fingerprint, in every message's header.
    pub(crate) fingerprint: u64,
}

/// A subscribed topic on the inbound thread.
struct Topic {
    key: String,
    decoder: Option<Prepared<Decode>>,
    inbox: Option<Arc<Inbox>>,
    /// The header of the messages to the inbox: the bridge is its one
    /// sender, numbering them from 1 whichever publisher they come from.
    header: WireHeader,
    /// The sequence number last taken from each publisher.
    publishers: HashMap<Gid, i64>,
    /// The message being made (kept to reuse its capacity).
    message: Vec<u8>,
}

/// The clocks of the messages' headers.
#[derive(Clone, Debug)]
pub(crate) struct Clocks {
    /// The wall clock of the run's instant zero \[ns since the UNIX epoch\]:
    /// a value's instant is when it arrived, after it (set again when the
    /// run starts: [`Bridge::set_inbound_zero`](super::Bridge::set_inbound_zero)).
    pub(crate) zero_ns: Arc<AtomicU64>,
    /// The bridge's epoch as a sender (fixed while it runs).
    pub(crate) epoch: u64,
}

/// The inbound thread's loop: take what Zenoh's callbacks hand over until
/// told to stop (or until every sender is gone).
pub(crate) fn run(
    from_callbacks: &Receiver<Inbound>,
    incoming: Vec<Incoming>,
    counts: &[InCounts],
    clocks: Clocks,
) {
    let mut topics: Vec<Topic> = incoming
        .into_iter()
        .map(|i| Topic {
            key: i.key,
            decoder: i.decoder.ready(),
            inbox: None,
            header: WireHeader {
                fingerprint: i.fingerprint,
                epoch: clocks.epoch,
                seq: 0,
                stamp: Stamp::new(0, Time::ZERO),
            },
            publishers: HashMap::new(),
            message: Vec::new(),
        })
        .collect();
    while let Ok(next) = from_callbacks.recv() {
        match next {
            Inbound::Subscribe { index, inbox } => {
                if let Some(topic) = topics.get_mut(index) {
                    topic.inbox = Some(inbox);
                }
            }
            Inbound::Sample { index, sample } => {
                if let (Some(topic), Some(counts)) = (topics.get_mut(index), counts.get(index)) {
                    let zero_ns = clocks.zero_ns.load(Ordering::Relaxed);
                    take(topic, counts, &sample, zero_ns);
                }
            }
            Inbound::Stop => return,
        }
    }
}

/// Check, decode and deliver one sample (or refuse it, counted).
fn take(topic: &mut Topic, counts: &InCounts, sample: &Sample, zero_ns: u64) {
    let key = sample.key_expr().as_str();
    if key != topic.key {
        return counts.refuse(
            &counts.wrong_type,
            format!("a sample on `{key}`, not `{}`", topic.key),
        );
    }
    let attachment = match sample
        .attachment()
        .map(|a| Attachment::decode(&a.to_bytes()))
    {
        Some(Ok(a)) => a,
        Some(Err(e)) => return counts.refuse(&counts.bad_attachment, e.to_string()),
        None => {
            return counts.refuse(&counts.bad_attachment, "a sample without attachment".into());
        }
    };
    match follow(&mut topic.publishers, &attachment) {
        Ok(lost) => {
            counts.lost.fetch_add(lost, Ordering::Relaxed);
        }
        Err(last) => {
            return counts.refuse(
                &counts.duplicate,
                format!(
                    "sequence number {} from publisher {} after {last}",
                    attachment.sequence_number, attachment.gid
                ),
            );
        }
    }
    let (Some(decoder), Some(inbox)) = (&topic.decoder, &topic.inbox) else {
        return counts.refuse(
            &counts.undecodable,
            "the bridge cannot read the topic's type".into(),
        );
    };
    let since = u64::try_from(now_ns()).unwrap_or(0).saturating_sub(zero_ns);
    let header = WireHeader {
        seq: topic.header.seq + 1,
        stamp: Stamp::new(0, Time::from_nanos(since)),
        ..topic.header
    };
    header.write(&mut topic.message);
    match decoder.decode(&sample.payload().to_bytes(), &mut topic.message) {
        Ok(()) => {}
        Err(Refusal::Undecodable(why)) => return counts.refuse(&counts.undecodable, why),
        Err(Refusal::Rejected(why)) => return counts.refuse(&counts.rejected, why),
    }
    topic.header = header;
    inbox.deliver(&topic.message);
    counts.delivered.fetch_add(1, Ordering::Relaxed);
}

/// Follow the numbering of the attachment's publisher: the samples lost
/// since its last one (none for the first heard), or, for a repeat or an
/// older sample, `Err` with the number last taken.
fn follow(publishers: &mut HashMap<Gid, i64>, attachment: &Attachment) -> Result<u64, i64> {
    let seq = attachment.sequence_number;
    let lost = match publishers.get(&attachment.gid) {
        Some(&last) if seq <= last => return Err(last),
        Some(&last) => u64::try_from(i128::from(seq) - i128::from(last) - 1).unwrap_or(0),
        None => {
            if publishers.len() >= MAX_PUBLISHERS {
                publishers.clear();
            }
            0
        }
    };
    publishers.insert(attachment.gid, seq);
    Ok(lost)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn from(gid: u8, seq: i64) -> Attachment {
        Attachment {
            sequence_number: seq,
            source_timestamp_ns: 0,
            gid: Gid::from_bytes([gid; 16]),
        }
    }

    /// Each publisher is numbered on its own: a repeat or an older number
    /// is refused, a jump counts the numbers skipped as lost, a publisher
    /// first heard late has lost nothing.
    #[test]
    fn each_publishers_numbering_is_followed() {
        let mut publishers = HashMap::new();
        assert_eq!(follow(&mut publishers, &from(1, 1)), Ok(0));
        assert_eq!(follow(&mut publishers, &from(1, 2)), Ok(0));
        assert_eq!(follow(&mut publishers, &from(1, 2)), Err(2));
        assert_eq!(follow(&mut publishers, &from(1, 1)), Err(2));
        assert_eq!(follow(&mut publishers, &from(2, 40)), Ok(0));
        assert_eq!(follow(&mut publishers, &from(1, 5)), Ok(2));
        assert_eq!(follow(&mut publishers, &from(2, 41)), Ok(0));
        assert_eq!(
            follow(&mut publishers, &from(1, i64::MAX)),
            Ok(u64::MAX / 2 - 6)
        );
        assert_eq!(follow(&mut publishers, &from(2, i64::MIN)), Err(41));
    }

    /// Past the tracked publishers, the tracks start again: memory stays
    /// bounded whatever GIDs arrive.
    #[test]
    fn the_tracks_are_bounded() {
        let mut publishers = HashMap::new();
        for k in 0..=MAX_PUBLISHERS {
            let gid = Gid::from_bytes(u128::try_from(k).unwrap_or(0).to_le_bytes());
            let attachment = Attachment { gid, ..from(0, 7) };
            assert_eq!(follow(&mut publishers, &attachment), Ok(0));
        }
        assert_eq!(publishers.len(), 1);
    }
}
