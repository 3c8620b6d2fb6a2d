//! The real-time executor: the same [`System`] as the deterministic [`Executor`]
//! runs, unchanged, on threads against the wall clock.
//!
//! # Threads
//!
//! Every subsystem runs on a thread of its own. Drivers that share the system's
//! environment ([`SystemBuilder::environment`]) run together on one thread, the
//! world's, in the deterministic order (real receptors last in an instant), since
//! the environment is theirs alone; without an environment each driver has its own
//! thread.
//!
//! # Timing
//!
//! Each thread runs its nodes' instants `k·period` on absolute deadlines of one
//! clock shared by every thread (`clock_nanosleep(TIMER_ABSTIME)` on Linux), so a
//! late wake-up or a long activation never shifts later deadlines; an activation
//! that ends after the node's next deadline is an overrun, and the next one starts
//! at once. Nodes see the nominal instant as their time (`k·period`, as in the
//! deterministic executor). With [`RtConfig::realtime`] each thread asks for
//! `SCHED_FIFO` priority, higher for shorter periods (rate-monotonic), and the
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
mod timing;
mod worker;

use std::any::Any;
use std::collections::{BTreeMap, HashSet};
use std::fmt;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::Receiver;
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime};

use crate::kinds::NodeKind;
use crate::link::remote::{self, Transport};
use crate::link::thread::SharedStats;
use crate::link::{LinkId, LinkStats, ThreadHalves};
use crate::probe::{ProbeFn, Probes, Target};
use crate::subsystem::{Driver, Subsystem};
use crate::system::{DriverHandle, SubsystemHandle, System};
use crate::time::Time;
use crate::trace::{Observer, SystemInfo};

