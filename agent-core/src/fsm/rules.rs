//! The shape rules of an FSM graph, written once.
//!
//! [`FsmBuilder`](crate::FsmBuilder) applies them when it builds an FSM, and the spec
//! checker (`agent-spec`) applies the same functions to a spec, adding its codes and
//! source spans. The rules:
//!
//! * an FSM names an initial behaviour ([`ShapeProblem::NoInitial`]);
//! * the initial declaration, the arcs and the final declarations name defined
//!   behaviours ([`ShapeProblem::UnknownBehaviour`]);
//! * every behaviour can be reached from the initial one ([`ShapeProblem::Unreachable`]);
//!   names resolve to the first behaviour of that name (a duplicate is the caller's
//!   uniqueness problem, and is not also reported unreachable);
//! * a final behaviour has no outgoing arc ([`ShapeProblem::FinalWithArcs`]);
//! * a behaviour that can end has an outgoing arc or is final
//!   ([`Resolved::lacks_way_out`]; whether it can end is the caller's: the builder
//!   asks whether the terminal condition is the constant `false`, the checker
//!   proves it). An arc whose condition is broken is still an arc: the condition
//!   is reported, not a missing way out;
//! * conditions name declared predicates ([`resolve_condition`]).

use crate::expr::Expr;

/// An FSM graph by names, as written.
#[derive(Clone, Debug, Default)]
pub struct Graph<'a> {
    /// The behaviours' names, by index.
    pub behaviours: Vec<&'a str>,
    /// The initial behaviour, if declared.
    pub initial: Option<&'a str>,
    /// The arcs as `(from, to)`, in declaration order.
    pub arcs: Vec<(&'a str, &'a str)>,
    /// The final declarations, in order.
    pub finals: Vec<&'a str>,
}

/// Where a behaviour name appears in a [`Graph`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Place {
    /// The initial declaration.
    Initial,
    /// The source of arc number `k`.
    ArcFrom(usize),
    /// The target of arc number `k`.
    ArcTo(usize),
    /// Final declaration number `k`.
    Final(usize),
}

/// A broken shape rule (behaviours by index into [`Graph::behaviours`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ShapeProblem {
    /// No initial behaviour is declared.
    NoInitial,
    /// A name at `place` is not a behaviour of the FSM.
    UnknownBehaviour {
        /// Where the name appears.
        place: Place,
        /// The name.
        name: String,
    },
    /// A behaviour cannot be reached from the initial one.
    Unreachable(usize),
    /// A final behaviour has outgoing arcs.
    FinalWithArcs(usize),
}

/// A [`Graph`] with its names resolved to indices.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Resolved {
    /// The initial behaviour, if declared and known.
    pub initial: Option<usize>,
    /// Each arc as `(from, to)`, or `None` if an end is unknown.
    pub arcs: Vec<Option<(usize, usize)>>,
    /// Whether each behaviour is declared final.
    pub finals: Vec<bool>,
    /// The resolved arcs leaving each behaviour, as indices into [`Resolved::arcs`].
    pub outgoing: Vec<Vec<usize>>,
}

impl Resolved {
    /// The last rule: behaviour `b`, which can end (`can_end`), has neither an
    /// outgoing arc nor a final declaration, so the FSM would have nowhere to go.
    pub fn lacks_way_out(&self, b: usize, can_end: bool) -> bool {
        can_end && !self.finals[b] && self.outgoing[b].is_empty()
    }
}

impl Graph<'_> {
    /// Resolve the names and check every rule but the last
    /// ([`Resolved::lacks_way_out`]): problems in the order of the rules, then of
    /// the declarations.
    pub fn check(&self) -> (Resolved, Vec<ShapeProblem>) {
        let n = self.behaviours.len();
        let index = |name: &str| self.behaviours.iter().position(|b| *b == name);
        let mut problems = Vec::new();
        let mut unknown = |place: Place, name: &str| {
            problems.push(ShapeProblem::UnknownBehaviour {
                place,
                name: name.to_owned(),
            });
        };
        let initial = match self.initial {
            None => None,
            Some(name) => {
                let i = index(name);
                if i.is_none() {
                    unknown(Place::Initial, name);
                }
                i
            }
        };
        let mut outgoing = vec![Vec::new(); n];
        let arcs = self
            .arcs
            .iter()
            .enumerate()
            .map(|(k, (from, to))| {
                let (f, t) = (index(from), index(to));
                if f.is_none() {
                    unknown(Place::ArcFrom(k), from);
                }
                if t.is_none() {
                    unknown(Place::ArcTo(k), to);
                }
                let arc = f.zip(t);
                if let Some((f, _)) = arc {
                    outgoing[f].push(k);
                }
                arc
            })
            .collect::<Vec<_>>();
        let mut finals = vec![false; n];
        for (k, name) in self.finals.iter().enumerate() {
            match index(name) {
                Some(i) => finals[i] = true,
                None => unknown(Place::Final(k), name),
            }
        }
        if self.initial.is_none() {
            problems.insert(0, ShapeProblem::NoInitial);
        }
        if let Some(start) = initial {
            let mut seen = vec![false; n];
            let mut stack = vec![start];
            seen[start] = true;
            while let Some(b) = stack.pop() {
                for &k in &outgoing[b] {
                    if let Some((_, to)) = arcs[k]
                        && !seen[to]
                    {
                        seen[to] = true;
                        stack.push(to);
                    }
                }
            }
            // A second behaviour of the same name is the caller's uniqueness
            // problem; every reference goes to the first, so it is not reported
            // unreachable as well.
            let first = |b: usize| index(self.behaviours[b]) == Some(b);
            problems.extend(
                (0..n)
                    .filter(|&b| !seen[b] && first(b))
                    .map(ShapeProblem::Unreachable),
            );
        }
        problems.extend(
            (0..n)
                .filter(|&b| finals[b] && !outgoing[b].is_empty())
                .map(ShapeProblem::FinalWithArcs),
        );
        let resolved = Resolved {
            initial,
            arcs,
            finals,
            outgoing,
        };
        (resolved, problems)
    }
}

