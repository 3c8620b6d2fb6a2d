//! The modules of agent-core import each other without a circle, as
//! `ARCHITECTURE.md` draws them: `error`, `kinds`, `time`, `expr` and `names` are
//! leaves, and every other module only looks down.
//!
//! Read from the sources as text: comments and the unit tests of a file (from its
//! `#[cfg(test)]` module on) are skipped; a path `crate::module::…` names `module`,
//! and a path through the crate root (`crate::Subsystem`, `use crate::{In, Out}`)
//! names the module that `lib.rs` re-exports the item from. `$crate::` paths belong
//! to macros expanded in users' crates and are skipped.

use std::collections::{BTreeMap, BTreeSet};
use std::fs;
use std::path::{Path, PathBuf};

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// The file without comments and without its unit tests.
fn code(text: &str) -> String {
    let mut out = String::new();
    for line in text.lines() {
        if line.trim_start().starts_with("#[cfg(test)]") {
            break;
        }
        let line = line.find("//").map_or(line, |i| &line[..i]);
        out.push_str(line);
        out.push('\n');
    }
    out
}

/// Identifiers at the top level of a `{…}` group that starts at `text[0]`, with the
/// first segment of each nested path (`{a::B, C}` gives `a`, `C`).
fn group_items(text: &str) -> Vec<String> {
    let mut items = Vec::new();
    let mut depth = 0usize;
    let mut current = String::new();
    let mut first_segment_done = false;
    for c in text.chars() {
        match c {
            '{' => {
                depth += 1;
                if depth > 1 {
                    first_segment_done = true;
                }
            }
            '}' => {
                depth = depth.saturating_sub(1);
                if depth == 0 {
                    break;
                }
            }
            ',' if depth == 1 => {
                if !current.is_empty() {
                    items.push(std::mem::take(&mut current));
                }
                first_segment_done = false;
            }
            ':' if depth == 1 => first_segment_done = true,
            c if depth == 1 && !first_segment_done && (c.is_alphanumeric() || c == '_') => {
                current.push(c)
            }
            _ => {}
        }
    }
    if !current.is_empty() {
        items.push(current);
    }
    items
}

/// What each `crate::X` path names: modules directly, items through the root's
/// `pub use module::{…}` re-exports.
fn root_items(lib: &str) -> BTreeMap<String, String> {
    let mut map = BTreeMap::new();
    let lib = code(lib);
    let mut rest = lib.as_str();
    while let Some(i) = rest.find("pub use ") {
        rest = &rest[i + "pub use ".len()..];
        let path: String = rest
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_' || *c == ':')
            .collect();
        let Some(module) = path.split("::").next().filter(|m| !m.is_empty()) else {
            continue;
        };
        if module == "crate" {
            continue;
        }
        let after = &rest[path.len()..];
        if after.starts_with('{') {
            for item in group_items(after) {
                map.insert(item, module.to_owned());
            }
        } else if let Some(item) = path.rsplit("::").next() {
            map.insert(item.to_owned(), module.to_owned());
        }
    }
    map
}

/// The modules a file's code names.
fn uses(
    code: &str,
    modules: &BTreeSet<String>,
    items: &BTreeMap<String, String>,
) -> BTreeSet<String> {
    let mut found = BTreeSet::new();
    let mut rest = code;
    while let Some(i) = rest.find("crate::") {
        let dollar = i > 0 && rest.as_bytes()[i - 1] == b'$';
        let ident_before = i > 0 && {
            let b = rest.as_bytes()[i - 1];
            b.is_ascii_alphanumeric() || b == b'_'
        };
        rest = &rest[i + "crate::".len()..];
        if dollar || ident_before {
            continue;
        }
        let names = if rest.starts_with('{') {
            group_items(rest)
        } else {
            vec![
                rest.chars()
                    .take_while(|c| c.is_alphanumeric() || *c == '_')
                    .collect(),
            ]
        };
        for name in names {
            if modules.contains(&name) {
                found.insert(name);
            } else if let Some(module) = items.get(&name) {
                found.insert(module.clone());
            }
        }
    }
    found
}

/// Module → the modules it uses, for every module of the crate.
fn graph() -> BTreeMap<String, BTreeSet<String>> {
    let root = src();
    let read = |p: &Path| fs::read_to_string(p).unwrap_or_else(|e| panic!("{}: {e}", p.display()));
    let items = root_items(&read(&root.join("lib.rs")));
    let mut files: BTreeMap<String, Vec<PathBuf>> = BTreeMap::new();
    for entry in fs::read_dir(&root).unwrap_or_else(|e| panic!("{e}")) {
        let path = entry.unwrap_or_else(|e| panic!("{e}")).path();
        let name = path
            .file_stem()
            .and_then(|s| s.to_str())
            .unwrap_or_default()
            .to_owned();
        if path.is_dir() {
            for inner in fs::read_dir(&path).unwrap_or_else(|e| panic!("{e}")) {
                let inner = inner.unwrap_or_else(|e| panic!("{e}")).path();
                // A module's own `tests.rs` is its unit tests.
                if inner.file_stem().is_some_and(|s| s != "tests") {
                    files.entry(name.clone()).or_default().push(inner);
                }
            }
        } else if name != "lib" {
            files.entry(name).or_default().push(path);
        }
    }
    let modules: BTreeSet<String> = files.keys().cloned().collect();
    files
        .iter()
        .map(|(module, paths)| {
            let mut used = BTreeSet::new();
            for p in paths {
                used.extend(uses(&code(&read(p)), &modules, &items));
            }
            used.remove(module);
            (module.clone(), used)
        })
        .collect()
}

