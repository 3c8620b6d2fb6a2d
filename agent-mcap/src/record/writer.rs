//! The recorder's writer thread: the MCAP records of every value, read,
//! switch and error it is sent, the derived channels, and the end.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender, TryRecvError};
use std::time::Duration;

use agent_core::link::remote::HEADER_LEN;
use agent_core::trace::{NodeInfo, SystemInfo};
use agent_core::{Stamp, Step, Time, TypeShape, Valuation, WireHeader};
use serde_json::{Value, json};

use super::batch::{Entry, entries};
use super::part::{Backlog, Counts, Record};
use super::{
    Derive, PREDICATES_PREFIX, RecordError, RecordSummary, WIRE_ENCODING, encode_read, small,
};
use crate::cdr::write_cdr;
use crate::codec::Codec;
use crate::json::write_json;

/// The writer thread's side.
pub(super) struct Output {
    pub(super) w: mcap::Writer<BufWriter<File>>,
    pub(super) path: PathBuf,
    pub(super) info: SystemInfo,
    pub(super) links: Vec<LinkChannels>,
    pub(super) fsm: Vec<u16>,
    /// Per node: its `/predicates/<node>` channel (made with its first
    /// message) and its count of messages.
    pub(super) predicates: Vec<(Option<u16>, u32)>,
    pub(super) errors: u16,
    pub(super) derived: Vec<Box<dyn Derive>>,
    pub(super) value_max_bytes: usize,
    pub(super) scratch: Vec<u8>,
    /// A raw message: the wire header, then the body or the codec's
    /// encoding of it.
    pub(super) encoded: Vec<u8>,
    pub(super) summary: RecordSummary,
}

impl Output {
    pub(super) fn run(
        mut self,
        rx: &Receiver<Record>,
        shapes: &[Option<TypeShape>],
        backlog: &Backlog,
    ) -> Result<RecordSummary, RecordError> {
        let mut error_count = 0u32;
        // The `/timing` channel (made with its first message) and its count.
        let mut timing = (None, 0u32);
        let mut give_back: BTreeMap<u16, Sender<Vec<u8>>> = BTreeMap::new();
        let mut counts = Counts::default();
        let mut finished = false;
        // Until the owner and every thread's part are gone.
        for record in Polled::new(rx) {
            match record {
                Record::Batch { part, bytes } => {
                    self.batch(&bytes, shapes)?;
                    // One raw message per link and batch.
                    self.write_pending()?;
                    // Counted out after the buffer is given back: a backlog of
                    // nothing means every buffer is back for reuse.
                    let n = bytes.len();
                    if let Some(back) = give_back.get(&part) {
                        let _ = back.send(bytes);
                    }
                    backlog.written(n);
                }
                Record::Transition {
                    node,
                    time,
                    iteration,
                    step,
                } => self.transition(node, time, iteration, step)?,
                Record::Error { time, message } => {
                    let data = json!({"time_s": time.as_secs_f64(), "message": message});
                    self.write(
                        self.errors,
                        error_count,
                        time,
                        &data.to_string().into_bytes(),
                    )?;
                    error_count += 1;
                }
                Record::Timing { time, json } => {
                    self.timing(&mut timing, time, json.as_bytes())?;
                }
                Record::Part { part, give_back: g } => {
                    give_back.insert(part, g);
                }
                Record::Counted(c) => counts.add(&c),
                Record::End => finished = true,
            }
        }
        self.write_pending()?;
        if finished {
            let mut end = BTreeMap::from([
                ("time_ns".to_owned(), counts.last.as_nanos().to_string()),
                ("finished".to_owned(), "true".to_owned()),
            ]);
            for (n, k) in self.info.nodes.iter().zip(&counts.iterations) {
                end.insert(format!("iterations/{}", n.name), k.to_string());
            }
            for ((n, t), k) in self
                .info
                .nodes
                .iter()
                .zip(&counts.last_of)
                .zip(&counts.iterations)
            {
                if *k > 0 || *t > Time::ZERO {
                    end.insert(format!("last/{}", n.name), t.as_nanos().to_string());
                }
            }
            for (n, t) in self.info.nodes.iter().zip(&counts.first_of) {
                if let Some(t) = t {
                    end.insert(format!("first/{}", n.name), t.as_nanos().to_string());
                }
            }
            self.w
                .write_metadata(&mcap::records::Metadata {
                    name: "end".into(),
                    metadata: end,
                })
                .map_err(|e| self.fail(&e))?;
        }
        self.summary.waits = counts.waits;
        self.summary.backlog_peak_bytes = backlog.peak.load(std::sync::atomic::Ordering::Relaxed);
        self.summary.undecodable += counts.encode_failures;
        let Output {
            w, path, summary, ..
        } = self;
        crate::close::close(w).map_err(|e| RecordError::Write {
            path,
            message: e.to_string(),
        })?;
        Ok(summary)
    }

