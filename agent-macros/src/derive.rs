//! The derives: `Group`, `Buffers`, `Memory` and `Subsystem`.
//!
//! Each derive has two stages, tested separately on token input: a *parse* stage
//! that reads the struct into a small model (and rejects what it cannot describe,
//! with an error on the offending tokens) and a *generate* stage that writes the
//! trait implementations of `agent_core::describe` from the model.

use proc_macro2::{Span, TokenStream};
use quote::{ToTokens, quote, quote_spanned};
use syn::ext::IdentExt;
use syn::spanned::Spanned;
use syn::{Data, DeriveInput, Fields, GenericArgument, Ident, PathArguments, Type};

use crate::util::{runtime, type_text};

/// Whether a field is an input or an output buffer.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Dir {
    In,
    Out,
}

impl Dir {
    fn tokens(self, rt: &TokenStream) -> TokenStream {
        match self {
            Dir::In => quote!(#rt::Direction::In),
            Dir::Out => quote!(#rt::Direction::Out),
        }
    }
}

/// `In<T>` or `Out<T>`: the direction and the payload type.
pub(crate) fn buffer_type(ty: &Type) -> Option<(Dir, &Type)> {
    let Type::Path(p) = ty else { return None };
    if p.qself.is_some() {
        return None;
    }
    let last = p.path.segments.last()?;
    let dir = match last.ident.to_string().as_str() {
        "In" => Dir::In,
        "Out" => Dir::Out,
        _ => return None,
    };
    let PathArguments::AngleBracketed(args) = &last.arguments else {
        return None;
    };
    match args.args.iter().collect::<Vec<_>>()[..] {
        [GenericArgument::Type(t)] => Some((dir, t)),
        _ => None,
    }
}

/// A named field of the derived struct.
#[derive(Clone)]
pub(crate) struct NamedField {
    pub(crate) ident: Ident,
    pub(crate) ty: Type,
}

fn named_fields(input: &DeriveInput, what: &str) -> syn::Result<Vec<NamedField>> {
    match &input.data {
        Data::Struct(s) => match &s.fields {
            Fields::Named(f) => Ok(f
                .named
                .iter()
                .filter_map(|f| {
                    f.ident.clone().map(|ident| NamedField {
                        ident,
                        ty: f.ty.clone(),
                    })
                })
                .collect()),
            Fields::Unit => Ok(Vec::new()),
            Fields::Unnamed(f) => Err(syn::Error::new(
                f.span(),
                format!("`{what}` needs named fields: each field is described by its name"),
            )),
        },
        Data::Enum(e) => Err(syn::Error::new(
            e.enum_token.span,
            format!("`{what}` can only be derived for a struct"),
        )),
        Data::Union(u) => Err(syn::Error::new(
            u.union_token.span,
            format!("`{what}` can only be derived for a struct"),
        )),
    }
}

/// The five kinds of component, as written in `#[group(peer = ...)]`.
const PEERS: [&str; 5] = [
    "Control",
    "VirtualEffector",
    "VirtualReceptor",
    "RealEffector",
    "RealReceptor",
];

/// Read `#[name(key = Value)]` attributes into `(key, value)` pairs; a value is a
/// type (`StationMemory`, `()`, `Vec<u8>`) or a kind (`Control`).
fn attr_pairs(input: &DeriveInput, name: &str) -> syn::Result<Vec<(Ident, Type)>> {
    let mut pairs = Vec::new();
    for attr in input.attrs.iter().filter(|a| a.path().is_ident(name)) {
        attr.parse_nested_meta(|meta| {
            let key = meta
                .path
                .get_ident()
                .cloned()
                .ok_or_else(|| meta.error("expected `key = value`"))?;
            let value: Type = meta.value()?.parse()?;
            pairs.push((key, value));
            Ok(())
        })?;
    }
    Ok(pairs)
}

/// `Control` written as a type: its identifier.
fn single_ident(ty: &Type) -> Option<Ident> {
    match ty {
        Type::Path(p) if p.qself.is_none() => p.path.get_ident().cloned(),
        _ => None,
    }
}

// ---------------------------------------------------------------------------
// Group

/// The model of `#[derive(Group)]`: a struct of buffers of one direction towards one
/// kind of peer.
pub(crate) struct GroupModel {
    pub(crate) input: DeriveInput,
    pub(crate) peer: Ident,
    pub(crate) dir: Dir,
    /// Field name, payload type.
    pub(crate) buffers: Vec<(Ident, Type)>,
}

pub(crate) fn parse_group(input: DeriveInput) -> syn::Result<GroupModel> {
    let fields = named_fields(&input, "Group")?;
    let pairs = attr_pairs(&input, "group")?;
    let mut peer = None;
    for (key, value) in pairs {
        if key != "peer" {
            return Err(syn::Error::new(
                key.span(),
                format!("unknown key `{key}`: `#[group(peer = <kind>)]` has only `peer`"),
            ));
        }
        match single_ident(&value) {
            Some(i) if PEERS.contains(&i.to_string().as_str()) => peer = Some(i),
            _ => {
                return Err(syn::Error::new_spanned(
                    value,
                    format!("the peer is one of {}", PEERS.join(", ")),
                ));
            }
        }
    }
    let Some(peer) = peer else {
        return Err(syn::Error::new(
            Span::call_site(),
            "a group names the kind of component at its other end: add `#[group(peer = VirtualEffector)]` (or Control, VirtualReceptor, RealEffector, RealReceptor)",
        ));
    };
    let mut dir = None;
    let mut buffers = Vec::new();
    for f in fields {
        let Some((d, payload)) = buffer_type(&f.ty) else {
            return Err(syn::Error::new_spanned(
                &f.ty,
                format!(
                    "field `{}` of a group must be a buffer, `In<T>` or `Out<T>`",
                    f.ident
                ),
            ));
        };
        match dir {
            None => dir = Some(d),
            Some(first) if first != d => {
                return Err(syn::Error::new_spanned(
                    &f.ty,
                    "a group holds either input buffers (`In<T>`) or output buffers (`Out<T>`), not both",
                ));
            }
            Some(_) => {}
        }
        buffers.push((f.ident, payload.clone()));
    }
    Ok(GroupModel {
        input,
        peer,
        dir: dir.unwrap_or(Dir::In),
        buffers,
    })
}

pub(crate) fn generate_group(m: &GroupModel) -> TokenStream {
    let rt = runtime();
    let name = &m.input.ident;
    let (impl_g, ty_g, where_g) = m.input.generics.split_for_impl();
    let peer = &m.peer;
    let fields = m.buffers.iter().map(|(ident, ty)| {
        let n = ident.unraw().to_string();
        let t = type_text(ty);
        quote!(#rt::Field { name: #n, ty: #t })
    });
    let fresh = m.buffers.iter().enumerate().map(
        |(k, (ident, _))| quote!(| (#rt::describe::Buffer::is_fresh(&self.#ident) as u128) << #k),
    );
    let reads = m.buffers.iter().enumerate().map(
        |(k, (ident, _))| quote!(| (#rt::describe::Buffer::take_read(&self.#ident) as u128) << #k),
    );
    let dir = m.dir.tokens(&rt);
    let ty_name = name.to_string();
    let count = m.buffers.len();
    let too_many = count > rt_max_buffers();
    let guard = too_many
        .then(|| quote_spanned!(name.span()=> compile_error!("a group has at most 128 buffers");));
    // Buffers found by name (links made from a spec); a generic group keeps the
    // default (none), since its payloads need not be `Payload` for every parameter.
    let lookup = m.input.generics.params.is_empty().then(|| {
        let maker = match m.dir {
            Dir::In => quote!(in_group),
            Dir::Out => quote!(out_group),
        };
        let arms = m.buffers.iter().map(|(ident, _)| {
            let n = ident.unraw().to_string();
            quote!(#n => ::core::option::Option::Some(
                #rt::BufferPort::#maker(group_name, group, #n, |g: &mut Self| &mut g.#ident)
            ))
        });
        quote! {
            fn buffer_port<B: ::core::marker::Send + 'static>(
                group_name: &'static str,
                group: impl #rt::Access<B, Self>,
                buffer: &str,
            ) -> ::core::option::Option<#rt::BufferPort> {
                let _ = (group_name, group);
                match buffer {
                    #(#arms,)*
                    _ => ::core::option::Option::None,
                }
            }
        }
    });
    quote! {
        #guard
        impl #impl_g #rt::Group for #name #ty_g #where_g {
            const PEER: #rt::NodeKind = #rt::NodeKind::#peer;
            #lookup
        }
        impl #impl_g #rt::Fields for #name #ty_g #where_g {
            const FIELDS: &'static [#rt::Field] = &[#(#fields),*];
        }
        impl #impl_g #rt::Buffers for #name #ty_g #where_g {
            const GROUPS: &'static [#rt::GroupShape] = &[#rt::GroupShape {
                name: "",
                peer: ::core::option::Option::Some(#rt::NodeKind::#peer),
                ty: #ty_name,
                direction: #dir,
                buffers: <Self as #rt::Fields>::FIELDS,
            }];
            #[inline]
            fn fresh(&self) -> #rt::Fresh {
                #rt::Fresh(0 #(#fresh)*)
            }
            fn take_reads(&self) -> #rt::Fresh {
                #rt::Fresh(0 #(#reads)*)
            }
        }
    }
}

