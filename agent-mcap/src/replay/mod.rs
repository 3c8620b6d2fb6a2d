//! Replaying one subsystem against a recording, and proving it equivalent.
//!
//! [`replay`] takes the system built from the user's code (all of it, as for a
//! run: the same builder), runs only the named subsystem in the deterministic
//! executor ([`Executor::isolate`]), feeds it the recorded values of every link
//! into it ([`Executor::inject`], each with its recorded stamp) just before the
//! activation that read it in the run (the recording's reads channels: in a
//! real-time or distributed run which value an activation read depends on the
//! threads' timing; a file without them is fed by the deterministic
//! executor's rule, each value at the first activation after its instant), and
//! compares what it does with the recording, bit for bit:
//!
//! * every value it sends, on every link out of it: the instant, the sender's
//!   iteration, and the value's exact bytes;
//! * every behaviour switch: instant, iteration, behaviours, arc, and the value
//!   of every predicate at the decision (not the arc's text: a condition
//!   rewritten to the same effect is the same behaviour);
//! * the number of elementary actions it made.
//!
//! The result is [`Replayed::Equivalent`] or the first [`Divergence`]: the
//! instant, the iteration, the buffer and the field that differ, the two values,
//! and the behaviour each run was in.

mod compare;
mod verdict;

use std::collections::{BTreeMap, VecDeque};
use std::sync::Arc;

use agent_core::trace::{ErasedPayload, Observer, TransferEvent, TransitionEvent};
use agent_core::{
    ExecConfig, Executor, InjectError, NodeKind, Stamp, Step, System, Time, TypeShape, WireHeader,
};
use serde_json::Value;

use crate::codec::{CODEC_KEY, Codec};
use crate::read::Recording;
use crate::record::{FRAMES_ENCODING, READ_ENCODING, WIRE_ENCODING, decode_read, raw_values};
use compare::Compare;
pub use compare::first_difference;
pub use verdict::{Difference, Divergence, Replayed};

/// Why a replay could not be made (a replay that runs and differs is not an
/// error: it is a [`Divergence`]).
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The system has no subsystem of this name.
    #[error("no subsystem `{name}` in the system (it has: {available})")]
    NoSubsystem {
        /// The name asked for.
        name: String,
        /// The subsystems it has.
        available: String,
    },
    /// The recording has no raw channel for a link of the replayed subsystem.
    #[error(
        "the recording has no values of `{link}` (recorded by a system without this link? record again)"
    )]
    Unrecorded {
        /// The link.
        link: String,
    },
    /// A link was recorded through a codec this replay was not given.
    #[error(
        "`{link}` was recorded through the codec `{codec}`, which this replay was not given (ReplayOptions::codecs; given: {given})"
    )]
    Codec {
        /// The link.
        link: String,
        /// The codec its raw channel names.
        codec: String,
        /// The codecs the replay was given.
        given: String,
    },
    /// A link's payload type changed since the recording.
    #[error(
        "`{link}` carries a `{type_name}` whose type differs from the recorded one (fingerprint {built:016x}, recorded {recorded}): the recording cannot feed this build"
    )]
    Fingerprint {
        /// The link.
        link: String,
        /// The payload type.
        type_name: String,
        /// This build's fingerprint.
        built: u64,
        /// The recording's.
        recorded: String,
    },
    /// The recorder did not finish the file (no `end` record).
    #[error("{0} was not finished by its recorder (no `end` record): the run was cut short")]
    Unfinished(String),
    /// A recorded value could not be read or fed.
    #[error("the recorded value #{sequence} of `{link}` (file offset {offset}): {message}")]
    BadValue {
        /// The link.
        link: String,
        /// The value's sequence number in its channel.
        sequence: u32,
        /// The file offset of its record (or chunk).
        offset: u64,
        /// What is wrong.
        message: String,
    },
    /// The recording could not be read.
    #[error(transparent)]
    Read(#[from] crate::read::ReadError),
    /// The executor refused to go on.
    #[error("the replay stopped: {0}")]
    Exec(#[from] agent_core::ExecError),
}

/// How a replay runs.
#[derive(Clone)]
pub struct ReplayOptions {
    /// The executor's settings (its error policy should be the recorded run's).
    pub exec: ExecConfig,
    /// The codecs the recording was made with ([`RecordOptions::codecs`]):
    /// each link recorded through one is decoded with the codec of the name
    /// its raw channel gives.
    ///
    /// [`RecordOptions::codecs`]: crate::RecordOptions::codecs
    pub codecs: Vec<Arc<dyn Codec>>,
    /// Replay only one start of the subsystem's process (a recording of a
    /// run in which it was restarted holds several): its activations, from
    /// its first to its last. `None`: the whole recording, from instant zero.
    pub window: Option<Window>,
}

/// One start of a replayed subsystem's process in a recording: the instants
/// of the subsystem's first and last activations then, and how many actions
/// it made (as its part's `end` record says: `first/<node>`, `last/<node>`,
/// `iterations/<node>`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Window {
    /// The first activation's instant.
    pub first: Time,
    /// The last activation's instant.
    pub last: Time,
    /// The elementary actions it made.
    pub iterations: u64,
}

