//! [`FsmBuilder`]: an FSM declared piece by piece, checked as a whole (the shape
//! rules of [`rules`](super::rules), conditions resolved, actions well formed).

use std::borrow::Cow;
use std::collections::HashMap;
use std::sync::Arc;

use super::rules::{self, Place, ShapeProblem};
use super::{Fsm, FsmArc, FsmDef, Node, Predicate, Relation};
use crate::behaviour::Behaviour;
use crate::error::{FsmBuildError, FsmProblem};
use crate::expr::Expr;
use crate::subsystem::Subsystem;

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
        F: Fn(&S::Memory, &S::Input) -> bool + Send + Sync + 'static,
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
        self.check_behaviours(&mut problems);
        let preds = self.index_predicates(&mut problems);
        let terminals = self.resolve_terminals(&preds, &mut problems);
        let conditions = self.resolve_arc_conditions(&preds, &mut problems);
        let shape = self.check_shape(&terminals, &mut problems);
        if !problems.is_empty() {
            return Err(FsmBuildError { problems });
        }
        let (Some(initial), Some(terminals), Some(conditions)) = (
            shape.initial,
            terminals.into_iter().collect::<Option<Vec<_>>>(),
            conditions.into_iter().collect::<Option<Vec<_>>>(),
        ) else {
            // Unreachable: every `None` above recorded a problem.
            return Err(FsmBuildError { problems });
        };
        Ok(self.assemble(initial, shape, terminals, conditions))
    }

    /// Record an empty FSM, duplicate behaviour names and ill-formed actions.
    fn check_behaviours(&self, problems: &mut Vec<FsmProblem>) {
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
    }

    /// The predicates' indices by name, recording duplicates and relations
    /// that name an unknown predicate.
    fn index_predicates(&self, problems: &mut Vec<FsmProblem>) -> HashMap<&str, usize> {
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
        preds
    }

    /// Each behaviour's terminal condition, parsed and resolved (`None` where
    /// a problem was recorded).
    fn resolve_terminals(
        &self,
        preds: &HashMap<&str, usize>,
        problems: &mut Vec<FsmProblem>,
    ) -> Vec<Option<Expr<usize>>> {
        self.behaviours
            .iter()
            .map(|b| {
                resolve(
                    preds,
                    problems,
                    format!("terminal condition of `{}`", b.name),
                    &b.terminal,
                )
            })
            .collect()
    }

    /// Each arc's initial condition, parsed and resolved (`None` where a
    /// problem was recorded).
    fn resolve_arc_conditions(
        &self,
        preds: &HashMap<&str, usize>,
        problems: &mut Vec<FsmProblem>,
    ) -> Vec<Option<Expr<usize>>> {
        self.arcs
            .iter()
            .map(|(from, to, cond)| {
                let place = format!("initial condition of arc `{from}` -> `{to}`");
                resolve(preds, problems, place, cond)
            })
            .collect()
    }

    /// The graph resolved by the shape rules (shared with the spec checker),
    /// recording their problems and each behaviour that can end with no way out.
    fn check_shape(
        &self,
        terminals: &[Option<Expr<usize>>],
        problems: &mut Vec<FsmProblem>,
    ) -> rules::Resolved {
        let graph = rules::Graph {
            behaviours: self.behaviours.iter().map(|b| b.name.as_ref()).collect(),
            initial: self.initial.as_deref(),
            arcs: self
                .arcs
                .iter()
                .map(|(f, t, _)| (f.as_ref(), t.as_ref()))
                .collect(),
            finals: self.finals.iter().map(AsRef::as_ref).collect(),
        };
        let (shape, broken) = graph.check();
        for p in broken {
            problems.push(self.shape_problem(p));
        }
        for (b, behaviour) in self.behaviours.iter().enumerate() {
            let never_ends = terminals[b].as_ref().is_some_and(Expr::is_const_false);
            if shape.lacks_way_out(b, !never_ends) {
                problems.push(FsmProblem::NoWayOut(behaviour.name.to_string()));
            }
        }
        shape
    }

    /// A shape rule's problem in the builder's terms (names, not indices).
    fn shape_problem(&self, problem: ShapeProblem) -> FsmProblem {
        match problem {
            ShapeProblem::NoInitial => FsmProblem::NoInitial,
            ShapeProblem::UnknownBehaviour { place, name } => FsmProblem::UnknownBehaviour {
                place: match place {
                    Place::Initial => "the initial declaration".to_owned(),
                    Place::ArcFrom(k) | Place::ArcTo(k) => {
                        let (from, to, _) = &self.arcs[k];
                        format!("arc `{from}` -> `{to}`")
                    }
                    Place::Final(_) => "a final declaration".to_owned(),
                },
                name,
            },
            ShapeProblem::Unreachable(b) => {
                FsmProblem::Unreachable(self.behaviours[b].name.to_string())
            }
            ShapeProblem::FinalWithArcs(b) => {
                FsmProblem::FinalWithArcs(self.behaviours[b].name.to_string())
            }
        }
    }

    /// The checked FSM: each behaviour a node with its resolved terminal
    /// condition and its outgoing arcs.
    fn assemble(
        self,
        initial: usize,
        shape: rules::Resolved,
        terminals: Vec<Expr<usize>>,
        conditions: Vec<Expr<usize>>,
    ) -> Fsm<S> {
        let mut arcs: Vec<Vec<FsmArc>> = self.behaviours.iter().map(|_| Vec::new()).collect();
        for (((_, _, text), condition), ends) in
            self.arcs.into_iter().zip(conditions).zip(shape.arcs)
        {
            if let Some((from, to)) = ends {
                arcs[from].push(FsmArc {
                    from,
                    to,
                    condition,
                    text,
                });
            }
        }
        let nodes = self
            .behaviours
            .into_iter()
            .zip(terminals)
            .zip(arcs)
            .zip(shape.finals)
            .map(|(((behaviour, terminal), arcs), is_final)| Node {
                behaviour,
                never_ends: terminal.is_const_false(),
                terminal,
                arcs,
                is_final,
            })
            .collect();
        Fsm {
            def: Arc::new(FsmDef {
                predicates: self.predicates,
                relations: self.relations,
                nodes,
                initial,
                described: std::sync::OnceLock::new(),
            }),
        }
    }
}

