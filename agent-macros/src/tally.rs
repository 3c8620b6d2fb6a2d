//! `#[derive(Tally)]`: counts that add up field by field.

use proc_macro2::TokenStream;
use quote::quote;
use syn::{Data, DeriveInput, Fields, Index};

use crate::util::runtime;

/// The `Tally` impl of a struct: every field tallied with the other's.
pub(crate) fn derive_tally(input: DeriveInput) -> syn::Result<TokenStream> {
    let Data::Struct(data) = &input.data else {
        return Err(syn::Error::new_spanned(
            &input.ident,
            "`Tally` is derived for structs: counts added field by field (an enum's variants do not add up)",
        ));
    };
    let fields: Vec<TokenStream> = match &data.fields {
        Fields::Named(f) => f
            .named
            .iter()
            .filter_map(|f| f.ident.as_ref())
            .map(|name| quote!(self.#name.tally(other.#name);))
            .collect(),
        Fields::Unnamed(f) => (0..f.unnamed.len())
            .map(Index::from)
            .map(|k| quote!(self.#k.tally(other.#k);))
            .collect(),
        Fields::Unit => Vec::new(),
    };
    let rt = runtime();
    let name = &input.ident;
    let (impl_generics, ty_generics, where_clause) = input.generics.split_for_impl();
    Ok(quote! {
        impl #impl_generics #rt::app::Tally for #name #ty_generics #where_clause {
            #[allow(unused_variables)]
            fn tally(&mut self, other: Self) {
                use #rt::app::Tally as _;
                #(#fields)*
            }
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn derived(input: TokenStream) -> Result<String, String> {
        let input: DeriveInput = syn::parse2(input).map_err(|e| e.to_string())?;
        derive_tally(input)
            .map(|t| t.to_string())
            .map_err(|e| e.to_string())
    }

    #[test]
    fn every_field_is_tallied_by_name_or_position() {
        let named = derived(quote!(
            struct C {
                a: u32,
                b: Vec<u8>,
            }
        ));
        let text = named.unwrap_or_else(|e| panic!("{e}"));
        assert!(text.contains("self . a . tally (other . a)"), "{text}");
        assert!(text.contains("self . b . tally (other . b)"), "{text}");
        let tuple = derived(quote!(
            struct T(u64, (u8, u8));
        ));
        let text = tuple.unwrap_or_else(|e| panic!("{e}"));
        assert!(text.contains("self . 1 . tally (other . 1)"), "{text}");
        let generic = derived(quote!(
            struct G<N: Copy> {
                n: N,
            }
        ));
        let text = generic.unwrap_or_else(|e| panic!("{e}"));
        assert!(text.contains("impl < N : Copy >"), "{text}");
    }

    #[test]
    fn an_enum_is_refused_with_why() {
        let why = derived(quote!(
            enum E {
                A(u32),
                B,
            }
        ));
        assert!(
            why.as_ref()
                .is_err_and(|w| w.contains("`Tally` is derived for structs")),
            "{why:?}"
        );
    }
}
