//! `agent!`: Rust types and traits generated from a RON spec.
//!
//! Stages, each tested on token input or spec text:
//!
//! 1. [`parse`]: the arguments `spec = "path", agent = "name"`;
//! 2. [`load`]: read the file, run the spec checker (every error finding becomes a
//!    compile error `file:line:col: error[code]: message`) and find the agent;
//! 3. [`generate`]: one module per component with its types, and for a subsystem the
//!    trait of its transition functions and predicates and the FSM over them.

use std::path::{Path, PathBuf};

use agent_spec::model::{self, Spec};
use agent_spec::span::Seg;
use agent_spec::{Loaded, Severity};
use proc_macro2::{Span, TokenStream};
use quote::{format_ident, quote};
use syn::parse::{Parse, ParseStream};
use syn::{Ident, LitStr, Token};

use crate::util::runtime;

mod subsystem;

/// The arguments.
pub(crate) struct AgentArgs {
    pub(crate) spec: LitStr,
    pub(crate) agent: LitStr,
    /// Extra derives for the generated memory structs (`Debug` and `Clone` always).
    pub(crate) memory_derive: Vec<syn::Path>,
}

mod kw {
    syn::custom_keyword!(spec);
    syn::custom_keyword!(agent);
    syn::custom_keyword!(memory_derive);
}

impl Parse for AgentArgs {
    fn parse(input: ParseStream<'_>) -> syn::Result<Self> {
        let (mut spec, mut agent, mut memory_derive) = (None, None, Vec::new());
        while !input.is_empty() {
            let look = input.lookahead1();
            if look.peek(kw::spec) {
                input.parse::<kw::spec>()?;
                input.parse::<Token![=]>()?;
                spec = Some(input.parse()?);
            } else if look.peek(kw::agent) {
                input.parse::<kw::agent>()?;
                input.parse::<Token![=]>()?;
                agent = Some(input.parse()?);
            } else if look.peek(kw::memory_derive) {
                input.parse::<kw::memory_derive>()?;
                input.parse::<Token![=]>()?;
                let content;
                syn::bracketed!(content in input);
                memory_derive.extend(
                    syn::punctuated::Punctuated::<syn::Path, Token![,]>::parse_terminated(
                        &content,
                    )?,
                );
            } else {
                return Err(look.error());
            }
            if !input.is_empty() {
                input.parse::<Token![,]>()?;
            }
        }
        let missing = |what: &str| {
            syn::Error::new(
                Span::call_site(),
                format!(
                    "`agent!` needs `{what}`: `agent!(spec = \"specs/my.ron\", agent = \"a1\")`"
                ),
            )
        };
        Ok(AgentArgs {
            spec: spec.ok_or_else(|| missing("spec = \"<file>\""))?,
            agent: agent.ok_or_else(|| missing("agent = \"<name>\""))?,
            memory_derive,
        })
    }
}

/// Parse stage.
pub(crate) fn parse(tokens: TokenStream) -> syn::Result<AgentArgs> {
    syn::parse2(tokens)
}

/// Where the spec file is: relative to `CARGO_MANIFEST_DIR` (like copper-rs), or,
/// if there is no such file, to the directory of the file invoking the macro (like
/// `include_str!`). `invoker` is that file, when the compiler says.
fn resolve(path: &str, invoker: Option<PathBuf>) -> PathBuf {
    let p = Path::new(path);
    if p.is_absolute() {
        return p.to_owned();
    }
    let from_manifest = std::env::var_os("CARGO_MANIFEST_DIR").map(|dir| Path::new(&dir).join(p));
    if let Some(f) = from_manifest.as_ref().filter(|f| f.exists()) {
        return f.clone();
    }
    let beside = invoker
        .as_deref()
        .and_then(Path::parent)
        .map(|dir| dir.join(p))
        .filter(|f| f.exists());
    beside.or(from_manifest).unwrap_or_else(|| p.to_owned())
}

/// A checked spec and the agent to generate.
pub(crate) struct Found {
    pub(crate) loaded: Loaded,
    pub(crate) agent: usize,
    /// The checker's errors that belong to this agent ([`owner`]), one compile
    /// error each, and one line for the errors of the other agents; `None` if the
    /// spec has no error.
    pub(crate) errors: Option<syn::Error>,
}

