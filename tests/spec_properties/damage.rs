//! The fuzzer's inputs: real specs (Rex and the corpus) damaged at the byte, token,
//! line and entry level, and soups of RON tokens.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::LazyLock;

use embodied::spec::span::{self, SKind, SNode};
use proptest::prelude::*;

/// The real specs the damage starts from: Rex and every file of the corpus.
pub(crate) static SEEDS: LazyLock<Vec<(PathBuf, String)>> = LazyLock::new(|| {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut paths = vec![root.join("specs/rex.ron")];
    for dir in ["tests/specs/valid", "tests/specs/invalid"] {
        let mut files: Vec<PathBuf> = std::fs::read_dir(root.join(dir))
            .expect("corpus directory")
            .map(|e| e.expect("entry").path())
            .filter(|p| p.extension().is_some_and(|x| x == "ron"))
            // The case that spends the whole proof budget (a pigeonhole): damaged,
            // it would spend it again in thousands of cases.
            .filter(|p| !p.ends_with("proof_budget.ron"))
            .collect();
        files.sort();
        paths.extend(files);
    }
    paths
        .into_iter()
        .map(|p| {
            // `encoding.ron` is not UTF-8 on purpose: damage its lossy text.
            let text = String::from_utf8_lossy(&std::fs::read(&p).expect("readable")).into_owned();
            (p, text)
        })
        .collect()
});

/// What damage inserts: RON punctuation, pieces of condition syntax, odd numbers and
/// strings, comment and attribute openers, non-ASCII.
#[rustfmt::skip]
pub(crate) const PUNCTUATION: &[&str] = &[
    "(", ")", "[", "]", "{", "}", ",", ":", "::", "\"", "'", "#", "!", "#![", "r#\"",
    "\"#", "//", "/*", "*/", "\n", "\\", "\\u{0}", "&&", "||", "!(", "é", "\u{0}",
    "\u{feff}", "0", "-0.0", "1e999", "NaN", "-inf", "18446744073709551616", "Some(",
    "None", "()", "[]", "true", "false", "x", "_", "\"\"", "\"c1\"", "\"a.b.c\"",
    "Queue(0)", "Sample", "Output(\"c1\")", "Exclusive([\"a\"])",
    "Implies(\"a\", \"a\")",
];

/// Tokens of RON text as byte ranges (whitespace runs and comments included, so the
/// tokens tile the text): strings, words (identifiers and numbers), single characters.
pub(crate) fn tokens(text: &str) -> Vec<Range<usize>> {
    let b = text.as_bytes();
    let mut out = Vec::new();
    let mut i = 0;
    while i < b.len() {
        let start = i;
        let word = |c: u8| c.is_ascii_alphanumeric() || c == b'_' || c == b'.';
        if b[i].is_ascii_whitespace() {
            while i < b.len() && b[i].is_ascii_whitespace() {
                i += 1;
            }
        } else if b[i..].starts_with(b"//") {
            while i < b.len() && b[i] != b'\n' {
                i += 1;
            }
        } else if b[i..].starts_with(b"/*") {
            i = text[i + 2..].find("*/").map_or(b.len(), |k| i + 2 + k + 2);
        } else if b[i] == b'"' {
            i += 1;
            while i < b.len() && b[i] != b'"' {
                i += if b[i] == b'\\' { 2 } else { 1 };
            }
            i = (i + 1).min(b.len());
        } else if word(b[i]) {
            while i < b.len() && word(b[i]) {
                i += 1;
            }
        } else {
            i += text[i..].chars().next().map_or(1, char::len_utf8);
        }
        while !text.is_char_boundary(i) {
            i += 1;
        }
        out.push(start..i);
    }
    out
}

/// Byte ranges of the lines of `text`, newlines included.
pub(crate) fn lines(text: &str) -> Vec<Range<usize>> {
    let mut out = Vec::new();
    let mut start = 0;
    for line in text.split_inclusive('\n') {
        out.push(start..start + line.len());
        start += line.len();
    }
    out
}

