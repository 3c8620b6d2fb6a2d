//! How a real-time run starts: nodes assigned to threads, links made (between
//! threads, or over the transport to other processes), each thread's work handed
//! out, the clock agreed, the threads spawned.

use std::any::Any;
use std::collections::{BTreeMap, HashSet};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, mpsc};
use std::thread::JoinHandle;
use std::time::{Duration, SystemTime};

use crate::kinds::NodeKind;
use crate::link::reads::ReadGrid;
use crate::link::remote::{self, Transport};
use crate::link::thread::SharedStats;
use crate::link::{ChannelPlan, InPlan, OutPlan, ThreadHalves};
use crate::node::NodeSeed;
use crate::probe::{ProbeFn, Target};
use crate::system::System;
use crate::trace::SystemInfo;

use super::{
    MakeObserver, Placement, RealTime, Refused, RtError, Running, StopHandle, Threading, clock,
    worker,
};

/// A transport and the first part of its keys.
type Away = (String, Box<dyn Transport>);

impl RealTime {
    /// [`RealTime::start`] and [`RealTime::start_when`]: the threads assigned,
    /// the links made, each thread's work handed out, memory locked, the clock
    /// agreed (with `sync`, if given), the threads spawned.
    pub(super) fn start_inner(
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
            observers,
            feeds,
        } = self;
        let System {
            info,
            nodes,
            outs,
            ins,
            channels,
            environment,
        } = system;
        let here = placed_here(&info, placement.as_ref(), nodes.len());
        let threads = Threads::assign(&info, &here, environment.is_some(), config.threading);
        let priorities = threads.priorities(&info, config.priority);
        let epoch = placement
            .as_ref()
            .map(|p| p.epoch)
            .filter(|e| *e != 0)
            .unwrap_or_else(remote::new_epoch);
        let mut transport = placement.map(|p| (p.prefix, p.transport));
        let Links {
            txs,
            rxs,
            stats,
            subscriptions,
            inboxes,
        } = make_links(&info, &channels, &here, &threads, epoch, transport.as_mut())?;
        let rxs = feed_links(&info, &channels, &here, &threads, rxs, feeds)?;
        let mut works = threads.empty_works(txs, rxs, priorities, &clock::allowed_cpus());
        give_nodes(&mut works, &threads, &info, nodes, outs, ins);
        if let Some(w) = threads.world {
            works[w].environment = environment;
        }
        give_observers(&mut works, observers);
        give_probes(&mut works, &threads, probes);
        let memory_locked = config.lock_memory.then(clock::lock_memory);
        let stop = Arc::new(AtomicBool::new(false));
        let end = u64::try_from(limit.as_nanos()).unwrap_or(u64::MAX);
        let shared = Arc::new(worker::Shared {
            info: info.clone(),
            gate: worker::Gate::default(),
            stop: stop.clone(),
            end,
            config: config.exec,
            errors: AtomicU64::new(0),
            safe_stopped: AtomicU64::new(u64::MAX),
            halted: (0..info.nodes.len())
                .map(|_| AtomicBool::new(false))
                .collect(),
        });
        // The threads build their nodes, then wait at the gate: instant zero
        // is fixed once every thread is ready, so that building a large
        // system's nodes is not taken for lateness.
        let (ready, readies) = mpsc::channel();
        let handles = spawn(works, &shared, &stop, memory_locked.as_ref(), &ready)?;
        drop(ready);
        if readies.iter().take(handles.len()).count() < handles.len() {
            // A thread ended before it was ready: it panicked building its
            // nodes.
            stop.store(true, Ordering::Relaxed);
            let name = abandon(&shared, handles).unwrap_or_else(|| "(unknown)".to_owned());
            if memory_locked.as_ref().is_some_and(Result::is_ok) {
                clock::unlock_memory();
            }
            return Err(RtError::Panicked(name));
        }
        let (clock, joining) =
            match start_clock(sync, &inboxes, memory_locked.as_ref(), config.lead) {
                Ok(started) => started,
                Err(e) => {
                    // `start_clock` unlocked the memory.
                    stop.store(true, Ordering::Relaxed);
                    let _ = abandon(&shared, handles);
                    return Err(e);
                }
            };
        // Decided once for every thread: a thread woken late on a loaded
        // machine still runs from instant zero (its deadlines catch up); a
        // process joining a running deployment begins now.
        let first = if joining { clock.now() } else { 0 };
        shared.gate.open(clock, first);
        Ok(Running {
            info,
            handles,
            stop: StopHandle(stop),
            shared,
            stats,
            dropped,
            memory_locked,
            clock,
            started: std::time::Instant::now(),
            lead: config.lead,
            _subscriptions: subscriptions,
            _transport: transport,
        })
    }
}

