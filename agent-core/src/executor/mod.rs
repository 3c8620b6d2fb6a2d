//! The deterministic executor: virtual time, multi-rate, a fixed stepping order.
//!
//! # Semantics
//!
//! Every node (subsystem or driver) has a period and is activated at
//! `0, period, 2·period, …` of virtual time. The executor jumps from one activation
//! instant to the next. It keeps the nodes grouped by period and next instant,
//! so an instant costs the nodes due at it, not all the system's nodes. At an instant `t`, with `D` the nodes due at `t` in
//! declaration order (the order they were added to the [`SystemBuilder`]), the real
//! receptors moved after all the others:
//!
//! 1. every node of `D` **reads** its input buffers from its links (the last line of
//!    Algorithm 1: `y → x`, which ends the wait of the previous action);
//! 2. every node of `D`, in order, **steps**: a subsystem's FSM tests the terminal
//!    condition and selects an arc if the behaviour ends (Algorithms 2 and 3), then
//!    the current behaviour's elementary action computes the transition function;
//!    a driver advances its device;
//! 3. right after its step, the node **sends** the output buffers it wrote into its
//!    links (Algorithm 1's `→`). The wait `i → i + 1` is the time to its next instant.
//!
//! Because all reads of an instant happen before any send of that instant, a value
//! sent at `t` is received at the receiver's first activation strictly after `t`, so
//! the result does not depend on the order within `D` as far as buffers go; that
//! order fixes the order of trace events, and what drivers see of the system's
//! environment ([`SystemBuilder::environment`]): real receptors step last, so they
//! sense what the effectors did in the same instant. Everything is integer arithmetic on nanoseconds, so
//! the same system with the same inputs gives a bit-identical [`Trace`](crate::Trace).
//!
//! [`SystemBuilder`]: crate::SystemBuilder
//! [`SystemBuilder::environment`]: crate::SystemBuilder::environment

use std::any::Any;
use std::time::Duration;

mod build;
mod reach;
mod schedule;

use crate::cache::{Collapse, HugePages};
use crate::error::ExecError;
use crate::kinds::NodeKind;
use crate::link::{Channels, LinkCx, LinkId, LinkStats, Wants};
use crate::node::{DriverCore, InProcessNode, NodeStep, SubsystemCore};
use crate::probe::{ProbeFn, Probes, Target};
use crate::subsystem::{Driver, Subsystem};
use crate::system::{DriverHandle, SubsystemHandle, System};
use crate::time::Time;
use crate::trace::{NoObserver, Observer, SystemInfo};
use build::in_process;
use schedule::Schedule;

/// What the executor does when a node reports an error.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum OnError {
    /// Return the error from the run call; the executor then refuses to go on.
    #[default]
    Stop,
    /// Record the error in the [`RunReport`] (and tell the observer) and go on:
    /// a subsystem whose FSM contract is violated
    /// ([`FsmError::is_contract_violation`](crate::FsmError::is_contract_violation):
    /// no arc, several arcs, a livelock) is halted; a failed action or driver step
    /// sent nothing and is retried at the next period; a value refused by a full queue is
    /// counted in the link's statistics.
    Continue,
    /// As [`OnError::Continue`], and at the first error the run safe-stops: every
    /// subsystem is halted (none acts or sends again) and every driver's
    /// [`Driver::safe_stop`] is called once, before its next step; the drivers
    /// go on stepping, so the world goes on (a real effector holding its safe
    /// state: Rex's platform brakes and holds) until the run ends. In the
    /// real-time executor every thread of the run safe-stops at its next
    /// instant; a deployment's other processes are not told (they see the
    /// values stop, which their own contracts watch).
    SafeStop,
}

/// Under [`OnError::Continue`] (and [`OnError::SafeStop`]), whether an error halts its node (a violated FSM
/// contract) rather than letting it retry at its next period. One rule for both
/// executors.
pub(crate) fn halts_under_continue(e: &ExecError) -> bool {
    matches!(e, ExecError::Fsm { error, .. } if error.is_contract_violation())
}

