//! One thread of the real-time executor: its nodes, built on the thread with the
//! ports of links between threads, run on absolute deadlines.
//!
//! Within a thread an instant runs as in the deterministic executor: the nodes due
//! read, then step in order (real receptors last), each sending right after its
//! step. Between threads, instants line up on the common clock; which thread
//! reaches an instant first is up to the scheduler, as on a real robot.

use std::any::Any;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};

use crate::error::ExecError;
use crate::executor::{ExecConfig, OnError, halts_under_continue};
use crate::link::{InPlan, LinkCx, OutPlan, ThreadHalves};
use crate::node::{InProcessNode, NodeSeed, NodeStep};
use crate::time::Time;
use crate::trace::{Observer, SystemInfo};

use crate::probe::{ProbeFn, Target};

use super::clock::{self, Clock};
use super::timing::{NodeTiming, Recorder};

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
    /// Called on this thread after each activation of the node they watch
    /// (the environment's: after each instant).
    pub(crate) probes: Vec<(Target, ProbeFn)>,
    /// The thread's observer ([`RealTime::observe`](super::RealTime::observe)).
    pub(crate) observer: Option<Box<dyn Observer>>,
}

/// What the threads share.
pub(crate) struct Shared {
    pub(crate) info: SystemInfo,
    pub(crate) clock: Clock,
    pub(crate) stop: Arc<AtomicBool>,
    /// The first instant the threads run (ns since the clock's origin): zero,
    /// or for a process joining a running deployment the time it joined.
    pub(crate) first: u64,
    /// Instants at or after this end the run (ns since the clock's origin).
    pub(crate) end: u64,
    pub(crate) config: ExecConfig,
    pub(crate) errors: AtomicU64,
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
    pub(crate) priority: Option<(u8, Result<(), String>)>,
    /// The virtual time of the last instant executed.
    pub(crate) last: Time,
}

