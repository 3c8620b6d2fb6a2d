//! The runtime form of subsystems and drivers.
//!
//! A [`System`](crate::System) holds every node as a [`NodeSeed`]: its buffers, memory
//! and FSM (or device), `Send`, without any transport. An executor turns each seed
//! into its own runtime node by adding the ports of its transport; the deterministic
//! executor makes a [`InProcess`] node whose ports share single-threaded channels.

use std::any::{Any, TypeId};

use crate::describe::Fresh;
use crate::error::{ExecError, FsmError, LinkError};
use crate::fsm::{Activated, Fsm, FsmState};
use crate::link::{InPort, LinkCx, OutPort, Wants};
use crate::subsystem::{Driver, DriverContext, Subsystem};
use crate::time::{Stamp, Time};
use crate::trace::{ActionEvent, AuditEvent, NodeEvents, NodeInfo, TransitionEvent};

/// What one activation of a node did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum NodeStep {
    /// An action (or driver step) ran.
    Ran,
    /// The node is halted and will not run again.
    Halted,
}

/// A node as a system holds it, before an executor gives it ports.
pub(crate) trait NodeSeed: Send {
    /// `TypeId` of the input and output buffer structs, to check handles.
    fn buffer_types(&self) -> (TypeId, TypeId);
    /// The output (`output`) or input buffer struct, erased: what the builder
    /// counts a fan's elements in.
    fn buffers_any(&mut self, output: bool) -> &mut dyn Any;
    /// The node for the in-process executor; its activations audited
    /// (`ExecConfig::audit`) if `audit`.
    fn into_in_process(self: Box<Self>, audit: bool) -> Box<dyn InProcessNode>;
}

/// A node of the in-process executor.
pub(crate) trait InProcessNode {
    /// Install an erased `Box<dyn OutPort<Output>>`; false if the type does not match.
    fn install_out(&mut self, port: Box<dyn Any>) -> bool;
    /// Install an erased `Box<dyn InPort<Input>>`; false if the type does not match.
    fn install_in(&mut self, port: Box<dyn Any>) -> bool;
    /// The read at the start of an activation (the end of Algorithm 1's wait).
    /// Every port is read; the first problem of a link between processes is
    /// returned (in-process and thread links have none).
    fn read(&mut self, cx: &mut LinkCx<'_>) -> Result<(), LinkError>;
    /// The observer's needs, once at the start of a run (the node is node
    /// `index`): the ports leave out the events of links whose observer needs
    /// none, the node the activations and transitions it needs not.
    fn observe(&mut self, index: usize, wants: &Wants);
    /// The addresses beyond the node's own that its read and its step touch
    /// (its port tables, ports and their channels), pushed onto `read` and
    /// `step`: what the executor asks the cache for a few nodes ahead
    /// ([`crate::cache`]).
    fn reach(&self, read: &mut Vec<usize>, step: &mut Vec<usize>);
    /// FSM decision, action (or driver step) and send.
    /// Errors are boxed: they are rare, and a small `Result` keeps the hot path lean.
    fn step(
        &mut self,
        now: Time,
        index: usize,
        cx: &mut LinkCx<'_>,
    ) -> Result<NodeStep, Box<ExecError>>;
    fn halt(&mut self);
    /// The run safe-stops ([`OnError::SafeStop`](crate::OnError::SafeStop)): a
    /// subsystem halts, a driver makes its device safe and runs on.
    fn safe_stop(&mut self);
    fn is_halted(&self) -> bool;
    fn iteration(&self) -> u64;
    /// The node's core (a `SubsystemCore`, an `Audited` one, or a `DriverCore`),
    /// erased: what inspection downcasts ([`subsystem_core`]).
    fn core(&self) -> &dyn Any;
    fn core_mut(&mut self) -> &mut dyn Any;
    /// The node's core (buffers, memory and FSM, or the device) without its
    /// ports: what a thread of the real-time executor hands back when it ends.
    fn into_core(self: Box<Self>) -> Box<dyn Any + Send>;
}

/// What every node has, whatever the transport: buffers and a way to compute.
pub(crate) trait NodeCore: Send + Sized + 'static {
    type Input: 'static;
    type Output: 'static;
    fn input(&mut self) -> &mut Self::Input;
    fn output(&mut self) -> &mut Self::Output;
    /// Decide and compute one activation. `Ok(Some(stamp))`: outputs are to be sent
    /// with `stamp`; `Ok(None)`: the node is halted.
    fn compute(
        &mut self,
        now: Time,
        index: usize,
        cx: &mut LinkCx<'_>,
    ) -> Result<Option<Stamp>, Box<ExecError>>;
    /// Whether [`NodeCore::compute_audited`] observes anything (a subsystem's
    /// transition functions); a driver has nothing to audit.
    const AUDITED: bool = false;
    /// [`NodeCore::compute`], telling the observer what each transition function
    /// read and wrote (`ExecConfig::audit`).
    fn compute_audited(
        &mut self,
        now: Time,
        index: usize,
        cx: &mut LinkCx<'_>,
    ) -> Result<Option<Stamp>, Box<ExecError>> {
        self.compute(now, index, cx)
    }
    /// The transitions and activations the observer needs
    /// ([`InProcessNode::observe`]; every one until told).
    fn observe(&mut self, events: NodeEvents);
    fn halt(&mut self);
    /// [`InProcessNode::safe_stop`]: a subsystem halts (the default).
    fn safe_stop(&mut self) {
        self.halt();
    }
    fn is_halted(&self) -> bool;
    fn iteration(&self) -> u64;
}

