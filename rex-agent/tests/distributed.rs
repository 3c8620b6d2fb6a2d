//! Rex split into processes over Zenoh, started for real: `rex launch` runs the
//! spec's deployment `split_without_vo` (the world with the partner agents in one
//! process, c1 with e11 in another) on loopback, and the mission completes with
//! every plan achieved, tracking within 25% of the in-process run of the same
//! mission (judged on a run that kept real time: one whose processes overran
//! at most ~2.5 % of the plant's steps, up to three attempts). A process that
//! never appears is named in a timely error.
//!
//! Faults, injected by `rex launch --kill PROCESS@SECONDS` (SIGKILL, as a crash):
//! c1 with e11 killed in the middle of a mission are restarted, the platform's
//! watchdog holds it meanwhile, and the mission completes with no plan lost and
//! no fragment executed twice; r11 killed, a1 goes on without visual odometry
//! and reports the outage.
//!
//! The launches run one at a time (each is several real-time processes).

#![cfg(feature = "distributed")]
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::process::Command;
use std::time::Duration;

use rex_agent::mission::Mission;
use rex_agent::run::run_mission;
use rex_agent::system::RexConfig;
use rex_agent::world::WorldConfig;

const MISSION: &str = r#"(
    name: "short",
    plans: [[(x: 1.0, y: 0.0), (x: 1.5, y: 0.5)], [(x: 1.0, y: 1.0), (x: 0.0, y: 1.0)]],
)"#;

fn mission_file() -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("rex-distributed-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("short.ron");
    std::fs::write(&path, MISSION).unwrap();
    path
}

/// One launch at a time: each runs real-time processes on every core.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// `rex launch` of the short mission with `args`; its stdout and stderr, after
/// checking that it succeeded.
fn launch(args: &[&str]) -> (String, String) {
    let mission = mission_file();
    let out = Command::new(env!("CARGO_BIN_EXE_rex"))
        .arg("launch")
        .args(args)
        .args(["--limit", "90", "--no-report", "--mission"])
        .arg(&mission)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(
        out.status.success(),
        "rex launch {args:?} failed:\n{stdout}\n{stderr}"
    );
    (stdout, stderr)
}

fn line<'a>(text: &'a str, start: &str) -> &'a str {
    text.lines()
        .find(|l| l.starts_with(start))
        .unwrap_or_else(|| panic!("no line `{start}...` in\n{text}"))
}

#[test]
fn killing_locomotion_mid_mission_loses_no_plan_and_repeats_no_fragment() {
    let _one = one_at_a_time();
    // At 4 s plan 1 is acknowledged (early: its last fragment runs) and plan 2
    // sent: both are lost with c1.
    let (stdout, stderr) = launch(&[
        "--deployment",
        "split_without_vo",
        "--no-vo",
        "--port",
        "17840",
        "--kill",
        "locomotion@4",
    ]);
    let last = stdout.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("mission=short plans_acked=2/2"),
        "every plan achieved (acknowledged, reached, confirmed by the truth):\n{stdout}\n{stderr}"
    );
    assert_eq!(figure(last, "restarts"), 1.0, "{last}");
    assert!(
        stderr.contains("[locomotion] exited (killed by a signal); restarting it"),
        "{stderr}"
    );
    let recovery = line(&stdout, "recovery ");
    assert_eq!(figure(recovery, "c1_restarts"), 1.0, "{recovery}");
    assert!(figure(recovery, "plans_resent") >= 1.0, "{recovery}");
    assert_eq!(figure(recovery, "fragments_repeated"), 0.0, "{recovery}");
    // The platform's watchdog held it while nobody commanded it.
    let faults = line(&stdout, "faults: ");
    assert!(
        faults.contains("platform steps at zero torque (command watchdog)"),
        "{faults}"
    );
    // The restarted process joined the running deployment: no false gap.
    assert!(!stderr.contains("sequence gap"), "{stderr}");
    // Each plan was acknowledged done, and reported reached once.
    for plan in ["plan=1", "plan=2"] {
        let reached = stdout
            .lines()
            .filter(|l| l.starts_with("outcome ") && l.contains(plan))
            .collect::<Vec<_>>();
        assert_eq!(reached.len(), 1, "{plan}: {reached:?}");
        assert!(reached[0].contains("reached its last point"), "{reached:?}");
    }
}

