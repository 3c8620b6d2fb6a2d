//! # agent-core: the embodied-agent formalism as a Rust library
//!
//! This crate implements the formalism of Zieliński's embodied agents as used by
//! Janiak & Zieliński for the Rex mobile platform (Bull. Pol. Ac. Tech. 63(3), 2015),
//! section 2, and a deterministic executor to run it.
//!
//! | paper | here |
//! |---|---|
//! | agent `a_j` | an agent of a [`SystemBuilder`]: one control subsystem, virtual effectors and receptors, drivers |
//! | `c_j`, `e_{j,n}`, `r_{j,k}` | a type implementing [`Subsystem`] (kind, memory, input and output buffers) |
//! | `E_j`, `R_j` | a type implementing [`Driver`] |
//! | `_x c`, `_y c`, `^c c` | [`In`] and [`Out`] fields grouped by peer ([`Group`]); the memory is any struct |
//! | `isnew(buf)`, `ι` | [`In::is_new`], [`In::stamp`] |
//! | `^{c,e} f_{j,m}` | a part of an [`Action`] writing one group (type-checked target) |
//! | `A_{j,m}` (Alg. 1) | [`Action`] + the executor's read / compute / send / wait cycle |
//! | `B_{j,m}` (Alg. 2, 3) | [`Behaviour::while_loop`], [`Behaviour::repeat_loop`] |
//! | `f^σ`, `f^τ` | Boolean [`Expr`]essions over named predicates |
//! | FSM (Fig. 5) | [`Fsm`], built and checked by [`FsmBuilder`] |
//! | links | [`SystemBuilder::connect`] with a [`Policy`] (sample or queue) |
//!
//! Start with [`Subsystem`], [`Action`], [`Behaviour`], [`Fsm`], then
//! [`SystemBuilder`] and [`Executor`]. The `testing` feature adds the
//! module `testing`: termination properties checked with proptest.

pub mod allocations;
pub mod behaviour;
pub mod buffer;
mod cache;
pub mod describe;
pub mod error;
pub mod executor;
pub mod expr;
pub mod fsm;
pub mod kinds;
pub mod link;
pub mod names;
mod node;
pub mod offload;
pub mod probe;
pub mod realtime;
pub mod subsystem;
pub mod system;
#[cfg(feature = "testing")]
pub mod testing;
pub mod time;
pub mod trace;
pub mod transition;
pub mod untyped;

pub use behaviour::Behaviour;
pub use buffer::{Access, BufferPort, Direction, Fan, Group, In, Out, Payload};
pub use cache::HugePages;
pub use describe::{Buffers, Field, Fields, Fresh, GroupShape, PortTable, Shape};
pub use error::{
    ActionError, BufferError, BuildError, BuildProblem, DriverError, ExecError, FsmBuildError,
    FsmError, FsmProblem, LinkError, RemoteProblem,
};
pub use executor::{ExecConfig, Executor, OnError, RunReport};
pub use expr::{Expr, ExprError};
pub use fsm::{
    Activated, BehaviourShape, Fsm, FsmArc, FsmBuilder, FsmGraph, FsmShape, FsmState, Predicate,
    Relation, Step, Valuation,
};
pub use kinds::{BehaviourKind, DeviceKind, NodeKind, Policy, SubsystemKind};
pub use link::remote::{
    Inbox, Publisher, Transport, TransportError, TypeShape, WireHeader, reflect,
};
pub use link::{InjectError, LinkId, LinkStats, Port};
pub use offload::{Offload, OffloadError, OffloadMode, UnknownOffloadMode};
pub use probe::Probes;
pub use realtime::{
    Finished, NodeTiming, Placement, Probed, RealTime, Refused, RtConfig, RtError, RtReport,
    Running, Spread, StopHandle, ThreadReport, Threading,
};
/// The tracer of payload types' shapes ([`reflect`]), for reading [`TypeShape`]s.
pub use serde_reflection;
pub use subsystem::{Driver, DriverContext, Subsystem};
pub use system::{
    AgentId, DriverHandle, NodeId, Sink, Source, SubsystemHandle, System, SystemBuilder,
    structure_violation,
};
pub use time::{Period, PeriodError, Stamp, Time};
pub use trace::{
    ActionEvent, AuditEvent, ErasedPayload, LinkInfo, NoObserver, NodeInfo, Observer, ReadEvent,
    Recorder, SystemInfo, Trace, TraceEvent, TransferEvent, TransitionEvent,
};
pub use transition::{Action, Outcome, Part, PartTarget};

/// What writing and running an agent needs, in one import:
/// `use agent_core::prelude::*;` (or `use embodied::prelude::*;`, which adds the
/// derives and the `fsm!` and `agent!` macros).
///
/// The prelude holds the formalism's types (subsystems, drivers, buffers, actions,
/// behaviours, FSMs, the kinds and link policies), the builder and executor of a
/// system, time, and the errors user code returns. Tracing, description and
/// introspection types stay in their modules.
pub mod prelude {
    pub use crate::port;
    pub use crate::{
        Action, ActionError, Behaviour, BehaviourKind, Buffers, DeviceKind, Driver, DriverContext,
        DriverError, DriverHandle, ExecConfig, ExecError, Executor, Fsm, FsmBuilder, Group, In,
        NodeKind, OnError, Out, Payload, Period, Policy, PortTable, Shape, Stamp, Subsystem,
        SubsystemHandle, SubsystemKind, System, SystemBuilder, Time,
    };
}

/// Items used by macro-generated code. Not part of the public API.
#[doc(hidden)]
pub mod __private {
    use crate::buffer::Group;
    use crate::kinds::NodeKind;

    /// The peer kind of the group a projection returns (the projection is never called).
    pub fn peer_of<B, G: Group>(_projection: fn(&mut B) -> &mut G) -> NodeKind {
        G::PEER
    }

    /// `group[index].field`, interned: the name of a port of a fan's element.
    pub fn fan_port_name(group: &str, index: usize, field: &str) -> &'static str {
        crate::names::intern_name(format!("{group}[{index}].{field}"))
    }
}