impl<C: NodeCore> NodeSeed for C {
    fn buffer_types(&self) -> (TypeId, TypeId) {
        (TypeId::of::<C::Input>(), TypeId::of::<C::Output>())
    }

    fn buffers_any(&mut self, output: bool) -> &mut dyn Any {
        if output { self.output() } else { self.input() }
    }

    fn into_in_process(self: Box<Self>, audit: bool) -> Box<dyn InProcessNode> {
        if audit && C::AUDITED {
            // A type of its own: the unaudited node's hot path knows nothing of it.
            Box::new(InProcess {
                core: Audited(*self),
                ins: Vec::new(),
                outs: Vec::new(),
            })
        } else {
            Box::new(InProcess {
                core: *self,
                ins: Vec::new(),
                outs: Vec::new(),
            })
        }
    }
}

/// The subsystem core behind an erased node core, audited or not: how the
/// executors' inspection (memory, inputs, behaviour) and probes reach it.
pub(crate) fn subsystem_core<S: Subsystem>(core: &dyn Any) -> Option<&SubsystemCore<S>> {
    core.downcast_ref::<SubsystemCore<S>>().or_else(|| {
        core.downcast_ref::<Audited<SubsystemCore<S>>>()
            .map(|a| &a.0)
    })
}

/// A node core whose activations are audited (`ExecConfig::audit`).
pub(crate) struct Audited<C>(pub(crate) C);

impl<C: NodeCore> NodeCore for Audited<C> {
    type Input = C::Input;
    type Output = C::Output;
    fn input(&mut self) -> &mut C::Input {
        self.0.input()
    }
    fn output(&mut self) -> &mut C::Output {
        self.0.output()
    }
    fn compute(
        &mut self,
        now: Time,
        index: usize,
        cx: &mut LinkCx<'_>,
    ) -> Result<Option<Stamp>, Box<ExecError>> {
        self.0.compute_audited(now, index, cx)
    }
    fn observe(&mut self, events: NodeEvents) {
        self.0.observe(events);
    }
    fn halt(&mut self) {
        self.0.halt();
    }
    fn safe_stop(&mut self) {
        self.0.safe_stop();
    }
    fn is_halted(&self) -> bool {
        self.0.is_halted()
    }
    fn iteration(&self) -> u64 {
        self.0.iteration()
    }
}

