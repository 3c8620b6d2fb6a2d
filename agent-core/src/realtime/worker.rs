//! One thread of the real-time executor: its nodes, built on the thread with the
//! ports of links between threads, run on absolute deadlines.
//!
//! Within a thread an instant runs as in the deterministic executor: the nodes due
//! read, then step in order (real receptors last), each sending right after its
//! step. Between threads, instants line up on the common clock; which thread
//! reaches an instant first is up to the scheduler, as on a real robot.

use std::any::Any;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::mpsc::Sender;
use std::sync::{Arc, Condvar, Mutex, PoisonError};

use crate::error::{ExecError, LinkError};
use crate::executor::{ExecConfig, OnError, halts_under_continue};
use crate::link::{InPlan, LinkCx, OutPlan, ThreadHalves, Wants};
use crate::node::{InProcessNode, NodeSeed, NodeStep};
use crate::time::Time;
use crate::trace::{Observer, SystemInfo};

use crate::probe::{ProbeFn, Target};

use super::Refused;
use super::clock::{self, Clock};
use super::timing::{NodeTiming, Recorder, Wakes};

/// What a thread is given.
pub(crate) struct Work {
    pub(crate) name: String,
    /// Global node indices, in stepping order (real receptors last).
    pub(crate) nodes: Vec<usize>,
    pub(crate) seeds: Vec<Box<dyn NodeSeed>>,
    /// (global node index, plan).
    pub(crate) outs: Vec<(usize, Box<dyn OutPlan>)>,
    pub(crate) ins: Vec<(usize, Box<dyn InPlan>)>,
    pub(crate) txs: ThreadHalves,
    pub(crate) rxs: ThreadHalves,
    pub(crate) environment: Option<Box<dyn Any + Send>>,
    pub(crate) priority: Option<u8>,
    /// The CPU to pin the thread to, if any.
    pub(crate) pin: Option<usize>,
    /// The pool's core whose nodes this worker runs, if it is a pool worker.
    pub(crate) core: Option<usize>,
    /// Called on this thread after each activation of the node they watch
    /// (the environment's: after each instant).
    pub(crate) probes: Vec<(Target, ProbeFn)>,
    /// The thread's observer ([`RealTime::observe`](super::RealTime::observe)).
    pub(crate) observer: Option<Box<dyn Observer>>,
}

/// Where the threads wait, their nodes built, for instant zero.
#[derive(Default)]
pub(crate) struct Gate {
    /// `None` while closed and undecided; then the clock and the first
    /// instant the threads run (ns since the clock's origin: zero, or for a
    /// process joining a running deployment the time it joined), or `None`
    /// if the run does not start.
    start: Mutex<Option<Option<(Clock, u64)>>>,
    opened: Condvar,
}

impl Gate {
    /// Let the threads run from `first` on `clock`.
    pub(crate) fn open(&self, clock: Clock, first: u64) {
        self.decide(Some((clock, first)));
    }

    /// The run does not start: the threads end without running an instant.
    pub(crate) fn close(&self) {
        self.decide(None);
    }

    fn decide(&self, start: Option<(Clock, u64)>) {
        let mut decided = self.start.lock().unwrap_or_else(PoisonError::into_inner);
        decided.get_or_insert(start);
        self.opened.notify_all();
    }

    /// Wait for the decision: the clock and the first instant, or `None`.
    fn wait(&self) -> Option<(Clock, u64)> {
        let mut decided = self.start.lock().unwrap_or_else(PoisonError::into_inner);
        loop {
            if let Some(start) = *decided {
                return start;
            }
            decided = self
                .opened
                .wait(decided)
                .unwrap_or_else(PoisonError::into_inner);
        }
    }
}

/// What the threads share.
pub(crate) struct Shared {
    pub(crate) info: SystemInfo,
    /// Instant zero, once every thread is ready.
    pub(crate) gate: Gate,
    pub(crate) stop: Arc<AtomicBool>,
    /// Instants at or after this end the run (ns since the clock's origin).
    pub(crate) end: u64,
    pub(crate) config: ExecConfig,
    pub(crate) errors: AtomicU64,
    /// When the run safe-stopped (ns; `u64::MAX`: it has not): every thread
    /// safe-stops its nodes at its next instant.
    pub(crate) safe_stopped: AtomicU64,
    /// Per node (global index): whether it has halted.
    pub(crate) halted: Vec<AtomicBool>,
}

