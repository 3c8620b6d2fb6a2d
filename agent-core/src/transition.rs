//! Transition functions, decomposed by the buffer they write, and the elementary
//! action they parameterise (Algorithm 1 of the paper).
//!
//! A subsystem's transition function `f` maps `(memory^ι, inputs^ι)` to
//! `(memory^ι+1, outputs^ι+1)`. The paper decomposes it by target: `f_{c,c}`
//! writes the memory, `f_{c,e}` the outputs towards the virtual effector, `f_{c,T}`
//! the transmission buffers towards another agent, and so on. An [`Action`] is
//! assembled from such parts:
//!
//! * [`Action::output`] takes a *target* (a projection `&mut Output -> &mut G` onto
//!   one [`Group`]) and a function that receives `&mut G` only, so the compiler
//!   rejects a write to any other buffer;
//! * [`Action::memory`] takes the function that computes the next memory;
//! * [`Action::common`] (optional) computes intermediate results shared by several
//!   parts (a solver's solution both stored in memory and sent as a command).
//!
//! Order of evaluation within one action: `common`, then every output part (each
//! sees the memory as `common` left it), then the memory part. Since `common` is a
//! function of `(memory^ι, inputs^ι)`, every output is still a function of
//! `(memory^ι, inputs^ι)`, as in the paper: outputs are computed from the memory of
//! the current iteration, the memory part alone produces `memory^ι+1`.

use std::any::TypeId;
use std::borrow::Cow;
use std::fmt;

use crate::buffer::Group;
use crate::describe::Fresh;
use crate::error::ActionError;
use crate::kinds::NodeKind;
use crate::subsystem::Subsystem;

/// What a transition function may return: `()` when it cannot fail, or
/// `Result<(), E>` for any `E` convertible into [`ActionError`].
#[diagnostic::on_unimplemented(
    message = "a transition function must return `()` or `Result<(), E>` with `E: Into<ActionError>`, not `{Self}`"
)]
pub trait Outcome {
    /// Convert into the runtime's result type.
    fn into_result(self) -> Result<(), ActionError>;
}

impl Outcome for () {
    #[inline]
    fn into_result(self) -> Result<(), ActionError> {
        Ok(())
    }
}

impl<E: Into<ActionError>> Outcome for Result<(), E> {
    #[inline]
    fn into_result(self) -> Result<(), ActionError> {
        self.map_err(Into::into)
    }
}

/// One part of an action as the executor runs it: every part (common, output,
/// memory) behind one signature, so that an action's parts lie in one
/// contiguous slice of 16-byte entries in evaluation order. What a part may
/// write is fixed where it is made ([`Action::output`] gives its function
/// `&Memory` and one group only).
type PartFn<S> = Box<
    dyn Fn(
            &mut <S as Subsystem>::Memory,
            &<S as Subsystem>::Input,
            &mut <S as Subsystem>::Output,
        ) -> Result<(), ActionError>
        + Send
        + Sync,
>;

/// The description of an output part (cold: read by the builder and the
/// descriptions, never by an action).
struct OutputPart {
    target: TypeId,
    target_name: &'static str,
    peer: NodeKind,
    field: Option<&'static str>,
    name: Option<Cow<'static, str>>,
}

/// The description of the common or the memory part.
struct MemoryPart {
    name: Option<Cow<'static, str>>,
}

/// Which part [`Action::named`] names.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Last {
    None,
    Common,
    Output,
    Memory,
}

/// Description of one part of a transition function, for specs and diagrams.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum PartTarget {
    /// Computes intermediate results into the memory (evaluated first).
    Common,
    /// Writes the group `group` (a type name) towards a peer of kind `peer`.
    Output {
        /// Type name of the group.
        group: &'static str,
        /// Kind of the component the group is connected to.
        peer: NodeKind,
        /// The field of the output struct that holds the group, when known (the
        /// `fsm!` macro records it; by hand the projection closure hides it).
        field: Option<&'static str>,
    },
    /// Computes the next memory (evaluated last).
    Memory,
}