/// Executor settings.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ExecConfig {
    /// Stop or continue on errors.
    pub on_error: OnError,
    /// With [`OnError::Continue`], how many errors the report keeps (the rest are
    /// counted in [`RunReport::error_count`]).
    pub max_recorded_errors: usize,
    /// Observe every transition function: which inputs it reads and which outputs
    /// it writes, reported part by part to the observer
    /// ([`Observer::audit`]), for checking the code
    /// against a spec's `reads` and `writes`. Off by default. Reads are observed
    /// only with the `audit` feature of agent-core (`embodied`'s `audit`), which
    /// makes input buffers record them; without it they come back empty. An
    /// audited subsystem is a node of its own type, so the unaudited hot path
    /// pays nothing for it.
    pub audit: bool,
    /// The deterministic executor backs the memory of the nodes, their ports
    /// and their channels with huge pages when it is made (on Linux 6.1 and
    /// later: `MADV_COLLAPSE` of each 2 MiB region that holds one; elsewhere
    /// nothing). On by default: in a system of thousands of subsystems an
    /// instant's walks then miss the TLB far less (about 8 % faster an
    /// action at 9,999 subsystems, docs/scaling.md). A small system's memory
    /// is one or two regions, asked for as the executor is made (microseconds);
    /// more are asked for on a thread of the executor's own, so that the build
    /// does not wait for the kernel to copy them (from a few to tens of
    /// milliseconds for 10,000 subsystems' fresh memory, up to about 85 ms
    /// on a loaded host):
    /// the executor steps meanwhile, the same run on either pages, and
    /// [`Executor::wait_for_huge_pages`] waits for the copy; dropping the
    /// executor does too, before its memory is freed. That thread makes the
    /// process one with threads, if it was not (the C library's allocator
    /// then locks its arenas). Off: the pages the allocator gave (no
    /// region's unused pages made resident, at most 2 MiB a region
    /// otherwise). The real-time executor's threads do not ask (measured no
    /// better).
    pub huge_pages: bool,
}

impl Default for ExecConfig {
    fn default() -> Self {
        ExecConfig {
            on_error: OnError::Stop,
            max_recorded_errors: 1000,
            audit: false,
            huge_pages: true,
        }
    }
}

impl ExecConfig {
    /// Settings that continue after errors.
    pub fn continue_on_error() -> Self {
        ExecConfig {
            on_error: OnError::Continue,
            ..Self::default()
        }
    }
}

/// What happened during a run, beyond the buffers.
#[derive(Debug, Default)]
pub struct RunReport {
    /// Errors met under [`OnError::Continue`] (at most `max_recorded_errors`).
    pub errors: Vec<ExecError>,
    /// All errors met, including those not kept.
    pub error_count: u64,
    /// Instants executed.
    pub instants: u64,
    /// When the run safe-stopped ([`OnError::SafeStop`]): the instant of the
    /// error that stopped it.
    pub safe_stopped: Option<Time>,
}

/// Runs a [`System`] in virtual time, deterministically, on the calling thread. See
/// the module docs. (The executor itself is not `Send`: its links share channels
/// without locks. Move the [`System`] to another thread and build the executor there.)
pub struct Executor<O: Observer = NoObserver> {
    /// The huge pages asked for its memory ([`ExecConfig::huge_pages`]).
    /// First, so dropped first: a drop waits for the kernel's copy before
    /// the memory it copies is freed.
    huge_pages: Collapse,
    pub(crate) info: SystemInfo,
    pub(crate) nodes: Vec<Box<dyn InProcessNode>>,
    periods: Vec<u64>,
    /// Whether each node is a driver (a real effector or receptor): whether
    /// an instant at which it runs moves the world, so that an action need
    /// not reach the node's description.
    drives: Vec<bool>,
    /// Each node's next instant (`u64::MAX`: never again), the truth that
    /// `schedule` indexes.
    next: Vec<u64>,
    /// The order of the nodes within an instant (real receptors last): a
    /// node's rank is its position here.
    order: Vec<usize>,
    /// The ranks below this are the components', the others the real
    /// receptors' (each part in declaration order).
    receptors_from: usize,
    /// The nodes by period and next instant, so that an instant visits only
    /// the nodes due.
    schedule: Schedule,
    /// The system's environment, which drivers reach through their context.
    pub(crate) environment: Option<Box<dyn Any + Send>>,
    pub(crate) channels: Channels,
    pub(crate) now: Time,
    config: ExecConfig,
    pub(crate) observer: O,
    /// Per link, the sends and reads the observer needs (asked at the start).
    wants: Wants,
    /// The last sends' instants the observer asked for, if it asked
    /// ([`LinkEvents::stamps`](crate::trace::LinkEvents::stamps)).
    stamps: Option<crate::trace::SendStamps>,
    /// What each node's read and step touch, for the cache ([`crate::cache`]).
    reach: reach::Reach,
    started: bool,
    stopped: bool,
    pub(crate) report: RunReport,
    /// Probes, by node index (`probes`), and of the environment.
    probes: Vec<Vec<ProbeFn>>,
    environment_probes: Vec<ProbeFn>,
    /// The counters of the probe sets' full channels.
    pub(crate) probes_dropped: Vec<std::sync::Arc<std::sync::atomic::AtomicU64>>,
}

