//! Subsystems (`c`, `e`, `r`) and drivers of real effectors and receptors (`E`, `R`).

use std::any::Any;
use std::fmt;

use crate::describe::{Buffers, Fields, Fresh, PortTable, Shape};
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

    /// What an audit observes ([`ExecConfig::audit`](crate::ExecConfig::audit)):
    /// the inputs read since the last call (clearing the marks) and the outputs
    /// written in the current iteration, in the order of the buffers' [`Shape`].
    /// `#[derive(Subsystem)]` writes it from the derives of the buffer structs; the
    /// default observes nothing.
    fn audit(input: &Self::Input, output: &Self::Output) -> (Fresh, Fresh) {
        let _ = (input, output);
        (Fresh(0), Fresh(0))
    }
}

/// What a driver step knows: its timing, and the system's environment.
pub struct DriverContext<'a> {
    /// Virtual time of this step.
    pub now: Time,
    /// The driver's own iteration counter.
    pub iteration: u64,
    /// The driver's period (the time until its next step).
    pub period: Period,
    environment: Option<&'a mut (dyn Any + Send)>,
}

impl fmt::Debug for DriverContext<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("DriverContext")
            .field("now", &self.now)
            .field("iteration", &self.iteration)
            .field("period", &self.period)
            .field("environment", &self.environment.is_some())
            .finish()
    }
}

impl DriverContext<'static> {
    /// The context of a step at `now`, without an environment (for testing a
    /// driver alone; the executor makes the contexts of a run).
    pub fn new(now: Time, iteration: u64, period: Period) -> Self {
        DriverContext {
            now,
            iteration,
            period,
            environment: None,
        }
    }
}

impl<'a> DriverContext<'a> {
    /// The executor's context of a step.
    pub(crate) fn of_step(
        now: Time,
        iteration: u64,
        period: Period,
        environment: Option<&'a mut (dyn Any + Send)>,
    ) -> Self {
        DriverContext {
            now,
            iteration,
            period,
            environment,
        }
    }

    /// The same context, reaching `environment`.
    pub fn with_environment<W: Any + Send>(self, environment: &'a mut W) -> DriverContext<'a> {
        DriverContext {
            environment: Some(environment),
            ..self
        }
    }

    /// The system's environment ([`SystemBuilder::environment`]): the world that
    /// real effectors act on and real receptors sense. Within an instant, the
    /// executor steps the real receptors after every other component, so a
    /// receptor senses what the effectors did in that instant, whatever the order
    /// in which the components were added.
    ///
    /// An error if the system has no environment, or one of another type. The
    /// reference borrows the context: read `now`, `iteration` and `period` first
    /// (they are `Copy`).
    ///
    /// [`SystemBuilder::environment`]: crate::SystemBuilder::environment
    pub fn environment<W: Any>(&mut self) -> Result<&mut W, DriverError> {
        let Some(env) = self.environment.as_deref_mut() else {
            return Err(DriverError::new(format!(
                "this driver needs an environment of type `{}`, and the system has none: add it with `SystemBuilder::environment`",
                std::any::type_name::<W>()
            )));
        };
        env.downcast_mut::<W>().ok_or_else(|| {
            DriverError::new(format!(
                "this driver needs an environment of type `{}`, and the system's is of another type",
                std::any::type_name::<W>()
            ))
        })
    }
}

/// A real effector or receptor: hardware, or a simulator standing in for it.
///
/// A driver exchanges buffers with its agent's virtual effectors or receptors like a
/// subsystem does, but it has no FSM: the executor calls [`Driver::step`] once per
/// period, between reading its inputs and sending its outputs.
///
/// Its input and output structs describe their buffers (`#[derive(Buffers)]` on a
/// struct of `In<T>` or `Out<T>` buffers or of groups, or `()` for none), so a
/// driver is described by its types alone: [`Driver::shape`] and [`Driver::ports`]
/// are provided, for spec export and for links made by name. A struct that does
/// not describe its buffers is a compile error at `type Input = ...`.
///
/// ```
/// use agent_core::{DeviceKind, Driver, DriverContext, DriverError};
///
/// /// A receptor that senses nothing (a driver with buffers derives `Buffers` on
/// /// its input or output struct).
/// struct Clock {
///     ticks: u64,
/// }
///
/// impl Driver for Clock {
///     const KIND: DeviceKind = DeviceKind::Receptor;
///     type Input = ();
///     type Output = ();
///     fn step(&mut self, _: DriverContext<'_>, _: &(), _: &mut ()) -> Result<(), DriverError> {
///         self.ticks += 1;
///         Ok(())
///     }
/// }
/// let shape = Clock::shape().expect("every driver is described");
/// assert!(shape.inputs.is_empty() && shape.outputs.is_empty() && shape.memory.is_none());
/// assert!(Clock::ports().is_some());
/// ```
pub trait Driver: Send + 'static {
    /// Real effector or real receptor.
    const KIND: DeviceKind;
    /// Commands received from virtual effectors or receptors (`_x E`): a struct of
    /// `In<T>` buffers (or of groups) with `#[derive(Buffers)]`, or `()`.
    type Input: Buffers + Default + Send + 'static;
    /// Readings sent to virtual effectors or receptors (`_y E`): a struct of
    /// `Out<T>` buffers (or of groups) with `#[derive(Buffers)]`, or `()`.
    type Output: Buffers + Default + Send + 'static;

    /// The names and types of the buffers, for spec export and checks: provided,
    /// from the descriptions of `Input` and `Output` ([`Shape::of_driver`]). Always
    /// `Some` (the `Option` is that of [`Subsystem::shape`], where it is optional).
    fn shape() -> Option<Shape> {
        Some(Shape::of_driver::<Self>())
    }

    /// How its buffers are found by name, for links made from a spec: provided,
    /// from the descriptions of `Input` and `Output` ([`PortTable::of`]).
    fn ports() -> Option<PortTable> {
        Some(PortTable::of::<Self::Input, Self::Output>())
    }

    /// Advance the device by one period: act on `input`, write readings to `output`.
    fn step(
        &mut self,
        ctx: DriverContext<'_>,
        input: &Self::Input,
        output: &mut Self::Output,
    ) -> Result<(), DriverError>;

    /// Bring the device to a safe state: called once when the run safe-stops
    /// ([`OnError::SafeStop`](crate::OnError::SafeStop)), before the driver's next
    /// step. Every subsystem is then halted, and the driver goes on stepping with
    /// the last commands its input buffers hold: a real effector should latch
    /// the safe state and hold it whatever they say (Rex's platform brakes and
    /// holds). The default does nothing (a receptor has no state to make safe).
    fn safe_stop(&mut self) {}
}

// Defined here rather than with `Shape`, so that descriptions do not depend on the
// component traits.
impl Shape {
    /// The shape of a subsystem whose memory, inputs and outputs are described.
    pub const fn of_subsystem<S>() -> Shape
    where
        S: Subsystem,
        S::Memory: Fields,
        S::Input: Buffers,
        S::Output: Buffers,
    {
        Shape {
            memory: Some(<S::Memory as Fields>::FIELDS),
            inputs: <S::Input as Buffers>::GROUPS,
            outputs: <S::Output as Buffers>::GROUPS,
        }
    }

    /// The shape of a driver (what [`Driver::shape`] returns): its input and output
    /// buffers, no memory.
    pub const fn of_driver<D: Driver + ?Sized>() -> Shape {
        Shape {
            memory: None,
            inputs: <D::Input as Buffers>::GROUPS,
            outputs: <D::Output as Buffers>::GROUPS,
        }
    }
}
