//! Replaying one subsystem against a recording, and proving it equivalent.
//!
//! [`replay`] takes the system built from the user's code (all of it, as for a
//! run: the same builder), runs only the named subsystem in the deterministic
//! executor ([`Executor::isolate`]), feeds it the recorded values of every link
//! into it at the recorded instants ([`Executor::inject`], each with its
//! recorded stamp: the executor's semantics make it read a value at its first
//! activation after the value's instant, as in the run), and compares what it
//! does with the recording, bit for bit:
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

use std::collections::{BTreeMap, VecDeque};
use std::fmt;

use agent_core::trace::{ErasedPayload, Observer, TransferEvent, TransitionEvent};
use agent_core::{
    ExecConfig, Executor, InjectError, NodeKind, Stamp, Step, System, Time, TypeShape, WireHeader,
};
use serde_json::Value;

use crate::json::to_json;
use crate::read::Recording;
use crate::record::{WIRE_ENCODING, transition_json};

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

/// What a replay found.
#[derive(Clone, Debug, PartialEq)]
pub enum Replayed {
    /// The subsystem did what the recording says, bit for bit.
    Equivalent {
        /// Elementary actions made (and recorded).
        iterations: u64,
        /// Values compared (sent by the subsystem) and fed (recorded values
        /// of the links into it).
        transfers: u64,
        /// Behaviour switches compared.
        switches: u64,
    },
    /// The first place where it did not.
    Diverged(Box<Divergence>),
}

impl Replayed {
    /// Whether the replay is equivalent.
    pub fn is_equivalent(&self) -> bool {
        matches!(self, Replayed::Equivalent { .. })
    }
}

impl fmt::Display for Replayed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Replayed::Equivalent {
                iterations,
                transfers,
                switches,
            } => write!(
                f,
                "equivalent: {iterations} iterations, {transfers} transfers, {switches} behaviour switches"
            ),
            Replayed::Diverged(d) => write!(f, "{d}"),
        }
    }
}

/// The first difference between a replay and its recording.
#[derive(Clone, Debug, PartialEq)]
pub struct Divergence {
    /// The subsystem.
    pub node: String,
    /// The instant of the first difference.
    pub time: Time,
    /// The subsystem's iteration there (its elementary actions made before).
    pub iteration: u64,
    /// What differs.
    pub what: Difference,
    /// The behaviour the recorded run was in.
    pub recorded_behaviour: String,
    /// The behaviour the replay was in.
    pub replayed_behaviour: String,
}

/// What differs at a [`Divergence`].
#[derive(Clone, Debug, PartialEq)]
pub enum Difference {
    /// A value sent on a link differs.
    Value {
        /// The link (`node.port -> node.port`).
        link: String,
        /// The first field that differs (`points[3].x`; empty: the whole value,
        /// or its bytes only, for example a NaN's).
        field: String,
        /// The recorded value of that field (JSON).
        recorded: String,
        /// The replayed one.
        replayed: String,
    },
    /// The recorded run sent a value the replay did not send (then).
    Missing {
        /// The link.
        link: String,
        /// The recorded value (JSON).
        recorded: String,
    },
    /// The replay sent a value the recorded run did not send (then).
    Extra {
        /// The link.
        link: String,
        /// The replayed value (JSON).
        replayed: String,
    },
    /// A behaviour switch differs, is missing, or is extra (`None`).
    Switch {
        /// The recorded switch (JSON).
        recorded: Option<String>,
        /// The replayed one.
        replayed: Option<String>,
    },
    /// The replay made a different number of elementary actions.
    Iterations {
        /// Recorded.
        recorded: u64,
        /// Replayed.
        replayed: u64,
    },
}