/// `agent_core::describe::MAX_BUFFERS`, known to the macro.
const fn rt_max_buffers() -> usize {
    agent_core::describe::MAX_BUFFERS
}

// ---------------------------------------------------------------------------
// Buffers

/// The model of `#[derive(Buffers)]`: a struct of groups, or a struct of buffers.
pub(crate) enum BuffersModel {
    /// A subsystem's input or output struct: each field is a group.
    Groups {
        input: DeriveInput,
        groups: Vec<NamedField>,
    },
    /// A driver's input or output struct: each field is a buffer of one direction.
    Flat {
        input: DeriveInput,
        dir: Dir,
        buffers: Vec<(Ident, Type)>,
    },
}

pub(crate) fn parse_buffers(input: DeriveInput) -> syn::Result<BuffersModel> {
    let fields = named_fields(&input, "Buffers")?;
    let buffers: Vec<_> = fields
        .iter()
        .filter_map(|f| buffer_type(&f.ty).map(|(d, t)| (f, d, t)))
        .collect();
    if buffers.is_empty() {
        return Ok(BuffersModel::Groups {
            input,
            groups: fields,
        });
    }
    if buffers.len() != fields.len() {
        let group = fields
            .iter()
            .find(|f| buffer_type(&f.ty).is_none())
            .map_or_else(|| input.ident.to_token_stream(), |f| f.ty.to_token_stream());
        return Err(syn::Error::new_spanned(
            group,
            "the fields of an input or output struct are either all groups (a subsystem's) or all buffers `In<T>`/`Out<T>` (a driver's); move the buffers into a `#[derive(Group)]` struct",
        ));
    }
    let dir = buffers[0].1;
    if let Some((f, _, _)) = buffers.iter().find(|(_, d, _)| *d != dir) {
        return Err(syn::Error::new_spanned(
            &f.ty,
            "an input or output struct holds either input buffers (`In<T>`) or output buffers (`Out<T>`), not both",
        ));
    }
    let buffers = buffers
        .into_iter()
        .map(|(f, _, t)| (f.ident.clone(), t.clone()))
        .collect();
    Ok(BuffersModel::Flat {
        input,
        dir,
        buffers,
    })
}