/// Byte ranges of the entries of `text`'s RON structure, outermost first: list items,
/// and (if `fields`) struct fields `key: value`. None if the span parser gives up.
pub(crate) fn entries(text: &str, fields: bool) -> Vec<Range<usize>> {
    fn walk(node: &SNode, fields: bool, out: &mut Vec<Range<usize>>) {
        match &node.kind {
            SKind::Struct { fields: fs, .. } => {
                for f in fs {
                    if fields {
                        out.push(f.key_span.start..f.value.span.end);
                    }
                    walk(&f.value, fields, out);
                }
            }
            SKind::List(items) => {
                for item in items {
                    out.push(item.span.clone());
                    walk(item, fields, out);
                }
            }
            SKind::Tuple { items, .. } => {
                for item in items {
                    walk(item, fields, out);
                }
            }
            SKind::Map(entries) => {
                for (_, v) in entries {
                    walk(v, fields, out);
                }
            }
            SKind::Str { .. } | SKind::Atom => {}
        }
    }
    let mut out = Vec::new();
    if let Some(root) = span::parse(text) {
        walk(&root, fields, &mut out);
    }
    out
}

/// The largest character boundary of `text` at or below `i`.
pub(crate) fn floor(text: &str, i: usize) -> usize {
    let mut i = i.min(text.len());
    while !text.is_char_boundary(i) {
        i -= 1;
    }
    i
}

/// Replace range `a` by the text of `b` and `b` by that of `a` (`a` before `b`, apart).
pub(crate) fn swap(text: &mut String, a: Range<usize>, b: Range<usize>) {
    if a.end > b.start {
        return;
    }
    let (ta, tb) = (text[a.clone()].to_owned(), text[b.clone()].to_owned());
    text.replace_range(b, &ta);
    text.replace_range(a, &tb);
}

