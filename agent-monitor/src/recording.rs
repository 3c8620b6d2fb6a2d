//! The contracts evaluated over a recording ([`agent_mcap::Recording`]):
//! the same monitors fed the events the recorder wrote, in time order.
//!
//! What each kind reads (the channels of [`agent_mcap::record`]):
//!
//! * freshness: `/reads/links/...`, each read at the reader's instant (log
//!   time) with the stamp of the value read;
//! * rate: the link's value channel `/links/...`, one message per value sent,
//!   at the sender's instant (a value larger than the recorder's
//!   `value_max_bytes` is on the raw channel only, and is not counted);
//! * response: the same value channels, of the links from the trigger and the
//!   response;
//! * bound: `/fsm/<subsystem>`, each switch with its instant and the
//!   subsystem's iteration (a run entered at iteration `i` and left at
//!   iteration `j` took `j - i` activations); the initial behaviour is entered
//!   at the subsystem's first activation (metadata `end`, `first/<node>`);
//! * range: the value channel. CDR (the recorder's default): each message
//!   read back into the value's postcard bytes by the payload's shape the
//!   channel's metadata holds ([`agent_mcap::read::ChannelInfo::payload_shape`],
//!   [`agent_mcap::cdr::read_cdr`], which checks every length, tag and the
//!   message's end), then the field read as the live watch reads it (the
//!   payload's layout, `field`): the same values as while the robot ran,
//!   NaN included. A CDR channel without a shape (a recording made before the
//!   recorder kept them) makes its ranges not evaluable, said so. JSON
//!   (`RecordOptions::values` `Values::Json`): the field read from the JSON
//!   form, where a non-finite number is `null` (read as NaN: out of range).
//!   A message that does not decode is an error naming its channel and
//!   offset. A range on a memory buffer is not evaluable (the recorder writes
//!   links only);
//! * invariant: `/predicates/<subsystem>`, the values of the predicates the
//!   live watch asked for after each activation of the subsystem (the
//!   recorder writes them for the subsystems whose invariants a watch beside
//!   it judged, and for no other). A recording without that channel (made
//!   without the watch, or by an older recorder) makes the subsystem's
//!   invariants not evaluable, said so; `/fsm` holds predicate values at
//!   behaviour switches only, which is not enough.
//!
//! A contract is matched to a link by its ends: the input `c.g.b` is the end
//! of the link from node `g` into node `c` whose port is `g.b` or ends with
//! `.b` (the code may name its port groups otherwise than the spec's peers);
//! an output likewise from its writer's side. A contract whose buffer is on
//! no recorded link is reported not evaluable, never passed silently.
//!
//! The watch starts at the first activation of any node (metadata `end`, or
//! the first message) and ends at the last activation (or the last message).

use std::collections::BTreeMap;
use std::rc::Rc;

use agent_core::{Time, TypeShape};
use agent_mcap::Recording;
use agent_mcap::read::ChannelInfo;
use agent_mcap::record::PREDICATES_PREFIX;
use serde_json::Value;

use crate::ends::Ends;
use crate::field::Layout;
use crate::{
    BehaviourId, ContractId, InputId, Monitors, OutputId, RangeId, SubsystemId, Violation,
};

/// Why a recording could not be evaluated.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// A message that does not read as its channel says.
    #[error("{topic}: message at offset {offset}: {why}")]
    Message {
        /// Its channel's topic.
        topic: String,
        /// The offset of the message (of its chunk).
        offset: u64,
        /// What is wrong.
        why: String,
    },
    /// The recording names a behaviour the spec does not have.
    #[error("{topic}: behaviour `{behaviour}` is not in the spec (a recording of another spec?)")]
    Behaviour {
        /// The `/fsm/<node>` channel.
        topic: String,
        /// The behaviour.
        behaviour: String,
    },
}

/// The verdicts over one recording.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Report {
    /// The contracts evaluated.
    pub checked: Vec<ContractId>,
    /// The contracts that could not be, each with why.
    pub not_evaluable: Vec<(ContractId, String)>,
    /// The violations, in time order.
    pub violations: Vec<Violation>,
    /// The instant the watch started.
    pub start: Time,
    /// The instant it ended.
    pub end: Time,
}

