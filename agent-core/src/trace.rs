//! Observing a run: the [`Observer`] hook, and a [`Recorder`] that turns a run into a
//! comparable, serialisable [`Trace`].
//!
//! The executor calls the observer at each FSM transition, each elementary action or
//! driver step, each buffer transfer (with the value) and each error. With the default
//! [`NoObserver`] these calls compile to nothing.

use std::fmt;
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::buffer::Payload;
use crate::describe::{Fresh, Shape};
use crate::error::ExecError;
use crate::fsm::{FsmShape, Step, Valuation};
use crate::kinds::{NodeKind, Policy};
use crate::time::{Period, Stamp, Time};

mod forward;
mod pick;
mod wants;

pub use pick::{FieldPath, PickError};
pub(crate) use wants::LinkWant;
pub use wants::{LinkEvents, NodeEvents, NumberBound, SendStamps, within};

/// A value in a buffer, seen through the observer without knowing its type.
pub trait ErasedPayload {
    /// The value for `{:?}`.
    fn as_debug(&self) -> &dyn fmt::Debug;
    /// Append the value's canonical binary encoding (postcard) to `out`; on
    /// an error `out` is left as it was.
    fn encode(&self, out: &mut Vec<u8>) -> Result<(), EncodeError>;
    /// The number at `path` in the value, read through its `Serialize` impl
    /// without encoding it (see [`FieldPath`]); `Ok(None)` where it has none.
    fn number_at(&self, path: &FieldPath) -> Result<Option<f64>, PickError>;
}

/// A value could not be encoded.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("cannot encode a buffer value: {0}")]
pub struct EncodeError(String);

impl<T: Payload> ErasedPayload for T {
    fn as_debug(&self) -> &dyn fmt::Debug {
        self
    }
    fn encode(&self, out: &mut Vec<u8>) -> Result<(), EncodeError> {
        let start = out.len();
        match postcard::serialize_with_flavor(self, AppendTo(out)) {
            Ok(()) => Ok(()),
            Err(e) => {
                out.truncate(start);
                Err(EncodeError(e.to_string()))
            }
        }
    }
    #[inline]
    fn number_at(&self, path: &FieldPath) -> Result<Option<f64>, PickError> {
        path.number(self)
    }
}

/// Postcard's output appended to a borrowed buffer, which a failed encoding
/// gives back as it was (an owned `ExtendFlavor` would be lost with the error).
struct AppendTo<'a>(&'a mut Vec<u8>);

impl postcard::ser_flavors::Flavor for AppendTo<'_> {
    type Output = ();

    #[inline]
    fn try_push(&mut self, byte: u8) -> postcard::Result<()> {
        self.0.push(byte);
        Ok(())
    }

    #[inline]
    fn try_extend(&mut self, bytes: &[u8]) -> postcard::Result<()> {
        self.0.extend_from_slice(bytes);
        Ok(())
    }

    fn finalize(self) -> postcard::Result<()> {
        Ok(())
    }
}

/// Static description of one node (subsystem or driver) of a running system.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NodeInfo {
    /// Unique name (`c1`, `e1`, `E1`...).
    pub name: String,
    /// Which kind of component.
    pub kind: NodeKind,
    /// Name of the agent it belongs to.
    pub agent: String,
    /// Its period.
    pub period: Period,
    /// Names of its behaviours, by index (empty for drivers); shared by the
    /// subsystems of one FSM ([`Fsm::behaviour_names`](crate::Fsm::behaviour_names)).
    pub behaviours: Arc<[String]>,
    /// Its memory and buffers, if its types describe them ([`Subsystem::shape`],
    /// [`Driver::shape`]).
    ///
    /// [`Subsystem::shape`]: crate::Subsystem::shape
    /// [`Driver::shape`]: crate::Driver::shape
    pub shape: Option<Shape>,
    /// Its FSM as a spec describes it (`None` for drivers), shared by the
    /// subsystems of one FSM ([`Fsm::shape`](crate::Fsm::shape)).
    pub fsm: Option<Arc<FsmShape>>,
}

