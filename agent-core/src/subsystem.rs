//! Subsystems (`c`, `e`, `r`) and drivers of real effectors and receptors (`E`, `R`).

use crate::describe::{PortTable, Shape};
use crate::error::DriverError;
use crate::kinds::{DeviceKind, SubsystemKind};
use crate::time::{Period, Time};

/// The types that make up one subsystem: its kind, internal memory, input buffers
/// and output buffers.
///
/// Implement it on a marker type; the behaviour lives in an [`Fsm`](crate::Fsm) of
/// [`Behaviour`](crate::Behaviour)s built over it. `Input` is a struct of [`Group`]s
/// of [`In`](crate::In) buffers and `Output` a struct of groups of
/// [`Out`](crate::Out) buffers.
///
/// [`Group`]: crate::Group
#[diagnostic::on_unimplemented(
    message = "`{Self}` is not a subsystem",
    label = "this type does not implement `Subsystem`",
    note = "implement `Subsystem` for `{Self}`: its KIND, Memory, Input and Output types"
)]
pub trait Subsystem: Sized + 'static {
    /// Control subsystem, virtual effector or virtual receptor.
    const KIND: SubsystemKind;
    /// The internal memory `^c c`.
    type Memory: Send + 'static;
    /// The input buffers `_x c`.
    type Input: Default + Send + 'static;
    /// The output buffers `_y c`.
    type Output: Default + Send + 'static;

    /// The names and types of the memory fields and buffers, for spec export and
    /// checks; `None` if they are not described. `#[derive(Subsystem)]` writes it;
    /// by hand, with described types: `Some(Shape::of_subsystem::<Self>())`.
    fn shape() -> Option<Shape> {
        None
    }

    /// How its buffers are found by name, for links made from a spec
    /// ([`SystemBuilder::connect_named`](crate::SystemBuilder::connect_named)).
    /// `#[derive(Subsystem)]` returns `Some(PortTable::of::<Input, Output>())`.
    fn ports() -> Option<PortTable> {
        None
    }
}

/// Timing of one driver step.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DriverContext {
    /// Virtual time of this step.
    pub now: Time,
    /// The driver's own iteration counter.
    pub iteration: u64,
    /// The driver's period (the time until its next step).
    pub period: Period,
}

/// A real effector or receptor: hardware, or a simulator standing in for it.
///
/// A driver exchanges buffers with its agent's virtual effectors or receptors like a
/// subsystem does, but it has no FSM: the executor calls [`Driver::step`] once per
/// period, between reading its inputs and sending its outputs.
pub trait Driver: Send + 'static {
    /// Real effector or real receptor.
    const KIND: DeviceKind;
    /// Commands received from virtual effectors or receptors (`_x E`).
    type Input: Default + Send + 'static;
    /// Readings sent to virtual effectors or receptors (`_y E`).
    type Output: Default + Send + 'static;

    /// The names and types of the buffers, for spec export and checks; `None` if
    /// they are not described. With `#[derive(Buffers)]` on the input and output
    /// structs: `Some(Shape::of_driver::<Self>())`.
    fn shape() -> Option<Shape> {
        None
    }

    /// How its buffers are found by name, for links made from a spec:
    /// `fn ports() -> Option<PortTable> { Some(PortTable::of::<Self::Input, Self::Output>()) }`
    /// with `#[derive(Buffers)]` on the input and output structs.
    fn ports() -> Option<PortTable> {
        None
    }

    /// Advance the device by one period: act on `input`, write readings to `output`.
    fn step(
        &mut self,
        ctx: DriverContext,
        input: &Self::Input,
        output: &mut Self::Output,
    ) -> Result<(), DriverError>;
}
