//! The `FsmBuilder` chain both `fsm!` and `agent!` expand to: the code one would
//! write by hand, so that a macro-built FSM is the same FSM at run time.

use proc_macro2::{Ident, TokenStream};
use quote::{quote, quote_spanned};
use syn::ext::IdentExt;

use agent_core::Relation;

use crate::util::runtime;

/// What a part writes.
pub(crate) enum Target {
    Memory,
    Common,
    /// The output group in this field (its span is where a wrong field is reported).
    Output(Ident),
}

/// One part of an elementary action: its spec name, target and function.
pub(crate) struct Part {
    pub(crate) name: String,
    pub(crate) target: Target,
    pub(crate) function: TokenStream,
}

/// A behaviour: name, kind, terminal condition (text), parts.
pub(crate) struct Behaviour {
    pub(crate) name: String,
    pub(crate) repeat: bool,
    pub(crate) terminal: String,
    pub(crate) parts: Vec<Part>,
}

/// A whole FSM over subsystem type `subsystem`.
pub(crate) struct Chain {
    pub(crate) subsystem: TokenStream,
    /// Name and the function (a path or closure) of each predicate.
    pub(crate) predicates: Vec<(String, TokenStream)>,
    pub(crate) relations: Vec<Relation>,
    pub(crate) behaviours: Vec<Behaviour>,
    pub(crate) initial: Option<String>,
    /// `(from, to, condition)`.
    pub(crate) arcs: Vec<(String, String, String)>,
    pub(crate) finals: Vec<String>,
}

impl Chain {
    /// The expression `FsmBuilder::<S>::new()...build()`, of type
    /// `Result<Fsm<S>, FsmBuildError>`.
    pub(crate) fn generate(&self) -> TokenStream {
        let rt = runtime();
        let s = &self.subsystem;
        let predicates = self
            .predicates
            .iter()
            .map(|(n, f)| quote!(.predicate(#n, #f)));
        let relations = self.relations.iter().map(|r| match r {
            Relation::Exclusive(v) => {
                let v = v.iter().map(|n| n.as_ref());
                quote!(.exclusive([#(#v),*]))
            }
            Relation::Implies(a, b) => {
                let (a, b) = (a.as_ref(), b.as_ref());
                quote!(.implies(#a, #b))
            }
        });
        let behaviours = self.behaviours.iter().map(|b| {
            let name = &b.name;
            let kind = if b.repeat {
                quote!(#rt::BehaviourKind::Repeat)
            } else {
                quote!(#rt::BehaviourKind::While)
            };
            let parts = b.parts.iter().map(|p| {
                let (f, n) = (&p.function, &p.name);
                match &p.target {
                    Target::Memory => quote!(.memory(#f).named(#n)),
                    Target::Common => quote!(.common(#f).named(#n)),
                    Target::Output(field) => {
                        let y = Ident::new("__y", field.span());
                        let fs = field.unraw().to_string();
                        let projection = quote_spanned!(field.span()=> |#y| &mut #y.#field);
                        quote!(.output(#projection, #f).named(#n).__at_field(#fs))
                    }
                }
            });
            let terminal = &b.terminal;
            quote! {
                .behaviour(#rt::Behaviour::new(
                    #name,
                    #kind,
                    #rt::Action::<#s>::new() #(#parts)*,
                    #terminal,
                ))
            }
        });
        let initial = self.initial.as_ref().map(|i| quote!(.initial(#i)));
        let arcs = self.arcs.iter().map(|(f, t, w)| quote!(.arc(#f, #t, #w)));
        let finals = self.finals.iter().map(|f| quote!(.final_behaviour(#f)));
        quote! {
            #rt::FsmBuilder::<#s>::new()
                #(#predicates)*
                #(#relations)*
                #(#behaviours)*
                #initial
                #(#arcs)*
                #(#finals)*
                .build()
        }
    }
}