impl<O: Observer> std::fmt::Debug for Executor<O> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Executor")
            .field("now", &self.now)
            .field("nodes", &self.info.nodes.len())
            .field("links", &self.info.links.len())
            .finish()
    }
}

impl Executor<NoObserver> {
    /// An executor for `system`, observing nothing.
    pub fn new(system: System, config: ExecConfig) -> Self {
        Executor::with_observer(system, config, NoObserver)
    }
}

impl<O: Observer> Executor<O> {
    /// An executor for `system` that reports to `observer`.
    pub fn with_observer(system: System, config: ExecConfig, observer: O) -> Self {
        let System {
            info,
            nodes,
            outs,
            ins,
            channels,
            environment,
        } = system;
        let n = info.nodes.len();
        // Within an instant: every component in declaration order, then the real
        // receptors, so that they sense what the effectors did in that instant.
        let (mut order, receptors): (Vec<usize>, Vec<usize>) =
            (0..n).partition(|&i| info.nodes[i].kind != NodeKind::RealReceptor);
        let receptors_from = order.len();
        order.extend(receptors);
        let (nodes, channels, reach) =
            in_process(nodes, outs, ins, &channels, &order, config.audit);
        let periods: Vec<u64> = info.nodes.iter().map(|n| n.period.as_nanos()).collect();
        let drives = info
            .nodes
            .iter()
            .map(|n| matches!(n.kind, NodeKind::RealEffector | NodeKind::RealReceptor))
            .collect();
        let next = vec![0; n];
        let schedule = Schedule::new(&next, &periods, &order);
        let huge_pages = if config.huge_pages {
            Collapse::start(reach.addresses(&nodes))
        } else {
            Collapse::none()
        };
        Executor {
            reach,
            huge_pages,
            stamps: None,
            channels,
            info,
            nodes,
            periods,
            drives,
            next,
            order,
            receptors_from,
            schedule,
            environment,
            now: Time::ZERO,
            config,
            observer,
            wants: Wants::default(),
            started: false,
            stopped: false,
            report: RunReport::default(),
            probes: Vec::new(),
            environment_probes: Vec::new(),
            probes_dropped: Vec::new(),
        }
    }

    /// Watch the run with a set of probes (see [`Probes`]): each is called
    /// within [`Executor::step`], right after each activation of the node it
    /// watches (an environment probe after each instant at which a driver ran).
    pub fn watch<M>(&mut self, probes: Probes<M>) -> &mut Self {
        self.probes_dropped.push(probes.dropped_counter());
        if self.probes.is_empty() {
            self.probes = (0..self.nodes.len()).map(|_| Vec::new()).collect();
        }
        for (target, f) in probes.entries {
            match target {
                Target::Node(i) => {
                    if let Some(p) = self.probes.get_mut(i) {
                        p.push(f);
                    }
                }
                Target::Environment => self.environment_probes.push(f),
            }
        }
        self
    }

    /// The current virtual time (the last instant executed).
    pub fn now(&self) -> Time {
        self.now
    }

    /// Names, kinds, periods and links.
    pub fn info(&self) -> &SystemInfo {
        &self.info
    }

    /// Errors and counters of the run so far.
    pub fn report(&self) -> &RunReport {
        &self.report
    }

    /// Wait until the kernel has backed the executor's memory with huge
    /// pages ([`ExecConfig::huge_pages`]), and what it did. The executor
    /// asks when it is made, on a thread of its own for more than a few
    /// regions, so that a large system need not wait for the kernel's copy
    /// to start stepping; this returns at once when the copy is done or none
    /// was asked for. For a program that times the executor's actions, or
    /// wants the copy off the machine's cores before its first instant.
    pub fn wait_for_huge_pages(&mut self) -> HugePages {
        self.huge_pages.wait()
    }

    /// The observer.
    pub fn observer(&self) -> &O {
        &self.observer
    }

