//! `fsm!`: behaviours and their FSM in the paper's notation.
//!
//! Three stages, each tested on token input:
//!
//! 1. [`parse`]: the DSL into a [`FsmDecl`] (syntax errors point at the tokens);
//! 2. [`check`]: the declaration is turned into a one-subsystem spec and run through
//!    the spec checker of `agent-spec` (the same checker as `embodied check`), whose
//!    findings come back as compile errors on the DSL's tokens;
//! 3. [`generate`]: the `FsmBuilder` chain a user would write by hand.
//!
//! ```text
//! fsm! {
//!     subsystem Station;
//!     predicates { has_order, order_valid: |m: &StationMemory, _| m.valid(), reached }
//!     relations { order_valid => has_order }
//!     while idle until has_order { pump <- stop_pump, memory <- take_order }
//!     repeat fill until reached { pump <- fill_flow }
//!     initial idle;
//!     idle -> fill when order_valid;
//!     idle -> report when !order_valid;
//!     fill -> settle;
//!     final done;
//! }
//! ```

use std::collections::HashMap;

use proc_macro2::{Span, TokenStream, TokenTree};
use quote::{ToTokens, quote};
use syn::ext::IdentExt;
use syn::parse::{Parse, ParseStream};
use syn::punctuated::Punctuated;
use syn::{Expr, Ident, Token, braced, parenthesized};

use agent_core::Relation;

use crate::chain::{self, Chain};
use crate::synth::{self, Cond, SynthFsm};
use crate::util::runtime;

/// While-type (Algorithm 2) or repeat-type (Algorithm 3).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Kind {
    While,
    Repeat,
}

/// What a part writes.
#[derive(Clone)]
pub(crate) enum TargetDecl {
    /// `memory <- f`: the next memory, computed last.
    Memory(Ident),
    /// `common <- f`: intermediate results, computed first.
    Common(Ident),
    /// `field <- f`: the output group in field `field`.
    Output(Ident),
}

impl TargetDecl {
    fn ident(&self) -> &Ident {
        match self {
            TargetDecl::Memory(i) | TargetDecl::Common(i) | TargetDecl::Output(i) => i,
        }
    }
}

/// `target <- function`.
#[derive(Clone)]
pub(crate) struct PartDecl {
    pub(crate) target: TargetDecl,
    pub(crate) function: Expr,
}

/// `while name until condition { parts }` or `repeat ...`.
#[derive(Clone)]
pub(crate) struct BehaviourDecl {
    pub(crate) kind: Kind,
    pub(crate) name: Ident,
    pub(crate) terminal: Cond,
    pub(crate) parts: Vec<PartDecl>,
}

/// `from -> to when condition;` (no `when`: the condition is `true`).
#[derive(Clone)]
pub(crate) struct ArcDecl {
    pub(crate) from: Ident,
    pub(crate) to: Ident,
    pub(crate) when: Option<Cond>,
}

/// `name` (a function of that name in scope) or `name: expression`.
#[derive(Clone)]
pub(crate) struct PredicateDecl {
    pub(crate) name: Ident,
    pub(crate) function: Option<Expr>,
}

/// `exclusive(a, b, ...)` or `a => b`.
#[derive(Clone)]
pub(crate) enum RelationDecl {
    Exclusive(Vec<Ident>),
    Implies(Ident, Ident),
}

/// A whole `fsm!` invocation.
#[derive(Clone)]
pub(crate) struct FsmDecl {
    pub(crate) subsystem: syn::Type,
    pub(crate) predicates: Vec<PredicateDecl>,
    pub(crate) relations: Vec<RelationDecl>,
    pub(crate) behaviours: Vec<BehaviourDecl>,
    pub(crate) initial: Option<Ident>,
    pub(crate) arcs: Vec<ArcDecl>,
    pub(crate) finals: Vec<Ident>,
}

mod kw {
    syn::custom_keyword!(subsystem);
    syn::custom_keyword!(predicates);
    syn::custom_keyword!(relations);
    syn::custom_keyword!(repeat);
    syn::custom_keyword!(until);
    syn::custom_keyword!(initial);
    syn::custom_keyword!(when);
    syn::custom_keyword!(exclusive);
    syn::custom_keyword!(memory);
    syn::custom_keyword!(common);
}

