//! The finite state machine of one subsystem: nodes are behaviours, arcs carry
//! initial conditions.
//!
//! When the current behaviour's terminal condition holds, exactly one outgoing arc's
//! initial condition must hold; the FSM follows it and the target behaviour starts in
//! the same activation. No arc or several arcs holding is an [`FsmError`], returned
//! with the predicate values that caused it: never a panic and never a silent choice.
//! Conditions are Boolean [`Expr`]essions over named predicates, each predicate
//! evaluated at most once per decision.

use std::borrow::Cow;
use std::fmt;
use std::sync::{Arc, OnceLock};

use crate::behaviour::Behaviour;
use crate::describe::Fresh;
use crate::error::{FsmBuildError, FsmError};
use crate::expr::Expr;
use crate::kinds::BehaviourKind;
use crate::subsystem::Subsystem;
use crate::transition::Part;

mod builder;
pub mod rules;

pub use builder::{FsmBuilder, FsmGraph};

type PredicateFn<S> =
    Box<dyn Fn(&<S as Subsystem>::Memory, &<S as Subsystem>::Input) -> bool + Send + Sync>;

/// A named predicate over memory and inputs: the atoms of initial and terminal
/// conditions (`f^σ`, `f^τ`).
pub struct Predicate<S: Subsystem> {
    name: Cow<'static, str>,
    f: PredicateFn<S>,
}

impl<S: Subsystem> Predicate<S> {
    /// The predicate's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// Evaluate it.
    pub fn holds(&self, memory: &S::Memory, input: &S::Input) -> bool {
        (self.f)(memory, input)
    }
}

/// A fact about predicates that the FSM's arcs rely on: the arc proof of the spec
/// checker (and of the `fsm!` macro) assumes it. The runtime does not: an arc choice
/// that a false relation makes ambiguous is still caught as an [`FsmError`].
///
/// In a spec (RON): `Exclusive(["a", "b"])`, `Implies("a", "b")`.
#[derive(Clone, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Relation {
    /// At most one of these predicates holds at a time.
    Exclusive(Vec<Cow<'static, str>>),
    /// If the first holds, so does the second.
    Implies(Cow<'static, str>, Cow<'static, str>),
}

impl Relation {
    /// The predicates it names.
    pub fn names(&self) -> Vec<&str> {
        match self {
            Relation::Exclusive(v) => v.iter().map(|n| n.as_ref()).collect(),
            Relation::Implies(a, b) => vec![a.as_ref(), b.as_ref()],
        }
    }
}

/// The description of one behaviour, for specs and diagrams.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BehaviourShape {
    /// Its name.
    pub name: String,
    /// While or repeat.
    pub kind: BehaviourKind,
    /// The terminal condition as written.
    pub terminal: String,
    /// The parts of its elementary action, in evaluation order.
    pub parts: Vec<Part>,
}

/// The description of an FSM: what a spec says of it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FsmShape {
    /// Predicate names, in declaration order.
    pub predicates: Vec<String>,
    /// Declared relations between predicates.
    pub relations: Vec<Relation>,
    /// The behaviours, by index.
    pub behaviours: Vec<BehaviourShape>,
    /// The initial behaviour.
    pub initial: String,
    /// The arcs as `(from, to, condition)`, grouped by source behaviour (in the
    /// order of the behaviours), in declaration order within each: the order that
    /// numbers them in traces.
    pub arcs: Vec<(String, String, String)>,
    /// The final behaviours.
    pub finals: Vec<String>,
}

/// An arc of the FSM.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FsmArc {
    /// Index of the source behaviour.
    pub from: usize,
    /// Index of the target behaviour.
    pub to: usize,
    /// The initial condition, resolved to predicate indices.
    pub condition: Expr<usize>,
    /// The initial condition as written.
    pub text: Cow<'static, str>,
}