pub(crate) fn run(work: Work, shared: &Shared) -> Done {
    let Work {
        name,
        nodes: ids,
        seeds,
        outs,
        ins,
        mut txs,
        mut rxs,
        mut environment,
        priority,
        mut probes,
        observer,
    } = work;
    let mut observer = observer.filter(|o| o.enabled());
    if let Some(o) = observer.as_deref_mut() {
        o.start(&shared.info);
    }
    let priority = priority.map(|p| (p, clock::set_fifo_priority(p)));
    let info = &shared.info;
    let position = |global: usize| ids.iter().position(|&g| g == global);
    let mut nodes: Vec<Box<dyn InProcessNode>> = seeds
        .into_iter()
        .map(|s| s.into_in_process(shared.config.audit))
        .collect();
    // Handles and payload types were checked when the links were declared, and
    // the halves were made from the same plans: installation cannot fail.
    for (global, plan) in &outs {
        let installed = position(*global).is_some_and(|k| {
            plan.threaded(&mut txs)
                .is_some_and(|port| nodes[k].install_out(port))
        });
        debug_assert!(installed, "output port type checked at connect()");
    }
    for (global, plan) in &ins {
        let installed = position(*global).is_some_and(|k| {
            plan.threaded(&mut rxs)
                .is_some_and(|port| nodes[k].install_in(port))
        });
        debug_assert!(installed, "input port type checked at connect()");
    }
    let periods: Vec<u64> = ids
        .iter()
        .map(|&g| info.nodes[g].period.as_nanos())
        .collect();
    // A process joining a running deployment begins at each node's next
    // instant; otherwise every node begins at instant zero, however late this
    // thread was spawned.
    let mut next: Vec<u64> = periods
        .iter()
        .map(|&p| shared.first.div_ceil(p.max(1)).saturating_mul(p))
        .collect();
    let mut recorders: Vec<Recorder> = ids.iter().map(|_| Recorder::new()).collect();
    let mut errors = Vec::new();
    let mut last = Time::ZERO;
    let clock = shared.clock;
    loop {
        if shared.stop.load(Ordering::Relaxed) {
            break;
        }
        let Some(t) = next.iter().copied().min().filter(|t| *t != u64::MAX) else {
            break;
        };
        if t >= shared.end {
            break;
        }
        clock.sleep_until(t);
        let woke = clock.now();
        let jitter = woke.saturating_sub(t);
        let now = Time::from_nanos(t);
        last = now;
        let mut cx = LinkCx {
            time: now,
            observer: observer.as_deref_mut().map(|o| o as &mut dyn Observer),
            links: &info.links,
            environment: None,
        };
        let mut unread = Vec::new();
        for (k, (node, due)) in nodes.iter_mut().zip(&next).enumerate() {
            if *due == t
                && let Err(e) = node.read(&mut cx)
            {
                unread.push((k, e));
            }
        }
        // A link between processes that failed to deliver: the error goes
        // through the policy (under `Continue` the node still runs, its buffer
        // aged; under `Stop` the run ends).
        for (k, e) in unread {
            shared.errors.fetch_add(1, Ordering::Relaxed);
            let e = ExecError::Link(e);
            if let Some(o) = observer.as_deref_mut() {
                o.error(now, &e);
            }
            match shared.config.on_error {
                OnError::Stop => {
                    shared.stop.store(true, Ordering::Relaxed);
                    errors.push(e);
                    next[k] = u64::MAX;
                }
                OnError::Continue => {
                    if errors.len() < shared.config.max_recorded_errors {
                        errors.push(e);
                    }
                }
            }
        }
        let mut started = clock.now();
        for k in 0..nodes.len() {
            if next[k] != t {
                continue;
            }
            let mut cx = LinkCx {
                time: now,
                observer: observer.as_deref_mut().map(|o| o as &mut dyn Observer),
                links: &info.links,
                environment: environment.as_deref_mut(),
            };
            let result = nodes[k].step(now, ids[k], &mut cx);
            let ended = clock.now();
            recorders[k].record(jitter, ended.saturating_sub(started));
            started = ended;
            match result {
                Ok(NodeStep::Ran) => next[k] = t.saturating_add(periods[k]),
                Ok(NodeStep::Halted) => next[k] = u64::MAX,
                Err(e) => {
                    shared.errors.fetch_add(1, Ordering::Relaxed);
                    if let Some(o) = observer.as_deref_mut() {
                        o.error(now, &e);
                    }
                    match shared.config.on_error {
                        OnError::Stop => {
                            shared.stop.store(true, Ordering::Relaxed);
                            errors.push(*e);
                            next[k] = u64::MAX;
                        }
                        OnError::Continue => {
                            if halts_under_continue(&e) {
                                nodes[k].halt();
                                next[k] = u64::MAX;
                            } else {
                                next[k] = t.saturating_add(periods[k]);
                            }
                            if errors.len() < shared.config.max_recorded_errors {
                                errors.push(*e);
                            }
                        }
                    }
                }
            }
            if next[k] != u64::MAX && ended > next[k] {
                recorders[k].overruns += 1;
            }
            if nodes[k].is_halted()
                && let Some(h) = shared.halted.get(ids[k])
            {
                h.store(true, Ordering::Relaxed);
            }
            for (target, f) in &mut probes {
                if matches!(target, Target::Node(g) if *g == ids[k]) {
                    f(now, nodes[k].core());
                }
            }
        }
        if let Some(env) = environment.as_deref() {
            for (target, f) in &mut probes {
                if matches!(target, Target::Environment) {
                    f(now, env);
                }
            }
        }
    }
    let timings = ids
        .iter()
        .zip(&recorders)
        .map(|(&g, r)| {
            let n = &info.nodes[g];
            (g, r.finish(n.name.clone(), name.clone(), n.period))
        })
        .collect();
    let cores = ids
        .iter()
        .copied()
        .zip(nodes)
        .map(|(g, n)| (g, n.into_core()))
        .collect();
    Done {
        name,
        cores,
        environment,
        timings,
        errors,
        priority,
        last,
    }
}