pub(crate) fn generate_buffers(m: &BuffersModel) -> TokenStream {
    match m {
        BuffersModel::Groups { input, groups } => generate_group_buffers(input, groups),
        BuffersModel::Flat {
            input,
            dir,
            buffers,
        } => generate_flat_buffers(input, *dir, buffers),
    }
}

/// `Buffers` for a subsystem's struct of groups: the groups' shapes, and the
/// freshness and read bits of each group shifted past the groups before it.
fn generate_group_buffers(input: &DeriveInput, groups: &[NamedField]) -> TokenStream {
    let rt = runtime();
    let name = &input.ident;
    let (impl_g, ty_g, where_g) = input.generics.split_for_impl();
    let shapes = groups.iter().map(|g| {
        let (field, ty) = (g.ident.unraw().to_string(), &g.ty);
        let ty_text = type_text(ty);
        quote_spanned! {ty.span()=>
            #rt::GroupShape {
                name: #field,
                peer: ::core::option::Option::Some(<#ty as #rt::Group>::PEER),
                ty: #ty_text,
                direction: <#ty as #rt::Buffers>::GROUPS[0].direction,
                buffers: <#ty as #rt::Fields>::FIELDS,
            }
        }
    });
    // Bit offset of each group: the buffers of the groups before it.
    let mut offset = quote!(0usize);
    let mut fresh = Vec::new();
    let mut reads = Vec::new();
    for g in groups {
        let (ident, ty) = (&g.ident, &g.ty);
        // `checked_shl`: an empty group may start at bit 128.
        fresh.push(quote!(| #rt::Buffers::fresh(&self.#ident).0.checked_shl((#offset) as u32).unwrap_or(0)));
        reads.push(quote!(| #rt::Buffers::take_reads(&self.#ident).0.checked_shl((#offset) as u32).unwrap_or(0)));
        offset = quote!(#offset + <#ty as #rt::Fields>::FIELDS.len());
    }
    let lookup = input.generics.params.is_empty().then(|| {
        let arms = groups.iter().map(|g| {
            let (ident, ty) = (&g.ident, &g.ty);
            let n = ident.unraw().to_string();
            quote!(#n => <#ty as #rt::Group>::buffer_port::<Self>(#n, |s: &mut Self| &mut s.#ident, buffer))
        });
        quote! {
            fn port(path: &str) -> ::core::option::Option<#rt::BufferPort> {
                // `group.buffer`, or `group[k].buffer` for a fan (whose lookup
                // reads the `[k].buffer` left).
                let (group, rest) = path.split_at(path.find(['.', '['])?);
                let buffer = match rest.strip_prefix('.') {
                    ::core::option::Option::Some(b) if !b.starts_with('[') => b,
                    ::core::option::Option::Some(_) => return ::core::option::Option::None,
                    ::core::option::Option::None => rest,
                };
                match group {
                    #(#arms,)*
                    _ => ::core::option::Option::None,
                }
            }
        }
    });
    // An inline `const` block may use the struct's generic parameters.
    quote! {
        impl #impl_g #rt::Buffers for #name #ty_g #where_g {
            #lookup
            const GROUPS: &'static [#rt::GroupShape] = &[#(#shapes),*];
            #[inline]
            fn fresh(&self) -> #rt::Fresh {
                const {
                    ::core::assert!(
                        #offset <= #rt::describe::MAX_BUFFERS,
                        "an input or output struct has at most 128 buffers"
                    )
                };
                #rt::Fresh(0 #(#fresh)*)
            }
            fn take_reads(&self) -> #rt::Fresh {
                #rt::Fresh(0 #(#reads)*)
            }
        }
    }
}

/// `Buffers` for a driver's flat struct of buffers of one direction: one
/// unnamed group, one bit per buffer.
fn generate_flat_buffers(input: &DeriveInput, dir: Dir, buffers: &[(Ident, Type)]) -> TokenStream {
    let rt = runtime();
    let name = &input.ident;
    let (impl_g, ty_g, where_g) = input.generics.split_for_impl();
    let fields = buffers.iter().map(|(ident, ty)| {
        let (n, t) = (ident.unraw().to_string(), type_text(ty));
        quote!(#rt::Field { name: #n, ty: #t })
    });
    let fresh = buffers.iter().enumerate().map(
        |(k, (ident, _))| quote!(| (#rt::describe::Buffer::is_fresh(&self.#ident) as u128) << #k),
    );
    let reads = buffers.iter().enumerate().map(
        |(k, (ident, _))| quote!(| (#rt::describe::Buffer::take_read(&self.#ident) as u128) << #k),
    );
    let guard = (buffers.len() > rt_max_buffers()).then(|| {
        quote_spanned!(name.span()=> compile_error!("a struct of buffers has at most 128 buffers");)
    });
    let lookup = input.generics.params.is_empty().then(|| {
        let maker = match dir {
            Dir::In => quote!(input),
            Dir::Out => quote!(output),
        };
        let arms = buffers.iter().map(|(ident, _)| {
            let n = ident.unraw().to_string();
            quote!(#n => ::core::option::Option::Some(#rt::BufferPort::#maker(
                #rt::Port::new(#n, |s: &mut Self| &mut s.#ident, ::core::option::Option::None)
            )))
        });
        quote! {
            fn port(path: &str) -> ::core::option::Option<#rt::BufferPort> {
                match path {
                    #(#arms,)*
                    _ => ::core::option::Option::None,
                }
            }
        }
    });
    let dir = dir.tokens(&rt);
    quote! {
        #guard
        impl #impl_g #rt::Buffers for #name #ty_g #where_g {
            #lookup
            const GROUPS: &'static [#rt::GroupShape] = &[#rt::GroupShape {
                name: "",
                peer: ::core::option::Option::None,
                ty: "",
                direction: #dir,
                buffers: &[#(#fields),*],
            }];
            #[inline]
            fn fresh(&self) -> #rt::Fresh {
                #rt::Fresh(0 #(#fresh)*)
            }
            fn take_reads(&self) -> #rt::Fresh {
                #rt::Fresh(0 #(#reads)*)
            }
        }
    }
}