/// Load stage: `text` is the spec file's content, `file` its name as written.
///
/// An error only when nothing can be generated (the file does not parse, the agent
/// does not exist). The checker's findings come back in [`Found::errors`], those of
/// this agent only: each `agent!` call reports its own agent's findings, so that a
/// finding is reported once, and the code is still generated, so that no cascade
/// of "cannot find" errors follows.
pub(crate) fn load(file: &LitStr, text: String, agent: &LitStr) -> syn::Result<Found> {
    let name = file.value();
    let loaded = match agent_spec::load(name.clone(), text) {
        Ok(l) => l,
        Err(report) => return Err(report_error(file, &report)),
    };
    let wanted = agent.value();
    let Some(index) = loaded.spec.agents.iter().position(|a| a.name == wanted) else {
        let names: Vec<&str> = loaded.spec.agents.iter().map(|a| a.name.as_str()).collect();
        return Err(syn::Error::new(
            agent.span(),
            format!(
                "{name} has no agent `{wanted}`; its agents: {}",
                names.join(", ")
            ),
        ));
    };
    let report = agent_spec::check(&loaded);
    let mut errors = findings_error(file, &report, |offset| owner(&loaded, offset) == index);
    // The errors of other agents are reported by their `agent!`, which this crate
    // may not invoke: one line here, so that a broken spec never compiles.
    let elsewhere: Vec<&agent_spec::Finding> = report
        .findings
        .iter()
        .filter(|f| f.severity() == Severity::Error && owner(&loaded, f.offset()) != index)
        .collect();
    if let Some(first) = elsewhere.first() {
        let (l, c) = report.line_col(first.offset());
        let e = syn::Error::new(
            file.span(),
            format!(
                "{name} has {} error{} outside agent `{wanted}` (the first: {name}:{l}:{c}: error[{}]: {}); `agent!` reports them for their agent, and `embodied check {name}` lists them all",
                elsewhere.len(),
                if elsewhere.len() == 1 { "" } else { "s" },
                first.code,
                first.message
            ),
        );
        match &mut errors {
            Some(all) => all.combine(e),
            None => errors = Some(e),
        }
    }
    Ok(Found {
        loaded,
        agent: index,
        errors,
    })
}