/// What an action reads of its behaviour first (`never_ends`, the
/// behaviour's kind and its slice of parts), in the node's first 40 bytes:
/// one cache line more often than not.
#[repr(C)]
struct Node<S: Subsystem> {
    /// The terminal condition is the constant `false`: the behaviour never ends.
    never_ends: bool,
    is_final: bool,
    behaviour: Behaviour<S>,
    terminal: Expr<usize>,
    arcs: Vec<FsmArc>,
}

/// Where an FSM is: its current behaviour and whether an action of it already ran.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct FsmState {
    node: usize,
    actions_done: bool,
    halted: bool,
}

impl FsmState {
    /// Index of the current behaviour.
    pub fn behaviour(&self) -> usize {
        self.node
    }

    /// Whether the FSM ended in a final behaviour (or was halted by the executor).
    pub fn is_halted(&self) -> bool {
        self.halted
    }

    /// Whether at least one action of the current behaviour has run.
    pub fn actions_done(&self) -> bool {
        self.actions_done
    }

    pub(crate) fn halt(&mut self) {
        self.halted = true;
    }

    /// The state on entering behaviour `node` afresh: no action of it done yet.
    fn entering(node: usize) -> FsmState {
        FsmState {
            node,
            actions_done: false,
            halted: false,
        }
    }
}

/// The values of an FSM's predicates at one decision: bit `i` of `value` is
/// the value of predicate `i` (in [`FsmShape::predicates`] order) for every
/// predicate in `known`, which holds all of them, up to the first 64.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
pub struct Valuation {
    /// The predicates evaluated, as bits.
    pub known: u64,
    /// Their values, as bits.
    pub value: u64,
}

impl Valuation {
    /// The value of predicate `i`, if it was evaluated.
    pub fn get(&self, i: usize) -> Option<bool> {
        (i < 64 && self.known >> i & 1 == 1).then(|| self.value >> i & 1 == 1)
    }
}

/// One decision of the FSM (terminal test and, if the behaviour ends, arc selection).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Step {
    /// The current behaviour goes on: run its action.
    Run,
    /// The behaviour ended and the FSM followed arc number `arc` of `from` to `to`.
    Entered {
        /// Behaviour that ended.
        from: usize,
        /// Index of the arc among `from`'s outgoing arcs.
        arc: usize,
        /// Behaviour entered.
        to: usize,
        /// The value of every predicate at the decision (the terminal
        /// condition's and the arcs', and the others: predicates are pure, and
        /// a transition is when a recording wants them all).
        predicates: Valuation,
    },
    /// A final behaviour ended: the subsystem halts.
    Finished,
}

/// What one activation of a subsystem did.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Activated {
    /// The action of behaviour `behaviour` ran.
    Ran {
        /// Index of the behaviour whose action ran.
        behaviour: usize,
    },
    /// The FSM is halted (it ended in a final behaviour); nothing ran.
    Halted,
}

/// Memo of predicate values within one decision (up to 64 predicates are cached;
/// more are evaluated on each use).
#[derive(Default)]
struct Memo {
    known: u64,
    value: u64,
}

impl Memo {
    #[inline]
    fn get(&mut self, i: usize, f: impl FnOnce() -> bool) -> bool {
        if i >= 64 {
            return f();
        }
        let bit = 1u64 << i;
        if self.known & bit != 0 {
            return self.value & bit != 0;
        }
        let v = f();
        self.known |= bit;
        if v {
            self.value |= bit;
        }
        v
    }
}

/// The FSM of one subsystem: behaviours, predicates, arcs and the initial behaviour.
///
/// An FSM is immutable once built, and a handle to its definition: a clone
/// shares it (behaviours, their actions' functions, predicates), so that many
/// subsystems of one kind (the robots of a fleet, the copies of an agent in a
/// large graph) keep one copy, which an instant's actions then find in the
/// caches. Each subsystem keeps its own state ([`FsmState`]).
pub struct Fsm<S: Subsystem> {
    def: Arc<FsmDef<S>>,
}