impl fmt::Display for Divergence {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "diverged at {:.3} s ({} iteration {}): ",
            self.time.as_secs_f64(),
            self.node,
            self.iteration
        )?;
        match &self.what {
            Difference::Value {
                link,
                field,
                recorded,
                replayed,
            } => {
                let field = if field.is_empty() {
                    "(the value)"
                } else {
                    field
                };
                write!(
                    f,
                    "buffer `{link}`, field {field}: recorded {recorded}, replayed {replayed}"
                )?;
            }
            Difference::Missing { link, recorded } => {
                write!(f, "buffer `{link}`: recorded {recorded}, replayed nothing")?;
            }
            Difference::Extra { link, replayed } => {
                write!(f, "buffer `{link}`: recorded nothing, replayed {replayed}")?;
            }
            Difference::Switch { recorded, replayed } => {
                let or_none = |s: &Option<String>| s.clone().unwrap_or_else(|| "none".into());
                write!(
                    f,
                    "behaviour switch: recorded {}, replayed {}",
                    or_none(recorded),
                    or_none(replayed)
                )?;
            }
            Difference::Iterations { recorded, replayed } => {
                write!(f, "recorded {recorded} iterations, replayed {replayed}")?;
            }
        }
        write!(
            f,
            "; {} was in {} (recorded) and {} (replayed)",
            self.node, self.recorded_behaviour, self.replayed_behaviour
        )
    }
}

/// How a replay runs.
#[derive(Clone, Copy, Debug)]
pub struct ReplayOptions {
    /// The executor's settings (its error policy should be the recorded run's).
    pub exec: ExecConfig,
}

impl Default for ReplayOptions {
    fn default() -> Self {
        ReplayOptions {
            exec: ExecConfig::continue_on_error(),
        }
    }
}

/// What the replayed subsystem did in one instant.
enum Event {
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
struct Recorded {
    stamp: Stamp,
    body: Vec<u8>,
    sequence: u32,
    offset: u64,
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
            || (c.message_encoding == WIRE_ENCODING
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
    if !recording.finished() {
        return Err(ReplayError::Unfinished(
            recording.path.display().to_string(),
        ));
    }
    let end = recording.metadata.get("end");
    let end_time = end
        .and_then(|m| m.get("time_ns")?.parse::<u64>().ok())
        .map_or(Time::ZERO, Time::from_nanos);
    let recorded_iterations = end
        .and_then(|m| m.get(&format!("iterations/{node}"))?.parse::<u64>().ok())
        .unwrap_or(0);

    // The raw channels by link name.
    let by_link: BTreeMap<&str, &crate::read::ChannelInfo> = recording
        .channels
        .values()
        .filter(|c| c.message_encoding == WIRE_ENCODING)
        .filter_map(|c| Some((c.metadata.get("link")?.as_str(), c)))
        .collect();
    let mut channel_link: BTreeMap<u16, usize> = BTreeMap::new();
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
        channel_link.insert(c.id, k);
        if output {
            shapes.insert(k, system.payload_shape(k));
        }
    }
    let fsm_channel = recording.channel(&format!("/fsm/{node}")).map(|c| c.id);