/// Tokens up to (not including) a brace group or `;`, for a condition.
fn condition_tokens(input: ParseStream<'_>, stop_at_brace: bool) -> syn::Result<TokenStream> {
    let mut tokens = TokenStream::new();
    input.step(|cursor| {
        let mut rest = *cursor;
        while let Some((tt, next)) = rest.token_tree() {
            let stop = match &tt {
                TokenTree::Group(g) => {
                    stop_at_brace && g.delimiter() == proc_macro2::Delimiter::Brace
                }
                TokenTree::Punct(p) => p.as_char() == ';',
                _ => false,
            };
            if stop {
                break;
            }
            tokens.extend([tt]);
            rest = next;
        }
        Ok(((), rest))
    })?;
    if tokens.is_empty() {
        return Err(input.error("expected a condition over predicates (`true`, `a && !b`, ...)"));
    }
    Ok(tokens)
}

impl Parse for PartDecl {
    fn parse(input: ParseStream<'_>) -> syn::Result<Self> {
        let target = if input.peek(kw::memory) {
            let k: kw::memory = input.parse()?;
            TargetDecl::Memory(Ident::new("memory", k.span))
        } else if input.peek(kw::common) {
            let k: kw::common = input.parse()?;
            TargetDecl::Common(Ident::new("common", k.span))
        } else {
            let field: Ident = input.parse().map_err(|e| {
                syn::Error::new(
                    e.span(),
                    "expected a part `target <- function`: the target is `memory`, `common` or an output group field",
                )
            })?;
            TargetDecl::Output(field)
        };
        input.parse::<Token![<-]>()?;
        let function: Expr = input.parse()?;
        Ok(PartDecl { target, function })
    }
}

impl Parse for PredicateDecl {
    fn parse(input: ParseStream<'_>) -> syn::Result<Self> {
        let name: Ident = input.parse()?;
        let function = if input.peek(Token![:]) {
            input.parse::<Token![:]>()?;
            Some(input.parse()?)
        } else {
            None
        };
        Ok(PredicateDecl { name, function })
    }
}

impl Parse for RelationDecl {
    fn parse(input: ParseStream<'_>) -> syn::Result<Self> {
        if input.peek(kw::exclusive) && input.peek2(syn::token::Paren) {
            input.parse::<kw::exclusive>()?;
            let content;
            parenthesized!(content in input);
            let names = Punctuated::<Ident, Token![,]>::parse_terminated(&content)?;
            return Ok(RelationDecl::Exclusive(names.into_iter().collect()));
        }
        let a: Ident = input.parse()?;
        input.parse::<Token![=>]>().map_err(|e| {
            syn::Error::new(
                e.span(),
                "expected a relation: `exclusive(a, b, ...)` or `a => b`",
            )
        })?;
        let b: Ident = input.parse()?;
        Ok(RelationDecl::Implies(a, b))
    }
}

/// A behaviour from its keyword (`while` or `repeat`) to its closing brace.
impl Parse for BehaviourDecl {
    fn parse(input: ParseStream<'_>) -> syn::Result<Self> {
        let kind = if input.peek(Token![while]) {
            input.parse::<Token![while]>()?;
            Kind::While
        } else {
            input.parse::<kw::repeat>()?;
            Kind::Repeat
        };
        let name: Ident = input.parse()?;
        input.parse::<kw::until>().map_err(|e| {
            syn::Error::new(
                e.span(),
                format!(
                    "expected `until <terminal condition>` after the behaviour's name: `{} {name} until done {{ ... }}`",
                    if kind == Kind::While { "while" } else { "repeat" }
                ),
            )
        })?;
        let terminal = Cond::new(condition_tokens(input, true)?);
        let content;
        braced!(content in input);
        let parts = Punctuated::<PartDecl, Token![,]>::parse_terminated(&content)?;
        Ok(BehaviourDecl {
            kind,
            name,
            terminal,
            parts: parts.into_iter().collect(),
        })
    }
}