/// The agent a finding at `offset` belongs to: the agent whose entry holds it; for
/// a link, the agent of the component it leaves (or enters, if that one is
/// unknown); for anything else (deployments, the system's name), the agent of the
/// component named at `offset`, or else the spec's first agent.
fn owner(loaded: &Loaded, offset: usize) -> usize {
    let spec = &loaded.spec;
    let Some(root) = loaded.index.as_ref() else {
        return 0;
    };
    let inside = |path: &[Seg<'_>]| root.at(path).is_some_and(|n| n.span.contains(&offset));
    if let Some(a) = (0..spec.agents.len()).find(|&a| inside(&[Seg::Field("agents"), Seg::Item(a)]))
    {
        return a;
    }
    let agent_of = |component: &str| {
        spec.agents.iter().position(|a| {
            a.subsystems.iter().any(|s| s.name == component)
                || a.devices.iter().any(|d| d.name == component)
        })
    };
    let of_end = |end: &str| end.split('.').next().and_then(agent_of);
    if let Some(l) = (0..spec.links.len()).find(|&k| inside(&[Seg::Field("links"), Seg::Item(k)])) {
        let link = &spec.links[l];
        return of_end(&link.from).or_else(|| of_end(&link.to)).unwrap_or(0);
    }
    let word: String = loaded
        .source
        .get(offset..)
        .unwrap_or_default()
        .chars()
        .take_while(|c| c.is_alphanumeric() || *c == '_')
        .collect();
    agent_of(&word).unwrap_or(0)
}

/// Every error finding of `report`, one compile error each,
/// `file:line:col: error[code]: message`.
fn report_error(file: &LitStr, report: &agent_spec::Report) -> syn::Error {
    findings_error(file, report, |_| true)
        .unwrap_or_else(|| syn::Error::new(file.span(), "the spec has errors"))
}

/// One compile error per error finding at an offset that `keep` accepts,
/// `file:line:col: error[code]: message`; `None` if there is none.
fn findings_error(
    file: &LitStr,
    report: &agent_spec::Report,
    keep: impl Fn(usize) -> bool,
) -> Option<syn::Error> {
    let mut all: Option<syn::Error> = None;
    for f in report
        .findings
        .iter()
        .filter(|f| f.severity() == Severity::Error && keep(f.offset()))
    {
        let (l, c) = report.line_col(f.offset());
        let mut message = format!("{}:{l}:{c}: error[{}]: {}", report.file, f.code, f.message);
        if !f.help.is_empty() {
            message.push_str(&format!("\nhelp: {}", f.help));
        }
        let e = syn::Error::new(file.span(), message);
        match &mut all {
            Some(a) => a.combine(e),
            None => all = Some(e),
        }
    }
    all
}

/// A Rust identifier for a spec name (raw if it is a keyword). The checker refuses
/// the names that can be no identifier (`agent_spec::names::check`), and
/// [`generate`] again, first.
fn ident(name: &str) -> Ident {
    if agent_spec::names::KEYWORDS.contains(&name) {
        Ident::new_raw(name, Span::call_site())
    } else {
        Ident::new(name, Span::call_site())
    }
}

use agent_spec::names::type_name as camel;

/// The name of a kind's variant in generated code (`NodeKind::VirtualEffector`,
/// and the same name in `SubsystemKind`).
fn node_kind_name(kind: agent_core::NodeKind) -> &'static str {
    use agent_core::NodeKind as K;
    match kind {
        K::Control => "Control",
        K::VirtualEffector => "VirtualEffector",
        K::VirtualReceptor => "VirtualReceptor",
        K::RealEffector => "RealEffector",
        K::RealReceptor => "RealReceptor",
    }
}

/// The component kinds of the spec, by name.
fn peer_kind(spec: &Spec, name: &str) -> &'static str {
    for a in &spec.agents {
        if let Some(s) = a.subsystems.iter().find(|s| s.name == name) {
            return node_kind_name(s.kind.into());
        }
        if let Some(d) = a.devices.iter().find(|d| d.name == name) {
            return node_kind_name(d.kind.into());
        }
    }
    // Only for a spec the checker rejected (unknown peers are errors, reported):
    // the items are still generated, so that no cascade follows.
    "Control"
}

