//! What a real-time run measured: per node, per thread, and what the OS granted.

use std::fmt;
use std::time::Duration;

use crate::error::ExecError;
use crate::time::Time;

use super::timing::NodeTiming;

/// What the OS granted one thread.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ThreadReport {
    /// The thread's name (a subsystem's name, or `world`).
    pub name: String,
    /// The FIFO priority asked for, if any.
    pub priority_asked: Option<u8>,
    /// Why it was refused, if it was.
    pub priority_refused: Option<Refused>,
    /// The CPU a pool worker asked to be pinned to ([`Threading::Pool`]'s
    /// `pin`), if any.
    ///
    /// [`Threading::Pool`]: super::Threading::Pool
    pub pinned_to: Option<usize>,
    /// Why the pinning was refused, if it was.
    pub pin_refused: Option<Refused>,
    /// The core of the pool whose nodes a worker runs (`None`: not a pool
    /// worker).
    pub core: Option<usize>,
    /// The CPU time the thread used over the run (`None` where the platform
    /// does not say): over the run's wall time, its share of a CPU.
    pub cpu_time: Option<Duration>,
}

/// What the OS refused a real-time run: the run goes on without it (at ordinary
/// priority, or with memory that may page), and the report says so.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Refused {
    /// A FIFO priority outside what the scheduler accepts (1–99 on Linux).
    #[error("priority {priority}: {reason}")]
    PriorityOutOfRange {
        /// The priority asked for.
        priority: u8,
        /// What the scheduler's interface said.
        reason: String,
    },
    /// The OS refused `SCHED_FIFO` (on Linux: no `CAP_SYS_NICE` and an
    /// `RLIMIT_RTPRIO` below the priority).
    #[error("SCHED_FIFO {priority} refused: {reason}")]
    Priority {
        /// The priority asked for.
        priority: u8,
        /// What the OS said.
        reason: String,
    },
    /// The OS refused `mlockall` (on Linux: `RLIMIT_MEMLOCK` too small).
    #[error("mlockall refused: {reason}")]
    LockMemory {
        /// What the OS said.
        reason: String,
    },
    /// The OS refused to pin a thread to a CPU (`sched_setaffinity`).
    #[error("pinning to CPU {cpu} refused: {reason}")]
    Affinity {
        /// The CPU asked for.
        cpu: usize,
        /// What the OS said.
        reason: String,
    },
    /// The platform has no such facility.
    #[error("{what}: {why}")]
    Unsupported {
        /// What was asked (`SCHED_FIFO 80`, `mlockall`).
        what: String,
        /// What the platform lacks.
        why: &'static str,
    },
}

/// What a real-time run measured.
#[derive(Debug, Default)]
pub struct RtReport {
    /// Each node's timing, in declaration order.
    pub nodes: Vec<NodeTiming>,
    /// Each thread and its priority.
    pub threads: Vec<ThreadReport>,
    /// `Some(Ok)`: memory was locked; `Some(Err(why))`: refused; `None`: not asked.
    pub memory_locked: Option<Result<(), Refused>>,
    /// Errors met (all of them under `OnError::Stop`, the first ones under
    /// `Continue`).
    pub errors: Vec<ExecError>,
    /// All errors met.
    pub error_count: u64,
    /// Probe results that found their channel full.
    pub probe_dropped: u64,
    /// Wall-clock time from instant zero to the end.
    pub wall: Duration,
    /// The last instant executed.
    pub last_instant: Time,
    /// When the run safe-stopped ([`OnError::SafeStop`](crate::OnError::SafeStop)):
    /// the instant of the error that stopped it.
    pub safe_stopped: Option<Time>,
}

impl RtReport {
    /// Whether every thread got the real-time priority it asked for (false when
    /// none was asked).
    pub fn rt_priority(&self) -> bool {
        !self.threads.is_empty()
            && self
                .threads
                .iter()
                .all(|t| t.priority_asked.is_some() && t.priority_refused.is_none())
    }

    /// The timing of the node named `name`.
    pub fn node(&self, name: &str) -> Option<&NodeTiming> {
        self.nodes.iter().find(|n| n.name == name)
    }
}

impl fmt::Display for RtReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "{:<14} {:<10} {:>9} {:>8} {:>9} {:>9} {:>9} {:>9} {:>9} {:>9} {:>8}",
            "node",
            "thread",
            "period_us",
            "runs",
            "jit_p50",
            "jit_p99",
            "jit_max",
            "cpu_p50",
            "cpu_p99",
            "cpu_max",
            "overruns"
        )?;
        for n in &self.nodes {
            writeln!(
                f,
                "{:<14} {:<10} {:>9} {:>8} {} {} {:>8}",
                n.name,
                n.thread,
                n.period.as_nanos() / 1000,
                n.activations,
                n.jitter,
                n.compute,
                n.overruns
            )?;
        }
        for t in &self.threads {
            match (&t.priority_asked, &t.priority_refused) {
                (None, _) => writeln!(f, "thread {}: ordinary priority", t.name)?,
                (Some(p), None) => writeln!(f, "thread {}: SCHED_FIFO {p}", t.name)?,
                (Some(_), Some(why)) => {
                    writeln!(f, "thread {}: ordinary priority (fallback: {why})", t.name)?
                }
            }
            match (t.pinned_to, &t.pin_refused) {
                (Some(cpu), None) => writeln!(f, "thread {}: pinned to CPU {cpu}", t.name)?,
                (Some(_), Some(why)) => writeln!(f, "thread {}: not pinned ({why})", t.name)?,
                (None, _) => {}
            }
        }
        match &self.memory_locked {
            Some(Ok(())) => writeln!(f, "memory locked")?,
            Some(Err(why)) => writeln!(f, "memory not locked (fallback: {why})")?,
            None => {}
        }
        if self.probe_dropped > 0 {
            writeln!(f, "probe results dropped: {}", self.probe_dropped)?;
        }
        write!(
            f,
            "errors: {}; wall {:.3} s to instant {}",
            self.error_count,
            self.wall.as_secs_f64(),
            self.last_instant
        )
    }
}
