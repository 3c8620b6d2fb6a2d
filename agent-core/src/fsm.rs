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
use std::collections::HashMap;
use std::fmt;

use crate::behaviour::Behaviour;
use crate::error::{FsmBuildError, FsmError, FsmProblem};
use crate::expr::Expr;
use crate::kinds::BehaviourKind;
use crate::subsystem::Subsystem;
use crate::transition::Part;

type PredicateFn<S> =
    Box<dyn Fn(&<S as Subsystem>::Memory, &<S as Subsystem>::Input) -> bool + Send>;

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

struct Node<S: Subsystem> {
    behaviour: Behaviour<S>,
    terminal: Expr<usize>,
    /// The terminal condition is the constant `false`: the behaviour never ends.
    never_ends: bool,
    arcs: Vec<FsmArc>,
    is_final: bool,
}

/// Builds an [`Fsm`]; [`FsmBuilder::build`] checks it and reports every problem at once.
pub struct FsmBuilder<S: Subsystem> {
    predicates: Vec<Predicate<S>>,
    relations: Vec<Relation>,
    behaviours: Vec<Behaviour<S>>,
    arcs: Vec<(Cow<'static, str>, Cow<'static, str>, Cow<'static, str>)>,
    initial: Option<Cow<'static, str>>,
    finals: Vec<Cow<'static, str>>,
}

impl<S: Subsystem> Default for FsmBuilder<S> {
    fn default() -> Self {
        FsmBuilder {
            predicates: Vec::new(),
            relations: Vec::new(),
            behaviours: Vec::new(),
            arcs: Vec::new(),
            initial: None,
            finals: Vec::new(),
        }
    }
}

impl<S: Subsystem> FsmBuilder<S> {
    /// An empty builder.
    pub fn new() -> Self {
        Self::default()
    }

    /// Declare a named predicate usable in conditions.
    pub fn predicate<F>(mut self, name: impl Into<Cow<'static, str>>, f: F) -> Self
    where
        F: Fn(&S::Memory, &S::Input) -> bool + Send + 'static,
    {
        self.predicates.push(Predicate {
            name: name.into(),
            f: Box::new(f),
        });
        self
    }

    /// Declare that at most one of `predicates` holds at a time (an assumption of
    /// the arc proof, exported into specs; see [`Relation`]).
    pub fn exclusive<N: Into<Cow<'static, str>>>(
        mut self,
        predicates: impl IntoIterator<Item = N>,
    ) -> Self {
        self.relations.push(Relation::Exclusive(
            predicates.into_iter().map(Into::into).collect(),
        ));
        self
    }

    /// Declare that predicate `a` implies predicate `b` (see [`Relation`]).
    pub fn implies(
        mut self,
        a: impl Into<Cow<'static, str>>,
        b: impl Into<Cow<'static, str>>,
    ) -> Self {
        self.relations.push(Relation::Implies(a.into(), b.into()));
        self
    }

    /// Add a behaviour (a node).
    pub fn behaviour(mut self, behaviour: Behaviour<S>) -> Self {
        self.behaviours.push(behaviour);
        self
    }

    /// Name the initial behaviour.
    pub fn initial(mut self, name: impl Into<Cow<'static, str>>) -> Self {
        self.initial = Some(name.into());
        self
    }

    /// Add an arc `from -> to` labelled with an initial condition.
    pub fn arc(
        mut self,
        from: impl Into<Cow<'static, str>>,
        to: impl Into<Cow<'static, str>>,
        condition: impl Into<Cow<'static, str>>,
    ) -> Self {
        self.arcs.push((from.into(), to.into(), condition.into()));
        self
    }

    /// Declare a behaviour final: when it ends, the subsystem halts.
    pub fn final_behaviour(mut self, name: impl Into<Cow<'static, str>>) -> Self {
        self.finals.push(name.into());
        self
    }