/// One part of an action as described for specs and diagrams: its name, if it was
/// given one ([`Action::named`]), and what it writes.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Part {
    /// The transition function's name (`stop_pump`), if known.
    pub name: Option<Cow<'static, str>>,
    /// What it writes.
    pub target: PartTarget,
}

/// An elementary action `A_{j,m}(f_{j,m})`: the decomposed transition function of one
/// behaviour. The executor supplies the rest of Algorithm 1 (send, wait, read).
#[repr(C)]
pub struct Action<S: Subsystem> {
    /// The parts' functions in evaluation order: the common part's (if
    /// any), the output parts' in the order they were added, the memory
    /// part's (if any). The only field an action's evaluation reads, first
    /// (the behaviour and the FSM's node are `repr(C)` too).
    run: Vec<PartFn<S>>,
    common: Option<MemoryPart>,
    outputs: Vec<OutputPart>,
    memory: Option<MemoryPart>,
    last: Last,
    defects: Vec<String>,
}

impl<S: Subsystem> Default for Action<S> {
    fn default() -> Self {
        Action {
            run: Vec::new(),
            common: None,
            outputs: Vec::new(),
            memory: None,
            last: Last::None,
            defects: Vec::new(),
        }
    }
}

impl<S: Subsystem> fmt::Debug for Action<S> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.parts()).finish()
    }
}

impl<S: Subsystem> Action<S> {
    /// An action that computes nothing (the subsystem just waits for one period).
    pub fn new() -> Self {
        Self::default()
    }