impl<S: Subsystem> Clone for Fsm<S> {
    /// The same FSM, shared.
    fn clone(&self) -> Self {
        Fsm {
            def: Arc::clone(&self.def),
        }
    }
}

/// What an [`Fsm`] is, shared by its clones.
struct FsmDef<S: Subsystem> {
    predicates: Vec<Predicate<S>>,
    relations: Vec<Relation>,
    nodes: Vec<Node<S>>,
    initial: usize,
    /// Its description ([`Fsm::shape`]) and its behaviours' names
    /// ([`Fsm::behaviour_names`]), made once and shared by every subsystem
    /// it runs: each subsystem's [`NodeInfo`](crate::trace::NodeInfo) holds
    /// them, and ten thousand copies of an agent made ten thousand copies.
    described: OnceLock<(Arc<FsmShape>, Arc<[String]>)>,
}

impl<S: Subsystem> fmt::Debug for Fsm<S> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Fsm")
            .field("behaviours", &self.def.nodes.len())
            .field("predicates", &self.def.predicates.len())
            .field("initial", &self.behaviour_name(self.def.initial))
            .finish()
    }
}

impl<S: Subsystem> Fsm<S> {
    /// Start building an FSM.
    pub fn builder() -> FsmBuilder<S> {
        FsmBuilder::new()
    }

    /// An FSM of one behaviour that never ends (typical of virtual effectors and
    /// receptors). Its terminal condition must be `false`.
    pub fn single(behaviour: Behaviour<S>) -> Result<Fsm<S>, FsmBuildError> {
        let name = behaviour.name.clone();
        FsmBuilder::new().behaviour(behaviour).initial(name).build()
    }

    /// The state at the start: in the initial behaviour, no action done yet.
    pub fn start(&self) -> FsmState {
        FsmState::entering(self.def.initial)
    }

    /// The state on entering behaviour `index` afresh, as when an arc into it is
    /// followed (`None` for an unknown index). The termination helpers start a
    /// behaviour this way.
    pub fn start_at(&self, index: usize) -> Option<FsmState> {
        (index < self.def.nodes.len()).then(|| FsmState::entering(index))
    }

    /// Number of behaviours.
    pub fn len(&self) -> usize {
        self.def.nodes.len()
    }

    /// Whether the FSM has no behaviour (never true for a built FSM).
    pub fn is_empty(&self) -> bool {
        self.def.nodes.is_empty()
    }

    /// Index of the initial behaviour.
    pub fn initial(&self) -> usize {
        self.def.initial
    }

    /// The behaviour at `index`.
    pub fn behaviour(&self, index: usize) -> Option<&Behaviour<S>> {
        self.def.nodes.get(index).map(|n| &n.behaviour)
    }

    /// The name of the behaviour at `index` (`"?"` if out of range).
    pub fn behaviour_name(&self, index: usize) -> &str {
        self.def.nodes.get(index).map_or("?", |n| &n.behaviour.name)
    }

    /// The index of the behaviour called `name`.
    pub fn behaviour_index(&self, name: &str) -> Option<usize> {
        self.def.nodes.iter().position(|n| n.behaviour.name == name)
    }

    /// The arcs leaving behaviour `index`.
    pub fn arcs(&self, index: usize) -> &[FsmArc] {
        self.def.nodes.get(index).map_or(&[], |n| &n.arcs)
    }

    /// The resolved terminal condition of behaviour `index`.
    pub fn terminal(&self, index: usize) -> Option<&Expr<usize>> {
        self.def.nodes.get(index).map(|n| &n.terminal)
    }

    /// Whether the terminal condition of behaviour `index` holds (false for an
    /// unknown index).
    pub fn terminal_holds(&self, index: usize, memory: &S::Memory, input: &S::Input) -> bool {
        self.def
            .nodes
            .get(index)
            .is_some_and(|n| self.eval(&n.terminal, memory, input, &mut Memo::default()))
    }

