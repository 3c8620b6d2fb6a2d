//! What a replay reads of a recording: the channels of the replayed
//! subsystem's links (checked against this build, each with its codec), and
//! the values on them: the inputs to feed, the outputs and switches to compare.

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

use agent_core::trace::LinkInfo;
use agent_core::{Stamp, System, SystemInfo, TypeShape, WireHeader};
use serde_json::Value;

use super::{Recorded, ReplayError, Window};
use crate::codec::{CODEC_KEY, Codec};
use crate::read::{ChannelInfo, Message, Recording};
use crate::record::{FRAMES_ENCODING, READ_ENCODING, WIRE_ENCODING, decode_read, raw_values};

/// The recording's channels of the replayed subsystem's links.
pub(super) struct Routes<'r> {
    /// Each raw (or received) channel: its link and encoding.
    channel_link: BTreeMap<u16, (usize, &'r str)>,
    /// The codec of each raw (or received) channel recorded through one.
    codecs: BTreeMap<u16, Arc<dyn Codec>>,
    /// Each reads channel of a link into the subsystem: its link.
    read_channel_link: BTreeMap<u16, usize>,
    /// The payload shapes of the links out of it (to name a field).
    pub(super) shapes: BTreeMap<usize, Option<TypeShape>>,
}

/// A recording's raw, reads and received channels, by the link they carry.
struct ByLink<'r> {
    raw: BTreeMap<&'r str, &'r ChannelInfo>,
    reads: BTreeMap<&'r str, &'r ChannelInfo>,
    /// Values a process took from another: fed where the sender's recording
    /// lacks them (a sender killed before its recorder wrote them).
    received: BTreeMap<&'r str, &'r ChannelInfo>,
}

impl<'r> ByLink<'r> {
    fn of(recording: &'r Recording) -> ByLink<'r> {
        let by_encoding = |encoding: &str| -> BTreeMap<&str, &ChannelInfo> {
            recording
                .channels
                .values()
                .filter(|c| c.message_encoding == encoding)
                .filter_map(|c| Some((c.metadata.get("link")?.as_str(), c)))
                .collect()
        };
        let received = |c: &&ChannelInfo| c.metadata.contains_key("received");
        let mut raw: BTreeMap<&str, &ChannelInfo> = recording
            .channels
            .values()
            .filter(|c| c.message_encoding == WIRE_ENCODING && !received(c))
            .filter_map(|c| Some((c.metadata.get("link")?.as_str(), c)))
            .collect();
        raw.extend(by_encoding(FRAMES_ENCODING));
        let reads = by_encoding(READ_ENCODING);
        let received = recording
            .channels
            .values()
            .filter(|c| c.message_encoding == WIRE_ENCODING && received(c))
            .filter_map(|c| Some((c.metadata.get("link")?.as_str(), c)))
            .collect();
        ByLink {
            raw,
            reads,
            received,
        }
    }
}

impl<'r> Routes<'r> {
    /// The channels of every link into or out of subsystem `x`, each link's
    /// raw channel checked against this build (its payload type) and the
    /// codecs given.
    pub(super) fn of(
        recording: &'r Recording,
        system: &System,
        x: usize,
        given: &[Arc<dyn Codec>],
    ) -> Result<Routes<'r>, ReplayError> {
        let by_link = ByLink::of(recording);
        let mut routes = Routes {
            channel_link: BTreeMap::new(),
            codecs: BTreeMap::new(),
            read_channel_link: BTreeMap::new(),
            shapes: BTreeMap::new(),
        };
        for (k, link) in system.info().links.iter().enumerate() {
            let input = link.to == x && link.from != x;
            let output = link.from == x;
            if !(input || output) {
                continue;
            }
            let c = by_link
                .raw
                .get(link.name.as_str())
                .ok_or_else(|| ReplayError::Unrecorded {
                    link: link.name.clone(),
                })?;
            same_payload(system, k, link, c)?;
            if let Some(codec) = codec_of(given, link, c)? {
                routes.codecs.insert(c.id, codec);
            }
            routes
                .channel_link
                .insert(c.id, (k, c.message_encoding.as_str()));
            if input && let Some(r) = by_link.reads.get(link.name.as_str()) {
                routes.read_channel_link.insert(r.id, k);
            }
            if input && let Some(r) = by_link.received.get(link.name.as_str()) {
                routes.channel_link.insert(r.id, (k, WIRE_ENCODING));
                if let Some(codec) = routes.codecs.get(&c.id).cloned() {
                    routes.codecs.insert(r.id, codec);
                }
            }
            if output {
                routes.shapes.insert(k, system.payload_shape(k));
            }
        }
        Ok(routes)
    }
}

/// Refuses a link whose payload type changed since the recording (its
/// fingerprint differs from its raw channel's).
fn same_payload(
    system: &System,
    k: usize,
    link: &LinkInfo,
    c: &ChannelInfo,
) -> Result<(), ReplayError> {
    let built = system.payload_fingerprint(k).unwrap_or(0);
    let recorded = c.metadata.get("fingerprint").cloned().unwrap_or_default();
    if recorded != format!("{built:016x}") {
        return Err(ReplayError::Fingerprint {
            link: link.name.clone(),
            type_name: link.payload.to_owned(),
            built,
            recorded,
        });
    }
    Ok(())
}