impl Window {
    /// The window of `node` in an `end` record (a file's own, or one part's
    /// `end/<process>` in a merged file), if the record names its first and
    /// last activations.
    pub fn of(end: &BTreeMap<String, String>, node: &str) -> Option<Window> {
        let get = |k: &str| end.get(&format!("{k}/{node}"))?.parse::<u64>().ok();
        Some(Window {
            first: Time::from_nanos(get("first")?),
            last: Time::from_nanos(get("last")?),
            iterations: get("iterations").unwrap_or(0),
        })
    }

    fn holds(&self, ns: u64) -> bool {
        (self.first.as_nanos()..=self.last.as_nanos()).contains(&ns)
    }
}

impl std::fmt::Debug for ReplayOptions {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ReplayOptions")
            .field("exec", &self.exec)
            .field(
                "codecs",
                &self.codecs.iter().map(|c| c.name()).collect::<Vec<_>>(),
            )
            .field("window", &self.window)
            .finish()
    }
}

impl Default for ReplayOptions {
    fn default() -> Self {
        ReplayOptions {
            exec: ExecConfig::continue_on_error(),
            codecs: Vec::new(),
            window: None,
        }
    }
}

/// What the replayed subsystem did in one instant.
pub(crate) enum Event {
    Transfer {
        link: usize,
        stamp: Stamp,
        bytes: Vec<u8>,
    },
    Switch {
        time: Time,
        iteration: u64,
        step: Step,
    },
}

struct Watch {
    node: usize,
    events: Vec<Event>,
    actions: u64,
}

impl Observer for Watch {
    fn transition(&mut self, e: &TransitionEvent) {
        if e.node == self.node {
            self.events.push(Event::Switch {
                time: e.time,
                iteration: e.iteration,
                step: e.step,
            });
        }
    }
    fn action(&mut self, e: &agent_core::ActionEvent) {
        if e.node == self.node {
            self.actions += 1;
        }
    }
    fn transfer(&mut self, e: &TransferEvent, value: &dyn ErasedPayload) {
        let mut bytes = Vec::new();
        // A value that cannot be encoded compares as no bytes (it differs
        // from any recorded value, which was encoded).
        let _ = value.encode(&mut bytes);
        self.events.push(Event::Transfer {
            link: e.link,
            stamp: e.stamp,
            bytes,
        });
    }
}

/// A recorded value: its stamp, its bytes, where it is in the file.
pub(crate) struct Recorded {
    pub(crate) stamp: Stamp,
    pub(crate) body: Vec<u8>,
    pub(crate) sequence: u32,
    pub(crate) offset: u64,
}

/// [`replay`] against the file at `path`, reading only what the replay needs:
/// the values of the links into and out of `node`, and its behaviour switches.
pub fn replay_file(
    path: &std::path::Path,
    system: System,
    node: &str,
    options: ReplayOptions,
) -> Result<Replayed, ReplayError> {
    let info = system.info();
    let wanted: std::collections::BTreeSet<&str> = info
        .links
        .iter()
        .filter(|l| info.nodes[l.from].name == node || info.nodes[l.to].name == node)
        .map(|l| l.name.as_str())
        .collect();
    let fsm = format!("/fsm/{node}");
    let recording = Recording::open_filtered(path, |c| {
        c.topic == fsm
            || ([FRAMES_ENCODING, WIRE_ENCODING, READ_ENCODING]
                .contains(&c.message_encoding.as_str())
                && c.metadata
                    .get("link")
                    .is_some_and(|l| wanted.contains(l.as_str())))
    })?;
    replay(&recording, system, node, options)
}