/// The cores a pool deals its nodes over: `cores`, or with `0` as many as
/// the process may use.
fn pool_cores(cores: u16) -> usize {
    match cores {
        0 => std::thread::available_parallelism().map_or(1, std::num::NonZero::get),
        n => usize::from(n),
    }
}

/// Per node: whether this process runs it (every node, without a placement).
fn placed_here(info: &SystemInfo, placement: Option<&Placement>, n: usize) -> Vec<bool> {
    match placement {
        None => vec![true; n],
        Some(p) => info
            .nodes
            .iter()
            .map(|node| p.here.contains(&node.name))
            .collect(),
    }
}

/// The threads of a run and which node each runs.
struct Threads {
    /// Per node: its thread, or `usize::MAX` for a node not run here.
    thread_of: Vec<usize>,
    /// Per thread: its name (a subsystem's, a driver's, `world`, or a pool
    /// worker's `core<k>@<period>`).
    names: Vec<String>,
    /// Per thread: the pool's core whose nodes it runs (`None`: not a pool
    /// worker).
    cores: Vec<Option<usize>>,
    /// Per thread: whether it is pinned to its core.
    pins: Vec<bool>,
    /// The thread of the drivers that share the environment, if they do.
    world: Option<usize>,
}

impl Threads {
    /// The drivers together if they share an environment; the other nodes as
    /// `threading` says: a pool worker per core and period, or one thread
    /// each.
    fn assign(info: &SystemInfo, here: &[bool], has_env: bool, threading: Threading) -> Threads {
        let mut threads = Threads {
            thread_of: vec![usize::MAX; here.len()],
            names: Vec::new(),
            cores: Vec::new(),
            pins: Vec::new(),
            world: None,
        };
        let pool = match threading {
            Threading::Pool { cores, pin } => Some((pool_cores(cores), pin)),
            Threading::PerSubsystem => None,
        };
        // Pool: each agent's core, dealt in declaration order to the core
        // with the fewest nodes so far (an agent's nodes stay together, so
        // that the links within it stay on one core); per (core, period),
        // the worker's thread.
        let mut load: Vec<usize> = pool.map_or(Vec::new(), |(cores, _)| vec![0; cores]);
        let mut agent_core: BTreeMap<&str, usize> = BTreeMap::new();
        let mut workers: BTreeMap<(usize, u64), usize> = BTreeMap::new();
        for (i, node) in info.nodes.iter().enumerate() {
            if !here[i] {
                continue;
            }
            let is_driver = matches!(node.kind, NodeKind::RealEffector | NodeKind::RealReceptor);
            threads.thread_of[i] = if is_driver && has_env {
                match threads.world {
                    Some(w) => w,
                    None => {
                        let w = threads.push("world".to_owned(), None, false);
                        threads.world = Some(w);
                        w
                    }
                }
            } else if let Some((_, pin)) = pool {
                let k = *agent_core
                    .entry(node.agent.as_str())
                    .or_insert_with(|| (0..load.len()).min_by_key(|&c| (load[c], c)).unwrap_or(0));
                if let Some(l) = load.get_mut(k) {
                    *l += 1;
                }
                let period = node.period.as_nanos();
                match workers.get(&(k, period)) {
                    Some(&w) => w,
                    None => {
                        let name = format!("core{k}@{}", node.period);
                        let w = threads.push(name, Some(k), pin);
                        workers.insert((k, period), w);
                        w
                    }
                }
            } else {
                threads.push(node.name.clone(), None, false)
            };
        }
        threads.name_lone_workers(info);
        threads
    }

