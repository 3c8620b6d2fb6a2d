//! The `fsm!` declaration as a spec, checked by the spec checker.
//!
//! The DSL declares what a spec's subsystem declares about its FSM: predicates,
//! relations, behaviours with their functions and terminal conditions, the initial
//! behaviour, arcs and finals. [`check`] writes that as the RON text of a
//! one-subsystem spec, remembering which DSL tokens each string came from, runs
//! `agent_spec::check` on it, and turns each FSM finding into a compile error on the
//! tokens under the finding's primary label. So the DSL gets the checker's every FSM
//! rule (names, reachability, ways out, finals, condition syntax, and the proof that
//! the arcs leaving a behaviour are exclusive and complete) with the same messages
//! as `embodied check`, without a second implementation.

use std::fmt::Write as _;
use std::ops::Range;

use agent_spec::{Code, Finding};
use proc_macro2::{TokenStream, TokenTree};
use quote::ToTokens;
use syn::ext::IdentExt;

/// A condition written in the DSL: its tokens, its text, and where each predicate
/// name sits in the text.
#[derive(Clone)]
pub(crate) struct Cond {
    tokens: TokenStream,
    text: String,
    idents: Vec<(Range<usize>, TokenStream)>,
}

impl Cond {
    pub(crate) fn new(tokens: TokenStream) -> Cond {
        let mut c = Cond {
            tokens: tokens.clone(),
            text: String::new(),
            idents: Vec::new(),
        };
        c.write(tokens);
        let trimmed = c.text.trim_end().len();
        c.text.truncate(trimmed);
        c
    }

    /// A space before the next word, unless after `(`, `!` or at the start.
    fn gap(&mut self) {
        if self
            .text
            .chars()
            .last()
            .is_some_and(|c| !matches!(c, '(' | '!' | ' '))
        {
            self.text.push(' ');
        }
    }

    fn write(&mut self, tokens: TokenStream) {
        let mut joint = false;
        for tt in tokens {
            match tt {
                TokenTree::Ident(i) => {
                    self.gap();
                    let start = self.text.len();
                    self.text.push_str(&i.unraw().to_string());
                    self.idents
                        .push((start..self.text.len(), i.to_token_stream()));
                    joint = false;
                }
                TokenTree::Punct(p) => {
                    if !joint {
                        self.gap();
                    }
                    self.text.push(p.as_char());
                    joint = p.spacing() == proc_macro2::Spacing::Joint;
                }
                TokenTree::Group(g) => {
                    let (open, close) = match g.delimiter() {
                        proc_macro2::Delimiter::Parenthesis => ('(', ')'),
                        proc_macro2::Delimiter::Bracket => ('[', ']'),
                        proc_macro2::Delimiter::Brace => ('{', '}'),
                        proc_macro2::Delimiter::None => (' ', ' '),
                    };
                    self.gap();
                    self.text.push(open);
                    self.write(g.stream());
                    self.text.push(close);
                    joint = false;
                }
                TokenTree::Literal(l) => {
                    self.gap();
                    self.text.push_str(&l.to_string());
                    joint = false;
                }
            }
        }
    }

    /// The condition as text for `Expr::parse` (`a && ! b`).
    pub(crate) fn text(&self) -> String {
        self.text.clone()
    }
}

/// A name and the tokens it came from.
pub(crate) type Named = (String, TokenStream);

pub(crate) enum Relation {
    Exclusive(Vec<Named>),
    Implies(Named, Named),
}

pub(crate) enum Target {
    Memory,
    Common,
    Output(String),
}

pub(crate) struct Part {
    pub(crate) name: String,
    pub(crate) target: Target,
    pub(crate) tokens: TokenStream,
}

pub(crate) struct Behaviour {
    pub(crate) name: Named,
    pub(crate) repeat: bool,
    pub(crate) terminal: Cond,
    pub(crate) parts: Vec<Part>,
}

pub(crate) struct FsmArc {
    pub(crate) from: Named,
    pub(crate) to: Named,
    pub(crate) when: Option<Cond>,
    pub(crate) tokens: TokenStream,
}

/// What the DSL declares.
pub(crate) struct SynthFsm {
    pub(crate) predicates: Vec<Named>,
    pub(crate) relations: Vec<Relation>,
    pub(crate) behaviours: Vec<Behaviour>,
    pub(crate) initial: Option<Named>,
    pub(crate) arcs: Vec<FsmArc>,
    pub(crate) finals: Vec<Named>,
}

