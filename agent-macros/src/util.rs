//! Helpers shared by the macros.

use proc_macro2::{Delimiter, TokenStream, TokenTree};
use quote::{ToTokens, quote};

/// The path of the runtime crate in generated code: the `embodied` facade, the one
/// dependency a user adds.
pub(crate) fn runtime() -> TokenStream {
    quote!(::embodied)
}

/// A type (or any tokens) as compact text: `Option<Vec<u8>>`, `[f64; 4]`,
/// `&'static str`. Spaces only where two words would otherwise merge.
pub(crate) fn type_text(ty: &impl ToTokens) -> String {
    let mut out = String::new();
    write_tokens(ty.to_token_stream(), &mut out);
    out
}

fn write_tokens(ts: TokenStream, out: &mut String) {
    for tt in ts {
        match tt {
            TokenTree::Group(g) => {
                let (open, close) = match g.delimiter() {
                    Delimiter::Parenthesis => ("(", ")"),
                    Delimiter::Bracket => ("[", "]"),
                    Delimiter::Brace => ("{", "}"),
                    Delimiter::None => ("", ""),
                };
                out.push_str(open);
                write_tokens(g.stream(), out);
                out.push_str(close);
            }
            TokenTree::Punct(p) => {
                let c = p.as_char();
                out.push(c);
                if c == ';' || (c == ',' && p.spacing() == proc_macro2::Spacing::Alone) {
                    out.push(' ');
                }
            }
            TokenTree::Ident(i) => {
                word(out, &i.to_string());
            }
            TokenTree::Literal(l) => {
                word(out, &l.to_string());
            }
        }
    }
    let trimmed = out.trim_end().len();
    out.truncate(trimmed);
}

fn word(out: &mut String, w: &str) {
    let joins = out
        .chars()
        .last()
        .is_some_and(|c| c.is_alphanumeric() || c == '_');
    if joins {
        out.push(' ');
    }
    out.push_str(w);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn types_print_compactly() {
        let t = |ts: TokenStream| type_text(&ts);
        assert_eq!(t(quote!(Option<Vec<u8>>)), "Option<Vec<u8>>");
        assert_eq!(t(quote!([f64; 4])), "[f64; 4]");
        assert_eq!(t(quote!(&'static str)), "&'static str");
        assert_eq!(t(quote!((u8, f64))), "(u8, f64)");
        assert_eq!(t(quote!(crate::x::Plan)), "crate::x::Plan");
        assert_eq!(t(quote!(dyn Fn(u8) -> u8)), "dyn Fn(u8)->u8");
    }
}
