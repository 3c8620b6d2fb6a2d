//! The crate's layout keeps what `ARCHITECTURE.md` says of it. Its folders import
//! downward only, as the paper stacks them:
//!
//! 1. `math` (linear solves, geometry, the random generator) and `config` (RON
//!    files): nothing of the crate;
//! 2. `model` (the skid-steer platform), then `payload` (what the buffers carry)
//!    and `mission` (a2's plans) over it;
//! 3. `algorithms` (NMPC, MHE, planners, visual odometry) over `model`, `math` and
//!    `config` only, and nothing of the framework (`embodied`, `agent_core`,
//!    `agent_spec`): they are plain Rust an agent calls;
//! 4. `world` (the plant, devices, camera, partner agents) and `a1` (c1, e11,
//!    r11, the map) over those, neither importing the other;
//! 5. the composition root (`system`, `run`, `report`, `record`, `ros2`, `app`,
//!    `soak`, `main.rs`) over everything.
//!
//! Unit tests (`tests.rs` files and what follows `#[cfg(test)]`) may use any
//! layer, as the crate's integration tests do. No source file is longer than 800
//! lines.
//!
//! Both are read from the sources as text: comments are skipped, paths are found
//! wherever they stand (`use` lines, grouped imports, paths in expressions), and a
//! chain of `super::` that climbs out of a layer counts as a path from the crate
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

/// The first segment of the path at `rest` (`a1` for `a1::map::Map`).
fn path_of(rest: &str) -> String {
    let rest = rest.trim_start();
    let end = rest
        .find(|c: char| !(c.is_alphanumeric() || c == '_'))
        .unwrap_or(rest.len());
    rest[..end].to_owned()
}

/// What the world and the agent both stand on: the algorithms and every layer
/// below them (they do not use each other).
const UNDER_WORLD_AND_AGENT: &[&str] = &[
    "algorithms",
    "mission",
    "payload",
    "model",
    "math",
    "config",
];

/// The layers: each top-level module of the crate and the modules it may use.
/// A module not listed is the composition root, which may use anything.
const LAYERS: [(&str, &[&str]); 8] = [
    ("math", &[]),
    ("config", &[]),
    ("model", &["math", "config"]),
    ("payload", &["model", "math", "config"]),
    ("mission", &["payload", "model", "math", "config"]),
    ("algorithms", &["payload", "model", "math", "config"]),
    ("world", UNDER_WORLD_AND_AGENT),
    ("a1", UNDER_WORLD_AND_AGENT),
];

/// What `layer` may use of the crate.
fn allowed(layer: &str) -> &'static [&'static str] {
    LAYERS
        .iter()
        .find(|(name, _)| *name == layer)
        .map_or(&[], |(_, below)| *below)
}