/// Replay subsystem `node` of `system` (built from the user's code, whole)
/// against `recording` (see the module's documentation).
pub fn replay(
    recording: &Recording,
    system: System,
    node: &str,
    options: ReplayOptions,
) -> Result<Replayed, ReplayError> {
    let info = system.info().clone();
    let subsystems = || {
        info.nodes
            .iter()
            .filter(|n| !matches!(n.kind, NodeKind::RealEffector | NodeKind::RealReceptor))
            .map(|n| n.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    let x = info
        .nodes
        .iter()
        .position(|n| {
            n.name == node && !matches!(n.kind, NodeKind::RealEffector | NodeKind::RealReceptor)
        })
        .ok_or_else(|| ReplayError::NoSubsystem {
            name: node.to_owned(),
            available: subsystems(),
        })?;
    // One start of a restarted process is replayed from its part's own end
    // record (another part may never have been finished: killed).
    let window = options.window;
    if window.is_none() && !recording.finished() {
        return Err(ReplayError::Unfinished(
            recording.path.display().to_string(),
        ));
    }
    let end = recording.metadata.get("end");
    // The node's own last instant (the processes of a deployment stop at
    // different instants), else the run's.
    let end_time = match window {
        Some(w) => w.last,
        None => end
            .and_then(|m| {
                m.get(&format!("last/{node}"))
                    .or_else(|| m.get("time_ns"))?
                    .parse::<u64>()
                    .ok()
            })
            .map_or(Time::ZERO, Time::from_nanos),
    };
    let recorded_iterations = match window {
        Some(w) => w.iterations,
        None => end
            .and_then(|m| m.get(&format!("iterations/{node}"))?.parse::<u64>().ok())
            .unwrap_or(0),
    };
    // What the node itself did is the window's; what others sent it is
    // matched by its reads.
    let own = |ns: u64| window.is_none_or(|w| w.holds(ns));

    // The raw and reads channels by link name.
    let by_encoding = |encoding: &str| -> BTreeMap<&str, &crate::read::ChannelInfo> {
        recording
            .channels
            .values()
            .filter(|c| c.message_encoding == encoding)
            .filter_map(|c| Some((c.metadata.get("link")?.as_str(), c)))
            .collect()
    };
    let received = |c: &&crate::read::ChannelInfo| c.metadata.contains_key("received");
    let mut by_link: BTreeMap<&str, &crate::read::ChannelInfo> = recording
        .channels
        .values()
        .filter(|c| c.message_encoding == WIRE_ENCODING && !received(c))
        .filter_map(|c| Some((c.metadata.get("link")?.as_str(), c)))
        .collect();
    by_link.extend(by_encoding(FRAMES_ENCODING));
    let reads_by_link = by_encoding(READ_ENCODING);
    // Values a process took from another: fed where the sender's recording
    // lacks them (a sender killed before its recorder wrote them).
    let received_by_link: BTreeMap<&str, &crate::read::ChannelInfo> = recording
        .channels
        .values()
        .filter(|c| c.message_encoding == WIRE_ENCODING && received(c))
        .filter_map(|c| Some((c.metadata.get("link")?.as_str(), c)))
        .collect();
    let mut channel_link: BTreeMap<u16, (usize, &str)> = BTreeMap::new();
    let mut codecs: BTreeMap<u16, Arc<dyn Codec>> = BTreeMap::new();
    let mut read_channel_link: BTreeMap<u16, usize> = BTreeMap::new();
    let mut shapes: BTreeMap<usize, Option<TypeShape>> = BTreeMap::new();
    for (k, link) in info.links.iter().enumerate() {
        let input = link.to == x && link.from != x;
        let output = link.from == x;
        if !(input || output) {
            continue;
        }
        let c = by_link
            .get(link.name.as_str())
            .ok_or_else(|| ReplayError::Unrecorded {
                link: link.name.clone(),
            })?;
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
        if let Some(name) = c.metadata.get(CODEC_KEY) {
            let codec = options
                .codecs
                .iter()
                .find(|codec| codec.name() == name)
                .ok_or_else(|| ReplayError::Codec {
                    link: link.name.clone(),
                    codec: name.clone(),
                    given: options
                        .codecs
                        .iter()
                        .map(|c| format!("`{}`", c.name()))
                        .collect::<Vec<_>>()
                        .join(", "),
                })?;
            codecs.insert(c.id, codec.clone());
        }
        channel_link.insert(c.id, (k, c.message_encoding.as_str()));
        if input && let Some(r) = reads_by_link.get(link.name.as_str()) {
            read_channel_link.insert(r.id, k);
        }
        if input && let Some(r) = received_by_link.get(link.name.as_str()) {
            channel_link.insert(r.id, (k, WIRE_ENCODING));
            if let Some(codec) = codecs.get(&c.id).cloned() {
                codecs.insert(r.id, codec);
            }
        }
        if output {
            shapes.insert(k, system.payload_shape(k));
        }
    }
    let fsm_channel = recording.channel(&format!("/fsm/{node}")).map(|c| c.id);

    // The recorded values: inputs to feed, outputs and switches to compare.
    let mut sent: BTreeMap<usize, Vec<Recorded>> = BTreeMap::new();
    let mut reads: BTreeMap<usize, Vec<(u64, Stamp, &crate::read::Message)>> = BTreeMap::new();
    let mut outputs: BTreeMap<usize, VecDeque<Recorded>> = BTreeMap::new();
    let mut switches: VecDeque<(u64, Value)> = VecDeque::new();
    for m in &recording.messages {
        if Some(m.channel) == fsm_channel {
            if !own(m.log_time) {
                continue;
            }
            let v: Value = serde_json::from_slice(&m.data).map_err(|e| ReplayError::BadValue {
                link: format!("/fsm/{node}"),
                sequence: m.sequence,
                offset: m.offset,
                message: e.to_string(),
            })?;
            switches.push_back((m.log_time, v));
            continue;
        }
        if let Some(&k) = read_channel_link.get(&m.channel) {
            let stamp = decode_read(&m.data).ok_or_else(|| ReplayError::BadValue {
                link: info.links[k].name.clone(),
                sequence: m.sequence,
                offset: m.offset,
                message: format!("a read of {} bytes (16 expected)", m.data.len()),
            })?;
            if own(m.log_time) {
                reads.entry(k).or_default().push((m.log_time, stamp, m));
            }
            continue;
        }
        let Some(&(k, encoding)) = channel_link.get(&m.channel) else {
            continue;
        };
        let bad = |sequence: u32, message: String| ReplayError::BadValue {
            link: info.links[k].name.clone(),
            sequence,
            offset: m.offset,
            message,
        };
        for value in raw_values(encoding, &m.data) {
            let value = value.map_err(|e| bad(m.sequence, format!("raw message: {e}")))?;
            let (header, body) =
                WireHeader::read(value).map_err(|e| bad(m.sequence, e.to_string()))?;
            // The value's number on its link, from 0 (the header's count is from 1).
            let sequence = header.seq.wrapping_sub(1) as u32;
            let body = match codecs.get(&m.channel) {
                Some(codec) => {
                    let mut decoded = Vec::new();
                    codec
                        .decode(body, &mut decoded)
                        .map_err(|e| bad(sequence, format!("codec `{}`: {e}", codec.name())))?;
                    decoded
                }
                None => body.to_vec(),
            };
            let r = Recorded {
                stamp: header.stamp,
                body,
                sequence,
                offset: m.offset,
            };
            if info.links[k].from == x {
                if own(header.stamp.time.as_nanos()) {
                    outputs.entry(k).or_default().push_back(r);
                }
            } else {
                sent.entry(k).or_default().push(r);
            }
        }
    }
    for k in read_channel_link.values() {
        reads.entry(*k).or_default();
    }
    let inputs = feeds(&info, sent, reads)?;
    let out_links: Vec<usize> = info
        .links
        .iter()
        .enumerate()
        .filter(|(_, l)| l.from == x && l.to != x)
        .map(|(k, _)| k)
        .collect();

    let n = &info.nodes[x];
    let initial = n.fsm.as_ref().map_or_else(
        || n.behaviours.first().cloned().unwrap_or_default(),
        |f| f.initial.clone(),
    );
    let mut cmp = Compare {
        node: &info.nodes[x],
        info: &info,
        shapes: &shapes,
        recorded_behaviour: initial.clone(),
        replayed_behaviour: initial,
        compared: 0,
        switched: 0,
    };

    let id = system.node(node).ok_or_else(|| ReplayError::NoSubsystem {
        name: node.to_owned(),
        available: subsystems(),
    })?;
    let mut exec = Executor::with_observer(
        system,
        options.exec,
        Watch {
            node: x,
            events: Vec::new(),
            actions: 0,
        },
    );
    exec.isolate(id);
    if let Some(w) = window {
        exec.start_at(id, w.first);
    }
    let mut fed = 0u64;
    let mut next_input = 0usize;
    while let Some(t) = exec.next_instant() {
        if t > end_time {
            break;
        }
        while let Some((due, k, r)) = inputs.get(next_input) {
            if *due > t {
                break;
            }
            exec.inject(*k, &r.body, r.stamp)
                .map_err(|e| bad_input(&info, *k, r, &e))?;
            next_input += 1;
            fed += 1;
        }
        let iteration = exec.observer().actions;
        exec.step()?;
        for &k in &out_links {
            exec.discard(k);
        }
        let events = std::mem::take(&mut exec.observer_mut().events);
        if let Some(d) = cmp.instant(t, iteration, events, &mut outputs, &mut switches) {
            return Ok(Replayed::Diverged(Box::new(d)));
        }
    }
    let replayed = exec.observer().actions;
    Ok(cmp.end(
        (end_time, replayed, recorded_iterations),
        fed,
        &mut outputs,
        &mut switches,
    ))
}

/// The inputs in the order they are fed, each with the instant of the
/// activation that reads it: the recorded reads of a link where the file has
/// them (`reads` has an entry, perhaps empty, for each link whose reads were
/// recorded), else the first activation after the value's instant.
fn feeds(
    info: &agent_core::SystemInfo,
    sent: BTreeMap<usize, Vec<Recorded>>,
    reads: BTreeMap<usize, Vec<(u64, Stamp, &crate::read::Message)>>,
) -> Result<Vec<(Time, usize, Recorded)>, ReplayError> {
    let mut inputs = Vec::new();
    for (k, values) in sent {
        match reads.get(&k) {
            Some(reads) => {
                let mut by_stamp: BTreeMap<(u64, u64), Recorded> = values
                    .into_iter()
                    .map(|r| ((r.stamp.iteration, r.stamp.time.as_nanos()), r))
                    .collect();
                for (at, stamp, m) in reads {
                    let r = by_stamp
                        .remove(&(stamp.iteration, stamp.time.as_nanos()))
                        .ok_or_else(|| ReplayError::BadValue {
                            link: info.links[k].name.clone(),
                            sequence: m.sequence,
                            offset: m.offset,
                            message: format!(
                                "read at {} a value the recording does not hold (sent at {}, iteration {})",
                                Time::from_nanos(*at),
                                stamp.time,
                                stamp.iteration
                            ),
                        })?;
                    inputs.push((Time::from_nanos(*at), k, r));
                }
            }
            None => {
                // A value recorded by its sender and by its receiver is fed once.
                let mut seen = std::collections::BTreeSet::new();
                inputs.extend(
                    values
                        .into_iter()
                        .filter(|r| seen.insert((r.stamp.iteration, r.stamp.time.as_nanos())))
                        .map(|r| {
                            (
                                Time::from_nanos(r.stamp.time.as_nanos().saturating_add(1)),
                                k,
                                r,
                            )
                        }),
                );
            }
        }
    }
    // Stable: a link's values stay in their order.
    inputs.sort_by_key(|(due, _, _)| *due);
    Ok(inputs)
}

fn bad_input(
    info: &agent_core::SystemInfo,
    k: usize,
    r: &Recorded,
    e: &InjectError,
) -> ReplayError {
    ReplayError::BadValue {
        link: info.links[k].name.clone(),
        sequence: r.sequence,
        offset: r.offset,
        message: e.to_string(),
    }
}
