//! The fleet launched as a deployment over Zenoh (issue 57), for real: four
//! robots of the short warehouse in `grouped_without_vo` (the shared world
//! with the partner agents, the fleet's one `c2` among them, in `world`, the
//! robots' c1 and e11 two by two in `robots_0` and `robots_1`), `robots_1`
//! killed (SIGKILL, as a crash) in the middle of the missions and restarted,
//! the run recorded. Every plan of every robot is judged against the
//! simulation's truth (never a false success), the parts of the recording
//! (both starts of `robots_1` among them) are merged; on a run that kept real
//! time (up to three attempts: one whose world process overran or dropped
//! samples may fail its plans honestly) every plan is achieved, the one `c2`
//! hears the restarted robots' c1 come back and sends those robots, and only
//! them, their lost plans again, no fragment runs twice, and the killed
//! process's c1 and the world's c2 replay equivalent from the merged file.
//! Invalid input is refused with exit 2 first.
//!
//! `harness = false`: this binary is the `fleet` example (the same file,
//! `examples/fleet.rs`) when `REX_FLEET_PROGRAM` is set, so that the launch
//! and the processes it starts run the example's code as `cargo run
//! --example fleet` would, without a second build; the test otherwise.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::path::{Path, PathBuf};
use std::process::{Command, ExitCode, Output};
use std::time::Instant;

#[path = "../examples/fleet.rs"]
mod program;

/// Set for this binary run as the fleet program (inherited by the processes
/// a launch starts).
const PROGRAM: &str = "REX_FLEET_PROGRAM";

fn main() -> ExitCode {
    if std::env::var_os(PROGRAM).is_some() {
        return program::main();
    }
    let scratch = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("fleet-launch");
    let _ = std::fs::remove_dir_all(&scratch);
    std::fs::create_dir_all(&scratch).unwrap();
    let started = Instant::now();
    invalid_input_is_refused_with_exit_2(&scratch);
    println!("ok: invalid input refused with exit 2");
    let record = a_launched_fleet_with_a_killed_process_achieves_every_plan(&scratch);
    println!("ok: the fleet launched, robots_1 killed and restarted, every plan judged");
    the_killed_process_replays_equivalent(&scratch, &record);
    println!(
        "ok: the killed process's c1 replays equivalent ({:.1} s in all)",
        started.elapsed().as_secs_f64()
    );
    ExitCode::SUCCESS
}

/// This binary as the fleet program, in `dir`.
fn fleet(dir: &Path, args: &[&str]) -> (Output, String, String) {
    let out = Command::new(std::env::current_exe().unwrap())
        .env(PROGRAM, "1")
        .current_dir(dir)
        .args(args)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    (out, stdout, stderr)
}

fn figure(line: &str, key: &str) -> f64 {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(&format!("{key}=")))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {key}= in {line}"))
}

fn line<'a>(text: &'a str, start: &str) -> &'a str {
    text.lines()
        .find(|l| l.starts_with(start))
        .unwrap_or_else(|| panic!("no line `{start}...` in\n{text}"))
}

fn invalid_input_is_refused_with_exit_2(dir: &Path) {
    for (args, says) in [
        (
            &[
                "launch",
                "--deployment",
                "grouped_without_vo",
                "--robots",
                "0",
            ][..],
            "--robots 0",
        ),
        (
            &[
                "launch",
                "--deployment",
                "grouped_without_vo",
                "--per-process",
                "0",
            ][..],
            "--per-process 0",
        ),
        (
            &["launch", "--deployment", "nowhere"][..],
            "no deployment `nowhere`",
        ),
        (
            &[
                "launch",
                "--deployment",
                "grouped_without_vo",
                "--kill",
                "robots_9@1",
            ][..],
            "no process `robots_9`",
        ),
        (&["--robots", "4,x"][..], "--robots: `x`"),
    ] {
        let (out, stdout, stderr) = fleet(dir, args);
        assert_eq!(out.status.code(), Some(2), "{args:?}:\n{stdout}\n{stderr}");
        assert!(
            stderr.contains(says),
            "{args:?} should say `{says}`:\n{stderr}"
        );
    }
}

/// Overruns of the world process, at most, for a failed plan to be blamed on
/// the machine rather than the fleet: the world steps every platform at
/// 1 kHz on one thread, and on a machine that does not give it its CPU (a
/// busy or descheduled virtual machine) the robots' tracking degrades until
/// e11 stops them, and the judge says FAILED. Runs here overran 19 times
/// with four robots when they kept real time.
const REAL_TIME_OVERRUNS: f64 = 100.0;