    // The recorded values: inputs to feed, outputs and switches to compare.
    let mut inputs: Vec<(usize, Recorded)> = Vec::new();
    let mut outputs: BTreeMap<usize, VecDeque<Recorded>> = BTreeMap::new();
    let mut switches: VecDeque<(u64, Value)> = VecDeque::new();
    for m in &recording.messages {
        if Some(m.channel) == fsm_channel {
            let v: Value = serde_json::from_slice(&m.data).map_err(|e| ReplayError::BadValue {
                link: format!("/fsm/{node}"),
                sequence: m.sequence,
                offset: m.offset,
                message: e.to_string(),
            })?;
            switches.push_back((m.log_time, v));
            continue;
        }
        let Some(&k) = channel_link.get(&m.channel) else {
            continue;
        };
        let (header, body) = WireHeader::read(&m.data).map_err(|e| ReplayError::BadValue {
            link: info.links[k].name.clone(),
            sequence: m.sequence,
            offset: m.offset,
            message: e.to_string(),
        })?;
        let r = Recorded {
            stamp: header.stamp,
            body: body.to_vec(),
            sequence: m.sequence,
            offset: m.offset,
        };
        if info.links[k].from == x {
            outputs.entry(k).or_default().push_back(r);
        } else {
            inputs.push((k, r));
        }
    }
    inputs.sort_by_key(|(_, r)| r.stamp.time);
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
        node: node.to_owned(),
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
    let mut fed = 0u64;
    let mut next_input = 0usize;
    while let Some(t) = exec.next_instant() {
        if t > end_time {
            break;
        }
        while let Some((k, r)) = inputs.get(next_input) {
            if r.stamp.time >= t {
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
    // What the recording has and the replay never did.
    if let Some(d) = cmp.leftover(replayed, &mut outputs, &mut switches) {
        return Ok(Replayed::Diverged(Box::new(d)));
    }
    if replayed != recorded_iterations {
        return Ok(Replayed::Diverged(Box::new(Divergence {
            node: node.to_owned(),
            time: end_time,
            iteration: replayed,
            what: Difference::Iterations {
                recorded: recorded_iterations,
                replayed,
            },
            recorded_behaviour: cmp.recorded_behaviour.clone(),
            replayed_behaviour: cmp.replayed_behaviour.clone(),
        })));
    }
    Ok(Replayed::Equivalent {
        iterations: replayed,
        transfers: cmp.compared + fed,
        switches: cmp.switched,
    })
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

/// The comparison's state.
struct Compare<'a> {
    node: String,
    info: &'a agent_core::SystemInfo,
    shapes: &'a BTreeMap<usize, Option<TypeShape>>,
    recorded_behaviour: String,
    replayed_behaviour: String,
    compared: u64,
    switched: u64,
}

/// A switch as compared: without the arc's text.
fn comparable(mut v: Value) -> Value {
    if let Some(o) = v.as_object_mut() {
        o.remove("condition");
    }
    v
}

fn entered(v: &Value) -> Option<String> {
    v.get("to")?.as_str().map(str::to_owned)
}

impl Compare<'_> {
    fn json(&self, link: usize, body: &[u8]) -> Value {
        match self.shapes.get(&link).and_then(Option::as_ref) {
            Some(shape) => to_json(shape, body).unwrap_or_else(|_| hex(body)),
            None => hex(body),
        }
    }

    fn divergence(&self, time: Time, iteration: u64, what: Difference) -> Divergence {
        Divergence {
            node: self.node.clone(),
            time,
            iteration,
            what,
            recorded_behaviour: self.recorded_behaviour.clone(),
            replayed_behaviour: self.replayed_behaviour.clone(),
        }
    }

    /// The recorded behaviour up to and including instant `t`.
    fn follow_recorded(&mut self, t: Time, switches: &VecDeque<(u64, Value)>) {
        if let Some(to) = switches
            .iter()
            .take_while(|(at, _)| *at <= t.as_nanos())
            .filter_map(|(_, v)| entered(v))
            .last()
        {
            self.recorded_behaviour = to;
        }
    }

    /// Compare one instant's events; then what was recorded up to it and not
    /// replayed.
    fn instant(
        &mut self,
        t: Time,
        iteration: u64,
        events: Vec<Event>,
        outputs: &mut BTreeMap<usize, VecDeque<Recorded>>,
        switches: &mut VecDeque<(u64, Value)>,
    ) -> Option<Divergence> {
        for event in events {
            match event {
                Event::Switch {
                    time,
                    iteration: it,
                    step,
                } => {
                    let node = &self.info.nodes.iter().find(|n| n.name == self.node)?;
                    let replayed = comparable(transition_json(node, time, it, step));
                    match switches.front() {
                        Some((at, v))
                            if *at == time.as_nanos() && comparable(v.clone()) == replayed =>
                        {
                            if let Some(to) = entered(v) {
                                self.recorded_behaviour = to;
                            }
                            if let Some(to) = entered(&replayed) {
                                self.replayed_behaviour = to;
                            }
                            switches.pop_front();
                            self.switched += 1;
                        }
                        other => {
                            let recorded = other
                                .filter(|(at, _)| *at <= time.as_nanos())
                                .map(|(_, v)| comparable(v.clone()).to_string());
                            return Some(self.divergence(
                                time,
                                iteration,
                                Difference::Switch {
                                    recorded,
                                    replayed: Some(replayed.to_string()),
                                },
                            ));
                        }
                    }
                }
                Event::Transfer { link, stamp, bytes } => {
                    let name = self.info.links[link].name.clone();
                    let queue = outputs.entry(link).or_default();
                    match queue.front() {
                        Some(r) if r.stamp == stamp && r.body == bytes => {
                            queue.pop_front();
                            self.compared += 1;
                        }
                        Some(r) if r.stamp.time == stamp.time => {
                            let (rec, rep) = (self.json(link, &r.body), self.json(link, &bytes));
                            let (field, a, b) = first_difference(&rec, &rep)
                                .unwrap_or_else(|| (String::new(), hex(&r.body), hex(&bytes)));
                            self.follow_recorded(t, switches);
                            return Some(self.divergence(
                                t,
                                iteration,
                                Difference::Value {
                                    link: name,
                                    field,
                                    recorded: a.to_string(),
                                    replayed: b.to_string(),
                                },
                            ));
                        }
                        _ => {
                            let replayed = self.json(link, &bytes).to_string();
                            self.follow_recorded(t, switches);
                            return Some(self.divergence(
                                t,
                                iteration,
                                Difference::Extra {
                                    link: name,
                                    replayed,
                                },
                            ));
                        }
                    }
                }
            }
        }
        // Recorded at or before this instant and not replayed.
        self.missing(Some(t), iteration, outputs, switches)
    }

    fn missing(
        &mut self,
        upto: Option<Time>,
        iteration: u64,
        outputs: &mut BTreeMap<usize, VecDeque<Recorded>>,
        switches: &mut VecDeque<(u64, Value)>,
    ) -> Option<Divergence> {
        let due = |at: Time| upto.is_none_or(|t| at <= t);
        let output = outputs
            .iter()
            .filter_map(|(k, q)| Some((*k, q.front()?)))
            .filter(|(_, r)| due(r.stamp.time))
            .min_by_key(|(_, r)| r.stamp.time);
        let switch = switches
            .front()
            .filter(|(at, _)| due(Time::from_nanos(*at)));
        match (output, switch) {
            (Some((k, r)), s) if s.is_none_or(|(at, _)| r.stamp.time.as_nanos() < *at) => {
                let at = r.stamp.time;
                let recorded = self.json(k, &r.body).to_string();
                let link = self.info.links[k].name.clone();
                self.follow_recorded(at, switches);
                Some(self.divergence(at, iteration, Difference::Missing { link, recorded }))
            }
            (_, Some((at, v))) => {
                let recorded = Some(comparable(v.clone()).to_string());
                Some(self.divergence(
                    Time::from_nanos(*at),
                    iteration,
                    Difference::Switch {
                        recorded,
                        replayed: None,
                    },
                ))
            }
            _ => None,
        }
    }

    fn leftover(
        &mut self,
        iteration: u64,
        outputs: &mut BTreeMap<usize, VecDeque<Recorded>>,
        switches: &mut VecDeque<(u64, Value)>,
    ) -> Option<Divergence> {
        self.missing(None, iteration, outputs, switches)
    }
}

/// The first field (a path like `points[3].x`) where two JSON values differ,
/// with the two values there.
pub fn first_difference(a: &Value, b: &Value) -> Option<(String, Value, Value)> {
    fn walk(path: &mut String, a: &Value, b: &Value) -> Option<(String, Value, Value)> {
        match (a, b) {
            (Value::Object(x), Value::Object(y)) => {
                for (k, va) in x {
                    let len = path.len();
                    if !path.is_empty() {
                        path.push('.');
                    }
                    path.push_str(k);
                    let found = match y.get(k) {
                        Some(vb) => walk(path, va, vb),
                        None => Some((path.clone(), va.clone(), Value::Null)),
                    };
                    if found.is_some() {
                        return found;
                    }
                    path.truncate(len);
                }
                y.iter()
                    .find(|(k, _)| !x.contains_key(*k))
                    .map(|(k, vb)| (format!("{path}.{k}"), Value::Null, vb.clone()))
            }
            (Value::Array(x), Value::Array(y)) => {
                for (i, (va, vb)) in x.iter().zip(y).enumerate() {
                    let len = path.len();
                    path.push_str(&format!("[{i}]"));
                    if let Some(found) = walk(path, va, vb) {
                        return Some(found);
                    }
                    path.truncate(len);
                }
                (x.len() != y.len()).then(|| {
                    (
                        format!("{path}.len()"),
                        Value::from(x.len()),
                        Value::from(y.len()),
                    )
                })
            }
            _ => (a != b).then(|| (path.clone(), a.clone(), b.clone())),
        }
    }
    walk(&mut String::new(), a, b)
}

fn hex(bytes: &[u8]) -> Value {
    let mut s = String::with_capacity(2 * bytes.len().min(64) + 3);
    for b in bytes.iter().take(64) {
        s.push_str(&format!("{b:02x}"));
    }
    if bytes.len() > 64 {
        s.push_str("...");
    }
    Value::String(s)
}