    /// A new thread; its index.
    fn push(&mut self, name: String, core: Option<usize>, pin: bool) -> usize {
        self.names.push(name);
        self.cores.push(core);
        self.pins.push(pin);
        self.names.len() - 1
    }

    /// A pool worker that runs one node is named after it, as its own thread
    /// would be.
    fn name_lone_workers(&mut self, info: &SystemInfo) {
        let mut count = vec![0usize; self.names.len()];
        let mut lone = vec![usize::MAX; self.names.len()];
        for (i, &th) in self.thread_of.iter().enumerate() {
            if let Some(c) = count.get_mut(th) {
                *c += 1;
                lone[th] = i;
            }
        }
        for (th, name) in self.names.iter_mut().enumerate() {
            if count[th] == 1 && Some(th) != self.world {
                *name = info.nodes[lone[th]].name.clone();
            }
        }
    }

    /// Per thread, the FIFO priority to ask for below `top`: rate-monotonic,
    /// the shortest period of a thread ranks it among the periods of the
    /// whole system, not only of the nodes run here, so that the processes of
    /// a deployment sharing a host rank their threads alike (a process's own
    /// ranking would put its slowest thread at `top` beside another's
    /// fastest).
    fn priorities(&self, info: &SystemInfo, top: Option<u8>) -> Vec<Option<u8>> {
        let mut shortest = vec![u64::MAX; self.names.len()];
        for (i, node) in info.nodes.iter().enumerate() {
            if let Some(s) = shortest.get_mut(self.thread_of[i]) {
                *s = (*s).min(node.period.as_nanos());
            }
        }
        let mut distinct: Vec<u64> = info.nodes.iter().map(|n| n.period.as_nanos()).collect();
        distinct.sort_unstable();
        distinct.dedup();
        (0..self.names.len())
            .map(|th| {
                top.map(|top| {
                    let rank = distinct
                        .iter()
                        .position(|p| *p == shortest[th])
                        .unwrap_or(0);
                    let rank = u8::try_from(rank).unwrap_or(u8::MAX);
                    top.saturating_sub(rank).max(1)
                })
            })
            .collect()
    }

    /// Per thread, a work holding its link halves and priority, nothing else yet.
    /// A pool worker pinned to core `k` is pinned to the `k`-th CPU of
    /// `cpus` (the process's, modulo their number; CPU `k` if unknown).
    fn empty_works(
        &self,
        txs: Vec<ThreadHalves>,
        rxs: Vec<ThreadHalves>,
        priorities: Vec<Option<u8>>,
        cpus: &[usize],
    ) -> Vec<worker::Work> {
        self.names
            .iter()
            .zip(self.cores.iter().zip(&self.pins))
            .zip(txs)
            .zip(rxs)
            .zip(priorities)
            .map(
                |((((name, (&core, &pin)), txs), rxs), priority)| worker::Work {
                    name: name.clone(),
                    nodes: Vec::new(),
                    seeds: Vec::new(),
                    outs: Vec::new(),
                    ins: Vec::new(),
                    txs,
                    rxs,
                    environment: None,
                    priority,
                    pin: core.filter(|_| pin).map(|k| match cpus.len() {
                        0 => k,
                        n => cpus[k % n],
                    }),
                    core,
                    probes: Vec::new(),
                    observer: None,
                },
            )
            .collect()
    }
}