    /// Whether behaviour `index` is declared final.
    pub fn is_final(&self, index: usize) -> bool {
        self.def.nodes.get(index).is_some_and(|n| n.is_final)
    }

    /// The declared predicates.
    pub fn predicates(&self) -> &[Predicate<S>] {
        &self.def.predicates
    }

    /// The declared relations between predicates.
    pub fn relations(&self) -> &[Relation] {
        &self.def.relations
    }

    /// [`Fsm::describe`], made once and shared by this FSM's clones.
    pub fn shape(&self) -> Arc<FsmShape> {
        Arc::clone(&self.described().0)
    }

    /// The behaviours' names, by index, made once and shared by this FSM's
    /// clones.
    pub fn behaviour_names(&self) -> Arc<[String]> {
        Arc::clone(&self.described().1)
    }

    fn described(&self) -> &(Arc<FsmShape>, Arc<[String]>) {
        self.def.described.get_or_init(|| {
            let names = self.def.nodes.iter();
            let names = names.map(|n| n.behaviour.name.to_string()).collect();
            (Arc::new(self.describe()), names)
        })
    }

    /// What a spec says of this FSM: predicates, relations, behaviours with their
    /// parts, the initial behaviour, arcs and finals. The system builder records it
    /// (once an FSM: [`Fsm::shape`]), and `agent-spec` exports it.
    pub fn describe(&self) -> FsmShape {
        FsmShape {
            predicates: self
                .def
                .predicates
                .iter()
                .map(|p| p.name.to_string())
                .collect(),
            relations: self.def.relations.clone(),
            behaviours: self
                .def
                .nodes
                .iter()
                .map(|n| BehaviourShape {
                    name: n.behaviour.name.to_string(),
                    kind: n.behaviour.kind,
                    terminal: n.behaviour.terminal.to_string(),
                    parts: n.behaviour.action.describe(),
                })
                .collect(),
            initial: self.behaviour_name(self.def.initial).to_owned(),
            arcs: self
                .def
                .nodes
                .iter()
                .flat_map(|n| n.arcs.iter())
                .map(|a| {
                    (
                        self.behaviour_name(a.from).to_owned(),
                        self.behaviour_name(a.to).to_owned(),
                        a.text.to_string(),
                    )
                })
                .collect(),
            finals: self
                .def
                .nodes
                .iter()
                .filter(|n| n.is_final)
                .map(|n| n.behaviour.name.to_string())
                .collect(),
        }
    }

    #[inline]
    fn eval(&self, e: &Expr<usize>, m: &S::Memory, x: &S::Input, memo: &mut Memo) -> bool {
        e.eval(&mut |&i: &usize| memo.get(i, || self.def.predicates[i].holds(m, x)))
    }

    fn assignment(&self, m: &S::Memory, x: &S::Input) -> String {
        let parts: Vec<String> = self
            .def
            .predicates
            .iter()
            .map(|p| format!("{}={}", p.name, p.holds(m, x)))
            .collect();
        if parts.is_empty() {
            "none declared".into()
        } else {
            parts.join(", ")
        }
    }

    fn arc_label(&self, a: &FsmArc) -> String {
        format!("-> {} [{}]", self.behaviour_name(a.to), a.text)
    }

    /// Whether the current behaviour ends now: its terminal condition is tested at
    /// this point (before every iteration for while-type; for repeat-type only once
    /// an action of it ran) and holds. This is the first half of [`Fsm::step`], the
    /// same code; it selects no arc and does not move the FSM.
    #[inline]
    pub fn ends(&self, state: &FsmState, memory: &S::Memory, input: &S::Input) -> bool {
        self.ends_with(state, memory, input, &mut Memo::default())
    }

    #[inline]
    fn ends_with(
        &self,
        state: &FsmState,
        memory: &S::Memory,
        input: &S::Input,
        memo: &mut Memo,
    ) -> bool {
        let node = &self.def.nodes[state.node];
        !node.never_ends
            && node.behaviour.kind.tests_terminal(state.actions_done)
            && self.eval(&node.terminal, memory, input, memo)
    }

