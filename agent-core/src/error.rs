//! Every error type of the runtime, in one leaf module (it imports only the
//! vocabulary, time, names and expressions), so that the modules reporting errors
//! do not import each other for them.
//!
//! | when | type |
//! |---|---|
//! | reading an input that never received data | [`BufferError`] |
//! | a transition function refuses to compute | [`ActionError`] |
//! | a device fails | [`DriverError`] |
//! | a queue link is full | [`LinkError`] |
//! | building an FSM | [`FsmBuildError`] of [`FsmProblem`]s |
//! | running an FSM | [`FsmError`] |
//! | building a system | [`BuildError`] of [`BuildProblem`]s |
//! | running a system | [`ExecError`] |

use std::borrow::Cow;
use std::fmt;

use crate::expr::ExprError;
use crate::kinds::NodeKind;
use crate::time::Time;

/// An error reading a buffer.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum BufferError {
    /// The input buffer has never received a value, but the behaviour needs one.
    #[error("input buffer `{buffer}` has not received any data yet")]
    NoData {
        /// Name of the buffer (as given to the link that feeds it).
        buffer: Cow<'static, str>,
    },
}

/// Why an elementary action could not complete.
#[derive(Debug, thiserror::Error)]
pub enum ActionError {
    /// A buffer the action needs holds no data.
    #[error(transparent)]
    Buffer(#[from] BufferError),
    /// The transition function refused to compute (bad data, solver failure...).
    #[error("{0}")]
    Failed(Cow<'static, str>),
    /// Any other error raised by user code.
    #[error(transparent)]
    Other(Box<dyn std::error::Error + Send + Sync>),
}

impl ActionError {
    /// An error with a message.
    pub fn failed(message: impl Into<Cow<'static, str>>) -> ActionError {
        ActionError::Failed(message.into())
    }
}

impl From<Box<dyn std::error::Error + Send + Sync>> for ActionError {
    fn from(e: Box<dyn std::error::Error + Send + Sync>) -> Self {
        ActionError::Other(e)
    }
}

/// A failure of a real device, reported by its driver.
#[derive(Debug, thiserror::Error)]
#[error("{message}")]
pub struct DriverError {
    /// What went wrong, for a person.
    pub message: String,
    /// The underlying error, if any.
    #[source]
    pub source: Option<Box<dyn std::error::Error + Send + Sync>>,
}

impl DriverError {
    /// A driver error with a message.
    pub fn new(message: impl fmt::Display) -> DriverError {
        DriverError {
            message: message.to_string(),
            source: None,
        }
    }
}

/// A transfer that could not be made.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LinkError {
    /// A value was sent into a full queue: the value was not delivered.
    #[error(
        "queue link `{link}` is full ({bound} values waiting): the value sent by iteration {iteration} at {time} was refused"
    )]
    QueueOverflow {
        /// The link's name.
        link: String,
        /// Its capacity.
        bound: usize,
        /// Iteration of the sender.
        iteration: u64,
        /// Virtual time of the send.
        time: Time,
    },
    /// A link between processes failed to carry a value.
    #[error("link `{link}` over key `{key}`: {problem}")]
    Remote {
        /// The link's name.
        link: String,
        /// The key its values travel on.
        key: String,
        /// What went wrong.
        problem: RemoteProblem,
    },
}

