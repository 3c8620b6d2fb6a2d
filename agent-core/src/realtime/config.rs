//! What a real-time run is given ([`RtConfig`]) and why it may not start
//! ([`RtError`]).

use std::time::Duration;

use crate::executor::ExecConfig;
use crate::link::remote::TransportError;

/// Settings of the real-time executor.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RtConfig {
    /// Error policy, audit, as for the deterministic executor.
    pub exec: ExecConfig,
    /// Ask for `SCHED_FIFO` priority: the highest, given to the nodes of the
    /// shortest period; each longer period one lower (never below 1). `None`:
    /// ordinary threads.
    pub priority: Option<u8>,
    /// Lock the process's memory (`mlockall`) for the run.
    pub lock_memory: bool,
    /// Time given to the threads to start before instant zero. A thread that
    /// starts later still runs every instant from zero (catching up), so the
    /// lead bounds the first instants' lateness, not what runs.
    pub lead: Duration,
    /// Capacity of each probe's channel.
    pub probe_capacity: usize,
    /// How nodes are put on threads: a bounded pool of workers per core (the
    /// default), or a thread per subsystem.
    pub threading: Threading,
}

/// How the real-time executor puts the nodes it runs on threads.
///
/// Drivers that share the system's environment always run together on one
/// thread, the world's (see the [module](super)).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Threading {
    /// A bounded set of worker threads: the agents are dealt out over `cores`
    /// cores in declaration order, each to the core with the fewest nodes so
    /// far (an agent's subsystems stay together, so the links within an
    /// agent stay on one core), and on each core one worker runs the nodes of
    /// one period, in declaration order (real receptors last). So a system
    /// has at most `cores` × (distinct periods) workers however many
    /// subsystems it has; a worker's FIFO priority is its period's rank
    /// (rate-monotonic, as a thread's in [`Threading::PerSubsystem`]), so a
    /// worker of a shorter period preempts the longer ones on its core.
    ///
    /// Within a worker, an activation that overruns delays the nodes after it
    /// (they run late, on the same absolute deadlines, and none loses an
    /// instant); other workers are not delayed by it beyond their share of
    /// the core.
    Pool {
        /// How many cores to deal the agents over; `0`: as many as the process
        /// may use (`std::thread::available_parallelism`).
        cores: u16,
        /// Pin each worker to its core (Linux: `sched_setaffinity`, core `k`
        /// being the `k`-th CPU of the process's affinity mask, modulo its
        /// size); what the OS refuses is reported, and the run goes on
        /// unpinned.
        pin: bool,
    },
    /// One thread per subsystem, and per driver without a shared
    /// environment: where isolation matters more than the thread count (a
    /// node that blocks delays no other node).
    PerSubsystem,
}

impl Default for Threading {
    /// A pool over every core the process may use, unpinned.
    fn default() -> Self {
        Threading::Pool {
            cores: 0,
            pin: false,
        }
    }
}

impl Threading {
    /// A pool over `cores` cores (`0`: all the process may use), pinned.
    pub fn pinned(cores: u16) -> Self {
        Threading::Pool { cores, pin: true }
    }
}

impl Default for RtConfig {
    /// Ordinary threads on absolute deadlines, no memory locking.
    fn default() -> Self {
        RtConfig {
            exec: ExecConfig::default(),
            priority: None,
            lock_memory: false,
            lead: Duration::from_millis(20),
            probe_capacity: 4096,
            threading: Threading::default(),
        }
    }
}

impl RtConfig {
    /// As on a robot: `SCHED_FIFO` priorities from 80 down, memory locked.
    pub fn realtime() -> Self {
        RtConfig {
            priority: Some(80),
            lock_memory: true,
            ..RtConfig::default()
        }
    }
}

/// Why a real-time run could not start.
#[derive(Debug, thiserror::Error)]
pub enum RtError {
    /// The OS refused a thread.
    #[error("cannot start thread `{thread}`: {source}")]
    Spawn {
        /// The thread's name.
        thread: String,
        /// The OS's reason.
        source: std::io::Error,
    },
    /// A thread panicked (a bug in a node; its nodes are lost).
    #[error("thread `{0}` panicked")]
    Panicked(String),
    /// A placement names a node the system does not have.
    #[error("the placement runs `{name}`, which the system does not have (it has: {known})")]
    UnknownNode {
        /// The name.
        name: String,
        /// The system's nodes.
        known: String,
    },
    /// The processes of a deployment could not agree on instant zero.
    #[error("cannot start in step with the other processes: {0}")]
    Sync(String),
    /// A link cannot be fed from outside the system ([`RealTime::feed`](crate::RealTime::feed)).
    #[error("link `{link}` cannot be fed from outside the system: {reason}")]
    Feed {
        /// The link.
        link: String,
        /// Why not.
        reason: String,
    },
    /// The transport could not publish or subscribe a link's key.
    #[error("link `{link}` over key `{key}`: {error}")]
    Transport {
        /// The link.
        link: String,
        /// Its key.
        key: String,
        /// The transport's error.
        error: TransportError,
    },
}
