//! The checker: every rule of the schema, all findings at once.

use std::collections::{HashMap, HashSet};
use std::ops::Range;

use agent_core::fsm::rules::{self, Place, ShapeProblem};
use agent_core::{Expr, NodeKind, structure_violation};

use crate::diag::{Code, Finding, abbreviate};
use crate::model::{Buffer, Group, Policy, Relation, Spec, Subsystem, SubsystemKind, Target};
use crate::proof::{self, Budget, Question, Undecided, Witness};
use crate::span::{SNode, Seg};

mod components;
mod contracts;
mod fsm;
mod ros2;
mod subsystem;
mod wiring;

/// A path into the spec, for spans.
type Path = Vec<Seg<'static>>;

fn join(base: &[Seg<'static>], rest: &[Seg<'static>]) -> Path {
    let mut p = base.to_vec();
    p.extend_from_slice(rest);
    p
}

use Seg::{Field as F, Item as I};

/// A component (subsystem or device) as the checker sees it.
struct Comp<'a> {
    name: &'a str,
    agent: usize,
    kind: NodeKind,
    path: Path,
    inputs: &'a [Group],
    outputs: &'a [Group],
}

pub(crate) struct Checker<'a> {
    spec: &'a Spec,
    index: Option<&'a SNode>,
    findings: Vec<Finding>,
    comps: HashMap<&'a str, Comp<'a>>,
    /// Whether to prove the arcs (diagrams need the structure only).
    prove: bool,
    budget: Budget,
    /// The lists of names that help lines offer, made once per collection (a
    /// spec with many findings about one long list would otherwise rebuild it for
    /// each: quadratic).
    lists: HashMap<(usize, Hint), std::rc::Rc<str>>,
    components_list: Option<std::rc::Rc<str>>,
    /// Name comparisons left for "did you mean" hints: a spec with very many
    /// unknown names among very many known ones stays linear.
    guesses_left: usize,
}

/// Which list of names a help line offers.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
enum Hint {
    Functions,
    Predicates,
    Behaviours,
    Readable,
    InputGroups,
    OutputGroups,
    Buffers,
}

/// The byte offset of the first occurrence of each identifier in condition `text`
/// as a whole identifier (`new` in `plan_new && !new` is at 13, not 5), in one
/// pass over the text.
fn ident_offsets(text: &str) -> HashMap<&str, usize> {
    let ident = |b: u8| b.is_ascii_alphanumeric() || b == b'_';
    let bytes = text.as_bytes();
    let mut out = HashMap::new();
    let mut i = 0;
    while i < bytes.len() {
        if ident(bytes[i]) {
            let start = i;
            while i < bytes.len() && ident(bytes[i]) {
                i += 1;
            }
            out.entry(&text[start..i]).or_insert(start);
        } else {
            i += 1;
        }
    }
    out
}

fn normalize_type(t: &str) -> String {
    t.split_whitespace()
        .collect::<Vec<_>>()
        .join(" ")
        .replace(" <", "<")
        .replace("< ", "<")
        .replace(" >", ">")
        .replace(" ,", ",")
}

impl<'a> Checker<'a> {
    pub(crate) fn new(spec: &'a Spec, index: Option<&'a SNode>) -> Self {
        Checker {
            spec,
            index,
            findings: Vec::new(),
            comps: HashMap::new(),
            prove: true,
            budget: Budget::new(),
            lists: HashMap::new(),
            components_list: None,
            guesses_left: GUESS_BUDGET,
        }
    }

    /// The help list `hint` of the collection at `at` (its address: the spec
    /// outlives the checker), made by `names` the first time.
    fn list<T>(
        &mut self,
        at: &[T],
        hint: Hint,
        names: impl FnOnce() -> Vec<String>,
    ) -> std::rc::Rc<str> {
        let key = (at.as_ptr() as usize, hint);
        if let Some(l) = self.lists.get(&key) {
            return std::rc::Rc::clone(l);
        }
        let names = names();
        let l: std::rc::Rc<str> =
            list_or_none(&names.iter().map(String::as_str).collect::<Vec<_>>()).into();
        self.lists.insert(key, std::rc::Rc::clone(&l));
        l
    }

    /// Leave out the arc proof (and the findings that need it: overlapping and
    /// incomplete arcs, terminal conditions that never hold).
    pub(crate) fn without_proof(mut self) -> Self {
        self.prove = false;
        self
    }

    pub(crate) fn run(mut self) -> Vec<Finding> {
        self.components();
        for (a, agent) in self.spec.agents.iter().enumerate() {
            self.agent(a);
            for (s, sub) in agent.subsystems.iter().enumerate() {
                self.subsystem(&[F("agents"), I(a), F("subsystems"), I(s)], sub);
            }
        }
        self.links();
        self.deployments();
        self.ros2();
        self.contracts();
        self.findings
    }