    /// Add the part `f_{·,target}` that writes the output group selected by `target`.
    ///
    /// ```
    /// # use agent_core::*;
    /// # struct Ctl;
    /// # #[derive(Default)] struct Input { level: In<f64> }
    /// # #[derive(Default)] struct Output { to_valve: ToValve }
    /// #[derive(Default)]
    /// struct ToValve { flow: Out<f64> }
    /// impl Group for ToValve { const PEER: NodeKind = NodeKind::VirtualEffector; }
    /// # impl Subsystem for Ctl { const KIND: SubsystemKind = SubsystemKind::Control;
    /// #   type Memory = f64; type Input = Input; type Output = Output; }
    ///
    /// // f_{c,e}: may write `ToValve` and nothing else.
    /// fn open_valve(target: &f64, x: &Input, y: &mut ToValve) -> Result<(), ActionError> {
    ///     let level = x.level.require()?;
    ///     y.flow.set((target - level).clamp(0.0, 1.0));
    ///     Ok(())
    /// }
    /// let action = Action::<Ctl>::new().output(|y| &mut y.to_valve, open_valve);
    /// ```
    ///
    /// # What the types guarantee, and what they do not
    ///
    /// `f` receives the memory as `&S::Memory`, the inputs as `&S::Input` and one
    /// group as `&mut G`: it cannot write another output group, nor the memory
    /// (only [`Action::memory`] and [`Action::common`] may). The examples below share
    /// one subsystem `Ctl` (memory `f64`) whose outputs are two groups,
    /// `Output { to_e: ToE, to_t: ToT }`: `ToE { flow: Out<f64> }` towards a virtual
    /// effector and `ToT { ack: Out<bool> }` towards another agent.
    ///
    /// **The projection is not checked.** `target` is user code too, and it receives
    /// the whole output struct, so the type system cannot stop it from writing other
    /// groups before returning its own. This compiles, and sends an acknowledgement
    /// from a part that is listed as writing `ToE` only:
    ///
    /// ```
    /// # use agent_core::*;
    /// # struct Ctl;
    /// # #[derive(Default)] struct Input { level: In<f64> }
    /// # #[derive(Default)] struct ToE { flow: Out<f64> }
    /// # impl Group for ToE { const PEER: NodeKind = NodeKind::VirtualEffector; }
    /// # #[derive(Default)] struct ToT { ack: Out<bool> }
    /// # impl Group for ToT { const PEER: NodeKind = NodeKind::Control; }
    /// # #[derive(Default)] struct Output { to_e: ToE, to_t: ToT }
    /// # impl Subsystem for Ctl { const KIND: SubsystemKind = SubsystemKind::Control;
    /// #   type Memory = f64; type Input = Input; type Output = Output; }
    /// let sneaky = Action::<Ctl>::new().output(
    ///     |y| {
    ///         y.to_t.ack.set(true); // not prevented: keep projections to `|y| &mut y.field`
    ///         &mut y.to_e
    ///     },
    ///     |m: &f64, _: &Input, y: &mut ToE| y.flow.set(*m),
    /// );
    /// # let mut y = Output::default();
    /// # sneaky.compute(&mut 0.5, &Input::default(), &mut y).unwrap();
    /// # assert_eq!(y.to_t.ack.written(), Some(&true));
    /// ```
    ///
    /// Keep every projection a plain field selection, `|y| &mut y.field` (or a path
    /// of fields), so that each part writes exactly its target. Likewise, a memory
    /// with interior mutability (`Cell`, `RefCell`, atomics, `Mutex`) can be changed
    /// through `&S::Memory`: keep such types out of a subsystem's memory.
    ///
    /// **`f` cannot write another group.** A part `f_{c,e}` that also writes the
    /// transmission buffer towards the other agent (`f_{c,T}`'s target) does not
    /// compile, because `f` only sees `ToE`:
    ///
    /// ```compile_fail,E0609
    /// # use agent_core::*;
    /// # struct Ctl;
    /// # #[derive(Default)] struct Input { level: In<f64> }
    /// # #[derive(Default)] struct ToE { flow: Out<f64> }
    /// # impl Group for ToE { const PEER: NodeKind = NodeKind::VirtualEffector; }
    /// # #[derive(Default)] struct ToT { ack: Out<bool> }
    /// # impl Group for ToT { const PEER: NodeKind = NodeKind::Control; }
    /// # #[derive(Default)] struct Output { to_e: ToE, to_t: ToT }
    /// # impl Subsystem for Ctl { const KIND: SubsystemKind = SubsystemKind::Control;
    /// #   type Memory = f64; type Input = Input; type Output = Output; }
    /// let action = Action::<Ctl>::new().output(
    ///     |y| &mut y.to_e,
    ///     |m: &f64, _: &Input, y: &mut ToE| {
    ///         y.flow.set(*m);
    ///         y.to_t.ack.set(true); // error[E0609]: no field `to_t` on type `&mut ToE`
    ///     },
    /// );
    /// ```
    ///
    /// **`f` cannot change the memory.** It gets `&Memory`; only the memory and common
    /// parts get `&mut Memory`:
    ///
    /// ```compile_fail,E0594
    /// # use agent_core::*;
    /// # struct Ctl;
    /// # #[derive(Default)] struct Input { level: In<f64> }
    /// # #[derive(Default)] struct ToE { flow: Out<f64> }
    /// # impl Group for ToE { const PEER: NodeKind = NodeKind::VirtualEffector; }
    /// # #[derive(Default)] struct ToT { ack: Out<bool> }
    /// # impl Group for ToT { const PEER: NodeKind = NodeKind::Control; }
    /// # #[derive(Default)] struct Output { to_e: ToE, to_t: ToT }
    /// # impl Subsystem for Ctl { const KIND: SubsystemKind = SubsystemKind::Control;
    /// #   type Memory = f64; type Input = Input; type Output = Output; }
    /// let action = Action::<Ctl>::new().output(
    ///     |y| &mut y.to_e,
    ///     |m: &f64, _: &Input, y: &mut ToE| {
    ///         y.flow.set(*m);
    ///         *m += 1.0; // error[E0594]: cannot assign to `*m`, which is behind a `&` reference
    ///     },
    /// );
    /// ```
    ///
    /// Without the marked line, each of these two parts compiles (it is the
    /// `|m: &f64, _: &Input, y: &mut ToE| y.flow.set(*m)` of the first example).
    pub fn output<G, P, F, R>(mut self, target: P, f: F) -> Self
    where
        G: Group,
        P: for<'a> Fn(&'a mut S::Output) -> &'a mut G + Send + Sync + 'static,
        F: Fn(&S::Memory, &S::Input, &mut G) -> R + Send + Sync + 'static,
        R: Outcome,
    {
        let id = TypeId::of::<G>();
        let target_name = short_type_name::<G>();
        if self.outputs.iter().any(|p| p.target == id) {
            self.defects.push(format!(
                "two transition functions write the same target `{target_name}`"
            ));
        }
        // After the common part and the output parts before it, before the
        // memory part.
        let at = usize::from(self.common.is_some()) + self.outputs.len();
        self.run.insert(
            at,
            Box::new(move |m, x, y| f(m, x, target(y)).into_result()),
        );
        self.outputs.push(OutputPart {
            target: id,
            target_name,
            peer: G::PEER,
            field: None,
            name: fn_name::<F>(),
        });
        self.last = Last::Output;
        self
    }

    /// Set the memory part `f_{·,·}`: computes `memory^ι+1` in place from
    /// `memory^ι` and the inputs. It runs after every output part.
    pub fn memory<F, R>(mut self, f: F) -> Self
    where
        F: Fn(&mut S::Memory, &S::Input) -> R + Send + Sync + 'static,
        R: Outcome,
    {
        let part: PartFn<S> = Box::new(move |m, x, _| f(m, x).into_result());
        if self.memory.is_some() {
            self.defects.push("the memory part is set twice".to_owned());
            // The second replaces the first, last in evaluation order.
            self.run.pop();
        }
        self.run.push(part);
        self.memory = Some(MemoryPart {
            name: fn_name::<F>(),
        });
        self.last = Last::Memory;
        self
    }

    /// Set the common part: intermediate results shared by several parts, stored in
    /// memory before the output parts run.
    pub fn common<F, R>(mut self, f: F) -> Self
    where
        F: Fn(&mut S::Memory, &S::Input) -> R + Send + Sync + 'static,
        R: Outcome,
    {
        let part: PartFn<S> = Box::new(move |m, x, _| f(m, x).into_result());
        if self.common.is_some() {
            self.defects.push("the common part is set twice".to_owned());
            // The second replaces the first, first in evaluation order.
            if let Some(first) = self.run.first_mut() {
                *first = part;
            }
        } else {
            self.run.insert(0, part);
        }
        self.common = Some(MemoryPart {
            name: fn_name::<F>(),
        });
        self.last = Last::Common;
        self
    }

    /// Name the part added last, as the transition function is named in a spec
    /// (`.output(|y| &mut y.pump, stop_pump).named("stop_pump")`). Names are only
    /// descriptions: they appear in exported specs and diagrams.
    pub fn named(mut self, name: impl Into<Cow<'static, str>>) -> Self {
        let name = Some(name.into());
        match self.last {
            Last::None => self
                .defects
                .push("`named` is called before any part was added".to_owned()),
            Last::Common => {
                if let Some(p) = &mut self.common {
                    p.name = name;
                }
            }
            Last::Memory => {
                if let Some(p) = &mut self.memory {
                    p.name = name;
                }
            }
            Last::Output => {
                if let Some(p) = self.outputs.last_mut() {
                    p.name = name;
                }
            }
        }
        self
    }

    /// Record the output field written by the output part added last (the `fsm!`
    /// macro calls it with the field it projects to).
    #[doc(hidden)]
    pub fn __at_field(mut self, field: &'static str) -> Self {
        if let (Last::Output, Some(p)) = (self.last, self.outputs.last_mut()) {
            p.field = Some(field);
        }
        self
    }

    /// Evaluate the transition function once: `common`, the output parts in the order
    /// they were added, then the memory part. Stops at the first error.
    #[inline]
    pub fn compute(
        &self,
        memory: &mut S::Memory,
        input: &S::Input,
        output: &mut S::Output,
    ) -> Result<(), ActionError> {
        for f in &self.run {
            f(memory, input, output)?;
        }
        Ok(())
    }

    /// [`Action::compute`], observed part by part: before each part the marks of
    /// the inputs read are cleared, after it `seen(k, reads, writes)` gets the
    /// index `k` of the part (the order of [`Action::describe`]), the inputs it
    /// read and the outputs it wrote ([`Subsystem::audit`]; memory is not
    /// observed). What `ExecConfig::audit` runs.
    pub fn compute_audited(
        &self,
        memory: &mut S::Memory,
        input: &S::Input,
        output: &mut S::Output,
        seen: &mut dyn FnMut(usize, Fresh, Fresh),
    ) -> Result<(), ActionError> {
        let mut k = 0;
        let mut written = S::audit(input, output).1;
        let mut observe = |k: &mut usize, output: &S::Output| {
            let (reads, now) = S::audit(input, output);
            seen(*k, reads, Fresh(now.0 & !written.0));
            written = now;
            *k += 1;
        };
        for f in &self.run {
            let _ = S::audit(input, output);
            f(memory, input, output)?;
            observe(&mut k, output);
        }
        Ok(())
    }

    /// The targets of the parts of this action, in evaluation order.
    pub fn parts(&self) -> Vec<PartTarget> {
        self.describe().into_iter().map(|p| p.target).collect()
    }

    /// The parts of this action with their names, in evaluation order.
    pub fn describe(&self) -> Vec<Part> {
        let mut v = Vec::new();
        if let Some(c) = &self.common {
            v.push(Part {
                name: c.name.clone(),
                target: PartTarget::Common,
            });
        }
        v.extend(self.outputs.iter().map(|p| Part {
            name: p.name.clone(),
            target: PartTarget::Output {
                group: p.target_name,
                peer: p.peer,
                field: p.field,
            },
        }));
        if let Some(m) = &self.memory {
            v.push(Part {
                name: m.name.clone(),
                target: PartTarget::Memory,
            });
        }
        v
    }

    /// Problems found while assembling the action (the FSM builder reports them).
    pub(crate) fn defects(&self) -> &[String] {
        &self.defects
    }
}

