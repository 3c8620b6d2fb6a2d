//! The bridge's publishing thread: it drains every tap's ring, transcodes each
//! value to CDR, and puts it on its topic's key with rmw_zenoh's attachment.

use std::sync::atomic::Ordering;
use std::sync::{Arc, PoisonError};
use std::time::Duration;

use zenoh::Wait;

use super::adapter::{Encoder, Prepared, Transcode};
use super::plan::ros_time;
use super::tap::{Outlet, Shared, Slot};
use crate::wire::{Attachment, Gid};

/// One topic as the publishing thread sends it.
pub(crate) struct Outgoing {
    /// Its Zenoh publisher (shared with the bridge, which asks it for
    /// matching subscribers).
    pub(crate) publisher: Arc<zenoh::pubsub::Publisher<'static>>,
    /// The publisher's GID, the hash of its liveliness token.
    pub(crate) gid: Gid,
    /// The value's postcard bytes to CDR (made ready on the thread).
    pub(crate) encoder: Encoder,
    /// The last sequence number put (the first put is 1).
    pub(crate) sequence: i64,
    /// The CDR of the value being sent (kept to reuse its capacity).
    pub(crate) scratch: Vec<u8>,
}

/// How long the thread sleeps when no tap wakes it (a tap that cannot wake
/// it does not exist; this bounds the harm of a lost wake-up).
const NAP: Duration = Duration::from_millis(50);

/// The thread's loop: drain every ring, sleep until woken; after the bridge
/// says stop, drain once more and end. `epoch_ns` is the wall clock of the
/// run's instant zero \[ns since the UNIX epoch\], for the messages' stamps.
pub(crate) fn run(shared: &Shared, outgoing: Vec<Outgoing>, epoch_ns: u64) {
    let mut topics: Vec<Topic> = outgoing
        .into_iter()
        .map(|o| Topic {
            encoder: o.encoder.ready(),
            out: o,
        })
        .collect();
    let mut outlets: Vec<Outlet> = Vec::new();
    loop {
        // Read first: what a tap pushed before the stop is drained below.
        let stop = shared.stop.load(Ordering::Acquire);
        outlets.append(&mut shared.new.lock().unwrap_or_else(PoisonError::into_inner));
        for outlet in &mut outlets {
            while let Ok(slot) = outlet.full.pop() {
                let bytes = send(shared, &mut topics, slot, epoch_ns);
                // The tap may be gone; then the buffer goes too.
                let _ = outlet.free.push(bytes);
            }
        }
        outlets.retain(|o| !(o.full.is_abandoned() && o.full.is_empty()));
        if stop {
            return;
        }
        std::thread::park_timeout(NAP);
    }
}

/// A topic on the publishing thread: its encoder made ready there.
struct Topic {
    out: Outgoing,
    encoder: Option<Prepared<Transcode>>,
}

/// Transcode and put one value; its byte buffer back, for its tap.
fn send(shared: &Shared, topics: &mut [Topic], slot: Slot, epoch_ns: u64) -> Vec<u8> {
    let (
        Some(Topic {
            out: topic,
            encoder,
        }),
        Some(counts),
    ) = (topics.get_mut(slot.topic), shared.counts.get(slot.topic))
    else {
        return slot.bytes;
    };
    topic.scratch.clear();
    let stamp = ros_time(epoch_ns.saturating_add(slot.stamp.time.as_nanos()));
    let encoded = encoder
        .as_ref()
        .is_some_and(|e| e.encode(&slot.bytes, stamp, &mut topic.scratch).is_ok());
    if !encoded {
        counts.encode_failures.fetch_add(1, Ordering::Relaxed);
        return slot.bytes;
    }
    let attachment = Attachment {
        sequence_number: topic.sequence + 1,
        source_timestamp_ns: slot.wall_ns,
        gid: topic.gid,
    }
    .encode();
    let put = topic
        .publisher
        .put(topic.scratch.as_slice())
        .attachment(attachment.as_slice())
        .wait();
    match put {
        Ok(()) => {
            topic.sequence += 1;
            counts.published.fetch_add(1, Ordering::Relaxed);
        }
        Err(_) => {
            counts.put_failures.fetch_add(1, Ordering::Relaxed);
        }
    }
    slot.bytes
}