/// Resolve the predicate names of a parsed condition with `index` (which may
/// record what it sees): the condition over indices, or every unknown name, once
/// each, in order of appearance.
pub fn resolve_condition(
    condition: &Expr<String>,
    mut index: impl FnMut(&str) -> Option<usize>,
) -> Result<Expr<usize>, Vec<String>> {
    let mut unknown: Vec<String> = Vec::new();
    let resolved = condition.try_map(&mut |name: &String| match index(name) {
        Some(i) => Ok::<usize, ()>(i),
        None => {
            if !unknown.contains(name) {
                unknown.push(name.clone());
            }
            Ok(0)
        }
    });
    match resolved {
        Ok(e) if unknown.is_empty() => Ok(e),
        _ => Err(unknown),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn graph<'a>(
        behaviours: &[&'a str],
        initial: Option<&'a str>,
        arcs: &[(&'a str, &'a str)],
        finals: &[&'a str],
    ) -> Graph<'a> {
        Graph {
            behaviours: behaviours.to_vec(),
            initial,
            arcs: arcs.to_vec(),
            finals: finals.to_vec(),
        }
    }

    #[test]
    fn a_sound_graph_breaks_no_rule() {
        let g = graph(&["a", "b"], Some("a"), &[("a", "b"), ("b", "a")], &[]);
        let (r, problems) = g.check();
        assert!(problems.is_empty(), "{problems:?}");
        assert_eq!(r.initial, Some(0));
        assert_eq!(r.outgoing, vec![vec![0], vec![1]]);
        assert!(!r.lacks_way_out(0, true));
    }

    #[test]
    fn every_rule_is_reported_with_its_place() {
        let g = graph(
            &["a", "b", "c", "d"],
            None,
            &[("a", "b"), ("x", "a"), ("b", "y"), ("c", "a")],
            &["c", "z"],
        );
        let (r, problems) = g.check();
        assert_eq!(
            problems,
            vec![
                ShapeProblem::NoInitial,
                ShapeProblem::UnknownBehaviour {
                    place: Place::ArcFrom(1),
                    name: "x".into()
                },
                ShapeProblem::UnknownBehaviour {
                    place: Place::ArcTo(2),
                    name: "y".into()
                },
                ShapeProblem::UnknownBehaviour {
                    place: Place::Final(1),
                    name: "z".into()
                },
                ShapeProblem::FinalWithArcs(2),
            ]
        );
        // `d` can end and goes nowhere; `c` is final; `b`'s only arc is unresolved.
        assert!(r.lacks_way_out(3, true));
        assert!(
            !r.lacks_way_out(3, false),
            "a behaviour that never ends needs no way out"
        );
        assert!(!r.lacks_way_out(2, true));
        assert!(r.lacks_way_out(1, true));
    }

    #[test]
    fn unreachable_behaviours_are_found_from_the_initial_one() {
        let g = graph(
            &["a", "b", "c"],
            Some("b"),
            &[("a", "b"), ("b", "c")],
            &["c"],
        );
        let (_, problems) = g.check();
        assert_eq!(problems, vec![ShapeProblem::Unreachable(0)]);
        let g = graph(&["a"], Some("q"), &[], &[]);
        assert_eq!(
            g.check().1,
            vec![ShapeProblem::UnknownBehaviour {
                place: Place::Initial,
                name: "q".into()
            }]
        );
    }

    #[test]
    fn unknown_predicates_are_listed_once_in_order() {
        let e = Expr::parse("b && !a || b && c").expect("parses");
        let known = |n: &str| (n == "a").then_some(0);
        assert_eq!(
            resolve_condition(&e, known),
            Err(vec!["b".to_owned(), "c".to_owned()])
        );
        let e = Expr::parse("!a").expect("parses");
        assert_eq!(
            resolve_condition(&e, known),
            Ok(Expr::Not(Box::new(Expr::Atom(0))))
        );
    }
}