    /// The observer, mutably.
    pub fn observer_mut(&mut self) -> &mut O {
        &mut self.observer
    }

    /// Consume the executor, returning its observer (for instance a recorded trace).
    pub fn into_observer(self) -> O {
        self.observer
    }

    /// The next instant at which some node is due, or `None` if every node halted.
    pub fn next_instant(&self) -> Option<Time> {
        if self.schedule.stale {
            return self
                .next
                .iter()
                .copied()
                .min()
                .filter(|t| *t != u64::MAX)
                .map(Time::from_nanos);
        }
        self.schedule.next_instant().map(Time::from_nanos)
    }

    /// Execute one instant (see the module docs). Returns the instant executed, or
    /// `None` if every node has halted.
    pub fn step(&mut self) -> Result<Option<Time>, ExecError> {
        if self.stopped {
            return Err(ExecError::Stopped);
        }
        if !self.started {
            self.started = true;
            self.observer.start(&self.info);
            if self.observer.enabled() {
                let links = 0..self.info.links.len();
                let nodes = 0..self.info.nodes.len();
                self.wants = Wants {
                    links: links
                        .map(|l| crate::trace::LinkWant::new(self.observer.link_events(l)))
                        .collect(),
                    nodes: nodes.map(|n| self.observer.node_events(n)).collect(),
                };
                for (i, node) in self.nodes.iter_mut().enumerate() {
                    node.observe(i, &self.wants);
                }
                if self.wants.links.iter().any(|w| w.events.stamps) {
                    let stamps = crate::trace::SendStamps::new(self.info.links.len());
                    self.observer.stamps(&stamps);
                    self.stamps = Some(stamps);
                }
            }
        }
        if self.schedule.stale {
            self.schedule = Schedule::new(&self.next, &self.periods, &self.order);
        }
        let Some(t) = self.next_instant() else {
            return Ok(None);
        };
        self.now = t;
        let tn = t.as_nanos();
        self.schedule.take_due(tn);
        let result = self.run_due(t);
        if result.is_ok() {
            self.schedule.reschedule(tn, &self.next);
        } else {
            // Stopped (some nodes due were not stepped): `next` alone says
            // what is due.
            self.schedule.stale = true;
        }
        result?;
        self.report.instants += 1;
        Ok(Some(t))
    }

    /// Read, then step, the nodes due at `t` (`self.schedule.due`).
    fn run_due(&mut self, t: Time) -> Result<(), ExecError> {
        let tn = t.as_nanos();
        let observe = self.observer.enabled();
        if observe {
            self.observer.instant(t);
        }
        let mut cx = LinkCx {
            time: t,
            observer: observe.then_some(&mut self.observer as &mut dyn Observer),
            wants: &self.wants,
            links: &self.info.links,
            stamps: self.stamps.as_ref(),
            environment: None,
        };
        // Reads in declaration order: the components due, then the
        // receptors due (each in declaration order) merged.
        let (due, rank) = (&self.schedule.due, &self.schedule.rank);
        let receptors = due.partition_point(|&i| rank[i] < self.receptors_from);
        if receptors == due.len() {
            for (k, &i) in due.iter().enumerate() {
                if let Some(&j) = due.get(k + AHEAD) {
                    self.reach.prefetch(&*self.nodes[j], j, false);
                }
                let read = self.nodes[i].read(&mut cx);
                debug_assert!(read.is_ok(), "in-process links report no problem");
            }
        } else {
            let (components, receptors) = due.split_at(receptors);
            let (mut a, mut b) = (components.iter().peekable(), receptors.iter().peekable());
            loop {
                let i = match (a.peek(), b.peek()) {
                    (Some(&&x), Some(&&y)) if y < x => b.next(),
                    (Some(_), _) => a.next(),
                    (None, _) => b.next(),
                };
                let Some(&i) = i else { break };
                let read = self.nodes[i].read(&mut cx);
                debug_assert!(read.is_ok(), "in-process links report no problem");
            }
        }
        // Whether a driver (the environment's, if there is one) ran.
        let mut world_ran = false;
        for k in 0..self.schedule.due.len() {
            let i = self.schedule.due[k];
            if let Some(&j) = self.schedule.due.get(k + AHEAD) {
                self.reach.prefetch(&*self.nodes[j], j, true);
            }
            if self.next[i] != tn {
                continue;
            }
            world_ran |= self.drives[i];
            let mut cx = LinkCx {
                time: t,
                observer: observe.then_some(&mut self.observer as &mut dyn Observer),
                wants: &self.wants,
                links: &self.info.links,
                stamps: self.stamps.as_ref(),
                environment: self.environment.as_deref_mut(),
            };
            match self.nodes[i].step(t, i, &mut cx) {
                Ok(NodeStep::Ran) => self.next[i] = tn.saturating_add(self.periods[i]),
                Ok(NodeStep::Halted) => {
                    self.next[i] = u64::MAX;
                    self.schedule.halted = true;
                }
                Err(e) => {
                    if let Some(o) = cx.observer.as_deref_mut() {
                        o.error(t, &e);
                    }
                    self.handle_error(i, tn, *e)?;
                }
            }
            if observe {
                while let Some(e) = self.observer.raised() {
                    self.observer.error(t, &e);
                    self.handle_raised(t, e)?;
                }
            }
            if let Some(probes) = self.probes.get_mut(i) {
                for f in probes {
                    f(t, self.nodes[i].core());
                }
            }
        }
        if world_ran
            && !self.environment_probes.is_empty()
            && let Some(env) = self.environment.as_deref()
        {
            for f in &mut self.environment_probes {
                f(t, env);
            }
        }
        Ok(())
    }