/// The graph of an FSM as text, as a spec writes it: what
/// [`Fsm::regraph`] puts in place of the code's.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct FsmGraph {
    /// The initial behaviour.
    pub initial: String,
    /// The arcs `(from, to, initial condition)`, in order.
    pub arcs: Vec<(String, String, String)>,
    /// The terminal condition of each behaviour, by name (a behaviour not
    /// named keeps its own).
    pub terminals: Vec<(String, String)>,
    /// The final behaviours.
    pub finals: Vec<String>,
}

impl<S: Subsystem> Fsm<S> {
    /// The same behaviours (actions) and predicates, with the graph `graph`:
    /// its initial behaviour, arcs, terminal conditions and finals, checked as
    /// [`FsmBuilder::build`] checks any FSM. This is how a spec drives the
    /// FSM of code that supplies the actions and predicates: an edited arc in
    /// the spec is an edited arc in the running system.
    ///
    /// An FSM that already has the graph is returned as it is, shared or not
    /// (a clone of a regraphed FSM for another subsystem with the same graph).
    /// Otherwise its behaviours move into the new one, so it must not be
    /// shared (no clone of it alive: [`FsmProblem::Shared`] otherwise).
    pub fn regraph(self, graph: &FsmGraph) -> Result<Fsm<S>, FsmBuildError> {
        if self.has_graph(graph) {
            return Ok(self);
        }
        let mut problems = Vec::new();
        let def = Arc::try_unwrap(self.def).map_err(|_| FsmBuildError {
            problems: vec![FsmProblem::Shared],
        })?;
        let mut behaviours: Vec<Behaviour<S>> =
            def.nodes.into_iter().map(|n| n.behaviour).collect();
        for (name, terminal) in &graph.terminals {
            match behaviours.iter_mut().find(|b| b.name == name.as_str()) {
                Some(b) => b.terminal = Cow::Owned(terminal.clone()),
                None => problems.push(FsmProblem::UnknownBehaviour {
                    place: "the graph's terminal conditions".to_owned(),
                    name: name.clone(),
                }),
            }
        }
        if !problems.is_empty() {
            return Err(FsmBuildError { problems });
        }
        FsmBuilder {
            predicates: def.predicates,
            relations: def.relations,
            behaviours,
            arcs: graph
                .arcs
                .iter()
                .map(|(f, t, c)| (f.clone().into(), t.clone().into(), c.clone().into()))
                .collect(),
            initial: Some(graph.initial.clone().into()),
            finals: graph.finals.iter().map(|f| f.clone().into()).collect(),
        }
        .build()
    }
}

impl<S: Subsystem> Fsm<S> {
    /// Whether the FSM's graph is `graph`: its initial behaviour, each
    /// behaviour's arcs in order with their initial conditions, the terminal
    /// conditions `graph` names and the final behaviours, the conditions
    /// compared as resolved (not as written).
    pub fn has_graph(&self, graph: &FsmGraph) -> bool {
        let def = &self.def;
        let preds: HashMap<&str, usize> = (def.predicates.iter().enumerate())
            .map(|(i, p)| (p.name.as_ref(), i))
            .collect();
        let condition = |text: &str| resolve(&preds, &mut Vec::new(), String::new(), text);
        let index = |name: &str| def.nodes.iter().position(|n| n.behaviour.name == name);
        if index(&graph.initial) != Some(def.initial) {
            return false;
        }
        let mut finals: Vec<Option<usize>> = graph.finals.iter().map(|f| index(f)).collect();
        finals.sort_unstable();
        finals.dedup();
        let own: Vec<Option<usize>> = (def.nodes.iter().enumerate())
            .filter(|(_, n)| n.is_final)
            .map(|(i, _)| Some(i))
            .collect();
        if finals != own {
            return false;
        }
        let terminals_equal = graph.terminals.iter().all(|(name, text)| {
            index(name).is_some_and(|b| condition(text).as_ref() == Some(&def.nodes[b].terminal))
        });
        let arcs_equal = def.nodes.iter().enumerate().all(|(b, node)| {
            let name = node.behaviour.name.as_ref();
            let mut given = graph.arcs.iter().filter(|(from, _, _)| from == name);
            node.arcs.iter().all(|arc| {
                given.next().is_some_and(|(_, to, when)| {
                    index(to) == Some(arc.to)
                        && arc.from == b
                        && condition(when).as_ref() == Some(&arc.condition)
                })
            }) && given.next().is_none()
        });
        terminals_equal && arcs_equal
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
    match rules::resolve_condition(&parsed, |name| preds.get(name).copied()) {
        Ok(e) => Some(e),
        Err(unknown) => {
            problems.extend(
                unknown
                    .into_iter()
                    .map(|name| FsmProblem::UnknownPredicate {
                        place: place.clone(),
                        name,
                    }),
            );
            None
        }
    }
}
