//! The runtime form of subsystems and drivers, behind one object-safe trait so that
//! executors can step a heterogeneous system.

use std::any::{Any, TypeId};

use crate::executor::{ExecError, FsmError};
use crate::fsm::{Activated, ActivationError, Fsm, FsmState};
use crate::link::{InPort, LinkCx, OutPort};
use crate::subsystem::{Driver, DriverContext, Subsystem};
use crate::time::{Stamp, Time};
use crate::trace::{ActionEvent, NodeInfo, TransitionEvent};

/// What one activation of a node did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum NodeStep {
    /// An action (or driver step) ran.
    Ran,
    /// The node is halted and will not run again.
    Halted,
}

pub(crate) trait NodeDyn: Send {
    /// `TypeId` of the input and output buffer structs, to check handles.
    fn buffer_types(&self) -> (TypeId, TypeId);
    /// Install an erased `Box<dyn OutPort<Output>>`; false if the type does not match.
    fn install_out(&mut self, port: Box<dyn Any>) -> bool;
    /// Install an erased `Box<dyn InPort<Input>>`; false if the type does not match.
    fn install_in(&mut self, port: Box<dyn Any>) -> bool;
    /// The read at the start of an activation (the end of Algorithm 1's wait).
    fn read(&mut self, cx: &mut LinkCx<'_>);
    /// FSM decision, action (or driver step) and send.
    fn step(&mut self, now: Time, index: usize, cx: &mut LinkCx<'_>)
    -> Result<NodeStep, ExecError>;
    fn halt(&mut self);
    fn is_halted(&self) -> bool;
    fn iteration(&self) -> u64;
    fn as_any(&self) -> &dyn Any;
    fn as_any_mut(&mut self) -> &mut dyn Any;
}

fn send_all<O>(
    outs: &mut [Box<dyn OutPort<O>>],
    output: &mut O,
    stamp: Stamp,
    cx: &mut LinkCx<'_>,
) -> Result<(), ExecError> {
    let mut first = None;
    for p in outs.iter_mut() {
        if let Err(e) = p.send(output, stamp, cx) {
            first.get_or_insert(e);
        }
    }
    first.map_or(Ok(()), |e| Err(ExecError::Link(e)))
}

/// A subsystem in a system: its buffers, memory, FSM and link ports.
pub(crate) struct Instance<S: Subsystem> {
    pub(crate) info: NodeInfo,
    pub(crate) memory: S::Memory,
    pub(crate) input: S::Input,
    pub(crate) output: S::Output,
    pub(crate) fsm: Fsm<S>,
    pub(crate) state: FsmState,
    pub(crate) iteration: u64,
    ins: Vec<Box<dyn InPort<S::Input>>>,
    outs: Vec<Box<dyn OutPort<S::Output>>>,
}

impl<S: Subsystem> Instance<S> {
    pub(crate) fn new(info: NodeInfo, memory: S::Memory, fsm: Fsm<S>) -> Self {
        Instance {
            info,
            memory,
            input: S::Input::default(),
            output: S::Output::default(),
            state: fsm.start(),
            fsm,
            iteration: 0,
            ins: Vec::new(),
            outs: Vec::new(),
        }
    }
}

impl<S: Subsystem> NodeDyn for Instance<S> {
    fn buffer_types(&self) -> (TypeId, TypeId) {
        (TypeId::of::<S::Input>(), TypeId::of::<S::Output>())
    }

    fn install_out(&mut self, port: Box<dyn Any>) -> bool {
        match port.downcast::<Box<dyn OutPort<S::Output>>>() {
            Ok(p) => {
                self.outs.push(*p);
                true
            }
            Err(_) => false,
        }
    }

    fn install_in(&mut self, port: Box<dyn Any>) -> bool {
        match port.downcast::<Box<dyn InPort<S::Input>>>() {
            Ok(p) => {
                p.attach(&mut self.input);
                self.ins.push(*p);
                true
            }
            Err(_) => false,
        }
    }

    #[inline]
    fn read(&mut self, cx: &mut LinkCx<'_>) {
        for p in &mut self.ins {
            p.read(&mut self.input, cx);
        }
    }

    #[inline]
    fn step(
        &mut self,
        now: Time,
        index: usize,
        cx: &mut LinkCx<'_>,
    ) -> Result<NodeStep, ExecError> {
        let iteration = self.iteration;
        let observer = &mut cx.observer;
        let result = self.fsm.activate(
            &mut self.state,
            &mut self.memory,
            &self.input,
            &mut self.output,
            |step| {
                if let Some(o) = observer.as_deref_mut() {
                    o.transition(&TransitionEvent {
                        time: now,
                        node: index,
                        iteration,
                        step: *step,
                    });
                }
            },
        );
        match result {
            Ok(Activated::Ran { behaviour }) => {
                if let Some(o) = cx.observer.as_deref_mut() {
                    o.action(&ActionEvent {
                        time: now,
                        node: index,
                        iteration,
                        behaviour: Some(behaviour),
                    });
                }
                self.iteration += 1;
                send_all(
                    &mut self.outs,
                    &mut self.output,
                    Stamp::new(iteration, now),
                    cx,
                )?;
                Ok(NodeStep::Ran)
            }
            Ok(Activated::Halted) => Ok(NodeStep::Halted),
            Err(ActivationError::Fsm(fault)) => Err(ExecError::Fsm(FsmError {
                subsystem: self.info.name.clone(),
                iteration,
                time: now,
                fault,
            })),
            Err(ActivationError::Action { behaviour, source }) => {
                for p in &mut self.outs {
                    p.discard(&mut self.output);
                }
                Err(ExecError::Action {
                    subsystem: self.info.name.clone(),
                    behaviour,
                    iteration,
                    time: now,
                    source,
                })
            }
        }
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

    fn as_any(&self) -> &dyn Any {
        self
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

/// A driver in a system: the device, its buffers and link ports.
pub(crate) struct DriverInstance<D: Driver> {
    pub(crate) info: NodeInfo,
    pub(crate) driver: D,
    pub(crate) input: D::Input,
    pub(crate) output: D::Output,
    pub(crate) iteration: u64,
    halted: bool,
    ins: Vec<Box<dyn InPort<D::Input>>>,
    outs: Vec<Box<dyn OutPort<D::Output>>>,
}

impl<D: Driver> DriverInstance<D> {
    pub(crate) fn new(info: NodeInfo, driver: D) -> Self {
        DriverInstance {
            info,
            driver,
            input: D::Input::default(),
            output: D::Output::default(),
            iteration: 0,
            halted: false,
            ins: Vec::new(),
            outs: Vec::new(),
        }
    }
}

impl<D: Driver> NodeDyn for DriverInstance<D> {
    fn buffer_types(&self) -> (TypeId, TypeId) {
        (TypeId::of::<D::Input>(), TypeId::of::<D::Output>())
    }

    fn install_out(&mut self, port: Box<dyn Any>) -> bool {
        match port.downcast::<Box<dyn OutPort<D::Output>>>() {
            Ok(p) => {
                self.outs.push(*p);
                true
            }
            Err(_) => false,
        }
    }

    fn install_in(&mut self, port: Box<dyn Any>) -> bool {
        match port.downcast::<Box<dyn InPort<D::Input>>>() {
            Ok(p) => {
                p.attach(&mut self.input);
                self.ins.push(*p);
                true
            }
            Err(_) => false,
        }
    }

    fn read(&mut self, cx: &mut LinkCx<'_>) {
        for p in &mut self.ins {
            p.read(&mut self.input, cx);
        }
    }

    fn step(
        &mut self,
        now: Time,
        index: usize,
        cx: &mut LinkCx<'_>,
    ) -> Result<NodeStep, ExecError> {
        if self.halted {
            return Ok(NodeStep::Halted);
        }
        let iteration = self.iteration;
        let ctx = DriverContext {
            now,
            iteration,
            period: self.info.period,
        };
        if let Err(source) = self.driver.step(ctx, &self.input, &mut self.output) {
            for p in &mut self.outs {
                p.discard(&mut self.output);
            }
            return Err(ExecError::Driver {
                driver: self.info.name.clone(),
                iteration,
                time: now,
                source,
            });
        }
        if let Some(o) = cx.observer.as_deref_mut() {
            o.action(&ActionEvent {
                time: now,
                node: index,
                iteration,
                behaviour: None,
            });
        }
        self.iteration += 1;
        send_all(
            &mut self.outs,
            &mut self.output,
            Stamp::new(iteration, now),
            cx,
        )?;
        Ok(NodeStep::Ran)
    }

    fn halt(&mut self) {
        self.halted = true;
    }

    fn is_halted(&self) -> bool {
        self.halted
    }

    fn iteration(&self) -> u64 {
        self.iteration
    }

    fn as_any(&self) -> &dyn Any {
        self
    }

    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}