// ---------------------------------------------------------------------------
// Memory

/// The model of `#[derive(Memory)]`: the named fields of a memory struct.
pub(crate) struct MemoryModel {
    pub(crate) input: DeriveInput,
    pub(crate) fields: Vec<NamedField>,
}

pub(crate) fn parse_memory(input: DeriveInput) -> syn::Result<MemoryModel> {
    let fields = named_fields(&input, "Memory")?;
    if let Some(f) = fields.iter().find(|f| buffer_type(&f.ty).is_some()) {
        return Err(syn::Error::new_spanned(
            &f.ty,
            "buffers belong in the input or output struct, not in the memory",
        ));
    }
    Ok(MemoryModel { input, fields })
}

pub(crate) fn generate_memory(m: &MemoryModel) -> TokenStream {
    let rt = runtime();
    let name = &m.input.ident;
    let (impl_g, ty_g, where_g) = m.input.generics.split_for_impl();
    let fields = m.fields.iter().map(|f| {
        let (n, t) = (f.ident.unraw().to_string(), type_text(&f.ty));
        quote!(#rt::Field { name: #n, ty: #t })
    });
    quote! {
        impl #impl_g #rt::Fields for #name #ty_g #where_g {
            const FIELDS: &'static [#rt::Field] = &[#(#fields),*];
        }
    }
}

