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
mod tape;
mod verdict;

use std::collections::BTreeMap;
use std::sync::Arc;

use agent_core::trace::{ErasedPayload, Observer, TransferEvent, TransitionEvent};
use agent_core::{
    ExecConfig, Executor, InjectError, NodeKind, Stamp, Step, System, SystemInfo, Time, TypeShape,
};

use crate::codec::Codec;
use crate::read::Recording;
use crate::record::{FRAMES_ENCODING, READ_ENCODING, WIRE_ENCODING};
use compare::Compare;
pub use compare::first_difference;
use tape::{Expected, Routes, Tape};
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
    let x = subsystem_index(&info, node)?;
    // One start of a restarted process is replayed from its part's own end
    // record (another part may never have been finished: killed).
    let window = options.window;
    if window.is_none() && !recording.finished() {
        return Err(ReplayError::Unfinished(
            recording.path.display().to_string(),
        ));
    }
    let end = recorded_end(recording, node, window);
    let routes = Routes::of(recording, &system, x, &options.codecs)?;
    let tape = Tape::read(recording, &info, x, node, &routes, window)?;
    let inputs = feeds(&info, tape.sent, tape.reads)?;
    let mut expected = tape.expected;
    let mut cmp = compare_from_start(&info, x, &routes.shapes);
    let id = system.node(node).ok_or_else(|| no_subsystem(&info, node))?;
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
    drive(&mut exec, &info, x, &inputs, end, &mut cmp, &mut expected)
}

/// Why there is no subsystem `node` to replay: the subsystems there are.
fn no_subsystem(info: &SystemInfo, node: &str) -> ReplayError {
    ReplayError::NoSubsystem {
        name: node.to_owned(),
        available: info
            .nodes
            .iter()
            .filter(|n| !matches!(n.kind, NodeKind::RealEffector | NodeKind::RealReceptor))
            .map(|n| n.name.as_str())
            .collect::<Vec<_>>()
            .join(", "),
    }
}

/// The index of subsystem `node` among the system's nodes (a real device is
/// not a subsystem to replay).
fn subsystem_index(info: &SystemInfo, node: &str) -> Result<usize, ReplayError> {
    info.nodes
        .iter()
        .position(|n| {
            n.name == node && !matches!(n.kind, NodeKind::RealEffector | NodeKind::RealReceptor)
        })
        .ok_or_else(|| no_subsystem(info, node))
}

/// Where the recorded run of `node` ends, and the elementary actions it made
/// up to there.
#[derive(Clone, Copy)]
struct RecordedEnd {
    time: Time,
    iterations: u64,
}

/// The recorded end of `node`: its window's, else the `end` record's.
fn recorded_end(recording: &Recording, node: &str, window: Option<Window>) -> RecordedEnd {
    let end = recording.metadata.get("end");
    // The node's own last instant (the processes of a deployment stop at
    // different instants), else the run's.
    let time = match window {
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
    let iterations = match window {
        Some(w) => w.iterations,
        None => end
            .and_then(|m| m.get(&format!("iterations/{node}"))?.parse::<u64>().ok())
            .unwrap_or(0),
    };
    RecordedEnd { time, iterations }
}

/// The comparison before the first instant: both runs in the subsystem's
/// initial behaviour.
fn compare_from_start<'a>(
    info: &'a SystemInfo,
    x: usize,
    shapes: &'a BTreeMap<usize, Option<TypeShape>>,
) -> Compare<'a> {
    let n = &info.nodes[x];
    let initial = n.fsm.as_ref().map_or_else(
        || n.behaviours.first().cloned().unwrap_or_default(),
        |f| f.initial.clone(),
    );
    Compare {
        node: n,
        info,
        shapes,
        recorded_behaviour: initial.clone(),
        replayed_behaviour: initial,
        compared: 0,
        switched: 0,
    }
}

/// Run the isolated subsystem `x` instant by instant up to the recorded end,
/// feeding each input just before the activation that reads it and comparing
/// each instant with the recording: the verdict.
fn drive(
    exec: &mut Executor<Watch>,
    info: &SystemInfo,
    x: usize,
    inputs: &[(Time, usize, Recorded)],
    end: RecordedEnd,
    cmp: &mut Compare<'_>,
    expected: &mut Expected,
) -> Result<Replayed, ReplayError> {
    // The links out of it: no isolated node reads them, so their values are
    // dropped after each instant.
    let out_links: Vec<usize> = info
        .links
        .iter()
        .enumerate()
        .filter(|(_, l)| l.from == x && l.to != x)
        .map(|(k, _)| k)
        .collect();
    let mut fed = 0u64;
    let mut next_input = 0usize;
    while let Some(t) = exec.next_instant() {
        if t > end.time {
            break;
        }
        while let Some((due, k, r)) = inputs.get(next_input) {
            if *due > t {
                break;
            }
            exec.inject(*k, &r.body, r.stamp)
                .map_err(|e| bad_input(info, *k, r, &e))?;
            next_input += 1;
            fed += 1;
        }
        let iteration = exec.observer().actions;
        exec.step()?;
        for &k in &out_links {
            exec.discard(k);
        }
        let events = std::mem::take(&mut exec.observer_mut().events);
        if let Some(d) = cmp.instant(
            t,
            iteration,
            events,
            &mut expected.outputs,
            &mut expected.switches,
        ) {
            return Ok(Replayed::Diverged(Box::new(d)));
        }
    }
    let replayed = exec.observer().actions;
    Ok(cmp.end(
        (end.time, replayed, end.iterations),
        fed,
        &mut expected.outputs,
        &mut expected.switches,
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