/// What `code` (comments removed) of a file at `depth` in module `layer` names
/// outside `allowed` (and the framework, unless `framework_allowed`): each with
/// its byte offset in `code`.
fn violations(
    code: &str,
    depth: usize,
    layer: &str,
    allowed: &[&str],
    framework_allowed: bool,
) -> Vec<(usize, String)> {
    let forbidden = |path: &str| path != layer && !allowed.contains(&path);
    let mut found = Vec::new();
    for name in FRAMEWORK.iter().filter(|_| !framework_allowed) {
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
                        "`{}{path}` (a `super::` chain that climbs out of `{layer}`)",
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
        for (at, what) in violations(
            &code,
            module_depth(file),
            "algorithms",
            allowed("algorithms"),
            false,
        ) {
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
        "the algorithms must not use the framework, agent a1, the payloads or the simulated \
         world (only `crate::model`, `math`, `config`); move the glue to `a1` or `world`, \
         or give the algorithm a plain type of its own:\n{}",
        problems.join("\n")
    );
}

/// The code of a file without its unit tests (what follows `#[cfg(test)]`; a
/// `tests.rs` file is all tests).
fn without_tests(file: &Path, code: &str) -> String {
    let name = file.file_name().map(|n| n.to_string_lossy().into_owned());
    if name.is_some_and(|n| n == "tests.rs" || n.ends_with("_tests.rs")) {
        return String::new();
    }
    code.find("#[cfg(test)]")
        .map_or(code, |i| &code[..i])
        .to_owned()
}

#[test]
fn every_layer_imports_only_the_layers_below_it() {
    let mut problems = Vec::new();
    let mut seen = Vec::new();
    for file in rust_files(&src()) {
        let rel = file.strip_prefix(src()).unwrap();
        let top = rel
            .components()
            .next()
            .map(|c| {
                c.as_os_str()
                    .to_string_lossy()
                    .trim_end_matches(".rs")
                    .to_owned()
            })
            .unwrap_or_default();
        let Some((layer, below)) = LAYERS.iter().find(|(name, _)| *name == top) else {
            continue; // the composition root
        };
        seen.push(*layer);
        let text = fs::read_to_string(&file).unwrap();
        let (code, starts) = code_of(&text);
        let code = without_tests(&file, &code);
        let lines: Vec<&str> = text.lines().collect();
        for (at, what) in violations(&code, module_depth(&file), layer, below, true) {
            let n = starts.partition_point(|&s| s <= at) - 1;
            problems.push(format!(
                "{}:{}: `{layer}` uses {what}: {}",
                shown(&file),
                n + 1,
                lines[n].trim()
            ));
        }
    }
    for (layer, _) in LAYERS {
        assert!(seen.contains(&layer), "no source file of layer `{layer}`");
    }
    assert!(
        problems.is_empty(),
        "a layer may use only the layers below it (see this file's header); move the \
         code that joins two layers up to the composition root (`system`):\n{}",
        problems.join("\n")
    );
}

#[test]
fn the_layer_check_sees_what_it_looks_for() {
    let below = allowed("a1");
    for (line, depth) in [
        ("use crate::world::camera::SceneConfig;", 2),
        ("use crate::system::RexConfig;", 2),
        ("use super::super::world::devices::Truth;", 2),
    ] {
        assert!(
            !violations(line, depth, "a1", below, true).is_empty(),
            "the layer check lets a1 `{line}`"
        );
    }
    for (line, depth) in [
        ("use crate::payload::Plan;", 2),
        ("use crate::{model::Friction, math::geometry::wrap};", 3),
        ("use super::map::Map;", 2),
        ("use embodied::{In, Out};", 2),
    ] {
        assert!(
            violations(line, depth, "a1", below, true).is_empty(),
            "the layer check refuses a1 `{line}`"
        );
    }
    let test_file = Path::new("src/a1/c1/tests.rs");
    assert_eq!(without_tests(test_file, "use crate::world::x;"), "");
    let module = "use crate::payload::Plan;\n#[cfg(test)]\nmod tests { use crate::world::x; }";
    assert_eq!(
        without_tests(Path::new("src/a1/r11.rs"), module),
        "use crate::payload::Plan;\n"
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
        ("use crate::system::RexConfig;", 2),
        ("use crate::world::camera::kitti::Pose34;", 2),
        ("use crate::{a1::payload::State, world::model::Reduced};", 2),
        ("let s: crate::world::devices::Truth = t;", 3),
        ("use super::super::a1::payload::State;", 2),
        ("use super::super::super::world::camera::Renderer;", 3),
        (
            "use crate::{\n    math::rng::Rng,\n    a1::map::Map,\n};",
            2,
        ),
        ("use crate::mission::Mission;", 2),
    ];
    for (line, depth) in caught {
        assert!(
            !violations(line, depth, "algorithms", allowed("algorithms"), false).is_empty(),
            "the layout check misses `{line}` at depth {depth}"
        );
    }
    let passed = [
        ("use crate::model::{Reduced, SlipParams};", 2),
        ("use crate::payload::State;", 2),
        ("use crate::{math::rng::Rng, model::State5};", 3),
        ("use super::super::geometry::wrap;", 3),
        ("use super::linalg::Mat;", 3),
        ("let embodied_energy = 1.0;", 2),
        (code("let x = 1; // see embodied::Group"), 2),
    ];
    for (line, depth) in passed {
        assert!(
            violations(line, depth, "algorithms", allowed("algorithms"), false).is_empty(),
            "the layout check refuses `{line}` at depth {depth}: {:?}",
            violations(line, depth, "algorithms", allowed("algorithms"), false)
        );
    }
}
