//! The arc proof: for one FSM node, assuming its terminal condition and the
//! declared relations between predicates, are the conditions of the outgoing arcs
//! mutually exclusive, and does one of them always hold?
//!
//! Two engines answer, both with a cost known in advance:
//!
//! * a **truth table**, when a node's conditions use at most [`TABLE_VARS`]
//!   predicates and are not too large: every condition is evaluated on every
//!   assignment at once, 64 assignments per machine word, so the cost is the size
//!   of the conditions times `2^k / 64` words; exact, and a few microseconds for
//!   the handful of predicates a real FSM node looks at;
//! * a **CDCL SAT solver** ([batsat](https://crates.io/crates/batsat), a Rust
//!   MiniSat) otherwise: the conditions are Tseitin-encoded once per node, with
//!   identical sub-conditions shared, and every question is a solve under
//!   assumptions. Each question may spend [`Budget::PER_QUESTION`] conflicts, a
//!   whole check [`Budget::TOTAL`]: a question the budget does not decide is
//!   reported as undecided, never as an answer.
//!
//! (The DPLL search this replaces re-evaluated every formula at every step and had
//! a budget per question only: ten arcs of random 3-CNF over 60 predicates took
//! 58 s, forty did not finish. The same with the solver: see `bench_check`.)

use std::collections::HashMap;

use agent_core::Expr;

/// At most this many predicates for the truth table.
pub(crate) const TABLE_VARS: usize = 16;

/// At most this many word operations (condition nodes × words) for the truth table.
const TABLE_WORK: u64 = 20_000_000;

/// An assignment of some of a subsystem's predicates (`None`: either value).
pub(crate) type Witness = Vec<Option<bool>>;

/// The questions about one node.
pub(crate) struct Question<'e> {
    /// Number of predicates of the subsystem (atoms are indices below it).
    pub predicates: usize,
    /// What is assumed: the relations and the node's terminal condition.
    pub assumed: Vec<&'e Expr<usize>>,
    /// The conditions of the outgoing arcs (none: only whether the node can end).
    pub arcs: Vec<&'e Expr<usize>>,
}

/// A question the budget left undecided.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Undecided {
    /// Whether the terminal condition can hold at all.
    CanEnd,
    /// Whether arcs `x` and `y` can hold at once.
    Overlap(usize, usize),
    /// Whether some case holds no arc.
    Gap,
}

/// The answers.
#[derive(Clone, Debug, Default, PartialEq)]
pub(crate) struct Answer {
    /// Whether the assumptions can hold (the node can end); `None`: undecided.
    pub can_end: Option<bool>,
    /// Pairs of arcs that can hold at once, with an assignment where they do.
    pub overlaps: Vec<(usize, usize, Witness)>,
    /// An assignment where the node ends and no arc holds.
    pub gap: Option<Witness>,
    /// What the budget did not decide.
    pub undecided: Vec<Undecided>,
    /// Which engine answered.
    pub engine: Engine,
}

/// Which engine answered.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) enum Engine {
    /// The truth table.
    #[default]
    Table,
    /// The SAT solver.
    Sat,
}

/// Conflicts the SAT solver may spend: per question and over a whole check.
#[derive(Clone, Debug)]
pub(crate) struct Budget {
    left: u64,
}

impl Budget {
    /// Conflicts per question.
    pub(crate) const PER_QUESTION: u64 = 20_000;
    /// Conflicts over a whole check.
    pub(crate) const TOTAL: u64 = 400_000;

    pub(crate) fn new() -> Budget {
        Budget { left: Self::TOTAL }
    }

    /// Conflicts spent so far.
    #[cfg(test)]
    pub(crate) fn spent(&self) -> u64 {
        Self::TOTAL - self.left
    }
}

/// Answer `q`, spending at most what `budget` has left.
pub(crate) fn answer(q: &Question<'_>, budget: &mut Budget) -> Answer {
    // The predicates the node's conditions use, in order of first appearance.
    let mut local: HashMap<usize, usize> = HashMap::new();
    let mut used: Vec<usize> = Vec::new();
    let mut nodes = 0u64;
    for e in q.assumed.iter().chain(&q.arcs) {
        nodes += size(e);
        e.for_each_atom(&mut |a: &usize| {
            local.entry(*a).or_insert_with(|| {
                used.push(*a);
                used.len() - 1
            });
        });
    }
    let k = used.len();
    let words = (1u64 << k.min(TABLE_VARS)).div_ceil(64);
    if k <= TABLE_VARS && nodes.saturating_mul(words) <= TABLE_WORK {
        table::answer(q, &local, &used)
    } else {
        sat::answer(q, &local, &used, budget)
    }
}