    /// Check the FSM and build it.
    pub fn build(self) -> Result<Fsm<S>, FsmBuildError> {
        let mut problems = Vec::new();
        if self.behaviours.is_empty() {
            problems.push(FsmProblem::Empty);
        }
        let mut index: HashMap<&str, usize> = HashMap::new();
        for (i, b) in self.behaviours.iter().enumerate() {
            if index.insert(&b.name, i).is_some() {
                problems.push(FsmProblem::DuplicateBehaviour(b.name.to_string()));
            }
            for d in b.action.defects() {
                problems.push(FsmProblem::Action {
                    behaviour: b.name.to_string(),
                    message: d.clone(),
                });
            }
        }
        let mut preds: HashMap<&str, usize> = HashMap::new();
        for (i, p) in self.predicates.iter().enumerate() {
            if preds.insert(&p.name, i).is_some() {
                problems.push(FsmProblem::DuplicatePredicate(p.name.to_string()));
            }
        }
        for r in &self.relations {
            for name in r.names() {
                if !preds.contains_key(name) {
                    problems.push(FsmProblem::UnknownPredicate {
                        place: "a relation".into(),
                        name: name.to_owned(),
                    });
                }
            }
        }
        let terminals: Vec<Option<Expr<usize>>> = self
            .behaviours
            .iter()
            .map(|b| {
                resolve(
                    &preds,
                    &mut problems,
                    format!("terminal condition of `{}`", b.name),
                    &b.terminal,
                )
            })
            .collect();
        let mut arcs: Vec<Vec<FsmArc>> = self.behaviours.iter().map(|_| Vec::new()).collect();
        for (from, to, cond) in &self.arcs {
            let place = format!("arc `{from}` -> `{to}`");
            let f = index.get(from.as_ref()).copied();
            let t = index.get(to.as_ref()).copied();
            for (name, found) in [(from, f), (to, t)] {
                if found.is_none() {
                    problems.push(FsmProblem::UnknownBehaviour {
                        place: place.clone(),
                        name: name.to_string(),
                    });
                }
            }
            let condition = resolve(
                &preds,
                &mut problems,
                format!("initial condition of {place}"),
                cond,
            );
            if let (Some(f), Some(t), Some(condition)) = (f, t, condition) {
                arcs[f].push(FsmArc {
                    from: f,
                    to: t,
                    condition,
                    text: cond.clone(),
                });
            }
        }
        let mut is_final = vec![false; self.behaviours.len()];
        for name in &self.finals {
            match index.get(name.as_ref()) {
                Some(&i) => is_final[i] = true,
                None => problems.push(FsmProblem::UnknownBehaviour {
                    place: "a final declaration".into(),
                    name: name.to_string(),
                }),
            }
        }
        let initial = match &self.initial {
            None => {
                problems.push(FsmProblem::NoInitial);
                None
            }
            Some(name) => {
                let i = index.get(name.as_ref()).copied();
                if i.is_none() {
                    problems.push(FsmProblem::UnknownBehaviour {
                        place: "the initial declaration".into(),
                        name: name.to_string(),
                    });
                }
                i
            }
        };
        if let Some(start) = initial {
            let mut seen = vec![false; self.behaviours.len()];
            let mut stack = vec![start];
            seen[start] = true;
            while let Some(n) = stack.pop() {
                for a in &arcs[n] {
                    if !seen[a.to] {
                        seen[a.to] = true;
                        stack.push(a.to);
                    }
                }
            }
            for (i, b) in self.behaviours.iter().enumerate() {
                if !seen[i] {
                    problems.push(FsmProblem::Unreachable(b.name.to_string()));
                }
            }
        }
        for (i, b) in self.behaviours.iter().enumerate() {
            let never_ends = terminals[i].as_ref().is_some_and(Expr::is_const_false);
            if is_final[i] && !arcs[i].is_empty() {
                problems.push(FsmProblem::FinalWithArcs(b.name.to_string()));
            } else if !is_final[i] && arcs[i].is_empty() && !never_ends {
                problems.push(FsmProblem::NoWayOut(b.name.to_string()));
            }
        }
        if !problems.is_empty() {
            return Err(FsmBuildError { problems });
        }
        let (Some(initial), Some(terminals)) =
            (initial, terminals.into_iter().collect::<Option<Vec<_>>>())
        else {
            // Unreachable: every `None` above recorded a problem.
            return Err(FsmBuildError { problems });
        };
        let nodes = self
            .behaviours
            .into_iter()
            .zip(terminals)
            .zip(arcs)
            .zip(is_final)
            .map(|(((behaviour, terminal), arcs), is_final)| Node {
                behaviour,
                never_ends: terminal.is_const_false(),
                terminal,
                arcs,
                is_final,
            })
            .collect();
        Ok(Fsm {
            predicates: self.predicates,
            relations: self.relations,
            nodes,
            initial,
        })
    }
}

/// Parse `text` and resolve its predicate names, recording problems.
fn resolve(
    preds: &HashMap<&str, usize>,
    problems: &mut Vec<FsmProblem>,
    place: String,
    text: &str,
) -> Option<Expr<usize>> {
    let parsed = match Expr::parse(text) {
        Ok(e) => e,
        Err(error) => {
            problems.push(FsmProblem::Syntax { place, error });
            return None;
        }
    };
    let mut missing: Vec<String> = Vec::new();
    let resolved = parsed.try_map(&mut |name: &String| match preds.get(name.as_str()) {
        Some(&i) => Ok::<usize, ()>(i),
        None => {
            if !missing.contains(name) {
                missing.push(name.clone());
            }
            Ok(0)
        }
    });
    for name in &missing {
        problems.push(FsmProblem::UnknownPredicate {
            place: place.clone(),
            name: name.clone(),
        });
    }
    match resolved {
        Ok(e) if missing.is_empty() => Some(e),
        _ => None,
    }
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
pub struct Fsm<S: Subsystem> {
    predicates: Vec<Predicate<S>>,
    relations: Vec<Relation>,
    nodes: Vec<Node<S>>,
    initial: usize,
}

impl<S: Subsystem> fmt::Debug for Fsm<S> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Fsm")
            .field("behaviours", &self.nodes.len())
            .field("predicates", &self.predicates.len())
            .field("initial", &self.behaviour_name(self.initial))
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
        FsmState::entering(self.initial)
    }

