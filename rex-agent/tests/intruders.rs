//! Rex's unprotected deployment (`split_without_vo`, asked for by name) against
//! an outside Zenoh peer we did not write: `tests/interop/zenoh_intruder.py`
//! on PyPI's `eclipse-zenoh` 1.10.2, in the virtual environment `scripts/test`
//! installs (it sets `EMBODIED_INTEROP_PYTHON`). Every message the intruder
//! sends is refused and counted, the counts equal what it sent, and none blocks
//! or poisons a subsystem: the mission completes with no torque clamped; a stop
//! it puts on the runtime's key stops the launch, which says who sent it.
//!
//! Plain `cargo test` stays offline: without `EMBODIED_INTEROP_PYTHON` these
//! tests say so and pass without running.

#![cfg(feature = "distributed")]
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

#[path = "../../agent-ros2/tests/interop/python.rs"]
mod python;

use std::net::{TcpListener, UdpSocket};
use std::path::PathBuf;
use std::process::{Command, Output, Stdio};

use embodied::link::shape::fingerprint;
use python::python;
use rex_agent::model::reduced::Torques;
use rex_agent::payload::Plan;

const MISSION: &str = r#"(
    name: "short",
    plans: [[(x: 1.0, y: 0.0), (x: 1.5, y: 0.5)], [(x: 1.0, y: 1.0), (x: 0.0, y: 1.0)]],
)"#;

const PLAN_KEY: &str = "rex/a2/c2/c1/desired_plan";
const TORQUE_KEY: &str = "rex/a1/e11/E1/tau";

/// A folder of this test's own, with the short mission in it.
fn scratch(name: &str) -> (PathBuf, String) {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("intruders-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let mission = dir.join("short.ron");
    std::fs::write(&mission, MISSION).unwrap();
    (dir, mission.display().to_string())
}

/// One launch at a time: each runs real-time processes on every core.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

/// A first port whose next one is free too, for TCP (the deployment is plain).
fn ports() -> u16 {
    loop {
        let first = TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .unwrap()
            .port();
        let free = (0..2).all(|k| {
            first.checked_add(k).is_some_and(|p| {
                TcpListener::bind(("127.0.0.1", p)).is_ok()
                    && UdpSocket::bind(("127.0.0.1", p)).is_ok()
            })
        });
        if free {
            return first;
        }
    }
}

/// `rex launch` of the unprotected deployment on `port`, and the intruder with
/// `extra` arguments beside it; their outputs.
fn launch_with_intruder(python: &PathBuf, name: &str, extra: &[&str]) -> (Output, Output) {
    let _one = ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner);
    let (_dir, mission) = scratch(name);
    let port = ports();
    let launch = Command::new(env!("CARGO_BIN_EXE_rex"))
        .args(["launch", "--deployment", "split_without_vo", "--no-vo"])
        .args(["--no-report", "--quiet", "--limit", "60"])
        .args(["--port", &port.to_string(), "--mission", &mission])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/interop/zenoh_intruder.py"
    );
    let intruder = Command::new(python)
        .arg(script)
        .args(["--connect", &format!("tcp/127.0.0.1:{port}")])
        .args(["--connect", &format!("tcp/127.0.0.1:{}", port + 1)])
        .args(["--system", "rex", "--processes", "world,locomotion"])
        .args(["--plan-key", PLAN_KEY])
        .args(["--plan-fingerprint", &fingerprint::<Plan>().to_string()])
        .args(["--torque-key", TORQUE_KEY])
        .args([
            "--torque-fingerprint",
            &fingerprint::<Torques>().to_string(),
        ])
        .args(extra)
        .output()
        .unwrap();
    let launched = launch.wait_with_output().unwrap();
    (launched, intruder)
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

/// The number after `key=` on the first line that has it.
fn figure(text: &str, key: &str) -> Option<u64> {
    let at = text.find(&format!("{key}="))? + key.len() + 1;
    text[at..]
        .split(|c: char| !c.is_ascii_digit())
        .next()?
        .parse()
        .ok()
}

#[test]
fn every_message_of_an_outside_peer_is_refused_counted_and_blocks_nothing() {
    let Some(python) = python() else { return };
    let (launched, intruder) = launch_with_intruder(&python, "messages", &["--count", "20"]);
    let (stdout, stderr) = (text(&launched.stdout), text(&launched.stderr));
    let said = text(&intruder.stdout);
    assert!(
        intruder.status.success(),
        "the intruder: {said}\n{}\nthe launch: {stdout}\n{stderr}",
        text(&intruder.stderr)
    );
    let sent = figure(&said, "sent total").unwrap();
    // Values of a second sender (a plan numbered 77, one stamped 2^63 ns,
    // forged torques, two 10 MB bodies), bytes of no message, and overheard
    // torques sent again.
    assert_eq!(sent, 20 + 20 + 20 + 2 + 40 + 20 + 20, "{said}");

    assert!(launched.status.success(), "{stdout}\n{stderr}");
    // Rex says at start that the deployment is unprotected.
    assert!(
        stderr.contains("deployment `split_without_vo` is unprotected"),
        "{stderr}"
    );
    let last = stdout.lines().last().unwrap_or_default();
    assert!(
        last.starts_with("mission=short plans_acked=2/2"),
        "{last}\n{stderr}"
    );
    // Nothing reached c1 or E1: no plan refused by c1 as out of sequence (a
    // fault the summary lists when there is one), no torque clamped.
    assert!(
        !stdout.contains("plans refused by c1 as numbered out of sequence"),
        "{stdout}"
    );
    assert_eq!(figure(&stdout, "clamped_torques"), Some(0), "{stdout}");
    // Every message refused is counted, by the launcher over the processes'
    // links: exactly what was sent.
    assert_eq!(
        figure(&stdout, "links refused"),
        Some(sent),
        "{stdout}\n{stderr}"
    );
    // Each receiving process names its link (c1's plans in locomotion, E1's
    // torques in the world).
    for (process, link) in [("locomotion", "desired_plan"), ("world", "tau")] {
        assert!(
            stderr
                .lines()
                .any(|l| l.starts_with(&format!("[{process}]"))
                    && l.contains(link)
                    && l.contains("messages refused")),
            "{process} does not name `{link}`:\n{stderr}"
        );
    }
}

#[test]
fn a_stop_from_an_outside_peer_stops_the_launch_and_names_its_sender() {
    let Some(python) = python() else { return };
    let (launched, intruder) =
        launch_with_intruder(&python, "stop", &["--stop-as", "an intruder at 10.0.0.66"]);
    let (stdout, stderr) = (text(&launched.stdout), text(&launched.stderr));
    assert!(
        intruder.status.success(),
        "the intruder: {}\n{}\nthe launch: {stdout}\n{stderr}",
        text(&intruder.stdout),
        text(&intruder.stderr)
    );
    // Stopped before the mission's end, and said so: not a success.
    assert_eq!(launched.status.code(), Some(1), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("a stop from an intruder at 10.0.0.66")
            || stderr.contains("a stop from an intruder at 10.0.0.66"),
        "{stdout}\n{stderr}"
    );
}