    /// The entries of one part's batch.
    fn batch(&mut self, bytes: &[u8], shapes: &[Option<TypeShape>]) -> Result<(), RecordError> {
        for entry in entries(bytes) {
            match entry {
                Entry::Transfer { link, stamp, body } => {
                    let shape = shapes.get(link as usize).and_then(Option::as_ref);
                    self.transfer(link, shape, stamp, body)?;
                }
                Entry::Read { link, time, stamp } => self.read(link, time, stamp)?,
                Entry::Received { link, stamp, body } => self.received(link, stamp, body)?,
                Entry::Predicates {
                    node,
                    time,
                    iteration,
                    values,
                } => self.predicates(node, time, iteration, values)?,
            }
        }
        Ok(())
    }

    /// One process's timing statistics on `/timing`, the channel made with
    /// the first (`channel`: its id, if made, and its count of messages).
    fn timing(
        &mut self,
        channel: &mut (Option<u16>, u32),
        time: Time,
        json: &[u8],
    ) -> Result<(), RecordError> {
        let id = match channel.0 {
            Some(c) => c,
            None => {
                let made = self.w.add_channel(
                    0,
                    crate::timing::TIMING_TOPIC,
                    crate::timing::TIMING_ENCODING,
                    &BTreeMap::new(),
                );
                let c = made.map_err(|e| self.fail(&e))?;
                channel.0 = Some(c);
                c
            }
        };
        self.write(id, channel.1, time, json)?;
        channel.1 += 1;
        Ok(())
    }

    fn fail(&self, e: &mcap::McapError) -> RecordError {
        RecordError::Write {
            path: self.path.clone(),
            message: e.to_string(),
        }
    }