/// Static description of one link.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LinkInfo {
    /// `node.port -> node.port`.
    pub name: String,
    /// Sending node (index into [`SystemInfo::nodes`]).
    pub from: usize,
    /// Output port path.
    pub from_port: &'static str,
    /// Receiving node.
    pub to: usize,
    /// Input port path.
    pub to_port: &'static str,
    /// Delivery policy.
    pub policy: Policy,
    /// Rust type of the payload.
    pub payload: &'static str,
}

/// Static description of a system, given to observers at the start of a run.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct SystemInfo {
    /// Agent names, in declaration order.
    pub agents: Vec<String>,
    /// Nodes, in declaration order (the executor's stepping order within an
    /// instant, real receptors last).
    pub nodes: Vec<NodeInfo>,
    /// Links, in declaration order.
    pub links: Vec<LinkInfo>,
}

/// An FSM transition.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TransitionEvent {
    /// Virtual time.
    pub time: Time,
    /// Node index.
    pub node: usize,
    /// Iteration of the subsystem at which the decision was taken.
    pub iteration: u64,
    /// What the FSM did.
    pub step: Step,
}

/// An elementary action (subsystem) or a step (driver) that ran.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ActionEvent {
    /// Virtual time.
    pub time: Time,
    /// Node index.
    pub node: usize,
    /// Iteration number of this action.
    pub iteration: u64,
    /// Behaviour whose action ran; `None` for a driver step.
    pub behaviour: Option<usize>,
}

/// What one part of an elementary action (one transition function) read and
/// wrote, observed with [`ExecConfig::audit`](crate::ExecConfig::audit).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AuditEvent {
    /// Virtual time.
    pub time: Time,
    /// Node index.
    pub node: usize,
    /// The behaviour whose action ran.
    pub behaviour: usize,
    /// The part, in the order of the behaviour's `BehaviourShape::parts`.
    pub part: usize,
    /// The inputs it read, in the order of the node's `Shape::inputs`.
    pub reads: Fresh,
    /// The outputs it wrote, in the order of the node's `Shape::outputs`.
    pub writes: Fresh,
}

/// A value sent into a link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TransferEvent {
    /// Link index.
    pub link: usize,
    /// Sender's iteration and time.
    pub stamp: Stamp,
}

/// A value taken from a link into its receiver's input buffer.
///
/// In the deterministic executor which value a node reads follows from the
/// stamps; in the real-time one it depends on which thread reached an instant
/// first, so a replay of a real-time run needs these.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ReadEvent {
    /// The receiver's instant (the activation that read it).
    pub time: Time,
    /// Link index.
    pub link: usize,
    /// The value's stamp: its sender's iteration and instant.
    pub stamp: Stamp,
}

