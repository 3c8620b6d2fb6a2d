//! The `contracts` and `timing` sections: every name they use exists, every
//! number is a positive finite one, chains connect a real receptor to a real
//! effector through links.

use super::components::names_at;
use super::*;
use crate::model::{DeviceKind, Link};

/// Where a contract's buffer was found.
struct Found<'a> {
    /// The buffer's declared type.
    ty: &'a str,
}

impl<'a> Checker<'a> {
    /// Both sections, when the spec has them.
    pub(super) fn contracts(&mut self) {
        if let Some(c) = &self.spec.contracts {
            self.contracts_section(c);
        }
        if let Some(t) = &self.spec.timing {
            self.timing_section(t);
            // The system as one process: the analysis of a deployment is
            // `embodied check --timing --deployment D`. Only on a spec that is
            // otherwise sound: the analysis trusts names, links and numbers.
            let sound = self
                .findings
                .iter()
                .all(|f| f.severity() == crate::diag::Severity::Warning);
            if sound && let Ok(a) = crate::timing::analyse(self.spec, self.index, None) {
                self.findings.extend(a.findings);
            }
        }
    }

    /// The `contracts` section.
    fn contracts_section(&mut self, c: &'a crate::model::Contracts) {
        {
            let base: Path = vec![F("contracts")];
            for (i, f) in c.freshness.iter().enumerate() {
                let at = join(&base, &[F("freshness"), I(i)]);
                self.input_ref(&f.input, &join(&at, &[F("input")]));
                self.positive(
                    f.max_age_ms,
                    &join(&at, &[F("max_age_ms")]),
                    "a largest age [ms]",
                );
            }
            for (i, r) in c.rates.iter().enumerate() {
                let at = join(&base, &[F("rates"), I(i)]);
                self.input_ref(&r.input, &join(&at, &[F("input")]));
                self.positive(r.min_hz, &join(&at, &[F("min_hz")]), "a rate [Hz]");
            }
            for (i, b) in c.bounds.iter().enumerate() {
                let at = join(&base, &[F("bounds"), I(i)]);
                self.behaviour_ref(&b.behaviour, &join(&at, &[F("behaviour")]));
                if let Some(s) = b.max_s {
                    self.positive(s, &join(&at, &[F("max_s")]), "a duration [s]");
                }
                if b.max_iterations == Some(0) {
                    self.contract_finding(
                        &join(&at, &[F("max_iterations")]),
                        "zero",
                        format!("behaviour `{}` is bounded by 0 iterations", b.behaviour),
                        "a behaviour runs its elementary action at least once: give at least 1",
                    );
                }
                if b.max_s.is_none() && b.max_iterations.is_none() {
                    self.contract_finding(
                        &at,
                        "no bound",
                        format!("the bound of behaviour `{}` gives neither `max_s` nor `max_iterations`", b.behaviour),
                        "give `max_s`, `max_iterations` or both",
                    );
                }
            }
            self.unique(
                "invariant",
                names_at(
                    &base,
                    "invariants",
                    c.invariants.iter().map(|x| x.name.as_str()),
                ),
            );
            for (i, inv) in c.invariants.iter().enumerate() {
                let at = join(&base, &[F("invariants"), I(i)]);
                let Some(sub) = self.subsystem_ref(&inv.subsystem, &join(&at, &[F("subsystem")]))
                else {
                    continue;
                };
                let preds: HashMap<&str, usize> = sub
                    .predicates
                    .iter()
                    .enumerate()
                    .map(|(k, p)| (p.name.as_str(), k))
                    .collect();
                let mut used = HashSet::new();
                self.condition(
                    sub,
                    &inv.holds,
                    &preds,
                    &join(&at, &[F("holds")]),
                    &mut used,
                );
            }
            self.unique(
                "range",
                names_at(&base, "ranges", c.ranges.iter().map(|x| x.name.as_str())),
            );
            for (i, r) in c.ranges.iter().enumerate() {
                let at = join(&base, &[F("ranges"), I(i)]);
                self.range(r, &at);
            }
            self.unique(
                "response",
                names_at(
                    &base,
                    "responses",
                    c.responses.iter().map(|x| x.name.as_str()),
                ),
            );
            for (i, r) in c.responses.iter().enumerate() {
                let at = join(&base, &[F("responses"), I(i)]);
                self.buffer_ref(&r.trigger, &join(&at, &[F("trigger")]));
                self.buffer_ref(&r.response, &join(&at, &[F("response")]));
                self.paired_fans(r, &at);
                self.positive(r.within_s, &join(&at, &[F("within_s")]), "a deadline [s]");
            }
            self.unique(
                "chain",
                names_at(&base, "chains", c.chains.iter().map(|x| x.name.as_str())),
            );
            for (i, ch) in c.chains.iter().enumerate() {
                let at = join(&base, &[F("chains"), I(i)]);
                self.chain(ch, &at);
            }
        }
    }

