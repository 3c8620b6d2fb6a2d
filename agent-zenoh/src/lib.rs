//! The processes of an embodied-agents deployment over Eclipse Zenoh.
//!
//! A spec's deployment places each component in a process on a host. This crate
//! runs one such process and carries its links to the others:
//!
//! * [`ZenohTransport`] implements agent-core's byte [`Transport`]: a publisher
//!   per output buffer that leaves the process (queue links: reliable, blocking
//!   congestion control; sample links: dropping, and given only the values their
//!   readers can see: agent-core's runtime publishes a sample value at the
//!   writer's last activation before the read that sees it, and a fallback a
//!   read), a callback
//!   subscriber per input buffer fed from elsewhere. Nodes hand their messages to wait-free rings that
//!   the transport's own thread publishes from, so a real-time node never waits
//!   for Zenoh.
//! * [`Member`] is the process's membership in the running deployment: its Zenoh
//!   session (peer mode, listening on the endpoint the spec gives it, connected to
//!   every other process's endpoint, no multicast), its presence (a liveliness
//!   token, declared once its links are made, that the others watch: a process
//!   that vanishes is reported on every link it fed), the shared instant zero,
//!   the stop signal, and observations published for a launcher or a monitor.
//! * [`Launcher`] starts every process of a deployment as a child, prefixes and
//!   collects their output, restarts a crashed one, and stops them together.
//!
//! ```text
//! let mut member = Member::join(&spec, "split", "locomotion", &Options::default())?;
//! let mut rt = RealTime::new(system, RtConfig::realtime());
//! rt.place(member.placement()?)?;       // c1 and e11 here, the rest over Zenoh
//! // Links made, then ready: instant zero is shared with the other processes.
//! let running = rt.start_when(limit, || member.ready(Duration::from_millis(500)))?;
//! ```
//!
//! Keys: a link's values travel on `<system>/<agent>/<component>/<group>/<buffer>`
//! of its output buffer ([`agent_core::link::remote::link_key`]); the runtime's
//! own keys live under `<system>/_rt/`.

mod launch;
mod member;
mod outbox;
pub mod security;
mod transport;

pub use launch::{Child, Control, LaunchError, LaunchReport, Launcher, Line};
pub use member::{
    Member, MemberError, Observation, Options, SessionError, Watch, open_peer, open_secure_client,
    open_secure_peer,
};

pub use transport::ZenohTransport;
/// The Zenoh crate this one is built on, for sessions of your own.
pub use zenoh;

pub use agent_core::{Inbox, Publisher, Transport, TransportError};
