//! The checker on the corpus of invalid specs: every finding code is demonstrated by
//! a file of `tests/specs/invalid/` named after it, a few more cases have files of
//! their own ([`EXTRA_CASES`]), and the rendered diagnostics of each file are
//! snapshot-tested (`tests/snapshots/`). The valid specs of `tests/specs/valid/` check
//! clean, and the relations of `relations.ron` are shown to be what makes its arc
//! proofs succeed.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::path::{Path, PathBuf};

use embodied::spec::diag::offset_of;
use embodied::spec::model::{Relation, Reliability};
use embodied::spec::{Code, Report, Severity, check_file, check_source};

fn corpus() -> &'static Path {
    Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/specs"))
}

/// The `.ron` files of `tests/specs/<dir>/`, sorted.
fn ron_files(dir: &str) -> Vec<PathBuf> {
    let mut files: Vec<PathBuf> = std::fs::read_dir(corpus().join(dir))
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "ron"))
        .collect();
    files.sort();
    files
}

/// Cases beyond the one file per code: (file stem, the code it demonstrates, the text
/// under the primary span of each finding with that code, in order).
const EXTRA_CASES: &[(&str, Code, &[&str])] = &[
    // A misspelt name inside `Exclusive([...])` and inside `Implies(..)`.
    (
        "unknown_predicate_in_relation",
        Code::UnknownPredicate,
        &["cancelld", "at_gaol"],
    ),
    // An undeclared predicate in an arc's condition, `ack` after `acked`.
    ("unknown_predicate_in_arc", Code::UnknownPredicate, &["ack"]),
    // A ROS 2 entry naming a buffer its component does not have (`akc`), and one
    // naming a component that does not exist.
    ("ros2_unknown_buffer", Code::UnknownBuffer, &["c1.c2.akc"]),
    (
        "ros2_unknown_component",
        Code::UnknownComponent,
        &["c3.c2.order"],
    ),
    // The default package made from the system's name `Mini`, pointed at the
    // section; a private topic whose full name, `/mini__1/ack`, breaks the rules.
    ("ros2_default_package", Code::Ros2Name, &["ros2"]),
    ("ros2_private_topic", Code::Ros2Name, &["~/ack"]),
];

/// Every label of every finding covers a non-empty range of whole characters of the
/// source, starting at a character of a line of the file (not past its end).
fn assert_labels_point_into_the_file(report: &Report) {
    let source = &report.source;
    let lines: Vec<&str> = source.split('\n').collect();
    for f in &report.findings {
        assert!(!f.labels.is_empty(), "{f:?}");
        for label in &f.labels {
            let span = &label.span;
            assert!(
                span.start < span.end && span.end <= source.len(),
                "{}: label {span:?} of {f:?} is empty or outside the source ({} bytes)",
                report.file,
                source.len()
            );
            assert!(
                source.is_char_boundary(span.start) && source.is_char_boundary(span.end),
                "{}: label {span:?} of {f:?} splits a character",
                report.file
            );
            let (line, col) = report.line_col(span.start);
            assert!(
                (1..=lines.len()).contains(&line)
                    && (1..=lines[line - 1].chars().count()).contains(&col),
                "{}: label {span:?} of {f:?} starts at {line}:{col}, outside the file",
                report.file
            );
            assert_eq!(offset_of(source, line, col), span.start, "{f:?}");
            assert!(
                !source[span.clone()].trim().is_empty(),
                "{}: label {span:?} of {f:?} covers only blanks",
                report.file
            );
        }
        assert!(!f.message.is_empty() && !f.help.is_empty(), "{f:?}");
    }
}

/// Check `tests/specs/invalid/<name>.ron`, named relative to the repository in the
/// report so that snapshots do not depend on where the checkout is.
fn check_invalid(name: &str) -> Report {
    let path = corpus().join("invalid").join(format!("{name}.ron"));
    let (_, report) = check_file(&path)
        .unwrap_or_else(|e| panic!("{}: cannot read the case ({e})", path.display()));
    Report::new(
        format!("tests/specs/invalid/{name}.ron"),
        report.source.clone(),
        report.findings.clone(),
    )
}