/// RON text with the tokens behind its strings.
#[derive(Default)]
struct Text {
    s: String,
    marks: Vec<(Range<usize>, TokenStream)>,
}

impl Text {
    fn raw(&mut self, t: &str) {
        self.s.push_str(t);
    }

    /// A string literal; names are identifiers, so they need no escapes.
    fn string(&mut self, value: &str, tokens: &TokenStream) {
        let start = self.s.len();
        self.s.push('"');
        escape_into(&mut self.s, value);
        self.s.push('"');
        self.marks.push((start..self.s.len(), tokens.clone()));
    }

    fn cond(&mut self, c: &Cond) {
        let start = self.s.len();
        self.s.push('"');
        if c.text.contains(['"', '\\']) {
            escape_into(&mut self.s, &c.text);
        } else {
            let base = self.s.len();
            self.s.push_str(&c.text);
            for (r, t) in &c.idents {
                self.marks.push((base + r.start..base + r.end, t.clone()));
            }
        }
        self.s.push('"');
        self.marks.push((start..self.s.len(), c.tokens.clone()));
    }

    /// The tokens of the innermost mark holding the whole of `span` (or, if none
    /// does, its first byte).
    fn tokens_at(&self, span: &Range<usize>) -> Option<&TokenStream> {
        let innermost = |holds: &dyn Fn(&Range<usize>) -> bool| {
            self.marks
                .iter()
                .filter(|(r, _)| holds(r))
                .min_by_key(|(r, _)| r.end - r.start)
                .map(|(_, t)| t)
        };
        let end = span.end.max(span.start + 1);
        innermost(&|r| r.start <= span.start && end <= r.end)
            .or_else(|| innermost(&|r| r.start <= span.start && span.start < r.end))
    }
}

fn escape_into(out: &mut String, value: &str) {
    for ch in value.chars() {
        match ch {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            c => out.push(c),
        }
    }
}

/// The findings about an FSM, the ones the DSL can have. The rest (components,
/// links, buffers) concern parts of a spec the DSL does not declare.
const FSM_CODES: [Code; 12] = [
    Code::DuplicateName,
    Code::InvalidName,
    Code::UnknownBehaviour,
    Code::UnknownPredicate,
    Code::DuplicateTarget,
    Code::NoInitial,
    Code::Unreachable,
    Code::NoWayOut,
    Code::FinalWithArcs,
    Code::ConditionSyntax,
    Code::ArcsOverlap,
    Code::ArcsIncomplete,
];

/// The help line in the DSL's words where the checker's speaks of spec fields.
fn dsl_help(f: &Finding) -> String {
    match f.code {
        Code::NoInitial => "add `initial <behaviour>;`".into(),
        Code::NoWayOut => {
            "add an arc `from -> to when ...;`, declare it `final <behaviour>;`, or make its terminal condition `false`".into()
        }
        Code::FinalWithArcs => {
            "a final behaviour halts the subsystem when it ends; remove its arcs or its `final` declaration".into()
        }
        Code::ArcsOverlap => {
            "when a behaviour ends exactly one arc must hold: strengthen a condition, or declare `relations { exclusive(a, b) }` if the predicates cannot hold together".into()
        }
        Code::UnknownPredicate => "declare it in `predicates { .. }`".into(),
        _ => f.help.clone(),
    }
}

/// A valid spec name for the subsystem: the last identifier of its type.
fn subsystem_name(ty: &TokenStream) -> String {
    ty.clone()
        .into_iter()
        .take_while(|t| !matches!(t, TokenTree::Punct(p) if p.as_char() == '<'))
        .filter_map(|t| match t {
            TokenTree::Ident(i) => Some(i.to_string()),
            _ => None,
        })
        .last()
        .unwrap_or_else(|| "subsystem".into())
}

/// The one-subsystem spec of `fsm`, with the subsystem named `name`.
fn write_spec(fsm: &SynthFsm, name: &str) -> Text {
    let mut t = Text::default();
    let none = TokenStream::new();
    t.raw("(name: \"fsm\", agents: [(name: \"fsm\", subsystems: [(\n  name: ");
    t.string(name, &none);
    t.raw(", kind: Control, period_ms: 1.0,\n  outputs: [");
    write_outputs(&mut t, fsm);
    t.raw("],\n  predicates: [");
    write_predicates(&mut t, fsm);
    t.raw("],\n  relations: [");
    write_relations(&mut t, fsm);
    t.raw("],\n  functions: [");
    write_functions(&mut t, fsm);
    t.raw("],\n  behaviours: [\n");
    write_behaviours(&mut t, fsm);
    t.raw("  ],\n  fsm: (");
    write_graph(&mut t, fsm);
    t.raw("]),\n)])])\n");
    t
}

