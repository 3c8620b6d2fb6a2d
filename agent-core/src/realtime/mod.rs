//! The real-time executor: the same [`System`] as the deterministic [`Executor`]
//! runs, unchanged, on threads against the wall clock.
//!
//! # Threads
//!
//! By default ([`Threading::Pool`]) a bounded set of worker threads runs the
//! subsystems: the agents are dealt out over the cores (each to the core with
//! the fewest subsystems so far, so that an agent's links stay on one core),
//! and on each core one worker runs the subsystems of one period, in
//! declaration order.
//! A system of a thousand subsystems at two periods on two cores runs on four
//! workers, not a thousand threads. [`Threading::PerSubsystem`] gives every
//! subsystem a thread of its own instead, where isolation matters more.
//! Drivers that share the system's environment ([`SystemBuilder::environment`])
//! run together on one thread, the world's, in the deterministic order (real
//! receptors last in an instant), since the environment is theirs alone;
//! without an environment drivers are placed as subsystems are.
//!
//! # Timing
//!
//! Each thread runs its nodes' instants `k·period` on absolute deadlines of one
//! clock shared by every thread (`clock_nanosleep(TIMER_ABSTIME)` on Linux), so a
//! late wake-up or a long activation never shifts later deadlines; an activation
//! that ends after the node's next deadline is an overrun, and the next one starts
//! at once. Nodes see the nominal instant as their time (`k·period`, as in the
//! deterministic executor). [`NodeTiming`] keeps each node's wake-up jitter,
//! compute time and response time (deadline to end). With
//! [`RtConfig::realtime`] each thread asks for `SCHED_FIFO` priority, higher
//! for shorter periods (rate-monotonic), and the
//! process locks its memory (`mlockall`); what the OS refuses is reported in
//! [`RtReport`] and the run goes on without it.
//!
//! # Links
//!
//! Links between threads keep their policy without locks: a sample link is a
//! wait-free triple buffer (latest value; values overwritten before they were
//! read are counted), a queue link a wait-free bounded ring allocated once (a value
//! refused by a full ring is an error, as in-process). Values move rather than
//! copy, so `Copy` payloads never allocate after the start. Reads are causal:
//! an activation of instant `t` takes only values stamped at or before `t`, so a
//! thread running late (catching up after an overrun) never sees a value its
//! sender stamped after the instant it is running; such a value waits in the
//! link for the activation whose instant reaches it.
//!
//! # Watching a run
//!
//! Threads own their nodes, so the program watches through probes
//! ([`RealTime::probe`], [`RealTime::probe_environment`]): a function called on the
//! node's thread after each activation, whose results arrive on a bounded channel
//! (results that find it full are counted in [`RtReport::probe_dropped`], never
//! blocking the node). [`Running::stop`] ends the run; [`Running::join`] returns
//! every node, the environment and the report ([`Finished`]).
//!
//! An [`Observer`] sees a run as in the deterministic executor, one per thread
//! ([`RealTime::observe`]); here it also matters which value each activation
//! read ([`Observer::read`]): that depends on which thread reached an instant
//! first, so a recording keeps it and a replay feeds it.
//!
//! [`Executor`]: crate::Executor
//! [`SystemBuilder::environment`]: crate::SystemBuilder::environment

mod clock;
mod config;
mod finished;
mod report;
mod start;
mod timing;
mod worker;

use std::any::Any;
use std::collections::BTreeMap;
use std::fmt;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::Receiver;
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

use crate::link::remote::{Inbox, Transport};
use crate::link::thread::SharedStats;
use crate::link::{LinkId, LinkStats};
use crate::probe::{ProbeFn, Probes, Target};
use crate::subsystem::{Driver, Subsystem};
use crate::system::{DriverHandle, SubsystemHandle, System};
use crate::time::Time;
use crate::trace::{Observer, SystemInfo};

pub use crate::probe::Probed;
pub use config::{RtConfig, RtError, Threading};
pub use finished::Finished;
pub use report::{Refused, RtReport, ThreadReport};
pub use timing::{NodeTiming, Spread};

/// A system prepared for a real-time run: add probes, then [`RealTime::start`].
pub struct RealTime {
    system: System,
    config: RtConfig,
    probes: Vec<(Target, ProbeFn)>,
    /// The counters of the probe sets' full channels.
    dropped: Vec<Arc<AtomicU64>>,
    placement: Option<Placement>,
    observers: Option<MakeObserver>,
    /// Input buffers fed from outside the system: (link, inbox).
    feeds: Vec<(usize, Arc<Inbox>)>,
}