/// The launch, up to three times: every attempt judges every plan against the
/// truth (never a false success), restarts the killed process and merges the
/// recording; the first that kept real time must achieve every plan. The
/// recording of that attempt.
fn a_launched_fleet_with_a_killed_process_achieves_every_plan(dir: &Path) -> PathBuf {
    let mut lost = Vec::new();
    for attempt in 1..=3 {
        let record = dir.join(format!("fleet-{attempt}.mcap"));
        let (out, stdout, stderr) = launch(dir, &record);
        let said = format!("{stdout}\n{stderr}");
        let last = stdout.lines().last().unwrap_or_default();
        assert!(last.starts_with("fleet robots=4 plans=8 "), "{said}");
        assert!(last.ends_with("processes=3 restarts=1"), "{said}");
        // Every plan of every robot judged against the truth; none claimed
        // achieved that was not.
        for robot in 0..4 {
            for plan in 1..=2 {
                let judged = line(&stdout, &format!("robot {robot}: plan {plan}: "));
                assert!(!judged.contains("FALSE SUCCESS"), "{judged}\n{said}");
            }
        }
        assert!(
            stderr.contains("[robots_1] exited (killed by a signal); restarting it"),
            "{said}"
        );
        // Every process's part, both starts of robots_1 among them, merged.
        let merged = line(&stdout, "record: ");
        assert!(
            merged.contains("merged from 3 processes and 1 restarts"),
            "{merged}"
        );
        let world = line(&stderr, "[world] process=world ");
        if out.status.code() != Some(0)
            && (figure(world, "overruns") > REAL_TIME_OVERRUNS
                || figure(world, "sample_dropped") > 0.0)
        {
            eprintln!("attempt {attempt}: the machine did not keep real time ({world}); again");
            lost.push(world.to_owned());
            continue;
        }
        assert_eq!(out.status.code(), Some(0), "{said}");
        for robot in 0..4 {
            for plan in 1..=2 {
                let judged = line(&stdout, &format!("robot {robot}: plan {plan}: "));
                assert!(judged.contains(": achieved"), "{judged}\n{said}");
            }
        }
        assert_eq!(figure(last, "achieved"), 8.0, "{last}");
        // Both robots of the killed process were restarted; the one c2 heard
        // it and sent again what was lost to them, and nothing to the robots
        // of the process that ran on; no fragment ran twice.
        assert_eq!(figure(last, "c1_restarts"), 2.0, "{last}");
        assert_eq!(figure(last, "fragments_repeated"), 0.0, "{last}");
        let recovery = |robot: usize| line(&stdout, &format!("robot {robot}: recovery "));
        for robot in [0, 1] {
            let r = recovery(robot);
            assert_eq!(figure(r, "c1_restarts"), 0.0, "{r}");
            assert_eq!(figure(r, "plans_resent"), 0.0, "{r}");
        }
        for robot in [2, 3] {
            let r = recovery(robot);
            assert_eq!(figure(r, "c1_restarts"), 1.0, "{r}");
            assert_eq!(figure(r, "fragments_repeated"), 0.0, "{r}");
        }
        let resent = figure(recovery(2), "plans_resent") + figure(recovery(3), "plans_resent");
        assert_eq!(resent, figure(last, "plans_resent"), "{said}");
        // Killed at 4 s, in the middle of their missions: a plan of theirs
        // was not settled.
        assert!(resent >= 1.0, "{said}");
        assert!(figure(last, "min_separation_m") >= 0.9, "{last}");
        return record;
    }
    panic!(
        "no attempt kept real time ({lost:?}; at most {REAL_TIME_OVERRUNS} overruns and no sample dropped expected): this machine cannot run the fleet's processes now"
    );
}

/// One launch of four robots in `grouped_without_vo`, `robots_1` killed at
/// 4 s, recorded to `record`.
fn launch(dir: &Path, record: &Path) -> (Output, String, String) {
    fleet(
        dir,
        &[
            "launch",
            "--deployment",
            "grouped_without_vo",
            "--robots",
            "4",
            "--per-process",
            "2",
            "--short",
            "--kill",
            "robots_1@4",
            "--record",
            record.to_str().unwrap(),
            "--port",
            "17940",
            "--for",
            "60",
            "--quiet",
        ],
    )
}

fn the_killed_process_replays_equivalent(dir: &Path, record: &Path) {
    let record = record.to_str().unwrap();
    // c1_3 ran in robots_1: its first start was killed (its part cut short,
    // not replayable), its second replays equivalent.
    let (out, stdout, stderr) = fleet(dir, &["replay", record, "--subsystem", "c1_3"]);
    let said = format!("{stdout}\n{stderr}");
    assert_eq!(out.status.code(), Some(0), "{said}");
    assert!(
        stdout.contains("replay c1_3 (start 1 of process `robots_1`): equivalent"),
        "{said}"
    );
    assert!(
        stdout.contains("replay c1_3 (start 0 of process `robots_1`): not replayed"),
        "{said}"
    );
    // The fleet's one c2, of the world process, which ran once.
    let (out, stdout, stderr) = fleet(dir, &["replay", record, "--subsystem", "c2"]);
    assert_eq!(out.status.code(), Some(0), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("replay c2: equivalent"),
        "{stdout}\n{stderr}"
    );
}