    /// The `timing` section.
    fn timing_section(&mut self, t: &'a crate::model::Timing) {
        {
            let base: Path = vec![F("timing")];
            let wcets = t.wcet.iter().map(|w| (w.component.as_str(), w.ms));
            self.per_component(&base, "wcet", wcets, "worst-case execution time", true);
            let jitters = t
                .release_jitter
                .iter()
                .map(|j| (j.component.as_str(), j.ms));
            self.per_component(&base, "release_jitter", jitters, "release jitter", false);
            let mut seen: HashMap<&str, Path> = HashMap::new();
            for (i, l) in t.latency.iter().enumerate() {
                let at = join(&base, &[F("latency"), I(i)]);
                let dpath = join(&at, &[F("deployment")]);
                if self.spec.deployment(&l.deployment).is_none() {
                    let guess = self.guess(
                        &l.deployment,
                        self.spec.deployments.iter().map(|d| d.name.as_str()),
                    );
                    let known = self.spec.deployment_names();
                    self.contract_finding(
                        &dpath,
                        "no such deployment",
                        format!(
                            "a latency is declared for deployment `{}`, which does not exist",
                            l.deployment
                        ),
                        format!(
                            "{guess}deployments: {}",
                            if known.is_empty() { "(none)" } else { &known }
                        ),
                    );
                } else if let Some(first) = seen.get(l.deployment.as_str()) {
                    let first = self.span(first);
                    self.push(
                        Finding::new(
                            Code::DuplicateName,
                            self.span(&dpath),
                            "given again here",
                            format!(
                                "the latency of deployment `{}` is given twice",
                                l.deployment
                            ),
                        )
                        .label(first, "first given here")
                        .help("give each deployment's latency once"),
                    );
                } else {
                    seen.insert(&l.deployment, dpath);
                }
                if !(l.ms.is_finite() && l.ms >= 0.0) {
                    self.contract_finding(
                        &join(&at, &[F("ms")]),
                        "not a latency",
                        format!("latency {} ms is not a finite number of at least 0", l.ms),
                        "a latency bound is in milliseconds, 0 or more",
                    );
                }
            }
            for (i, w) in t.writes.iter().enumerate() {
                self.writes_entry(i, w, &base);
            }
        }
    }

