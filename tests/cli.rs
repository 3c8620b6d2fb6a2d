//! The `embodied` binary as a user runs it: exit statuses, output, files written,
//! and the crates `embodied new` makes: their files (snapshots), then built,
//! tested, linted and run as their user would.
//!
//! The binary needs the `cli` feature, and so does this test (`Cargo.toml`):
//! `cargo test --features cli --test cli`.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

#[path = "common/binary.rs"]
mod binary;

use std::path::{Path, PathBuf};
use std::process::Command;

use binary::embodied;

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

// ---------------------------------------------------------------------------
// `embodied new`

/// A fresh directory for a test's crate.
fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

/// The files under `dir`, as sorted paths relative to it with `/` between folders.
fn files_under(dir: &Path) -> Vec<String> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<String>) {
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(root, &path, out);
            } else {
                let relative = path.strip_prefix(root).unwrap();
                let parts: Vec<_> = relative.iter().map(|p| p.to_string_lossy()).collect();
                out.push(parts.join("/"));
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

/// The `--config` that builds a new crate against this checkout instead of
/// crates.io, as its README says.
fn patch() -> String {
    format!(
        "patch.crates-io.embodied.path={:?}",
        env!("CARGO_MANIFEST_DIR")
    )
}

/// `cargo SUBCOMMAND ARGS` in a crate made by `embodied new`: offline, with the
/// dependency versions of this workspace (its `Cargo.lock`), `embodied` patched with
/// this checkout (by `--config`, unless the crate's own `.cargo/config.toml` does
/// it), and one target directory shared by such crates, so that their dependencies
/// are built once.
fn cargo(dir: &Path, subcommand: &str, args: &[&str]) -> (bool, String, String) {
    let lock = dir.join("Cargo.lock");
    if !lock.exists() {
        std::fs::copy(concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.lock"), lock).unwrap();
    }
    let mut command = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    command.arg(subcommand).arg("--offline");
    if !dir.join(".cargo/config.toml").exists() {
        command.args(["--config", &patch()]);
    }
    let out = command
        .args(args)
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

/// `cargo fmt --check` in a crate made by `embodied new`: the generated code is
/// formatted as rustfmt would (for the specs of these tests).
fn formatted(dir: &Path) -> (bool, String) {
    let out = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()))
        .args(["fmt", "--check"])
        .current_dir(dir)
        .output()
        .expect("cargo fmt runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
    )
}

/// The files `embodied new` writes for the small spec of the corpus and for the
/// tank, file by file (`tests/snapshots/new_*`). The crate depends on `embodied` by
/// version, and `spec.ron` is the spec as given.
#[test]
fn new_writes_the_files_of_a_spec() {
    for (spec, name, subsystems) in [
        (
            "tests/specs/valid/minimal.ron",
            "mini-app",
            &["c1", "c2", "e1"][..],
        ),
        ("specs/tank.ron", "my-tank", &["c1", "c2", "e1", "r1"][..]),
    ] {
        let dir = scratch(&format!("snapshot-{name}"));
        let (code, stdout, stderr) =
            embodied(&["new", name, "--spec", spec, "--path", dir.to_str().unwrap()]);
        assert_eq!(code, 0, "{stderr}");
        assert!(
            stdout.contains(&format!("from {spec}")) && stdout.contains("cargo run"),
            "{stdout}"
        );
        let mut expected = vec![
            ".gitignore",
            "Cargo.toml",
            "README.md",
            "spec.ron",
            "src/devices.rs",
            "src/lib.rs",
            "src/logic.rs",
            "src/main.rs",
            "src/system.rs",
            "src/types.rs",
            "tests/app.rs",
            "tests/properties/main.rs",
        ]
        .into_iter()
        .map(String::from)
        .collect::<Vec<_>>();
        for s in subsystems {
            expected.push(format!("src/logic/{s}.rs"));
            expected.push(format!("tests/properties/{s}.rs"));
        }
        expected.sort();
        let files = files_under(&dir);
        assert_eq!(files, expected);
        let source = std::fs::read_to_string(spec).unwrap();
        for path in &files {
            let text = std::fs::read_to_string(dir.join(path)).unwrap();
            if path == "spec.ron" {
                assert_eq!(text, source, "the spec as given");
                continue;
            }
            let snapshot = format!("new_{name}__{}", path.replace(['/', '.'], "_"));
            insta::with_settings!({snapshot_path => "snapshots", prepend_module_to_snapshot => false}, {
                insta::assert_snapshot!(snapshot, text);
            });
        }
        let manifest = std::fs::read_to_string(dir.join("Cargo.toml")).unwrap();
        assert!(
            manifest.contains(
                "\nembodied = { version = \"0.1\", features = [\"app\", \"distributed\"] }\n"
            ),
            "{manifest}"
        );
    }
}

/// `embodied new` makes a crate from Rex's spec (three agents, devices, links
/// between agents) that its user can work in at once: a driver given a field
/// compiles (drivers are made with `Default`), its tests pass (the termination
/// tests too: on stubs, they say what they could not check; and the program's:
/// real time, a recording replayed, the spec's largest deployment launched and
/// one of its processes killed and restarted), it is clean under `cargo clippy
/// --all-targets -- -D warnings`, `cargo run -- --transitions` runs the system
/// and prints its FSM transitions, and it compiles the application layer's
/// command line (clap) but not the checker's drawing (miette). Its code is
/// formatted as rustfmt would.
#[test]
fn new_makes_a_crate_that_builds_runs_and_passes_clippy() {
    let dir = scratch("new-rex");
    let (code, stdout, stderr) = embodied(&[
        "new",
        "rex-app",
        "--spec",
        "specs/rex.ron",
        "--path",
        dir.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{stderr}");
    assert!(stdout.contains("created"), "{stdout}");
    assert!(!dir.join(".cargo").exists(), "no patch unless asked");

    // The user gives a driver state.
    let devices = std::fs::read_to_string(dir.join("src/devices.rs")).unwrap();
    let (before, after) = devices.split_at(devices.find("impl Driver for E1Driver").unwrap());
    let before = before.replace(
        "pub struct E1Driver {}",
        "pub struct E1Driver {\n    /// Steps taken.\n    pub steps: u64,\n}",
    );
    let after = after.replacen(
        "let _ = (context, input, output);",
        "let _ = (context, input, output);\n        self.steps += 1;",
        1,
    );
    let edited = before + &after;
    assert!(edited.contains("pub steps: u64") && edited.contains("self.steps += 1;"));
    std::fs::write(dir.join("src/devices.rs"), edited).unwrap();

    let (ok, stdout, stderr) = cargo(&dir, "test", &["--quiet"]);
    assert!(ok, "{stdout}\n{stderr}");
    assert!(
        stdout.contains("16 passed; 0 failed; 0 ignored"),
        "structure, run, six action properties and eight termination properties: {stdout}"
    );
    assert!(
        stdout.contains("4 passed; 0 failed; 0 ignored"),
        "real time, record and replay, a launch, a killed process restarted: {stdout}"
    );
    assert!(
        !stderr.contains("warning"),
        "the crate builds without warnings: {stderr}"
    );

    let (ok, stdout, stderr) = cargo(&dir, "clippy", &["--all-targets", "--", "-D", "warnings"]);
    assert!(ok, "clippy: {stdout}\n{stderr}");
    let (ok, diff) = formatted(&dir);
    assert!(ok, "rustfmt: {diff}");

    let (ok, stdout, stderr) = cargo(
        &dir,
        "run",
        &["--quiet", "--", "--for", "3", "--transitions", "--quiet"],
    );
    assert!(ok, "{stdout}\n{stderr}");
    assert!(
        stdout.contains("t=0.000000 s c2: next_plan -> settle (arc 1, when !more)\n"),
        "every transition is printed: {stdout}"
    );
    assert!(
        stdout
            .lines()
            .last()
            .is_some_and(|l| l.starts_with("run=rex ended=limit sim_s=2.999")),
        "{stdout}"
    );
    let (ok, _, stderr) = cargo(&dir, "run", &["--quiet", "--", "--for", "soon"]);
    assert!(
        !ok && stderr.contains("invalid value 'soon' for '--for <SECONDS>'"),
        "{stderr}"
    );

    let (ok, stdout, stderr) = cargo(&dir, "tree", &["-e", "normal", "--prefix", "none"]);
    assert!(ok, "{stderr}");
    assert!(stdout.contains("embodied v0.1.0"), "{stdout}");
    assert!(
        stdout.lines().any(|l| l.starts_with("clap ")),
        "the program's command line: {stdout}"
    );
    assert!(
        !stdout.lines().any(|l| l.starts_with("miette")),
        "miette draws the `embodied` tool's reports, not the user's: {stdout}"
    );
}

/// The smallest system: one agent, one control subsystem without buffers, no
/// devices, no links; a memory field and a function named by Rust keywords, and a
/// period (9 ms) that is no round number of seconds. Made with `--embodied-path`,
/// the crate builds against this checkout through its own `.cargo/config.toml`,
/// without a warning, and its tests pass.
#[test]
fn new_handles_a_system_without_devices_links_or_buffers() {
    let dir = scratch("new-solo");
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
        "--embodied-path",
        ".",
    ]);
    assert_eq!(code, 0, "{stderr}");
    let config = std::fs::read_to_string(crate_dir.join(".cargo/config.toml")).unwrap();
    assert!(
        config.contains(&format!(
            "[patch.crates-io]\nembodied = {{ path = {:?} }}\n",
            env!("CARGO_MANIFEST_DIR")
        )),
        "an absolute path: {config}"
    );
    let (ok, stdout, stderr) = cargo(&crate_dir, "test", &["--quiet"]);
    assert!(ok, "{stdout}\n{stderr}");
    assert_eq!(
        stdout.matches("4 passed; 0 failed; 0 ignored").count(),
        2,
        "the properties, and the program (one process launched, killed, restarted): {stdout}"
    );
    let spec_ron = std::fs::read_to_string(crate_dir.join("spec.ron")).unwrap();
    assert!(
        spec_ron.contains("(name: \"solo\", runs: [\"c1\"]),"),
        "a deployment added: {spec_ron}"
    );
    assert!(!stderr.contains("warning"), "no warning: {stderr}");
    let (ok, stdout, stderr) = cargo(
        &crate_dir,
        "clippy",
        &["--all-targets", "--", "-D", "warnings"],
    );
    assert!(ok, "clippy: {stdout}\n{stderr}");
    let (ok, diff) = formatted(&crate_dir);
    assert!(ok, "rustfmt: {diff}");

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
    assert!(!dir.join("clash").exists(), "nothing is written");
}

/// What `embodied new` refuses, with a message and status 1, writing nothing: a
/// directory that is not empty, a file where the directory should be, a spec that
/// cannot be read or has errors, a bad crate name, a checkout that is not one.
#[test]
fn new_refuses_bad_input_with_a_message() {
    let dir = scratch("new-refused");
    std::fs::create_dir_all(dir.join("full")).unwrap();
    std::fs::write(dir.join("full/keep.txt"), "mine").unwrap();
    std::fs::write(dir.join("a-file"), "mine").unwrap();
    let at = |name: &str| dir.join(name).to_str().unwrap().to_owned();
    let new = |name: &str, spec: &str, path: &str, more: &[&str]| {
        let mut args = vec!["new", name, "--spec", spec, "--path", path];
        args.extend(more);
        embodied(&args)
    };
    let cases: [(_, &str); 8] = [
        (
            new("app", "specs/rex.ron", &at("full"), &[]),
            "full exists and is not empty; choose another --path",
        ),
        (
            new("app", "specs/rex.ron", &at("a-file"), &[]),
            "a-file exists and is not a directory",
        ),
        (
            new("app", "no/such.ron", &at("x"), &[]),
            "error: cannot read no/such.ron",
        ),
        (
            new("app", "tests/specs/invalid/arcs_overlap.ron", &at("x"), &[]),
            "error: tests/specs/invalid/arcs_overlap.ron has errors; no crate was made",
        ),
        (
            new("Rex App", "specs/rex.ron", &at("x"), &[]),
            "`Rex App` is not a valid crate name",
        ),
        (
            new("serde", "specs/rex.ron", &at("x"), &[]),
            "`serde` is not a valid crate name",
        ),
        (
            new(
                "app",
                "specs/rex.ron",
                &at("x"),
                &["--embodied-path", "specs"],
            ),
            "error: --embodied-path specs: cannot read specs/Cargo.toml",
        ),
        (
            new(
                "app",
                "specs/rex.ron",
                &at("x"),
                &["--embodied-path", "rex-agent"],
            ),
            "rex-agent/Cargo.toml is not the manifest of the `embodied` package",
        ),
    ];
    for ((code, _, stderr), message) in cases {
        assert_eq!(code, 1, "{message}: {stderr}");
        assert!(stderr.contains(message), "{message}: {stderr}");
    }
    let (_, _, stderr) = new("app", "tests/specs/invalid/arcs_overlap.ron", &at("x"), &[]);
    assert!(
        stderr.contains("spec::arcs_overlap"),
        "the report: {stderr}"
    );
    assert!(!dir.join("x").exists(), "nothing is written");
    assert_eq!(files_under(&dir), ["a-file", "full/keep.txt"]);
}

#[test]
fn a_reader_that_stops_early_ends_the_output_not_the_program() {
    // `embodied check --timing specs/rex.ron | head -0`: the pipe is closed
    // before the program writes; its output ends there, and nothing panics
    // (`println!` would, on the broken pipe).
    let mut child = Command::new(env!("CARGO_BIN_EXE_embodied"))
        .args(["check", "--timing", "specs/rex.ron"])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .stdout(std::process::Stdio::piped())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    drop(child.stdout.take());
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
    assert_eq!(out.status.code(), Some(0), "{stderr}");
}
