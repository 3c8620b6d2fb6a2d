//! ARCHITECTURE.md stays true where a test can tell: its crate table names every
//! package of the workspace, its module tables name every module of `agent-core`
//! and of `rex-agent` and no module that is gone, and every file it lists for a
//! module of `rex-agent` exists.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::collections::BTreeSet;
use std::path::Path;

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

fn read(path: &str) -> String {
    std::fs::read_to_string(root().join(path)).unwrap()
}

/// The rows of the table that follows `heading`, as their cells.
fn table(doc: &str, heading: &str) -> Vec<Vec<String>> {
    let start = doc
        .find(heading)
        .unwrap_or_else(|| panic!("ARCHITECTURE.md has no `{heading}`"));
    doc[start..]
        .lines()
        .skip_while(|l| !l.starts_with('|'))
        .take_while(|l| l.starts_with('|'))
        .skip(2)
        .map(|l| {
            l.trim_matches('|')
                .split(" | ")
                .map(|c| c.trim().to_owned())
                .collect()
        })
        .collect()
}

/// The words in backticks of a cell.
fn ticked(cell: &str) -> Vec<&str> {
    cell.split('`').skip(1).step_by(2).collect()
}

/// The modules a crate root declares (`mod x;` and `pub mod x;`, inline
/// modules such as `prelude` included), but its private plumbing (`__private`).
fn declared(lib: &str) -> BTreeSet<String> {
    lib.lines()
        .filter_map(|l| {
            let l = l.trim_start();
            let l = l.strip_prefix("pub ").unwrap_or(l);
            let name = l.strip_prefix("mod ")?;
            let name = name.trim_end_matches([';', '{', ' ']);
            (!name.starts_with("__")).then(|| name.to_owned())
        })
        .collect()
}

/// `a/{b,c}.rs` as `a/b.rs`, `a/c.rs`.
fn expand(path: &str) -> Vec<String> {
    match (path.find('{'), path.find('}')) {
        (Some(open), Some(close)) if open < close => path[open + 1..close]
            .split(',')
            .flat_map(|part| expand(&format!("{}{part}{}", &path[..open], &path[close + 1..])))
            .collect(),
        _ => vec![path.to_owned()],
    }
}

#[test]
fn the_crate_table_names_every_package_of_the_workspace() {
    let doc = read("ARCHITECTURE.md");
    let listed: BTreeSet<String> = table(&doc, "## Crates")
        .iter()
        .filter_map(|row| ticked(&row[0]).first().map(|s| (*s).to_owned()))
        .collect();
    let manifest = read("Cargo.toml");
    let members = manifest
        .lines()
        .find_map(|l| l.strip_prefix("members = "))
        .expect("the workspace's members");
    let mut packages = BTreeSet::from(["embodied".to_owned()]);
    for dir in ticked(&members.replace('"', "`")) {
        let own = read(&format!("{dir}/Cargo.toml"));
        let name = own
            .lines()
            .find_map(|l| l.strip_prefix("name = "))
            .expect("a package name")
            .trim_matches('"');
        packages.insert(name.to_owned());
    }
    assert_eq!(listed, packages, "ARCHITECTURE.md, ## Crates");
}

#[test]
fn the_module_table_of_agent_core_names_its_modules() {
    let doc = read("ARCHITECTURE.md");
    let listed: BTreeSet<String> = table(&doc, "## Modules of `agent-core`")
        .iter()
        .filter_map(|row| ticked(&row[0]).first().map(|s| (*s).to_owned()))
        .collect();
    assert_eq!(
        listed,
        declared(&read("agent-core/src/lib.rs")),
        "ARCHITECTURE.md, ## Modules of `agent-core`, against agent-core/src/lib.rs"
    );
}

#[test]
fn the_module_table_of_rex_agent_names_its_modules_and_their_files() {
    let doc = read("ARCHITECTURE.md");
    let rows = table(&doc, "## Modules of `rex-agent`");
    let mut listed = BTreeSet::new();
    let mut missing = Vec::new();
    for row in &rows {
        for module in ticked(&row[0]) {
            let top = module.split("::").next().unwrap_or_default();
            listed.insert(top.trim_end_matches(".rs").to_owned());
        }
        for file in ticked(row.get(1).map_or("", String::as_str)) {
            for path in expand(file) {
                if !root().join("rex-agent/src").join(&path).exists() {
                    missing.push(path);
                }
            }
        }
    }
    let mut modules = declared(&read("rex-agent/src/lib.rs"));
    modules.insert("main".to_owned());
    assert_eq!(
        listed, modules,
        "ARCHITECTURE.md, ## Modules of `rex-agent`, against rex-agent/src/lib.rs"
    );
    assert!(
        missing.is_empty(),
        "files ARCHITECTURE.md lists under rex-agent/src/ that do not exist: {missing:?}"
    );
}