/// One piece of damage. Indices are taken modulo what there is to pick from, so
/// every edit applies to any text.
#[derive(Clone, Debug)]
pub(crate) enum Damage {
    /// Delete `len` bytes at `at`.
    DeleteBytes { at: usize, len: usize },
    /// Duplicate `len` bytes at `at`.
    DuplicateBytes { at: usize, len: usize },
    /// Swap `len` bytes at `at` with `len` bytes at `other`.
    SwapBytes { at: usize, other: usize, len: usize },
    /// Insert a piece of punctuation at byte `at`.
    InsertAtByte { at: usize, what: &'static str },
    /// Delete a token.
    DeleteToken(usize),
    /// Duplicate a token.
    DuplicateToken(usize),
    /// Swap two tokens.
    SwapTokens(usize, usize),
    /// Replace a token by a copy of another (a name by another name, a string by
    /// another string: damage that still parses and reaches the checker).
    CopyToken { to: usize, from: usize },
    /// Insert a piece of punctuation before a token.
    InsertBeforeToken { at: usize, what: &'static str },
    /// Delete a line.
    DeleteLine(usize),
    /// Duplicate a line (usually an entry of a list: a second definition or writer).
    DuplicateLine(usize),
    /// Swap two lines.
    SwapLines(usize, usize),
    /// Delete an entry (list item or struct field) and its comma.
    DeleteEntry(usize),
    /// Duplicate a list item (a second definition, arc, link...).
    DuplicateItem(usize),
    /// Swap two list items (when neither contains the other): a buffer moves to
    /// another group, an arc to another FSM...
    SwapItems(usize, usize),
}

pub(crate) fn damage() -> impl Strategy<Value = Damage> {
    let punct = || prop::sample::select(PUNCTUATION);
    // Weighted towards damage that keeps the text RON, so that much of it gets past
    // the parser into the checker and the diagrams.
    prop_oneof![
        1 => (any::<usize>(), 0usize..64).prop_map(|(at, len)| Damage::DeleteBytes { at, len }),
        1 => (any::<usize>(), 1usize..64).prop_map(|(at, len)| Damage::DuplicateBytes { at, len }),
        1 => (any::<usize>(), any::<usize>(), 1usize..32)
            .prop_map(|(at, other, len)| Damage::SwapBytes { at, other, len }),
        1 => (any::<usize>(), punct()).prop_map(|(at, what)| Damage::InsertAtByte { at, what }),
        1 => any::<usize>().prop_map(Damage::DeleteToken),
        1 => any::<usize>().prop_map(Damage::DuplicateToken),
        1 => (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Damage::SwapTokens(a, b)),
        4 => (any::<usize>(), any::<usize>()).prop_map(|(to, from)| Damage::CopyToken { to, from }),
        1 => (any::<usize>(), punct()).prop_map(|(at, what)| Damage::InsertBeforeToken { at, what }),
        1 => any::<usize>().prop_map(Damage::DeleteLine),
        1 => any::<usize>().prop_map(Damage::DuplicateLine),
        1 => (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Damage::SwapLines(a, b)),
        3 => any::<usize>().prop_map(Damage::DeleteEntry),
        3 => any::<usize>().prop_map(Damage::DuplicateItem),
        3 => (any::<usize>(), any::<usize>()).prop_map(|(a, b)| Damage::SwapItems(a, b)),
    ]
}

/// The range `i` selects among `v` (none of an empty list).
fn pick(v: &[Range<usize>], i: usize) -> Option<Range<usize>> {
    (!v.is_empty()).then(|| v[i % v.len()].clone())
}

/// Two ranges, the earlier first.
fn ordered(a: Range<usize>, b: Range<usize>) -> (Range<usize>, Range<usize>) {
    if a.start <= b.start { (a, b) } else { (b, a) }
}

/// Apply `d` to `text`.
pub(crate) fn apply_damage(text: &mut String, d: &Damage) {
    match *d {
        Damage::DeleteBytes { at, len } => {
            let start = floor(text, at % (text.len() + 1));
            let end = floor(text, start + len);
            text.replace_range(start..end, "");
        }
        Damage::DuplicateBytes { at, len } => {
            let start = floor(text, at % (text.len() + 1));
            let end = floor(text, start + len);
            let copy = text[start..end].to_owned();
            text.insert_str(end, &copy);
        }
        Damage::SwapBytes { at, other, len } => {
            let r = |i: usize| {
                let start = floor(text, i % (text.len() + 1));
                start..floor(text, start + len)
            };
            let (a, b) = ordered(r(at), r(other));
            swap(text, a, b);
        }
        Damage::InsertAtByte { at, what } => {
            let at = floor(text, at % (text.len() + 1));
            text.insert_str(at, what);
        }
        Damage::DeleteToken(i) => {
            if let Some(t) = pick(&tokens(text), i) {
                text.replace_range(t, "");
            }
        }
        Damage::DuplicateToken(i) => {
            if let Some(t) = pick(&tokens(text), i) {
                let copy = text[t.clone()].to_owned();
                text.insert_str(t.end, &copy);
            }
        }
        Damage::SwapTokens(i, j) => {
            let ts = tokens(text);
            if let (Some(a), Some(b)) = (pick(&ts, i), pick(&ts, j)) {
                let (a, b) = ordered(a, b);
                swap(text, a, b);
            }
        }
        Damage::CopyToken { to, from } => copy_token(text, to, from),
        Damage::InsertBeforeToken { at, what } => {
            if let Some(t) = pick(&tokens(text), at) {
                text.insert_str(t.start, what);
            }
        }
        Damage::DeleteLine(i) => {
            if let Some(l) = pick(&lines(text), i) {
                text.replace_range(l, "");
            }
        }
        Damage::DuplicateLine(i) => {
            if let Some(l) = pick(&lines(text), i) {
                let copy = text[l.clone()].to_owned();
                text.insert_str(l.start, &copy);
            }
        }
        Damage::DeleteEntry(i) => delete_entry(text, i),
        Damage::DuplicateItem(i) => {
            if let Some(e) = pick(&entries(text, false), i) {
                let copy = format!("{}, ", &text[e.clone()]);
                text.insert_str(e.start, &copy);
            }
        }
        Damage::SwapItems(i, j) => {
            let es = entries(text, false);
            if let (Some(a), Some(b)) = (pick(&es, i), pick(&es, j)) {
                let (a, b) = ordered(a, b);
                swap(text, a, b);
            }
        }
        Damage::SwapLines(i, j) => swap_lines(text, i, j),
    }
}

/// Token `to` replaced by a copy of token `from` among the tokens of the same
/// first byte (strings for strings, words for words), so that the result often
/// still parses.
fn copy_token(text: &mut String, to: usize, from: usize) {
    let ts = tokens(text);
    if let Some(t) = pick(&ts, to) {
        let first = text.as_bytes()[t.start];
        let alike: Vec<Range<usize>> = ts
            .into_iter()
            .filter(|u| {
                let f = text.as_bytes()[u.start];
                f == first || (f.is_ascii_alphanumeric() && first.is_ascii_alphanumeric())
            })
            .collect();
        if let Some(u) = pick(&alike, from) {
            let copy = text[u].to_owned();
            text.replace_range(t, &copy);
        }
    }
}

/// Entry `i` deleted, with the comma after it.
fn delete_entry(text: &mut String, i: usize) {
    if let Some(e) = pick(&entries(text, true), i) {
        let rest = &text[e.end..];
        let blank = rest.len() - rest.trim_start().len();
        let end = if rest.trim_start().starts_with(',') {
            e.end + blank + 1
        } else {
            e.end
        };
        text.replace_range(e.start..end, "");
    }
}

/// Lines `i` and `j` swapped, if both end with their newline.
fn swap_lines(text: &mut String, i: usize, j: usize) {
    let ls = lines(text);
    if let (Some(a), Some(b)) = (pick(&ls, i), pick(&ls, j)) {
        let (a, b) = ordered(a, b);
        // The last line may lack its newline: keep lines apart.
        let (ta, tb) = (text[a.clone()].to_owned(), text[b.clone()].to_owned());
        if ta.ends_with('\n') && tb.ends_with('\n') {
            swap(text, a, b);
        }
    }
}

/// A damaged copy of one of the seeds. Its `Debug` (what proptest prints for a failing
/// case) names the seed file and the damage, which together give the text.
#[derive(Clone)]
pub(crate) struct Damaged {
    pub(crate) seed: usize,
    pub(crate) edits: Vec<Damage>,
    pub(crate) text: String,
}

impl std::fmt::Debug for Damaged {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Damaged")
            .field("seed", &SEEDS[self.seed].0)
            .field("edits", &self.edits)
            .finish_non_exhaustive()
    }
}

pub(crate) fn damaged_spec() -> impl Strategy<Value = Damaged> {
    // Mostly light damage (which often still loads), sometimes heavy.
    let edits = prop_oneof![
        3 => prop::collection::vec(damage(), 1..3),
        1 => prop::collection::vec(damage(), 3..10),
    ];
    (0..SEEDS.len(), edits).prop_map(|(seed, edits)| {
        let mut text = SEEDS[seed].1.clone();
        for d in &edits {
            apply_damage(&mut text, d);
        }
        Damaged { seed, edits, text }
    })
}

/// RON vocabulary for token soups: punctuation and the schema's own words.
#[rustfmt::skip]
pub(crate) const VOCABULARY: &[&str] = &[
    "(", ")", "[", "]", "{", "}", ",", ":", " ", "\n", "\"", "r#\"", "\"#", "'a'",
    "b\"", "//", "/*", "*/", "#![enable(implicit_some)]", "\\", "é", "name", "doc",
    "agents", "subsystems", "devices", "kind", "period_ms", "memory", "inputs",
    "outputs", "peer", "buffers", "type", "predicates", "reads", "writes", "relations",
    "functions", "target", "behaviours", "terminal", "fsm", "initial", "arcs", "from",
    "to", "when", "finals", "links", "policy", "deployments", "hosts", "processes",
    "runs", "omit", "Control", "VirtualEffector", "VirtualReceptor", "Effector",
    "Receptor", "While", "Repeat", "Memory", "Common", "Output", "Sample", "Queue",
    "Exclusive", "Implies", "Some", "None", "true", "false", "\"c1\"", "\"e1\"",
    "\"a1\"", "\"c1.e1.x\"", "\"p && !q\"", "\"f64\"", "\"\"", "0", "1", "-1", "10.0",
    "0.0", "1e309", "NaN",
];

pub(crate) fn token_soup() -> impl Strategy<Value = String> {
    prop::collection::vec(prop::sample::select(VOCABULARY), 0..300).prop_map(|v| v.concat())
}
