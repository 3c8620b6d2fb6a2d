//! A subsystem's FSM: the shape rules (agent-core's) with spans, and the arc proof.

use super::*;

/// What the proof of one subsystem's behaviours works from.
struct Graph<'s> {
    base: &'s [Seg<'static>],
    sub: &'s Subsystem,
    /// The relations as assumptions.
    relations: Vec<Expr<usize>>,
    /// Whether every relation named declared predicates only.
    relations_resolve: bool,
    shape: rules::Resolved,
    /// Per behaviour, its outgoing arcs with their conditions (`None`: did not
    /// resolve, reported).
    arcs: Vec<Vec<(usize, Option<Expr<usize>>)>>,
}

impl<'a> Checker<'a> {
    /// The FSM of `sub`: its relations, shape and arc conditions, then for each
    /// behaviour whose terminal condition resolved, its ways out and arc proof.
    pub(super) fn fsm(
        &mut self,
        base: &[Seg<'static>],
        sub: &Subsystem,
        preds: &HashMap<&str, usize>,
        terminals: &[Option<Expr<usize>>],
        used: &mut HashSet<usize>,
    ) {
        let (relations, relations_resolve) = self.relations(base, sub, preds, used);
        let shape = self.shape_rules(base, sub);
        let arcs = self.arc_conditions(base, sub, preds, &shape, used);
        let graph = Graph {
            base,
            sub,
            relations,
            relations_resolve,
            shape,
            arcs,
        };
        for (i, terminal) in terminals.iter().enumerate() {
            let Some(terminal) = terminal else {
                continue;
            };
            if !self.prove {
                continue;
            }
            self.ways_out(&graph, i, terminal);
        }
    }

    /// The relations as assumptions of the arc proof, and whether they all
    /// resolved. If one names an undeclared predicate (reported here), the arc
    /// proof would miss an assumption and report arcs that the relation may well
    /// make sound: it is skipped, like the proof of arcs whose conditions do not
    /// resolve.
    fn relations(
        &mut self,
        base: &[Seg<'static>],
        sub: &Subsystem,
        preds: &HashMap<&str, usize>,
        used: &mut HashSet<usize>,
    ) -> (Vec<Expr<usize>>, bool) {
        let at = |rest: &[Seg<'static>]| join(base, rest);
        let mut relations = Vec::new();
        let mut relations_resolve = true;
        for (i, r) in sub.relations.iter().enumerate() {
            // Paths to each name: `Exclusive([a, b, ...])` is a variant holding a list,
            // `Implies(a, b)` a variant holding two strings.
            let names: Vec<(&std::borrow::Cow<'static, str>, Path)> = match r {
                Relation::Exclusive(v) => v
                    .iter()
                    .enumerate()
                    .map(|(k, n)| (n, at(&[F("relations"), I(i), I(0), I(k)])))
                    .collect(),
                Relation::Implies(a, b) => vec![
                    (a, at(&[F("relations"), I(i), I(0)])),
                    (b, at(&[F("relations"), I(i), I(1)])),
                ],
            };
            let mut ok = Vec::new();
            for (n, path) in &names {
                match preds.get(n.as_ref()) {
                    Some(&p) => {
                        used.insert(p);
                        ok.push(p);
                    }
                    None => {
                        relations_resolve = false;
                        self.unknown_relation_predicate(sub, n, path);
                    }
                }
            }
            if ok.len() == names.len() {
                assume(r, &ok, &mut relations);
            }
        }
        (relations, relations_resolve)
    }

    /// A relation names predicate `name`, which is not declared.
    fn unknown_relation_predicate(&mut self, sub: &Subsystem, name: &str, path: &Path) {
        let known = self.list(&sub.predicates, Hint::Predicates, || {
            sorted(sub.predicates.iter().map(|p| p.name.clone()))
        });
        let guess = self.guess(name, sub.predicates.iter().map(|p| p.name.as_str()));
        self.push(
            Finding::new(
                Code::UnknownPredicate,
                self.span(path),
                "not declared",
                format!("relation names predicate `{name}`, which is not declared"),
            )
            .help(format!(
                "{guess}relations are between predicates declared under `predicates`; declared: {known}"
            )),
        );
    }

    /// The shape rules (agent-core's, shared with `FsmBuilder`), each problem
    /// reported with its span; the graph they resolved.
    fn shape_rules(&mut self, base: &[Seg<'static>], sub: &Subsystem) -> rules::Resolved {
        let graph = rules::Graph {
            behaviours: sub.behaviours.iter().map(|b| b.name.as_str()).collect(),
            initial: sub.fsm.initial.as_deref(),
            arcs: sub
                .fsm
                .arcs
                .iter()
                .map(|a| (a.from.as_str(), a.to.as_str()))
                .collect(),
            finals: sub.fsm.finals.iter().map(String::as_str).collect(),
        };
        let (shape, broken) = graph.check();
        for problem in broken {
            self.shape_problem(base, sub, &shape, problem);
        }
        shape
    }

    /// The finding of one problem of the FSM's shape.
    fn shape_problem(
        &mut self,
        base: &[Seg<'static>],
        sub: &Subsystem,
        shape: &rules::Resolved,
        problem: ShapeProblem,
    ) {
        let at = |rest: &[Seg<'static>]| join(base, rest);
        match problem {
            ShapeProblem::NoInitial => self.push(
                Finding::new(
                    Code::NoInitial,
                    self.key_span(&at(&[F("fsm")])),
                    "no `initial`",
                    format!("the FSM of `{}` has no initial behaviour", sub.name),
                )
                .help("add `initial: \"<behaviour>\"` to `fsm`"),
            ),
            ShapeProblem::UnknownBehaviour { place, name } => {
                let (path, what) = match place {
                    Place::Initial => (at(&[F("fsm"), F("initial")]), "the initial declaration"),
                    Place::ArcFrom(k) => (at(&[F("fsm"), F("arcs"), I(k), F("from")]), "an arc"),
                    Place::ArcTo(k) => (at(&[F("fsm"), F("arcs"), I(k), F("to")]), "an arc"),
                    Place::Final(k) => (at(&[F("fsm"), F("finals"), I(k)]), "a final declaration"),
                };
                self.unknown_behaviour(sub, &name, path, what);
            }
            ShapeProblem::Unreachable(i) => {
                let start = shape.initial.map_or("", |s| sub.behaviours[s].name.as_str());
                self.push(
                    Finding::new(
                        Code::Unreachable,
                        self.span(&at(&[F("behaviours"), I(i), F("name")])),
                        "unreachable",
                        format!(
                            "behaviour `{}` of `{}` cannot be reached from `{start}`",
                            sub.behaviours[i].name, sub.name
                        ),
                    )
                    .help("add an arc into it, or remove it"),
                );
            }
            ShapeProblem::FinalWithArcs(i) => self.push(
                Finding::new(
                    Code::FinalWithArcs,
                    self.span(&at(&[F("behaviours"), I(i), F("name")])),
                    "declared final",
                    format!(
                        "behaviour `{}` is declared final but has outgoing arcs",
                        sub.behaviours[i].name
                    ),
                )
                .help("a final behaviour halts the subsystem when it ends; remove the arcs or the final declaration"),
            ),
        }
    }

    /// `place` (at `path`) names behaviour `name`, which `sub` does not define.
    fn unknown_behaviour(&mut self, sub: &Subsystem, name: &str, path: Path, place: &str) {
        let known = self.list(&sub.behaviours, Hint::Behaviours, || {
            sub.behaviours.iter().map(|b| b.name.clone()).collect()
        });
        let guess = self.guess(name, sub.behaviours.iter().map(|b| b.name.as_str()));
        self.push(
            Finding::new(
                Code::UnknownBehaviour,
                self.span(&path),
                "no such behaviour",
                format!(
                    "{place} names behaviour `{name}`, which `{}` does not define",
                    sub.name
                ),
            )
            .help(format!("{guess}behaviours: {known}")),
        );
    }

    /// Each arc's condition resolved (reporting those that do not), by the
    /// behaviour it leaves, for the proof.
    fn arc_conditions(
        &mut self,
        base: &[Seg<'static>],
        sub: &Subsystem,
        preds: &HashMap<&str, usize>,
        shape: &rules::Resolved,
        used: &mut HashSet<usize>,
    ) -> Vec<Vec<(usize, Option<Expr<usize>>)>> {
        let mut arcs: Vec<Vec<(usize, Option<Expr<usize>>)>> =
            vec![Vec::new(); sub.behaviours.len()];
        for (k, arc) in sub.fsm.arcs.iter().enumerate() {
            let apath = join(base, &[F("fsm"), F("arcs"), I(k)]);
            let cond = self.condition(sub, &arc.when, preds, &join(&apath, &[F("when")]), used);
            if let Some((f, _)) = shape.arcs[k] {
                arcs[f].push((k, cond));
            }
        }
        arcs
    }

    /// Behaviour `i` (whose terminal condition resolved to `terminal`): its
    /// terminal condition can hold, it has a way out when it does, and the arcs
    /// leaving it are exclusive and complete (proven when each condition and
    /// relation resolved, and the behaviour is not final).
    fn ways_out(&mut self, g: &Graph<'_>, i: usize, terminal: &Expr<usize>) {
        let (sub, arcs) = (g.sub, &g.arcs[i]);
        let b = &sub.behaviours[i];
        let at = |rest: &[Seg<'static>]| join(g.base, rest);
        let name_span = self.span(&at(&[F("behaviours"), I(i), F("name")]));
        let literal_false = b.terminal.trim() == "false";
        let conds: Vec<(usize, &Expr<usize>)> = arcs
            .iter()
            .filter_map(|(k, c)| c.as_ref().map(|c| (*k, c)))
            .collect();
        let prove_arcs = !arcs.is_empty()
            && conds.len() == arcs.len()
            && g.relations_resolve
            && !g.shape.finals[i];
        let mut assumed: Vec<&Expr<usize>> = g.relations.iter().collect();
        assumed.push(terminal);
        let question = Question {
            predicates: sub.predicates.len(),
            assumed,
            arcs: if prove_arcs {
                conds.iter().map(|(_, c)| *c).collect()
            } else {
                Vec::new()
            },
        };
        let answer = proof::answer(&question, &mut self.budget);
        let can_end = answer.can_end.unwrap_or(true);
        let tpath = at(&[F("behaviours"), I(i), F("terminal")]);
        let runs_forever = literal_false && arcs.is_empty();
        if answer.can_end == Some(false) && !runs_forever {
            self.push(
                Finding::new(
                    Code::TerminalNever,
                    self.span(&tpath),
                    "never holds",
                    format!("the terminal condition of `{}` can never hold{}", b.name, if arcs.is_empty() { "" } else { ", so its arcs are never taken" }),
                )
                .help("a behaviour with a constant-false terminal condition runs forever; write `false` if that is meant"),
            );
        }
        if arcs.is_empty() {
            if g.shape.lacks_way_out(i, can_end) {
                self.push(
                    Finding::new(
                        Code::NoWayOut,
                        name_span,
                        "no outgoing arc",
                        format!("behaviour `{}` can end (terminal `{}`) but has no outgoing arc and is not final", b.name, abbreviate(&b.terminal, 80)),
                    )
                    .help("add an arc from it, declare it in `fsm.finals`, or make its terminal condition `false`"),
                );
            }
            return;
        }
        if prove_arcs {
            self.arc_findings(sub, g.base, i, &conds, &answer);
        }
    }

    /// The findings of the arc proof for behaviour `b`: arcs that can hold at once,
    /// a case no arc covers (each with the assignment), questions the budget left
    /// undecided.
    pub(super) fn arc_findings(
        &mut self,
        sub: &Subsystem,
        base: &[Seg<'static>],
        b: usize,
        conds: &[(usize, &Expr<usize>)],
        answer: &proof::Answer,
    ) {
        let arc_span =
            |this: &Self, k: usize| this.span(&join(base, &[F("fsm"), F("arcs"), I(k), F("when")]));
        let bname = &sub.behaviours[b].name;
        let terminal = abbreviate(&sub.behaviours[b].terminal, 80);
        let used = |w: &Witness| render_assignment(sub, w);
        for (x, y, w) in &answer.overlaps {
            let (ax, ay) = (&sub.fsm.arcs[conds[*x].0], &sub.fsm.arcs[conds[*y].0]);
            let assignment = used(w);
            self.push(
                Finding::new(
                    Code::ArcsOverlap,
                    arc_span(self, conds[*y].0),
                    format!("holds when {assignment}"),
                    format!(
                        "arcs `{bname} -> {}` and `{bname} -> {}` can hold at once (when {assignment}, with terminal `{terminal}`)",
                        ax.to, ay.to
                    ),
                )
                .label(arc_span(self, conds[*x].0), "this one holds too")
                .help("when a behaviour ends exactly one arc must hold: strengthen a condition, or declare the predicates `Exclusive` under `relations` if they cannot hold together"),
            );
        }
        if let Some(w) = &answer.gap {
            let assignment = used(w);
            let mut f = Finding::new(
                Code::ArcsIncomplete,
                self.span(&join(base, &[F("behaviours"), I(b), F("terminal")])),
                format!("ends when {assignment}"),
                format!("when `{bname}` ends with {assignment}, none of its arcs holds"),
            )
            .help("add an arc for this case (the arcs' conditions must cover every case in which the terminal condition holds), or declare relations that rule it out");
            for (k, _) in conds {
                f = f.label(arc_span(self, *k), "does not hold");
            }
            self.push(f);
        }
        if let Some(first) = answer.undecided.first() {
            let what = match *first {
                Undecided::CanEnd => format!("whether `{bname}` can end at all"),
                Undecided::Overlap(x, y) => format!(
                    "whether arcs `{bname} -> {}` and `{bname} -> {}` can hold at once",
                    sub.fsm.arcs[conds[x].0].to, sub.fsm.arcs[conds[y].0].to
                ),
                Undecided::Gap => format!("whether some case ending `{bname}` holds no arc"),
            };
            let more = answer.undecided.len() - 1;
            self.push(
                Finding::new(
                    Code::ProofBudget,
                    self.span(&join(base, &[F("behaviours"), I(b), F("name")])),
                    "not proven",
                    format!(
                        "the proof's budget ran out before deciding {what}{}: the arcs of `{bname}` are neither proven nor refuted",
                        if more > 0 { format!(" ({more} more questions undecided)") } else { String::new() }
                    ),
                )
                .help(format!(
                    "the SAT solver may spend {} conflicts per question and {} per check; simplify the conditions, declare relations, or split the behaviour (at run time the one-arc rule is still enforced)",
                    Budget::PER_QUESTION,
                    Budget::TOTAL
                )),
            );
        }
    }

    // -----------------------------------------------------------------------
    // Links
}

/// Add relation `r`'s assumptions over its predicates `ok` (resolved, in
/// order) to `relations`: no two of an exclusive set hold at once; the first of
/// an implication implies the second.
fn assume(r: &Relation, ok: &[usize], relations: &mut Vec<Expr<usize>>) {
    match r {
        Relation::Exclusive(_) => {
            for x in 0..ok.len() {
                for y in x + 1..ok.len() {
                    relations.push(Expr::Not(Box::new(Expr::And(vec![
                        Expr::Atom(ok[x]),
                        Expr::Atom(ok[y]),
                    ]))));
                }
            }
        }
        Relation::Implies(..) => relations.push(Expr::Or(vec![
            Expr::Not(Box::new(Expr::Atom(ok[0]))),
            Expr::Atom(ok[1]),
        ])),
    }
}
