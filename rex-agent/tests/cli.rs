//! The `rex` command line against bad input: each is refused before anything
//! runs, with the file, field or flag named, and exit status 2.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::path::{Path, PathBuf};
use std::process::Command;

fn rex(args: &[&str]) -> (Option<i32>, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_rex"))
        .args(args)
        .output()
        .unwrap();
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    (out.status.code(), text)
}

struct Dir(PathBuf);

impl Dir {
    fn new(name: &str) -> Dir {
        let d = std::env::temp_dir().join(format!("rex-cli-{name}-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        Dir(d)
    }

    fn file(&self, name: &str, text: &str) -> String {
        let p = self.0.join(name);
        std::fs::write(&p, text).unwrap();
        p.display().to_string()
    }
}

impl Drop for Dir {
    fn drop(&mut self) {
        std::fs::remove_dir_all(&self.0).ok();
    }
}

fn shipped_world() -> String {
    std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("config/world.ron")).unwrap()
}

#[test]
fn absurd_or_negative_limits_are_refused() {
    // Before: `--limit 1e20` panicked converting to a duration; `--limit -1` was
    // read as a flag.
    for limit in ["1e20", "-1", "0", "NaN"] {
        let (code, text) = rex(&[
            "--mission",
            "square",
            "--no-vo",
            "--quiet",
            "--limit",
            limit,
        ]);
        assert_eq!(code, Some(2), "{limit}: {text}");
        assert!(
            text.contains("--limit") && text.contains("must be a positive number of seconds"),
            "{limit}: {text}"
        );
    }
    let d = Dir::new("limit");
    let run = d.file("run.ron", "(limit_s: 1e30)");
    let (code, text) = rex(&["--config", &run, "--quiet", "--no-vo"]);
    assert_eq!(code, Some(2), "{text}");
    assert!(
        text.contains("limit_s = 1000000000000000000000000000000"),
        "{text}"
    );
    // A margin for the estimate's error that leaves no tolerance: no plan
    // could ever be reported reached.
    let run = d.file(
        "margin.ron",
        "(limits: (final_m: 0.1, final_margin_m: 0.1))",
    );
    let (code, text) = rex(&["--config", &run, "--quiet", "--no-vo"]);
    assert_eq!(code, Some(2), "{text}");
    assert!(
        text.contains("limits.final_margin_m") && text.contains("less than limits.final_m"),
        "{text}"
    );
}

#[test]
fn an_unusable_report_folder_is_refused_before_the_simulation() {
    // Before: `Not a directory (os error 20)`, after the whole simulation.
    let d = Dir::new("out");
    let file = d.file("not_a_folder", "");
    let (code, text) = rex(&["--mission", "square", "--no-vo", "--out", &file]);
    assert_eq!(code, Some(2), "{text}");
    assert!(
        text.contains(&format!("--out {file}: exists and is not a folder")),
        "{text}"
    );
    assert!(!text.contains("c1 in B"), "nothing ran: {text}");
}

#[test]
fn bad_configuration_values_name_their_file_and_field() {
    let d = Dir::new("config");
    // A period that rounds to zero nanoseconds. Before: `a period must be
    // positive, got zero`, naming neither file nor field. The periods are the
    // spec's now (the world file had a copy of them).
    let spec_text = std::fs::read_to_string(rex_agent::system::default_spec()).unwrap();
    let spec = d.file(
        "rex.ron",
        &spec_text.replacen("period_ms: 1.0,", "period_ms: 1e-7,", 1),
    );
    let (code, text) = rex(&["--spec", &spec, "--quiet", "--no-vo"]);
    assert_eq!(code, Some(2), "{text}");
    assert!(
        text.contains(&format!("specification {spec}")) && text.contains("spec::period"),
        "{text}"
    );
    // The world file no longer holds periods: a copy of them is refused by name.
    let world = d.file(
        "world.ron",
        &shipped_world().replace("start: (", "periods: (platform_ms: 1.0),\n    start: ("),
    );
    let (code, text) = rex(&["--world", &world, "--quiet", "--no-vo"]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains(&world) && text.contains("periods"), "{text}");
    // A third coordinate, silently ignored before.
    let m = d.file(
        "z.ron",
        r#"(name: "z", plans: [[(x: 1.0, y: 0.0, z: 2.0)]])"#,
    );
    let (code, text) = rex(&["--mission", &m, "--quiet", "--no-vo"]);
    assert_eq!(code, Some(2), "{text}");
    assert!(
        text.contains(&format!("{m}:1:")) && text.contains("`z`"),
        "{text}"
    );
    // A name that would put the report outside `--out`, or into `--out` itself.
    for name in ["../x", "/tmp/x", ""] {
        let m = d.file(
            "n.ron",
            &format!("(name: {name:?}, plans: [[(x: 1.0, y: 0.0)]])"),
        );
        let (code, text) = rex(&["--mission", &m, "--quiet", "--no-vo"]);
        assert_eq!(code, Some(2), "{name}: {text}");
        assert!(
            text.contains(&format!("{m}: name = {name:?} is invalid")),
            "{text}"
        );
    }
    // A target inside a pillar of the shipped world.
    let m = d.file(
        "o.ron",
        r#"(name: "o", plans: [[(x: 1.0, y: 0.0), (x: 4.3, y: 4.3)]])"#,
    );
    let (code, text) = rex(&["--mission", &m, "--quiet", "--no-vo"]);
    assert_eq!(code, Some(2), "{text}");
    assert!(
        text.contains(&format!("{m}: plans[0][1] is off the world's free space"))
            && text.contains("obstacle 4"),
        "{text}"
    );
}

#[test]
fn a_recording_is_written_or_refused_with_the_reason() {
    let d = Dir::new("record");
    let file = d.0.join("run.mcap");
    let path = file.display().to_string();
    // Not for several missions: exit 2 first.
    let (code, text) = rex(&[
        "--no-report",
        "--no-vo",
        "--record",
        path.as_str(),
        "--mission",
        "all",
    ]);
    assert_eq!(code, Some(2), "{text}");
    assert!(text.contains("--record") && text.contains(&path), "{text}");
    assert!(!file.exists(), "nothing ran");
    // A short simulated run (it does not complete: exit 1) is recorded.
    let (code, text) = rex(&["--no-report", "--no-vo", "--limit", "2", "--record", &path]);
    assert_eq!(code, Some(1), "{text}");
    assert!(text.contains(&format!("record: {path} (")), "{text}");
    let bytes = std::fs::read(&file).unwrap();
    assert!(bytes.starts_with(b"\x89MCAP0\r\n"), "an MCAP file");
    assert!(
        bytes.ends_with(b"\x89MCAP0\r\n"),
        "finished, with its footer"
    );
    // Into a folder that does not exist, or onto a folder: invalid input, the
    // path named, before anything runs.
    let missing = d.0.join("missing/run.mcap").display().to_string();
    let folder = d.0.display().to_string();
    for bad in [&missing, &folder] {
        let (code, text) = rex(&["--no-report", "--no-vo", "--limit", "1", "--record", bad]);
        assert_eq!(code, Some(2), "{text}");
        assert!(text.contains(bad.as_str()), "{text}");
        assert!(
            !text.contains("run=") && !text.contains("mission="),
            "{text}"
        );
    }
    // By default the report folder holds the run's recording; `--no-record`
    // leaves it out.
    let out = d.0.join("report").display().to_string();
    let args = [
        "--no-vo",
        "--limit",
        "1",
        "--mission",
        "square",
        "--out",
        &out,
    ];
    let (code, text) = rex(&args);
    assert_eq!(code, Some(1), "{text}");
    let recorded = d.0.join("report/square/run.mcap");
    assert!(
        text.contains(&format!("record: {} (", recorded.display())),
        "{text}"
    );
    assert!(
        std::fs::read(&recorded)
            .unwrap()
            .ends_with(b"\x89MCAP0\r\n")
    );
    std::fs::remove_file(&recorded).unwrap();
    let (code, text) = rex(&[&args[..], &["--no-record"]].concat());
    assert_eq!(code, Some(1), "{text}");
    assert!(!text.contains("record: "), "{text}");
    assert!(!recorded.exists());
    assert!(d.0.join("report/square/summary.txt").exists());
}

#[test]
fn a_replay_with_a_changed_spec_says_the_spec_differs() {
    let d = Dir::new("spec-differs");
    let spec_text =
        std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("../specs/rex.ron"))
            .unwrap();
    let spec = d.file("rex.ron", &spec_text);
    let file = d.0.join("run.mcap").display().to_string();
    let (code, text) = rex(&[
        "--no-report",
        "--no-vo",
        "--limit",
        "1",
        "--spec",
        &spec,
        "--record",
        &file,
    ]);
    assert_eq!(code, Some(1), "a mission cut short: {text}");
    // The same spec: no word about it.
    let (code, text) = rex(&["replay", &file, "--subsystem", "c1"]);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains("replay c1: equivalent"), "{text}");
    assert!(!text.contains("differs from the one recorded"), "{text}");
    // The spec file changed since (a comment is enough): the replay says so,
    // naming both files, since a divergence may come from there.
    d.file("rex.ron", &format!("// changed after the run\n{spec_text}"));
    let (code, text) = rex(&["replay", &file, "--subsystem", "c1"]);
    assert_eq!(code, Some(0), "{text}");
    assert!(
        text.contains(&format!(
            "the spec {spec} differs from the one recorded in {file}"
        )),
        "{text}"
    );
}
