//! Satisfiability of conditions over predicates: the proof that the arcs leaving an
//! FSM node are mutually exclusive and cover every case.
//!
//! Predicates are Boolean variables, constrained only by the declared relations.
//! The search is a DPLL-style backtracking over three-valued evaluation: a branch is
//! cut as soon as a formula is false under the partial assignment, and an assignment
//! is found as soon as every formula is true. Exponential in the worst case, a few
//! microseconds for the handful of predicates an FSM node looks at; a step budget
//! keeps pathological specs from stalling the checker.

use agent_core::Expr;

/// The outcome of a satisfiability question.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) enum Sat {
    /// Satisfiable; the assignment (atoms left `None` may take either value).
    Yes(Vec<Option<bool>>),
    /// Unsatisfiable.
    No,
    /// The step budget ran out.
    Unknown,
}

/// Three-valued evaluation under a partial assignment.
fn eval3(e: &Expr<usize>, a: &[Option<bool>]) -> Option<bool> {
    match e {
        Expr::Const(b) => Some(*b),
        Expr::Atom(i) => a.get(*i).copied().flatten(),
        Expr::Not(x) => eval3(x, a).map(|v| !v),
        Expr::And(xs) => {
            let mut unknown = false;
            for x in xs {
                match eval3(x, a) {
                    Some(false) => return Some(false),
                    None => unknown = true,
                    Some(true) => {}
                }
            }
            if unknown { None } else { Some(true) }
        }
        Expr::Or(xs) => {
            let mut unknown = false;
            for x in xs {
                match eval3(x, a) {
                    Some(true) => return Some(true),
                    None => unknown = true,
                    Some(false) => {}
                }
            }
            if unknown { None } else { Some(false) }
        }
    }
}

fn first_unassigned(e: &Expr<usize>, a: &[Option<bool>]) -> Option<usize> {
    match e {
        Expr::Const(_) => None,
        Expr::Atom(i) => a.get(*i).is_some_and(Option::is_none).then_some(*i),
        Expr::Not(x) => first_unassigned(x, a),
        Expr::And(xs) | Expr::Or(xs) => xs.iter().find_map(|x| {
            // Only descend into sub-formulas that are still undecided.
            eval3(x, a)
                .is_none()
                .then(|| first_unassigned(x, a))
                .flatten()
        }),
    }
}

/// Is the conjunction of `formulas` satisfiable, over `atoms` variables?
pub(crate) fn solve(formulas: &[Expr<usize>], atoms: usize, budget: u64) -> Sat {
    let mut a = vec![None; atoms];
    let mut steps = 0u64;
    match search(formulas, &mut a, &mut steps, budget) {
        Some(true) => Sat::Yes(a),
        Some(false) => Sat::No,
        None => Sat::Unknown,
    }
}

fn search(
    fs: &[Expr<usize>],
    a: &mut [Option<bool>],
    steps: &mut u64,
    budget: u64,
) -> Option<bool> {
    *steps += 1;
    if *steps > budget {
        return None;
    }
    let mut branch = None;
    for f in fs {
        match eval3(f, a) {
            Some(false) => return Some(false),
            Some(true) => {}
            None => {
                if branch.is_none() {
                    branch = first_unassigned(f, a);
                }
            }
        }
    }
    let Some(i) = branch else {
        return Some(true);
    };
    for v in [true, false] {
        a[i] = Some(v);
        if search(fs, a, steps, budget)? {
            return Some(true);
        }
    }
    a[i] = None;
    Some(false)
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn e(s: &str, names: &[&str]) -> Expr<usize> {
        Expr::parse(s)
            .unwrap()
            .try_map(&mut |n: &String| names.iter().position(|x| x == n).ok_or(()))
            .unwrap()
    }

    #[test]
    fn small_cases() {
        let n = ["a", "b", "c"];
        assert_eq!(solve(&[e("a && !a", &n)], 3, 1000), Sat::No);
        assert!(
            matches!(solve(&[e("a || b", &n), e("!a", &n)], 3, 1000), Sat::Yes(v) if v[1] == Some(true))
        );
        // Exclusive(a, b) makes `a && b` impossible.
        assert_eq!(
            solve(&[e("!(a && b)", &n), e("a && b", &n)], 3, 1000),
            Sat::No
        );
        assert_eq!(solve(&[e("true", &n)], 3, 1000), Sat::Yes(vec![None; 3]));
    }

    /// Random formulas over 4 atoms: the solver agrees with the truth table, and any
    /// assignment it returns (completed arbitrarily) satisfies the formulas.
    fn formula() -> impl Strategy<Value = Expr<usize>> {
        let leaf = prop_oneof![
            (0usize..4).prop_map(Expr::Atom),
            any::<bool>().prop_map(Expr::Const)
        ];
        leaf.prop_recursive(4, 24, 3, |inner| {
            prop_oneof![
                inner.clone().prop_map(|x| Expr::Not(Box::new(x))),
                prop::collection::vec(inner.clone(), 2..4).prop_map(Expr::And),
                prop::collection::vec(inner, 2..4).prop_map(Expr::Or),
            ]
        })
    }

    proptest! {
        #[test]
        fn agrees_with_the_truth_table(fs in prop::collection::vec(formula(), 1..4)) {
            let table = (0..16u32).any(|bits| {
                let a: Vec<Option<bool>> = (0..4).map(|i| Some(bits >> i & 1 == 1)).collect();
                fs.iter().all(|f| eval3(f, &a) == Some(true))
            });
            match solve(&fs, 4, 1_000_000) {
                Sat::Yes(a) => {
                    prop_assert!(table);
                    for fill in [false, true] {
                        let full: Vec<Option<bool>> = a.iter().map(|x| Some(x.unwrap_or(fill))).collect();
                        prop_assert!(fs.iter().all(|f| eval3(f, &full) == Some(true)));
                    }
                }
                Sat::No => prop_assert!(!table),
                Sat::Unknown => prop_assert!(false, "budget"),
            }
        }
    }
}