#[test]
fn killing_the_camera_process_a1_goes_on_without_visual_odometry_and_says_so() {
    let _one = one_at_a_time();
    let (stdout, stderr) = launch(&[
        "--deployment",
        "split",
        "--port",
        "17860",
        "--kill",
        "vision@3",
    ]);
    let last = stdout.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("mission=short plans_acked=2/2"),
        "{stdout}\n{stderr}"
    );
    assert_eq!(figure(last, "processes"), 3.0, "{last}");
    assert_eq!(figure(last, "restarts"), 1.0, "{last}");
    let recovery = line(&stdout, "recovery ");
    assert!(figure(recovery, "vo_outages") >= 1.0, "{recovery}");
    assert_eq!(figure(recovery, "c1_restarts"), 0.0, "{recovery}");
    let faults = line(&stdout, "faults: ");
    assert!(faults.contains("visual odometry lost at"), "{faults}");
    // The link that lost its sender was reported by the process that reads it.
    assert!(
        stderr.contains("`r11.c1.A4x4 -> c1.r11.A4x4`")
            && stderr.contains("the sending process `vision` is gone"),
        "{stderr}"
    );
}

fn figure(line: &str, key: &str) -> f64 {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(&format!("{key}=")))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {key}= in {line}"))
}

/// Overruns of every process of a run together, at most, for its tracking to
/// be compared with the simulated run's: about 2.5 % of the plant's steps.
/// Beyond, the machine did not give the real-time threads their CPU (a busy
/// or descheduled virtual machine: runs here overran 0-140 times when it did,
/// 3 000 and more when not), and the tracking says nothing about the
/// deployment.
const REAL_TIME_OVERRUNS: f64 = 500.0;

#[test]
fn rex_split_into_processes_completes_its_mission_as_in_one_process() {
    let _one = one_at_a_time();
    let mission = mission_file();
    let record = mission.with_file_name("split.mcap");
    // The same mission in one process, deterministic.
    let mut config = RexConfig::new(
        WorldConfig::shipped().unwrap(),
        Mission::load(&mission).unwrap(),
    );
    config.visual_odometry = false;
    let one = run_mission(&config, Duration::from_secs(60), Duration::MAX, |_| {}).unwrap();
    assert!(one.succeeded(), "{}", one.summary_line());
    // Every attempt completes the mission, reports every process's part and
    // records a run that replays; the tracking is compared on the first that
    // kept real time (three attempts at most).
    let mut lost = Vec::new();
    for attempt in 1..=3 {
        let (stdout, stderr) = split_run(&mission, &record);
        recorded_in_parts_merged_and_replayed(&record, &stdout);
        let last = stdout.lines().last().unwrap_or_default();
        let overruns: f64 = ["world", "locomotion"]
            .iter()
            .map(|p| figure(line(&stderr, &format!("[{p}] process={p} ")), "overruns"))
            .sum();
        if overruns > REAL_TIME_OVERRUNS {
            eprintln!(
                "attempt {attempt}: {overruns} overruns, the machine did not keep real time; again"
            );
            lost.push(overruns);
            continue;
        }
        let split = figure(last, "rms_m");
        assert!(
            split <= 1.25 * one.rms(),
            "split rms {split:.4} m vs in-process {:.4} m\n{stderr}",
            one.rms()
        );
        return;
    }
    panic!(
        "no attempt kept real time (overruns {lost:?}, at most {REAL_TIME_OVERRUNS} expected): this machine cannot run real-time processes now"
    );
}