/// The links of a run: the halves each thread is given, and what the run keeps.
struct Links {
    /// Per thread, the sending halves of its links.
    txs: Vec<ThreadHalves>,
    /// Per thread, the receiving halves of its links.
    rxs: Vec<ThreadHalves>,
    /// Per link, its counters.
    stats: Vec<Arc<SharedStats>>,
    /// The transport's subscriptions, kept alive while the run goes on.
    subscriptions: Vec<Box<dyn Any + Send>>,
    /// The inboxes of links from other processes, started once the clock is agreed.
    inboxes: Vec<Arc<remote::Inbox>>,
}

/// Every link, made between threads where both ends run here (or without a
/// placement), over the transport where one end runs elsewhere, and not at all
/// (counters only) where neither does.
fn make_links(
    info: &SystemInfo,
    channels: &[Box<dyn ChannelPlan>],
    here: &[bool],
    threads: &Threads,
    epoch: u64,
    mut transport: Option<&mut Away>,
) -> Result<Links, RtError> {
    let threads_n = threads.names.len();
    let mut maker = LinkMaker {
        info,
        here,
        thread_of: &threads.thread_of,
        epoch,
        published: HashSet::new(),
        links: Links {
            txs: (0..threads_n).map(|_| empty(channels.len())).collect(),
            rxs: (0..threads_n).map(|_| empty(channels.len())).collect(),
            stats: Vec::with_capacity(channels.len()),
            subscriptions: Vec::new(),
            inboxes: Vec::new(),
        },
    };
    for (l, plan) in channels.iter().enumerate() {
        let link = &info.links[l];
        match (here[link.from], here[link.to], transport.as_deref_mut()) {
            (true, true, _) | (_, _, None) => maker.between_threads(l, plan.as_ref()),
            (true, false, Some((prefix, transport))) => {
                maker.sending_away(l, plan.as_ref(), prefix, transport.as_mut())?;
            }
            (false, true, Some((prefix, transport))) => {
                maker.receiving_from_away(l, plan.as_ref(), prefix, transport.as_mut())?;
            }
            (false, false, Some(_)) => maker.links.stats.push(Arc::new(SharedStats::default())),
        }
    }
    Ok(maker.links)
}

/// The receiving halves of the fed links with their feeds beside them
/// ([`RealTime::feed`]); a fed link whose receiver does not run here is an
/// error.
fn feed_links(
    info: &SystemInfo,
    channels: &[Box<dyn ChannelPlan>],
    here: &[bool],
    threads: &Threads,
    mut rxs: Vec<ThreadHalves>,
    feeds: Vec<(usize, Arc<remote::Inbox>)>,
) -> Result<Vec<ThreadHalves>, RtError> {
    for (l, inbox) in feeds {
        let (Some(link), Some(plan)) = (info.links.get(l), channels.get(l)) else {
            continue;
        };
        let refuse = |reason: String| RtError::Feed {
            link: link.name.clone(),
            reason,
        };
        if !here.get(link.to).copied().unwrap_or(false) {
            return Err(refuse(format!(
                "its receiver `{}` does not run in this process",
                info.nodes[link.to].name
            )));
        }
        let bug = || refuse("its receiving half was not made (a bug)".into());
        let slot = rxs
            .get_mut(threads.thread_of[link.to])
            .and_then(|halves| halves.get_mut(l))
            .ok_or_else(bug)?;
        let fed = slot.take().and_then(|rx| plan.fed(rx, inbox));
        *slot = Some(fed.ok_or_else(bug)?);
    }
    Ok(rxs)
}

fn empty(n: usize) -> ThreadHalves {
    (0..n).map(|_| None).collect()
}

/// Makes the links one by one (see [`make_links`]).
struct LinkMaker<'a> {
    info: &'a SystemInfo,
    /// Per node: whether it runs here.
    here: &'a [bool],
    thread_of: &'a [usize],
    /// The epoch this process's values carry on the links that leave it.
    epoch: u64,
    /// The keys that have a publisher already: one per output buffer (key),
    /// made by its first remote link.
    published: HashSet<String>,
    links: Links,
}

