//! The recorder's writer thread: the MCAP records of every value, read,
//! switch and error it is sent, the derived channels, and the end.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;
use std::sync::mpsc::{Receiver, Sender, TryRecvError};
use std::time::Duration;

use agent_core::link::remote::HEADER_LEN;
use agent_core::trace::{NodeInfo, SystemInfo};
use agent_core::{Stamp, Step, Time, TypeShape, WireHeader};
use serde_json::{Value, json};

use super::batch::{Entry, entries};
use super::{
    Backlog, Counts, Derive, FRAMES_ENCODING, LinkChannels, READ_ENCODING, Record, RecordError,
    RecordOptions, RecordSummary, Values, WIRE_ENCODING, encode_read, small,
};
use crate::cdr::{root_name, ros2msg_schema, write_cdr};
use crate::codec::CODEC_KEY;
use crate::json::{json_schema, write_json};

/// The writer thread's side.
pub(super) struct Output {
    pub(super) w: mcap::Writer<BufWriter<File>>,
    pub(super) path: PathBuf,
    pub(super) info: SystemInfo,
    pub(super) links: Vec<LinkChannels>,
    pub(super) fsm: Vec<u16>,
    pub(super) errors: u16,
    pub(super) derived: Vec<Box<dyn Derive>>,
    pub(super) value_max_bytes: usize,
    pub(super) scratch: Vec<u8>,
    /// A raw message: the wire header, then the body or the codec's
    /// encoding of it.
    pub(super) encoded: Vec<u8>,
    pub(super) summary: RecordSummary,
}

/// What the writer thread makes the file from: what needed the system, taken
/// on the caller's thread.
pub(super) struct Plan {
    pub(super) file: File,
    pub(super) path: PathBuf,
    pub(super) info: SystemInfo,
    /// Per link: the payload's shape as JSON text (`serde-reflection`'s
    /// formats cannot cross threads), and its fingerprint.
    pub(super) shapes: Vec<Option<String>>,
    pub(super) fingerprints: Vec<u64>,
    pub(super) options: RecordOptions,
}

impl Output {
    /// Start the file: its header, schemas, channels and metadata. Returns
    /// the writer and the links' shapes.
    pub(super) fn open(plan: Plan) -> Result<(Output, Vec<Option<TypeShape>>), RecordError> {
        let Plan {
            file,
            path,
            info,
            shapes,
            fingerprints,
            mut options,
        } = plan;
        let fail = |e: mcap::McapError| RecordError::Write {
            path: path.clone(),
            message: e.to_string(),
        };
        let shapes: Vec<Option<TypeShape>> = shapes
            .iter()
            .map(|text| {
                let (root, registry) = serde_json::from_str(text.as_deref()?).ok()?;
                Some(TypeShape { root, registry })
            })
            .collect();
        let mut w = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .compression_level(1)
            // On the writer thread: Zstd's default worker per CPU takes the
            // executor's core (measured: 1.47 -> 1.38 the wall time of a
            // recorded run without images, `bench_record`).
            .compression_threads(0)
            .profile("")
            .library(concat!(
                "embodied-agents agent-mcap ",
                env!("CARGO_PKG_VERSION")
            ))
            .create(BufWriter::new(file))
            .map_err(fail)?;
        let mut links = Vec::with_capacity(info.links.len());
        let mut json_values = Vec::new();
        let none = BTreeMap::new();
        let mut topics = std::collections::BTreeSet::new();
        for (k, link) in info.links.iter().enumerate() {
            let from = &info.nodes[link.from].name;
            let to = &info.nodes[link.to].name;
            let mut topic = format!("/links/{from}/{}/to/{to}", link.from_port.replace('.', "/"));
            if !topics.insert(topic.clone()) {
                topic = format!("{topic}/{}", link.to_port.replace('.', "/"));
                topics.insert(topic.clone());
            }
            let shape = shapes.get(k).and_then(Option::as_ref);
            let ros2 = match (shape, options.values) {
                (Some(s), Values::Cdr) => match ros2msg_schema(s, root_name(link.payload)) {
                    Ok(r) => Some(r),
                    Err(why) => {
                        json_values.push(format!("{}: {why}", link.name));
                        None
                    }
                },
                _ => None,
            };
            let (schema, encoding) = match (shape, &ros2) {
                (_, Some(r)) => (
                    w.add_schema(&r.name, "ros2msg", r.text.as_bytes())
                        .map_err(fail)?,
                    "cdr",
                ),
                (Some(s), None) => {
                    let text = json_schema(s, link.payload).to_string();
                    let id = w
                        .add_schema(link.payload, "jsonschema", text.as_bytes())
                        .map_err(fail)?;
                    (id, "json")
                }
                (None, None) => (0, "json"),
            };
            let value = w
                .add_channel(schema, &topic, encoding, &none)
                .map_err(fail)?;
            let fingerprint = fingerprints.get(k).copied().unwrap_or(0);
            let read_meta = BTreeMap::from([
                ("link".to_owned(), link.name.clone()),
                ("fingerprint".to_owned(), format!("{fingerprint:016x}")),
            ]);
            let codec = options
                .codecs
                .iter()
                .find(|c| c.payload() == link.payload)
                .cloned();
            let mut raw_meta = read_meta.clone();
            if let Some(c) = &codec {
                raw_meta.insert(CODEC_KEY.to_owned(), c.name().to_owned());
            }
            let raw = w
                .add_channel(0, &format!("/raw{topic}"), FRAMES_ENCODING, &raw_meta)
                .map_err(fail)?;
            let reads = w
                .add_channel(0, &format!("/reads{topic}"), READ_ENCODING, &read_meta)
                .map_err(fail)?;
            let mut derived = Vec::new();
            for (d, derive) in options.derived.iter_mut().enumerate() {
                if let Some(c) = derive.channel(k, link) {
                    let schema = w
                        .add_schema(&c.schema_name, &c.schema_encoding, &c.schema)
                        .map_err(fail)?;
                    let id = w
                        .add_channel(schema, &c.topic, &c.message_encoding, &none)
                        .map_err(fail)?;
                    derived.push((d, id));
                }
            }
            links.push(LinkChannels {
                topic: topic.clone(),
                raw_meta: raw_meta.clone(),
                received: None,
                received_count: 0,
                value,
                cdr: ros2.is_some(),
                raw,
                reads,
                read_sequence: 0,
                fingerprint,
                count: 0,
                derived,
                codec,
                pending: Vec::new(),
                pending_since: Time::ZERO,
                raw_messages: 0,
            });
        }
        let fsm_schema = w
            .add_schema(
                "embodied.Transition",
                "jsonschema",
                TRANSITION_SCHEMA.as_bytes(),
            )
            .map_err(fail)?;
        let mut fsm = Vec::with_capacity(info.nodes.len());
        for node in &info.nodes {
            fsm.push(
                w.add_channel(fsm_schema, &format!("/fsm/{}", node.name), "json", &none)
                    .map_err(fail)?,
            );
        }
        let error_schema = w
            .add_schema("embodied.Error", "jsonschema", ERROR_SCHEMA.as_bytes())
            .map_err(fail)?;
        let errors = w
            .add_channel(error_schema, "/errors", "json", &none)
            .map_err(fail)?;
        let mut metadata = std::mem::take(&mut options.metadata);
        metadata.insert("system".into(), describe(&info));
        for (name, entries) in metadata {
            w.write_metadata(&mcap::records::Metadata {
                name,
                metadata: entries,
            })
            .map_err(fail)?;
        }
        let channels =
            links.len() * 3 + links.iter().map(|l| l.derived.len()).sum::<usize>() + fsm.len() + 1;
        let out = Output {
            w,
            path,
            info,
            links,
            fsm,
            errors,
            derived: options.derived,
            value_max_bytes: options.value_max_bytes,
            scratch: Vec::new(),
            encoded: Vec::new(),
            summary: RecordSummary {
                channels,
                json_values,
                ..RecordSummary::default()
            },
        };
        Ok((out, shapes))
    }

