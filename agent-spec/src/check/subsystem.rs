//! A subsystem's memory, functions, reads and writes, predicates and conditions.

use super::components::names_at;
use super::*;

impl<'a> Checker<'a> {
    /// Subsystem `sub` at `base`: its period, names, reads and writes,
    /// behaviours and FSM, and what goes unused.
    pub(super) fn subsystem(&mut self, base: &[Seg<'static>], sub: &'a Subsystem) {
        self.period(sub.period_ms, &join(base, &[F("period_ms")]));
        self.unique_names(base, sub);
        self.reads_and_writes(base, sub);
        let pred_index: HashMap<&str, usize> = sub
            .predicates
            .iter()
            .enumerate()
            .map(|(i, p)| (p.name.as_str(), i))
            .collect();
        let mut used_functions = HashSet::new();
        let mut used_preds = HashSet::new();
        let terminals =
            self.behaviours(base, sub, &pred_index, &mut used_functions, &mut used_preds);
        self.fsm(base, sub, &pred_index, &terminals, &mut used_preds);
        self.unused(base, sub, &used_functions, &used_preds);
    }

    /// The names of the memory buffers, predicates, functions and behaviours
    /// are each unique.
    fn unique_names(&mut self, base: &[Seg<'static>], sub: &'a Subsystem) {
        let memory = sub.memory.iter().map(|b| b.name.as_str());
        self.unique("memory buffer", names_at(base, "memory", memory));
        let predicates = sub.predicates.iter().map(|p| p.name.as_str());
        self.unique("predicate", names_at(base, "predicates", predicates));
        let functions = sub.functions.iter().map(|f| f.name.as_str());
        self.unique("function", names_at(base, "functions", functions));
        let behaviours = sub.behaviours.iter().map(|b| b.name.as_str());
        self.unique("behaviour", names_at(base, "behaviours", behaviours));
    }

    /// The reads of predicates and functions, and the functions' writes.
    fn reads_and_writes(&mut self, base: &[Seg<'static>], sub: &Subsystem) {
        let at = |rest: &[Seg<'static>]| join(base, rest);
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
    }

    /// Each behaviour's functions and terminal condition; the terminal
    /// conditions resolved (`None` where one does not), by behaviour.
    fn behaviours(
        &mut self,
        base: &[Seg<'static>],
        sub: &Subsystem,
        pred_index: &HashMap<&str, usize>,
        used_functions: &mut HashSet<usize>,
        used_preds: &mut HashSet<usize>,
    ) -> Vec<Option<Expr<usize>>> {
        let mut terminals = Vec::new();
        for (i, b) in sub.behaviours.iter().enumerate() {
            let bpath = join(base, &[F("behaviours"), I(i)]);
            self.behaviour_functions(sub, b, &bpath, used_functions);
            let t = self.condition(
                sub,
                &b.terminal,
                pred_index,
                &join(&bpath, &[F("terminal")]),
                used_preds,
            );
            terminals.push(t);
        }
        terminals
    }

    /// Behaviour `b` (at `bpath`) uses functions `sub` defines, at most one per
    /// target.
    fn behaviour_functions(
        &mut self,
        sub: &Subsystem,
        b: &crate::model::Behaviour,
        bpath: &[Seg<'static>],
        used_functions: &mut HashSet<usize>,
    ) {
        let mut targets: HashMap<&Target, usize> = HashMap::new();
        for (k, fname) in b.functions.iter().enumerate() {
            let fp = join(bpath, &[F("functions"), I(k)]);
            match sub.functions.iter().position(|f| &f.name == fname) {
                None => {
                    let known = self.list(&sub.functions, Hint::Functions, || {
                        sub.functions.iter().map(|f| f.name.clone()).collect()
                    });
                    let guess = self.guess(fname, sub.functions.iter().map(|f| f.name.as_str()));
                    self.push(
                        Finding::new(
                            Code::UnknownFunction,
                            self.span(&fp),
                            "not defined",
                            format!("behaviour `{}` uses function `{fname}`, which `{}` does not define", b.name, sub.name),
                        )
                        .help(format!("{guess}define it under `functions`; defined: {known}")),
                    );
                }
                Some(fi) => {
                    used_functions.insert(fi);
                    let target = &sub.functions[fi].target;
                    if let Some(&other) = targets.get(target) {
                        let other_span = self.span(&join(bpath, &[F("functions"), I(other)]));
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
    }

    /// The functions no behaviour uses, and the predicates no condition or
    /// relation uses.
    fn unused(
        &mut self,
        base: &[Seg<'static>],
        sub: &Subsystem,
        used_functions: &HashSet<usize>,
        used_preds: &HashSet<usize>,
    ) {
        let at = |rest: &[Seg<'static>]| join(base, rest);
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
    pub(super) fn read(&mut self, sub: &Subsystem, r: &str, path: &[Seg<'static>]) {
        if let Some((group, name)) = r.split_once('.') {
            match sub.inputs.iter().find(|g| g.peer == group) {
                Some(g) if g.buffers.iter().any(|b| b.name == name) => {}
                Some(g) => {
                    let known = self.list(&g.buffers, Hint::Buffers, || {
                        g.buffers.iter().map(|b| b.name.clone()).collect()
                    });
                    let guess = self.guess(name, g.buffers.iter().map(|b| b.name.as_str()));
                    self.push(
                        Finding::new(
                            Code::UnknownBuffer,
                            self.span(path),
                            "no such input",
                            format!("`{}` has no input buffer `{name}` from `{group}`", sub.name),
                        )
                        .help(format!("{guess}inputs from `{group}`: {known}")),
                    );
                }
                None => {
                    let known = self.list(&sub.inputs, Hint::InputGroups, || {
                        sub.inputs.iter().map(|g| g.peer.clone()).collect()
                    });
                    let guess = self.guess(group, sub.inputs.iter().map(|g| g.peer.as_str()));
                    self.push(
                        Finding::new(
                            Code::UnknownBuffer,
                            self.span(path),
                            "no such input group",
                            format!("`{}` has no inputs from `{group}`", sub.name),
                        )
                        .help(format!("{guess}input groups: {known}")),
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
                // Keyed on the subsystem: the list mixes its memory and its inputs.
                let known = self.list(std::slice::from_ref(sub), Hint::Readable, || {
                    let mut known: Vec<String> =
                        sub.memory.iter().map(|b| b.name.clone()).collect();
                    known.extend(sub.inputs.iter().flat_map(|g| {
                        g.buffers
                            .iter()
                            .map(move |b| format!("{}.{}", g.peer, b.name))
                    }));
                    known
                });
                let guess = self.guess(
                    r,
                    sub.memory.iter().map(|b| b.name.as_str()).chain(
                        sub.inputs
                            .iter()
                            .flat_map(|g| g.buffers.iter().map(|b| b.name.as_str())),
                    ),
                );
                self.push(
                    Finding::new(
                        Code::UnknownBuffer,
                        self.span(path),
                        "no such buffer",
                        format!("`{}` has no memory or input buffer `{r}`", sub.name),
                    )
                    .help(format!("{guess}readable buffers: {known}")),
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
    pub(super) fn writes(&mut self, sub: &Subsystem, i: usize, fpath: &[Seg<'static>]) {
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
    pub(super) fn condition(
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
            let guess = self.guess(name, sub.predicates.iter().map(|p| p.name.as_str()));
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
                .help(format!(
                    "{guess}declare it under `predicates`; declared: {known}"
                )),
            );
        }
        resolved.ok()
    }
}