impl LinkMaker<'_> {
    /// Link `l` between two threads of this process.
    fn between_threads(&mut self, l: usize, plan: &dyn ChannelPlan) {
        let link = &self.info.links[l];
        let (tx, rx, s) = plan.threaded();
        self.links.txs[self.thread_of[link.from]][l] = Some(tx);
        self.links.rxs[self.thread_of[link.to]][l] = Some(rx);
        self.links.stats.push(s);
    }

    /// Link `l` from a node here to a node of another process: its sending
    /// half publishes on the link's key (the policy of a key with a queue link
    /// among its links is the queue's).
    fn sending_away(
        &mut self,
        l: usize,
        plan: &dyn ChannelPlan,
        prefix: &str,
        transport: &mut dyn Transport,
    ) -> Result<(), RtError> {
        let info = self.info;
        let link = &info.links[l];
        let key = remote::link_key(prefix, info, link);
        let s = Arc::new(SharedStats::default());
        let mut grid = None;
        let publisher = if self.published.insert(key.clone()) {
            let policy = info
                .links
                .iter()
                .filter(|k| k.from == link.from && k.from_port == link.from_port)
                .map(|k| k.policy)
                .find(|p| matches!(p, crate::Policy::Queue { .. }))
                .unwrap_or(link.policy);
            let made = transport
                .publisher(&key, policy)
                .map_err(|error| RtError::Transport {
                    link: link.name.clone(),
                    key: key.clone(),
                    error,
                })?;
            grid = self.read_grid(l, policy);
            Some(made)
        } else {
            None
        };
        let tx = remote::RemoteTx::new(
            publisher,
            key.into(),
            plan.fingerprint(),
            self.epoch,
            s.clone(),
        )
        .at_reads(grid);
        self.links.txs[self.thread_of[link.from]][l] = Some(plan.remote_tx(tx));
        self.links.stats.push(s);
        Ok(())
    }

    /// When the readers in other processes of link `l`'s output read, for a
    /// sample key: its publisher sends only the values they see
    /// ([`ReadGrid`]); none for a queue (every value is read).
    fn read_grid(&self, l: usize, policy: crate::Policy) -> Option<ReadGrid> {
        let info = self.info;
        let link = &info.links[l];
        if !matches!(policy, crate::Policy::Sample) {
            return None;
        }
        let readers = info
            .links
            .iter()
            .filter(|k| k.from == link.from && k.from_port == link.from_port)
            .filter(|k| !self.here.get(k.to).copied().unwrap_or(false))
            .map(|k| info.nodes[k.to].period);
        ReadGrid::new(info.nodes[link.from].period, readers)
    }

    /// Link `l` from a node of another process to a node here: its receiving
    /// half's inbox subscribes to the link's key.
    fn receiving_from_away(
        &mut self,
        l: usize,
        plan: &dyn ChannelPlan,
        prefix: &str,
        transport: &mut dyn Transport,
    ) -> Result<(), RtError> {
        let link = &self.info.links[l];
        let key = remote::link_key(prefix, self.info, link);
        let (rx, inbox, s) = plan.remote_rx(key.as_str().into());
        // Whether this process joins late is known at `sync`.
        inbox.defer_start();
        self.links.inboxes.push(inbox.clone());
        let guard = transport
            .subscribe(&key, inbox)
            .map_err(|error| RtError::Transport {
                link: link.name.clone(),
                key: key.clone(),
                error,
            })?;
        self.links.subscriptions.push(guard);
        self.links.rxs[self.thread_of[link.to]][l] = Some(rx);
        self.links.stats.push(s);
        Ok(())
    }
}

/// Each node run here, with its ports, to its thread's work, in stepping
/// order: declaration order, real receptors last.
fn give_nodes(
    works: &mut [worker::Work],
    threads: &Threads,
    info: &SystemInfo,
    nodes: Vec<Box<dyn NodeSeed>>,
    outs: Vec<(usize, Box<dyn OutPlan>)>,
    ins: Vec<(usize, Box<dyn InPlan>)>,
) {
    let thread_of = &threads.thread_of;
    let n = nodes.len();
    let mut seeds: Vec<Option<Box<dyn NodeSeed>>> = nodes.into_iter().map(Some).collect();
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
}

