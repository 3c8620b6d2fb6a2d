//! The checker: every rule of the schema, all findings at once.

use std::collections::{HashMap, HashSet};
use std::ops::Range;

use agent_core::fsm::rules::{self, Place, ShapeProblem};
use agent_core::{Expr, NodeKind, structure_violation};

use crate::diag::{Code, Finding, abbreviate};
use crate::model::{Group, Policy, Relation, Spec, Subsystem, SubsystemKind, Target};
use crate::proof::{self, Budget, Question, Undecided, Witness};
use crate::span::{SNode, Seg};

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

    fn push(&mut self, f: Finding) {
        self.findings.push(f);
    }

    /// The rules of a valid name (agent-core's, which the runtime and the code
    /// generators apply too); components have the rules of type names as well.
    fn name_rules(&mut self, name: &str, path: &[Seg<'static>], what: &str) {
        let component = matches!(what, "subsystem" | "device" | "component");
        let problem = if component {
            crate::names::component_problem(name)
        } else {
            crate::names::check(name).err().map(|p| p.to_string())
        };
        if let Some(problem) = problem {
            let label = match crate::names::check(name) {
                Err(crate::names::NameProblem::Empty) => "empty",
                Err(crate::names::NameProblem::NotIdentifier) => "not an identifier",
                Err(crate::names::NameProblem::Unusable) => "not usable",
                Ok(()) => "not a type name",
            };
            self.push(
                Finding::new(
                    Code::InvalidName,
                    self.span(path),
                    label,
                    format!("{what} name `{}` {problem}", abbreviate(name, 60)),
                )
                .help("names are letters, digits and `_`, not starting with a digit (they become Rust identifiers; `self`, `Self`, `super`, `crate` and `_` cannot)"),
            );
        }
    }

    /// Report duplicates among `names` (each with its path).
    fn unique<'n>(&mut self, what: &str, names: impl IntoIterator<Item = (&'n str, Path)>) {
        let mut seen: HashMap<&str, Path> = HashMap::new();
        for (name, path) in names {
            self.name_rules(name, &path, what);
            if let Some(first) = seen.get(name) {
                let first = self.span(first);
                self.push(
                    Finding::new(
                        Code::DuplicateName,
                        self.span(&path),
                        "defined again here",
                        format!("{what} `{name}` is defined twice"),
                    )
                    .label(first, "first defined here")
                    .help("give each one its own name"),
                );
            } else {
                seen.insert(name, path);
            }
        }
    }

    // -----------------------------------------------------------------------
    // Components and agents

    fn components(&mut self) {
        let spec = self.spec;
        // The system's name becomes a crate name (`embodied new`) and a key of the
        // network transport: the same rule.
        self.name_rules(&spec.name, &[F("name")], "system");
        self.unique(
            "agent",
            spec.agents
                .iter()
                .enumerate()
                .map(|(a, x)| (x.name.as_str(), vec![F("agents"), I(a), F("name")])),
        );
        let mut all = Vec::new();
        for (a, agent) in spec.agents.iter().enumerate() {
            for (s, sub) in agent.subsystems.iter().enumerate() {
                let path = vec![F("agents"), I(a), F("subsystems"), I(s)];
                all.push(Comp {
                    name: &sub.name,
                    agent: a,
                    kind: sub.kind.into(),
                    path,
                    inputs: &sub.inputs,
                    outputs: &sub.outputs,
                });
            }
            for (d, dev) in agent.devices.iter().enumerate() {
                all.push(Comp {
                    name: &dev.name,
                    agent: a,
                    kind: dev.kind.into(),
                    path: vec![F("agents"), I(a), F("devices"), I(d)],
                    inputs: &dev.inputs,
                    outputs: &dev.outputs,
                });
                self.period(
                    dev.period_ms,
                    &[F("agents"), I(a), F("devices"), I(d), F("period_ms")],
                );
            }
        }
        self.unique(
            "component",
            all.iter()
                .map(|c| (c.name, join(&c.path, &[F("name")])))
                .collect::<Vec<_>>(),
        );
        for c in all {
            self.comps.entry(c.name).or_insert(c);
        }
        let names: Vec<&str> = {
            let mut v: Vec<&str> = self.comps.keys().copied().collect();
            v.sort_unstable();
            v
        };
        for name in names {
            self.groups(name);
        }
    }

    fn agent(&mut self, a: usize) {
        let agent = &self.spec.agents[a];
        let controls: Vec<&str> = agent
            .subsystems
            .iter()
            .filter(|s| s.kind == SubsystemKind::Control)
            .map(|s| s.name.as_str())
            .collect();
        if controls.len() != 1 {
            let what = if controls.is_empty() {
                "no control subsystem".to_owned()
            } else {
                format!(
                    "{} control subsystems ({})",
                    controls.len(),
                    controls.join(", ")
                )
            };
            self.push(
                Finding::new(
                    Code::AgentControl,
                    self.span(&[F("agents"), I(a), F("name")]),
                    "this agent",
                    format!("agent `{}` has {what}", agent.name),
                )
                .help("an embodied agent has exactly one control subsystem; it coordinates the agent and talks to other agents"),
            );
        }
    }

    /// The runtime's rule ([`agent_core::Period::from_millis_f64`]): positive,
    /// finite, at least a nanosecond, at most 2^64 ns.
    fn period(&mut self, ms: f64, path: &[Seg<'static>]) {
        if let Err(e) = agent_core::Period::from_millis_f64(ms) {
            self.push(
                Finding::new(
                    Code::Period,
                    self.span(path),
                    "not a period",
                    format!("period {ms} ms: {e}"),
                )
                .help("a subsystem or device runs every `period_ms` milliseconds: a positive number from 0.000001 (1 ns)"),
            );
        }
    }

    /// Groups of one component: peers exist, are allowed, appear once; buffer names
    /// are unique in each group.
    fn groups(&mut self, name: &str) {
        let Some(c) = self.comps.get(name) else {
            return;
        };
        let (agent, kind, path, inputs, outputs) =
            (c.agent, c.kind, c.path.clone(), c.inputs, c.outputs);
        for (side, groups, outgoing) in [("inputs", inputs, false), ("outputs", outputs, true)] {
            self.unique(
                &format!("{side} group for peer"),
                groups
                    .iter()
                    .enumerate()
                    .map(|(g, x)| (x.peer.as_str(), join(&path, &[F(side), I(g), F("peer")])))
                    .collect::<Vec<_>>(),
            );
            for (g, group) in groups.iter().enumerate() {
                let gpath = join(&path, &[F(side), I(g)]);
                self.unique(
                    "buffer",
                    group
                        .buffers
                        .iter()
                        .enumerate()
                        .map(|(b, x)| {
                            (
                                x.name.as_str(),
                                join(&gpath, &[F("buffers"), I(b), F("name")]),
                            )
                        })
                        .collect::<Vec<_>>(),
                );
                let peer_path = join(&gpath, &[F("peer")]);
                match self.comps.get(group.peer.as_str()) {
                    None => {
                        let known = self.known_components();
                        self.push(
                            Finding::new(
                                Code::UnknownComponent,
                                self.span(&peer_path),
                                "no such component",
                                format!("group peer `{}` of `{name}` is not a component of the system", group.peer),
                            )
                            .help(format!("a group names the component at the other end of its buffers; components: {known}")),
                        );
                    }
                    Some(peer) => {
                        let (src, dst) = if outgoing {
                            (kind, peer.kind)
                        } else {
                            (peer.kind, kind)
                        };
                        if let Some(reason) = structure_violation(src, dst, agent == peer.agent) {
                            let peer_kind = peer.kind;
                            self.push(
                                Finding::new(
                                    Code::Structure,
                                    self.span(&peer_path),
                                    format!("a {peer_kind}"),
                                    format!("`{name}` ({kind}) cannot have {side} from/to `{}`: {reason}", group.peer),
                                )
                                .help("see the agent structure of Fig. 2: c talks to its e, r and other agents' c; e to its E; r to its R"),
                            );
                        }
                    }
                }
            }
        }
    }

    fn known_components(&mut self) -> std::rc::Rc<str> {
        if let Some(l) = &self.components_list {
            return std::rc::Rc::clone(l);
        }
        let mut v: Vec<&str> = self.comps.keys().copied().collect();
        v.sort_unstable();
        let l: std::rc::Rc<str> = list_or_none(&v).into();
        self.components_list = Some(std::rc::Rc::clone(&l));
        l
    }

    // -----------------------------------------------------------------------
    // Subsystems

    fn subsystem(&mut self, base: &[Seg<'static>], sub: &'a Subsystem) {
        let at = |rest: &[Seg<'static>]| join(base, rest);
        self.period(sub.period_ms, &at(&[F("period_ms")]));
        self.unique(
            "memory buffer",
            sub.memory
                .iter()
                .enumerate()
                .map(|(i, b)| (b.name.as_str(), at(&[F("memory"), I(i), F("name")])))
                .collect::<Vec<_>>(),
        );
        self.unique(
            "predicate",
            sub.predicates
                .iter()
                .enumerate()
                .map(|(i, p)| (p.name.as_str(), at(&[F("predicates"), I(i), F("name")])))
                .collect::<Vec<_>>(),
        );
        self.unique(
            "function",
            sub.functions
                .iter()
                .enumerate()
                .map(|(i, f)| (f.name.as_str(), at(&[F("functions"), I(i), F("name")])))
                .collect::<Vec<_>>(),
        );
        self.unique(
            "behaviour",
            sub.behaviours
                .iter()
                .enumerate()
                .map(|(i, b)| (b.name.as_str(), at(&[F("behaviours"), I(i), F("name")])))
                .collect::<Vec<_>>(),
        );

        // Reads of predicates and functions.
        for (i, p) in sub.predicates.iter().enumerate() {
            for (k, r) in p.reads.iter().enumerate() {
                self.read(sub, r, &at(&[F("predicates"), I(i), F("reads"), I(k)]));
            }
        }
        for (i, f) in sub.functions.iter().enumerate() {
            let fpath = at(&[F("functions"), I(i)]);
            for (k, r) in f.reads.iter().enumerate() {
                self.read(sub, r, &join(&fpath, &[F("reads"), I(k)]));
            }
            self.writes(sub, i, &fpath);
        }

        // Behaviours.
        let pred_index: HashMap<&str, usize> = sub
            .predicates
            .iter()
            .enumerate()
            .map(|(i, p)| (p.name.as_str(), i))
            .collect();
        let mut used_functions = HashSet::new();
        let mut used_preds = HashSet::new();
        let mut terminals = Vec::new();
        for (i, b) in sub.behaviours.iter().enumerate() {
            let bpath = at(&[F("behaviours"), I(i)]);
            let mut targets: HashMap<&Target, usize> = HashMap::new();
            for (k, fname) in b.functions.iter().enumerate() {
                let fp = join(&bpath, &[F("functions"), I(k)]);
                match sub.functions.iter().position(|f| &f.name == fname) {
                    None => {
                        let known = self.list(&sub.functions, Hint::Functions, || {
                            sub.functions.iter().map(|f| f.name.clone()).collect()
                        });
                        self.push(
                            Finding::new(
                                Code::UnknownFunction,
                                self.span(&fp),
                                "not defined",
                                format!("behaviour `{}` uses function `{fname}`, which `{}` does not define", b.name, sub.name),
                            )
                            .help(format!("define it under `functions`; defined: {known}")),
                        );
                    }
                    Some(fi) => {
                        used_functions.insert(fi);
                        let target = &sub.functions[fi].target;
                        if let Some(&other) = targets.get(target) {
                            let other_span = self.span(&join(&bpath, &[F("functions"), I(other)]));
                            self.push(
                                Finding::new(
                                    Code::DuplicateTarget,
                                    self.span(&fp),
                                    "writes the same target",
                                    format!(
                                        "behaviour `{}` has two functions writing {}",
                                        b.name,
                                        target_text(target)
                                    ),
                                )
                                .label(other_span, "also written by this one")
                                .help("the transition function is decomposed by target: one function per target per behaviour; merge them"),
                            );
                        } else {
                            targets.insert(target, k);
                        }
                    }
                }
            }
            let t = self.condition(
                sub,
                &b.terminal,
                &pred_index,
                &join(&bpath, &[F("terminal")]),
                &mut used_preds,
            );
            terminals.push(t);
        }
        self.fsm(base, sub, &pred_index, &terminals, &mut used_preds);

        for (i, f) in sub.functions.iter().enumerate() {
            if !used_functions.contains(&i) {
                self.push(
                    Finding::new(
                        Code::UnusedFunction,
                        self.span(&at(&[F("functions"), I(i), F("name")])),
                        "never used",
                        format!(
                            "function `{}` of `{}` is used by no behaviour",
                            f.name, sub.name
                        ),
                    )
                    .help("list it in a behaviour's `functions`, or remove it"),
                );
            }
        }
        for (i, p) in sub.predicates.iter().enumerate() {
            if !used_preds.contains(&i) {
                self.push(
                    Finding::new(
                        Code::UnusedPredicate,
                        self.span(&at(&[F("predicates"), I(i), F("name")])),
                        "never used",
                        format!(
                            "predicate `{}` of `{}` appears in no condition or relation",
                            p.name, sub.name
                        ),
                    )
                    .help("use it in a terminal or initial condition, or remove it"),
                );
            }
        }
    }

    /// Resolve a buffer read by a function or predicate of `sub`.
    fn read(&mut self, sub: &Subsystem, r: &str, path: &[Seg<'static>]) {
        if let Some((group, name)) = r.split_once('.') {
            match sub.inputs.iter().find(|g| g.peer == group) {
                Some(g) if g.buffers.iter().any(|b| b.name == name) => {}
                Some(g) => {
                    let known = self.list(&g.buffers, Hint::Buffers, || {
                        g.buffers.iter().map(|b| b.name.clone()).collect()
                    });
                    self.push(
                        Finding::new(
                            Code::UnknownBuffer,
                            self.span(path),
                            "no such input",
                            format!("`{}` has no input buffer `{name}` from `{group}`", sub.name),
                        )
                        .help(format!("inputs from `{group}`: {known}")),
                    );
                }
                None => {
                    let known = self.list(&sub.inputs, Hint::InputGroups, || {
                        sub.inputs.iter().map(|g| g.peer.clone()).collect()
                    });
                    self.push(
                        Finding::new(
                            Code::UnknownBuffer,
                            self.span(path),
                            "no such input group",
                            format!("`{}` has no inputs from `{group}`", sub.name),
                        )
                        .help(format!("input groups: {known}")),
                    );
                }
            }
            return;
        }
        if sub.memory.iter().any(|b| b.name == r) {
            return;
        }
        let groups: Vec<&str> = sub
            .inputs
            .iter()
            .filter(|g| g.buffers.iter().any(|b| b.name == r))
            .map(|g| g.peer.as_str())
            .collect();
        match groups.len() {
            1 => {}
            0 => {
                let known = self.list(&sub.memory, Hint::Readable, || {
                    let mut known: Vec<String> =
                        sub.memory.iter().map(|b| b.name.clone()).collect();
                    known.extend(sub.inputs.iter().flat_map(|g| {
                        g.buffers
                            .iter()
                            .map(move |b| format!("{}.{}", g.peer, b.name))
                    }));
                    known
                });
                self.push(
                    Finding::new(
                        Code::UnknownBuffer,
                        self.span(path),
                        "no such buffer",
                        format!("`{}` has no memory or input buffer `{r}`", sub.name),
                    )
                    .help(format!("readable buffers: {known}")),
                );
            }
            _ => self.push(
                Finding::new(
                    Code::AmbiguousBuffer,
                    self.span(path),
                    "which one?",
                    format!(
                        "input buffer `{r}` of `{}` exists in several groups ({})",
                        sub.name,
                        groups.join(", ")
                    ),
                )
                .help(format!(
                    "qualify it with its group, e.g. `{}.{r}`",
                    groups[0]
                )),
            ),
        }
    }

    /// A function's target exists and it writes only there.
    fn writes(&mut self, sub: &Subsystem, i: usize, fpath: &[Seg<'static>]) {
        let f = &sub.functions[i];
        let target_group = match &f.target {
            Target::Memory | Target::Common => None,
            Target::Output(peer) => match sub.outputs.iter().find(|g| &g.peer == peer) {
                Some(g) => Some(g),
                None => {
                    let known = self.list(&sub.outputs, Hint::OutputGroups, || {
                        sub.outputs.iter().map(|g| g.peer.clone()).collect()
                    });
                    self.push(
                        Finding::new(
                            Code::UnknownTarget,
                            self.span(&join(fpath, &[F("target")])),
                            "no such output group",
                            format!("function `{}` targets the outputs towards `{peer}`, which `{}` does not have", f.name, sub.name),
                        )
                        .help(format!("targets: Memory, Common, or Output(peer) with peer among: {known}")),
                    );
                    return;
                }
            },
        };
        for (k, w) in f.writes.iter().enumerate() {
            let wpath = join(fpath, &[F("writes"), I(k)]);
            let (group, name) = match w.split_once('.') {
                Some((g, n)) => (Some(g), n),
                None => (None, w.as_str()),
            };
            let inside = match (target_group, group) {
                (None, None) => sub.memory.iter().any(|b| b.name == name),
                (Some(g), None) => g.buffers.iter().any(|b| b.name == name),
                (Some(g), Some(q)) => g.peer == q && g.buffers.iter().any(|b| b.name == name),
                (None, Some(_)) => false,
            };
            if inside {
                continue;
            }
            let exists_elsewhere = sub.memory.iter().any(|b| b.name == name && group.is_none())
                || sub.outputs.iter().any(|g| {
                    group.is_none_or(|q| q == g.peer) && g.buffers.iter().any(|b| b.name == name)
                })
                || sub.inputs.iter().any(|g| {
                    group.is_none_or(|q| q == g.peer) && g.buffers.iter().any(|b| b.name == name)
                });
            if exists_elsewhere {
                self.push(
                    Finding::new(
                        Code::WriteOutsideTarget,
                        self.span(&wpath),
                        format!("not in {}", target_text(&f.target)),
                        format!("function `{}` writes `{w}`, outside its target {}", f.name, target_text(&f.target)),
                    )
                    .label(self.span(&join(fpath, &[F("target")])), "the declared target")
                    .help("a transition function writes only its target (the paper's decomposition by target); split it into one function per target"),
                );
            } else {
                let known = match target_group {
                    Some(g) => self.list(&g.buffers, Hint::Buffers, || {
                        g.buffers.iter().map(|b| b.name.clone()).collect()
                    }),
                    None => self.list(&sub.memory, Hint::Buffers, || {
                        sub.memory.iter().map(|b| b.name.clone()).collect()
                    }),
                };
                self.push(
                    Finding::new(
                        Code::UnknownBuffer,
                        self.span(&wpath),
                        "no such buffer",
                        format!(
                            "function `{}` writes `{w}`, which `{}` does not have",
                            f.name, sub.name
                        ),
                    )
                    .help(format!("buffers of {}: {known}", target_text(&f.target))),
                );
            }
        }
    }

    /// Parse and resolve a condition; report syntax errors and unknown predicates.
    fn condition(
        &mut self,
        sub: &Subsystem,
        text: &str,
        preds: &HashMap<&str, usize>,
        path: &[Seg<'static>],
        used: &mut HashSet<usize>,
    ) -> Option<Expr<usize>> {
        let parsed = match Expr::parse(text) {
            Ok(e) => e,
            Err(e) => {
                let span = match self.node(path) {
                    // At the end of the condition: point at the closing quote.
                    Some(n) if e.offset >= text.len() => {
                        let content = n.content_span();
                        if content.end < n.span.end {
                            content.end..content.end + 1
                        } else {
                            n.span.clone()
                        }
                    }
                    Some(n) => n.sub_span(e.offset..e.offset + e.len.max(1)),
                    None => self.span(path),
                };
                self.push(
                    Finding::new(Code::ConditionSyntax, span, e.message.clone(), format!("condition `{}` does not parse", abbreviate(text, 80)))
                        .help("conditions are predicate names with `!`, `&&`, `||`, parentheses, `true` and `false`"),
                );
                return None;
            }
        };
        let resolved = rules::resolve_condition(&parsed, |name| {
            let i = preds.get(name).copied();
            used.extend(i);
            i
        });
        let missing = resolved.as_ref().err().cloned().unwrap_or_default();
        let offsets = if missing.is_empty() {
            HashMap::new()
        } else {
            ident_offsets(text)
        };
        for name in &missing {
            let span = match (self.node(path), offsets.get(name.as_str())) {
                (Some(n), Some(&off)) => n.sub_span(off..off + name.len()),
                _ => self.span(path),
            };
            let known = self.list(&sub.predicates, Hint::Predicates, || {
                sorted(sub.predicates.iter().map(|p| p.name.clone()))
            });
            self.push(
                Finding::new(
                    Code::UnknownPredicate,
                    span,
                    "not declared",
                    format!(
                        "condition `{}` uses predicate `{name}`, which is not declared",
                        abbreviate(text, 80)
                    ),
                )
                .help(format!("declare it under `predicates`; declared: {known}")),
            );
        }
        resolved.ok()
    }

    fn fsm(
        &mut self,
        base: &[Seg<'static>],
        sub: &Subsystem,
        preds: &HashMap<&str, usize>,
        terminals: &[Option<Expr<usize>>],
        used: &mut HashSet<usize>,
    ) {
        let at = |rest: &[Seg<'static>]| join(base, rest);
        let unknown = |this: &mut Self, name: &str, path: Path, place: &str| {
            let known = this.list(&sub.behaviours, Hint::Behaviours, || {
                sub.behaviours.iter().map(|b| b.name.clone()).collect()
            });
            this.push(
                Finding::new(
                    Code::UnknownBehaviour,
                    this.span(&path),
                    "no such behaviour",
                    format!(
                        "{place} names behaviour `{name}`, which `{}` does not define",
                        sub.name
                    ),
                )
                .help(format!("behaviours: {known}")),
            );
        };

        // Relations. If one names an undeclared predicate (reported here), the arc proof
        // would miss an assumption and report arcs that the relation may well make
        // sound: it is skipped, like the proof of arcs whose conditions do not resolve.
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
                        let known = self.list(&sub.predicates, Hint::Predicates, || {
                            sorted(sub.predicates.iter().map(|p| p.name.clone()))
                        });
                        self.push(
                            Finding::new(
                                Code::UnknownPredicate,
                                self.span(path),
                                "not declared",
                                format!("relation names predicate `{n}`, which is not declared"),
                            )
                            .help(format!(
                                "relations are between predicates declared under `predicates`; declared: {known}"
                            )),
                        );
                    }
                }
            }
            if ok.len() == names.len() {
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
        }

        // The shape rules (agent-core's, shared with `FsmBuilder`), with spans.
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
                    unknown(self, &name, path, what);
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
        // The arcs' conditions, for the proof.
        let mut arcs: Vec<Vec<(usize, Option<Expr<usize>>)>> =
            vec![Vec::new(); sub.behaviours.len()];
        for (k, arc) in sub.fsm.arcs.iter().enumerate() {
            let apath = at(&[F("fsm"), F("arcs"), I(k)]);
            let cond = self.condition(sub, &arc.when, preds, &join(&apath, &[F("when")]), used);
            if let Some((f, _)) = shape.arcs[k] {
                arcs[f].push((k, cond));
            }
        }
        let finals = &shape.finals;

        // Ways out and the arc proof.
        for (i, b) in sub.behaviours.iter().enumerate() {
            let name_span = self.span(&at(&[F("behaviours"), I(i), F("name")]));
            let literal_false = b.terminal.trim() == "false";
            let Some(terminal) = &terminals[i] else {
                continue;
            };
            if !self.prove {
                continue;
            }
            let conds: Vec<(usize, &Expr<usize>)> = arcs[i]
                .iter()
                .filter_map(|(k, c)| c.as_ref().map(|c| (*k, c)))
                .collect();
            // Arcs are proven when each condition and relation resolved (the others
            // were reported), and the behaviour is not final.
            let prove_arcs = !arcs[i].is_empty()
                && conds.len() == arcs[i].len()
                && relations_resolve
                && !finals[i];
            let mut assumed: Vec<&Expr<usize>> = relations.iter().collect();
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
            let runs_forever = literal_false && arcs[i].is_empty();
            if answer.can_end == Some(false) && !runs_forever {
                self.push(
                    Finding::new(
                        Code::TerminalNever,
                        self.span(&tpath),
                        "never holds",
                        format!("the terminal condition of `{}` can never hold{}", b.name, if arcs[i].is_empty() { "" } else { ", so its arcs are never taken" }),
                    )
                    .help("a behaviour with a constant-false terminal condition runs forever; write `false` if that is meant"),
                );
            }
            if arcs[i].is_empty() {
                if shape.lacks_way_out(i, can_end) {
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
                continue;
            }
            if prove_arcs {
                self.arc_findings(sub, base, i, &conds, &answer);
            }
        }
    }

    /// The findings of the arc proof for behaviour `b`: arcs that can hold at once,
    /// a case no arc covers (each with the assignment), questions the budget left
    /// undecided.
    fn arc_findings(
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

    /// Find `comp.group.buffer`: (component, group peer, buffer type) on `outputs` or
    /// inputs.
    fn endpoint(
        &self,
        text: &str,
        outputs: bool,
    ) -> Result<(&'a str, &'a str, &'a str), EndpointError> {
        let parts: Vec<&str> = text.split('.').collect();
        let [comp, group, buffer] = parts[..] else {
            return Err(EndpointError::Form);
        };
        let Some(c) = self.comps.get(comp) else {
            return Err(EndpointError::Component(comp.to_owned()));
        };
        let find = |groups: &'a [Group]| {
            groups
                .iter()
                .find(|g| g.peer == group)
                .and_then(|g| g.buffers.iter().find(|b| b.name == buffer).map(|b| (g, b)))
        };
        match find(if outputs { c.outputs } else { c.inputs }) {
            Some((g, b)) => Ok((c.name, g.peer.as_str(), b.ty.as_str())),
            None if find(if outputs { c.inputs } else { c.outputs }).is_some() => {
                Err(EndpointError::Direction)
            }
            None => Err(EndpointError::Buffer),
        }
    }

    fn links(&mut self) {
        let spec = self.spec;
        let mut writers: HashMap<(String, String, String), Vec<usize>> = HashMap::new();
        let mut read_outputs: HashSet<(String, String, String)> = HashSet::new();
        for (k, link) in spec.links.iter().enumerate() {
            let lpath = vec![F("links"), I(k)];
            let from = self.endpoint(&link.from, true);
            let to = self.endpoint(&link.to, false);
            for (res, text, field, outputs) in [
                (&from, &link.from, "from", true),
                (&to, &link.to, "to", false),
            ] {
                if let Err(e) = res {
                    self.endpoint_error(e, text, &join(&lpath, &[F(field)]), outputs);
                }
            }
            if let Policy::Queue { bound: 0 } = link.policy {
                self.push(
                    Finding::new(
                        Code::QueueBound,
                        self.span(&join(&lpath, &[F("policy")])),
                        "capacity 0",
                        format!(
                            "link `{} -> {}` is a queue of capacity 0",
                            link.from, link.to
                        ),
                    )
                    .help("a queue holds at least one value; use Queue(n) with n >= 1, or Sample"),
                );
            }
            if let Ok((c, g, _)) = &from {
                read_outputs.insert((c.to_string(), g.to_string(), last(&link.from)));
            }
            let (Ok((fc, fg, fty)), Ok((tc, tg, tty))) = (from, to) else {
                continue;
            };
            writers
                .entry((tc.to_owned(), tg.to_owned(), last(&link.to)))
                .or_default()
                .push(k);
            if fg != tc || tg != fc {
                self.push(
                    Finding::new(
                        Code::PeerMismatch,
                        self.span(&join(&lpath, &[F("to")])),
                        format!("a buffer of `{tc}` for peer `{tg}`"),
                        format!("link `{} -> {}` joins groups that do not name each other: `{fc}`'s group is for `{fg}`, `{tc}`'s group is for `{tg}`", link.from, link.to),
                    )
                    .label(self.span(&join(&lpath, &[F("from")])), format!("a buffer of `{fc}` for peer `{fg}`"))
                    .help(format!("link `{fc}.{tc}.<buffer>` to `{tc}.{fc}.<buffer>`")),
                );
            }
            let (sc, dc) = (&self.comps[fc], &self.comps[tc]);
            if let Some(reason) = structure_violation(sc.kind, dc.kind, sc.agent == dc.agent) {
                self.push(
                    Finding::new(
                        Code::Structure,
                        self.span(&lpath),
                        format!("{} -> {}", sc.kind, dc.kind),
                        format!("link `{} -> {}` breaks the agent structure: {reason}", link.from, link.to),
                    )
                    .help("see Fig. 2 of the paper: c talks to its e, r and other agents' c; e to its E; r to its R"),
                );
            }
            if normalize_type(fty) != normalize_type(tty) {
                self.push(
                    Finding::new(
                        Code::TypeMismatch,
                        self.span(&join(&lpath, &[F("to")])),
                        format!("`{tty}`"),
                        format!("link `{} -> {}` joins a `{fty}` output to a `{tty}` input", link.from, link.to),
                    )
                    .label(self.span(&join(&lpath, &[F("from")])), format!("`{fty}`"))
                    .help("both ends of a link carry the same type; change one of the buffer declarations"),
                );
            }
        }
        // Inputs: exactly one writer. Outputs: somebody reads.
        let mut comps: Vec<&Comp<'a>> = self.comps.values().collect();
        comps.sort_by_key(|c| c.path.clone().into_iter().map(seg_key).collect::<Vec<_>>());
        let mut found = Vec::new();
        for c in comps {
            for (side, groups, outgoing) in
                [("inputs", c.inputs, false), ("outputs", c.outputs, true)]
            {
                for (g, group) in groups.iter().enumerate() {
                    for (b, buffer) in group.buffers.iter().enumerate() {
                        let key = (c.name.to_owned(), group.peer.clone(), buffer.name.clone());
                        let bpath = join(&c.path, &[F(side), I(g), F("buffers"), I(b), F("name")]);
                        let dotted = format!("{}.{}.{}", c.name, group.peer, buffer.name);
                        if outgoing {
                            if !read_outputs.contains(&key) {
                                found.push(
                                    Finding::new(Code::UnreadOutput, self.span(&bpath), "read by nobody", format!("output `{dotted}` is linked to no input"))
                                        .help(format!("link it: `(from: \"{dotted}\", to: \"{}.{}.{}\")`, or remove it", group.peer, c.name, buffer.name)),
                                );
                            }
                            continue;
                        }
                        match writers.get(&key).map(Vec::as_slice) {
                            None | Some([]) => found.push(
                                Finding::new(Code::UnfedInput, self.span(&bpath), "fed by no output", format!("input `{dotted}` is fed by no output"))
                                    .help(format!("link an output to it: `(from: \"{}.{}.{}\", to: \"{dotted}\")`", group.peer, c.name, buffer.name)),
                            ),
                            Some([_]) => {}
                            Some(ks) => {
                                let mut f = Finding::new(
                                    Code::MultipleWriters,
                                    self.span(&bpath),
                                    format!("fed by {} outputs", ks.len()),
                                    format!("input `{dotted}` is fed by {} outputs", ks.len()),
                                )
                                .help("an input buffer has exactly one writer; remove all links to it but one");
                                for &k in ks {
                                    f = f.label(self.span(&[F("links"), I(k), F("from")]), "writes it");
                                }
                                found.push(f);
                            }
                        }
                    }
                }
            }
        }
        self.findings.extend(found);
    }

    fn endpoint_error(
        &mut self,
        e: &EndpointError,
        text: &str,
        path: &[Seg<'static>],
        outputs: bool,
    ) {
        let side = if outputs { "an output" } else { "an input" };
        let f = match e {
            EndpointError::Form => Finding::new(
                Code::UnknownBuffer,
                self.span(path),
                "not `component.group.buffer`",
                format!("link end `{text}` is not of the form `component.group.buffer`"),
            )
            .help("name the component, the group's peer and the buffer, e.g. `c1.e11.traj`"),
            EndpointError::Component(c) => {
                let known = self.known_components();
                Finding::new(
                    Code::UnknownComponent,
                    self.span(path),
                    "no such component",
                    format!("link end `{text}` names component `{c}`, which does not exist"),
                )
                .help(format!("components: {known}"))
            }
            EndpointError::Direction => Finding::new(
                Code::LinkDirection,
                self.span(path),
                format!("not {side}"),
                format!(
                    "link end `{text}` must be {side}, but it is {}",
                    if outputs { "an input" } else { "an output" }
                ),
            )
            .help("a link goes from an output buffer (`from`) to an input buffer (`to`)"),
            EndpointError::Buffer => Finding::new(
                Code::UnknownBuffer,
                self.span(path),
                "no such buffer",
                format!(
                    "link end `{text}` names no {} buffer",
                    if outputs { "output" } else { "input" }
                ),
            )
            .help("check the group (the peer's name) and the buffer's name"),
        };
        self.push(f);
    }

    // -----------------------------------------------------------------------
    // Deployments

    fn deployments(&mut self) {
        let spec = self.spec;
        self.unique(
            "deployment",
            spec.deployments
                .iter()
                .enumerate()
                .map(|(d, x)| (x.name.as_str(), vec![F("deployments"), I(d), F("name")]))
                .collect::<Vec<_>>(),
        );
        let mut all: Vec<&str> = self.comps.keys().copied().collect();
        all.sort_unstable();
        for (d, dep) in spec.deployments.iter().enumerate() {
            let dpath = vec![F("deployments"), I(d)];
            self.unique(
                "host",
                dep.hosts
                    .iter()
                    .enumerate()
                    .map(|(h, x)| {
                        (
                            x.name.as_str(),
                            join(&dpath, &[F("hosts"), I(h), F("name")]),
                        )
                    })
                    .collect::<Vec<_>>(),
            );
            self.unique(
                "process",
                dep.hosts
                    .iter()
                    .enumerate()
                    .flat_map(|(h, host)| {
                        let dpath = dpath.clone();
                        host.processes.iter().enumerate().map(move |(p, x)| {
                            (
                                x.name.as_str(),
                                join(&dpath, &[F("hosts"), I(h), F("processes"), I(p), F("name")]),
                            )
                        })
                    })
                    .collect::<Vec<_>>(),
            );
            let mut placed: HashMap<&str, Path> = HashMap::new();
            let mut place = |this: &mut Self, name: &'a str, path: Path, what: &str| {
                if !this.comps.contains_key(name) {
                    let known = this.known_components();
                    this.push(
                        Finding::new(
                            Code::UnknownComponent,
                            this.span(&path),
                            "no such component",
                            format!(
                                "deployment `{}` {what} `{name}`, which is not a component",
                                dep.name
                            ),
                        )
                        .help(format!("components: {known}")),
                    );
                    return;
                }
                if let Some(first) = placed.get(name) {
                    let first = this.span(first);
                    this.push(
                        Finding::new(
                            Code::DeployTwice,
                            this.span(&path),
                            "placed again",
                            format!("deployment `{}` places `{name}` twice", dep.name),
                        )
                        .label(first, "first placed here")
                        .help("a component runs in exactly one process, or is omitted"),
                    );
                } else {
                    placed.insert(name, path);
                }
            };
            for (h, host) in dep.hosts.iter().enumerate() {
                for (p, proc_) in host.processes.iter().enumerate() {
                    for (k, name) in proc_.runs.iter().enumerate() {
                        place(
                            self,
                            name,
                            join(
                                &dpath,
                                &[F("hosts"), I(h), F("processes"), I(p), F("runs"), I(k)],
                            ),
                            "runs",
                        );
                    }
                }
            }
            for (k, name) in dep.omit.iter().enumerate() {
                place(self, name, join(&dpath, &[F("omit"), I(k)]), "omits");
            }
            for name in &all {
                if !placed.contains_key(name) {
                    self.push(
                        Finding::new(Code::DeployMissing, self.span(&join(&dpath, &[F("name")])), format!("`{name}` is not placed"), format!("deployment `{}` neither runs nor omits `{name}`", dep.name))
                            .help(format!("add `{name}` to a process's `runs`, or to `omit` if this deployment goes without it")),
                    );
                }
            }
        }
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
