//! What a valid name is, once for everyone: the spec checker, the code generators
//! (`agent!`, `embodied new`) and the runtime (the system builder) use these rules.
//!
//! A name of an agent, a component, a buffer, a function, a behaviour or a
//! predicate is an identifier (ASCII letters, digits and `_`, not starting with a
//! digit) that can be a Rust identifier, raw if it must: `type` becomes `r#type`,
//! but `self`, `Self`, `super`, `crate` and `_` can be no identifier at all.

use std::fmt;

/// Rust's keywords, strict and reserved: a name among them becomes a raw
/// identifier (`r#type`) in generated code.
pub const KEYWORDS: &[&str] = &[
    "as", "break", "const", "continue", "crate", "else", "enum", "extern", "false", "fn", "for",
    "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut", "pub", "ref", "return",
    "self", "Self", "static", "struct", "super", "trait", "true", "type", "unsafe", "use", "where",
    "while", "async", "await", "dyn", "abstract", "become", "box", "do", "final", "macro",
    "override", "priv", "typeof", "unsized", "virtual", "yield", "try", "gen",
];

/// Identifiers that can be no Rust identifier, not even raw.
pub const UNUSABLE: &[&str] = &["self", "Self", "super", "crate", "_"];

/// Why a name is not valid.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NameProblem {
    /// The name is empty.
    Empty,
    /// Not letters, digits and `_` starting with a letter or `_`.
    NotIdentifier,
    /// An identifier Rust has no use for (`self`, `crate`, `_`...).
    Unusable,
}

impl fmt::Display for NameProblem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            NameProblem::Empty => "is empty",
            NameProblem::NotIdentifier => {
                "is not an identifier (ASCII letters, digits and `_`, not starting with a digit)"
            }
            NameProblem::Unusable => {
                "can be no Rust identifier, not even a raw one (`self`, `Self`, `super`, `crate` and `_` cannot)"
            }
        })
    }
}

/// Whether `name` is an ASCII identifier.
pub fn is_identifier(name: &str) -> bool {
    let mut chars = name.chars();
    chars
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && chars.all(|c| c.is_ascii_alphanumeric() || c == '_')
}

/// Why `name` is not a valid name, if it is not.
///
/// ```
/// use agent_core::names::{NameProblem, check};
/// assert_eq!(check("plan_new"), Ok(()));
/// assert_eq!(check("type"), Ok(()), "becomes r#type");
/// assert_eq!(check("self"), Err(NameProblem::Unusable));
/// assert_eq!(check("2fast"), Err(NameProblem::NotIdentifier));
/// assert_eq!(check(""), Err(NameProblem::Empty));
/// ```
pub fn check(name: &str) -> Result<(), NameProblem> {
    if name.is_empty() {
        Err(NameProblem::Empty)
    } else if !is_identifier(name) {
        Err(NameProblem::NotIdentifier)
    } else if UNUSABLE.contains(&name) {
        Err(NameProblem::Unusable)
    } else {
        Ok(())
    }
}

/// `name` as a `&'static str`, made once per distinct name: port names are
/// static (links, traces and records keep them), and a name found at run time is
/// interned so that building systems again does not leak.
pub(crate) fn intern_name(name: String) -> &'static str {
    use std::collections::HashSet;
    use std::sync::{Mutex, OnceLock};
    static NAMES: OnceLock<Mutex<HashSet<&'static str>>> = OnceLock::new();
    let mut names = NAMES
        .get_or_init(Default::default)
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    if let Some(known) = names.get(name.as_str()) {
        return known;
    }
    let leaked: &'static str = Box::leak(name.into_boxed_str());
    names.insert(leaked);
    leaked
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names() {
        for ok in ["a", "_a", "c1", "A4x4", "r#", "type"]
            .iter()
            .filter(|n| !n.contains('#'))
        {
            assert_eq!(check(ok), Ok(()), "{ok}");
        }
        for (bad, why) in [
            ("", NameProblem::Empty),
            ("a b", NameProblem::NotIdentifier),
            ("a\0", NameProblem::NotIdentifier),
            ("é", NameProblem::NotIdentifier),
            ("1a", NameProblem::NotIdentifier),
            ("_", NameProblem::Unusable),
            ("Self", NameProblem::Unusable),
            ("crate", NameProblem::Unusable),
        ] {
            assert_eq!(check(bad), Err(why), "{bad:?}");
        }
    }
}
