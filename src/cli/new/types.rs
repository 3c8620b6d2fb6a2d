//! The types a spec names that need a placeholder in the new crate: whatever is
//! not a Rust standard type (nor a path, which the user imports).

use std::collections::BTreeMap;

use embodied::spec::names::KEYWORDS;

/// Standard types a spec may name without a placeholder (`src/types.rs` imports
/// those outside the prelude).
const KNOWN: &[&str] = &[
    "bool",
    "char",
    "str",
    "u8",
    "u16",
    "u32",
    "u64",
    "u128",
    "usize",
    "i8",
    "i16",
    "i32",
    "i64",
    "i128",
    "isize",
    "f32",
    "f64",
    "String",
    "Option",
    "Vec",
    "VecDeque",
    "HashMap",
    "HashSet",
    "BTreeMap",
    "BTreeSet",
    "BinaryHeap",
    "Box",
    "Result",
    "Arc",
    "Rc",
    "Cow",
    "Duration",
];

/// The number of type arguments in the `<...>` that starts `rest`, if it starts one.
fn arity(rest: &str) -> usize {
    if !rest.starts_with('<') {
        return 0;
    }
    let (mut depth, mut commas) = (0i32, 0usize);
    for c in rest.chars() {
        match c {
            '<' | '(' | '[' => depth += 1,
            '>' | ')' | ']' => {
                depth -= 1;
                if depth == 0 {
                    break;
                }
            }
            ',' if depth == 1 => commas += 1,
            _ => {}
        }
    }
    commas + 1
}

/// Adds to `out` the type names in the spec type `ty` that need a placeholder,
/// with their number of type arguments: identifiers that are not standard, not
/// part of a path (`nalgebra::Vector3` is the user's to import) and not lifetimes.
pub(super) fn unknown_types(ty: &str, out: &mut BTreeMap<String, usize>) {
    let bytes = ty.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        if bytes[i].is_ascii_alphabetic() || bytes[i] == b'_' {
            let start = i;
            while i < bytes.len() && (bytes[i].is_ascii_alphanumeric() || bytes[i] == b'_') {
                i += 1;
            }
            let word = &ty[start..i];
            let after_path = ty[..start].ends_with("::");
            let before_path = ty[i..].starts_with("::");
            let lifetime = ty[..start].ends_with('\'');
            if !(after_path
                || before_path
                || lifetime
                || KNOWN.contains(&word)
                || KEYWORDS.contains(&word))
            {
                let n = arity(ty[i..].trim_start());
                let known = out.entry(word.to_owned()).or_insert(n);
                *known = (*known).max(n);
            }
        } else {
            i += 1;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_types_skip_standard_paths_and_lifetimes() {
        let mut out = BTreeMap::new();
        for t in [
            "Option<MapPose>",
            "Vec<(u8, Plan)>",
            "[f64; 4]",
            "nalgebra::Vector3<f64>",
            "HashMap<String, Ack>",
            "&'static str",
            "Grid<(u8, u8), Cell<f64>>",
            "Arc<Duration>",
        ] {
            unknown_types(t, &mut out);
        }
        assert_eq!(out.get("Grid"), Some(&2));
        assert_eq!(out.get("Cell"), Some(&1));
        out.retain(|_, n| *n == 0);
        assert_eq!(
            out.into_keys().collect::<Vec<_>>(),
            ["Ack", "MapPose", "Plan"]
        );
    }
}
