#![doc = include_str!("../README.md")]
//!
//! ---
//!
//! This crate is the one dependency a user adds: it re-exports the formalism and the
//! executor of `agent-core`, the specification tools of `agent-spec` as
//! [`spec`], and, with the feature `distributed`, the processes of a deployment
//! over Zenoh (`agent-zenoh`) as `distributed`.

pub use agent_core::*;

/// The derives and the `fsm!` and `agent!` macros (the `agent-macros` crate).
pub use agent_macros::{Buffers, Group, Memory, Subsystem, agent, fsm};

/// What writing and running an agent needs, in one import: agent-core's
/// [`prelude`](agent_core::prelude), the derives and the `fsm!` and `agent!` macros.
pub mod prelude {
    pub use agent_core::prelude::*;
    pub use agent_macros::{Buffers, Group, Memory, Subsystem, agent, fsm};
}

/// RON specifications: schema, checker, diagrams (the `agent-spec` crate).
pub use agent_spec as spec;

/// The processes of a deployment over Eclipse Zenoh (the `agent-zenoh` crate):
/// `Member` joins a deployment as one of its processes, `ZenohTransport` carries
/// links between processes, `Launcher` starts them all. Behind the feature
/// `distributed`, because Zenoh's build is long.
#[cfg(feature = "distributed")]
pub use agent_zenoh as distributed;

/// The application layer (the `agent-app` crate): one command line for any
/// agent crate (`run`, `--realtime`, `--record`, `replay`, `check`,
/// `diagram`, and with the feature `distributed` `--deployment D --process P`
/// and `launch`). Behind the feature `app`.
#[cfg(feature = "app")]
pub use agent_app as app;

/// Runtime monitors made from a spec's contracts (the `agent-monitor` crate):
/// freshness, rates, behaviour bounds, ranges, responses and invariants, fed
/// events in time order; with the feature `record` too, their evaluation over a recording. Behind the feature `monitor`.
#[cfg(feature = "monitor")]
pub use agent_monitor as monitor;

/// Recording runs to MCAP for Foxglove (the `agent-mcap` crate): the
/// `McapRecorder` observer, buffer values as JSON with their types' schemas,
/// derived channels (Foxglove's images and poses), reading a recording back.
/// Behind the feature `record`.
#[cfg(feature = "record")]
pub use agent_mcap as record;

/// Agents on ROS 2 over rmw_zenoh (the `agent-ros2` crate): the buffers a
/// spec's `ros2` section names, published as ROS 2 topics with their standard
/// or derived message types and REP 2011 type hashes (`bridge`), the types
/// (`types`) and rmw_zenoh's wire format (`wire`). Behind the feature `ros2`.
#[cfg(feature = "ros2")]
pub use agent_ros2 as ros2;

/// Replaying one subsystem against a recording, bit for bit: `replay(&recording,
/// system, "c1", options)` says `Equivalent` or gives the first `Divergence`.
/// Behind the feature `record`.
#[cfg(feature = "record")]
pub mod replay {
    pub use agent_mcap::replay::{
        Difference, Divergence, ReplayError, ReplayOptions, Replayed, Window, first_difference,
        replay, replay_file,
    };
    pub use agent_mcap::{ReadError, Recording};
}

/// The guide (`docs/`): each page with Rust examples is a module of the doctests,
/// so that its examples are compiled (and run, unless marked `no_run`) with this
/// crate's tests; `tests/docs.rs` checks that every page with Rust is here and that
/// none is ignored.
#[cfg(doctest)]
mod guide {
    #[doc = include_str!("../docs/concepts.md")]
    mod concepts {}
    #[doc = include_str!("../docs/writing-an-agent.md")]
    mod writing_an_agent {}
    #[cfg(feature = "app")]
    #[doc = include_str!("../docs/application.md")]
    mod application {}
    #[cfg(feature = "distributed")]
    #[doc = include_str!("../docs/runtime.md")]
    mod runtime {}
    #[doc = include_str!("../docs/specs.md")]
    mod specs {}
    #[doc = include_str!("../docs/spec-reference.md")]
    mod spec_reference {}
    #[cfg(feature = "record")]
    #[doc = include_str!("../docs/rex.md")]
    mod rex {}
    #[doc = include_str!("../docs/nmpc-mhe.md")]
    mod nmpc_mhe {}
    #[doc = include_str!("../docs/visual-odometry.md")]
    mod visual_odometry {}
}