/// Makes the observer of one thread (see [`RealTime::observe`]).
type MakeObserver = Box<dyn FnMut(&str, &[usize]) -> Box<dyn Observer> + Send>;

/// This process's part of a deployment: the nodes it runs, and the transport
/// that carries the links between them and the nodes of other processes.
///
/// A link whose two ends run here is a link between threads, as without a
/// placement; a link with one end here travels over `transport` on the key
/// [`link_key`](crate::link::remote::link_key)`(prefix, ...)`; a link with no end
/// here is not made. Nodes not placed here are not run (and not returned by
/// [`Finished`]).
pub struct Placement {
    /// The names of the nodes this process runs.
    pub here: Vec<String>,
    /// The first part of every key (the system's name, for example).
    pub prefix: String,
    /// How links leave the process.
    pub transport: Box<dyn Transport>,
    /// The epoch this process's values carry on the links that leave it (a
    /// number new at each start of the process, so that receivers tell a
    /// restart from another sender: [`remote::new_epoch`](crate::link::remote::new_epoch)).
    pub epoch: u64,
}

impl fmt::Debug for Placement {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Placement")
            .field("here", &self.here)
            .field("prefix", &self.prefix)
            .finish()
    }
}

impl fmt::Debug for RealTime {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("RealTime")
            .field("nodes", &self.system.info.nodes.len())
            .field("config", &self.config)
            .finish()
    }
}

/// Stops a running real-time system (from any thread, a signal handler's flag
/// watcher, or a probe's consumer).
#[derive(Clone, Debug)]
pub struct StopHandle(Arc<AtomicBool>);

impl StopHandle {
    /// Ask every thread to end after its current instant.
    pub fn stop(&self) {
        self.0.store(true, Ordering::Relaxed);
    }

    /// Whether a stop was asked (or an error stopped the run).
    pub fn is_stopped(&self) -> bool {
        self.0.load(Ordering::Relaxed)
    }
}

impl RealTime {
    /// Prepare `system` for a real-time run.
    pub fn new(system: System, config: RtConfig) -> Self {
        RealTime {
            system,
            config,
            probes: Vec::new(),
            dropped: Vec::new(),
            placement: None,
            observers: None,
            feeds: Vec::new(),
        }
    }

    /// Feed the input buffer at the receiving end of `link` from outside the
    /// system as well (a bridge to another middleware: a ROS 2 topic):
    /// values delivered to the returned inbox, as messages of the wire format
    /// between processes under `key` (a name for errors), are taken by the
    /// buffer's reads beside the link's own, each checked as a value from
    /// another process is (the payload's fingerprint, the feeder's epoch and
    /// numbering, a queue's bound: see [`Inbox`]) and its problems reported
    /// at the reads through the node's error policy. When the link and the
    /// feed both hold a value, the reads take them in turn: neither starves
    /// the other. The observer sees a fed value as one received from another
    /// process ([`Observer::received`]), so a recording keeps it.
    ///
    /// The receiving node must run in this process (checked when the run
    /// starts); a link is fed once.
    pub fn feed(&mut self, link: LinkId, key: &str) -> Result<Arc<Inbox>, RtError> {
        let l = link.index();
        let feed_error = |reason: String| RtError::Feed {
            link: self
                .system
                .info
                .links
                .get(l)
                .map_or_else(|| format!("#{l}"), |k| k.name.clone()),
            reason,
        };
        let Some(plan) = self.system.channels.get(l) else {
            return Err(feed_error(format!(
                "the system has {} links",
                self.system.channels.len()
            )));
        };
        if self.feeds.iter().any(|(k, _)| *k == l) {
            return Err(feed_error("the link is fed already".into()));
        }
        let inbox = plan.feed_inbox(key.into());
        self.feeds.push((l, inbox.clone()));
        Ok(inbox)
    }

    /// Observe the run as the deterministic executor's observer does: `make` is
    /// called once per thread when the run starts, with the thread's name and
    /// the nodes it runs (indices into [`SystemInfo::nodes`]); the observer it
    /// returns sees that thread's behaviour switches, actions, values sent and
    /// read, and errors, on that thread, and is dropped there when the thread
    /// ends (so an observer that hands its results to another thread does so
    /// when dropped; [`Running::join`] returns after every drop). Its calls run
    /// within the nodes' activations: keep them short and allocation-free (a
    /// recorder queues to a writer thread).
    pub fn observe(
        &mut self,
        make: impl FnMut(&str, &[usize]) -> Box<dyn Observer> + Send + 'static,
    ) -> &mut Self {
        self.observers = Some(Box::new(make));
        self
    }