/// An arc, up to and including its `;`.
impl Parse for ArcDecl {
    fn parse(input: ParseStream<'_>) -> syn::Result<Self> {
        let from: Ident = input.parse()?;
        input.parse::<Token![->]>()?;
        let to: Ident = input.parse()?;
        let when = if input.peek(kw::when) {
            input.parse::<kw::when>()?;
            Some(Cond::new(condition_tokens(input, false)?))
        } else {
            None
        };
        input.parse::<Token![;]>()?;
        Ok(ArcDecl { from, to, when })
    }
}

impl Parse for FsmDecl {
    fn parse(input: ParseStream<'_>) -> syn::Result<Self> {
        let mut subsystem = None;
        let mut d = FsmDecl {
            subsystem: syn::parse_quote!(()),
            predicates: Vec::new(),
            relations: Vec::new(),
            behaviours: Vec::new(),
            initial: None,
            arcs: Vec::new(),
            finals: Vec::new(),
        };
        while !input.is_empty() {
            let look = input.lookahead1();
            if look.peek(kw::subsystem) {
                let k: kw::subsystem = input.parse()?;
                if subsystem.is_some() {
                    return Err(syn::Error::new(k.span, "the subsystem is named twice"));
                }
                subsystem = Some(input.parse()?);
                input.parse::<Token![;]>()?;
            } else if look.peek(kw::predicates) {
                input.parse::<kw::predicates>()?;
                let content;
                braced!(content in input);
                d.predicates
                    .extend(Punctuated::<PredicateDecl, Token![,]>::parse_terminated(
                        &content,
                    )?);
            } else if look.peek(kw::relations) {
                input.parse::<kw::relations>()?;
                let content;
                braced!(content in input);
                d.relations
                    .extend(Punctuated::<RelationDecl, Token![,]>::parse_terminated(
                        &content,
                    )?);
            } else if look.peek(Token![while]) || look.peek(kw::repeat) {
                d.behaviours.push(input.parse()?);
            } else if look.peek(kw::initial) {
                let k: kw::initial = input.parse()?;
                if d.initial.is_some() {
                    return Err(syn::Error::new(
                        k.span,
                        "the initial behaviour is named twice",
                    ));
                }
                d.initial = Some(input.parse()?);
                input.parse::<Token![;]>()?;
            } else if look.peek(Token![final]) {
                input.parse::<Token![final]>()?;
                let names = Punctuated::<Ident, Token![,]>::parse_separated_nonempty(input)?;
                d.finals.extend(names);
                input.parse::<Token![;]>()?;
            } else if look.peek(Ident) && input.peek2(Token![->]) {
                d.arcs.push(input.parse()?);
            } else {
                let mut e = look.error();
                e.combine(syn::Error::new(
                    e.span(),
                    "an `fsm!` holds: `subsystem Type;`, `predicates { .. }`, `relations { .. }`, behaviours `while name until cond { .. }` / `repeat name until cond { .. }`, `initial name;`, arcs `from -> to when cond;` and `final name;`",
                ));
                return Err(e);
            }
        }
        d.subsystem = subsystem.ok_or_else(|| {
            syn::Error::new(
                Span::call_site(),
                "name the subsystem the FSM drives: `subsystem MySubsystem;`",
            )
        })?;
        Ok(d)
    }
}

/// Parse stage.
pub(crate) fn parse(tokens: TokenStream) -> syn::Result<FsmDecl> {
    syn::parse2(tokens)
}

/// An identifier as a name in specs and at run time: `r#type` is `type`.
pub(crate) fn name(ident: &Ident) -> String {
    ident.unraw().to_string()
}

/// The name of a part in specs: the function's name for a path, otherwise
/// `<behaviour>_<target>`.
fn base_name(b: &BehaviourDecl, p: &PartDecl) -> String {
    if let Expr::Path(path) = &p.function
        && let Some(last) = path.path.segments.last()
    {
        return name(&last.ident);
    }
    format!("{}_{}", b.name, p.target.ident())
}