fn snapshot(name: &str, report: &Report) {
    insta::with_settings!({snapshot_path => "snapshots", prepend_module_to_snapshot => false}, {
        insta::assert_snapshot!(format!("invalid_{name}"), report.render(100));
    });
}

#[test]
fn the_valid_specs_pass() {
    let valid = ron_files("valid");
    for name in ["minimal.ron", "relations.ron"] {
        assert!(
            valid.iter().any(|p| p.ends_with(name)),
            "tests/specs/valid/{name} is missing: {valid:?}"
        );
    }
    for path in valid
        .into_iter()
        .chain([Path::new(env!("CARGO_MANIFEST_DIR")).join("specs/rex.ron")])
    {
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
fn relations_are_what_make_the_arc_proofs_succeed() {
    let text = std::fs::read_to_string(corpus().join("valid/relations.ron")).unwrap();
    let exclusive = r#"Exclusive(["urgent", "cancelled"]),"#;
    let implies = r#"Implies("at_goal", "stopped"),"#;
    let without = |relations: &[&str]| {
        let mut t = text.clone();
        for r in relations {
            assert_eq!(t.matches(r).count(), 1, "{r} is in relations.ron once");
            t = t.replace(r, "");
        }
        check_source("relations.ron", t)
    };

    // With both relations: clean, and both really are parsed as relations of c1.
    let (spec, report) = without(&[]);
    assert!(report.findings.is_empty(), "{}", report.render(100));
    let c1 = &spec.unwrap().agents[0].subsystems[0];
    assert_eq!(
        c1.relations,
        [
            Relation::Exclusive(vec!["urgent".into(), "cancelled".into()]),
            Relation::Implies("at_goal".into(), "stopped".into()),
        ]
    );

    let codes = |report: &Report| report.findings.iter().map(|f| f.code).collect::<Vec<_>>();
    let primary = |report: &Report, k: usize| {
        let span = report.findings[k].labels[0].span.clone();
        report.source[span].to_owned()
    };

    // Without `Exclusive`: an urgent and cancelled order takes two arcs out of `idle`.
    let (_, report) = without(&[exclusive]);
    assert_eq!(
        codes(&report),
        [Code::ArcsOverlap],
        "{}",
        report.render(100)
    );
    let overlap = &report.findings[0];
    assert!(
        overlap
            .message
            .starts_with("arcs `idle -> rush` and `idle -> answer` can hold at once")
            && overlap.message.contains("urgent=true")
            && overlap.message.contains("cancelled=true"),
        "{}",
        overlap.message
    );
    assert_eq!(primary(&report, 0), "cancelled");

    // Without `Implies`: at the goal but not stopped, no arc leaves `rush`.
    let (_, report) = without(&[implies]);
    assert_eq!(
        codes(&report),
        [Code::ArcsIncomplete],
        "{}",
        report.render(100)
    );
    let incomplete = &report.findings[0];
    assert!(
        incomplete.message.starts_with("when `rush` ends with")
            && incomplete.message.contains("at_goal=true")
            && incomplete.message.contains("stopped=false"),
        "{}",
        incomplete.message
    );
    assert_eq!(primary(&report, 0), "finished", "rush's terminal condition");

    // Without both: both findings, and nothing else.
    let (_, report) = without(&[exclusive, implies]);
    let mut both = codes(&report);
    both.sort();
    assert_eq!(
        both,
        [Code::ArcsOverlap, Code::ArcsIncomplete],
        "{}",
        report.render(100)
    );
}

#[test]
fn every_code_is_demonstrated_and_its_diagnostic_is_stable() {
    // A code only programs find (the Rust types behind the buffers) is
    // demonstrated by the program's test: agent-app's
    // `a_buffer_type_that_cannot_be_the_message_is_said_at_the_specs_entry`.
    for code in Code::ALL.iter().filter(|c| !c.is_found_by_programs()) {
        let name = code.as_str().trim_start_matches("spec::");
        let report = check_invalid(name);
        assert!(
            report.findings.iter().any(|f| f.code == *code),
            "{name}.ron does not produce {code}:\n{}",
            report.render(100)
        );
        if code.severity() == Severity::Error {
            assert!(!report.is_ok());
        }
        // Every finding points into the file, at a real token.
        assert_labels_point_into_the_file(&report);
        snapshot(name, &report);
    }
}

#[test]
fn extra_cases_point_at_the_offending_name_and_their_diagnostics_are_stable() {
    for &(name, code, expected) in EXTRA_CASES {
        let report = check_invalid(name);
        assert_labels_point_into_the_file(&report);
        let under: Vec<&str> = report
            .findings
            .iter()
            .filter(|f| f.code == code)
            .map(|f| &report.source[f.labels[0].span.clone()])
            .collect();
        assert_eq!(under, expected, "{name}.ron:\n{}", report.render(100));
        // ... as a whole name, not a part of a longer one (`ack` of `acked`).
        let ident = |b: &u8| b.is_ascii_alphanumeric() || *b == b'_';
        for f in report.findings.iter().filter(|f| f.code == code) {
            let span = f.labels[0].span.clone();
            let bytes = report.source.as_bytes();
            let before = span.start.checked_sub(1).map(|i| &bytes[i]);
            assert!(
                !before.is_some_and(ident) && !bytes.get(span.end).is_some_and(ident),
                "{name}.ron: {span:?} is inside a longer name:\n{}",
                report.render(100)
            );
        }
        assert!(
            report.findings.iter().all(|f| f.code == code),
            "{name}.ron reports only {code}:\n{}",
            report.render(100)
        );
        snapshot(name, &report);
    }
}

#[test]
fn every_invalid_file_is_a_tested_case() {
    let mut expected: Vec<String> = Code::ALL
        .iter()
        .filter(|c| !c.is_found_by_programs())
        .map(|c| c.as_str().trim_start_matches("spec::").to_owned())
        .chain(EXTRA_CASES.iter().map(|(name, ..)| (*name).to_owned()))
        .collect();
    expected.sort();
    let found: Vec<String> = ron_files("invalid")
        .iter()
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    assert_eq!(
        found, expected,
        "each file of tests/specs/invalid/ is named after a code or listed in EXTRA_CASES"
    );
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
    // A file with many problems: they all come out, root causes first, each part in
    // file order. The misspelt peer `e2` (a root cause) leaves c1's input from it
    // unfed and e1's `done` unread (consequences, listed after every root cause).
    let text = std::fs::read_to_string(corpus().join("valid/minimal.ron"))
        .unwrap()
        .replace("period_ms: 10.0,", "period_ms: 0.0,")
        .replace(r#"terminal: "got_order""#, r#"terminal: "got_ordre""#)
        .replace(r#"policy: Queue(2)),"#, r#"policy: Queue(0)),"#)
        .replace(
            r#"(peer: "e1", buffers: [(name: "done", type: "bool")]),"#,
            r#"(peer: "e2", buffers: [(name: "done", type: "bool")]),"#,
        );
    let (_, report) = embodied::spec::check_source("many.ron", text);
    let codes: Vec<Code> = report.findings.iter().map(|f| f.code).collect();
    for c in [
        Code::Period,
        Code::UnknownPredicate,
        Code::QueueBound,
        Code::UnknownComponent,
    ] {
        assert!(codes.contains(&c), "{codes:?}");
    }
    assert!(
        codes.iter().any(|c| !c.is_root_cause()),
        "the misspelt peer has consequences: {codes:?}"
    );
    let keys: Vec<(bool, usize)> = report
        .findings
        .iter()
        .map(|f| (!f.code.is_root_cause(), f.offset()))
        .collect();
    assert!(keys.windows(2).all(|w| w[0] <= w[1]), "{keys:?}");
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

#[test]
fn the_systems_ros2_section_shows_in_each_deployment_what_it_runs() {
    // e1's buffer in the system's section: a deployment that omits e1 leaves it out,
    // and that is no finding; in the deployment's own section it is one.
    let text = std::fs::read_to_string(corpus().join("valid/minimal.ron")).unwrap();
    let one = r#"(name: "one", hosts: [(name: "pc", processes: [(name: "all", runs: ["c1", "e1", "E1", "c2"])])]),"#;
    let without_e1 = r#"(name: "without_e1", hosts: [(name: "pc", processes: [(name: "all", runs: ["c1", "E1", "c2"])])], omit: ["e1"]),"#;
    let section = r#"ros2: (publish: [(buffer: "e1.c1.done", topic: "done")]),"#;
    assert_eq!(text.matches(one).count(), 1);
    let system = text
        .replace(one, &format!("{one}\n        {without_e1}"))
        .replace(
            "    deployments: [",
            &format!("    {section}\n    deployments: ["),
        );
    let (spec, report) = check_source("system.ron", system);
    assert!(report.findings.is_empty(), "{}", report.render(100));
    let spec = spec.unwrap();
    let shown = |name: &str| {
        let deployment = spec.deployment(name);
        let interface = embodied::spec::ros2::interface(&spec, deployment).unwrap();
        interface
            .publish
            .iter()
            .map(|t| t.name.clone())
            .collect::<Vec<_>>()
    };
    assert_eq!(shown("one"), ["/done"]);
    assert!(shown("without_e1").is_empty());

    let own = text.replace(
        one,
        &format!(
            "{one}\n        {}",
            without_e1.replace("omit:", &format!("{section} omit:"))
        ),
    );
    let (_, report) = check_source("own.ron", own);
    let codes: Vec<Code> = report.findings.iter().map(|f| f.code).collect();
    assert_eq!(codes, [Code::Ros2NotDeployed], "{}", report.render(100));
}

#[test]
fn rex_shows_itself_to_ros2() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("specs/rex.ron");
    let (spec, report) = check_file(&path).unwrap();
    assert!(report.findings.is_empty(), "{}", report.render(100));
    let spec = spec.unwrap();
    let shown = |deployment: &str| {
        embodied::spec::ros2::interface(&spec, spec.deployment(deployment)).unwrap()
    };
    let rex = shown("simulation");
    assert_eq!(
        (
            rex.domain,
            rex.node.as_str(),
            rex.namespace.as_str(),
            rex.package.as_str()
        ),
        (0, "rex", "/rex", "rex_msgs")
    );
    let topics: Vec<(&str, Option<&str>)> = rex
        .publish
        .iter()
        .map(|t| (t.name.as_str(), t.message.as_deref()))
        .collect();
    assert_eq!(
        topics,
        [
            ("/rex/pose", Some("geometry_msgs/msg/PoseStamped")),
            ("/rex/estimate", None),
            ("/rex/reference_path", Some("nav_msgs/msg/Path")),
            ("/rex/imu", Some("sensor_msgs/msg/Imu")),
            (
                "/rex/camera/image/compressed",
                Some("sensor_msgs/msg/CompressedImage")
            ),
            ("/rex/ack", None),
            ("/rex/outcome", None),
        ]
    );
    // Plans come in as the queue link delivers them: reliable, four kept.
    let plan = &rex.subscribe[0];
    assert_eq!(
        (plan.name.as_str(), plan.buffer.as_str()),
        ("/rex/plan", "c1.c2.desired_plan")
    );
    assert_eq!(
        (plan.qos.reliability, plan.qos.depth),
        (Reliability::Reliable, 4)
    );
    // The camera's sample link: best effort; the pose's, made reliable by the spec.
    let qos = |name: &str| rex.publish.iter().find(|t| t.name == name).unwrap().qos;
    assert_eq!(
        qos("/rex/camera/image/compressed").reliability,
        Reliability::BestEffort
    );
    assert_eq!(qos("/rex/pose").reliability, Reliability::Reliable);
    // Without visual odometry, R1 does not run: no camera.
    let without = shown("simulation_without_vo");
    assert_eq!(without.publish.len(), rex.publish.len() - 1);
    assert!(without.publish.iter().all(|t| t.component != "R1"));
}
