//! How spec names become Rust names, shared by `agent!` (which generates the code)
//! and `embodied new` (which writes code that uses it), so that both agree.

/// Rust's keywords, strict and reserved: a spec name among them becomes a raw
/// identifier (`r#type`).
pub const KEYWORDS: &[&str] = &[
    "as", "break", "const", "continue", "crate", "else", "enum", "extern", "false", "fn", "for",
    "if", "impl", "in", "let", "loop", "match", "mod", "move", "mut", "pub", "ref", "return",
    "self", "Self", "static", "struct", "super", "trait", "true", "type", "unsafe", "use", "where",
    "while", "async", "await", "dyn", "abstract", "become", "box", "do", "final", "macro",
    "override", "priv", "typeof", "unsized", "virtual", "yield", "try", "gen",
];

/// A spec name as Rust source: the name itself, or `r#name` for a keyword.
pub fn rust_ident(name: &str) -> String {
    if KEYWORDS.contains(&name) {
        format!("r#{name}")
    } else {
        name.to_owned()
    }
}

/// The type name `agent!` gives a component: `pump_control` -> `PumpControl`,
/// `e11` -> `E11`. Group types add `From`/`To` in front of the peer's.
pub fn type_name(name: &str) -> String {
    name.split('_')
        .filter(|p| !p.is_empty())
        .map(|p| {
            let mut c = p.chars();
            c.next()
                .map(|f| f.to_uppercase().chain(c).collect::<String>())
                .unwrap_or_default()
        })
        .collect()
}

/// Whether [`type_name`] makes a Rust type name of `name` (`__` and `_1` do not).
pub fn has_type_name(name: &str) -> bool {
    type_name(name)
        .chars()
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names() {
        assert_eq!(type_name("pump_control"), "PumpControl");
        assert_eq!(type_name("e11"), "E11");
        assert_eq!(type_name("E1"), "E1");
        assert_eq!(rust_ident("type"), "r#type");
        assert_eq!(rust_ident("A4x4"), "A4x4");
        assert!(has_type_name("c1") && !has_type_name("__") && !has_type_name("_1"));
    }
}