impl Report {
    /// How many contracts were violated (at least once).
    pub fn contracts_violated(&self) -> usize {
        crate::contracts_violated(&self.violations)
    }
}

/// The channels [`evaluate`] reads: open a recording with this filter to
/// keep no other messages.
pub fn needed(c: &ChannelInfo) -> bool {
    ["/links/", "/reads/links/", "/fsm/", PREDICATES_PREFIX]
        .iter()
        .any(|p| c.topic.starts_with(p))
}

/// What one value-channel message feeds.
#[derive(Clone, Debug, Default)]
struct Feeds {
    inputs: Vec<InputId>,
    outputs: Vec<OutputId>,
    ranges: Vec<(RangeId, Vec<String>)>,
}

#[derive(Clone, Copy, Debug)]
enum Event {
    Arrived(InputId),
    Sent(OutputId),
    Read(InputId, Time),
    Value(RangeId, f64),
    Entered(SubsystemId, Option<BehaviourId>, u64),
    /// A subsystem's predicates after an activation (known, value; the
    /// spec's bits).
    Predicates(SubsystemId, u64, u64),
}

/// How a value channel's messages are read for its ranges.
enum Decode {
    /// JSON text.
    Json,
    /// CDR, by the payload's shape (read back to postcard bytes) and layout.
    Cdr(Rc<(TypeShape, Layout)>),
    /// Not read (no range on it).
    No,
}

/// What a channel is to the monitors.
enum Role {
    Values(Feeds, Decode),
    Reads(InputId),
    Fsm(SubsystemId),
    Predicates(SubsystemId),
}

/// Evaluate `monitors`' contracts over `recording` (opened with [`needed`] as
/// its filter, or with every channel).
pub fn evaluate(monitors: &mut Monitors, recording: &Recording) -> Result<Report, RecordingError> {
    let mut roles: BTreeMap<u16, Role> = BTreeMap::new();
    let mut seen: Vec<ContractId> = Vec::new();
    let mut not_evaluable: Vec<(ContractId, String)> = Vec::new();
    let links = links(recording);
    for c in recording.channels.values() {
        // Only the subsystems a bound watches: the others' switches feed nothing.
        if let Some(node) = c.topic.strip_prefix("/fsm/")
            && let Some(s) = monitors.subsystem(node)
            && monitors.bounds.iter().any(|b| b.subsystem == s)
        {
            roles.insert(c.id, Role::Fsm(s));
        }
    }
    for (value_topic, ends) in &links {
        link_roles(
            monitors,
            recording,
            (value_topic, ends),
            &mut roles,
            &mut seen,
            &mut not_evaluable,
        );
    }
    // A response needs both its ends recorded.
    for r in &monitors.responses {
        let on = |o: OutputId| {
            links
                .values()
                .any(|e| e.is_output(&monitors.outputs[o.0 as usize]))
        };
        if on(r.trigger) && on(r.response) {
            seen.push(r.contract);
        }
    }
    for b in &monitors.bounds {
        let node = &monitors.subsystems[b.subsystem.0 as usize].name;
        if roles
            .values()
            .any(|r| matches!(r, Role::Fsm(s) if *s == b.subsystem))
        {
            seen.push(b.contract);
        } else {
            not_evaluable.push((
                b.contract,
                format!("no `/fsm/{node}` channel in the recording"),
            ));
        }
    }
    for (c, sub, _) in monitors.invariants() {
        let node = monitors.subsystem_name(sub);
        let topic = format!("{PREDICATES_PREFIX}{node}");
        match recording.channels.values().find(|ch| ch.topic == topic) {
            Some(ch) => {
                roles.insert(ch.id, Role::Predicates(sub));
                seen.push(c);
            }
            None => not_evaluable.push((
                c,
                format!(
                    "no `{topic}` channel: the recorder writes a subsystem's predicates after \
                     each activation when the contracts' watch judged its invariants in the \
                     run (a recording without it, or an older recorder's, has none)"
                ),
            )),
        }
    }
    for (i, c) in monitors.contracts.iter().enumerate() {
        let id = ContractId(i as u32);
        if !seen.contains(&id) && !not_evaluable.iter().any(|(n, _)| *n == id) {
            not_evaluable.push((id, format!("`{}` is on no link of the recording", c.name)));
        }
    }
    let mut events = events(monitors, recording, &roles)?;
    events.sort_by_key(|(t, _)| *t);
    let (start, end) = span(recording);
    let mut report = Report {
        start,
        end,
        ..Report::default()
    };
    seen.sort_unstable();
    seen.dedup();
    seen.retain(|c| !not_evaluable.iter().any(|(n, _)| n == c));
    report.checked = seen;
    report.not_evaluable = not_evaluable;
    feed(
        monitors,
        recording,
        start,
        end,
        &events,
        &mut report.violations,
    );
    report.violations.sort_by_key(|v| v.time);
    Ok(report)
}