    /// The state on entering behaviour `index` afresh, as when an arc into it is
    /// followed (`None` for an unknown index). The termination helpers start a
    /// behaviour this way.
    pub fn start_at(&self, index: usize) -> Option<FsmState> {
        (index < self.nodes.len()).then(|| FsmState::entering(index))
    }

    /// Number of behaviours.
    pub fn len(&self) -> usize {
        self.nodes.len()
    }

    /// Whether the FSM has no behaviour (never true for a built FSM).
    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// Index of the initial behaviour.
    pub fn initial(&self) -> usize {
        self.initial
    }

    /// The behaviour at `index`.
    pub fn behaviour(&self, index: usize) -> Option<&Behaviour<S>> {
        self.nodes.get(index).map(|n| &n.behaviour)
    }

    /// The name of the behaviour at `index` (`"?"` if out of range).
    pub fn behaviour_name(&self, index: usize) -> &str {
        self.nodes.get(index).map_or("?", |n| &n.behaviour.name)
    }

    /// The index of the behaviour called `name`.
    pub fn behaviour_index(&self, name: &str) -> Option<usize> {
        self.nodes.iter().position(|n| n.behaviour.name == name)
    }

    /// The arcs leaving behaviour `index`.
    pub fn arcs(&self, index: usize) -> &[FsmArc] {
        self.nodes.get(index).map_or(&[], |n| &n.arcs)
    }

    /// The resolved terminal condition of behaviour `index`.
    pub fn terminal(&self, index: usize) -> Option<&Expr<usize>> {
        self.nodes.get(index).map(|n| &n.terminal)
    }