/// A circle of the graph, if there is one, as the modules along it.
fn find_circle(graph: &BTreeMap<String, BTreeSet<String>>) -> Option<Vec<String>> {
    #[derive(Clone, Copy, PartialEq)]
    enum Mark {
        New,
        Open,
        Done,
    }
    fn visit(
        m: &str,
        graph: &BTreeMap<String, BTreeSet<String>>,
        marks: &mut BTreeMap<String, Mark>,
        path: &mut Vec<String>,
    ) -> Option<Vec<String>> {
        marks.insert(m.to_owned(), Mark::Open);
        path.push(m.to_owned());
        for next in graph.get(m).into_iter().flatten() {
            match marks.get(next.as_str()).copied().unwrap_or(Mark::New) {
                Mark::Open => {
                    let start = path.iter().position(|p| p == next).unwrap_or(0);
                    let mut circle = path[start..].to_vec();
                    circle.push(next.clone());
                    return Some(circle);
                }
                Mark::New => {
                    if let Some(c) = visit(next, graph, marks, path) {
                        return Some(c);
                    }
                }
                Mark::Done => {}
            }
        }
        path.pop();
        marks.insert(m.to_owned(), Mark::Done);
        None
    }
    let mut marks = BTreeMap::new();
    for m in graph.keys() {
        if marks.get(m.as_str()).copied().unwrap_or(Mark::New) == Mark::New
            && let Some(c) = visit(m, graph, &mut marks, &mut Vec::new())
        {
            return Some(c);
        }
    }
    None
}

#[test]
fn the_modules_import_each_other_without_a_circle() {
    let graph = graph();
    assert!(graph.len() > 10, "modules found: {:?}", graph.keys());
    if let Some(circle) = find_circle(&graph) {
        panic!("an import circle: {}", circle.join(" → "));
    }
}

#[test]
fn the_vocabulary_and_the_errors_are_leaves() {
    let graph = graph();
    let allowed: [(&str, &[&str]); 5] = [
        ("kinds", &[]),
        ("time", &[]),
        ("expr", &[]),
        ("names", &[]),
        ("error", &["kinds", "time", "expr", "names"]),
    ];
    for (module, may) in allowed {
        let used = graph
            .get(module)
            .unwrap_or_else(|| panic!("no module `{module}`"));
        let extra: Vec<_> = used.iter().filter(|u| !may.contains(&u.as_str())).collect();
        assert!(extra.is_empty(), "`{module}` uses {extra:?}");
    }
}

#[test]
fn the_reader_finds_a_circle_and_paths_through_the_root() {
    // The test's own reader, on a made-up crate: a circle through a re-export.
    let items = root_items("pub use a::{Alpha, b::Beta};\npub use c::Gamma;\n");
    assert_eq!(items.get("Alpha").map(String::as_str), Some("a"));
    assert_eq!(items.get("b").map(String::as_str), Some("a"));
    assert_eq!(items.get("Gamma").map(String::as_str), Some("c"));
    let modules: BTreeSet<String> = ["a", "c"].map(String::from).into();
    let found = uses(
        &code(
            "use crate::{Gamma, a::X};\n// crate::zzz\nfn f() -> crate::Alpha { $crate::c::y() }",
        ),
        &modules,
        &items,
    );
    assert_eq!(found, modules);
    let graph: BTreeMap<String, BTreeSet<String>> = [
        ("a".to_owned(), ["c".to_owned()].into()),
        ("c".to_owned(), ["a".to_owned()].into()),
    ]
    .into();
    assert_eq!(
        find_circle(&graph),
        Some(vec!["a".to_owned(), "c".to_owned(), "a".to_owned()])
    );
}

#[test]
fn the_link_layer_s_modules_import_each_other_without_a_circle() {
    // `link/thread.rs` (links between threads) and `link/remote.rs` (between
    // processes) shared the counters through each other; they are a leaf now
    // (`link/stats.rs`). Paths `super::x` and `crate::link::x` to a sibling
    // file name it.
    let dir = src().join("link");
    let mut files: Vec<(String, String)> = fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| {
            let path = e.ok()?.path();
            let stem = path.file_stem()?.to_string_lossy().into_owned();
            let is_module = path.extension().is_some_and(|x| x == "rs")
                && stem != "mod"
                && !stem.ends_with("_tests");
            is_module.then(|| (stem, code(&fs::read_to_string(&path).unwrap_or_default())))
        })
        .collect();
    files.sort();
    let names: BTreeSet<String> = files.iter().map(|(n, _)| n.clone()).collect();
    assert!(
        names.contains("thread") && names.contains("remote"),
        "{names:?}"
    );
    let mut graph = BTreeMap::new();
    for (name, code) in &files {
        let mut used = BTreeSet::new();
        for prefix in ["super::", "crate::link::"] {
            for (i, _) in code.match_indices(prefix) {
                let rest = &code[i + prefix.len()..];
                let end = rest
                    .find(|c: char| !(c.is_alphanumeric() || c == '_'))
                    .unwrap_or(rest.len());
                let other = &rest[..end];
                if other != name && names.contains(other) {
                    used.insert(other.to_owned());
                }
            }
        }
        graph.insert(name.clone(), used);
    }
    if let Some(circle) = find_circle(&graph) {
        panic!("an import circle in link/: {}", circle.join(" → "));
    }
}