/// Hooks called by executors during a run. Every method has an empty default.
pub trait Observer: Send {
    /// Whether the executor should call this observer at all. [`NoObserver`] says
    /// no, which removes every call from the hot path.
    fn enabled(&self) -> bool {
        true
    }
    /// The run starts (called once, before the first instant).
    fn start(&mut self, _system: &SystemInfo) {}
    /// An FSM took a transition or finished.
    fn transition(&mut self, _event: &TransitionEvent) {}
    /// An elementary action or a driver step ran.
    fn action(&mut self, _event: &ActionEvent) {}
    /// One transition function of an action read and wrote these buffers (only
    /// with [`ExecConfig::audit`](crate::ExecConfig::audit); before the action's
    /// [`Observer::action`]).
    fn audit(&mut self, _event: &AuditEvent) {}
    /// Which of link `link`'s sends and reads this observer needs
    /// ([`LinkEvents`]): asked once per link, at the start of a run of the
    /// deterministic executor, which then leaves out the others where the
    /// link sends or reads. Every event by default. A hint only: the
    /// observer must see the same whether or not it gets what it did not ask
    /// for (other executors and other observers of the run may deliver it).
    fn link_events(&self, _link: usize) -> LinkEvents {
        LinkEvents::all()
    }
    /// Which of node `node`'s transitions and activations this observer
    /// needs ([`NodeEvents`]): asked once per node, at the start of a run of
    /// the deterministic executor, which then leaves out the others (and
    /// tells [`Observer::instant`] at every instant). Every event by default.
    /// A hint, as [`Observer::link_events`] is.
    fn node_events(&self, _node: usize) -> NodeEvents {
        NodeEvents::all()
    }
    /// The deterministic executor starts instant `time` (before its reads):
    /// the clock of an observer that asked for fewer events than every
    /// node's activations ([`Observer::node_events`]). Other executors do not
    /// call it; they tell every activation.
    fn instant(&mut self, _time: Time) {}
    /// The deterministic executor keeps the instant of the last value sent
    /// into each link this observer asked it to ([`LinkEvents::stamps`]) in
    /// `stamps`, given once before the first instant when any link asked:
    /// the observer reads it when it needs to (at [`Observer::instant`], say)
    /// instead of hearing of each send. Other executors do not call it; they
    /// tell every send.
    fn stamps(&mut self, _stamps: &SendStamps) {}
    /// A value was sent into a link.
    fn transfer(&mut self, _event: &TransferEvent, _value: &dyn ErasedPayload) {}
    /// A node took a value from a link (before its activation's step).
    fn read(&mut self, _event: &ReadEvent) {}
    /// A node's read took nothing new from a link, and the value its buffer
    /// still holds (stamped `event.stamp`) is older than the observer's
    /// bound ([`LinkEvents::older_than`]; only then, and only from the
    /// deterministic executor).
    fn held(&mut self, _event: &ReadEvent) {}
    /// A node took a value that came from another process (after its
    /// [`Observer::read`]): the value itself, which no recorder of this
    /// process saw sent (its sender's may not have kept it: a process killed
    /// before its recording was written).
    fn received(&mut self, _event: &ReadEvent, _value: &dyn ErasedPayload) {}
    /// An error occurred (whether the run stops or continues).
    fn error(&mut self, _time: Time, _error: &ExecError) {}
    /// The predicates of subsystem `node` whose values this observer wants
    /// after each of its activations ([`Observer::predicates`]): bit `i` for
    /// predicate `i` of its FSM ([`FsmShape::predicates`] order, the first
    /// 64). Asked once per node, at its first activation; none by default,
    /// and then the executor evaluates nothing more.
    fn predicates_wanted(&self, _node: usize) -> u64 {
        0
    }
    /// The values of the predicates wanted ([`Observer::predicates_wanted`],
    /// by any observer of the run) after each activation of a subsystem, right
    /// after its [`Observer::action`] (whether or not that is told:
    /// [`Observer::node_events`]): evaluated on the memory and inputs its
    /// action left (`values.known`: which were evaluated). What a contract
    /// monitor judges invariants by.
    fn predicates(&mut self, _event: &ActionEvent, _values: Valuation) {}
    /// An error the observer found in what it saw (a contract monitor's
    /// violation), taken by the executor right after each step of a node and
    /// handled by its error policy as that node's own error would be (then
    /// given to [`Observer::error`], so a recorder beside the monitor records
    /// it). Called until it returns `None`.
    fn raised(&mut self) -> Option<ExecError> {
        None
    }
}

/// The observer that observes nothing.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoObserver;

impl Observer for NoObserver {
    fn enabled(&self) -> bool {
        false
    }
}

/// One recorded event.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum TraceEvent {
    /// A behaviour ended and the FSM entered behaviour `to` by its arc `arc`.
    Transition {
        /// Virtual time.
        time: Time,
        /// Node index.
        node: u32,
        /// Iteration of the subsystem.
        iteration: u64,
        /// Behaviour that ended.
        from: u32,
        /// Behaviour entered.
        to: u32,
        /// Arc followed (index among `from`'s arcs).
        arc: u32,
        /// The value of every predicate at the decision.
        predicates: Valuation,
    },
    /// A final behaviour ended; the subsystem halted.
    Finished {
        /// Virtual time.
        time: Time,
        /// Node index.
        node: u32,
        /// Iteration of the subsystem.
        iteration: u64,
    },
    /// An elementary action of behaviour `behaviour` ran.
    Action {
        /// Virtual time.
        time: Time,
        /// Node index.
        node: u32,
        /// Iteration number of the action.
        iteration: u64,
        /// Behaviour index.
        behaviour: u32,
    },
    /// A driver stepped.
    DriverStep {
        /// Virtual time.
        time: Time,
        /// Node index.
        node: u32,
        /// Driver iteration.
        iteration: u64,
    },
    /// A value was sent into a link.
    Transfer {
        /// Link index.
        link: u32,
        /// Sender's iteration and time.
        stamp: Stamp,
        /// The value, postcard-encoded.
        value: Vec<u8>,
        /// The value's `Debug` text, if the recorder keeps it.
        text: Option<String>,
    },
    /// An error occurred.
    Error {
        /// Virtual time.
        time: Time,
        /// The error's message.
        message: String,
    },
}