/// Spec target of a part: `Memory`, `Common` or the output field.
fn target_key(t: &TargetDecl) -> String {
    match t {
        TargetDecl::Memory(_) => "memory".into(),
        TargetDecl::Common(_) => "common".into(),
        TargetDecl::Output(f) => name(f),
    }
}

/// Unique part names per target: a name used with two targets gets the target as
/// suffix for the second (a spec function has one target).
pub(crate) fn part_names(d: &FsmDecl) -> Vec<Vec<String>> {
    let mut target_of: HashMap<String, String> = HashMap::new();
    d.behaviours
        .iter()
        .map(|b| {
            b.parts
                .iter()
                .map(|p| {
                    let base = base_name(b, p);
                    let target = target_key(&p.target);
                    match target_of.get(&base) {
                        Some(t) if *t != target => {
                            let renamed = format!("{base}_{target}");
                            target_of.insert(renamed.clone(), target);
                            renamed
                        }
                        _ => {
                            target_of.insert(base.clone(), target);
                            base
                        }
                    }
                })
                .collect()
        })
        .collect()
}

/// Check stage: the FSM through the spec checker; every error becomes a compile error
/// on the DSL tokens it is about.
pub(crate) fn check(d: &FsmDecl) -> syn::Result<()> {
    let names = part_names(d);
    let fsm = SynthFsm {
        predicates: d
            .predicates
            .iter()
            .map(|p| (name(&p.name), p.name.to_token_stream()))
            .collect(),
        relations: d
            .relations
            .iter()
            .map(|r| match r {
                RelationDecl::Exclusive(v) => synth::Relation::Exclusive(
                    v.iter().map(|i| (name(i), i.to_token_stream())).collect(),
                ),
                RelationDecl::Implies(a, b) => synth::Relation::Implies(
                    (name(a), a.to_token_stream()),
                    (name(b), b.to_token_stream()),
                ),
            })
            .collect(),
        behaviours: d
            .behaviours
            .iter()
            .zip(&names)
            .map(|(b, names)| synth::Behaviour {
                name: (name(&b.name), b.name.to_token_stream()),
                repeat: b.kind == Kind::Repeat,
                terminal: b.terminal.clone(),
                parts: b
                    .parts
                    .iter()
                    .zip(names)
                    .map(|(p, n)| synth::Part {
                        name: n.clone(),
                        target: match &p.target {
                            TargetDecl::Memory(_) => synth::Target::Memory,
                            TargetDecl::Common(_) => synth::Target::Common,
                            TargetDecl::Output(f) => synth::Target::Output(name(f)),
                        },
                        tokens: {
                            let t = p.target.ident();
                            let f = &p.function;
                            quote!(#t <- #f)
                        },
                    })
                    .collect(),
            })
            .collect(),
        initial: d.initial.as_ref().map(|i| (name(i), i.to_token_stream())),
        arcs: d
            .arcs
            .iter()
            .map(|a| synth::FsmArc {
                from: (name(&a.from), a.from.to_token_stream()),
                to: (name(&a.to), a.to.to_token_stream()),
                when: a.when.clone(),
                tokens: {
                    let (f, t) = (&a.from, &a.to);
                    quote!(#f -> #t)
                },
            })
            .collect(),
        finals: d
            .finals
            .iter()
            .map(|i| (name(i), i.to_token_stream()))
            .collect(),
    };
    synth::check(&fsm, d.subsystem.to_token_stream())
}

/// Generate stage: the `FsmBuilder` chain, evaluating to
/// `Result<Fsm<S>, FsmBuildError>`.
pub(crate) fn generate(d: &FsmDecl) -> TokenStream {
    let names = part_names(d);
    Chain {
        subsystem: d.subsystem.to_token_stream(),
        predicates: d
            .predicates
            .iter()
            .map(|p| {
                let f = p
                    .function
                    .as_ref()
                    .map_or_else(|| p.name.to_token_stream(), ToTokens::to_token_stream);
                (name(&p.name), f)
            })
            .collect(),
        relations: d
            .relations
            .iter()
            .map(|r| match r {
                RelationDecl::Exclusive(v) => {
                    Relation::Exclusive(v.iter().map(|n| name(n).into()).collect())
                }
                RelationDecl::Implies(a, b) => Relation::Implies(name(a).into(), name(b).into()),
            })
            .collect(),
        behaviours: d
            .behaviours
            .iter()
            .zip(&names)
            .map(|(b, names)| chain::Behaviour {
                name: name(&b.name),
                repeat: b.kind == Kind::Repeat,
                terminal: b.terminal.text(),
                parts: b
                    .parts
                    .iter()
                    .zip(names)
                    .map(|(p, n)| chain::Part {
                        name: n.clone(),
                        target: match &p.target {
                            TargetDecl::Memory(_) => chain::Target::Memory,
                            TargetDecl::Common(_) => chain::Target::Common,
                            TargetDecl::Output(f) => chain::Target::Output(f.clone()),
                        },
                        function: p.function.to_token_stream(),
                    })
                    .collect(),
            })
            .collect(),
        initial: d.initial.as_ref().map(name),
        arcs: d
            .arcs
            .iter()
            .map(|a| {
                let when = a
                    .when
                    .as_ref()
                    .map_or_else(|| "true".to_owned(), Cond::text);
                (name(&a.from), name(&a.to), when)
            })
            .collect(),
        finals: d.finals.iter().map(name).collect(),
    }
    .generate()
}

/// The whole macro.
pub(crate) fn expand(tokens: TokenStream) -> TokenStream {
    let d = match parse(tokens) {
        Ok(d) => d,
        Err(e) => return e.to_compile_error(),
    };
    match check(&d) {
        Ok(()) => generate(&d),
        Err(e) => {
            // Still expand to a value of the right type, so that the only errors the
            // user sees are the FSM's.
            let rt = runtime();
            let s = &d.subsystem;
            let err = e.to_compile_error();
            quote! {{
                #err
                ::core::result::Result::<#rt::Fsm<#s>, #rt::FsmBuildError>::Err(
                    #rt::FsmBuildError { problems: ::std::vec::Vec::new() }
                )
            }}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn all_messages(e: syn::Error) -> String {
        e.into_iter()
            .map(|e| e.to_string())
            .collect::<Vec<_>>()
            .join("\n")
    }

    fn station() -> TokenStream {
        quote! {
            subsystem Station;
            predicates {
                has_order: |m: &StationMemory, _| m.order.is_some(),
                order_valid,
                reached,
            }
            while idle until has_order { pump <- stop_pump, memory <- take_order }
            repeat fill until reached { pump <- fill_flow, memory <- |m: &mut StationMemory, _| m.n = 0 }
            repeat report until true { operator <- acknowledge, pump <- stop_pump }
            initial idle;
            idle -> fill when order_valid;
            idle -> report when !order_valid;
            fill -> report;
            report -> idle;
        }
    }

    #[test]
    fn the_dsl_parses_into_behaviours_and_arcs() {
        let d = parse(station()).expect("valid DSL");
        assert_eq!(d.predicates.len(), 3);
        assert!(d.predicates[1].function.is_none());
        let names: Vec<String> = d.behaviours.iter().map(|b| b.name.to_string()).collect();
        assert_eq!(names, ["idle", "fill", "report"]);
        assert_eq!(d.behaviours[0].kind, Kind::While);
        assert_eq!(d.behaviours[1].kind, Kind::Repeat);
        assert_eq!(d.behaviours[0].terminal.text(), "has_order");
        assert_eq!(d.arcs.len(), 4);
        assert_eq!(
            d.arcs[1].when.as_ref().map(Cond::text).as_deref(),
            Some("!order_valid")
        );
        assert!(d.arcs[2].when.is_none());
        assert_eq!(
            d.initial.as_ref().map(Ident::to_string).as_deref(),
            Some("idle")
        );
    }

    #[test]
    fn parts_are_named_after_their_functions() {
        let d = parse(station()).expect("valid DSL");
        let names = part_names(&d);
        assert_eq!(names[0], ["stop_pump", "take_order"]);
        assert_eq!(names[1], ["fill_flow", "fill_memory"]);
        assert_eq!(names[2], ["acknowledge", "stop_pump"]);
    }

    #[test]
    fn a_sound_fsm_passes_the_checker_and_generates_the_builder_chain() {
        let d = parse(station()).expect("valid DSL");
        check(&d).expect("the checker accepts it");
        let code = generate(&d).to_string();
        for needle in [
            "FsmBuilder :: < Station > :: new ()",
            ". predicate (\"has_order\"",
            ". output (| __y | & mut __y . pump , stop_pump) . named (\"stop_pump\") . __at_field (\"pump\")",
            ". memory (take_order) . named (\"take_order\")",
            ". arc (\"idle\" , \"report\" , \"!order_valid\")",
            ". arc (\"fill\" , \"report\" , \"true\")",
            ". build ()",
        ] {
            assert!(code.contains(needle), "`{needle}` not in {code}");
        }
    }

    #[test]
    fn checker_findings_become_errors_on_the_tokens() {
        let d = parse(quote! {
            subsystem S;
            predicates { a, b }
            while x until a { }
            while y until false { }
            initial x;
            x -> y when a;
            x -> z when c;
        })
        .expect("parses");
        let e = check(&d).expect_err("unknown names");
        let spans: Vec<String> = e.clone().into_iter().map(|e| e.to_string()).collect();
        let e = all_messages(e);
        for needle in ["behaviour `z`", "predicate `c`"] {
            assert!(e.contains(needle), "`{needle}` not in {e}");
        }
        assert!(spans.len() >= 2, "{spans:?}");
        // Two behaviours of one name: only that is reported, the rest would be
        // about either of them.
        let d = parse(quote! {
            subsystem S;
            predicates { a }
            while x until a { }
            while x until false { }
            initial x;
            x -> x;
        })
        .expect("parses");
        let e = all_messages(check(&d).expect_err("duplicate"));
        assert!(e.contains("`x` is defined twice"), "{e}");
        // One finding, marked at both definitions (a second error on the first).
        assert!(
            e.contains("first defined here (see the error above)"),
            "{e}"
        );
        assert_eq!(e.matches("[spec::duplicate_name]").count(), 2, "{e}");
        assert_eq!(e.matches("[spec::").count(), 2, "nothing else: {e}");
    }

    #[test]
    fn overlapping_arcs_are_refused_with_the_counterexample() {
        let d = parse(quote! {
            subsystem S;
            predicates { a, b }
            repeat x until true { }
            while y until false { }
            while z until false { }
            initial x;
            x -> y when a;
            x -> z when b;
        })
        .expect("parses");
        let errors = check(&d).expect_err("overlap and gap");
        // The overlap is marked on both arcs: the error on one, a second on the other.
        let on: Vec<(String, String)> = errors
            .clone()
            .into_iter()
            .map(|e| (e.to_string(), format!("{:?}", e.span())))
            .collect();
        let overlap: Vec<&(String, String)> = on
            .iter()
            .filter(|(m, _)| m.contains("[spec::arcs_overlap]"))
            .collect();
        assert_eq!(overlap.len(), 2, "{on:?}");
        assert!(overlap[1].0.contains("this one holds too"), "{on:?}");
        let e = all_messages(errors);
        assert!(e.contains("can hold at once"), "{e}");
        assert!(e.contains("none of its arcs holds"), "{e}");
        let d = parse(quote! {
            subsystem S;
            predicates { a, b }
            relations { exclusive(a, b), a => b }
            repeat x until true { }
            while y until false { }
            initial x;
            x -> y when a || !a;
        })
        .expect("parses");
        check(&d).expect("relations resolve and the arc covers everything");
    }

    #[test]
    fn syntax_errors_say_what_was_expected() {
        let e = parse(quote!(subsystem S; while idle { }))
            .err()
            .expect("no until");
        assert!(e.to_string().contains("until"), "{e}");
        let e = parse(quote!(predicates { a })).err().expect("no subsystem");
        assert!(e.to_string().contains("subsystem MySubsystem"), "{e}");
        let e = parse(quote!(subsystem S; while a until b { pump = f }))
            .err()
            .expect("no arrow");
        assert!(e.to_string().contains("<-"), "{e}");
    }
}
