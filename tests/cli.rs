//! The `embodied` binary as a user runs it: exit statuses, output, files written.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::process::Command;

fn embodied(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_embodied"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("the binary runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn check_exit_status_follows_the_worst_finding() {
    let (code, stdout, _) = embodied(&["check", "specs/rex.ron"]);
    assert_eq!(code, 0, "{stdout}");
    assert!(stdout.contains("specs/rex.ron: ok (0 errors, 0 warnings)"));

    let (code, stdout, stderr) = embodied(&["check", "tests/specs/invalid/unused_function.ron"]);
    assert_eq!(code, 0, "warnings only: {stderr}");
    assert!(stdout.contains("(0 errors, 1 warnings)"), "{stdout}");
    assert!(stderr.contains("spec::unused_function"), "{stderr}");

    let (code, stdout, stderr) = embodied(&[
        "check",
        "specs/rex.ron",
        "tests/specs/invalid/arcs_overlap.ron",
        "tests/specs/invalid/period.ron",
    ]);
    assert_eq!(code, 1);
    assert!(stdout.contains("3 files: 2 errors, 0 warnings"), "{stdout}");
    assert!(stderr.contains("spec::arcs_overlap") && stderr.contains("spec::period"));

    let (code, _, stderr) = embodied(&["check", "no/such/file.ron"]);
    assert_eq!(code, 1);
    assert!(stderr.contains("cannot read no/such/file.ron"), "{stderr}");
}

#[test]
fn short_style_is_one_line_per_finding() {
    let (code, _, stderr) = embodied(&[
        "check",
        "--style",
        "short",
        "tests/specs/invalid/unfed_input.ron",
    ]);
    assert_eq!(code, 1);
    let lines: Vec<&str> = stderr.lines().collect();
    assert!(
        lines
            .iter()
            .any(|l| l.starts_with("tests/specs/invalid/unfed_input.ron:")
                && l.contains(
                    ": error[spec::unfed_input]: input `e1.E1.odometer` is fed by no output"
                )),
        "{stderr}"
    );
}

#[test]
fn diagram_writes_each_format() {
    let dir = std::env::temp_dir().join(format!("embodied-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    for (format, start) in [
        ("dot", "digraph"),
        ("mermaid", "stateDiagram-v2"),
        ("svg", "<svg"),
    ] {
        let path = dir.join(format!("c1.{format}"));
        let (code, _, stderr) = embodied(&[
            "diagram",
            "specs/rex.ron",
            "--kind",
            "fsm",
            "--subsystem",
            "c1",
            "--format",
            format,
            "-o",
            path.to_str().unwrap(),
        ]);
        assert_eq!(code, 0, "{stderr}");
        let text = std::fs::read_to_string(&path).unwrap();
        assert!(
            text.starts_with(start),
            "{format}: {}",
            &text[..40.min(text.len())]
        );
    }
    let (code, _, stderr) = embodied(&[
        "diagram",
        "specs/rex.ron",
        "--kind",
        "fsm",
        "--subsystem",
        "nope",
    ]);
    assert_eq!(code, 1);
    assert!(stderr.contains("no subsystem `nope`"), "{stderr}");
    let (code, _, stderr) = embodied(&["diagram", "specs/rex.ron", "--kind", "plan"]);
    assert_eq!(code, 2, "clap rejects an unknown kind");
    assert!(stderr.contains("fsm, structure, dataflow"), "{stderr}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn help_explains_each_command() {
    let (code, stdout, _) = embodied(&["--help"]);
    assert_eq!(code, 0);
    assert!(stdout.contains("check") && stdout.contains("diagram"));
    let (_, stdout, _) = embodied(&["help", "diagram"]);
    for needle in [
        "--kind <KIND>",
        "--subsystem <NAME>",
        "--format <FORMAT>",
        "-o, --output <PATH>",
        "Graphviz",
    ] {
        assert!(stdout.contains(needle), "missing {needle}:\n{stdout}");
    }
    // Each value of `--kind` and `--format` is listed with a word on what it is.
    for value in ["fsm", "structure", "dataflow", "dot", "mermaid", "svg"] {
        let line = stdout
            .lines()
            .find(|l| l.trim_start().starts_with(&format!("- {value}:")))
            .unwrap_or_else(|| panic!("`{value}` is not explained:\n{stdout}"));
        let (_, what) = line.split_once(':').unwrap();
        assert!(what.trim().len() > 10, "`{value}` is not explained: {line}");
    }
    let (_, stdout, _) = embodied(&["check", "--help"]);
    for value in ["human", "short"] {
        assert!(
            stdout.contains(&format!("- {value}:")),
            "`--style {value}` is not explained:\n{stdout}"
        );
    }
}

/// `cargo test` in a crate made by `embodied new`, offline, with the same dependency
/// versions as this workspace and a target directory shared by such crates.
fn cargo_test(dir: &std::path::Path) -> (bool, String, String) {
    std::fs::copy(
        concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.lock"),
        dir.join("Cargo.lock"),
    )
    .unwrap();
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args(["test", "--offline", "--quiet"])
        .current_dir(dir)
        .env(
            "CARGO_TARGET_DIR",
            concat!(env!("CARGO_MANIFEST_DIR"), "/target/scaffold"),
        )
        .output()
        .expect("cargo runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `embodied new` makes a crate that compiles and whose tests run, from Rex's spec
/// (three agents, devices, links between agents).
#[test]
fn new_scaffolds_a_crate_that_compiles_and_passes_its_tests() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("scaffold-rex");
    let _ = std::fs::remove_dir_all(&dir);
    let target = dir.to_str().unwrap();
    let (code, stdout, stderr) = embodied(&[
        "new",
        "rex-app",
        "--spec",
        "specs/rex.ron",
        "--path",
        target,
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("created"), "{stdout}");
    for f in [
        "Cargo.toml",
        "README.md",
        "spec.ron",
        "src/logic/c1.rs",
        "src/devices.rs",
        "tests/properties.rs",
    ] {
        assert!(dir.join(f).exists(), "{f} is made");
    }
    let (ok, stdout, stderr) = cargo_test(&dir);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(
        stdout.contains("8 passed; 0 failed; 8 ignored"),
        "structure, run and six action properties pass; eight termination properties wait: {stdout}"
    );
    assert!(
        !stderr.contains("warning"),
        "the crate builds without warnings: {stderr}"
    );

    // Not over an existing crate, not from a broken spec, not with a bad name.
    let (code, _, stderr) = embodied(&[
        "new",
        "rex-app",
        "--spec",
        "specs/rex.ron",
        "--path",
        target,
    ]);
    assert_eq!(code, 1);
    assert!(stderr.contains("not empty"), "{stderr}");
    let (code, _, stderr) = embodied(&[
        "new",
        "x",
        "--spec",
        "tests/specs/invalid/arcs_overlap.ron",
        "--path",
        target,
    ]);
    assert_eq!(code, 1);
    assert!(
        stderr.contains("spec::arcs_overlap") && stderr.contains("no crate was made"),
        "{stderr}"
    );
    for bad in ["Rex App", "serde", "type"] {
        let (code, _, stderr) = embodied(&["new", bad, "--spec", "specs/rex.ron"]);
        assert_eq!(code, 1, "{bad}");
        assert!(stderr.contains("not a valid crate name"), "{stderr}");
    }
}

/// The smallest system: one agent, one control subsystem without buffers, no
/// devices, no links; a memory field and a function named by Rust keywords, and a
/// period (9 ms) that is no round number of seconds. The crate still builds without
/// a warning and its spec test passes.
#[test]
fn new_handles_a_system_without_devices_links_or_buffers() {
    let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("scaffold-solo");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let spec = dir.join("solo.ron");
    std::fs::write(
        &spec,
        r#"(
    name: "counter",
    agents: [(
        name: "solo",
        doc: "One subsystem.\nIt counts.",
        subsystems: [(
            name: "c1", kind: Control, period_ms: 9.0,
            memory: [(name: "type", type: "u32")],
            predicates: [(name: "done", reads: ["type"])],
            functions: [(name: "move", target: Memory, reads: ["type"], writes: ["type"])],
            behaviours: [
                (name: "count", kind: Repeat, functions: ["move"], terminal: "done"),
                (name: "rest", kind: While, terminal: "false"),
            ],
            fsm: (initial: "count", arcs: [(from: "count", to: "rest", when: "true")]),
        )],
    )],
)"#,
    )
    .unwrap();
    let crate_dir = dir.join("app");
    let (code, _, stderr) = embodied(&[
        "new",
        "solo-app",
        "--spec",
        spec.to_str().unwrap(),
        "--path",
        crate_dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    let (ok, stdout, stderr) = cargo_test(&crate_dir);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(stdout.contains("3 passed; 0 failed; 1 ignored"), "{stdout}");
    assert!(!stderr.contains("warning"), "no warning: {stderr}");
    // An agent named like one of the crate's modules is refused.
    let clash = dir.join("clash.ron");
    let text = std::fs::read_to_string(&spec)
        .unwrap()
        .replace("\"solo\"", "\"system\"");
    std::fs::write(&clash, text).unwrap();
    let (code, _, stderr) = embodied(&[
        "new",
        "clash",
        "--spec",
        clash.to_str().unwrap(),
        "--path",
        dir.join("clash").to_str().unwrap(),
    ]);
    assert_eq!(code, 1);
    assert!(stderr.contains("crate's module `system`"), "{stderr}");
}