/// A node with the ports of the in-process executor.
pub(crate) struct InProcess<C: NodeCore> {
    pub(crate) core: C,
    ins: Vec<Box<dyn InPort<C::Input>>>,
    outs: Vec<Box<dyn OutPort<C::Output>>>,
}

impl<C: NodeCore> InProcess<C> {
    /// Every port publishes what it holds for readers in other processes
    /// ([`OutPort::flush`]); the first refusal.
    fn flush(&mut self) -> Option<crate::link::Refused> {
        let mut first = None;
        for p in &mut self.outs {
            if let Err(refused) = p.flush() {
                first.get_or_insert(refused);
            }
        }
        first
    }
}

impl<C: NodeCore> InProcessNode for InProcess<C> {
    fn install_out(&mut self, port: Box<dyn Any>) -> bool {
        match port.downcast::<Box<dyn OutPort<C::Output>>>() {
            Ok(p) => {
                self.outs.push(*p);
                true
            }
            Err(_) => false,
        }
    }

    fn install_in(&mut self, port: Box<dyn Any>) -> bool {
        match port.downcast::<Box<dyn InPort<C::Input>>>() {
            Ok(p) => {
                p.attach(self.core.input());
                self.ins.push(*p);
                true
            }
            Err(_) => false,
        }
    }

    #[inline]
    fn read(&mut self, cx: &mut LinkCx<'_>) -> Result<(), LinkError> {
        let input = self.core.input();
        let mut first = Ok(());
        for p in &mut self.ins {
            let r = p.read(input, cx);
            if first.is_ok() {
                first = r;
            }
        }
        first
    }

    fn observe(&mut self, index: usize, wants: &Wants) {
        self.ins.iter_mut().for_each(|p| p.observe(&wants.links));
        self.outs.iter_mut().for_each(|p| p.observe(&wants.links));
        if let Some(events) = wants.nodes.get(index) {
            self.core.observe(*events);
        }
    }

    fn reach(&self, read: &mut Vec<usize>, step: &mut Vec<usize>) {
        crate::cache::address_of(self.ins.as_slice(), read);
        for p in &self.ins {
            crate::cache::address_of(&**p, read);
            p.reach(read);
        }
        crate::cache::address_of(self.outs.as_slice(), step);
        for p in &self.outs {
            crate::cache::address_of(&**p, step);
            p.reach(step);
        }
    }

    #[inline]
    fn step(
        &mut self,
        now: Time,
        index: usize,
        cx: &mut LinkCx<'_>,
    ) -> Result<NodeStep, Box<ExecError>> {
        match self.core.compute(now, index, cx) {
            Ok(Some(stamp)) => {
                let output = self.core.output();
                let mut first = None;
                for p in &mut self.outs {
                    if let Err(refused) = p.send(output, stamp, cx) {
                        first.get_or_insert(refused);
                    }
                }
                match first {
                    None => Ok(NodeStep::Ran),
                    Some(r) => Err(Box::new(ExecError::Link(r.into_error(stamp, cx.links)))),
                }
            }
            Ok(None) => {
                // What the node wrote last still reaches its readers in
                // other processes.
                match self.flush() {
                    None => Ok(NodeStep::Halted),
                    Some(r) => {
                        let stamp = Stamp::new(self.core.iteration(), now);
                        Err(Box::new(ExecError::Link(r.into_error(stamp, cx.links))))
                    }
                }
            }
            Err(e) => {
                let output = self.core.output();
                for p in &mut self.outs {
                    p.discard(output);
                }
                Err(e)
            }
        }
    }

    fn halt(&mut self) {
        self.core.halt();
        // Halted from outside (an error, a stop): nobody to tell of a
        // value that could not be published.
        let _ = self.flush();
    }

    fn safe_stop(&mut self) {
        self.core.safe_stop();
        let _ = self.flush();
    }

    fn is_halted(&self) -> bool {
        self.core.is_halted()
    }