    pub(super) fn run(
        mut self,
        rx: &Receiver<Record>,
        shapes: &[Option<TypeShape>],
        backlog: &Backlog,
    ) -> Result<RecordSummary, RecordError> {
        let mut error_count = 0u32;
        let mut give_back: BTreeMap<u16, Sender<Vec<u8>>> = BTreeMap::new();
        let mut counts = Counts::default();
        let mut finished = false;
        // Until the owner and every thread's part are gone.
        for record in Polled::new(rx) {
            match record {
                Record::Batch { part, bytes } => {
                    for entry in entries(&bytes) {
                        match entry {
                            Entry::Transfer { link, stamp, body } => {
                                let shape = shapes.get(link as usize).and_then(Option::as_ref);
                                self.transfer(link, shape, stamp, body)?;
                            }
                            Entry::Read { link, time, stamp } => self.read(link, time, stamp)?,
                            Entry::Received { link, stamp, body } => {
                                self.received(link, stamp, body)?;
                            }
                        }
                    }
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
        self.w.finish().map_err(|e| self.fail(&e))?;
        self.summary.waits = counts.waits;
        self.summary.backlog_peak_bytes = backlog.peak.load(std::sync::atomic::Ordering::Relaxed);
        self.summary.undecodable += counts.encode_failures;
        Ok(self.summary)
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

/// The system's nodes, behaviours and links, for the metadata record.
pub(super) fn describe(info: &SystemInfo) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    for n in &info.nodes {
        m.insert(
            format!("node/{}", n.name),
            format!(
                "agent {}, {:?}, period {}, behaviours [{}]",
                n.agent,
                n.kind,
                n.period,
                n.behaviours.join(", ")
            ),
        );
    }
    for (k, l) in info.links.iter().enumerate() {
        m.insert(
            format!("link/{k}"),
            format!("{} ({:?}, {})", l.name, l.policy, l.payload),
        );
    }
    m
}

pub(super) const TRANSITION_SCHEMA: &str = r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"embodied.Transition","type":"object","properties":{"time_s":{"type":"number"},"iteration":{"type":"integer"},"from":{"type":"string"},"to":{"type":"string"},"arc":{"type":"integer"},"condition":{"type":"string"},"predicates":{"type":"object","additionalProperties":{"type":"boolean"}},"finished":{"type":"boolean"}}}"#;

pub(super) const ERROR_SCHEMA: &str = r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"embodied.Error","type":"object","properties":{"time_s":{"type":"number"},"message":{"type":"string"}},"required":["time_s","message"]}"#;

/// The records of a queue, taken by polling: the writer sleeps while the queue
/// is empty instead of blocking in `recv`, so that a sender never has to wake
/// it. A send to a blocked receiver is a futex wake-up, a system call on the
/// executor's thread for every batch (measured: 3 % of the executor thread's
/// time in `futex_wake`, recording Rex's figure-eight without images); a send
/// to a sleeping poller is a store. The sleep doubles from [`Polled::FIRST`]
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
