//! Probes: functions that watch nodes as they run, the same in both executors.
//!
//! A probe is called right after each activation of the node it watches (or,
//! for the environment, after each instant of the drivers that share it), with
//! a read-only view of the node; what it returns is sent on a bounded channel
//! to whoever consumes the run. The deterministic [`Executor`] calls probes on
//! its own thread within [`Executor::step`]; the [`RealTime`] executor on the
//! node's thread. A result that finds the channel full is counted
//! ([`Probes::dropped`]), never waited for, so a probe never blocks a node.
//!
//! ```
//! use agent_core::probe::Probes;
//! # use agent_core::prelude::*;
//! # fn watch(h: &SubsystemHandle<impl Subsystem>) {
//! let (mut probes, seen) = Probes::<(Time, bool)>::new(1024);
//! probes.subsystem(h, |p| Some((p.time, p.halted)));
//! // executor.watch(probes); ... for (t, halted) in seen.try_iter() { ... }
//! # let _ = seen;
//! # }
//! ```
//!
//! [`Executor`]: crate::Executor
//! [`Executor::step`]: crate::Executor::step
//! [`RealTime`]: crate::RealTime

use std::any::Any;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};

use crate::node::{DriverCore, subsystem_core};
use crate::subsystem::{Driver, Subsystem};
use crate::system::{DriverHandle, SubsystemHandle};
use crate::time::Time;

/// A subsystem as a probe sees it, right after an activation.
#[derive(Debug)]
pub struct Probed<'a, S: Subsystem> {
    /// The activation's instant.
    pub time: Time,
    /// Its memory after the activation.
    pub memory: &'a S::Memory,
    /// Its inputs as the activation read them.
    pub input: &'a S::Input,
    /// The behaviour it is in (the one that ran, or the next one if it ended).
    pub behaviour: &'a str,
    /// Whether it reached a final behaviour.
    pub halted: bool,
}

/// What a probe calls: the instant and the node's core (or the environment),
/// erased.
pub(crate) type ProbeFn = Box<dyn FnMut(Time, &dyn Any) + Send>;

/// Where a probe looks.
pub(crate) enum Target {
    /// A node, by index.
    Node(usize),
    /// The system's environment.
    Environment,
}

/// A set of probes whose results are of one type `M`, all sent on one
/// channel (see the [module](self)). Give it to an executor with
/// `Executor::watch` or `RealTime::watch`.
pub struct Probes<M> {
    pub(crate) entries: Vec<(Target, ProbeFn)>,
    tx: SyncSender<M>,
    dropped: Arc<AtomicU64>,
}

impl<M> std::fmt::Debug for Probes<M> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Probes")
            .field("probes", &self.entries.len())
            .field("dropped", &self.dropped())
            .finish()
    }
}

impl<M: Send + 'static> Probes<M> {
    /// An empty set whose channel holds `capacity` results; the receiver of
    /// its results.
    pub fn new(capacity: usize) -> (Probes<M>, Receiver<M>) {
        let (tx, rx) = sync_channel(capacity.max(1));
        (
            Probes {
                entries: Vec::new(),
                tx,
                dropped: Arc::new(AtomicU64::new(0)),
            },
            rx,
        )
    }

    /// Watch subsystem `h`: after each of its activations `f` sees it
    /// ([`Probed`]: the instant, its memory, its inputs, its behaviour).
    pub fn subsystem<S, F>(&mut self, h: &SubsystemHandle<S>, mut f: F) -> &mut Self
    where
        S: Subsystem,
        F: FnMut(&Probed<'_, S>) -> Option<M> + Send + 'static,
    {
        let (tx, dropped) = (self.tx.clone(), self.dropped.clone());
        self.entries.push((
            Target::Node(h.id().index()),
            Box::new(move |time, any: &dyn Any| {
                if let Some(core) = subsystem_core::<S>(any)
                    && let Some(m) = f(&Probed {
                        time,
                        memory: &core.memory,
                        input: &core.input,
                        behaviour: core.fsm.behaviour_name(core.state.behaviour()),
                        halted: core.state.is_halted(),
                    })
                {
                    send_or_count(&tx, m, &dropped);
                }
            }),
        ));
        self
    }

    /// Watch driver `h`: after each of its steps `f` sees the instant and the
    /// device.
    pub fn driver<D, F>(&mut self, h: &DriverHandle<D>, mut f: F) -> &mut Self
    where
        D: Driver,
        F: FnMut(Time, &D) -> Option<M> + Send + 'static,
    {
        let (tx, dropped) = (self.tx.clone(), self.dropped.clone());
        self.entries.push((
            Target::Node(h.id().index()),
            Box::new(move |time, any: &dyn Any| {
                if let Some(d) = any.downcast_ref::<DriverCore<D>>()
                    && let Some(m) = f(time, &d.driver)
                {
                    send_or_count(&tx, m, &dropped);
                }
            }),
        ));
        self
    }

    /// Watch the environment (of type `W`): after each instant at which the
    /// drivers that share it ran, `f` sees the instant and the environment.
    pub fn environment<W, F>(&mut self, mut f: F) -> &mut Self
    where
        W: Any,
        F: FnMut(Time, &W) -> Option<M> + Send + 'static,
    {
        let (tx, dropped) = (self.tx.clone(), self.dropped.clone());
        self.entries.push((
            Target::Environment,
            Box::new(move |t, any: &dyn Any| {
                if let Some(w) = any.downcast_ref::<W>()
                    && let Some(m) = f(t, w)
                {
                    send_or_count(&tx, m, &dropped);
                }
            }),
        ));
        self
    }
}

impl<M> Probes<M> {
    /// How many probes the set holds.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// Whether it holds none.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// Results that found the channel full so far.
    pub fn dropped(&self) -> u64 {
        self.dropped.load(Ordering::Relaxed)
    }

    /// The counter of [`Probes::dropped`], to read after the set was given away.
    pub fn dropped_counter(&self) -> Arc<AtomicU64> {
        self.dropped.clone()
    }
}

pub(crate) fn send_or_count<M>(tx: &SyncSender<M>, m: M, dropped: &AtomicU64) {
    if let Err(TrySendError::Full(_)) = tx.try_send(m) {
        dropped.fetch_add(1, Ordering::Relaxed);
    }
}