    fn iteration(&self) -> u64 {
        self.core.iteration()
    }

    fn core(&self) -> &dyn Any {
        &self.core
    }

    fn core_mut(&mut self) -> &mut dyn Any {
        &mut self.core
    }

    fn into_core(self: Box<Self>) -> Box<dyn Any + Send> {
        Box::new(self.core)
    }
}

/// A subsystem: its buffers, memory and FSM.
pub(crate) struct SubsystemCore<S: Subsystem> {
    /// Its name, for its errors (the rest of its description is the
    /// system's, [`NodeInfo`]): 16 bytes, so that the fields an action
    /// touches lie together.
    pub(crate) name: Box<str>,
    pub(crate) memory: S::Memory,
    pub(crate) input: S::Input,
    pub(crate) output: S::Output,
    pub(crate) fsm: Fsm<S>,
    pub(crate) state: FsmState,
    pub(crate) iteration: u64,
    /// The predicates the observer wants after each activation
    /// ([`Observer::predicates_wanted`](crate::Observer::predicates_wanted)),
    /// once asked.
    wanted: Option<u64>,
    /// The transitions and activations the observer needs.
    events: NodeEvents,
}

impl<S: Subsystem> SubsystemCore<S> {
    pub(crate) fn new(name: &str, memory: S::Memory, fsm: Fsm<S>) -> Self {
        SubsystemCore {
            name: name.into(),
            memory,
            input: S::Input::default(),
            output: S::Output::default(),
            state: fsm.start(),
            fsm,
            iteration: 0,
            wanted: None,
            events: NodeEvents::all(),
        }
    }

    /// The end of an activation: what each part read and wrote (`seen`, when
    /// audited), the action event and the next iteration; or the error with where
    /// and when it happened.
    #[inline(always)]
    fn finish(
        &mut self,
        result: Result<Activated, FsmError>,
        now: Time,
        index: usize,
        cx: &mut LinkCx<'_>,
        seen: &[(usize, Fresh, Fresh)],
    ) -> Result<Option<Stamp>, Box<ExecError>> {
        let iteration = self.iteration;
        match result {
            Ok(Activated::Ran { behaviour }) => {
                if let Some(o) = cx.observer.as_deref_mut() {
                    let told = self.events.action(Some(behaviour));
                    for &(part, reads, writes) in seen {
                        o.audit(&AuditEvent {
                            time: now,
                            node: index,
                            behaviour,
                            part,
                            reads,
                            writes,
                        });
                    }
                    let event = ActionEvent {
                        time: now,
                        node: index,
                        iteration,
                        behaviour: Some(behaviour),
                    };
                    if told {
                        o.action(&event);
                    }
                    // Asked once; most runs want none, and pay one branch.
                    let wanted = *self
                        .wanted
                        .get_or_insert_with(|| o.predicates_wanted(index));
                    if wanted != 0 {
                        let values = self.fsm.valuation(wanted, &self.memory, &self.input);
                        o.predicates(&event, values);
                    }
                }
                self.iteration += 1;
                Ok(Some(Stamp::new(iteration, now)))
            }
            Ok(Activated::Halted) => Ok(None),
            Err(error) => Err(Box::new(ExecError::Fsm {
                subsystem: self.name.to_string(),
                iteration,
                time: now,
                error,
            })),
        }
    }
}

impl<S: Subsystem> NodeCore for SubsystemCore<S> {
    type Input = S::Input;
    type Output = S::Output;

    fn input(&mut self) -> &mut S::Input {
        &mut self.input
    }

    fn output(&mut self) -> &mut S::Output {
        &mut self.output
    }