/// What went wrong on a link between processes.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum RemoteProblem {
    /// The sender's payload type is not the receiver's: the two processes were
    /// built from different specs or code.
    #[error(
        "the sender's payload has fingerprint {got:#018x}, this process expects {expected:#018x} (`{type_name}`): the two processes were built from different specs or code; value refused"
    )]
    Fingerprint {
        /// The receiver's fingerprint.
        expected: u64,
        /// The sender's.
        got: u64,
        /// The receiver's payload type.
        type_name: &'static str,
    },
    /// Values of a queue link were lost on the way.
    #[error("sequence gap: expected value {expected}, got {got} ({} lost)", got.saturating_sub(*expected))]
    Gap {
        /// The sequence number expected.
        expected: u64,
        /// The one received.
        got: u64,
    },
    /// A value numbered before the one expected (a repeat, a message replayed
    /// by whoever saw it, or out of order): refused, not delivered twice (on a
    /// sample link, not put back as the latest).
    #[error("value {got} arrived again or out of order (expected {expected}): refused")]
    Duplicate {
        /// The sequence number expected.
        expected: u64,
        /// The one received.
        got: u64,
    },
    /// More values arrived than the queue's bound holds; the value was refused.
    #[error("{bound} values already wait in the receiving queue: a value was refused")]
    Overflow {
        /// The link's bound.
        bound: usize,
    },
    /// A message that is not a value of this link.
    #[error("undecodable message: {0}")]
    Decode(String),
    /// A value that could not be encoded.
    #[error("cannot encode the value: {0}")]
    Encode(String),
    /// The transport refused or failed.
    #[error("transport: {0}")]
    Transport(String),
    /// The process at the other end is gone.
    #[error("the sending process `{process}` is gone")]
    PeerLost {
        /// The process.
        process: String,
    },
    /// A value from a second sender on the link's key while its sender runs
    /// (a process that restarted is seen to go first): not a member of the
    /// deployment's process that owns the buffer. Refused.
    #[error(
        "a value from a second sender (epoch {got:#x}) while the link's sender (epoch {current:#x}) runs: refused"
    )]
    Intruder {
        /// The sender's epoch.
        current: u64,
        /// The other's.
        got: u64,
    },
    /// A value stamped further ahead of the receiver's instant than any
    /// sender of the deployment can be: refused, so that it cannot hold the
    /// values behind it.
    #[error(
        "a value stamped {stamp}, more than {lead} s ahead of this activation's instant {now}: refused"
    )]
    Implausible {
        /// Its stamp's instant.
        stamp: Time,
        /// The reader's instant.
        now: Time,
        /// The most a stamp may lead by \[s\].
        lead: u64,
    },
}

/// A problem found while building an FSM.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum FsmProblem {
    /// The FSM has no behaviour.
    #[error("the FSM has no behaviour")]
    Empty,
    /// An FSM shared with another subsystem (a clone of it is alive) cannot
    /// give its behaviours to a new graph ([`Fsm::regraph`](crate::Fsm::regraph)).
    #[error("the FSM is shared (a clone of it is alive): regraph it before cloning")]
    Shared,
    /// Two behaviours have the same name.
    #[error("behaviour `{0}` is defined twice")]
    DuplicateBehaviour(String),
    /// Two predicates have the same name.
    #[error("predicate `{0}` is defined twice")]
    DuplicatePredicate(String),
    /// No initial behaviour was named.
    #[error("no initial behaviour: call `initial(name)`")]
    NoInitial,
    /// An arc, the initial node or a final declaration names an unknown behaviour.
    #[error("{place} names behaviour `{name}`, which is not defined")]
    UnknownBehaviour {
        /// Where the name appears.
        place: String,
        /// The unknown name.
        name: String,
    },
    /// A condition does not parse.
    #[error("{place}: {error}")]
    Syntax {
        /// Which condition.
        place: String,
        /// The syntax error.
        error: ExprError,
    },
    /// A condition names an undeclared predicate.
    #[error("{place} uses predicate `{name}`, which is not declared")]
    UnknownPredicate {
        /// Which condition.
        place: String,
        /// The unknown predicate.
        name: String,
    },
    /// A behaviour cannot be reached from the initial behaviour.
    #[error("behaviour `{0}` cannot be reached from the initial behaviour")]
    Unreachable(String),
    /// A behaviour can end but has no outgoing arc and is not declared final.
    #[error(
        "behaviour `{0}` can end (its terminal condition is not `false`) but has no outgoing arc; add an arc or declare it final"
    )]
    NoWayOut(String),
    /// A behaviour declared final also has outgoing arcs.
    #[error("behaviour `{0}` is declared final but has outgoing arcs")]
    FinalWithArcs(String),
    /// The action of a behaviour is malformed (for instance two parts write one target).
    #[error("behaviour `{behaviour}`: {message}")]
    Action {
        /// The behaviour.
        behaviour: String,
        /// What is wrong with its action.
        message: String,
    },
}

/// Every problem found while building an FSM.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub struct FsmBuildError {
    /// The problems, in the order found.
    pub problems: Vec<FsmProblem>,
}

impl fmt::Display for FsmBuildError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "the FSM is malformed ({} problem", self.problems.len())?;
        if self.problems.len() != 1 {
            f.write_str("s")?;
        }
        f.write_str("):")?;
        for p in &self.problems {
            write!(f, "\n  - {p}")?;
        }
        Ok(())
    }
}