/// Location text of a path in the spec: `file:line:col`.
fn location(found: &Found, path: &[Seg<'_>]) -> String {
    let offset = found
        .loaded
        .index
        .as_ref()
        .and_then(|i| i.at(path))
        .map_or(0, |n| n.content_span().start);
    let (l, c) = agent_spec::diag::line_col(&found.loaded.source, offset);
    format!("{}:{l}:{c}", found.loaded.file)
}

/// A spec type string as a Rust type, or an error naming where it is.
fn rust_type(
    found: &Found,
    file: &LitStr,
    ty: &str,
    path: &[Seg<'_>],
    what: &str,
) -> syn::Result<syn::Type> {
    syn::parse_str::<syn::Type>(ty).map_err(|e| {
        syn::Error::new(
            file.span(),
            format!(
                "{}: the type `{ty}` of {what} is not a Rust type: {e}",
                location(found, path)
            ),
        )
    })
}

fn doc_attr(doc: Option<&String>, extra: &str) -> TokenStream {
    let mut text = doc.map_or_else(String::new, |d| format!(" {d}\n\n"));
    if !extra.starts_with(' ') {
        text.push(' ');
    }
    text.push_str(extra);
    quote!(#[doc = #text])
}

/// The groups of one direction of a component: struct definitions and the
/// input or output struct holding them.
#[allow(
    clippy::too_many_arguments,
    reason = "the parts of one direction of a component, each from a different place of the spec"
)]
fn groups(
    found: &Found,
    file: &LitStr,
    groups: &[model::Group],
    base: &[Seg<'_>],
    field: &'static str,
    input: bool,
) -> syn::Result<TokenStream> {
    let rt = runtime();
    let spec = &found.loaded.spec;
    let mut defs = Vec::new();
    let mut members = Vec::new();
    for (g, group) in groups.iter().enumerate() {
        let gname = format_ident!(
            "{}{}",
            if input { "From" } else { "To" },
            camel(&group.peer)
        );
        // A fan's peers are components of one kind: its first one's.
        let peer = format_ident!(
            "{}",
            peer_kind(spec, group.peers.first().unwrap_or(&group.peer))
        );
        let mut fields = Vec::new();
        for (b, buffer) in group.buffers.iter().enumerate() {
            let path: Vec<Seg<'_>> = base
                .iter()
                .copied()
                .chain([
                    Seg::Field(field),
                    Seg::Item(g),
                    Seg::Field("buffers"),
                    Seg::Item(b),
                    Seg::Field("type"),
                ])
                .collect();
            let ty = rust_type(
                found,
                file,
                &buffer.ty,
                &path,
                &format!("buffer `{}.{}`", group.peer, buffer.name),
            )?;
            let name = ident(&buffer.name);
            let doc = doc_attr(buffer.doc.as_ref(), &format!("Spec type: `{}`.", buffer.ty));
            fields.push(if input {
                quote!(#doc pub #name: #rt::In<#ty>)
            } else {
                quote!(#doc pub #name: #rt::Out<#ty>)
            });
        }
        let derives = if input {
            quote!(#[derive(Debug, Default, Clone, #rt::Group)])
        } else {
            quote!(#[derive(Debug, Default, #rt::Group)])
        };
        let doc = format!(
            " The buffers {} `{}`.",
            if input { "received from" } else { "sent to" },
            group.peer
        );
        defs.push(quote! {
            #[doc = #doc]
            #derives
            #[group(peer = #peer)]
            #[allow(non_snake_case)]
            pub struct #gname { #(#fields),* }
        });
        let member = ident(&group.peer);
        let direction = if input { "from" } else { "to" };
        if group.peers.is_empty() {
            let member_doc = format!(" The group {direction} `{}`.", group.peer);
            members.push(quote!(#[doc = #member_doc] pub #member: #gname));
        } else {
            let member_doc = format!(
                " Fan `{}`: the group {direction} each of {}, element `k` {direction} the `k`-th; a default one has no element: make it with `Fan::new({})` and build the subsystem with `subsystem_with_buffers`.",
                group.peer,
                group.peers.join(", "),
                group.peers.len()
            );
            members.push(quote!(#[doc = #member_doc] pub #member: #rt::Fan<#gname>));
        }
    }
    let (sname, derives, doc) = if input {
        (
            format_ident!("Input"),
            quote!(#[derive(Debug, Default, Clone, #rt::Buffers)]),
            " The input buffers, one group per peer.",
        )
    } else {
        (
            format_ident!("Output"),
            quote!(#[derive(Debug, Default, #rt::Buffers)]),
            " The output buffers, one group per peer.",
        )
    };
    Ok(quote! {
        #(#defs)*
        #[doc = #doc]
        #derives
        #[allow(non_snake_case)]
        pub struct #sname { #(#members),* }
    })
}

fn device(found: &Found, file: &LitStr, d: usize, dev: &model::Device) -> syn::Result<TokenStream> {
    let base = [
        Seg::Field("agents"),
        Seg::Item(found.agent),
        Seg::Field("devices"),
        Seg::Item(d),
    ];
    let module = ident(&dev.name);
    let inputs = groups(found, file, &dev.inputs, &base, "inputs", true)?;
    let outputs = groups(found, file, &dev.outputs, &base, "outputs", false)?;
    let name = &dev.name;
    let period = dev.period_ms;
    let doc = doc_attr(
        dev.doc.as_ref(),
        &format!(
            " Device `{name}` of `{}`, generated by `agent!`: its buffers. Implement `Driver` on your own type with these as `Input` and `Output`.",
            found.loaded.file
        ),
    );
    Ok(quote! {
        #doc
        #[allow(non_snake_case, dead_code)]
        pub mod #module {
            #[allow(unused_imports)]
            use super::*;

            /// The component's name in the spec.
            pub const NAME: &str = #name;
            /// Its period in the spec \[ms\].
            pub const PERIOD_MS: f64 = #period;

            #inputs
            #outputs
        }
    })
}

/// Why a name of the agent cannot become Rust code, if one cannot.
fn unusable_name(agent: &model::Agent) -> Option<String> {
    fn groups(g: &[model::Group]) -> impl Iterator<Item = &str> {
        g.iter().flat_map(|g| {
            std::iter::once(g.peer.as_str()).chain(g.buffers.iter().map(|b| b.name.as_str()))
        })
    }
    let mut names: Vec<&str> = Vec::new();
    for s in &agent.subsystems {
        names.push(&s.name);
        names.extend(s.memory.iter().map(|m| m.name.as_str()));
        names.extend(groups(&s.inputs));
        names.extend(groups(&s.outputs));
        names.extend(s.functions.iter().map(|f| f.name.as_str()));
        names.extend(s.functions.iter().filter_map(|f| match &f.target {
            model::Target::Output(peer) => Some(peer.as_str()),
            _ => None,
        }));
        names.extend(s.predicates.iter().map(|p| p.name.as_str()));
    }
    for d in &agent.devices {
        names.push(&d.name);
        names.extend(groups(&d.inputs));
        names.extend(groups(&d.outputs));
    }
    // The checker's rules (it ran first; this keeps the generator safe alone).
    if let Some((n, p)) = names
        .into_iter()
        .find_map(|n| agent_spec::names::check(n).err().map(|p| (n, p)))
    {
        return Some(format!("the name `{n}` {p}"));
    }
    let components = agent
        .subsystems
        .iter()
        .map(|s| &s.name)
        .chain(agent.devices.iter().map(|d| &d.name));
    for c in components {
        if let Some(why) = agent_spec::names::component_problem(c) {
            return Some(format!("the component name `{c}` {why}"));
        }
    }
    None
}

/// Generate stage.
pub(crate) fn generate(
    found: &Found,
    args: &AgentArgs,
    tracked: Option<&Path>,
) -> syn::Result<TokenStream> {
    let agent = &found.loaded.spec.agents[found.agent];
    if let Some(why) = unusable_name(agent) {
        return Err(syn::Error::new(
            args.spec.span(),
            format!(
                "{}: in agent `{}`, {why}; rename it in the spec",
                found.loaded.file, agent.name
            ),
        ));
    }
    let mut items = Vec::new();
    for (s, sub) in agent.subsystems.iter().enumerate() {
        items.push(subsystem::subsystem(found, args, s, sub)?);
    }
    for (d, dev) in agent.devices.iter().enumerate() {
        items.push(device(found, &args.spec, d, dev)?);
    }
    // Rebuild when the spec changes.
    let track = tracked.and_then(Path::to_str).map(|p| {
        quote!(
            const _: &[u8] = ::core::include_bytes!(#p);
        )
    });
    Ok(quote! {
        #track
        #(#items)*
    })
}

/// The whole macro.
pub(crate) fn expand(tokens: TokenStream, invoker: Option<PathBuf>) -> TokenStream {
    let result = parse(tokens).and_then(|args| {
        let path = resolve(&args.spec.value(), invoker);
        let bytes = std::fs::read(&path).map_err(|e| {
            syn::Error::new(
                args.spec.span(),
                format!(
                    "cannot read the spec `{}` ({e}); the path is relative to the crate's Cargo.toml or to the file invoking `agent!`",
                    path.display()
                ),
            )
        })?;
        let text = agent_spec::decode(&args.spec.value(), bytes)
            .map_err(|report| report_error(&args.spec, &report))?;
        let found = load(&args.spec, text, &args.agent)?;
        let items = generate(&found, &args, Some(&path));
        match (found.errors, items) {
            (None, items) => items,
            // The findings, and the items they concern (generated as well as the
            // broken spec allows), so that code using them compiles on.
            (Some(errors), Ok(items)) => {
                let errors = errors.into_compile_error();
                Ok(quote!(#errors #items))
            }
            (Some(mut errors), Err(e)) => {
                errors.combine(e);
                Err(errors)
            }
        }
    });
    result.unwrap_or_else(syn::Error::into_compile_error)
}

#[cfg(test)]
mod tests;