    #[inline]
    fn compute(
        &mut self,
        now: Time,
        index: usize,
        cx: &mut LinkCx<'_>,
    ) -> Result<Option<Stamp>, Box<ExecError>> {
        let iteration = self.iteration;
        let transitions = cx.observer.is_some() && self.events.transitions;
        let observer = &mut cx.observer;
        let result = self.fsm.activate(
            &mut self.state,
            &mut self.memory,
            &self.input,
            &mut self.output,
            |step| {
                if let Some(o) = observer.as_deref_mut().filter(|_| transitions) {
                    o.transition(&TransitionEvent {
                        time: now,
                        node: index,
                        iteration,
                        step: *step,
                    });
                }
            },
        );
        self.finish(result, now, index, cx, &[])
    }

    const AUDITED: bool = true;

    #[cold]
    #[inline(never)]
    fn compute_audited(
        &mut self,
        now: Time,
        index: usize,
        cx: &mut LinkCx<'_>,
    ) -> Result<Option<Stamp>, Box<ExecError>> {
        let iteration = self.iteration;
        let transitions = cx.observer.is_some() && self.events.transitions;
        let observer = &mut cx.observer;
        let mut seen: Vec<(usize, Fresh, Fresh)> = Vec::new();
        let result = self.fsm.activate_audited(
            &mut self.state,
            &mut self.memory,
            &self.input,
            &mut self.output,
            |step| {
                if let Some(o) = observer.as_deref_mut().filter(|_| transitions) {
                    o.transition(&TransitionEvent {
                        time: now,
                        node: index,
                        iteration,
                        step: *step,
                    });
                }
            },
            &mut |part, reads, writes| seen.push((part, reads, writes)),
        );
        self.finish(result, now, index, cx, &seen)
    }

    fn observe(&mut self, events: NodeEvents) {
        self.events = events;
    }

    fn halt(&mut self) {
        self.state.halt();
    }

    fn is_halted(&self) -> bool {
        self.state.is_halted()
    }

    fn iteration(&self) -> u64 {
        self.iteration
    }
}

/// A driver: the device and its buffers.
pub(crate) struct DriverCore<D: Driver> {
    pub(crate) info: NodeInfo,
    pub(crate) driver: D,
    pub(crate) input: D::Input,
    pub(crate) output: D::Output,
    pub(crate) iteration: u64,
    halted: bool,
    /// Whether the observer needs its steps.
    told: bool,
}

impl<D: Driver> DriverCore<D> {
    pub(crate) fn new(info: NodeInfo, driver: D) -> Self {
        DriverCore {
            info,
            driver,
            input: D::Input::default(),
            output: D::Output::default(),
            iteration: 0,
            halted: false,
            told: true,
        }
    }
}

impl<D: Driver> NodeCore for DriverCore<D> {
    type Input = D::Input;
    type Output = D::Output;

    fn input(&mut self) -> &mut D::Input {
        &mut self.input
    }

    fn output(&mut self) -> &mut D::Output {
        &mut self.output
    }

    fn compute(
        &mut self,
        now: Time,
        index: usize,
        cx: &mut LinkCx<'_>,
    ) -> Result<Option<Stamp>, Box<ExecError>> {
        if self.halted {
            return Ok(None);
        }
        let iteration = self.iteration;
        let ctx = DriverContext::of_step(
            now,
            iteration,
            self.info.period,
            cx.environment.as_deref_mut(),
        );
        self.driver
            .step(ctx, &self.input, &mut self.output)
            .map_err(|source| {
                Box::new(ExecError::Driver {
                    driver: self.info.name.clone(),
                    iteration,
                    time: now,
                    source,
                })
            })?;
        if let Some(o) = cx.observer.as_deref_mut()
            && self.told
        {
            o.action(&ActionEvent {
                time: now,
                node: index,
                iteration,
                behaviour: None,
            });
        }
        self.iteration += 1;
        Ok(Some(Stamp::new(iteration, now)))
    }

    fn observe(&mut self, events: NodeEvents) {
        self.told = events.action(None);
    }

    fn halt(&mut self) {
        self.halted = true;
    }

    fn safe_stop(&mut self) {
        self.driver.safe_stop();
    }

    fn is_halted(&self) -> bool {
        self.halted
    }

    fn iteration(&self) -> u64 {
        self.iteration
    }
}