/// The name of a function item, as a spec names a transition function: the last
/// segment of its path (`rex_agent::c1::cT_1_tp` is `cT_1_tp`). A closure has no
/// name of its own (`None`: it is named after its behaviour and target, or by
/// [`Action::named`]).
fn fn_name<F>() -> Option<Cow<'static, str>> {
    let path = std::any::type_name::<F>();
    if path.contains('{') || path.contains('<') || path.contains('(') {
        return None;
    }
    path.rsplit("::").next().map(Cow::Borrowed)
}

/// `a::b::Name<c::D>` -> `Name<D>`.
pub(crate) fn short_type_name<T: ?Sized>() -> &'static str {
    let full = std::any::type_name::<T>();
    let base = full.split('<').next().unwrap_or(full);
    match base.rfind("::") {
        Some(i) if !full.contains('<') => &full[i + 2..],
        _ => full,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::buffer::{In, Out};
    use crate::kinds::SubsystemKind;

    struct S;
    #[derive(Default)]
    struct X {
        a: In<i32>,
    }
    #[derive(Default, Debug)]
    struct ToE {
        cmd: Out<i32>,
    }
    impl Group for ToE {
        const PEER: NodeKind = NodeKind::VirtualEffector;
    }
    #[derive(Default, Debug)]
    struct ToT {
        ack: Out<bool>,
    }
    impl Group for ToT {
        const PEER: NodeKind = NodeKind::Control;
    }
    #[derive(Default, Debug)]
    struct Y {
        e: ToE,
        t: ToT,
    }
    impl Subsystem for S {
        const KIND: SubsystemKind = SubsystemKind::Control;
        type Memory = Vec<i32>;
        type Input = X;
        type Output = Y;
    }

    #[test]
    fn outputs_see_the_old_memory_and_memory_part_runs_last() {
        // Like Algorithms 6 and 7: f_{c,e} sends the first element of the list that
        // f_{c,c} removes in the same iteration.
        let action = Action::<S>::new()
            .memory(|m: &mut Vec<i32>, _x: &X| {
                m.remove(0);
            })
            .output(
                |y| &mut y.e,
                |m: &Vec<i32>, _x: &X, y: &mut ToE| y.cmd.set(m[0]),
            );
        let mut mem = vec![10, 20];
        let mut y = Y::default();
        action.compute(&mut mem, &X::default(), &mut y).unwrap();
        assert_eq!(y.e.cmd.written(), Some(&10));
        assert_eq!(mem, vec![20]);
        assert!(!y.t.ack.is_written());
    }

    #[test]
    fn common_part_runs_first() {
        let action = Action::<S>::new()
            .common(|m: &mut Vec<i32>, _x: &X| m.push(5))
            .output(
                |y| &mut y.e,
                |m: &Vec<i32>, _x: &X, y: &mut ToE| y.cmd.set(m.iter().sum()),
            );
        let mut mem = vec![1];
        let mut y = Y::default();
        action.compute(&mut mem, &X::default(), &mut y).unwrap();
        assert_eq!(y.e.cmd.written(), Some(&6));
    }

    #[test]
    fn errors_stop_the_action() {
        let action = Action::<S>::new()
            .output(
                |y| &mut y.e,
                |_m: &Vec<i32>, x: &X, y: &mut ToE| {
                    y.cmd.set(*x.a.require()?);
                    Ok::<(), ActionError>(())
                },
            )
            .memory(|m: &mut Vec<i32>, _x: &X| m.push(1));
        let mut mem = vec![];
        let err = action
            .compute(&mut mem, &X::default(), &mut Y::default())
            .unwrap_err();
        assert!(matches!(
            err,
            ActionError::Buffer(crate::BufferError::NoData { .. })
        ));
        assert!(mem.is_empty(), "the memory part did not run");
    }

    #[test]
    fn parts_run_common_outputs_memory_whatever_order_they_were_added_in() {
        // Each part appends its mark to the memory or (outputs) writes the
        // memory's length: the order they ran in.
        let action = Action::<S>::new()
            .memory(|m: &mut Vec<i32>, _x: &X| m.push(8))
            .output(
                |y| &mut y.t,
                |m: &Vec<i32>, _x: &X, y: &mut ToT| y.ack.set(m == &[1]),
            )
            .memory(|m: &mut Vec<i32>, _x: &X| m.push(9))
            .common(|m: &mut Vec<i32>, _x: &X| m.push(0))
            .output(
                |y| &mut y.e,
                |m: &Vec<i32>, _x: &X, y: &mut ToE| y.cmd.set(m.len() as i32),
            )
            .common(|m: &mut Vec<i32>, _x: &X| m.push(1));
        // The second memory and common parts replace the first ones.
        assert_eq!(action.defects().len(), 2);
        assert_eq!(action.parts().len(), 4);
        assert_eq!(action.parts()[0], PartTarget::Common);
        assert_eq!(action.parts()[3], PartTarget::Memory);
        let mut mem = vec![];
        let mut y = Y::default();
        action.compute(&mut mem, &X::default(), &mut y).unwrap();
        assert_eq!(mem, vec![1, 9]);
        assert_eq!(y.t.ack.written(), Some(&true));
        assert_eq!(y.e.cmd.written(), Some(&1));
        // Audited, the same order, each part observed once.
        let mut mem = vec![];
        let mut y = Y::default();
        let mut seen = Vec::new();
        action
            .compute_audited(&mut mem, &X::default(), &mut y, &mut |k, _, _| seen.push(k))
            .unwrap();
        assert_eq!(mem, vec![1, 9]);
        assert_eq!(seen, vec![0, 1, 2, 3]);
    }

    #[test]
    fn duplicate_targets_are_defects() {
        let action = Action::<S>::new()
            .output(|y| &mut y.t, |_: &Vec<i32>, _: &X, _: &mut ToT| {})
            .output(|y| &mut y.t, |_: &Vec<i32>, _: &X, _: &mut ToT| {});
        assert_eq!(action.defects().len(), 1);
        assert!(action.defects()[0].contains("ToT"));
        assert_eq!(
            action.parts(),
            vec![
                PartTarget::Output {
                    group: "ToT",
                    peer: NodeKind::Control,
                    field: None,
                };
                2
            ]
        );
    }
}
