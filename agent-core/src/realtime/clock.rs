//! The wall clock of the real-time executor: absolute deadlines on the monotonic
//! clock, and what the operating system grants (FIFO priority, locked memory).
//!
//! On Linux a thread sleeps with `clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME)`
//! (through `nix`), so a late wake-up never shifts the following deadlines; the
//! priority is set with `pthread_setschedparam(SCHED_FIFO)` (through
//! `thread-priority`) and memory locked with `mlockall` (through `nix`). Where any
//! of them is refused, the executor goes on with what it has and the report says
//! what was refused and why. Elsewhere the sleep is `std::thread::sleep` towards the
//! same absolute deadline.

use std::time::{Duration, Instant};

use super::Refused;

/// The common origin of every thread's deadlines: instant `t` of a node is
/// `origin + t` on the monotonic clock.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Clock {
    origin: Instant,
}

impl Clock {
    /// A clock whose instant zero is `lead` from now (time for the threads to start).
    pub(crate) fn starting_in(lead: Duration) -> Clock {
        Clock {
            origin: Instant::now() + lead,
        }
    }

    /// A clock whose instant zero is the wall-clock time `origin` (shared by the
    /// processes of a deployment; in the past for a process that joins late).
    pub(crate) fn at_wall(origin: std::time::SystemTime) -> Clock {
        let (now, wall) = (Instant::now(), std::time::SystemTime::now());
        let origin = match origin.duration_since(wall) {
            Ok(ahead) => now + ahead,
            Err(behind) => now.checked_sub(behind.duration()).unwrap_or(now),
        };
        Clock { origin }
    }

    /// The wall-clock time of instant zero (as this host's clock reads it
    /// now).
    pub(crate) fn zero_on_wall(&self) -> std::time::SystemTime {
        let (now, wall) = (Instant::now(), std::time::SystemTime::now());
        match self.origin.checked_duration_since(now) {
            Some(ahead) => wall.checked_add(ahead).unwrap_or(wall),
            None => wall
                .checked_sub(now.duration_since(self.origin))
                .unwrap_or(wall),
        }
    }

    /// Nanoseconds since the origin (0 before it).
    #[inline]
    pub(crate) fn now(&self) -> u64 {
        let d = Instant::now().saturating_duration_since(self.origin);
        u64::try_from(d.as_nanos()).unwrap_or(u64::MAX)
    }

    /// Sleep until `t` nanoseconds after the origin (at once if that is past).
    #[inline]
    pub(crate) fn sleep_until(&self, t: u64) {
        let deadline = self.origin + Duration::from_nanos(t);
        sleep_until(deadline);
    }
}

#[cfg(target_os = "linux")]
fn sleep_until(deadline: Instant) {
    use nix::errno::Errno;
    use nix::sys::time::TimeSpec;
    use nix::time::{ClockId, ClockNanosleepFlags, clock_gettime, clock_nanosleep};
    // `Instant` is CLOCK_MONOTONIC on Linux; the deadline is turned into the
    // clock's own reading once, then slept to absolutely.
    let Ok(now_ts) = clock_gettime(ClockId::CLOCK_MONOTONIC) else {
        return fallback_sleep_until(deadline);
    };
    let left = deadline.saturating_duration_since(Instant::now());
    if left.is_zero() {
        return;
    }
    let target = now_ts + TimeSpec::from_duration(left);
    loop {
        match clock_nanosleep(
            ClockId::CLOCK_MONOTONIC,
            ClockNanosleepFlags::TIMER_ABSTIME,
            &target,
        ) {
            Err(Errno::EINTR) => continue,
            Ok(_) => return,
            Err(_) => return fallback_sleep_until(deadline),
        }
    }
}

#[cfg(not(target_os = "linux"))]
fn sleep_until(deadline: Instant) {
    fallback_sleep_until(deadline)
}

fn fallback_sleep_until(deadline: Instant) {
    let left = deadline.saturating_duration_since(Instant::now());
    if !left.is_zero() {
        std::thread::sleep(left);
    }
}