    /// A list of `timing.<field>` giving each component a figure `what` in
    /// ms: known components, each once, the figure positive (`positive`) or
    /// else at least 0.
    fn per_component(
        &mut self,
        base: &[Seg<'static>],
        field: &'static str,
        entries: impl Iterator<Item = (&'a str, f64)>,
        what: &str,
        positive: bool,
    ) {
        let mut seen: HashMap<&str, Path> = HashMap::new();
        for (i, (component, ms)) in entries.enumerate() {
            let at = join(base, &[F(field), I(i)]);
            let cpath = join(&at, &[F("component")]);
            if !self.comps.contains_key(component) {
                self.unknown_component(component, &cpath, &format!("a {what}"));
            } else if let Some(first) = seen.get(component) {
                let first = self.span(first);
                self.push(
                    Finding::new(
                        Code::DuplicateName,
                        self.span(&cpath),
                        "given again here",
                        format!("the {what} of `{component}` is given twice"),
                    )
                    .label(first, "first given here")
                    .help(format!("give each component's {what} once")),
                );
            } else {
                seen.insert(component, cpath);
            }
            let mpath = join(&at, &[F("ms")]);
            if positive {
                self.positive(ms, &mpath, &format!("a {what} [ms]"));
            } else if !(ms.is_finite() && ms >= 0.0) {
                self.contract_finding(
                    &mpath,
                    "not a time",
                    format!("{what} {ms} ms is not a finite number of at least 0"),
                    format!("a {what} is in milliseconds, 0 or more"),
                );
            }
        }
    }

    /// One entry of `timing.writes`.
    fn writes_entry(&mut self, i: usize, w: &crate::model::Writes, base: &[Seg<'static>]) {
        let at = join(base, &[F("writes"), I(i)]);
        let lpath = join(&at, &[F("link")]);
        let link = self
            .spec
            .links
            .iter()
            .find(|l: &&Link| l.from == w.link || l.to == w.link);
        let end = match self.endpoint(&w.link, true) {
            Err(EndpointError::Direction) => self.endpoint(&w.link, false).map(|_| ()),
            other => other.map(|_| ()),
        };
        match end {
            Err(e) => self.endpoint_error(&e, &w.link, &lpath, true),
            Ok(()) => {
                let queue = link.is_some_and(|l| matches!(l.policy, Policy::Queue { .. }));
                if link.is_none() {
                    self.contract_finding(
                        &lpath,
                        "no link",
                        format!("no link carries `{}`", w.link),
                        "name the output end of a link (`links: [(from: ...)]`)",
                    );
                } else if w.min_interval_ms.is_some() && !queue {
                    self.contract_finding(
                        &join(&at, &[F("min_interval_ms")]),
                        "not a queue link",
                        format!("`{}` is not the output end of a queue link: `min_interval_ms` means nothing there", w.link),
                        "a least write interval bounds how fast a queue fills; a sample link keeps the latest value whatever the rate",
                    );
                }
            }
        }
        let (lo, hi) = (w.min_interval_ms, w.max_interval_ms);
        if let Some(v) = lo {
            self.positive(v, &join(&at, &[F("min_interval_ms")]), "an interval [ms]");
        }
        if let Some(v) = hi {
            self.positive(v, &join(&at, &[F("max_interval_ms")]), "an interval [ms]");
        }
        match (lo, hi) {
            (None, None) => self.contract_finding(
                &at,
                "no interval",
                format!(
                    "the writes of `{}` give neither `min_interval_ms` nor `max_interval_ms`",
                    w.link
                ),
                "give `min_interval_ms` (queue links), `max_interval_ms`, or both",
            ),
            (Some(lo), Some(hi)) if lo > hi => self.contract_finding(
                &join(&at, &[F("max_interval_ms")]),
                "below `min_interval_ms`",
                format!(
                    "the writes of `{}` have `max_interval_ms` {hi} below `min_interval_ms` {lo}",
                    w.link
                ),
                "swap them, or correct one",
            ),
            _ => {}
        }
    }

    /// A finding of code [`Code::Contract`] at `path`.
    fn contract_finding(
        &mut self,
        path: &[Seg<'static>],
        label: &str,
        message: String,
        help: impl Into<String>,
    ) {
        self.push(Finding::new(Code::Contract, self.span(path), label, message).help(help));
    }

    /// `value` is a positive finite number.
    fn positive(&mut self, value: f64, path: &[Seg<'static>], what: &str) {
        if !(value.is_finite() && value > 0.0) {
            self.contract_finding(
                path,
                "not positive",
                format!("{value} is not {what}: it must be a positive finite number"),
                format!("give {what} greater than 0"),
            );
        }
    }

    fn unknown_component(&mut self, name: &str, path: &[Seg<'static>], what: &str) {
        let known = self.known_components();
        let guess = self.guess_component(name);
        self.push(
            Finding::new(
                Code::UnknownComponent,
                self.span(path),
                "no such component",
                format!("{what} names component `{name}`, which does not exist"),
            )
            .help(format!("{guess}components: {known}")),
        );
    }

    /// The subsystem called `name`, or a finding.
    fn subsystem_ref(&mut self, name: &str, path: &[Seg<'static>]) -> Option<&'a Subsystem> {
        let spec = self.spec;
        if let Some(s) = spec.subsystem(name) {
            return Some(s);
        }
        let names: Vec<&str> = spec.subsystems().map(|(_, s)| s.name.as_str()).collect();
        let guess = self.guess(name, names.iter().copied());
        self.push(
            Finding::new(
                Code::UnknownComponent,
                self.span(path),
                "no such subsystem",
                format!("a contract names subsystem `{name}`, which does not exist"),
            )
            .help(format!("{guess}subsystems: {}", list_or_none(&names))),
        );
        None
    }

    /// `subsystem.behaviour`.
    fn behaviour_ref(&mut self, text: &str, path: &[Seg<'static>]) {
        let Some((s, b)) = text.split_once('.') else {
            self.contract_finding(
                path,
                "not `subsystem.behaviour`",
                format!("`{text}` is not of the form `subsystem.behaviour`"),
                "name the subsystem and its behaviour, e.g. `c1.B2`",
            );
            return;
        };
        let Some(sub) = self.subsystem_ref(s, path) else {
            return;
        };
        if sub.behaviours.iter().any(|x| x.name == b) {
            return;
        }
        let names: Vec<&str> = sub.behaviours.iter().map(|x| x.name.as_str()).collect();
        let guess = self.guess(b, names.iter().copied());
        self.push(
            Finding::new(
                Code::UnknownBehaviour,
                self.span(path),
                "no such behaviour",
                format!("a bound names behaviour `{b}`, which `{s}` does not define"),
            )
            .help(format!("{guess}behaviours: {}", list_or_none(&names))),
        );
    }

    /// An input buffer `component.group.buffer`.
    fn input_ref(&mut self, text: &str, path: &[Seg<'static>]) {
        if let Err(e) = self.endpoint(&self.one_element(text), false) {
            self.endpoint_error(&e, text, path, false);
        }
    }

    /// What an entry naming buffer `text` is checked as: `text`, or for a
    /// whole fan (`c2.c1[*].plan`, [`crate::fans`]) that `text`'s component
    /// has, its element 0 (every element has the same buffers).
    pub(super) fn one_element(&self, text: &str) -> String {
        match crate::fans::elements(self.spec, text).into_iter().next() {
            Some((first, Some(_))) => first,
            _ => text.to_owned(),
        }
    }

    /// A response whose trigger and response both name a whole fan: element
    /// `k` answered on element `k`, so the fans have as many elements.
    fn paired_fans(&mut self, r: &crate::model::Response, at: &[Seg<'static>]) {
        let (t, x) = (
            crate::fans::elements(self.spec, &r.trigger).len(),
            crate::fans::elements(self.spec, &r.response).len(),
        );
        if crate::fans::is_every(&r.trigger) && crate::fans::is_every(&r.response) && t != x {
            self.contract_finding(
                &join(at, &[F("response")]),
                &format!("{x} element(s), the trigger's fan {t}"),
                format!(
                    "response `{}` pairs fans of different sizes: `{}` has {t} element(s), `{}` {x}",
                    r.name, r.trigger, r.response
                ),
                "with a whole fan on both sides, element k is answered on element k: name fans of the same peers, or one element on a side",
            );
        }
    }

    /// A buffer: `component.group.buffer` on either side, or `subsystem.memory`.
    fn buffer_ref(&mut self, text: &str, path: &[Seg<'static>]) -> Option<Found<'a>> {
        let parts: Vec<&str> = text.split('.').collect();
        if let [s, m] = parts[..] {
            let sub = self.subsystem_ref(s, path)?;
            if let Some(b) = sub.memory.iter().find(|b| b.name == m) {
                return Some(Found { ty: &b.ty });
            }
            let names: Vec<&str> = sub.memory.iter().map(|b| b.name.as_str()).collect();
            let guess = self.guess(m, names.iter().copied());
            self.push(
                Finding::new(
                    Code::UnknownBuffer,
                    self.span(path),
                    "no such buffer",
                    format!("`{text}` names no memory buffer of `{s}`"),
                )
                .help(format!("{guess}memory of `{s}`: {}", list_or_none(&names))),
            );
            return None;
        }
        let one = self.one_element(text);
        match self.endpoint(&one, true) {
            Ok((_, _, ty)) => Some(Found { ty }),
            Err(EndpointError::Direction) => match self.endpoint(&one, false) {
                Ok((_, _, ty)) => Some(Found { ty }),
                Err(e) => {
                    self.endpoint_error(&e, text, path, false);
                    None
                }
            },
            Err(EndpointError::Form) => {
                self.contract_finding(
                    path,
                    "not a buffer",
                    format!("`{text}` is neither `component.group.buffer` nor `subsystem.memory_buffer`"),
                    "name an input or output as links do (`e11.E1.tau`), or a memory buffer (`e11.tau`)",
                );
                None
            }
            Err(e) => {
                self.endpoint_error(&e, text, path, true);
                None
            }
        }
    }

    fn range(&mut self, r: &crate::model::ValueRange, at: &[Seg<'static>]) {
        let found = self.buffer_ref(&r.buffer, &join(at, &[F("buffer")]));
        for (v, f) in [(r.min, "min"), (r.max, "max")] {
            if let Some(v) = v.filter(|v| !v.is_finite()) {
                self.contract_finding(
                    &join(at, &[F(f)]),
                    "not finite",
                    format!("range `{}`: `{f}` {v} is not a finite number", r.name),
                    "limits are finite numbers; leave one out for no limit on that side",
                );
            }
        }
        match (r.min, r.max) {
            (None, None) => self.contract_finding(
                at,
                "no limit",
                format!("range `{}` gives neither `min` nor `max`", r.name),
                "give `min`, `max` or both",
            ),
            (Some(lo), Some(hi)) if lo > hi => self.contract_finding(
                &join(at, &[F("max")]),
                "below `min`",
                format!(
                    "range `{}` has `max` {hi} below `min` {lo}: no value is allowed",
                    r.name
                ),
                "swap them, or correct one",
            ),
            _ => {}
        }
        let Some(found) = found else { return };
        if let Err(why) = field_fits(found.ty, r.field.as_deref()) {
            let fpath = if r.field.is_some() {
                join(at, &[F("field")])
            } else {
                join(at, &[F("buffer")])
            };
            self.contract_finding(
                &fpath,
                "not a numeric field of the type",
                format!("range `{}`: {why}", r.name),
                "a field path is what the buffer's type has: nothing for a number, an index `0`.. for an array or a tuple, field names for a named type (checked when the system runs)",
            );
        }
    }

    fn chain(&mut self, ch: &crate::model::Chain, at: &[Seg<'static>]) {
        for (v, f) in [
            (ch.max_age_ms, "max_age_ms"),
            (ch.max_reaction_ms, "max_reaction_ms"),
        ] {
            if let Some(v) = v {
                self.positive(v, &join(at, &[F(f)]), "a deadline [ms]");
            }
        }
        if ch.path.is_empty() {
            self.push(
                Finding::new(
                    Code::Chain,
                    self.span(&join(at, &[F("path")])),
                    "no hops",
                    format!("chain `{}` has no hops", ch.name),
                )
                .help("list its output buffers from a real receptor's to the one a real effector reads, e.g. [\"R3.r31.pose\", \"r31.c3.pose\", ...]"),
            );
            return;
        }
        let mut ends = Vec::new();
        for (k, hop) in ch.path.iter().enumerate() {
            let hpath = join(at, &[F("path"), I(k)]);
            match self.endpoint(hop, true) {
                Err(e) => {
                    self.endpoint_error(&e, hop, &hpath, true);
                    ends.push(None);
                }
                Ok((c, peer, _)) => {
                    if !self.spec.links.iter().any(|l| &l.from == hop) {
                        self.push(
                            Finding::new(
                                Code::Chain,
                                self.span(&hpath),
                                "no link",
                                format!("chain `{}`: no link carries `{hop}`", ch.name),
                            )
                            .help("each hop is the output end of a link (`links: [(from: ...)]`)"),
                        );
                    }
                    ends.push(Some((c, peer, hpath)));
                }
            }
        }
        for w in ends.windows(2) {
            if let [Some((_, peer, _)), Some((c, _, p))] = w
                && peer != c
            {
                self.push(
                    Finding::new(
                        Code::Chain,
                        self.span(p),
                        format!("written by `{c}`, not `{peer}`"),
                        format!(
                            "chain `{}` does not connect: the hop before reaches `{peer}`, this one leaves `{c}`",
                            ch.name
                        ),
                    )
                    .help(format!("the next hop is an output of `{peer}`, the component the previous hop reaches")),
                );
            }
        }
        if let Some(Some((c, _, p))) = ends.first()
            && self
                .comps
                .get(c)
                .is_none_or(|x| x.kind != NodeKind::RealReceptor)
        {
            self.push(
                Finding::new(
                    Code::Chain,
                    self.span(p),
                    "not a real receptor",
                    format!("chain `{}` starts at `{c}`, which is not a real receptor", ch.name),
                )
                .help("a chain starts where the world is sensed: an output of a device of kind Receptor"),
            );
        }
        if let Some(Some((_, peer, p))) = ends.last()
            && !self.is_device(peer, DeviceKind::Effector)
        {
            self.push(
                Finding::new(
                    Code::Chain,
                    self.span(p),
                    "not read by a real effector",
                    format!("chain `{}` ends at `{peer}`, which is not a real effector", ch.name),
                )
                .help("a chain ends where the world is acted on: an input of a device of kind Effector"),
            );
        }
    }

    fn is_device(&self, name: &str, kind: DeviceKind) -> bool {
        self.spec
            .agents
            .iter()
            .flat_map(|a| &a.devices)
            .any(|d| d.name == name && d.kind == kind)
    }
}

/// The numeric primitive types.
const NUMBERS: [&str; 14] = [
    "f32", "f64", "i8", "i16", "i32", "i64", "i128", "isize", "u8", "u16", "u32", "u64", "u128",
    "usize",
];

/// Whether `field` names a number in a value of type `ty`, as far as the type's
/// text tells: a number has no field, an array `[T; N]` has indices below
/// `N`, a tuple `(A, B)` its positions. A named type's fields are not in the
/// spec: any path is accepted there (a monitor checks it when the system runs).
pub(crate) fn field_fits(ty: &str, field: Option<&str>) -> Result<(), String> {
    let ty = normalize_type(ty);
    let ty = ty.trim();
    let Some(field) = field else {
        return if NUMBERS.contains(&ty) || !is_structural(ty) && !is_known_non_number(ty) {
            Ok(())
        } else {
            Err(format!("a `{ty}` is not a number: name a numeric field"))
        };
    };
    let (head, rest) = match field.split_once('.') {
        Some((h, r)) => (h, Some(r)),
        None => (field, None),
    };
    if NUMBERS.contains(&ty) || is_known_non_number(ty) {
        return Err(format!("a `{ty}` has no field `{head}`"));
    }
    let items = if let Some(inner) = ty.strip_prefix('[').and_then(|t| t.strip_suffix(']')) {
        let Some((elem, n)) = inner.rsplit_once(';') else {
            return Ok(());
        };
        let Ok(n) = n.trim().parse::<usize>() else {
            return Ok(());
        };
        vec![elem.trim().to_owned(); n]
    } else if let Some(inner) = ty.strip_prefix('(').and_then(|t| t.strip_suffix(')')) {
        split_top(inner)
    } else {
        return Ok(());
    };
    let Ok(i) = head.parse::<usize>() else {
        return Err(format!(
            "a `{ty}` is indexed by position (`0`..`{}`), not `{head}`",
            items.len().saturating_sub(1)
        ));
    };
    let Some(elem) = items.get(i) else {
        return Err(format!("a `{ty}` has {} items: no index {i}", items.len()));
    };
    field_fits(elem, rest)
}

fn is_structural(ty: &str) -> bool {
    ty.starts_with('[') || ty.starts_with('(')
}

fn is_known_non_number(ty: &str) -> bool {
    matches!(ty, "bool" | "String" | "char" | "()")
        || ty.starts_with("Vec<")
        || ty.starts_with("Option<")
}

/// The items of a tuple's inside, split at top-level commas.
fn split_top(inner: &str) -> Vec<String> {
    let (mut out, mut depth, mut cur) = (Vec::new(), 0i32, String::new());
    for ch in inner.chars() {
        match ch {
            '<' | '(' | '[' => depth += 1,
            '>' | ')' | ']' => depth -= 1,
            ',' if depth == 0 => {
                out.push(std::mem::take(&mut cur).trim().to_owned());
                continue;
            }
            _ => {}
        }
        cur.push(ch);
    }
    if !cur.trim().is_empty() {
        out.push(cur.trim().to_owned());
    }
    out
}

#[cfg(test)]
mod tests {
    use super::field_fits;

    #[test]
    fn field_paths_follow_what_the_type_text_tells() {
        assert!(field_fits("f64", None).is_ok());
        assert!(field_fits("f64", Some("x")).is_err());
        assert!(field_fits("[f64; 4]", Some("3")).is_ok());
        assert!(field_fits("[f64; 4]", Some("4")).is_err());
        assert!(field_fits("[f64; 4]", None).is_err());
        assert!(field_fits("(f64, [i32; 2])", Some("1.1")).is_ok());
        assert!(field_fits("(f64, [i32; 2])", Some("1.2")).is_err());
        assert!(field_fits("(f64, bool)", Some("1")).is_err());
        // A named type's fields are not in the spec: left to the running system.
        assert!(field_fits("Torques", Some("left")).is_ok());
        assert!(field_fits("Torques", None).is_ok());
        assert!(field_fits("bool", None).is_err());
    }
}