    fn write(
        &mut self,
        channel: u16,
        sequence: u32,
        time: Time,
        data: &[u8],
    ) -> Result<(), RecordError> {
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence,
            log_time: time.as_nanos(),
            publish_time: time.as_nanos(),
        };
        self.w
            .write_to_known_channel(&header, data)
            .map_err(|e| RecordError::Write {
                path: self.path.clone(),
                message: e.to_string(),
            })?;
        self.summary.messages += 1;
        Ok(())
    }

    /// A value received from another process: on the link's `/received`
    /// channel (made with its first value), as its raw channel would carry it.
    fn received(&mut self, link: u32, stamp: Stamp, body: &[u8]) -> Result<(), RecordError> {
        let Some(l) = self.links.get(link as usize) else {
            return Ok(());
        };
        let channel = match l.received {
            Some(c) => c,
            None => {
                let mut meta = l.raw_meta.clone();
                meta.insert("received".to_owned(), "true".to_owned());
                let topic = format!("/received{}", l.topic);
                let made = self.w.add_channel(0, &topic, WIRE_ENCODING, &meta);
                let c = made.map_err(|e| self.fail(&e))?;
                if let Some(l) = self.links.get_mut(link as usize) {
                    l.received = Some(c);
                }
                c
            }
        };
        let Some(l) = self.links.get_mut(link as usize) else {
            return Ok(());
        };
        l.received_count += 1;
        let sequence = (l.received_count - 1) as u32;
        let mut raw = std::mem::take(&mut self.encoded);
        WireHeader {
            fingerprint: l.fingerprint,
            epoch: 0,
            seq: l.received_count,
            stamp,
        }
        .write(&mut raw);
        match &l.codec {
            Some(codec) => codec.encode(body, &mut raw),
            None => raw.extend_from_slice(body),
        }
        let written = self.write(channel, sequence, stamp.time, &raw);
        self.encoded = raw;
        written
    }

    fn read(&mut self, link: u32, time: Time, stamp: Stamp) -> Result<(), RecordError> {
        let Some(l) = self.links.get_mut(link as usize) else {
            return Ok(());
        };
        let (channel, sequence) = (l.reads, l.read_sequence);
        l.read_sequence = l.read_sequence.wrapping_add(1);
        self.write(channel, sequence, time, &encode_read(stamp))
    }

    fn transfer(
        &mut self,
        link: u32,
        shape: Option<&TypeShape>,
        stamp: Stamp,
        body: &[u8],
    ) -> Result<(), RecordError> {
        let Some(l) = self.links.get_mut(link as usize) else {
            return Ok(());
        };
        let time = stamp.time;
        let sequence = l.count as u32;
        l.count += 1;
        // The raw message: the wire header a link between processes would
        // send, then the body, as it is or through the link's codec.
        let mut raw = std::mem::take(&mut self.encoded);
        WireHeader {
            fingerprint: l.fingerprint,
            epoch: 0,
            seq: l.count,
            stamp,
        }
        .write(&mut raw);
        let coded = match &l.codec {
            Some(codec) => {
                codec.encode(body, &mut raw);
                true
            }
            None => {
                raw.extend_from_slice(body);
                false
            }
        };
        // Framed into the link's pending raw message (written at the end of
        // the batch, or now if it is long).
        let framed = u32::try_from(raw.len()).map_err(|_| RecordError::Write {
            path: self.path.clone(),
            message: format!(
                "a value of {} bytes on `{}` (4 GiB at most)",
                raw.len(),
                self.info
                    .links
                    .get(link as usize)
                    .map_or("?", |i| i.name.as_str())
            ),
        });
        let framed = framed.map(|len| {
            if l.pending.is_empty() {
                l.pending_since = time;
            }
            l.pending.extend_from_slice(&len.to_le_bytes());
            l.pending.extend_from_slice(&raw);
            l.pending.len() >= PENDING_BYTES
        });
        let (value, cdr) = (l.value, l.cdr);
        let written = framed.and_then(|long| {
            if long {
                self.write_pending_of(link as usize)?;
            }
            let encoded = coded.then(|| &raw[HEADER_LEN..]);
            self.derive(link, sequence, time, body, encoded)
        });
        self.encoded = raw;
        written?;
        if body.len() > self.value_max_bytes {
            self.summary.raw_only += 1;
            return Ok(());
        }
        // A type without a shape is recorded raw only (its value channel
        // stays empty): not a failure of this value.
        let Some(shape) = shape else {
            return Ok(());
        };
        let mut text = std::mem::take(&mut self.scratch);
        text.clear();
        let made = if cdr {
            write_cdr(shape, body, &mut text)
        } else {
            write_json(shape, body, &mut text)
        };
        let written = match made {
            Ok(()) => self.write(value, sequence, time, &text),
            Err(_) => {
                self.summary.undecodable += 1;
                Ok(())
            }
        };
        self.scratch = text;
        written
    }

    /// Write every link's pending raw values.
    fn write_pending(&mut self) -> Result<(), RecordError> {
        for k in 0..self.links.len() {
            self.write_pending_of(k)?;
        }
        Ok(())
    }

    /// Write the pending raw values of link `k` as one message, if any.
    fn write_pending_of(&mut self, k: usize) -> Result<(), RecordError> {
        let Some(l) = self.links.get_mut(k) else {
            return Ok(());
        };
        if l.pending.is_empty() {
            return Ok(());
        }
        let mut pending = std::mem::take(&mut l.pending);
        let (channel, sequence, time) = (l.raw, l.raw_messages, l.pending_since);
        l.raw_messages = l.raw_messages.wrapping_add(1);
        let written = self.write(channel, sequence, time, &pending);
        pending.clear();
        self.links[k].pending = pending;
        written
    }

    /// The derived channels' messages for one value of `link`.
    fn derive(
        &mut self,
        link: u32,
        sequence: u32,
        time: Time,
        body: &[u8],
        encoded: Option<&[u8]>,
    ) -> Result<(), RecordError> {
        for k in 0..self.links[link as usize].derived.len() {
            let (d, channel) = self.links[link as usize].derived[k];
            let mut out = std::mem::take(&mut self.scratch);
            out.clear();
            let made = self.derived.get_mut(d).is_some_and(|derive| match encoded {
                Some(e) => derive.message_encoded(link as usize, time, body, e, &mut out),
                None => derive.message(link as usize, time, body, &mut out),
            });
            let written = if made {
                self.write(channel, sequence, time, &out)
            } else {
                Ok(())
            };
            self.scratch = out;
            written?;
        }
        Ok(())
    }

    /// The predicates of node `node` after its activation at `time` (those
    /// an observer beside the recorder asked for: a contract monitor's
    /// invariants), on its `/predicates/<node>` channel, made with the first.
    fn predicates(
        &mut self,
        node: u32,
        time: Time,
        iteration: u64,
        values: Valuation,
    ) -> Result<(), RecordError> {
        let Some(n) = self.info.nodes.get(node as usize) else {
            return Ok(());
        };
        let names = n.fsm.as_ref().map_or(&[][..], |f| f.predicates.as_slice());
        let map: serde_json::Map<String, Value> = names
            .iter()
            .enumerate()
            .filter_map(|(i, p)| Some((p.clone(), Value::Bool(values.get(i)?))))
            .collect();
        let data = json!({"time_s": time.as_secs_f64(), "iteration": iteration, "predicates": map});
        let topic = format!("{PREDICATES_PREFIX}{}", n.name);
        let Some(slot) = self.predicates.get(node as usize).copied() else {
            return Ok(());
        };
        let id = match slot.0 {
            Some(c) => c,
            None => {
                let schema = self
                    .w
                    .add_schema(
                        "embodied.Predicates",
                        "jsonschema",
                        PREDICATES_SCHEMA.as_bytes(),
                    )
                    .map_err(|e| self.fail(&e))?;
                let made = self.w.add_channel(schema, &topic, "json", &BTreeMap::new());
                made.map_err(|e| self.fail(&e))?
            }
        };
        if let Some(s) = self.predicates.get_mut(node as usize) {
            *s = (Some(id), slot.1.wrapping_add(1));
        }
        self.write(id, slot.1, time, &data.to_string().into_bytes())
    }

    fn transition(
        &mut self,
        node: u32,
        time: Time,
        iteration: u64,
        step: Step,
    ) -> Result<(), RecordError> {
        let Some(n) = self.info.nodes.get(node as usize) else {
            return Ok(());
        };
        let data = transition_json(n, time, iteration, step);
        let channel = self.fsm[node as usize];
        self.write(
            channel,
            small(iteration as usize),
            time,
            &data.to_string().into_bytes(),
        )
    }
}