    /// Whether the terminal condition of behaviour `index` holds (false for an
    /// unknown index).
    pub fn terminal_holds(&self, index: usize, memory: &S::Memory, input: &S::Input) -> bool {
        self.nodes
            .get(index)
            .is_some_and(|n| self.eval(&n.terminal, memory, input, &mut Memo::default()))
    }

    /// Whether behaviour `index` is declared final.
    pub fn is_final(&self, index: usize) -> bool {
        self.nodes.get(index).is_some_and(|n| n.is_final)
    }

    /// The declared predicates.
    pub fn predicates(&self) -> &[Predicate<S>] {
        &self.predicates
    }

    /// The declared relations between predicates.
    pub fn relations(&self) -> &[Relation] {
        &self.relations
    }

    /// What a spec says of this FSM: predicates, relations, behaviours with their
    /// parts, the initial behaviour, arcs and finals. The system builder records it,
    /// and `agent-spec` exports it.
    pub fn describe(&self) -> FsmShape {
        FsmShape {
            predicates: self.predicates.iter().map(|p| p.name.to_string()).collect(),
            relations: self.relations.clone(),
            behaviours: self
                .nodes
                .iter()
                .map(|n| BehaviourShape {
                    name: n.behaviour.name.to_string(),
                    kind: n.behaviour.kind,
                    terminal: n.behaviour.terminal.to_string(),
                    parts: n.behaviour.action.describe(),
                })
                .collect(),
            initial: self.behaviour_name(self.initial).to_owned(),
            arcs: self
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
                .nodes
                .iter()
                .filter(|n| n.is_final)
                .map(|n| n.behaviour.name.to_string())
                .collect(),
        }
    }

    #[inline]
    fn eval(&self, e: &Expr<usize>, m: &S::Memory, x: &S::Input, memo: &mut Memo) -> bool {
        e.eval(&mut |&i: &usize| memo.get(i, || self.predicates[i].holds(m, x)))
    }