/// The roles of a link's value and reads channels, and the contracts they
/// make evaluable (or not).
fn link_roles(
    monitors: &Monitors,
    recording: &Recording,
    (value_topic, ends): (&String, &Ends),
    roles: &mut BTreeMap<u16, Role>,
    seen: &mut Vec<ContractId>,
    not_evaluable: &mut Vec<(ContractId, String)>,
) {
    let channel = recording
        .channels
        .values()
        .find(|c| &c.topic == value_topic);
    let json = channel.is_some_and(|c| c.message_encoding == "json");
    // A CDR channel's shape, read once (and only when a range needs it).
    let mut cdr: Option<Result<Rc<(TypeShape, Layout)>, String>> = None;
    let mut feeds = Feeds::default();
    for f in &monitors.freshness {
        if ends.is_input(&monitors.inputs[f.input.0 as usize]) {
            seen.push(f.contract);
            let reads = format!("/reads{value_topic}");
            if let Some(c) = recording.channels.values().find(|c| c.topic == reads) {
                roles.insert(c.id, Role::Reads(f.input));
            }
        }
    }
    for r in &monitors.rates {
        if ends.is_input(&monitors.inputs[r.input.0 as usize]) {
            seen.push(r.contract);
            feeds.inputs.push(r.input);
        }
    }
    for r in &monitors.responses {
        for o in [r.trigger, r.response] {
            if ends.is_output(&monitors.outputs[o.0 as usize]) {
                feeds.outputs.push(o);
            }
        }
    }
    for (i, (buffer, field)) in monitors.ranges_of.iter().enumerate() {
        if !(ends.is_input(buffer) || ends.is_output(buffer)) {
            continue;
        }
        let contract = monitors.ranges[i].contract;
        let path: Vec<String> = field
            .as_deref()
            .map(|f| f.split('.').map(str::to_owned).collect())
            .unwrap_or_default();
        match channel {
            Some(_) if json => {
                seen.push(contract);
                feeds.ranges.push((RangeId(i as u32), path));
            }
            Some(c) if c.message_encoding == "cdr" => {
                let shape = cdr.get_or_insert_with(|| cdr_layout(c, buffer)).clone();
                match shape {
                    Ok(s) if crate::field::reaches_number(&s.1, &path) => {
                        seen.push(contract);
                        feeds.ranges.push((RangeId(i as u32), path));
                    }
                    Ok(_) => not_evaluable.push((
                        contract,
                        format!(
                            "`{}` does not lead to a number in `{buffer}`",
                            field.as_deref().unwrap_or("")
                        ),
                    )),
                    Err(why) => not_evaluable.push((contract, why)),
                }
            }
            Some(c) => not_evaluable.push((
                contract,
                format!(
                    "`{buffer}` is recorded as `{}`, which this monitor does not read",
                    c.message_encoding
                ),
            )),
            None => not_evaluable.push((
                contract,
                format!("`{buffer}` has no value channel in the recording"),
            )),
        }
    }
    feeds.outputs.dedup();
    if let Some(c) = channel {
        let decode = match cdr {
            _ if feeds.ranges.is_empty() => Decode::No,
            _ if json => Decode::Json,
            Some(Ok(s)) => Decode::Cdr(s),
            _ => Decode::No,
        };
        roles.insert(c.id, Role::Values(feeds, decode));
    }
}