/// What a thread hands back.
pub(crate) struct Done {
    pub(crate) name: String,
    /// (global node index, core).
    pub(crate) cores: Vec<(usize, Box<dyn Any + Send>)>,
    pub(crate) environment: Option<Box<dyn Any + Send>>,
    pub(crate) timings: Vec<(usize, NodeTiming)>,
    pub(crate) errors: Vec<ExecError>,
    /// The priority asked for and what the OS said.
    pub(crate) priority: Option<(u8, Result<(), Refused>)>,
    /// The CPU asked to be pinned to and what the OS said.
    pub(crate) pinned: Option<(usize, Result<(), Refused>)>,
    /// The pool's core, if a pool worker.
    pub(crate) core: Option<usize>,
    /// The CPU time the thread used.
    pub(crate) cpu_time: Option<std::time::Duration>,
    /// The virtual time of the last instant executed.
    pub(crate) last: Time,
    /// When the run safe-stopped, if it did.
    pub(crate) safe_stopped: Option<Time>,
}

/// Run a thread's work: build its nodes, say so on `ready`, wait at the gate,
/// run their instants until the end, a stop, or every node halted, and hand
/// back what it holds.
pub(crate) fn run(work: Work, shared: &Shared, ready: Sender<()>) -> Done {
    let Work {
        name,
        nodes: ids,
        seeds,
        outs,
        ins,
        mut txs,
        mut rxs,
        environment,
        priority,
        pin,
        core,
        probes,
        observer,
    } = work;
    let pinned = pin.map(|cpu| (cpu, clock::pin_to(cpu)));
    let mut observer = observer.filter(|o| o.enabled());
    if let Some(o) = observer.as_deref_mut() {
        o.start(&shared.info);
    }
    let priority = priority.map(|p| (p, clock::set_fifo_priority(p)));
    let mut nodes: Vec<Box<dyn InProcessNode>> = seeds
        .into_iter()
        .map(|s| s.into_in_process(shared.config.audit))
        .collect();
    install_ports(&ids, &mut nodes, &outs, &ins, &mut txs, &mut rxs);
    let recorders: Vec<Recorder> = ids.iter().map(|_| Recorder::new()).collect();
    // The receiver counts the ready threads; gone, the run is being abandoned.
    let _ = ready.send(());
    drop(ready);
    let start = shared.gate.wait();
    let (clock, first) = start.unwrap_or((Clock::starting_in(std::time::Duration::ZERO), u64::MAX));
    let mut thread = Thread::new(
        shared,
        clock,
        first,
        ids,
        nodes,
        recorders,
        environment,
        observer,
        probes,
    );
    if start.is_some() {
        while let Some(t) = thread.next_instant() {
            thread.run_instant(t);
        }
    }
    let mut done = thread.finish(name, priority, pinned);
    done.core = core;
    done.cpu_time = clock::thread_cpu_time();
    done
}

/// Give each node the thread-link ports of its outputs, then of its inputs.
fn install_ports(
    ids: &[usize],
    nodes: &mut [Box<dyn InProcessNode>],
    outs: &[(usize, Box<dyn OutPlan>)],
    ins: &[(usize, Box<dyn InPlan>)],
    txs: &mut ThreadHalves,
    rxs: &mut ThreadHalves,
) {
    let position = |global: usize| ids.iter().position(|&g| g == global);
    // Handles and payload types were checked when the links were declared, and
    // the halves were made from the same plans: installation cannot fail.
    for (global, plan) in outs {
        let installed = position(*global).is_some_and(|k| {
            plan.threaded(txs)
                .is_some_and(|port| nodes[k].install_out(port))
        });
        debug_assert!(installed, "output port type checked at connect()");
    }
    for (global, plan) in ins {
        let installed = position(*global).is_some_and(|k| {
            plan.threaded(rxs)
                .is_some_and(|port| nodes[k].install_in(port))
        });
        debug_assert!(installed, "input port type checked at connect()");
    }
}

/// A running thread: its nodes (in stepping order), when each runs next, and
/// what it records.
struct Thread<'a> {
    shared: &'a Shared,
    clock: Clock,
    /// Global node indices, in stepping order.
    ids: Vec<usize>,
    nodes: Vec<Box<dyn InProcessNode>>,
    /// Per node: its period (ns).
    periods: Vec<u64>,
    /// Per node: its next instant (ns), `u64::MAX` once it runs no more.
    next: Vec<u64>,
    recorders: Vec<Recorder>,
    wakes: Wakes,
    errors: Vec<ExecError>,
    /// The virtual time of the last instant executed.
    last: Time,
    /// Whether this thread's nodes were safe-stopped.
    safe_stopped: bool,
    environment: Option<Box<dyn Any + Send>>,
    // The observer is dropped before the probes, as it always was.
    observer: Option<Box<dyn Observer>>,
    probes: Vec<(Target, ProbeFn)>,
}