    /// Apply the error policy to an error of node `i` at instant `tn`.
    #[cold]
    fn handle_error(&mut self, i: usize, tn: u64, e: ExecError) -> Result<(), ExecError> {
        self.report.error_count += 1;
        match self.config.on_error {
            OnError::Stop => {
                self.stopped = true;
                Err(e)
            }
            OnError::Continue | OnError::SafeStop => {
                if halts_under_continue(&e) {
                    self.nodes[i].halt();
                    self.next[i] = u64::MAX;
                    self.schedule.halted = true;
                } else {
                    self.next[i] = tn.saturating_add(self.periods[i]);
                }
                self.keep(Time::from_nanos(tn), e);
                Ok(())
            }
        }
    }

    /// Apply the error policy to an error the observer raised at `t` (a broken
    /// contract): it names its subsystem, and no node's schedule changes
    /// unless the run stops or safe-stops.
    #[cold]
    fn handle_raised(&mut self, t: Time, e: ExecError) -> Result<(), ExecError> {
        self.report.error_count += 1;
        if self.config.on_error == OnError::Stop {
            self.stopped = true;
            return Err(e);
        }
        self.keep(t, e);
        Ok(())
    }

    /// Keep an error in the report (up to the limit); under
    /// [`OnError::SafeStop`], safe-stop the run at its first.
    fn keep(&mut self, t: Time, e: ExecError) {
        if self.report.errors.len() < self.config.max_recorded_errors {
            self.report.errors.push(e);
        }
        if self.config.on_error == OnError::SafeStop && self.report.safe_stopped.is_none() {
            self.report.safe_stopped = Some(t);
            for (i, node) in self.nodes.iter_mut().enumerate() {
                node.safe_stop();
                if node.is_halted() {
                    self.next[i] = u64::MAX;
                }
            }
            self.schedule.halted = true;
            self.schedule.prune(&self.next);
        }
    }

    /// Execute every instant before `end` (`t < end`); the clock then reads `end`.
    pub fn run_until(&mut self, end: Time) -> Result<(), ExecError> {
        if self.stopped {
            return Err(ExecError::Stopped);
        }
        while let Some(t) = self.next_instant() {
            if t >= end {
                break;
            }
            self.step()?;
        }
        self.now = self.now.max(end);
        Ok(())
    }

    /// Execute the instants of the next `duration` of virtual time: those in
    /// `[now, now + duration)` not yet executed.
    pub fn run_for(&mut self, duration: Duration) -> Result<(), ExecError> {
        self.run_until(self.now.saturating_add(duration))
    }

    fn subsystem_core<S: Subsystem>(&self, h: &SubsystemHandle<S>) -> Option<&SubsystemCore<S>> {
        crate::node::subsystem_core(self.nodes.get(h.id().index())?.core())
    }

    /// The memory of a subsystem.
    pub fn memory<S: Subsystem>(&self, h: &SubsystemHandle<S>) -> Option<&S::Memory> {
        self.subsystem_core(h).map(|i| &i.memory)
    }

    /// The input buffers of a subsystem, as read at its last activation.
    pub fn input<S: Subsystem>(&self, h: &SubsystemHandle<S>) -> Option<&S::Input> {
        self.subsystem_core(h).map(|i| &i.input)
    }