    /// The values of the predicates of `wanted` (bit `i`: predicate `i`, the
    /// first 64) on `memory` and `input`: what an observer that judges
    /// invariants is given after an activation
    /// ([`Observer::predicates`](crate::Observer::predicates)).
    pub fn valuation(&self, wanted: u64, memory: &S::Memory, input: &S::Input) -> Valuation {
        let mut v = Valuation::default();
        for (i, p) in self.def.predicates.iter().enumerate().take(64) {
            let bit = 1u64 << i;
            if wanted & bit != 0 {
                v.known |= bit;
                if p.holds(memory, input) {
                    v.value |= bit;
                }
            }
        }
        v
    }

    /// One decision: test the current behaviour's terminal condition (before every
    /// iteration for while-type, after each iteration for repeat-type; see
    /// [`Fsm::ends`]) and, if it holds, select the one arc whose initial condition
    /// holds.
    #[inline]
    pub fn step(
        &self,
        state: &mut FsmState,
        memory: &S::Memory,
        input: &S::Input,
    ) -> Result<Step, FsmError> {
        let from = state.node;
        let mut memo = Memo::default();
        if !self.ends_with(state, memory, input, &mut memo) {
            return Ok(Step::Run);
        }
        let node = &self.def.nodes[from];
        let mut chosen = None;
        let mut count = 0usize;
        for (i, a) in node.arcs.iter().enumerate() {
            if self.eval(&a.condition, memory, input, &mut memo) {
                count += 1;
                chosen.get_or_insert(i);
            }
        }
        match (count, chosen) {
            (1, Some(arc)) => {
                let to = node.arcs[arc].to;
                *state = FsmState::entering(to);
                for i in 0..self.def.predicates.len().min(64) {
                    memo.get(i, || self.def.predicates[i].holds(memory, input));
                }
                Ok(Step::Entered {
                    from,
                    arc,
                    to,
                    predicates: Valuation {
                        known: memo.known,
                        value: memo.value,
                    },
                })
            }
            (0, _) if node.is_final => {
                state.halted = true;
                Ok(Step::Finished)
            }
            (0, _) => Err(FsmError::NoArcHolds {
                behaviour: node.behaviour.name.to_string(),
                arcs: node
                    .arcs
                    .iter()
                    .map(|a| self.arc_label(a))
                    .collect::<Vec<_>>()
                    .join(", "),
                assignment: self.assignment(memory, input),
            }),
            _ => Err(FsmError::SeveralArcsHold {
                behaviour: node.behaviour.name.to_string(),
                count,
                held: node
                    .arcs
                    .iter()
                    .filter(|a| self.eval(&a.condition, memory, input, &mut Memo::default()))
                    .map(|a| self.arc_label(a))
                    .collect::<Vec<_>>()
                    .join(", "),
                assignment: self.assignment(memory, input),
            }),
        }
    }

    /// One activation after the inputs were read: FSM decisions ([`Fsm::step`]) until
    /// a behaviour goes on (at most one transition per behaviour), then that
    /// behaviour's elementary action ([`Fsm::act`]). `on_step` sees every transition.
    /// This is what the executor runs for a subsystem and what the termination helper
    /// `testing::Termination::returns_to` runs; `testing::Termination::behaviour`
    /// calls its two halves instead, [`Fsm::ends`] and [`Fsm::act`], to stay in one
    /// behaviour.
    pub fn activate(
        &self,
        state: &mut FsmState,
        memory: &mut S::Memory,
        input: &S::Input,
        output: &mut S::Output,
        on_step: impl FnMut(&Step),
    ) -> Result<Activated, FsmError> {
        self.activate_by(state, memory, input, output, on_step, |action, m, x, y| {
            action.compute(m, x, y)
        })
    }

