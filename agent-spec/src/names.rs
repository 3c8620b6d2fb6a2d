//! How spec names become Rust names, shared by the checker, `agent!` (which
//! generates the code) and `embodied new` (which writes code that uses it), so
//! that all three agree on what is valid. The rule for any name is agent-core's
//! ([`check`], which the runtime applies too); component names have one more, as
//! they become type names ([`component_problem`]).

pub use agent_core::names::{KEYWORDS, NameProblem, UNUSABLE, check, is_identifier};

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

/// The types every module `agent!` generates has: a component named after one
/// would clash with it.
pub const MODULE_TYPES: [&str; 4] = ["Memory", "Input", "Output", "Functions"];

/// Why `name` cannot name a component (a subsystem or device), if it cannot:
/// beyond [`check`], its type name (`c1` -> `C1`) must be a Rust type name, and
/// not one of the types of its module.
pub fn component_problem(name: &str) -> Option<String> {
    if let Err(p) = check(name) {
        return Some(p.to_string());
    }
    let t = type_name(name);
    if !has_type_name(name) {
        return Some(format!("makes no Rust type name (`{t}`)"));
    }
    if MODULE_TYPES.contains(&t.as_str()) {
        return Some(format!(
            "makes the type name `{t}`, which the module `agent!` generates for it already has"
        ));
    }
    None
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
        assert_eq!(component_problem("c1"), None);
        for bad in ["__", "_1", "memory", "input", "self", ""] {
            assert!(component_problem(bad).is_some(), "{bad}");
        }
    }
}

/// The name among `known` closest to `name`, if one is close enough to be a typo
/// (Jaro-Winkler similarity of at least 0.8, or the same name but for case): for
/// "did you mean" hints.
pub fn did_you_mean<'a>(name: &str, known: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    known
        .into_iter()
        .filter(|k| *k != name)
        .map(|k| {
            let score = if k.eq_ignore_ascii_case(name) {
                1.0
            } else {
                strsim::jaro_winkler(name, k)
            };
            (score, k)
        })
        .filter(|(score, _)| *score >= 0.8)
        .max_by(|a, b| a.0.total_cmp(&b.0).then_with(|| b.1.cmp(a.1)))
        .map(|(_, k)| k)
}

#[cfg(test)]
mod did_you_mean_tests {
    use super::did_you_mean;

    #[test]
    fn a_typo_finds_its_name_and_nonsense_finds_none() {
        let known = ["c1", "e11", "r11", "E1", "desired_plan", "q_est"];
        assert_eq!(did_you_mean("desired_plans", known), Some("desired_plan"));
        assert_eq!(did_you_mean("e1", known), Some("E1"));
        assert_eq!(did_you_mean("qest", known), Some("q_est"));
        assert_eq!(did_you_mean("zzzz", known), None);
        assert_eq!(did_you_mean("c1", known), None, "not itself");
    }
}