    /// The name of the behaviour a subsystem is in.
    pub fn behaviour<S: Subsystem>(&self, h: &SubsystemHandle<S>) -> Option<&str> {
        self.subsystem_core(h)
            .map(|i| i.fsm.behaviour_name(i.state.behaviour()))
    }

    /// The number of elementary actions (or driver steps) a node has executed.
    pub fn iteration(&self, node: crate::NodeId) -> Option<u64> {
        self.nodes.get(node.index()).map(|n| n.iteration())
    }

    /// Whether a node has halted (final behaviour, or an FSM error under `Continue`).
    pub fn is_halted(&self, node: crate::NodeId) -> bool {
        self.nodes.get(node.index()).is_some_and(|n| n.is_halted())
    }

    /// The system's environment ([`SystemBuilder::environment`]), if it has one of
    /// type `W`: what the simulated world is, for a report or a test.
    ///
    /// [`SystemBuilder::environment`]: crate::SystemBuilder::environment
    pub fn environment<W: Any>(&self) -> Option<&W> {
        self.environment.as_deref()?.downcast_ref()
    }

    /// The system's environment, mutably (to disturb the world between instants).
    pub fn environment_mut<W: Any>(&mut self) -> Option<&mut W> {
        self.environment.as_deref_mut()?.downcast_mut()
    }

    /// A driver's device.
    pub fn driver<D: Driver>(&self, h: &DriverHandle<D>) -> Option<&D> {
        let node = self.nodes.get(h.id().index())?;
        node.core()
            .downcast_ref::<DriverCore<D>>()
            .map(|d| &d.driver)
    }

    /// A driver's device, mutably (to inject faults or change the world in tests).
    pub fn driver_mut<D: Driver>(&mut self, h: &DriverHandle<D>) -> Option<&mut D> {
        let node = self.nodes.get_mut(h.id().index())?;
        node.core_mut()
            .downcast_mut::<DriverCore<D>>()
            .map(|d| &mut d.driver)
    }

    /// Counters of a link.
    pub fn link_stats(&self, link: LinkId) -> Option<LinkStats> {
        self.channels
            .stats(link.index())
            .map(|c| *c.borrow().stats())
    }

    /// Run only `node` from now on: every other node is never stepped again (a
    /// replay: the others' values come from a recording, through
    /// [`Executor::inject`]). Its instants stay those of its period.
    pub fn isolate(&mut self, node: crate::NodeId) {
        for (i, next) in self.next.iter_mut().enumerate() {
            if i != node.index() {
                *next = u64::MAX;
            }
        }
        self.schedule.stale = true;
    }

    /// Let `node` run from instant `from` on (its first activation at or after
    /// `from` on its period's grid), as a process started late in a running
    /// deployment did: a replay of that start of it. A halted node stays
    /// halted.
    pub fn start_at(&mut self, node: crate::NodeId, from: Time) {
        let i = node.index();
        if let (Some(next), Some(&period)) = (self.next.get_mut(i), self.periods.get(i))
            && *next != u64::MAX
        {
            let p = period.max(1);
            *next = from.as_nanos().div_ceil(p).saturating_mul(p);
            self.schedule.stale = true;
        }
    }

    /// Put a value into link `link` as if its sender had sent it with `stamp`:
    /// `body` is the value's postcard encoding (what a recording keeps). The
    /// receiver reads it at its next activation, as any value.
    pub fn inject(
        &mut self,
        link: usize,
        body: &[u8],
        stamp: crate::Stamp,
    ) -> Result<(), crate::InjectError> {
        self.channels
            .stats(link)
            .ok_or(crate::InjectError::NoLink(link))?
            .borrow_mut()
            .put_encoded(body, stamp)
    }

    /// Drop the values waiting in link `link` (those no isolated node reads).
    pub fn discard(&mut self, link: usize) {
        if let Some(c) = self.channels.stats(link) {
            c.borrow_mut().clear();
        }
    }

    /// Values waiting in a link (0 or 1 for a sample link).
    pub fn pending(&self, link: LinkId) -> Option<usize> {
        self.channels
            .stats(link.index())
            .map(|c| c.borrow().pending())
    }
}

/// How many nodes ahead of the one being read or stepped the executor asks
/// the cache for ([`crate::cache::prefetch`]).
const AHEAD: usize = 8;