// ---------------------------------------------------------------------------
// Subsystem

/// The model of `#[derive(Subsystem)]` on a marker type.
pub(crate) struct SubsystemModel {
    pub(crate) input: DeriveInput,
    pub(crate) kind: Ident,
    pub(crate) memory: Type,
    pub(crate) inputs: Type,
    pub(crate) outputs: Type,
}

const KINDS: [&str; 3] = ["Control", "VirtualEffector", "VirtualReceptor"];

pub(crate) fn parse_subsystem(input: DeriveInput) -> syn::Result<SubsystemModel> {
    let (mut kind, mut memory, mut inputs, mut outputs) = (None, None, None, None);
    for (key, value) in attr_pairs(&input, "subsystem")? {
        match key.to_string().as_str() {
            "kind" => match single_ident(&value) {
                Some(i) if KINDS.contains(&i.to_string().as_str()) => kind = Some(i),
                _ => {
                    return Err(syn::Error::new_spanned(
                        value,
                        format!("the kind is one of {}", KINDS.join(", ")),
                    ));
                }
            },
            "memory" => memory = Some(value),
            "input" => inputs = Some(value),
            "output" => outputs = Some(value),
            other => {
                return Err(syn::Error::new(
                    key.span(),
                    format!(
                        "unknown key `{other}`: `#[subsystem(...)]` takes kind, memory, input and output"
                    ),
                ));
            }
        }
    }
    let missing = |what: &str| {
        syn::Error::new(
            Span::call_site(),
            format!(
                "`#[derive(Subsystem)]` needs `#[subsystem(kind = Control, memory = M, input = I, output = O)]`: `{what}` is missing"
            ),
        )
    };
    Ok(SubsystemModel {
        kind: kind.ok_or_else(|| missing("kind"))?,
        memory: memory.ok_or_else(|| missing("memory"))?,
        inputs: inputs.ok_or_else(|| missing("input"))?,
        outputs: outputs.ok_or_else(|| missing("output"))?,
        input,
    })
}