/// A recorded run: names, then events in the order they happened.
///
/// Two runs of the same system with the same inputs give equal traces (the
/// determinism the executor guarantees); [`Trace::first_difference`] says where two
/// traces part.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct Trace {
    /// Node names by index.
    pub nodes: Vec<String>,
    /// Behaviour names by node and index.
    pub behaviours: Vec<Vec<String>>,
    /// Link names by index.
    pub links: Vec<String>,
    /// The events.
    pub events: Vec<TraceEvent>,
}

impl Trace {
    /// The index and both renderings of the first event where `self` and `other`
    /// differ, or `None` if they are equal.
    pub fn first_difference(&self, other: &Trace) -> Option<(usize, String, String)> {
        let n = self.events.len().max(other.events.len());
        (0..n).find_map(|i| {
            let a = self.events.get(i);
            let b = other.events.get(i);
            (a != b).then(|| {
                let show = |e: Option<&TraceEvent>| {
                    e.map_or_else(|| "(end of trace)".to_owned(), |e| self.render(e))
                };
                (i, show(a), show(b))
            })
        })
    }

    /// Encode the whole trace (postcard), for files and replay.
    pub fn to_bytes(&self) -> Result<Vec<u8>, EncodeError> {
        postcard::to_allocvec(self).map_err(|e| EncodeError(e.to_string()))
    }

    /// Decode a trace written by [`Trace::to_bytes`].
    pub fn from_bytes(bytes: &[u8]) -> Result<Trace, EncodeError> {
        postcard::from_bytes(bytes).map_err(|e| EncodeError(e.to_string()))
    }

    /// The behaviour that ran at each action of node `node`, as `(iteration, name)`.
    pub fn behaviours_of(&self, node: &str) -> Vec<(u64, &str)> {
        let Some(n) = self.nodes.iter().position(|x| x == node) else {
            return Vec::new();
        };
        self.events
            .iter()
            .filter_map(|e| match e {
                TraceEvent::Action {
                    node,
                    iteration,
                    behaviour,
                    ..
                } if *node as usize == n => Some((*iteration, self.behaviour_name(n, *behaviour))),
                _ => None,
            })
            .collect()
    }

    fn node_name(&self, n: u32) -> &str {
        self.nodes.get(n as usize).map_or("?", String::as_str)
    }

    fn behaviour_name(&self, node: usize, b: u32) -> &str {
        self.behaviours
            .get(node)
            .and_then(|bs| bs.get(b as usize))
            .map_or("?", String::as_str)
    }

    /// One event as a line of text.
    pub fn render(&self, e: &TraceEvent) -> String {
        match e {
            TraceEvent::Transition {
                time,
                node,
                iteration,
                from,
                to,
                ..
            } => format!(
                "{time} {} ι={iteration}: {} -> {}",
                self.node_name(*node),
                self.behaviour_name(*node as usize, *from),
                self.behaviour_name(*node as usize, *to)
            ),
            TraceEvent::Finished {
                time,
                node,
                iteration,
            } => format!("{time} {} ι={iteration}: finished", self.node_name(*node)),
            TraceEvent::Action {
                time,
                node,
                iteration,
                behaviour,
            } => format!(
                "{time} {} ι={iteration}: {}",
                self.node_name(*node),
                self.behaviour_name(*node as usize, *behaviour)
            ),
            TraceEvent::DriverStep {
                time,
                node,
                iteration,
            } => format!("{time} {} ι={iteration}: step", self.node_name(*node)),
            TraceEvent::Transfer {
                link,
                stamp,
                value,
                text,
            } => format!(
                "{} {}: {} ({} bytes)",
                stamp.time,
                self.links.get(*link as usize).map_or("?", String::as_str),
                text.as_deref().unwrap_or("…"),
                value.len()
            ),
            TraceEvent::Error { time, message } => format!("{time} error: {message}"),
        }
    }
}

