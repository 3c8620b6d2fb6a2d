//! The documentation holds together: the README stays a short start (at most 400
//! lines), no Rust example of the README, the guide or a doc comment is ignored, every page of
//! the guide with Rust examples is compiled by the doctests (a module of
//! `src/lib.rs`), and every relative link points to a file of the repository.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::path::{Path, PathBuf};

fn root() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The README, ARCHITECTURE.md and every page of `docs/`.
fn pages() -> Vec<PathBuf> {
    let mut pages: Vec<PathBuf> = std::fs::read_dir(root().join("docs"))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|e| e == "md"))
        .collect();
    pages.sort();
    pages.push(root().join("README.md"));
    pages.push(root().join("ARCHITECTURE.md"));
    pages
}

/// The info strings of the code blocks of `text` (what follows the opening
/// fence), with their line numbers.
fn fences(text: &str) -> Vec<(usize, &str)> {
    let mut open = false;
    let mut found = Vec::new();
    for (n, line) in text.lines().enumerate() {
        if let Some(info) = line.trim_start().strip_prefix("```") {
            if !open {
                found.push((n + 1, info.trim()));
            }
            open = !open;
        }
    }
    found
}

fn is_rust(info: &str) -> bool {
    // rustdoc tests a block without an info string, or whose first word is
    // `rust` or an attribute it knows.
    let first = info.split(',').next().unwrap_or_default().trim();
    first.is_empty()
        || first == "rust"
        || ["no_run", "should_panic", "compile_fail", "ignore"].contains(&first)
}

#[test]
fn the_readme_is_a_short_start() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let lines = readme.lines().count();
    assert!(
        lines <= 400,
        "README.md has {lines} lines: guides go to docs/"
    );
    for section in ["## Quick start", "## Where to go next"] {
        assert!(readme.contains(section), "README.md lacks `{section}`");
    }
}

/// Every Rust source of the workspace's crates (their `src/` folders).
fn sources() -> Vec<PathBuf> {
    fn walk(dir: &Path, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(&path, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    let mut out = Vec::new();
    for entry in std::fs::read_dir(root()).unwrap() {
        let src = entry.unwrap().path().join("src");
        if src.is_dir() && src.parent().unwrap().join("Cargo.toml").is_file() {
            walk(&src, &mut out);
        }
    }
    walk(&root().join("src"), &mut out);
    out.sort();
    out
}

/// The documentation comments of a Rust source (`///` and `//!`), each line in
/// its place and every other line empty, so that fences keep their line numbers.
fn doc_comments(source: &str) -> String {
    source
        .lines()
        .map(|l| {
            let l = l.trim_start();
            l.strip_prefix("///")
                .or_else(|| l.strip_prefix("//!"))
                .map_or("", |d| d.strip_prefix(' ').unwrap_or(d))
        })
        .collect::<Vec<_>>()
        .join("\n")
}

#[test]
fn no_rust_example_is_ignored() {
    let mut ignored = Vec::new();
    let docs = pages()
        .into_iter()
        .map(|p| (std::fs::read_to_string(&p).unwrap(), p));
    let comments = sources()
        .into_iter()
        .map(|p| (doc_comments(&std::fs::read_to_string(&p).unwrap()), p));
    let all: Vec<(String, PathBuf)> = docs.chain(comments).collect();
    assert!(all.len() > 100, "the sources were not found");
    for (text, page) in all {
        for (line, info) in fences(&text) {
            if is_rust(info) && info.split(',').any(|a| a.trim() == "ignore") {
                ignored.push(format!("{}:{line}: ```{info}", page.display()));
            }
        }
    }
    assert!(
        ignored.is_empty(),
        "ignored examples:\n{}",
        ignored.join("\n")
    );
}

#[test]
fn every_page_with_rust_examples_is_compiled_by_the_doctests() {
    let lib = std::fs::read_to_string(root().join("src/lib.rs")).unwrap();
    let mut missing = Vec::new();
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        if !fences(&text).iter().any(|(_, info)| is_rust(info)) {
            continue;
        }
        let name = page.file_name().unwrap().to_string_lossy();
        let included = if name == "README.md" {
            lib.contains("#![doc = include_str!(\"../README.md\")]")
        } else {
            lib.contains(&format!("include_str!(\"../docs/{name}\")"))
        };
        if !included {
            missing.push(page.display().to_string());
        }
    }
    assert!(
        missing.is_empty(),
        "pages with Rust examples that src/lib.rs does not include as doctests:\n{}",
        missing.join("\n")
    );
}

#[test]
fn relative_links_point_to_files_of_the_repository() {
    let mut broken = Vec::new();
    for page in pages() {
        let text = std::fs::read_to_string(&page).unwrap();
        let dir = page.parent().unwrap();
        let mut open = false;
        for (n, line) in text.lines().enumerate() {
            if line.trim_start().starts_with("```") {
                open = !open;
            }
            if open {
                continue;
            }
            let mut rest = line;
            while let Some(at) = rest.find("](") {
                rest = &rest[at + 2..];
                let Some(end) = rest.find(')') else { break };
                let target = &rest[..end];
                rest = &rest[end..];
                if target.contains("://") || target.starts_with('#') || target.is_empty() {
                    continue;
                }
                let file = target.split('#').next().unwrap_or_default();
                if !dir.join(file).exists() {
                    broken.push(format!("{}:{}: {target}", page.display(), n + 1));
                }
            }
        }
    }
    assert!(broken.is_empty(), "broken links:\n{}", broken.join("\n"));
}