/// Why a subsystem's FSM could not go on: its contract was violated (no arc or
/// several arcs hold, a livelock) or the action of its current behaviour failed.
///
/// The one FSM error of the runtime: [`Fsm::step`](crate::Fsm::step),
/// [`Fsm::activate`](crate::Fsm::activate) and [`Fsm::act`](crate::Fsm::act) return
/// it, and the executor reports it in [`ExecError::Fsm`] with the subsystem, its
/// iteration and the time.
#[derive(Debug, thiserror::Error)]
pub enum FsmError {
    /// The behaviour ended but no outgoing arc's initial condition holds.
    #[error(
        "behaviour `{behaviour}` ended but none of its arcs holds ({arcs}); predicates: {assignment}"
    )]
    NoArcHolds {
        /// The behaviour that ended.
        behaviour: String,
        /// Its arcs, as `-> target [condition]`.
        arcs: String,
        /// The value of every predicate at that moment.
        assignment: String,
    },
    /// The behaviour ended and several arcs' initial conditions hold.
    #[error(
        "behaviour `{behaviour}` ended and {count} arcs hold at once ({held}); predicates: {assignment}"
    )]
    SeveralArcsHold {
        /// The behaviour that ended.
        behaviour: String,
        /// How many arcs hold.
        count: usize,
        /// The arcs that hold, as `-> target [condition]`.
        held: String,
        /// The value of every predicate at that moment.
        assignment: String,
    },
    /// Behaviours keep ending and starting without any action: a cycle of
    /// while-behaviours whose terminal conditions hold at once.
    #[error("livelock: {transitions} transitions without an action, from `{from}` through {path}")]
    Livelock {
        /// The behaviour the activation started in.
        from: String,
        /// Transitions made.
        transitions: usize,
        /// The behaviours entered, in order.
        path: String,
    },
    /// The action of the current behaviour failed; nothing it wrote was sent.
    #[error("the action of behaviour `{behaviour}` failed: {source}")]
    Action {
        /// The behaviour.
        behaviour: String,
        /// The error.
        #[source]
        source: ActionError,
    },
}

impl FsmError {
    /// Whether the FSM's contract was violated (the subsystem cannot go on), as
    /// opposed to a failed action (the next period may succeed).
    pub fn is_contract_violation(&self) -> bool {
        !matches!(self, FsmError::Action { .. })
    }
}

/// A problem in a system's composition.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum BuildProblem {
    /// Two agents have the same name.
    #[error("agent `{0}` is declared twice")]
    DuplicateAgent(String),
    /// A name that is not valid ([`crate::names::check`]).
    #[error("{what} name `{name}` {problem}")]
    InvalidName {
        /// `agent`, `subsystem` or `driver`.
        what: &'static str,
        /// The name.
        name: String,
        /// Why.
        problem: crate::names::NameProblem,
    },
    /// Two nodes have the same name.
    #[error("`{0}` is declared twice (subsystem and driver names are unique in a system)")]
    DuplicateNode(String),
    /// An id or handle from another builder.
    #[error("{0} does not belong to this system builder")]
    ForeignHandle(String),
    /// An agent without a control subsystem.
    #[error("agent `{0}` has no control subsystem")]
    NoControl(String),
    /// An agent with several control subsystems.
    #[error("agent `{agent}` has {count} control subsystems ({names}); an agent has exactly one")]
    SeveralControls {
        /// The agent.
        agent: String,
        /// How many.
        count: usize,
        /// Their names.
        names: String,
    },
    /// A link that breaks the agent structure.
    #[error("link `{link}` breaks the agent structure: {reason}")]
    Structure {
        /// The link.
        link: String,
        /// Which rule.
        reason: String,
    },
    /// A buffer group declares a peer kind that does not match the linked node.
    #[error(
        "link `{link}`: port `{port}` belongs to a group connected to a {declared}, but the other end is a {actual}"
    )]
    PeerMismatch {
        /// The link.
        link: String,
        /// The port whose group disagrees.
        port: String,
        /// The group's declared peer.
        declared: NodeKind,
        /// The kind at the other end.
        actual: NodeKind,
    },
    /// An input buffer fed by two outputs.
    #[error("input `{input}` is fed by two outputs: `{first}` and `{second}`")]
    InputFedTwice {
        /// The input buffer.
        input: String,
        /// The first link.
        first: String,
        /// The second link.
        second: String,
    },
    /// A queue of capacity zero.
    #[error("link `{0}` is a queue of capacity 0; a queue holds at least one value")]
    ZeroQueueBound(String),
    /// A link by name to a component that was not added.
    #[error("link `{link}`: no component `{node}` in this system")]
    UnknownNode {
        /// The link.
        link: String,
        /// The missing component.
        node: String,
    },
    /// A link by name to a component whose buffers cannot be found by name.
    #[error(
        "link `{link}`: the buffers of `{node}` cannot be found by name: derive `Subsystem` with `#[derive(Buffers)]` and `#[derive(Group)]` on its buffer structs (a driver is described by its `Input` and `Output`; do not override `Driver::ports` with `None`)"
    )]
    NoPorts {
        /// The link.
        link: String,
        /// The component.
        node: String,
    },
    /// A link by name to a buffer the component does not have.
    #[error("link `{link}`: `{node}` has no {direction} buffer `{buffer}`{known}")]
    UnknownBuffer {
        /// The link.
        link: String,
        /// The component.
        node: String,
        /// `input` or `output`.
        direction: &'static str,
        /// The buffer's path.
        buffer: String,
        /// The buffers it has, as `" (it has: a.b, c.d)"`, or empty.
        known: String,
    },
    /// A link to an element of a [`Fan`](crate::Fan) the component's fan does
    /// not have (its length is fixed when the component's buffers are made).
    #[error(
        "link `{link}`: `{node}`'s fan `{group}` has {len} element(s), so no `{group}[{index}]`; make the subsystem's buffers with a fan of more (SystemBuilder::subsystem_with_buffers) or link to an index below {len}"
    )]
    NoFanElement {
        /// The link.
        link: String,
        /// The component.
        node: String,
        /// The fan's field.
        group: String,
        /// The index linked to.
        index: usize,
        /// The fan's length.
        len: usize,
    },
    /// `SystemBuilder::environment` was called twice.
    #[error("the system has two environments; a system has one (make it a struct of both)")]
    SeveralEnvironments,
    /// A link between buffers of different payload types.
    #[error("link `{link}` joins an output of type `{from}` to an input of type `{to}`")]
    TypeMismatch {
        /// The link.
        link: String,
        /// The output's payload type.
        from: &'static str,
        /// The input's payload type.
        to: &'static str,
    },
}

