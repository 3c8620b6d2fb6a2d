//! The crate's layout keeps what `ARCHITECTURE.md` says of it:
//!
//! * the algorithms (`src/algorithms/`) use nothing of the framework (`embodied`,
//!   `agent_core`, `agent_spec`), of agent a1 (`crate::a1`) or of the simulated world
//!   (`crate::world`), except the platform model (`crate::world::model`: parameters
//!   and the reduced model, pure math);
//! * no source file is longer than 800 lines.
//!
//! Both are read from the sources as text: comments are skipped, paths are found
//! wherever they stand (`use` lines, grouped imports, paths in expressions), and a
//! chain of `super::` that climbs out of `algorithms` counts as a path from the crate
//! root.

use std::fs;
use std::path::{Path, PathBuf};

/// The longest a source file may be.
const MAX_LINES: usize = 800;

/// Crates the algorithms must not name.
const FRAMEWORK: [&str; 3] = ["embodied", "agent_core", "agent_spec"];

fn src() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("src")
}

/// Every `.rs` file below `dir`, sorted.
fn rust_files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let path = entry
                .unwrap_or_else(|e| panic!("{}: {e}", d.display()))
                .path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// `path` relative to the crate, for messages.
fn shown(path: &Path) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    path.strip_prefix(root)
        .unwrap_or(path)
        .display()
        .to_string()
}

/// The line without its `//` comment (doc comments included). A `//` inside a
/// string literal cuts the line there too, which can only hide what follows it; the
/// algorithms have no such string.
fn code(line: &str) -> &str {
    line.find("//").map_or(line, |i| &line[..i])
}

/// The code of `text` (comments removed, lines kept) and the byte offset at which
/// each line starts in it.
fn code_of(text: &str) -> (String, Vec<usize>) {
    let mut out = String::with_capacity(text.len());
    let mut starts = Vec::new();
    for line in text.lines() {
        starts.push(out.len());
        out.push_str(code(line));
        out.push('\n');
    }
    (out, starts)
}

/// The depth of the module a file under `src/algorithms` defines: `algorithms` is 1,
/// `algorithms::mpc` 2 (`mpc/mod.rs`), `algorithms::mpc::linalg` 3, ...
fn module_depth(file: &Path) -> usize {
    let rel = file
        .strip_prefix(src())
        .unwrap_or_else(|_| panic!("{} is not under src/", file.display()));
    let parts = rel.components().count();
    if rel.file_name().is_some_and(|n| n == "mod.rs") {
        parts - 1
    } else {
        parts
    }
}

/// The first segments of the paths that follow `crate::` at `rest` (one for
/// `crate::a::b`, each item's for a group `crate::{a::b, c}`, over as many lines as
/// the group takes).
fn first_segments(rest: &str) -> Vec<String> {
    let ident = |s: &str| {
        s.trim_start()
            .chars()
            .take_while(|c| c.is_alphanumeric() || *c == '_')
            .collect::<String>()
    };
    let Some(group) = rest.trim_start().strip_prefix('{') else {
        return vec![path_of(rest)];
    };
    // Top-level items of the group.
    let mut items = Vec::new();
    let mut depth = 0usize;
    let mut start = 0;
    for (i, c) in group.char_indices() {
        match c {
            '{' => depth += 1,
            '}' if depth == 0 => {
                items.push(&group[start..i]);
                start = group.len();
                break;
            }
            '}' => depth -= 1,
            ',' if depth == 0 => {
                items.push(&group[start..i]);
                start = i + 1;
            }
            _ => {}
        }
    }
    items.push(&group[start.min(group.len())..]);
    items
        .into_iter()
        .filter(|item| !ident(item).is_empty())
        .map(path_of)
        .collect()
}

/// `a1`, `world::model`, `world::camera`...: the first segment, and the second for
/// `world` (the one place the algorithms may use).
fn path_of(rest: &str) -> String {
    let segs: Vec<&str> = rest
        .trim_start()
        .split("::")
        .map(|s| {
            let end = s
                .find(|c: char| !(c.is_alphanumeric() || c == '_'))
                .unwrap_or(s.len());
            &s[..end]
        })
        .take(2)
        .collect();
    match segs.as_slice() {
        ["world", second, ..] => format!("world::{second}"),
        [first, ..] => (*first).to_owned(),
        [] => String::new(),
    }
}

/// Whether a crate-root path (its first segments, as [`path_of`] gives them) is
/// forbidden to the algorithms.
fn forbidden(path: &str) -> bool {
    path == "a1" || (path.starts_with("world") && path != "world::model")
}