/// Number of nodes of an expression.
fn size(e: &Expr<usize>) -> u64 {
    match e {
        Expr::Const(_) | Expr::Atom(_) => 1,
        Expr::Not(x) => 1 + size(x),
        Expr::And(xs) | Expr::Or(xs) => 1 + xs.iter().map(size).sum::<u64>(),
    }
}

/// Three-valued evaluation under a partial assignment.
pub(crate) fn eval3(e: &Expr<usize>, a: &[Option<bool>]) -> Option<bool> {
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

/// A full assignment of `used` (values by local index) as a witness over all
/// `predicates`, reduced to the predicates that matter: each is left free in turn
/// if every formula (`true` wanted, or `false` for the `negated` ones) keeps its
/// value without it.
fn witness(
    predicates: usize,
    used: &[usize],
    values: &[bool],
    hold: &[&Expr<usize>],
    fail: &[&Expr<usize>],
) -> Witness {
    let mut w: Witness = vec![None; predicates];
    for (j, &p) in used.iter().enumerate() {
        w[p] = Some(values[j]);
    }
    let ok = |w: &Witness| {
        hold.iter().all(|e| eval3(e, w) == Some(true))
            && fail.iter().all(|e| eval3(e, w) == Some(false))
    };
    for &p in used {
        let keep = w[p].take();
        if !ok(&w) {
            w[p] = keep;
        }
    }
    w
}

mod table {
    //! Every assignment of the used predicates at once: variable `j` is bit
    //! `k − 1 − j` of the assignment's number, so that the highest numbers have
    //! the first predicates true (the order a search trying `true` first meets).

    use std::collections::HashMap;

    use agent_core::Expr;

    use super::{Answer, Engine, Question, witness};

    struct Table {
        k: usize,
        words: usize,
        /// Valid bits of the last word (all, unless `2^k < 64`).
        last_mask: u64,
    }

    impl Table {
        fn column(&self, j: usize) -> Vec<u64> {
            let p = self.k - 1 - j;
            let mut v = vec![0u64; self.words];
            if p < 6 {
                let mut m = 0u64;
                for b in 0..64 {
                    if (b >> p) & 1 == 1 {
                        m |= 1 << b;
                    }
                }
                v.fill(m);
            } else {
                for (w, x) in v.iter_mut().enumerate() {
                    if (w >> (p - 6)) & 1 == 1 {
                        *x = !0;
                    }
                }
            }
            self.mask(v)
        }

        fn mask(&self, mut v: Vec<u64>) -> Vec<u64> {
            if let Some(l) = v.last_mut() {
                *l &= self.last_mask;
            }
            v
        }

        fn constant(&self, b: bool) -> Vec<u64> {
            self.mask(vec![if b { !0 } else { 0 }; self.words])
        }

        fn eval(&self, e: &Expr<usize>, local: &HashMap<usize, usize>) -> Vec<u64> {
            match e {
                Expr::Const(b) => self.constant(*b),
                Expr::Atom(a) => local
                    .get(a)
                    .map_or_else(|| self.constant(false), |&j| self.column(j)),
                Expr::Not(x) => {
                    let v = self.eval(x, local).into_iter().map(|w| !w).collect();
                    self.mask(v)
                }
                Expr::And(xs) => {
                    let mut acc = self.constant(true);
                    for x in xs {
                        for (a, b) in acc.iter_mut().zip(self.eval(x, local)) {
                            *a &= b;
                        }
                    }
                    acc
                }
                Expr::Or(xs) => {
                    let mut acc = self.constant(false);
                    for x in xs {
                        for (a, b) in acc.iter_mut().zip(self.eval(x, local)) {
                            *a |= b;
                        }
                    }
                    acc
                }
            }
        }

        /// The highest assignment in `v`, as values of the used predicates.
        fn highest(&self, v: &[u64]) -> Option<Vec<bool>> {
            let (w, word) = v.iter().enumerate().rev().find(|(_, x)| **x != 0)?;
            let bit = 63 - word.leading_zeros() as usize;
            let a = w * 64 + bit;
            Some(
                (0..self.k)
                    .map(|j| (a >> (self.k - 1 - j)) & 1 == 1)
                    .collect(),
            )
        }
    }

    fn and(a: &[u64], b: &[u64]) -> Vec<u64> {
        a.iter().zip(b).map(|(x, y)| x & y).collect()
    }

    pub(super) fn answer(
        q: &Question<'_>,
        local: &HashMap<usize, usize>,
        used: &[usize],
    ) -> Answer {
        let k = used.len();
        let words = (1usize << k).div_ceil(64);
        let t = Table {
            k,
            words,
            last_mask: if k >= 6 { !0 } else { (1u64 << (1 << k)) - 1 },
        };
        let mut base = t.constant(true);
        for e in &q.assumed {
            base = and(&base, &t.eval(e, local));
        }
        let can_end = base.iter().any(|w| *w != 0);
        let mut answer = Answer {
            can_end: Some(can_end),
            engine: Engine::Table,
            ..Answer::default()
        };
        if !can_end || q.arcs.is_empty() {
            return answer;
        }
        let arcs: Vec<Vec<u64>> = q
            .arcs
            .iter()
            .map(|e| and(&base, &t.eval(e, local)))
            .collect();
        for x in 0..arcs.len() {
            for y in x + 1..arcs.len() {
                if let Some(values) = t.highest(&and(&arcs[x], &arcs[y])) {
                    let mut hold = q.assumed.clone();
                    hold.extend([q.arcs[x], q.arcs[y]]);
                    let w = witness(q.predicates, used, &values, &hold, &[]);
                    answer.overlaps.push((x, y, w));
                }
            }
        }
        let mut none = base;
        for a in &arcs {
            for (n, w) in none.iter_mut().zip(a) {
                *n &= !w;
            }
        }
        if let Some(values) = t.highest(&none) {
            answer.gap = Some(witness(q.predicates, used, &values, &q.assumed, &q.arcs));
        }
        answer
    }
}

mod sat {
    //! The SAT solver: one instance per node, conditions encoded once.

    use std::collections::HashMap;

    use agent_core::Expr;
    use batsat::{Callbacks, ClauseKind, Lit, SolverInterface, SolverOpts, lbool};

    use super::{Answer, Budget, Engine, Question, Undecided, witness};

    /// Counts the conflicts (one learnt clause each) and stops the search at the
    /// limit.
    #[derive(Debug, Default)]
    struct Counted {
        conflicts: u64,
        limit: u64,
    }

    impl Callbacks for Counted {
        fn on_new_clause(&mut self, _: &[Lit], kind: ClauseKind) {
            if kind == ClauseKind::Learnt {
                self.conflicts += 1;
            }
        }

        fn stop(&self) -> bool {
            self.conflicts >= self.limit
        }
    }

    type Solver = batsat::Solver<Counted>;

    /// Tseitin encoding with structural sharing: a sub-condition written twice is
    /// one literal.
    struct Encoder<'l> {
        local: &'l HashMap<usize, usize>,
        vars: Vec<Lit>,
        truth: Lit,
        shared: HashMap<(bool, Vec<Lit>), Lit>,
    }

    impl Encoder<'_> {
        fn lit(&mut self, s: &mut Solver, e: &Expr<usize>) -> Lit {
            match e {
                Expr::Const(true) => self.truth,
                Expr::Const(false) => !self.truth,
                Expr::Atom(a) => self.local.get(a).map_or(!self.truth, |&j| self.vars[j]),
                Expr::Not(x) => !self.lit(s, x),
                Expr::And(xs) | Expr::Or(xs) => {
                    let is_and = matches!(e, Expr::And(_));
                    let mut ls: Vec<Lit> = xs.iter().map(|x| self.lit(s, x)).collect();
                    ls.sort_unstable();
                    ls.dedup();
                    let key = (is_and, ls);
                    if let Some(&l) = self.shared.get(&key) {
                        return l;
                    }
                    let v = Lit::new(s.new_var_default(), true);
                    // And: v -> l for each l; (all l) -> v. Or: dually.
                    let (g, sign) = if is_and { (v, true) } else { (!v, false) };
                    for &l in &key.1 {
                        let l = if sign { l } else { !l };
                        s.add_clause_reuse(&mut vec![!g, l]);
                    }
                    let mut big: Vec<Lit> =
                        key.1.iter().map(|&l| if sign { !l } else { l }).collect();
                    big.push(g);
                    s.add_clause_reuse(&mut big);
                    self.shared.insert(key, v);
                    v
                }
            }
        }
    }

    /// Solve under `assumptions` with the per-question budget (at most what is
    /// left): `Some(model of the used predicates)`, `Some(None)` for unsatisfiable,
    /// `None` when undecided.
    fn solve(
        s: &mut Solver,
        vars: &[Lit],
        assumptions: &[Lit],
        budget: &mut Budget,
    ) -> Option<Option<Vec<bool>>> {
        let limit = Budget::PER_QUESTION.min(budget.left);
        if limit == 0 {
            return None;
        }
        let before = s.cb().conflicts;
        s.cb_mut().limit = before + limit;
        let r = s.solve_limited(assumptions);
        let spent = s.cb().conflicts - before;
        budget.left = budget.left.saturating_sub(spent);
        if r == lbool::TRUE {
            Some(Some(
                vars.iter()
                    .map(|l| s.value_lit(*l) == lbool::TRUE)
                    .collect(),
            ))
        } else if r == lbool::FALSE {
            Some(None)
        } else {
            None
        }
    }

    pub(super) fn answer(
        q: &Question<'_>,
        local: &HashMap<usize, usize>,
        used: &[usize],
        budget: &mut Budget,
    ) -> Answer {
        let mut s = Solver::new(SolverOpts::default(), Counted::default());
        let truth = Lit::new(s.new_var_default(), true);
        s.add_clause_reuse(&mut vec![truth]);
        let vars: Vec<Lit> = used
            .iter()
            .map(|_| Lit::new(s.new_var_default(), true))
            .collect();
        let mut enc = Encoder {
            local,
            vars: vars.clone(),
            truth,
            shared: HashMap::new(),
        };
        for e in &q.assumed {
            let l = enc.lit(&mut s, e);
            s.add_clause_reuse(&mut vec![l]);
        }
        let arcs: Vec<Lit> = q.arcs.iter().map(|e| enc.lit(&mut s, e)).collect();
        let mut answer = Answer {
            engine: Engine::Sat,
            ..Answer::default()
        };
        match solve(&mut s, &vars, &[], budget) {
            None => {
                answer.undecided.push(Undecided::CanEnd);
                return answer;
            }
            Some(None) => {
                answer.can_end = Some(false);
                return answer;
            }
            Some(Some(_)) => answer.can_end = Some(true),
        }
        for x in 0..arcs.len() {
            for y in x + 1..arcs.len() {
                match solve(&mut s, &vars, &[arcs[x], arcs[y]], budget) {
                    None => answer.undecided.push(Undecided::Overlap(x, y)),
                    Some(None) => {}
                    Some(Some(values)) => {
                        let mut hold = q.assumed.clone();
                        hold.extend([q.arcs[x], q.arcs[y]]);
                        let w = witness(q.predicates, used, &values, &hold, &[]);
                        answer.overlaps.push((x, y, w));
                    }
                }
            }
        }
        if !arcs.is_empty() {
            let none: Vec<Lit> = arcs.iter().map(|&l| !l).collect();
            match solve(&mut s, &vars, &none, budget) {
                None => answer.undecided.push(Undecided::Gap),
                Some(None) => {}
                Some(Some(values)) => {
                    answer.gap = Some(witness(q.predicates, used, &values, &q.assumed, &q.arcs));
                }
            }
        }
        answer
    }
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

    const N: [&str; 3] = ["a", "b", "c"];

    fn ask(assumed: &[&str], arcs: &[&str]) -> Answer {
        let assumed: Vec<Expr<usize>> = assumed.iter().map(|s| e(s, &N)).collect();
        let arcs: Vec<Expr<usize>> = arcs.iter().map(|s| e(s, &N)).collect();
        let q = Question {
            predicates: 3,
            assumed: assumed.iter().collect(),
            arcs: arcs.iter().collect(),
        };
        answer(&q, &mut Budget::new())
    }

    #[test]
    fn small_cases() {
        assert_eq!(ask(&["a && !a"], &[]).can_end, Some(false));
        let a = ask(&["a || b"], &["a", "b"]);
        assert_eq!(a.can_end, Some(true));
        assert_eq!(a.overlaps.len(), 1);
        assert_eq!(a.overlaps[0].2, vec![Some(true), Some(true), None]);
        assert_eq!(a.gap, None, "a || b is assumed");
        // Exclusive(a, b): no overlap; the gap is a = b = false.
        let a = ask(&["!(a && b)"], &["a", "b"]);
        assert!(a.overlaps.is_empty());
        assert_eq!(a.gap, Some(vec![Some(false), Some(false), None]));
        assert_eq!(ask(&["true"], &[]).can_end, Some(true));
    }

    /// Random formulas over 4 atoms: both engines agree with the truth table of
    /// `eval3`, and their witnesses (completed either way) are witnesses.
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

    fn truth(fs: &[&Expr<usize>], not: &[&Expr<usize>]) -> bool {
        (0..16u32).any(|bits| {
            let a: Vec<Option<bool>> = (0..4).map(|i| Some(bits >> i & 1 == 1)).collect();
            fs.iter().all(|f| eval3(f, &a) == Some(true))
                && not.iter().all(|f| eval3(f, &a) == Some(false))
        })
    }

    fn completes(w: &Witness, fs: &[&Expr<usize>], not: &[&Expr<usize>]) -> bool {
        [false, true].iter().all(|fill| {
            let full: Vec<Option<bool>> = w.iter().map(|x| Some(x.unwrap_or(*fill))).collect();
            fs.iter().all(|f| eval3(f, &full) == Some(true))
                && not.iter().all(|f| eval3(f, &full) == Some(false))
        })
    }

    proptest! {
        #[test]
        fn both_engines_agree_with_the_truth_table(
            assumed in prop::collection::vec(formula(), 1..3),
            arcs in prop::collection::vec(formula(), 0..4),
        ) {
            let q = Question {
                predicates: 4,
                assumed: assumed.iter().collect(),
                arcs: arcs.iter().collect(),
            };
            let mut local = HashMap::new();
            let mut used = Vec::new();
            for f in q.assumed.iter().chain(&q.arcs) {
                f.for_each_atom(&mut |a: &usize| {
                    local.entry(*a).or_insert_with(|| { used.push(*a); used.len() - 1 });
                });
            }
            let by_table = table::answer(&q, &local, &used);
            let by_sat = sat::answer(&q, &local, &used, &mut Budget::new());
            for a in [&by_table, &by_sat] {
                prop_assert!(a.undecided.is_empty());
                let can_end = truth(&q.assumed, &[]);
                prop_assert_eq!(a.can_end, Some(can_end));
                if !can_end || q.arcs.is_empty() {
                    continue;
                }
                for x in 0..arcs.len() {
                    for y in x + 1..arcs.len() {
                        let mut fs = q.assumed.clone();
                        fs.extend([&arcs[x], &arcs[y]]);
                        let found = a.overlaps.iter().find(|o| (o.0, o.1) == (x, y));
                        prop_assert_eq!(found.is_some(), truth(&fs, &[]));
                        if let Some(o) = found {
                            prop_assert!(completes(&o.2, &fs, &[]));
                        }
                    }
                }
                let not: Vec<&Expr<usize>> = arcs.iter().collect();
                prop_assert_eq!(a.gap.is_some(), truth(&q.assumed, &not));
                if let Some(w) = &a.gap {
                    prop_assert!(completes(w, &q.assumed, &not));
                }
            }
        }
    }

    #[test]
    fn the_budget_leaves_hard_questions_undecided_not_answered() {
        // A pigeonhole: 10 pigeons in 9 holes, as two arcs that can hold together
        // only if the pigeons fit. Unsatisfiable, and hard for resolution.
        let (p, h) = (10, 9);
        let var = |i: usize, j: usize| i * h + j;
        let mut names = Vec::new();
        for i in 0..p {
            for j in 0..h {
                names.push(format!("x{i}_{j}"));
            }
        }
        let each_in_a_hole: Vec<Expr<usize>> = (0..p)
            .map(|i| Expr::Or((0..h).map(|j| Expr::Atom(var(i, j))).collect()))
            .collect();
        let mut no_two: Vec<Expr<usize>> = Vec::new();
        for j in 0..h {
            for i in 0..p {
                for k in i + 1..p {
                    no_two.push(Expr::Not(Box::new(Expr::And(vec![
                        Expr::Atom(var(i, j)),
                        Expr::Atom(var(k, j)),
                    ]))));
                }
            }
        }
        let (x, y) = (Expr::And(each_in_a_hole), Expr::And(no_two));
        let t = Expr::Const(true);
        let q = Question {
            predicates: p * h,
            assumed: vec![&t],
            arcs: vec![&x, &y],
        };
        let mut budget = Budget::new();
        let a = answer(&q, &mut budget);
        assert_eq!(a.engine, Engine::Sat);
        assert!(a.overlaps.is_empty(), "never a false overlap");
        assert!(
            a.undecided.contains(&Undecided::Overlap(0, 1)),
            "{:?}",
            a.undecided
        );
        assert!(budget.spent() >= Budget::PER_QUESTION);
        // Once the whole budget is spent, nothing more is decided.
        let mut empty = Budget { left: 0 };
        let a = answer(&q, &mut empty);
        assert_eq!(a.undecided, vec![Undecided::CanEnd]);
    }
}