    /// The span of the value at `path`, or of the nearest ancestor that has one.
    fn span(&self, path: &[Seg<'_>]) -> Range<usize> {
        let Some(root) = self.index else { return 0..0 };
        for n in (0..=path.len()).rev() {
            if let Some(node) = root.at(&path[..n]) {
                return node.content_span();
            }
        }
        0..0
    }

    /// The span of a field's name (falls back to the value's span).
    fn key_span(&self, path: &[Seg<'_>]) -> Range<usize> {
        self.index
            .and_then(|root| root.key_at(path))
            .unwrap_or_else(|| self.span(path))
    }

    fn node(&self, path: &[Seg<'_>]) -> Option<&'a SNode> {
        self.index?.at(path)
    }

    /// `"did you mean `x`? "` when a known name is close to `name` (a typo), else
    /// empty; within the checker's budget of comparisons.
    fn guess<'n>(&mut self, name: &str, known: impl IntoIterator<Item = &'n str>) -> String {
        let known: Vec<&str> = known.into_iter().collect();
        if known.len() > self.guesses_left {
            return String::new();
        }
        self.guesses_left -= known.len();
        crate::names::did_you_mean(name, known)
            .map(|k| format!("did you mean `{k}`? "))
            .unwrap_or_default()
    }

    /// [`Checker::guess`] among the components.
    fn guess_component(&mut self, name: &str) -> String {
        let known: Vec<&'a str> = self.comps.keys().copied().collect();
        self.guess(name, known)
    }

    fn push(&mut self, f: Finding) {
        self.findings.push(f);
    }
}

enum EndpointError {
    Form,
    Component(String),
    Direction,
    Buffer,
}

fn last(dotted: &str) -> String {
    dotted.rsplit('.').next().unwrap_or(dotted).to_owned()
}

fn seg_key(s: Seg<'_>) -> (usize, String) {
    match s {
        Seg::Field(f) => (0, f.to_owned()),
        Seg::Item(i) => (1, format!("{i:08}")),
    }
}

fn target_text(t: &Target) -> String {
    match t {
        Target::Memory => "the memory".into(),
        Target::Common => "the memory (common part)".into(),
        Target::Output(p) => format!("the outputs towards `{p}`"),
    }
}

/// The first [`LIST_MAX`] of `names`, and how many there are in all.
fn list_or_none(names: &[&str]) -> String {
    match names.len() {
        0 => "(none)".into(),
        n if n > LIST_MAX => format!("{}, … ({n} in all)", names[..LIST_MAX].join(", ")),
        _ => names.join(", "),
    }
}

fn sorted(names: impl Iterator<Item = String>) -> Vec<String> {
    let mut v: Vec<String> = names.collect();
    v.sort_unstable();
    v
}

/// How many names a help line lists.
const LIST_MAX: usize = 12;

/// How many name comparisons "did you mean" hints may cost in one check.
const GUESS_BUDGET: usize = 1_000_000;

/// `a=true, b=false`: the predicates a witness fixes, by name, in the order of
/// their declaration.
fn render_assignment(sub: &Subsystem, w: &Witness) -> String {
    let parts: Vec<String> = w
        .iter()
        .enumerate()
        .filter_map(|(i, v)| Some(format!("{}={}", sub.predicates.get(i)?.name, (*v)?)))
        .collect();
    if parts.is_empty() {
        "any predicate values".into()
    } else {
        parts.join(", ")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn types_compare_modulo_spaces() {
        assert_eq!(normalize_type("Vec< f64 >"), normalize_type("Vec<f64>"));
        assert_eq!(normalize_type("[f64 ;  4]"), normalize_type("[f64 ; 4]"));
        assert_ne!(normalize_type("Vec<f32>"), normalize_type("Vec<f64>"));
    }

    #[test]
    fn undeclared_names_are_found_as_whole_identifiers() {
        let find = |text: &str, name: &str| ident_offsets(text).get(name).copied();
        assert_eq!(find("plan_new && !new", "new"), Some(13));
        assert_eq!(find("new_plan || new", "new"), Some(12));
        assert_eq!(find("new && plan_new", "new"), Some(0));
        assert_eq!(find("(a1&&a)", "a"), Some(5));
        assert_eq!(find("renew || news", "new"), None);
        assert_eq!(find("é && new", "new"), Some(6));
    }

    #[test]
    fn identifiers() {
        use crate::names::is_identifier as is_ident;
        assert!(is_ident("A4x4") && is_ident("_x") && is_ident("q_est"));
        assert!(!is_ident("4x") && !is_ident("a-b") && !is_ident(""));
    }
}