/// One output group (with no buffers) per field the parts write, in first-use
/// order.
fn write_outputs(t: &mut Text, fsm: &SynthFsm) {
    let mut peers: Vec<&str> = Vec::new();
    for b in &fsm.behaviours {
        for p in &b.parts {
            if let Target::Output(f) = &p.target
                && !peers.contains(&f.as_str())
            {
                peers.push(f);
            }
        }
    }
    for p in &peers {
        let _ = write!(t.s, "(peer: \"{p}\", buffers: []), ");
    }
}

/// The predicates, by name.
fn write_predicates(t: &mut Text, fsm: &SynthFsm) {
    for (n, tok) in &fsm.predicates {
        t.raw("(name: ");
        t.string(n, tok);
        t.raw("), ");
    }
}

/// The relations between predicates.
fn write_relations(t: &mut Text, fsm: &SynthFsm) {
    for r in &fsm.relations {
        match r {
            Relation::Exclusive(v) => {
                t.raw("Exclusive([");
                for (n, tok) in v {
                    t.string(n, tok);
                    t.raw(", ");
                }
                t.raw("]), ");
            }
            Relation::Implies((a, ta), (b, tb)) => {
                t.raw("Implies(");
                t.string(a, ta);
                t.raw(", ");
                t.string(b, tb);
                t.raw("), ");
            }
        }
    }
}

/// One function per distinct part name, with its target.
fn write_functions(t: &mut Text, fsm: &SynthFsm) {
    let mut defined: Vec<&str> = Vec::new();
    for b in &fsm.behaviours {
        for p in &b.parts {
            if defined.contains(&p.name.as_str()) {
                continue;
            }
            defined.push(&p.name);
            t.raw("(name: ");
            t.string(&p.name, &p.tokens);
            t.raw(", target: ");
            match &p.target {
                Target::Memory => t.raw("Memory"),
                Target::Common => t.raw("Common"),
                Target::Output(f) => {
                    let _ = write!(t.s, "Output(\"{f}\")");
                }
            }
            t.raw("), ");
        }
    }
}

/// The behaviours: kind, functions and terminal condition.
fn write_behaviours(t: &mut Text, fsm: &SynthFsm) {
    for b in &fsm.behaviours {
        t.raw("    (name: ");
        t.string(&b.name.0, &b.name.1);
        t.raw(if b.repeat {
            ", kind: Repeat, functions: ["
        } else {
            ", kind: While, functions: ["
        });
        for p in &b.parts {
            t.string(&p.name, &p.tokens);
            t.raw(", ");
        }
        t.raw("], terminal: ");
        t.cond(&b.terminal);
        t.raw("),\n");
    }
}

/// The FSM's graph: the initial behaviour, the arcs (each marked as a whole
/// with its tokens) and the finals.
fn write_graph(t: &mut Text, fsm: &SynthFsm) {
    if let Some((n, tok)) = &fsm.initial {
        t.raw("initial: ");
        t.string(n, tok);
        t.raw(", ");
    }
    t.raw("arcs: [\n");
    for a in &fsm.arcs {
        let start = t.s.len();
        t.raw("    (from: ");
        t.string(&a.from.0, &a.from.1);
        t.raw(", to: ");
        t.string(&a.to.0, &a.to.1);
        t.raw(", when: ");
        match &a.when {
            Some(c) => t.cond(c),
            None => t.string("true", &a.tokens),
        }
        t.raw(")");
        t.marks.push((start..t.s.len(), a.tokens.clone()));
        t.raw(",\n");
    }
    t.raw("  ], finals: [");
    for (n, tok) in &fsm.finals {
        t.string(n, tok);
        t.raw(", ");
    }
}