/// The codec, among those `given`, that the raw channel `c` of `link` was
/// recorded through, if it names one.
fn codec_of(
    given: &[Arc<dyn Codec>],
    link: &LinkInfo,
    c: &ChannelInfo,
) -> Result<Option<Arc<dyn Codec>>, ReplayError> {
    let Some(name) = c.metadata.get(CODEC_KEY) else {
        return Ok(None);
    };
    let codec = given
        .iter()
        .find(|codec| codec.name() == name)
        .ok_or_else(|| ReplayError::Codec {
            link: link.name.clone(),
            codec: name.clone(),
            given: given
                .iter()
                .map(|c| format!("`{}`", c.name()))
                .collect::<Vec<_>>()
                .join(", "),
        })?;
    Ok(Some(codec.clone()))
}

/// What the replayed subsystem is to do, as recorded: the values it sent, by
/// link, and its behaviour switches (log time, the switch), each in order.
pub(super) struct Expected {
    pub(super) outputs: BTreeMap<usize, VecDeque<Recorded>>,
    pub(super) switches: VecDeque<(u64, Value)>,
}

/// The recorded values of the replayed subsystem: inputs to feed, outputs
/// and switches to compare.
pub(super) struct Tape<'r> {
    /// The values sent to it, by link.
    pub(super) sent: BTreeMap<usize, Vec<Recorded>>,
    /// Its recorded reads, by link: the instant, the stamp of the value read,
    /// the message (an entry, perhaps empty, for each link whose reads were
    /// recorded).
    pub(super) reads: BTreeMap<usize, Vec<(u64, Stamp, &'r Message)>>,
    pub(super) expected: Expected,
}

impl<'r> Tape<'r> {
    /// The messages of `recording` on the channels `routes` names, and on
    /// subsystem `x`'s (`node`'s) `/fsm` channel; what the subsystem itself
    /// did is kept only in `window`.
    pub(super) fn read(
        recording: &'r Recording,
        info: &SystemInfo,
        x: usize,
        node: &str,
        routes: &Routes<'_>,
        window: Option<Window>,
    ) -> Result<Tape<'r>, ReplayError> {
        let fsm_channel = recording.channel(&format!("/fsm/{node}")).map(|c| c.id);
        // What the node itself did is the window's; what others sent it is
        // matched by its reads.
        let own = |ns: u64| window.is_none_or(|w| w.holds(ns));
        let mut tape = Tape {
            sent: BTreeMap::new(),
            reads: BTreeMap::new(),
            expected: Expected {
                outputs: BTreeMap::new(),
                switches: VecDeque::new(),
            },
        };
        for m in &recording.messages {
            if Some(m.channel) == fsm_channel {
                if own(m.log_time) {
                    let switch = recorded_switch(node, m)?;
                    tape.expected.switches.push_back((m.log_time, switch));
                }
                continue;
            }
            if let Some(&k) = routes.read_channel_link.get(&m.channel) {
                let stamp = decode_read(&m.data).ok_or_else(|| ReplayError::BadValue {
                    link: info.links[k].name.clone(),
                    sequence: m.sequence,
                    offset: m.offset,
                    message: format!("a read of {} bytes (16 expected)", m.data.len()),
                })?;
                if own(m.log_time) {
                    tape.reads
                        .entry(k)
                        .or_default()
                        .push((m.log_time, stamp, m));
                }
                continue;
            }
            let Some(&(k, encoding)) = routes.channel_link.get(&m.channel) else {
                continue;
            };
            let codec = routes.codecs.get(&m.channel);
            for r in recorded_values(&info.links[k].name, encoding, m, codec)? {
                if info.links[k].from == x {
                    if own(r.stamp.time.as_nanos()) {
                        tape.expected.outputs.entry(k).or_default().push_back(r);
                    }
                } else {
                    tape.sent.entry(k).or_default().push(r);
                }
            }
        }
        for k in routes.read_channel_link.values() {
            tape.reads.entry(*k).or_default();
        }
        Ok(tape)
    }
}

/// A behaviour switch of `node` as its `/fsm` channel recorded it.
fn recorded_switch(node: &str, m: &Message) -> Result<Value, ReplayError> {
    serde_json::from_slice(&m.data).map_err(|e| ReplayError::BadValue {
        link: format!("/fsm/{node}"),
        sequence: m.sequence,
        offset: m.offset,
        message: e.to_string(),
    })
}

/// The values of `link` in raw message `m` (of `encoding`), each read off
/// its wire header and decoded through the link's `codec`, if it has one.
fn recorded_values(
    link: &str,
    encoding: &str,
    m: &Message,
    codec: Option<&Arc<dyn Codec>>,
) -> Result<Vec<Recorded>, ReplayError> {
    let bad = |sequence: u32, message: String| ReplayError::BadValue {
        link: link.to_owned(),
        sequence,
        offset: m.offset,
        message,
    };
    let mut values = Vec::new();
    for value in raw_values(encoding, &m.data) {
        let value = value.map_err(|e| bad(m.sequence, format!("raw message: {e}")))?;
        let (header, body) = WireHeader::read(value).map_err(|e| bad(m.sequence, e.to_string()))?;
        // The value's number on its link, from 0 (the header's count is from 1).
        let sequence = header.seq.wrapping_sub(1) as u32;
        let body = match codec {
            Some(codec) => {
                let mut decoded = Vec::new();
                codec
                    .decode(body, &mut decoded)
                    .map_err(|e| bad(sequence, format!("codec `{}`: {e}", codec.name())))?;
                decoded
            }
            None => body.to_vec(),
        };
        values.push(Recorded {
            stamp: header.stamp,
            body,
            sequence,
            offset: m.offset,
        });
    }
    Ok(values)
}