/// What `code` (comments removed) of a file at `depth` names that the algorithms
/// must not: each with its byte offset in `code`.
fn violations(code: &str, depth: usize) -> Vec<(usize, String)> {
    let mut found = Vec::new();
    for name in FRAMEWORK {
        let mut from = 0;
        while let Some(i) = code[from..].find(name).map(|i| i + from) {
            let before = code[..i].chars().next_back();
            let after = code[i + name.len()..].chars().next();
            let boundary = |c: Option<char>| !c.is_some_and(|c| c.is_alphanumeric() || c == '_');
            if boundary(before) && boundary(after) {
                found.push((i, format!("the framework (`{name}`)")));
            }
            from = i + name.len();
        }
    }
    for (i, _) in code.match_indices("crate::") {
        let rest = &code[i + "crate::".len()..];
        for path in first_segments(rest) {
            if forbidden(&path) {
                found.push((i, format!("`crate::{path}`")));
            }
        }
    }
    // `super::super::…` that climbs to the crate root names a root module too.
    for (i, _) in code.match_indices("super::") {
        if code[..i].ends_with("super::") {
            continue; // counted from the first `super` of the chain
        }
        let mut rest = &code[i..];
        let mut climbs = 0;
        while let Some(r) = rest.strip_prefix("super::") {
            climbs += 1;
            rest = r;
        }
        if climbs >= depth {
            let path = path_of(rest);
            if forbidden(&path) {
                found.push((
                    i,
                    format!(
                        "`{}{path}` (a `super::` chain that climbs out of `algorithms`)",
                        "super::".repeat(climbs)
                    ),
                ));
            }
        }
    }
    found
}

#[test]
fn the_algorithms_import_nothing_of_the_framework_of_a1_or_of_the_world() {
    let dir = src().join("algorithms");
    let files = rust_files(&dir);
    assert!(
        files.len() > 10,
        "{}: expected the algorithms' sources, found {} files",
        shown(&dir),
        files.len()
    );
    let mut problems = Vec::new();
    for file in &files {
        let text = fs::read_to_string(file).unwrap();
        let (code, starts) = code_of(&text);
        let lines: Vec<&str> = text.lines().collect();
        for (at, what) in violations(&code, module_depth(file)) {
            let n = starts.partition_point(|&s| s <= at) - 1;
            problems.push(format!(
                "{}:{}: uses {what}: {}",
                shown(file),
                n + 1,
                lines[n].trim()
            ));
        }
    }
    assert!(
        problems.is_empty(),
        "the algorithms must not use the framework, agent a1 or the simulated world \
         (except `crate::world::model`); move the glue to `a1` or `world`, or give the \
         algorithm a plain type of its own:\n{}",
        problems.join("\n")
    );
}

#[test]
fn no_source_file_is_longer_than_800_lines() {
    let mut long = Vec::new();
    for file in rust_files(&src()) {
        let lines = fs::read_to_string(&file).unwrap().lines().count();
        if lines > MAX_LINES {
            long.push(format!("{}:{lines}: {lines} lines", shown(&file)));
        }
    }
    assert!(
        long.is_empty(),
        "source files longer than {MAX_LINES} lines (split them by responsibility; unit \
         tests go to a `tests.rs` beside the module):\n{}",
        long.join("\n")
    );
}

#[test]
fn the_checks_see_what_they_look_for() {
    // Each kind of path the first test must catch, and what it must let pass.
    let caught = [
        ("use embodied::{Group, In};", 2),
        ("fn f(x: &agent_core::Time) {}", 2),
        ("use crate::a1::payload::State;", 2),
        ("use crate::world::camera::kitti::Pose34;", 2),
        ("use crate::{a1::payload::State, world::model::Reduced};", 2),
        ("let s: crate::world::devices::Truth = t;", 3),
        ("use super::super::a1::payload::State;", 2),
        ("use super::super::super::world::camera::Renderer;", 3),
        (
            "use crate::{\n    algorithms::rng::Rng,\n    a1::map::Map,\n};",
            2,
        ),
    ];
    for (line, depth) in caught {
        assert!(
            !violations(line, depth).is_empty(),
            "the layout check misses `{line}` at depth {depth}"
        );
    }
    let passed = [
        ("use crate::world::model::{Reduced, SlipParams};", 2),
        (
            "use crate::{algorithms::rng::Rng, world::model::State5};",
            3,
        ),
        ("use super::super::geometry::wrap;", 3),
        ("use super::linalg::Mat;", 3),
        ("let embodied_energy = 1.0;", 2),
        (code("let x = 1; // see embodied::Group"), 2),
    ];
    for (line, depth) in passed {
        assert!(
            violations(line, depth).is_empty(),
            "the layout check refuses `{line}` at depth {depth}: {:?}",
            violations(line, depth)
        );
    }
}
