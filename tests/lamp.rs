//! The lamp walk-through of `docs/application.md` ("A system built in code"),
//! run command by command as the guide gives them. The lamp of the guide's
//! macros walk-through, built in code, has the application layer's whole
//! command line from one call in its `main` (`examples/lamp/main.rs`): this
//! test is that program too (the same file), so that its commands, and the
//! processes a launch starts, run the example's code as `cargo run --example
//! lamp` would, without a second build.
//!
//! `harness = false`: the binary is the program when `EMBODIED_LAMP` is set,
//! and the walk-through otherwise.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::path::PathBuf;
use std::process::{Command, ExitCode};

#[path = "../examples/lamp/main.rs"]
mod program;

/// Set for this binary run as the lamp program (inherited by the processes a
/// launch starts).
const PROGRAM: &str = "EMBODIED_LAMP";

/// The arguments of the lamp's commands of the guide's walk-through, in order
/// (what follows `--` in `cargo run --example lamp ... -- ARGS`).
fn walkthrough() -> Vec<Vec<String>> {
    let guide =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/application.md"))
            .unwrap();
    let start = guide
        .find("```sh\ncargo run --example lamp")
        .expect("the guide's lamp walk-through starts with `cargo run --example lamp`");
    let block = &guide[start + "```sh\n".len()..];
    let block = &block[..block.find("```").expect("the block ends")];
    block
        .lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let (cargo, args) = l
                .split_once(" -- ")
                .unwrap_or_else(|| panic!("`{l}`: no `--` before the program's arguments"));
            assert!(cargo.starts_with("cargo run --example lamp"), "{l}");
            args.split_whitespace().map(str::to_owned).collect()
        })
        .collect()
}

fn main() -> ExitCode {
    if std::env::var_os(PROGRAM).is_some() {
        return program::main();
    }
    let scratch = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("lamp-walkthrough");
    let _ = std::fs::remove_dir_all(&scratch);
    std::fs::create_dir_all(&scratch).unwrap();
    let commands = walkthrough();
    assert!(commands.len() >= 7, "{commands:?}");
    let (mut recorded, mut replayed, mut launched, mut killed) = (false, 0, false, false);
    let mut by_hand = false;
    // A command that ends with `&` runs in the background, as in a shell,
    // until the next command has ended; it must then end with status 0 too.
    let mut background: Vec<(String, std::process::Child)> = Vec::new();
    for args in &commands {
        let line = args.join(" ");
        let lamp = || {
            let mut c = Command::new(std::env::current_exe().unwrap());
            c.env(PROGRAM, "1").current_dir(&scratch);
            c
        };
        if let Some((&_, args)) = args.split_last().filter(|(last, _)| *last == "&") {
            let child = lamp()
                .args(args)
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .unwrap();
            println!("started: lamp {line}");
            background.push((line, child));
            continue;
        }
        let out = lamp().args(args).output().unwrap();
        let (code, stdout, stderr) = (
            out.status.code(),
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr),
        );
        let said = format!("lamp {line}\n--- stdout\n{stdout}\n--- stderr\n{stderr}");
        let last = stdout.lines().last().unwrap_or_default();
        let words: Vec<&str> = args.iter().map(String::as_str).collect();
        match words.as_slice() {
            ["check", ..] => assert_eq!(code, Some(0), "{said}"),
            ["launch", rest @ ..] if rest.contains(&"--kill") => {
                assert_ne!(code, Some(2), "{said}");
                assert!(
                    stderr.contains("exited (killed by a signal); restarting it"),
                    "{said}"
                );
                assert!(last.ends_with("processes=2 restarts=1"), "{said}");
                killed = true;
            }
            ["launch", ..] => {
                assert_eq!(code, Some(0), "{said}");
                assert!(
                    last.contains("ended=limit") && last.ends_with("processes=2 restarts=0"),
                    "{said}"
                );
                launched = true;
            }
            ["replay", _, "--subsystem", subsystem] => {
                assert_eq!(code, Some(0), "{said}");
                assert!(
                    stdout.contains(&format!("replay {subsystem}: equivalent")),
                    "{said}"
                );
                replayed += 1;
            }
            flags => {
                assert_eq!(code, Some(0), "{said}");
                match flags.iter().position(|f| *f == "--process") {
                    // One process of a deployment, started by hand: its summary,
                    // and a word that the deployment is unprotected.
                    Some(i) => {
                        let process = flags.get(i + 1).copied().unwrap_or_default();
                        assert!(last.starts_with(&format!("process={process} ")), "{said}");
                        assert!(stderr.contains("is unprotected"), "{said}");
                    }
                    None => assert!(last.starts_with("run=lamp ended=limit"), "{said}"),
                }
                if flags.contains(&"--realtime") {
                    assert!(stdout.contains("rt_priority="), "{said}");
                }
                if let Some(file) = flags
                    .iter()
                    .position(|f| *f == "--record")
                    .and_then(|i| flags.get(i + 1))
                {
                    assert!(stdout.contains(&format!("record: {file} (")), "{said}");
                    if flags.contains(&"--process") {
                        // What came from the other process is in this one's file.
                        let bytes = std::fs::read(scratch.join(file)).unwrap();
                        let received = b"/received/links/";
                        assert!(
                            bytes.windows(received.len()).any(|w| w == received),
                            "{file} has no /received channel"
                        );
                    }
                    recorded = true;
                }
            }
        }
        println!("ok: lamp {line}");
        for (line, child) in background.drain(..) {
            let out = child.wait_with_output().unwrap();
            assert_eq!(
                out.status.code(),
                Some(0),
                "lamp {line}\n--- stdout\n{}\n--- stderr\n{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
            by_hand = true;
            println!("ok: lamp {line}");
        }
    }
    assert!(
        recorded && replayed >= 3 && launched && killed && by_hand,
        "{commands:?}"
    );
    println!("the lamp walk-through: {} commands ok", commands.len());
    ExitCode::SUCCESS
}