pub use crate::probe::Probed;
pub use config::{RtConfig, RtError};
pub use finished::Finished;
pub use report::{RtReport, ThreadReport};
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
    /// restart from another sender: [`remote::new_epoch`]).
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
        }
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
    /// every node halted, if that comes first).
    pub fn start(self, limit: Duration) -> Result<Running, RtError> {
        self.start_inner(limit, None)
    }

    /// As [`RealTime::start`], with instant zero at the wall-clock time that
    /// `sync` returns, called once every link is made (every subscription of a
    /// placed process declared) and before any thread starts. The processes of
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

    fn start_inner(
        self,
        limit: Duration,
        sync: Option<&mut dyn FnMut() -> Option<Result<SystemTime, RtError>>>,
    ) -> Result<Running, RtError> {
        let RealTime {
            system,
            config,
            probes,
            dropped,
            placement,
            mut observers,
        } = self;
        let System {
            info,
            nodes,
            outs,
            ins,
            channels,
            environment,
        } = system;
        let n = nodes.len();
        let here: Vec<bool> = match &placement {
            None => vec![true; n],
            Some(p) => info
                .nodes
                .iter()
                .map(|node| p.here.contains(&node.name))
                .collect(),
        };
        // Threads: one per subsystem; the drivers together if they share an
        // environment, else one each.
        let has_env = environment.is_some();
        let mut thread_of = vec![usize::MAX; n];
        let mut names: Vec<String> = Vec::new();
        let mut world = None;
        for (i, node) in info.nodes.iter().enumerate() {
            if !here[i] {
                continue;
            }
            let is_driver = matches!(node.kind, NodeKind::RealEffector | NodeKind::RealReceptor);
            thread_of[i] = if is_driver && has_env {
                *world.get_or_insert_with(|| {
                    names.push("world".to_owned());
                    names.len() - 1
                })
            } else {
                names.push(node.name.clone());
                names.len() - 1
            };
        }
        let threads = names.len();
        // Rate-monotonic priorities: the shortest period of a thread ranks it.
        let mut shortest = vec![u64::MAX; threads];
        for (i, node) in info.nodes.iter().enumerate() {
            if let Some(s) = shortest.get_mut(thread_of[i]) {
                *s = (*s).min(node.period.as_nanos());
            }
        }
        let mut distinct: Vec<u64> = shortest.clone();
        distinct.sort_unstable();
        distinct.dedup();
        let priority_of = |th: usize| {
            config.priority.map(|top| {
                let rank = distinct
                    .iter()
                    .position(|p| *p == shortest[th])
                    .unwrap_or(0);
                let rank = u8::try_from(rank).unwrap_or(u8::MAX);
                top.saturating_sub(rank).max(1)
            })
        };
        // Link halves, to the threads of their ends.
        let mut txs: Vec<ThreadHalves> = (0..threads).map(|_| empty(channels.len())).collect();
        let mut rxs: Vec<ThreadHalves> = (0..threads).map(|_| empty(channels.len())).collect();
        let mut stats: Vec<Arc<SharedStats>> = Vec::with_capacity(channels.len());
        let mut subscriptions: Vec<Box<dyn Any + Send>> = Vec::new();
        let mut inboxes: Vec<Arc<remote::Inbox>> = Vec::new();
        let epoch = placement
            .as_ref()
            .map(|p| p.epoch)
            .filter(|e| *e != 0)
            .unwrap_or_else(remote::new_epoch);
        let mut transport = placement.map(|p| (p.prefix, p.transport));
        // One publisher per output buffer (key), made by its first remote link;
        // the policy of a key with a queue link among its links is the queue's.
        let mut published: HashSet<String> = HashSet::new();
        for (l, plan) in channels.iter().enumerate() {
            let link = &info.links[l];
            match (here[link.from], here[link.to], transport.as_mut()) {
                (true, true, _) | (_, _, None) => {
                    let (tx, rx, s) = plan.threaded();
                    txs[thread_of[link.from]][l] = Some(tx);
                    rxs[thread_of[link.to]][l] = Some(rx);
                    stats.push(s);
                }
                (true, false, Some((prefix, transport))) => {
                    let key = remote::link_key(prefix, &info, link);
                    let s = Arc::new(SharedStats::default());
                    let publisher = if published.insert(key.clone()) {
                        let policy = info
                            .links
                            .iter()
                            .filter(|k| k.from == link.from && k.from_port == link.from_port)
                            .map(|k| k.policy)
                            .find(|p| matches!(p, crate::Policy::Queue { .. }))
                            .unwrap_or(link.policy);
                        let made = transport.publisher(&key, policy).map_err(|error| {
                            RtError::Transport {
                                link: link.name.clone(),
                                key: key.clone(),
                                error,
                            }
                        })?;
                        Some(made)
                    } else {
                        None
                    };
                    let tx = remote::RemoteTx::new(
                        publisher,
                        key.into(),
                        plan.fingerprint(),
                        epoch,
                        s.clone(),
                    );
                    txs[thread_of[link.from]][l] = Some(plan.remote_tx(tx));
                    stats.push(s);
                }
                (false, true, Some((prefix, transport))) => {
                    let key = remote::link_key(prefix, &info, link);
                    let (rx, inbox, s) = plan.remote_rx(key.as_str().into());
                    // Whether this process joins late is known at `sync`.
                    inbox.defer_start();
                    inboxes.push(inbox.clone());
                    let guard =
                        transport
                            .subscribe(&key, inbox)
                            .map_err(|error| RtError::Transport {
                                link: link.name.clone(),
                                key: key.clone(),
                                error,
                            })?;
                    subscriptions.push(guard);
                    rxs[thread_of[link.to]][l] = Some(rx);
                    stats.push(s);
                }
                (false, false, Some(_)) => stats.push(Arc::new(SharedStats::default())),
            }
        }
        let mut works: Vec<worker::Work> = names
            .iter()
            .enumerate()
            .map(|(th, name)| worker::Work {
                name: name.clone(),
                nodes: Vec::new(),
                seeds: Vec::new(),
                outs: Vec::new(),
                ins: Vec::new(),
                txs: std::mem::take(&mut txs[th]),
                rxs: std::mem::take(&mut rxs[th]),
                environment: None,
                priority: priority_of(th),
                probes: Vec::new(),
                observer: None,
            })
            .collect();
        // Nodes in stepping order: declaration order, real receptors last.
        let mut seeds: Vec<Option<Box<dyn crate::node::NodeSeed>>> =
            nodes.into_iter().map(Some).collect();
        let (mut order, receptors): (Vec<usize>, Vec<usize>) =
            (0..n).partition(|&i| info.nodes[i].kind != NodeKind::RealReceptor);
        order.extend(receptors);
        for i in order {
            if let (Some(seed), Some(w)) = (seeds[i].take(), works.get_mut(thread_of[i])) {
                w.nodes.push(i);
                w.seeds.push(seed);
            }
        }
        for (node, plan) in outs {
            if let Some(w) = works.get_mut(thread_of[node]) {
                w.outs.push((node, plan));
            }
        }
        for (node, plan) in ins {
            if let Some(w) = works.get_mut(thread_of[node]) {
                w.ins.push((node, plan));
            }
        }
        if let Some(w) = world {
            works[w].environment = environment;
        }
        if let Some(make) = observers.as_mut() {
            for w in &mut works {
                w.observer = Some(make(&w.name, &w.nodes));
            }
        }
        for (target, probe) in probes {
            let th = match target {
                Target::Node(i) => thread_of.get(i).copied().unwrap_or(usize::MAX),
                Target::Environment => world.unwrap_or(usize::MAX),
            };
            if let Some(w) = works.get_mut(th) {
                w.probes.push((target, probe));
            }
        }
        let memory_locked = config.lock_memory.then(clock::lock_memory);
        let stop = Arc::new(AtomicBool::new(false));
        // Whether this process joins a deployment whose instant zero is past.
        let mut joining = false;
        let clock = match sync.and_then(|f| f()) {
            Some(Ok(at)) => {
                // Instant zero in the past: this process joins a running
                // deployment (it was restarted). Across hosts this reads
                // another host's clock: they must agree well within the lead
                // the first process gives the others (a second in Rex).
                let late = at <= SystemTime::now();
                joining = late;
                for inbox in &inboxes {
                    inbox.start(late);
                }
                clock::Clock::at_wall(at)
            }
            Some(Err(e)) => {
                if memory_locked.as_ref().is_some_and(Result::is_ok) {
                    clock::unlock_memory();
                }
                return Err(e);
            }
            None => {
                for inbox in &inboxes {
                    inbox.start(false);
                }
                clock::Clock::starting_in(config.lead)
            }
        };
        let end = u64::try_from(limit.as_nanos()).unwrap_or(u64::MAX);
        // Decided once for every thread: a thread spawned late on a loaded
        // machine still runs from instant zero (its deadlines catch up).
        let first = if joining { clock.now() } else { 0 };
        let shared = Arc::new(worker::Shared {
            info: info.clone(),
            clock,
            stop: stop.clone(),
            first,
            end,
            config: config.exec,
            errors: AtomicU64::new(0),
            halted: (0..n).map(|_| AtomicBool::new(false)).collect(),
        });
        let mut handles = Vec::with_capacity(works.len());
        for work in works {
            let name = work.name.clone();
            let shared = shared.clone();
            let spawned = std::thread::Builder::new()
                .name(format!("rt-{name}"))
                .spawn(move || worker::run(work, &shared));
            match spawned {
                Ok(h) => handles.push((name, h)),
                Err(source) => {
                    stop.store(true, Ordering::Relaxed);
                    for (_, h) in handles {
                        let _ = h.join();
                    }
                    if memory_locked.is_some() {
                        clock::unlock_memory();
                    }
                    return Err(RtError::Spawn {
                        thread: name,
                        source,
                    });
                }
            }
        }
        Ok(Running {
            info,
            handles,
            stop: StopHandle(stop),
            shared,
            stats,
            dropped,
            memory_locked,
            started: Instant::now(),
            lead: config.lead,
            _subscriptions: subscriptions,
            _transport: transport,
        })
    }
}

fn empty(n: usize) -> ThreadHalves {
    (0..n).map(|_| None).collect()
}

/// A real-time run in progress.
pub struct Running {
    info: SystemInfo,
    handles: Vec<(String, JoinHandle<worker::Done>)>,
    stop: StopHandle,
    shared: Arc<worker::Shared>,
    stats: Vec<Arc<SharedStats>>,
    dropped: Vec<Arc<AtomicU64>>,
    memory_locked: Option<Result<(), String>>,
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
                    report.threads.push(ThreadReport {
                        name: done.name,
                        priority_asked: done.priority.as_ref().map(|(p, _)| *p),
                        priority_refused: done.priority.and_then(|(_, r)| r.err()),
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