/// A link's channels and how to read its values.
pub(super) struct LinkChannels {
    /// The link's topic (`/links/...`), and its raw channel's metadata.
    pub(super) topic: String,
    pub(super) raw_meta: BTreeMap<String, String>,
    /// The value's channel, and whether it is CDR (else JSON).
    pub(super) value: u16,
    pub(super) cdr: bool,
    pub(super) raw: u16,
    pub(super) reads: u16,
    pub(super) read_sequence: u32,
    /// The payload's fingerprint, for the raw messages' wire header.
    pub(super) fingerprint: u64,
    /// Values recorded: the MCAP sequence (wrapping) and, from 1, the wire
    /// header's.
    pub(super) count: u64,
    /// Derived channels: (the derive, its channel).
    pub(super) derived: Vec<(usize, u16)>,
    /// The codec of the raw channel.
    pub(super) codec: Option<Arc<dyn Codec>>,
    /// Values not yet written to the raw channel ([`FRAMES_ENCODING`]), and
    /// the first one's instant.
    pub(super) pending: Vec<u8>,
    pub(super) pending_since: Time,
    /// Raw messages written: their MCAP sequence (wrapping).
    pub(super) raw_messages: u32,
    /// The channel of values received from another process (made with the
    /// first), and how many.
    pub(super) received: Option<u16>,
    pub(super) received_count: u64,
}