/// Run the spec checker on the declaration; `Err` holds one compile error per FSM
/// finding of error severity.
pub(crate) fn check(fsm: &SynthFsm, subsystem: TokenStream) -> syn::Result<()> {
    let text = write_spec(fsm, &subsystem_name(&subsystem));
    let (_, report) = agent_spec::check_source("fsm!", text.s.clone());
    let mut errors: Option<syn::Error> = None;
    // With two behaviours (or predicates) of one name, findings that refer to the
    // name are about one of them at random: report only the duplicates.
    let duplicates = report
        .findings
        .iter()
        .any(|f| f.code == Code::DuplicateName);
    for f in &report.findings {
        if duplicates && f.code != Code::DuplicateName {
            continue;
        }
        let parse_failed = f.code == Code::Syntax || f.code == Code::UnknownField;
        if !(FSM_CODES.contains(&f.code) || parse_failed)
            || f.severity() != agent_spec::Severity::Error
        {
            continue;
        }
        let message = if parse_failed {
            format!(
                "internal error of `fsm!`: the generated spec does not parse ({}); please report it",
                f.message
            )
        } else {
            let help = dsl_help(f);
            if help.is_empty() {
                format!("{} [{}]", f.message, f.code)
            } else {
                format!("{} [{}]\nhelp: {help}", f.message, f.code)
            }
        };
        let primary = f.labels.first().map_or(0..0, |l| l.span.clone());
        let e = match text.tokens_at(&primary) {
            Some(tokens) if !tokens.is_empty() => syn::Error::new_spanned(tokens, message),
            _ => syn::Error::new_spanned(&subsystem, message),
        };
        match &mut errors {
            Some(all) => all.combine(e),
            None => errors = Some(e),
        }
        // The other place of a two-place finding (the other overlapping arc, the
        // first definition): stable proc macros have no secondary spans, so it gets
        // its own short error. (The arcs that `arcs_incomplete` lists are context,
        // not a second fault.)
        if !matches!(f.code, Code::ArcsOverlap | Code::DuplicateName) {
            continue;
        }
        for label in f.labels.iter().skip(1) {
            if let Some(tokens) = text.tokens_at(&label.span).filter(|t| !t.is_empty()) {
                let e = syn::Error::new_spanned(
                    tokens,
                    format!("{} (see the error above) [{}]", label.text, f.code),
                );
                if let Some(all) = &mut errors {
                    all.combine(e);
                }
            }
        }
    }
    errors.map_or(Ok(()), Err)
}

#[cfg(test)]
mod tests {
    use super::*;
    use quote::quote;

    #[test]
    fn conditions_keep_where_each_predicate_is() {
        let c = Cond::new(quote!(plan_sent || (planner_failed && !x)));
        assert_eq!(c.text(), "plan_sent || (planner_failed && !x)");
        let names: Vec<&str> = c.idents.iter().map(|(r, _)| &c.text[r.clone()]).collect();
        assert_eq!(names, ["plan_sent", "planner_failed", "x"]);
        assert_eq!(
            agent_core::Expr::parse(&c.text()).map(|e| e.to_string()),
            agent_core::Expr::parse("plan_sent || (planner_failed && !x)").map(|e| e.to_string())
        );
    }

    #[test]
    fn the_written_spec_parses_and_marks_point_back() {
        let fsm = SynthFsm {
            predicates: vec![("a".into(), quote!(a))],
            relations: vec![],
            behaviours: vec![Behaviour {
                name: ("idle".into(), quote!(idle)),
                repeat: false,
                terminal: Cond::new(quote!(a)),
                parts: vec![Part {
                    name: "stop".into(),
                    target: Target::Output("pump".into()),
                    tokens: quote!(pump <- stop),
                }],
            }],
            initial: Some(("idle".into(), quote!(idle))),
            arcs: vec![FsmArc {
                from: ("idle".into(), quote!(idle)),
                to: ("idle".into(), quote!(idle)),
                when: None,
                tokens: quote!(idle -> idle),
            }],
            finals: vec![],
        };
        let text = write_spec(&fsm, "S");
        let loaded = agent_spec::load("t", text.s.clone()).expect("the text is a spec");
        assert_eq!(
            loaded.spec.agents[0].subsystems[0].behaviours[0].name,
            "idle"
        );
        let at = text.s.find("\"stop\"").expect("written");
        assert_eq!(
            text.tokens_at(&(at + 1..at + 5))
                .map(ToString::to_string)
                .as_deref(),
            Some("pump <- stop")
        );
        // A label over a whole condition maps to the condition, not its first word.
        let c = Cond::new(quote!(a && b));
        let mut t = Text::default();
        t.cond(&c);
        assert_eq!(
            t.tokens_at(&(0..t.s.len()))
                .map(ToString::to_string)
                .as_deref(),
            Some("a && b")
        );
        assert_eq!(
            t.tokens_at(&(1..2)).map(ToString::to_string).as_deref(),
            Some("a")
        );
        check(&fsm, quote!(S)).expect("a sound FSM");
    }
}
