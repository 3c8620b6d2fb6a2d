//! The checker on the corpus of invalid specs: every finding code is demonstrated by
//! a file of `tests/specs/invalid/` named after it, and the rendered diagnostics of
//! each file are snapshot-tested (`tests/snapshots/`).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::path::Path;

use embodied::spec::{Code, Severity, check_file};

fn corpus() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/specs"))
}

#[test]
fn the_valid_specs_pass() {
    for path in [
        corpus().join("valid/minimal.ron"),
        Path::new(env!("CARGO_MANIFEST_DIR")).join("specs/rex.ron"),
    ] {
        let (spec, report) = check_file(&path).expect("readable");
        assert!(spec.is_some());
        assert!(
            report.findings.is_empty(),
            "{}:\n{}",
            path.display(),
            report.render(100)
        );
    }
}

#[test]
fn every_code_is_demonstrated_and_its_diagnostic_is_stable() {
    for code in Code::ALL {
        let name = code.as_str().trim_start_matches("spec::");
        let path = corpus().join("invalid").join(format!("{name}.ron"));
        let (_, report) = check_file(&path).unwrap_or_else(|e| {
            panic!(
                "{}: every code needs a demonstration file ({e})",
                path.display()
            )
        });
        let file = format!("tests/specs/invalid/{name}.ron");
        let report =
            embodied::spec::Report::new(file, report.source.clone(), report.findings.clone());
        assert!(
            report.findings.iter().any(|f| f.code == *code),
            "{name}.ron does not produce {code}:\n{}",
            report.render(100)
        );
        if code.severity() == Severity::Error {
            assert!(!report.is_ok());
        }
        // Every finding points into the file, at a real token.
        for f in &report.findings {
            let first = &f.labels[0];
            assert!(
                first.span.end <= report.source.len()
                    && first.span.start < first.span.end.max(first.span.start + 1)
            );
            assert!(!f.message.is_empty() && !f.help.is_empty(), "{f:?}");
        }
        insta::with_settings!({snapshot_path => "snapshots", prepend_module_to_snapshot => false}, {
            insta::assert_snapshot!(format!("invalid_{name}"), report.render(100));
        });
    }
}

#[test]
fn short_style_names_file_line_and_column() {
    let path = corpus().join("invalid/arcs_overlap.ron");
    let (_, report) = check_file(&path).unwrap();
    let short = report.short();
    assert!(
        short.contains("arcs_overlap.ron:39:65: error[spec::arcs_overlap]: arcs `idle -> move` and `idle -> answer` can hold at once"),
        "{short}"
    );
}

#[test]
fn findings_are_sorted_and_reported_all_at_once() {
    // A file with many problems: they all come out, in file order.
    let text = std::fs::read_to_string(corpus().join("valid/minimal.ron"))
        .unwrap()
        .replace("period_ms: 10.0,", "period_ms: 0.0,")
        .replace(r#"terminal: "got_order""#, r#"terminal: "got_ordre""#)
        .replace(r#"policy: Queue(2)),"#, r#"policy: Queue(0)),"#);
    let (_, report) = embodied::spec::check_source("many.ron", text);
    let codes: Vec<Code> = report.findings.iter().map(|f| f.code).collect();
    for c in [Code::Period, Code::UnknownPredicate, Code::QueueBound] {
        assert!(codes.contains(&c), "{codes:?}");
    }
    let offsets: Vec<usize> = report.findings.iter().map(|f| f.offset()).collect();
    assert!(offsets.windows(2).all(|w| w[0] <= w[1]), "{offsets:?}");
}

#[test]
fn the_reference_page_example_is_the_tested_minimal_spec_and_lists_every_code() {
    let page = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/docs/spec-reference.md"
    ))
    .unwrap();
    let minimal = std::fs::read_to_string(corpus().join("valid/minimal.ron")).unwrap();
    assert!(
        page.contains(&format!("```ron\n{minimal}```")),
        "docs/spec-reference.md has an outdated example"
    );
    for code in Code::ALL {
        let row = format!(
            "| `{}` | {} | {} |",
            code.as_str(),
            match code.severity() {
                Severity::Error => "error",
                Severity::Warning => "warning",
            },
            code.description()
        );
        assert!(page.contains(&row), "missing or outdated row: {row}");
    }
}