/// One launch of the split deployment, recorded to `record`: it completes the
/// mission, both processes report, and their counters reach the summary.
fn split_run(mission: &std::path::Path, record: &std::path::Path) -> (String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_rex"))
        .args([
            "launch",
            "--deployment",
            "split_without_vo",
            "--no-vo",
            "--quiet",
        ])
        .arg("--record")
        .arg(record)
        .args([
            "--port",
            "17800",
            "--limit",
            "60",
            "--no-report",
            "--mission",
        ])
        .arg(mission)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    let last = stdout.lines().last().unwrap_or_default();
    assert!(
        out.status.success(),
        "rex launch failed:\n{stdout}\n{stderr}"
    );
    assert!(last.starts_with("mission=short plans_acked=2/2"), "{last}");
    assert_eq!(figure(last, "processes"), 2.0, "{last}");
    assert_eq!(figure(last, "restarts"), 0.0, "{last}");
    // The counters of both processes reach the summary: c1's planner (in one
    // process) and e11's fragments (the same), the motion capture (the other).
    let counters = stdout
        .lines()
        .find(|l| l.starts_with("fragments planned="))
        .expect(&stdout);
    assert!(figure(counters, "planned") > 0.0, "{counters}");
    assert_eq!(
        figure(counters, "completed"),
        figure(counters, "received"),
        "{counters}"
    );
    let health = stdout
        .lines()
        .find(|l| l.contains("mocap_delivered="))
        .expect(&stdout);
    assert!(figure(health, "mocap_delivered") > 0.0, "{health}");
    // Both processes ran their part and said so.
    for p in ["world", "locomotion"] {
        assert!(
            stderr.contains(&format!("[{p}] process={p} ")),
            "no report of `{p}`:\n{stderr}"
        );
    }
    (stdout, stderr)
}

/// The launch recorded each process's part beside `record` and merged them
/// into it; the merged run replays equivalent, subsystem by subsystem, in
/// whichever process each ran.
fn recorded_in_parts_merged_and_replayed(record: &std::path::Path, stdout: &str) {
    use embodied::record::{Recording, merge};
    let merged_line = line(stdout, "record: ");
    assert!(
        merged_line.contains("merged from 2 processes"),
        "{merged_line}"
    );
    let parts: Vec<_> = ["world", "locomotion"]
        .iter()
        .map(|p| record.with_file_name(format!("split.{p}.mcap")))
        .collect();
    let mut messages = 0;
    for (part, process) in parts.iter().zip(["world", "locomotion"]) {
        let r = Recording::open(part).unwrap();
        assert!(r.finished(), "{}", part.display());
        assert_eq!(r.metadata["process"]["name"], process);
        messages += r.messages.len();
    }
    let whole = Recording::open(record).unwrap();
    assert!(whole.finished());
    assert_eq!(
        whole.messages.len(),
        messages,
        "every message of every part"
    );
    assert!(
        whole
            .messages
            .windows(2)
            .all(|w| w[0].log_time <= w[1].log_time),
        "in time order"
    );
    // c1 ran in `locomotion` with its own incarnation number, kept for the replay.
    assert!(whole.metadata["process/locomotion"].contains_key("boot"));
    let end = &whole.metadata["end"];
    assert_eq!(end["processes"], "world, locomotion");
    // The same merge by the library gives the same file's content.
    let again = record.with_file_name("split-again.mcap");
    let summary = merge(&parts, &again).unwrap();
    assert_eq!(summary.messages as usize, messages);
    for node in ["c1", "e11", "c2", "c3", "r31"] {
        let out = Command::new(env!("CARGO_BIN_EXE_rex"))
            .arg("replay")
            .arg(record)
            .args(["--subsystem", node])
            .output()
            .unwrap();
        let text = String::from_utf8_lossy(&out.stdout);
        assert!(
            out.status.success()
                && text.contains(&format!(
                    "replay {node}: equivalent: {}",
                    end[&format!("iterations/{node}")]
                )),
            "{node}:\n{text}\n{}",
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

#[test]
fn a_process_that_never_appears_is_named_and_the_wait_ends() {
    let mission = mission_file();
    let started = std::time::Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_rex"))
        .args([
            "--deployment",
            "split_without_vo",
            "--process",
            "locomotion",
            "--no-vo",
        ])
        .args(["--port", "17820", "--wait", "2", "--no-report", "--mission"])
        .arg(&mission)
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{stderr}");
    assert!(
        stderr.contains("`world`") && stderr.contains("tcp/127.0.0.1:17820"),
        "the error names the missing process and its endpoint:\n{stderr}"
    );
    assert!(
        started.elapsed() < Duration::from_secs(60),
        "the wait ended"
    );
}
