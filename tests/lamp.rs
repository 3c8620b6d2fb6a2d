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
    let mut walk = Walk::new(scratch);
    for args in &commands {
        let line = args.join(" ");
        if let Some((&_, args)) = args.split_last().filter(|(last, _)| *last == "&") {
            walk.start(line, args);
            continue;
        }
        walk.run(&line, args);
        println!("ok: lamp {line}");
        walk.background_ended();
    }
    let seen = &walk.seen;
    assert!(
        seen.recorded && seen.replayed >= 3 && seen.launched && seen.killed && seen.by_hand,
        "{commands:?}"
    );
    println!("the lamp walk-through: {} commands ok", commands.len());
    ExitCode::SUCCESS
}

/// What the walk-through has shown so far.
#[derive(Default)]
struct Seen {
    /// A run recorded.
    recorded: bool,
    /// Replays found equivalent.
    replayed: usize,
    /// A launch of the deployment.
    launched: bool,
    /// A launch with a process killed and restarted.
    killed: bool,
    /// Processes started by hand, in the background.
    by_hand: bool,
}

/// The walk-through under way, in its scratch folder.
struct Walk {
    scratch: PathBuf,
    seen: Seen,
    /// A command that ends with `&` runs in the background, as in a shell,
    /// until the next command has ended; it must then end with status 0 too.
    background: Vec<(String, std::process::Child)>,
}

/// One command's outcome: its status and what it printed.
struct Ran<'a> {
    code: Option<i32>,
    stdout: &'a str,
    stderr: &'a str,
    /// Its last line of stdout.
    last: &'a str,
    /// The command and what it printed, for a failure's message.
    said: String,
}

impl Walk {
    fn new(scratch: PathBuf) -> Walk {
        Walk {
            scratch,
            seen: Seen::default(),
            background: Vec::new(),
        }
    }

    /// This binary as the lamp program, in the scratch folder.
    fn lamp(&self) -> Command {
        let mut c = Command::new(std::env::current_exe().unwrap());
        c.env(PROGRAM, "1").current_dir(&self.scratch);
        c
    }

    /// Start `lamp ARGS` in the background.
    fn start(&mut self, line: String, args: &[String]) {
        let child = self
            .lamp()
            .args(args)
            .stdout(std::process::Stdio::piped())
            .stderr(std::process::Stdio::piped())
            .spawn()
            .unwrap();
        println!("started: lamp {line}");
        self.background.push((line, child));
    }

    /// Run `lamp ARGS` and check what it says, as its command calls for.
    fn run(&mut self, line: &str, args: &[String]) {
        let out = self.lamp().args(args).output().unwrap();
        let (stdout, stderr) = (
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr),
        );
        let ran = Ran {
            code: out.status.code(),
            stdout: &stdout,
            stderr: &stderr,
            last: stdout.lines().last().unwrap_or_default(),
            said: format!("lamp {line}\n--- stdout\n{stdout}\n--- stderr\n{stderr}"),
        };
        let words: Vec<&str> = args.iter().map(String::as_str).collect();
        match words.as_slice() {
            ["check", ..] => assert_eq!(ran.code, Some(0), "{}", ran.said),
            ["launch", rest @ ..] if rest.contains(&"--kill") => {
                assert_ne!(ran.code, Some(2), "{}", ran.said);
                assert!(
                    ran.stderr
                        .contains("exited (killed by a signal); restarting it"),
                    "{}",
                    ran.said
                );
                assert!(ran.last.ends_with("processes=2 restarts=1"), "{}", ran.said);
                self.seen.killed = true;
            }
            ["launch", ..] => {
                assert_eq!(ran.code, Some(0), "{}", ran.said);
                assert!(
                    ran.last.contains("ended=limit")
                        && ran.last.ends_with("processes=2 restarts=0"),
                    "{}",
                    ran.said
                );
                self.seen.launched = true;
            }
            ["replay", _, "--subsystem", subsystem] => {
                assert_eq!(ran.code, Some(0), "{}", ran.said);
                assert!(
                    ran.stdout
                        .contains(&format!("replay {subsystem}: equivalent")),
                    "{}",
                    ran.said
                );
                self.seen.replayed += 1;
            }
            flags => self.check_run(flags, &ran),
        }
    }

    /// A run of the lamp (or of one process of its deployment): its summary,
    /// its real-time figures and its recording, as its flags ask.
    fn check_run(&mut self, flags: &[&str], ran: &Ran<'_>) {
        let said = &ran.said;
        assert_eq!(ran.code, Some(0), "{said}");
        match flags.iter().position(|f| *f == "--process") {
            // One process of a deployment, started by hand: its summary,
            // and a word that the deployment is unprotected.
            Some(i) => {
                let process = flags.get(i + 1).copied().unwrap_or_default();
                assert!(
                    ran.last.starts_with(&format!("process={process} ")),
                    "{said}"
                );
                assert!(ran.stderr.contains("is unprotected"), "{said}");
            }
            None => assert!(ran.last.starts_with("run=lamp ended=limit"), "{said}"),
        }
        if flags.contains(&"--realtime") {
            assert!(ran.stdout.contains("rt_priority="), "{said}");
        }
        if flags.windows(2).any(|w| w == ["--threads", "pinned"]) {
            // The timing report names each worker's CPU (or why the OS
            // refused it).
            assert!(
                ran.stderr.contains("pinned to CPU") || ran.stderr.contains("not pinned ("),
                "{said}"
            );
        }
        if let Some(file) = flags
            .iter()
            .position(|f| *f == "--record")
            .and_then(|i| flags.get(i + 1))
        {
            assert!(ran.stdout.contains(&format!("record: {file} (")), "{said}");
            if flags.contains(&"--process") {
                // What came from the other process is in this one's file.
                let bytes = std::fs::read(self.scratch.join(file)).unwrap();
                let received = b"/received/links/";
                assert!(
                    bytes.windows(received.len()).any(|w| w == received),
                    "{file} has no /received channel"
                );
            }
            self.seen.recorded = true;
        }
    }

    /// Wait for the commands started in the background: each ends with
    /// status 0.
    fn background_ended(&mut self) {
        for (line, child) in self.background.drain(..) {
            let out = child.wait_with_output().unwrap();
            assert_eq!(
                out.status.code(),
                Some(0),
                "lamp {line}\n--- stdout\n{}\n--- stderr\n{}",
                String::from_utf8_lossy(&out.stdout),
                String::from_utf8_lossy(&out.stderr)
            );
            self.seen.by_hand = true;
            println!("ok: lamp {line}");
        }
    }
}