/// Give the calling thread FIFO real-time priority `priority` (1–99).
pub(crate) fn set_fifo_priority(priority: u8) -> Result<(), Refused> {
    #[cfg(unix)]
    {
        use thread_priority::{
            RealtimeThreadSchedulePolicy, ThreadPriority, ThreadPriorityValue,
            ThreadSchedulePolicy, set_thread_priority_and_policy, thread_native_id,
        };
        let value =
            ThreadPriorityValue::try_from(priority).map_err(|e| Refused::PriorityOutOfRange {
                priority,
                reason: e.to_string(),
            })?;
        set_thread_priority_and_policy(
            thread_native_id(),
            ThreadPriority::Crossplatform(value),
            ThreadSchedulePolicy::Realtime(RealtimeThreadSchedulePolicy::Fifo),
        )
        .map_err(|e| Refused::Priority {
            priority,
            reason: format!("{e:?}"),
        })
    }
    #[cfg(not(unix))]
    {
        Err(Refused::Unsupported {
            what: format!("SCHED_FIFO {priority}"),
            why: "no real-time scheduling on this platform",
        })
    }
}

/// Lock the process's memory (current and future) so that no page fault delays a
/// period.
pub(crate) fn lock_memory() -> Result<(), Refused> {
    #[cfg(target_os = "linux")]
    {
        use nix::sys::mman::{MlockAllFlags, mlockall};
        mlockall(MlockAllFlags::MCL_CURRENT | MlockAllFlags::MCL_FUTURE).map_err(|e| {
            Refused::LockMemory {
                reason: e.to_string(),
            }
        })
    }
    #[cfg(not(target_os = "linux"))]
    {
        Err(Refused::Unsupported {
            what: "mlockall".to_owned(),
            why: "not on this platform",
        })
    }
}

/// Undo [`lock_memory`] (when the run ends).
pub(crate) fn unlock_memory() {
    #[cfg(target_os = "linux")]
    {
        let _ = nix::sys::mman::munlockall();
    }
}

/// The CPUs this process may run on (its affinity mask), in order; empty where
/// the platform does not say.
pub(crate) fn allowed_cpus() -> Vec<usize> {
    #[cfg(target_os = "linux")]
    {
        use nix::sched::{CpuSet, sched_getaffinity};
        use nix::unistd::Pid;
        match sched_getaffinity(Pid::from_raw(0)) {
            Ok(set) => (0..CpuSet::count())
                .filter(|&c| set.is_set(c).unwrap_or(false))
                .collect(),
            Err(_) => Vec::new(),
        }
    }
    #[cfg(not(target_os = "linux"))]
    {
        Vec::new()
    }
}

/// Pin the calling thread to `cpu`.
pub(crate) fn pin_to(cpu: usize) -> Result<(), Refused> {
    #[cfg(target_os = "linux")]
    {
        use nix::sched::{CpuSet, sched_setaffinity};
        use nix::unistd::Pid;
        let refused = |e: nix::errno::Errno| Refused::Affinity {
            cpu,
            reason: e.to_string(),
        };
        let mut set = CpuSet::new();
        set.set(cpu).map_err(refused)?;
        // Pid 0: the calling thread.
        sched_setaffinity(Pid::from_raw(0), &set).map_err(refused)
    }
    #[cfg(not(target_os = "linux"))]
    {
        Err(Refused::Unsupported {
            what: format!("pinning to CPU {cpu}"),
            why: "not on this platform",
        })
    }
}

/// The CPU time the calling thread has used; `None` where the platform does
/// not say.
pub(crate) fn thread_cpu_time() -> Option<Duration> {
    #[cfg(target_os = "linux")]
    {
        use nix::time::{ClockId, clock_gettime};
        clock_gettime(ClockId::CLOCK_THREAD_CPUTIME_ID)
            .ok()
            .map(Duration::from)
    }
    #[cfg(not(target_os = "linux"))]
    {
        None
    }
}