impl<'a> Thread<'a> {
    /// The thread before its first instant: each node due at its first
    /// instant.
    #[allow(
        clippy::too_many_arguments,
        reason = "the thread's parts, each moved in once"
    )]
    fn new(
        shared: &'a Shared,
        clock: Clock,
        first: u64,
        ids: Vec<usize>,
        nodes: Vec<Box<dyn InProcessNode>>,
        recorders: Vec<Recorder>,
        environment: Option<Box<dyn Any + Send>>,
        observer: Option<Box<dyn Observer>>,
        probes: Vec<(Target, ProbeFn)>,
    ) -> Self {
        let periods: Vec<u64> = ids
            .iter()
            .map(|&g| shared.info.nodes[g].period.as_nanos())
            .collect();
        // A process joining a running deployment begins at each node's next
        // instant; otherwise every node begins at instant zero, however late this
        // thread was spawned.
        let next: Vec<u64> = periods
            .iter()
            .map(|&p| first.div_ceil(p.max(1)).saturating_mul(p))
            .collect();
        Thread {
            shared,
            clock,
            ids,
            nodes,
            periods,
            next,
            recorders,
            wakes: Wakes::new(),
            errors: Vec::new(),
            last: Time::ZERO,
            safe_stopped: false,
            environment,
            observer,
            probes,
        }
    }

    /// The next instant to run (ns), or `None` when the run is stopped, every
    /// node has halted, or the next instant is past the end.
    fn next_instant(&self) -> Option<u64> {
        if self.shared.stop.load(Ordering::Relaxed) {
            return None;
        }
        let t = self.next.iter().copied().min().filter(|t| *t != u64::MAX)?;
        (t < self.shared.end).then_some(t)
    }

    /// Run instant `t` at its deadline: the nodes due read, then step in order,
    /// then the environment's probes see it.
    fn run_instant(&mut self, t: u64) {
        let clock = self.clock;
        clock.sleep_until(t);
        let woke = clock.now();
        self.wakes.record(woke.saturating_sub(t));
        let now = Time::from_nanos(t);
        self.last = now;
        if !self.safe_stopped && self.shared.safe_stopped.load(Ordering::Relaxed) != u64::MAX {
            self.safe_stop_nodes();
        }
        let unread = self.read_due(t, now);
        for (k, e) in unread {
            self.link_failed(k, now, e);
        }
        // The instant's reads count in the execution time of its first node
        // (every node due reads before any steps): the work of the instant's
        // nodes, summed, is then all of it, as the timing analysis's WCETs
        // need (the nodes of one worker share a priority and interfere).
        let mut started = woke;
        for k in 0..self.nodes.len() {
            if self.next[k] != t {
                continue;
            }
            started = self.step(k, t, now, started);
        }
        self.probe_environment(now);
    }

    /// Read the inputs of the nodes due at `t`; the nodes whose read failed,
    /// with the error.
    fn read_due(&mut self, t: u64, now: Time) -> Vec<(usize, LinkError)> {
        let mut cx = LinkCx {
            time: now,
            observer: self.observer.as_deref_mut().map(|o| o as &mut dyn Observer),
            wants: &Wants::ALL,
            links: &self.shared.info.links,
            stamps: None,
            environment: None,
        };
        let mut unread = Vec::new();
        for (k, (node, due)) in self.nodes.iter_mut().zip(&self.next).enumerate() {
            if *due == t
                && let Err(e) = node.read(&mut cx)
            {
                unread.push((k, e));
            }
        }
        unread
    }

    /// A link between processes that failed to deliver to node `k`: the error
    /// goes through the policy (under `Continue` the node still runs, its
    /// buffer aged; under `Stop` the run ends).
    fn link_failed(&mut self, k: usize, now: Time, e: LinkError) {
        self.shared.errors.fetch_add(1, Ordering::Relaxed);
        let e = ExecError::Link(e);
        if let Some(o) = self.observer.as_deref_mut() {
            o.error(now, &e);
        }
        match self.shared.config.on_error {
            OnError::Stop => {
                self.shared.stop.store(true, Ordering::Relaxed);
                self.errors.push(e);
                self.next[k] = u64::MAX;
            }
            OnError::Continue | OnError::SafeStop => self.keep(now, e),
        }
    }

    /// Step node `k` at instant `t` (its activation timed from `started`),
    /// schedule its next instant, and let its probes see it; when the step
    /// ended.
    fn step(&mut self, k: usize, t: u64, now: Time, started: u64) -> u64 {
        let shared = self.shared;
        let mut cx = LinkCx {
            time: now,
            observer: self.observer.as_deref_mut().map(|o| o as &mut dyn Observer),
            wants: &Wants::ALL,
            links: &shared.info.links,
            stamps: None,
            environment: self.environment.as_deref_mut(),
        };
        let result = self.nodes[k].step(now, self.ids[k], &mut cx);
        let ended = self.clock.now();
        self.recorders[k].record(ended.saturating_sub(started), ended.saturating_sub(t));
        match result {
            Ok(NodeStep::Ran) => self.next[k] = t.saturating_add(self.periods[k]),
            Ok(NodeStep::Halted) => self.next[k] = u64::MAX,
            Err(e) => self.step_failed(k, t, now, e),
        }
        if self.observer.is_some() {
            self.raised(now);
        }
        if self.next[k] != u64::MAX && ended > self.next[k] {
            self.recorders[k].overruns += 1;
        }
        if self.nodes[k].is_halted()
            && let Some(h) = shared.halted.get(self.ids[k])
        {
            h.store(true, Ordering::Relaxed);
        }
        for (target, f) in &mut self.probes {
            if matches!(target, Target::Node(g) if *g == self.ids[k]) {
                f(now, self.nodes[k].core());
            }
        }
        ended
    }

    /// Node `k` failed at instant `t`: the error goes through the policy
    /// (under `Continue` the node runs on, unless the error halts it).
    fn step_failed(&mut self, k: usize, t: u64, now: Time, e: Box<ExecError>) {
        self.shared.errors.fetch_add(1, Ordering::Relaxed);
        if let Some(o) = self.observer.as_deref_mut() {
            o.error(now, &e);
        }
        match self.shared.config.on_error {
            OnError::Stop => {
                self.shared.stop.store(true, Ordering::Relaxed);
                self.errors.push(*e);
                self.next[k] = u64::MAX;
            }
            OnError::Continue | OnError::SafeStop => {
                if halts_under_continue(&e) {
                    self.nodes[k].halt();
                    self.next[k] = u64::MAX;
                } else {
                    self.next[k] = t.saturating_add(self.periods[k]);
                }
                self.keep(now, *e);
            }
        }
    }

    /// The errors the observer raised after a step (broken contracts), through
    /// the policy: no node's schedule changes unless the run stops or
    /// safe-stops.
    fn raised(&mut self, now: Time) {
        while let Some(e) = self.observer.as_deref_mut().and_then(|o| o.raised()) {
            self.shared.errors.fetch_add(1, Ordering::Relaxed);
            if let Some(o) = self.observer.as_deref_mut() {
                o.error(now, &e);
            }
            if self.shared.config.on_error == OnError::Stop {
                self.shared.stop.store(true, Ordering::Relaxed);
                self.errors.push(e);
            } else {
                self.keep(now, e);
            }
        }
    }

    /// Keep an error (up to the limit); under [`OnError::SafeStop`], safe-stop
    /// the run at its first: this thread's nodes now, the others' at their
    /// next instant.
    fn keep(&mut self, now: Time, e: ExecError) {
        if self.errors.len() < self.shared.config.max_recorded_errors {
            self.errors.push(e);
        }
        if self.shared.config.on_error == OnError::SafeStop && !self.safe_stopped {
            let _ = self.shared.safe_stopped.compare_exchange(
                u64::MAX,
                now.as_nanos(),
                Ordering::Relaxed,
                Ordering::Relaxed,
            );
            self.safe_stop_nodes();
        }
    }

    /// Safe-stop this thread's nodes: subsystems halt, drivers make their
    /// devices safe and run on.
    #[cold]
    fn safe_stop_nodes(&mut self) {
        self.safe_stopped = true;
        for (k, node) in self.nodes.iter_mut().enumerate() {
            node.safe_stop();
            if node.is_halted() {
                self.next[k] = u64::MAX;
                if let Some(h) = self.shared.halted.get(self.ids[k]) {
                    h.store(true, Ordering::Relaxed);
                }
            }
        }
    }

    /// Let the environment's probes see it after the instant `now`.
    fn probe_environment(&mut self, now: Time) {
        if let Some(env) = self.environment.as_deref() {
            for (target, f) in &mut self.probes {
                if matches!(target, Target::Environment) {
                    f(now, env);
                }
            }
        }
    }

    /// What the thread hands back: its nodes' timings and cores, the
    /// environment, the errors recorded.
    fn finish(
        self,
        name: String,
        priority: Option<(u8, Result<(), Refused>)>,
        pinned: Option<(usize, Result<(), Refused>)>,
    ) -> Done {
        let info = &self.shared.info;
        let timings = self
            .ids
            .iter()
            .zip(&self.recorders)
            .map(|(&g, r)| {
                let n = &info.nodes[g];
                (
                    g,
                    r.finish(n.name.clone(), name.clone(), n.period, &self.wakes),
                )
            })
            .collect();
        let cores = self
            .ids
            .iter()
            .copied()
            .zip(self.nodes)
            .map(|(g, n)| (g, n.into_core()))
            .collect();
        Done {
            name,
            cores,
            environment: self.environment,
            timings,
            errors: self.errors,
            priority,
            pinned,
            core: None,
            cpu_time: None,
            last: self.last,
            safe_stopped: match self.shared.safe_stopped.load(Ordering::Relaxed) {
                u64::MAX => None,
                ns => Some(Time::from_nanos(ns)),
            },
        }
    }
}