/// Each thread's observer, made in thread order (if the run is observed).
fn give_observers(works: &mut [worker::Work], mut observers: Option<MakeObserver>) {
    if let Some(make) = observers.as_mut() {
        for w in works {
            w.observer = Some(make(&w.name, &w.nodes));
        }
    }
}

/// Each probe to the thread of what it watches (the environment's: the
/// world's); a probe of something not run here is dropped.
fn give_probes(works: &mut [worker::Work], threads: &Threads, probes: Vec<(Target, ProbeFn)>) {
    for (target, probe) in probes {
        let th = match target {
            Target::Node(i) => threads.thread_of.get(i).copied().unwrap_or(usize::MAX),
            Target::Environment => threads.world.unwrap_or(usize::MAX),
        };
        if let Some(w) = works.get_mut(th) {
            w.probes.push((target, probe));
        }
    }
}

/// The run's clock and whether this process joins a deployment whose instant
/// zero is past: instant zero from `sync` if given, else `lead` from now; the
/// inboxes start knowing which. A failed `sync` unlocks the memory it locked.
fn start_clock(
    sync: Option<&mut dyn FnMut() -> Option<Result<SystemTime, RtError>>>,
    inboxes: &[Arc<remote::Inbox>],
    memory_locked: Option<&Result<(), Refused>>,
    lead: Duration,
) -> Result<(clock::Clock, bool), RtError> {
    match sync.and_then(|f| f()) {
        Some(Ok(at)) => {
            // Instant zero in the past: this process joins a running
            // deployment (it was restarted). Across hosts this reads
            // another host's clock: they must agree well within the lead
            // the first process gives the others (a second in Rex).
            let late = at <= SystemTime::now();
            for inbox in inboxes {
                inbox.start(late);
            }
            Ok((clock::Clock::at_wall(at), late))
        }
        Some(Err(e)) => {
            if memory_locked.is_some_and(Result::is_ok) {
                clock::unlock_memory();
            }
            Err(e)
        }
        None => {
            for inbox in inboxes {
                inbox.start(false);
            }
            Ok((clock::Clock::starting_in(lead), false))
        }
    }
}

/// One thread per work, each told to say on `ready` when it has built its
/// nodes; if one cannot be spawned, the run stops, the threads spawned are
/// let through the gate closed and joined, and memory is unlocked before the
/// error is returned.
fn spawn(
    works: Vec<worker::Work>,
    shared: &Arc<worker::Shared>,
    stop: &AtomicBool,
    memory_locked: Option<&Result<(), Refused>>,
    ready: &mpsc::Sender<()>,
) -> Result<Vec<(String, JoinHandle<worker::Done>)>, RtError> {
    let mut handles = Vec::with_capacity(works.len());
    for work in works {
        let name = work.name.clone();
        let given = shared.clone();
        let ready = ready.clone();
        let spawned = std::thread::Builder::new()
            .name(format!("rt-{name}"))
            .spawn(move || worker::run(work, &given, ready));
        match spawned {
            Ok(h) => handles.push((name, h)),
            Err(source) => {
                stop.store(true, Ordering::Relaxed);
                let _ = abandon(shared, handles);
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
    Ok(handles)
}

/// Close the gate on the threads spawned (they end without running an
/// instant, handing their nodes back) and join them: the name of one that
/// panicked, if one did.
fn abandon(
    shared: &worker::Shared,
    handles: Vec<(String, JoinHandle<worker::Done>)>,
) -> Option<String> {
    shared.gate.close();
    let mut panicked = None;
    for (name, h) in handles {
        if h.join().is_err() {
            panicked.get_or_insert(name);
        }
    }
    panicked
}
