//! The walk-through of `docs/application.md`, from `embodied new` to a launched,
//! recorded and replayed run, run command by command as the guide gives them:
//! `embodied` is this checkout's tool, `cargo` builds the new crate offline
//! against this checkout (as its README says, `--config` patching `embodied`),
//! in a scratch folder that holds the spec the first command names.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::path::{Path, PathBuf};
use std::process::Command;

/// The commands of the guide's walk-through, in order.
fn walkthrough() -> Vec<Vec<String>> {
    let guide =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/application.md"))
            .unwrap();
    let start = guide
        .find("```sh\nembodied new")
        .expect("the guide's walk-through starts with `embodied new`");
    let block = &guide[start + "```sh\n".len()..];
    let block = &block[..block.find("```").expect("the block ends")];
    block
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| l.split_whitespace().map(str::to_owned).collect())
        .collect()
}

/// `program args` in `dir`: success, standard output and error.
fn run(mut command: Command, dir: &Path) -> (Option<i32>, String, String) {
    let out = command.current_dir(dir).output().expect("it starts");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `cargo SUBCOMMAND ARGS` in the new crate: offline, with this workspace's
/// dependency versions, `embodied` patched with this checkout, and the target
/// folder the other new crates of the tests share (their dependencies built
/// once).
fn cargo(args: &[String], dir: &Path) -> Command {
    let lock = dir.join("Cargo.lock");
    if !lock.exists() {
        std::fs::copy(concat!(env!("CARGO_MANIFEST_DIR"), "/Cargo.lock"), lock).unwrap();
    }
    let mut c = Command::new(std::env::var("CARGO").unwrap_or_else(|_| "cargo".into()));
    c.arg(&args[0]).arg("--offline").args([
        "--config",
        &format!(
            "patch.crates-io.embodied.path={:?}",
            env!("CARGO_MANIFEST_DIR")
        ),
    ]);
    c.args(&args[1..]).env(
        "CARGO_TARGET_DIR",
        concat!(env!("CARGO_MANIFEST_DIR"), "/target/scaffold"),
    );
    c
}

#[test]
fn the_application_guides_walkthrough_runs_command_by_command() {
    let scratch = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("walkthrough");
    let _ = std::fs::remove_dir_all(&scratch);
    std::fs::create_dir_all(scratch.join("specs")).unwrap();
    std::fs::copy(
        concat!(env!("CARGO_MANIFEST_DIR"), "/specs/tank.ron"),
        scratch.join("specs/tank.ron"),
    )
    .unwrap();
    let mut dir = scratch.clone();
    let commands = walkthrough();
    assert!(commands.len() >= 8, "{commands:?}");
    for words in &commands {
        let line = words.join(" ");
        let (tool, args) = words.split_first().unwrap();
        let (code, stdout, stderr) = match tool.as_str() {
            "cd" => {
                dir = dir.join(&args[0]);
                assert!(dir.is_dir(), "{line}: no folder {}", dir.display());
                continue;
            }
            "embodied" => {
                let mut c = Command::new(env!("CARGO_BIN_EXE_embodied"));
                c.args(args);
                run(c, &dir)
            }
            "cargo" => run(cargo(args, &dir), &dir),
            other => {
                panic!("{line}: the walk-through runs `{other}`, which this test does not know")
            }
        };
        let said = format!("{line}\n--- stdout\n{stdout}\n--- stderr\n{stderr}");
        let last = stdout.lines().last().unwrap_or_default();
        match args
            .iter()
            .map(String::as_str)
            .collect::<Vec<_>>()
            .as_slice()
        {
            ["new", ..] => assert_eq!(code, Some(0), "{said}"),
            ["test"] => {
                assert_eq!(code, Some(0), "{said}");
                assert!(!stdout.contains("FAILED"), "{said}");
            }
            ["run", "--", "launch", rest @ ..] if rest.contains(&"--kill") => {
                // The other process may have met errors while it was away (a
                // link whose sender is gone): judged, not refused.
                assert_ne!(code, Some(2), "{said}");
                assert!(
                    stderr.contains("exited (killed by a signal); restarting it"),
                    "{said}"
                );
                assert!(last.ends_with("processes=2 restarts=1"), "{said}");
            }
            ["run", "--", "launch", ..] => {
                assert_eq!(code, Some(0), "{said}");
                assert!(
                    last.contains("ended=limit") && last.ends_with("processes=2 restarts=0"),
                    "{said}"
                );
            }
            ["run", "--", "replay", ..] => {
                assert_eq!(code, Some(0), "{said}");
                assert!(stdout.contains("replay c1: equivalent"), "{said}");
            }
            ["run", "--", flags @ ..] => {
                assert_eq!(code, Some(0), "{said}");
                assert!(last.starts_with("run=tank ended=limit"), "{said}");
                if flags.contains(&"--realtime") {
                    assert!(stdout.contains("rt_priority="), "{said}");
                }
                if flags.contains(&"--record") {
                    assert!(stdout.contains("record: run.mcap ("), "{said}");
                    assert!(dir.join("run.mcap").is_file(), "{said}");
                }
            }
            _ => panic!("{line}: a command this test does not check"),
        }
    }
}