/// The shape and layout of a CDR value channel's payload, from its metadata.
fn cdr_layout(c: &ChannelInfo, buffer: &str) -> Result<Rc<(TypeShape, Layout)>, String> {
    match c.payload_shape() {
        Some(Ok(shape)) => {
            let layout = Layout::of(&shape);
            Ok(Rc::new((shape, layout)))
        }
        Some(Err(why)) => Err(format!("`{buffer}` is recorded as CDR, and {why}")),
        None => Err(format!(
            "`{buffer}` is recorded as CDR without its payload's shape (a recording made \
             before the recorder kept shapes): record again, or with JSON values"
        )),
    }
}

/// Each link's value topic and ends (from its raw channel's metadata).
fn links(recording: &Recording) -> BTreeMap<String, Ends> {
    let mut out = BTreeMap::new();
    for c in recording.channels.values() {
        if let Some(value) = c.topic.strip_prefix("/raw")
            && value.starts_with("/links/")
            && let Some(ends) = c.metadata.get("link").and_then(|l| Ends::parse(l))
        {
            out.insert(value.to_owned(), ends);
        }
    }
    out
}

/// The first and last activations of the run.
fn span(recording: &Recording) -> (Time, Time) {
    let end = recording.metadata.get("end");
    let of = |prefix: &str| -> Vec<u64> {
        end.into_iter()
            .flat_map(|m| m.iter())
            .filter(|(k, _)| k.starts_with(prefix))
            .filter_map(|(_, v)| v.parse().ok())
            .collect()
    };
    let times = recording.messages.iter().map(|m| m.log_time);
    let start = of("first/")
        .into_iter()
        .min()
        .or_else(|| times.clone().min())
        .unwrap_or(0);
    let end = of("last/")
        .into_iter()
        .max()
        .or_else(|| times.max())
        .unwrap_or(0);
    (Time::from_nanos(start), Time::from_nanos(end))
}

/// The events of the recording, unsorted.
fn events(
    monitors: &Monitors,
    recording: &Recording,
    roles: &BTreeMap<u16, Role>,
) -> Result<Vec<(Time, Event)>, RecordingError> {
    let mut out = Vec::new();
    // A CDR value's postcard bytes, reused.
    let mut bytes = Vec::new();
    for m in &recording.messages {
        let Some(role) = roles.get(&m.channel) else {
            continue;
        };
        let t = Time::from_nanos(m.log_time);
        let bad = |why: String| RecordingError::Message {
            topic: recording
                .channels
                .get(&m.channel)
                .map(|c| c.topic.clone())
                .unwrap_or_default(),
            offset: m.offset,
            why,
        };
        match role {
            Role::Reads(input) => {
                let stamp = m
                    .data
                    .get(8..16)
                    .and_then(|b| <[u8; 8]>::try_from(b).ok())
                    .map(u64::from_le_bytes)
                    .ok_or_else(|| bad(format!("a read of {} bytes, not 16", m.data.len())))?;
                out.push((t, Event::Read(*input, Time::from_nanos(stamp))));
            }
            Role::Values(feeds, decode) => {
                out.extend(feeds.inputs.iter().map(|&i| (t, Event::Arrived(i))));
                out.extend(feeds.outputs.iter().map(|&o| (t, Event::Sent(o))));
                match decode {
                    Decode::No => {}
                    Decode::Json => {
                        let v: Value = serde_json::from_slice(&m.data)
                            .map_err(|e| bad(format!("not JSON: {e}")))?;
                        for (r, path) in &feeds.ranges {
                            let x = field(&v, path).ok_or_else(|| {
                                bad(format!("no number at field `{}`", path.join(".")))
                            })?;
                            out.push((t, Event::Value(*r, x)));
                        }
                    }
                    Decode::Cdr(s) => {
                        let (shape, layout) = &**s;
                        bytes.clear();
                        agent_mcap::cdr::read_cdr(shape, &m.data, &mut bytes)
                            .map_err(|e| bad(format!("not CDR of its payload's shape: {e}")))?;
                        for (r, path) in &feeds.ranges {
                            // An absent option or a short sequence: no value there.
                            if let Some(x) = crate::field::number(layout, &bytes, path)
                                .map_err(|e| bad(format!("field `{}`: {e}", path.join("."))))?
                            {
                                out.push((t, Event::Value(*r, x)));
                            }
                        }
                    }
                }
            }
            Role::Predicates(s) => {
                let v: Value =
                    serde_json::from_slice(&m.data).map_err(|e| bad(format!("not JSON: {e}")))?;
                let values = v
                    .get("predicates")
                    .and_then(Value::as_object)
                    .ok_or_else(|| bad("no `predicates` object".to_owned()))?;
                let (mut known, mut value) = (0u64, 0u64);
                for (k, name) in monitors.predicate_names(*s).iter().enumerate().take(64) {
                    match values.get(name) {
                        Some(Value::Bool(b)) => {
                            known |= 1 << k;
                            value |= u64::from(*b) << k;
                        }
                        Some(other) => {
                            return Err(bad(format!("predicate `{name}` is {other}, not a bool")));
                        }
                        None => {}
                    }
                }
                out.push((t, Event::Predicates(*s, known, value)));
            }
            Role::Fsm(s) => {
                let v: Value =
                    serde_json::from_slice(&m.data).map_err(|e| bad(format!("not JSON: {e}")))?;
                let iteration = v.get("iteration").and_then(Value::as_u64).unwrap_or(0);
                let to = match v.get("to").and_then(Value::as_str) {
                    Some(name) => Some(monitors.behaviour(*s, name).ok_or_else(|| {
                        RecordingError::Behaviour {
                            topic: format!("/fsm/{}", monitors.subsystems[s.0 as usize].name),
                            behaviour: name.to_owned(),
                        }
                    })?),
                    None => None,
                };
                out.push((t, Event::Entered(*s, to, iteration)));
            }
        }
    }
    Ok(out)
}