impl fmt::Display for Trace {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for e in &self.events {
            writeln!(f, "{}", self.render(e))?;
        }
        Ok(())
    }
}

/// An observer that records everything into a [`Trace`].
#[derive(Clone, Debug, Default)]
pub struct Recorder {
    trace: Trace,
    keep_text: bool,
}

impl Recorder {
    /// A recorder that keeps values in binary only.
    pub fn new() -> Recorder {
        Recorder::default()
    }

    /// A recorder that also keeps each value's `Debug` text (for reading traces).
    pub fn with_text() -> Recorder {
        Recorder {
            keep_text: true,
            ..Recorder::default()
        }
    }

    /// The trace recorded so far.
    pub fn trace(&self) -> &Trace {
        &self.trace
    }

    /// Take the recorded trace.
    pub fn into_trace(self) -> Trace {
        self.trace
    }
}

fn small(n: usize) -> u32 {
    u32::try_from(n).unwrap_or(u32::MAX)
}

impl Observer for Recorder {
    fn start(&mut self, system: &SystemInfo) {
        self.trace.nodes = system.nodes.iter().map(|n| n.name.clone()).collect();
        self.trace.behaviours = system.nodes.iter().map(|n| n.behaviours.to_vec()).collect();
        self.trace.links = system.links.iter().map(|l| l.name.clone()).collect();
    }

    fn transition(&mut self, e: &TransitionEvent) {
        let (time, node, iteration) = (e.time, small(e.node), e.iteration);
        self.trace.events.push(match e.step {
            Step::Entered {
                from,
                arc,
                to,
                predicates,
            } => TraceEvent::Transition {
                time,
                node,
                iteration,
                from: small(from),
                to: small(to),
                arc: small(arc),
                predicates,
            },
            Step::Finished | Step::Run => TraceEvent::Finished {
                time,
                node,
                iteration,
            },
        });
    }

    fn action(&mut self, e: &ActionEvent) {
        let (time, node, iteration) = (e.time, small(e.node), e.iteration);
        self.trace.events.push(match e.behaviour {
            Some(b) => TraceEvent::Action {
                time,
                node,
                iteration,
                behaviour: small(b),
            },
            None => TraceEvent::DriverStep {
                time,
                node,
                iteration,
            },
        });
    }

    fn transfer(&mut self, e: &TransferEvent, value: &dyn ErasedPayload) {
        let mut bytes = Vec::new();
        if let Err(err) = value.encode(&mut bytes) {
            self.trace.events.push(TraceEvent::Error {
                time: e.stamp.time,
                message: err.to_string(),
            });
        }
        self.trace.events.push(TraceEvent::Transfer {
            link: small(e.link),
            stamp: e.stamp,
            value: bytes,
            text: self.keep_text.then(|| format!("{:?}", value.as_debug())),
        });
    }

    fn error(&mut self, time: Time, error: &ExecError) {
        self.trace.events.push(TraceEvent::Error {
            time,
            message: error.to_string(),
        });
    }
}

#[cfg(test)]
mod encode_tests {
    use super::ErasedPayload;
    use serde::{Deserialize, Serialize};

    /// Serialises its first field, then fails (as a map of unknown length
    /// does under postcard).
    #[derive(Clone, Debug, Deserialize)]
    struct FailsHalfway(u32);

    impl Serialize for FailsHalfway {
        fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            use serde::ser::{Error, SerializeTuple};
            let mut t = s.serialize_tuple(2)?;
            t.serialize_element(&self.0)?;
            Err(S::Error::custom("no second field"))
        }
    }

    #[test]
    fn encoding_appends_and_a_failure_leaves_the_buffer_as_it_was() {
        let mut out = vec![7, 8];
        (300u16, true).encode(&mut out).expect("encodes");
        assert_eq!(out, [7, 8, 0xac, 0x02, 1], "appended after what was there");
        let err = FailsHalfway(5).encode(&mut out).expect_err("fails");
        assert!(err.to_string().contains("cannot encode"), "{err}");
        assert_eq!(
            out,
            [7, 8, 0xac, 0x02, 1],
            "nothing of the failed value stays"
        );
    }
}