    /// Run only this process's part of a deployment (see [`Placement`]).
    pub fn place(&mut self, placement: Placement) -> Result<&mut Self, RtError> {
        let info = &self.system.info;
        for name in &placement.here {
            if !info.nodes.iter().any(|n| &n.name == name) {
                return Err(RtError::UnknownNode {
                    name: name.clone(),
                    known: info
                        .nodes
                        .iter()
                        .map(|n| n.name.as_str())
                        .collect::<Vec<_>>()
                        .join(", "),
                });
            }
        }
        self.placement = Some(placement);
        Ok(self)
    }

    /// Names, kinds, periods and links.
    pub fn info(&self) -> &SystemInfo {
        &self.system.info
    }

    /// Watch the run with a set of probes (see [`Probes`]): each is called on
    /// the thread of the node it watches (the environment's: the world's),
    /// after each activation.
    pub fn watch<M>(&mut self, probes: Probes<M>) -> &mut Self {
        self.dropped.push(probes.dropped_counter());
        self.probes.extend(probes.entries);
        self
    }

    /// Watch subsystem `h`: after each of its activations, on its thread, `f` sees
    /// it ([`Probed`]: the instant, its memory, its inputs, its behaviour); what
    /// `f` returns arrives on the receiver.
    pub fn probe<S, M, F>(&mut self, h: &SubsystemHandle<S>, f: F) -> Receiver<M>
    where
        S: Subsystem,
        M: Send + 'static,
        F: FnMut(&Probed<'_, S>) -> Option<M> + Send + 'static,
    {
        let (mut probes, rx) = Probes::new(self.config.probe_capacity);
        probes.subsystem(h, f);
        self.watch(probes);
        rx
    }

    /// Watch driver `h`: after each of its steps, on its thread, `f` sees the
    /// instant and the device.
    pub fn probe_driver<D, M, F>(&mut self, h: &DriverHandle<D>, f: F) -> Receiver<M>
    where
        D: Driver,
        M: Send + 'static,
        F: FnMut(Time, &D) -> Option<M> + Send + 'static,
    {
        let (mut probes, rx) = Probes::new(self.config.probe_capacity);
        probes.driver(h, f);
        self.watch(probes);
        rx
    }

    /// Watch the environment (of type `W`): after each instant of the world's
    /// thread, `f` sees the instant and the environment.
    pub fn probe_environment<W, M, F>(&mut self, f: F) -> Receiver<M>
    where
        W: Any,
        M: Send + 'static,
        F: FnMut(Time, &W) -> Option<M> + Send + 'static,
    {
        let (mut probes, rx) = Probes::new(self.config.probe_capacity);
        probes.environment(f);
        self.watch(probes);
        rx
    }

    /// Start the threads and run for at most `limit` (until stopped, or until
    /// every node halted, if that comes first). Each thread builds its nodes
    /// first; instant zero is [`RtConfig::lead`] after the last is ready, so
    /// that the time a large system takes to build is not lateness.
    pub fn start(self, limit: Duration) -> Result<Running, RtError> {
        self.start_inner(limit, None)
    }

    /// As [`RealTime::start`], with instant zero at the wall-clock time that
    /// `sync` returns, called once every link is made (every subscription of a
    /// placed process declared) and every thread has built its nodes, before
    /// any runs an instant. The processes of
    /// a deployment agree on it there (each announces itself ready, and one of
    /// them sets instant zero for all), so their instants line up (on one host
    /// exactly; across hosts as well as their clocks agree) and, normally, no
    /// value is sent before its receiver listens (if one is, a queue link's
    /// receiver reports the gap). When the time is past (a process restarted
    /// in a running deployment), each node starts at its next instant.
    pub fn start_when<E: fmt::Display>(
        self,
        limit: Duration,
        sync: impl FnOnce() -> Result<SystemTime, E>,
    ) -> Result<Running, RtError> {
        let mut sync = Some(sync);
        let mut call = move || {
            sync.take()
                .map(|f| f().map_err(|e| RtError::Sync(e.to_string())))
        };
        self.start_inner(limit, Some(&mut call))
    }
}

/// A real-time run in progress.
pub struct Running {
    info: SystemInfo,
    handles: Vec<(String, JoinHandle<worker::Done>)>,
    stop: StopHandle,
    shared: Arc<worker::Shared>,
    stats: Vec<Arc<SharedStats>>,
    dropped: Vec<Arc<AtomicU64>>,
    memory_locked: Option<Result<(), Refused>>,
    clock: clock::Clock,
    started: Instant,
    lead: Duration,
    /// Links from other processes stay subscribed while the run goes on.
    _subscriptions: Vec<Box<dyn Any + Send>>,
    _transport: Option<(String, Box<dyn Transport>)>,
}

impl fmt::Debug for Running {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Running")
            .field("threads", &self.handles.len())
            .finish()
    }
}