/// The number at `path` in a JSON value (`null`: a non-finite number).
fn field(v: &Value, path: &[String]) -> Option<f64> {
    let mut at = v;
    for p in path {
        at = match at {
            Value::Array(a) => a.get(p.parse::<usize>().ok()?)?,
            Value::Object(o) => o.get(p)?,
            _ => return None,
        };
    }
    match at {
        Value::Null => Some(f64::NAN),
        other => other.as_f64(),
    }
}

/// Feed the events to the monitors, the initial behaviours entered first.
fn feed(
    monitors: &mut Monitors,
    recording: &Recording,
    start: Time,
    end: Time,
    events: &[(Time, Event)],
    out: &mut Vec<Violation>,
) {
    let mut sink = |v: Violation| out.push(v);
    monitors.start(start);
    let first = recording.metadata.get("end");
    let bounded: Vec<SubsystemId> = monitors.bounds.iter().map(|b| b.subsystem).collect();
    let mut iterations: BTreeMap<u32, u64> = BTreeMap::new();
    for s in bounded {
        let name = &monitors.subsystems[s.0 as usize].name;
        let at = first
            .and_then(|m| m.get(&format!("first/{name}")))
            .and_then(|v| v.parse().ok())
            .map_or(start, Time::from_nanos);
        if iterations.insert(s.0, 0).is_none() {
            let initial = monitors.initial(s);
            monitors.entered(s, initial, at, &mut sink);
        }
    }
    for &(t, e) in events {
        match e {
            Event::Arrived(i) => monitors.arrived(i, t, &mut sink),
            Event::Sent(o) => monitors.sent(o, t, &mut sink),
            Event::Read(i, stamp) => monitors.read(i, t, stamp, &mut sink),
            Event::Value(r, x) => monitors.value(r, t, x, &mut sink),
            Event::Predicates(s, known, value) => {
                monitors.predicates(s, t, known, value, &mut sink);
            }
            Event::Entered(s, b, iteration) => {
                // The activations of the run being left, then the switch.
                let before = iterations.insert(s.0, iteration).unwrap_or(0);
                for _ in before..iteration {
                    monitors.activation(s, t, None, &mut sink);
                }
                monitors.entered(s, b, t, &mut sink);
            }
        }
    }
    monitors.finish(end, &mut sink);
}