    /// [`Fsm::activate`] with the action observed part by part
    /// ([`Action::compute_audited`](crate::Action::compute_audited)): `seen(part,
    /// reads, writes)` after each part of the action that runs.
    pub fn activate_audited(
        &self,
        state: &mut FsmState,
        memory: &mut S::Memory,
        input: &S::Input,
        output: &mut S::Output,
        on_step: impl FnMut(&Step),
        seen: &mut dyn FnMut(usize, Fresh, Fresh),
    ) -> Result<Activated, FsmError> {
        self.activate_by(state, memory, input, output, on_step, |action, m, x, y| {
            action.compute_audited(m, x, y, seen)
        })
    }

    /// The decisions of an activation, then `compute` runs the action of the
    /// behaviour that goes on: one body for [`Fsm::activate`] (the executor's hot
    /// path, so always inlined) and [`Fsm::activate_audited`].
    #[inline(always)]
    fn activate_by(
        &self,
        state: &mut FsmState,
        memory: &mut S::Memory,
        input: &S::Input,
        output: &mut S::Output,
        mut on_step: impl FnMut(&Step),
        compute: impl FnOnce(
            &crate::Action<S>,
            &mut S::Memory,
            &S::Input,
            &mut S::Output,
        ) -> Result<(), crate::ActionError>,
    ) -> Result<Activated, FsmError> {
        if state.halted {
            return Ok(Activated::Halted);
        }
        let start = state.node;
        let mut transitions = 0;
        loop {
            match self.step(state, memory, input)? {
                Step::Run => break,
                step @ Step::Entered { .. } => {
                    on_step(&step);
                    transitions += 1;
                    if transitions >= self.def.nodes.len() {
                        return Err(self.livelock(start, transitions, state));
                    }
                }
                Step::Finished => {
                    on_step(&Step::Finished);
                    return Ok(Activated::Halted);
                }
            }
        }
        self.run_action(state, memory, input, output, compute)
    }

    /// The action of the current behaviour (not halted), by `compute`, and the
    /// record that an action of it ran: the end of [`Fsm::activate`] and of
    /// [`Fsm::act`].
    #[inline(always)]
    fn run_action(
        &self,
        state: &mut FsmState,
        memory: &mut S::Memory,
        input: &S::Input,
        output: &mut S::Output,
        compute: impl FnOnce(
            &crate::Action<S>,
            &mut S::Memory,
            &S::Input,
            &mut S::Output,
        ) -> Result<(), crate::ActionError>,
    ) -> Result<Activated, FsmError> {
        let node = &self.def.nodes[state.node];
        compute(&node.behaviour.action, memory, input, output).map_err(|source| {
            FsmError::Action {
                behaviour: node.behaviour.name.to_string(),
                source,
            }
        })?;
        state.actions_done = true;
        Ok(Activated::Ran {
            behaviour: state.node,
        })
    }

    /// The livelock error: `transitions` without an action, from `start`.
    #[cold]
    fn livelock(&self, start: usize, transitions: usize, state: &FsmState) -> FsmError {
        FsmError::Livelock {
            from: self.behaviour_name(start).to_owned(),
            transitions,
            path: format!("… -> `{}`", self.behaviour_name(state.node)),
        }
    }

    /// One iteration of the current behaviour, without any decision: run its
    /// elementary action and record that an action of it ran (from now on a
    /// repeat-type behaviour tests its terminal condition). The second half of
    /// [`Fsm::activate`], the same code. Nothing runs in a halted FSM.
    #[inline]
    pub fn act(
        &self,
        state: &mut FsmState,
        memory: &mut S::Memory,
        input: &S::Input,
        output: &mut S::Output,
    ) -> Result<Activated, FsmError> {
        if state.halted {
            return Ok(Activated::Halted);
        }
        self.run_action(state, memory, input, output, |action, m, x, y| {
            action.compute(m, x, y)
        })
    }
}

#[cfg(test)]
mod tests;