impl Running {
    /// A handle that stops the run.
    pub fn stop_handle(&self) -> StopHandle {
        self.stop.clone()
    }

    /// The wall-clock time of the run's instant zero: what code outside the
    /// run stamps its values against (a bridge feeding an input:
    /// [`RealTime::feed`]; a value's instant is the wall-clock time minus
    /// this).
    pub fn zero(&self) -> SystemTime {
        self.clock.zero_on_wall()
    }

    /// Ask every thread to end after its current instant.
    pub fn stop(&self) {
        self.stop.stop();
    }

    /// Whether every thread has ended (limit reached, stopped, or every node
    /// halted).
    pub fn is_finished(&self) -> bool {
        self.handles.iter().all(|(_, h)| h.is_finished())
    }

    /// Whether `node` (one this process runs) has halted: reached a final
    /// behaviour, or was halted by its error policy.
    pub fn is_halted(&self, node: crate::NodeId) -> bool {
        self.shared
            .halted
            .get(node.index())
            .is_some_and(|h| h.load(Ordering::Relaxed))
    }

    /// Errors met so far.
    pub fn error_count(&self) -> u64 {
        self.shared.errors.load(Ordering::Relaxed)
    }

    /// Counters of a link, while the run goes on.
    pub fn link_stats(&self, link: LinkId) -> Option<LinkStats> {
        self.stats.get(link.index()).map(|s| s.snapshot())
    }

    /// Names, kinds, periods and links.
    pub fn info(&self) -> &SystemInfo {
        &self.info
    }

    /// Wait for every thread to end (stop first to end early).
    pub fn join(self) -> Result<Finished, RtError> {
        let mut cores: BTreeMap<usize, Box<dyn Any + Send>> = BTreeMap::new();
        let mut environment = None;
        let mut report = RtReport {
            memory_locked: self.memory_locked.clone(),
            ..RtReport::default()
        };
        let mut timings = Vec::new();
        let mut panicked = None;
        for (name, h) in self.handles {
            match h.join() {
                Ok(done) => {
                    cores.extend(done.cores);
                    if done.environment.is_some() {
                        environment = done.environment;
                    }
                    timings.extend(done.timings);
                    report.errors.extend(done.errors);
                    report.last_instant = report.last_instant.max(done.last);
                    report.safe_stopped = report.safe_stopped.or(done.safe_stopped);
                    report.threads.push(ThreadReport {
                        name: done.name,
                        priority_asked: done.priority.as_ref().map(|(p, _)| *p),
                        priority_refused: done.priority.and_then(|(_, r)| r.err()),
                        pinned_to: done.pinned.as_ref().map(|(cpu, _)| *cpu),
                        pin_refused: done.pinned.and_then(|(_, r)| r.err()),
                        core: done.core,
                        cpu_time: done.cpu_time,
                    });
                }
                Err(_) => {
                    panicked.get_or_insert(name);
                }
            }
        }
        if self.memory_locked.as_ref().is_some_and(Result::is_ok) {
            clock::unlock_memory();
        }
        if let Some(name) = panicked {
            return Err(RtError::Panicked(name));
        }
        timings.sort_by_key(|(g, _)| *g);
        report.nodes = timings.into_iter().map(|(_, t)| t).collect();
        report.error_count = self.shared.errors.load(Ordering::Relaxed);
        report.probe_dropped = self.dropped.iter().map(|d| d.load(Ordering::Relaxed)).sum();
        report.wall = self.started.elapsed().saturating_sub(self.lead);
        Ok(Finished {
            info: self.info,
            cores,
            environment,
            links: self.stats.iter().map(|s| s.snapshot()).collect(),
            report,
        })
    }
}