pub(crate) fn generate_subsystem(m: &SubsystemModel) -> TokenStream {
    let rt = runtime();
    let name = &m.input.ident;
    let (impl_g, ty_g, where_g) = m.input.generics.split_for_impl();
    let (kind, memory, inputs, outputs) = (&m.kind, &m.memory, &m.inputs, &m.outputs);
    quote! {
        impl #impl_g #rt::Subsystem for #name #ty_g #where_g {
            const KIND: #rt::SubsystemKind = #rt::SubsystemKind::#kind;
            type Memory = #memory;
            type Input = #inputs;
            type Output = #outputs;
            fn shape() -> ::core::option::Option<#rt::Shape> {
                ::core::option::Option::Some(#rt::Shape::of_subsystem::<Self>())
            }
            fn ports() -> ::core::option::Option<#rt::PortTable> {
                ::core::option::Option::Some(#rt::PortTable::of::<#inputs, #outputs>())
            }
            fn audit(input: &#inputs, output: &#outputs) -> (#rt::Fresh, #rt::Fresh) {
                (#rt::Buffers::take_reads(input), #rt::Buffers::fresh(output))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(tokens: TokenStream) -> DeriveInput {
        syn::parse2(tokens).expect("a struct")
    }

    #[test]
    fn a_group_reads_its_peer_direction_and_payloads() {
        let m = parse_group(parse(quote! {
            #[group(peer = VirtualEffector)]
            struct ToValve { flow: Out<f64>, mode: Out<Option<Mode>> }
        }))
        .expect("a valid group");
        assert_eq!(m.peer, "VirtualEffector");
        assert_eq!(m.dir, Dir::Out);
        let payloads: Vec<String> = m.buffers.iter().map(|(_, t)| type_text(t)).collect();
        assert_eq!(payloads, ["f64", "Option<Mode>"]);
        let code = generate_group(&m).to_string();
        assert!(code.contains("const PEER"), "{code}");
        assert!(code.contains("\"Option<Mode>\""), "{code}");
        assert!(code.contains("is_fresh (& self . mode)"), "{code}");
    }

    #[test]
    fn a_group_without_peer_or_with_mixed_buffers_is_refused() {
        let e = parse_group(parse(quote!(
            struct G {
                a: In<u8>,
            }
        )))
        .err()
        .expect("no peer");
        assert!(
            e.to_string().contains("#[group(peer = VirtualEffector)]"),
            "{e}"
        );
        let e = parse_group(parse(quote! {
            #[group(peer = Control)] struct G { a: In<u8>, b: Out<u8> }
        }))
        .err()
        .expect("mixed");
        assert!(e.to_string().contains("not both"), "{e}");
        let e = parse_group(parse(quote! {
            #[group(peer = Controller)] struct G { a: In<u8> }
        }))
        .err()
        .expect("bad peer");
        assert!(e.to_string().contains("VirtualEffector"), "{e}");
        let e = parse_group(parse(quote! {
            #[group(peer = Control)] struct G { a: u8 }
        }))
        .err()
        .expect("not a buffer");
        assert!(e.to_string().contains("`a`"), "{e}");
    }

    #[test]
    fn buffers_are_groups_or_flat_never_mixed() {
        let m = parse_buffers(parse(quote!(
            struct I {
                pump: FromPump,
                op: FromOp,
            }
        )))
        .expect("groups");
        assert!(matches!(&m, BuffersModel::Groups { groups, .. } if groups.len() == 2));
        let code = generate_buffers(&m).to_string();
        assert!(
            code.contains("< FromPump as :: embodied :: Group > :: PEER"),
            "{code}"
        );
        let m = parse_buffers(parse(quote!(
            struct I {
                duty: In<f64>,
            }
        )))
        .expect("flat");
        assert!(matches!(&m, BuffersModel::Flat { dir: Dir::In, .. }));
        let e = parse_buffers(parse(quote!(
            struct I {
                duty: In<f64>,
                g: G,
            }
        )))
        .err()
        .expect("mixed");
        assert!(e.to_string().contains("either all groups"), "{e}");
    }

    #[test]
    fn memory_and_subsystem() {
        let m = parse_memory(parse(quote!(
            struct M {
                order: Option<Order>,
                n: u32,
            }
        )))
        .expect("memory");
        let code = generate_memory(&m).to_string();
        assert!(code.contains("\"Option<Order>\""), "{code}");
        let e = parse_memory(parse(quote!(
            struct M {
                x: In<u8>,
            }
        )))
        .err()
        .expect("buffer");
        assert!(e.to_string().contains("not in the memory"), "{e}");
        let m = parse_subsystem(parse(quote! {
            #[subsystem(kind = Control, memory = M, input = I, output = O)]
            struct S;
        }))
        .expect("subsystem");
        let code = generate_subsystem(&m).to_string();
        assert!(code.contains("SubsystemKind :: Control"), "{code}");
        assert!(code.contains("of_subsystem"), "{code}");
        let e = parse_subsystem(parse(quote! {
            #[subsystem(kind = Control, memory = M, input = I)] struct S;
        }))
        .err()
        .expect("no output");
        assert!(e.to_string().contains("`output` is missing"), "{e}");
    }
}