/// The schema of a `/predicates/<node>` message.
const PREDICATES_SCHEMA: &str = r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"embodied.Predicates","type":"object","properties":{"time_s":{"type":"number"},"iteration":{"type":"integer"},"predicates":{"type":"object","additionalProperties":{"type":"boolean"}}},"required":["time_s","iteration","predicates"]}"#;

/// A behaviour switch of node `n` as recorded on its `/fsm/<node>` channel
/// (and as a replay compares it).
pub(crate) fn transition_json(n: &NodeInfo, time: Time, iteration: u64, step: Step) -> Value {
    let name = |b: usize| n.behaviours.get(b).cloned().unwrap_or_default();
    let predicates = n
        .fsm
        .as_ref()
        .map(|f| f.predicates.clone())
        .unwrap_or_default();
    match step {
        Step::Entered {
            from,
            arc,
            to,
            predicates: values,
        } => {
            let arc_text = n
                .fsm
                .as_ref()
                .and_then(|f| {
                    f.arcs
                        .iter()
                        .filter(|(a, _, _)| *a == name(from))
                        .nth(arc)
                        .map(|(_, _, c)| c.clone())
                })
                .unwrap_or_default();
            let values: serde_json::Map<String, Value> = predicates
                .iter()
                .enumerate()
                .filter_map(|(i, p)| Some((p.clone(), Value::Bool(values.get(i)?))))
                .collect();
            json!({
                "time_s": time.as_secs_f64(),
                "iteration": iteration,
                "from": name(from),
                "to": name(to),
                "arc": arc,
                "condition": arc_text,
                "predicates": values,
            })
        }
        Step::Finished | Step::Run => json!({
            "time_s": time.as_secs_f64(),
            "iteration": iteration,
            "finished": true,
        }),
    }
}

/// The length at which a link's pending raw values are written at once,
/// not at the end of the batch (one camera image is longer).
const PENDING_BYTES: usize = 64 * 1024;

/// The records of a queue, taken by polling: the writer sleeps while the queue
/// is empty instead of blocking in `recv`, so that a sender never has to wake
/// it. A send to a blocked receiver is a futex wake-up, a system call on the
/// executor's thread for every batch (a visible share of its time:
/// docs/measurements.md, "The recorder's encodings"); a send to a sleeping
/// poller is a store. The sleep doubles from [`Polled::FIRST`]
/// up to [`Polled::LONGEST`] while the queue stays empty, so an idle recording
/// costs a few wake-ups a second and a busy one lags the run by about a
/// millisecond. A full queue still wakes its waiting sender at once (`try_recv`
/// notifies it). The nap is a `park_timeout`: the recorder's owner unparks the
/// writer when it finishes the recording, so the run's end never waits out a
/// nap.
struct Polled<'a, T> {
    rx: &'a Receiver<T>,
    nap: Duration,
}

impl<'a, T> Polled<'a, T> {
    const FIRST: Duration = Duration::from_micros(500);
    const LONGEST: Duration = Duration::from_millis(32);

    fn new(rx: &'a Receiver<T>) -> Self {
        Polled {
            rx,
            nap: Self::FIRST,
        }
    }
}

impl<T> Iterator for Polled<'_, T> {
    type Item = T;

    fn next(&mut self) -> Option<T> {
        loop {
            match self.rx.try_recv() {
                Ok(record) => {
                    self.nap = Self::FIRST;
                    return Some(record);
                }
                Err(TryRecvError::Empty) => {
                    std::thread::park_timeout(self.nap);
                    self.nap = (self.nap * 2).min(Self::LONGEST);
                }
                Err(TryRecvError::Disconnected) => return None,
            }
        }
    }
}