    fn assignment(&self, m: &S::Memory, x: &S::Input) -> String {
        let parts: Vec<String> = self
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
        let node = &self.nodes[state.node];
        !node.never_ends
            && node.behaviour.kind.tests_terminal(state.actions_done)
            && self.eval(&node.terminal, memory, input, memo)
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
        let node = &self.nodes[from];
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
                Ok(Step::Entered { from, arc, to })
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
        mut on_step: impl FnMut(&Step),
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
                    if transitions >= self.nodes.len() {
                        return Err(FsmError::Livelock {
                            from: self.behaviour_name(start).to_owned(),
                            transitions,
                            path: format!("… -> `{}`", self.behaviour_name(state.node)),
                        }
                        .into());
                    }
                }
                Step::Finished => {
                    on_step(&Step::Finished);
                    return Ok(Activated::Halted);
                }
            }
        }
        self.act(state, memory, input, output)
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
        let node = &self.nodes[state.node];
        node.behaviour
            .action
            .compute(memory, input, output)
            .map_err(|source| FsmError::Action {
                behaviour: node.behaviour.name.to_string(),
                source,
            })?;
        state.actions_done = true;
        Ok(Activated::Ran {
            behaviour: state.node,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::buffer::{In, Out};
    use crate::kinds::{NodeKind, SubsystemKind};
    use crate::transition::{Action, PartTarget};
    use crate::{Group, Stamp, Time};

    struct S;
    #[derive(Default, Clone, Debug)]
    struct X {
        go: In<bool>,
        stop: In<bool>,
    }
    #[derive(Default, Debug)]
    struct Y {
        e: ToE,
    }
    #[derive(Default, Debug)]
    struct ToE {
        n: Out<u32>,
    }
    impl Group for ToE {
        const PEER: NodeKind = NodeKind::VirtualEffector;
    }
    impl Subsystem for S {
        const KIND: SubsystemKind = SubsystemKind::Control;
        type Memory = u32;
        type Input = X;
        type Output = Y;
    }

    fn count() -> Action<S> {
        Action::<S>::new()
            .memory(|m: &mut u32, _: &X| *m += 1)
            .output(|y| &mut y.e, |m: &u32, _: &X, y: &mut ToE| y.n.set(*m))
    }

    fn builder() -> FsmBuilder<S> {
        Fsm::builder()
            .predicate("go", |_, x: &X| x.go.get() == Some(&true))
            .predicate("stop", |_, x: &X| x.stop.get() == Some(&true))
            .predicate("three", |m: &u32, _| *m >= 3)
    }

    #[test]
    fn the_description_names_parts_relations_arcs_and_finals() {
        let fsm = builder()
            .exclusive(["go", "stop"])
            .implies("three", "go")
            .behaviour(Behaviour::repeat_loop(
                "run",
                count().named("tick").__at_field("e"),
                "three",
            ))
            .behaviour(Behaviour::while_loop("rest", Action::new(), "false"))
            .initial("run")
            .arc("run", "rest", "true")
            .build()
            .expect("a valid FSM");
        let d = fsm.describe();
        assert_eq!(d.predicates, ["go", "stop", "three"]);
        assert_eq!(d.relations.len(), 2);
        assert_eq!(d.relations[1].names(), ["three", "go"]);
        assert_eq!(d.initial, "run");
        assert_eq!(d.arcs, [("run".into(), "rest".into(), "true".into())]);
        assert!(d.finals.is_empty());
        let parts = &d.behaviours[0].parts;
        // `named` names the part added last (the output of `count`); the memory
        // part stays unnamed. Outputs come before the memory part, as they run.
        let names: Vec<_> = parts.iter().map(|p| p.name.as_deref()).collect();
        assert_eq!(names, [Some("tick"), None]);
        assert!(matches!(
            parts[0].target,
            PartTarget::Output {
                field: Some("e"),
                ..
            }
        ));
        assert_eq!(d.behaviours[1].kind, BehaviourKind::While);
    }

    #[test]
    fn relations_must_name_declared_predicates() {
        let err = builder()
            .exclusive(["go", "gone"])
            .behaviour(Behaviour::while_loop("rest", Action::new(), "false"))
            .initial("rest")
            .build()
            .expect_err("unknown predicate");
        assert_eq!(
            err.problems,
            [FsmProblem::UnknownPredicate {
                place: "a relation".into(),
                name: "gone".into()
            }]
        );
        let err = Fsm::<S>::builder()
            .behaviour(Behaviour::while_loop(
                "rest",
                Action::new().named("x"),
                "false",
            ))
            .initial("rest")
            .build()
            .expect_err("named before any part");
        assert!(matches!(&err.problems[0], FsmProblem::Action { .. }));
    }

    fn input(go: bool, stop: bool) -> X {
        let s = Stamp::new(0, Time::ZERO);
        X {
            go: In::new_value(go, s),
            stop: In::new_value(stop, s),
        }
    }

    #[test]
    fn while_tests_before_and_repeat_after() {
        let fsm = builder()
            .behaviour(Behaviour::while_loop("w", count(), "true"))
            .behaviour(Behaviour::repeat_loop("r", count(), "true"))
            .behaviour(Behaviour::while_loop("idle", Action::new(), "false"))
            .initial("w")
            .arc("w", "r", "true")
            .arc("r", "idle", "true")
            .build()
            .unwrap();
        let mut st = fsm.start();
        let (mut m, x, mut y) = (0u32, input(false, false), Y::default());
        let mut steps = Vec::new();
        // Activation 1: `w` ends before its first action (while-type); `r` runs once.
        let a = fsm
            .activate(&mut st, &mut m, &x, &mut y, |s| steps.push(*s))
            .unwrap();
        assert_eq!(a, Activated::Ran { behaviour: 1 });
        assert_eq!(m, 1);
        assert_eq!(
            steps,
            vec![Step::Entered {
                from: 0,
                arc: 0,
                to: 1
            }]
        );
        // Activation 2: `r` tests after its first action, ends, `idle` runs forever.
        let a = fsm.activate(&mut st, &mut m, &x, &mut y, |_| {}).unwrap();
        assert_eq!(a, Activated::Ran { behaviour: 2 });
        assert_eq!(m, 1, "idle's action does nothing");
    }

    #[test]
    fn ends_and_act_are_the_halves_of_activate() {
        let fsm = builder()
            .behaviour(Behaviour::while_loop("w", count(), "three"))
            .behaviour(Behaviour::repeat_loop("r", count(), "three"))
            .behaviour(Behaviour::while_loop("idle", count(), "false"))
            .initial("w")
            .arc("w", "r", "true")
            .arc("r", "idle", "true")
            .build()
            .unwrap();
        let x = input(false, false);
        assert_eq!(fsm.start_at(3), None);
        assert_eq!(fsm.start_at(0), Some(fsm.start()));
        // While-type: tested before the first action.
        let w = fsm.start_at(0).unwrap();
        assert!(fsm.ends(&w, &3, &x));
        assert!(!fsm.ends(&w, &2, &x));
        // Repeat-type: not tested before its first action, even if it would hold.
        let mut r = fsm.start_at(1).unwrap();
        assert!(!fsm.ends(&r, &3, &x));
        let mut probe = r;
        assert!(
            matches!(fsm.step(&mut probe, &3, &x), Ok(Step::Run)),
            "step agrees"
        );
        let (mut m, mut y) = (3u32, Y::default());
        assert_eq!(
            fsm.act(&mut r, &mut m, &x, &mut y).unwrap(),
            Activated::Ran { behaviour: 1 }
        );
        assert_eq!((m, y.e.n.written()), (4, Some(&3)), "the action ran once");
        assert!(
            r.actions_done() && r.behaviour() == 1,
            "act does not decide"
        );
        assert!(fsm.ends(&r, &m, &x));
        let mut probe = r;
        assert!(
            matches!(
                fsm.step(&mut probe, &m, &x),
                Ok(Step::Entered {
                    from: 1,
                    arc: 0,
                    to: 2
                })
            ),
            "step agrees"
        );
        // A behaviour whose terminal condition is `false` never ends.
        let mut i = fsm.start_at(2).unwrap();
        fsm.act(&mut i, &mut m, &x, &mut Y::default()).unwrap();
        assert!(!fsm.ends(&i, &m, &x));
        // Nothing runs in a halted FSM.
        i.halt();
        assert_eq!(
            fsm.act(&mut i, &mut m, &x, &mut Y::default()).unwrap(),
            Activated::Halted
        );
        assert_eq!(m, 5);
    }

    #[test]
    fn exactly_one_arc_must_hold() {
        let fsm = builder()
            .behaviour(Behaviour::repeat_loop("a", count(), "three"))
            .behaviour(Behaviour::while_loop("b", Action::new(), "false"))
            .behaviour(Behaviour::while_loop("c", Action::new(), "false"))
            .initial("a")
            .arc("a", "b", "go")
            .arc("a", "c", "stop")
            .build()
            .unwrap();
        let mut st = fsm.start();
        let mut m = 3;
        // The first activation of a repeat behaviour does not test: it runs.
        let a = fsm
            .activate(
                &mut st,
                &mut m,
                &input(false, false),
                &mut Y::default(),
                |_| {},
            )
            .unwrap();
        assert_eq!((a, m), (Activated::Ran { behaviour: 0 }, 4));
        // Now it ends, and no arc holds.
        let err = fsm
            .activate(
                &mut st,
                &mut m,
                &input(false, false),
                &mut Y::default(),
                |_| {},
            )
            .unwrap_err();
        let FsmError::NoArcHolds {
            behaviour,
            arcs,
            assignment,
        } = err
        else {
            panic!("expected NoArcHolds, got {err:?}");
        };
        assert_eq!(behaviour, "a");
        assert_eq!(arcs, "-> b [go], -> c [stop]");
        assert_eq!(assignment, "go=false, stop=false, three=true");
        // Several arcs hold.
        let err = fsm
            .activate(
                &mut st,
                &mut m,
                &input(true, true),
                &mut Y::default(),
                |_| {},
            )
            .unwrap_err();
        let FsmError::SeveralArcsHold { count, held, .. } = err else {
            panic!("expected SeveralArcsHold, got {err:?}");
        };
        assert_eq!((count, held.as_str()), (2, "-> b [go], -> c [stop]"));
        assert_eq!(st.behaviour(), 0, "a failed decision does not move the FSM");
        // Exactly one.
        let a = fsm
            .activate(
                &mut st,
                &mut m,
                &input(false, true),
                &mut Y::default(),
                |_| {},
            )
            .unwrap();
        assert_eq!(a, Activated::Ran { behaviour: 2 });
    }

    #[test]
    fn livelock_is_detected() {
        let fsm = builder()
            .behaviour(Behaviour::while_loop("a", Action::new(), "true"))
            .behaviour(Behaviour::while_loop("b", Action::new(), "true"))
            .initial("a")
            .arc("a", "b", "true")
            .arc("b", "a", "true")
            .build()
            .unwrap();
        let mut st = fsm.start();
        let err = fsm
            .activate(
                &mut st,
                &mut 0,
                &input(false, false),
                &mut Y::default(),
                |_| {},
            )
            .unwrap_err();
        assert!(
            matches!(err, FsmError::Livelock { transitions: 2, .. }),
            "{err:?}"
        );
    }

    #[test]
    fn final_behaviour_halts() {
        let fsm = builder()
            .behaviour(Behaviour::repeat_loop("once", count(), "true"))
            .initial("once")
            .final_behaviour("once")
            .build()
            .unwrap();
        let mut st = fsm.start();
        let mut m = 0;
        let x = input(false, false);
        assert_eq!(
            fsm.activate(&mut st, &mut m, &x, &mut Y::default(), |_| {})
                .unwrap(),
            Activated::Ran { behaviour: 0 }
        );
        let mut steps = vec![];
        assert_eq!(
            fsm.activate(&mut st, &mut m, &x, &mut Y::default(), |s| steps.push(*s))
                .unwrap(),
            Activated::Halted
        );
        assert_eq!(steps, vec![Step::Finished]);
        assert!(st.is_halted());
        assert_eq!(m, 1);
    }

    #[test]
    fn build_reports_every_problem() {
        let err = builder()
            .predicate("go", |_, _| true)
            .behaviour(Behaviour::while_loop("a", count(), "go && "))
            .behaviour(Behaviour::while_loop("a", count(), "false"))
            .behaviour(Behaviour::repeat_loop("lost", count(), "nope"))
            .behaviour(Behaviour::repeat_loop("dead_end", count(), "go"))
            .behaviour(Behaviour::repeat_loop(
                "twice",
                Action::<S>::new()
                    .memory(|_: &mut u32, _: &X| {})
                    .memory(|_: &mut u32, _: &X| {}),
                "false",
            ))
            .initial("a")
            .arc("a", "dead_end", "go")
            .arc("a", "nowhere", "stop")
            .arc("dead_end", "twice", "unknown_pred")
            .final_behaviour("ghost")
            .build()
            .unwrap_err();
        let text = err.to_string();
        for needle in [
            "behaviour `a` is defined twice",
            "predicate `go` is defined twice",
            "terminal condition of `a`",
            "uses predicate `nope`",
            "names behaviour `nowhere`",
            "uses predicate `unknown_pred`",
            "names behaviour `ghost`",
            "`lost` cannot be reached",
            "`dead_end` can end",
            "the memory part is set twice",
        ] {
            assert!(text.contains(needle), "missing {needle:?} in:\n{text}");
        }
    }
}
