//! Rex split into processes over Zenoh, started for real: `rex launch` runs the
//! spec's deployment `split_without_vo` (the world with the partner agents in one
//! process, c1 with e11 in another) on loopback, and the mission completes with
//! every plan achieved, tracking within 25% of the in-process run of the same
//! mission. A process that never appears is named in a timely error.

#![cfg(feature = "distributed")]
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::process::Command;
use std::time::Duration;

use rex_agent::a1::RexConfig;
use rex_agent::mission::Mission;
use rex_agent::run::run_mission;
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

fn figure(line: &str, key: &str) -> f64 {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(&format!("{key}=")))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {key}= in {line}"))
}

#[test]
fn rex_split_into_processes_completes_its_mission_as_in_one_process() {
    let mission = mission_file();
    let out = Command::new(env!("CARGO_BIN_EXE_rex"))
        .args([
            "launch",
            "--deployment",
            "split_without_vo",
            "--no-vo",
            "--quiet",
        ])
        .args([
            "--port",
            "17800",
            "--limit",
            "60",
            "--no-report",
            "--mission",
        ])
        .arg(&mission)
        .output()
        .unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
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
    // The same mission in one process, deterministic.
    let mut config = RexConfig::new(
        WorldConfig::shipped().unwrap(),
        Mission::load(&mission).unwrap(),
    );
    config.visual_odometry = false;
    let one = run_mission(&config, Duration::from_secs(60), Duration::MAX, |_| {}).unwrap();
    assert!(one.succeeded(), "{}", one.summary_line());
    let split = figure(last, "rms_m");
    assert!(
        split <= 1.25 * one.rms(),
        "split rms {split:.4} m vs in-process {:.4} m\n{stderr}",
        one.rms()
    );
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