/// Every problem found in a system's composition.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub struct BuildError {
    /// The problems, in the order found.
    pub problems: Vec<BuildProblem>,
}

impl fmt::Display for BuildError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "the system is malformed:")?;
        for p in &self.problems {
            write!(f, "\n  - {p}")?;
        }
        Ok(())
    }
}

/// An error during a run.
#[derive(Debug, thiserror::Error)]
pub enum ExecError {
    /// A subsystem's FSM failed: no arc or several arcs held, it looped without
    /// acting, or the action of its behaviour failed (then nothing it wrote was sent).
    #[error("subsystem `{subsystem}`, iteration {iteration} at {time}: {error}")]
    Fsm {
        /// The subsystem.
        subsystem: String,
        /// Its iteration when it failed.
        iteration: u64,
        /// Virtual time.
        time: Time,
        /// What went wrong (which behaviour, which arcs, the predicate values, or the
        /// action's error). Written into this error's message, so not its `source`.
        error: FsmError,
    },
    /// A link refused a value (a full queue).
    #[error(transparent)]
    Link(#[from] LinkError),
    /// A driver failed; nothing it wrote was sent.
    #[error("driver `{driver}`, iteration {iteration} at {time}: {source}")]
    Driver {
        /// The driver.
        driver: String,
        /// Its iteration.
        iteration: u64,
        /// Virtual time.
        time: Time,
        /// The error.
        #[source]
        source: DriverError,
    },
    /// A promise of the spec broken: a contract that a monitor watching the run
    /// found violated (agent-monitor's), raised by the run's observer
    /// ([`Observer::raised`](crate::Observer::raised)) and handled by the error
    /// policy as the subsystem's own error would be.
    #[error("subsystem `{subsystem}` at {time}: {source}")]
    Contract {
        /// The subsystem the contract holds of.
        subsystem: String,
        /// When it was broken.
        time: Time,
        /// The violation: the contract and the values that broke it (a typed error
        /// of the monitor's crate, to downcast).
        #[source]
        source: Box<dyn std::error::Error + Send + Sync>,
    },
    /// The executor stopped on an earlier error (with [`OnError::Stop`](crate::OnError::Stop)).
    #[error("the executor stopped after an error; build a new executor to run again")]
    Stopped,
}
