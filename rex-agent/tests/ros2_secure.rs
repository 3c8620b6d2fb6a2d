//! Rex's secure deployments and a ROS 2 side that only the credentials
//! `rex credentials` made let in.
//!
//! `rex credentials --deployment split_secure_without_vo DIR --ros2-listen
//! ENDPOINT` writes the deployment's authority and certificates, the ROS 2
//! side's and its router's, and both Zenoh configurations. Against them, a
//! router and a ROS 2 node we did not write (Eclipse Zenoh's Python API,
//! PyPI `eclipse-zenoh` 1.10.2, and rosbags' Kilted type store,
//! tests/ros2_secure.py): the router opened from `ros2_router.json5` as it
//! is (as rmw_zenohd would, by `ZENOH_ROUTER_CONFIG_URI`), the node from
//! `ros2_session.json5`. Then `rex launch --deployment
//! split_secure_without_vo --credentials DIR --ros2=ENDPOINT --mission listen
//! --no-vo`: every process's bridge reaches the router over mutual TLS with
//! its own certificate.
//!
//! The node waits for Rex's subscription to `/rex/plan`, puts a plan, and
//! decodes the plan's acks and outcome: Rex exits 0 with `plans_acked=1/1`.
//! What the access control refuses is refused: the node's forged pose on
//! `/rex/pose` (Rex only publishes it) and its value on a link key of the
//! deployment (the router's log names both, and the pose never comes back to
//! a subscriber), and a client without a certificate of the authority does
//! not connect.
//!
//! Beside it, what needs no Python: the command's refusals (exit 2, nothing
//! written, keys never overwritten), and a launch with `--ros2` of a secure
//! deployment without `--credentials` refused before anything starts.
//!
//! `scripts/test -p rex-agent --test ros2_secure` installs the clients and
//! sets `EMBODIED_INTEROP_PYTHON`; plain `cargo test` skips the end-to-end
//! test, saying so.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

mod common;
#[path = "common/listen.rs"]
mod listen;
#[path = "../../agent-ros2/tests/interop/python.rs"]
mod python;
#[path = "../../agent-ros2/tests/interop/router.rs"]
mod router;
#[path = "../../agent-ros2/tests/interop/script.rs"]
mod script;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use common::{bridge_plan, own_messages};
use listen::listened;
use python::python;
use rex_agent::mission::Mission;
use rex_agent::world::WorldConfig;
use router::{Router, refusals};
use script::{Script, free_port};
use serde_json::{Value, json};

const DEPLOYMENT: &str = "split_secure";
/// `split_secure` without the camera and r11 (`--no-vo`), the partner
/// agents in a process of their own: the deployment the end-to-end test
/// launches (`split_secure` runs r11, which `--no-vo` leaves out).
const WITHOUT_VO: &str = "split_secure_without_vo";
const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/ros2_secure.py");

/// A folder of this test's own under the target's, not there yet.
fn folder(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("ros2_secure-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    dir
}

fn rex(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_rex"))
        .args(args)
        .output()
        .unwrap()
}

/// How long Rex runs \[s\]: the processes meet and reach the router in a
/// few seconds, the plan takes about 10 s from its put to its outcome; the
/// rest is for a loaded machine.
const RUN_SECONDS: u32 = 15;

/// The deployment's first port (beside the other tests' launches).
const PORT: &str = "17880";

/// The plan the node sends: 1.5 m straight ahead of Rex's start (the
/// shipped world's, checked below).
const PLAN: [(f64, f64); 3] = [(0.5, 0.0), (1.0, 0.0), (1.5, 0.0)];

/// The plan's id.
const PLAN_ID: u32 = 1;

/// A link key of the deployment (`agent_core::link::remote::link_key`:
/// agent/component/group/buffer): a2's plans to c1.
const LINK: &str = "rex/a2/c2/c1/desired_plan";

#[test]
fn credentials_are_refused_for_what_cannot_take_them_and_never_overwritten() {
    let dir = folder("refused");
    let d = dir.to_str().unwrap();
    for (args, said) in [
        (vec!["credentials", d], "--deployment NAME"),
        (
            vec!["credentials", "--deployment", "nowhere", d],
            "no deployment `nowhere`",
        ),
        (
            vec!["credentials", "--deployment", "split", d],
            "deployment `split` is unprotected",
        ),
        (
            vec![
                "credentials",
                "--deployment",
                DEPLOYMENT,
                d,
                "--ros2-listen",
                "tcp/127.0.0.1:7447",
            ],
            "--ros2-listen tcp/127.0.0.1:7447: the ROS 2 router of a secure deployment listens over mutual TLS",
        ),
    ] {
        let out = rex(&args);
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(2), "{args:?}: {stderr}");
        assert!(
            stderr.contains(&format!("rex: credentials {d}: ")) && stderr.contains(said),
            "{said}: {stderr}"
        );
        assert!(!dir.exists(), "{args:?} wrote {d}");
    }

    // Made once, with what to type next; then refused, the keys kept.
    let out = rex(&["credentials", "--deployment", DEPLOYMENT, d]);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{stdout}");
    for file in [
        "ca.pem",
        "world.key",
        "launcher.key",
        "ros2.key",
        "ros2_router.key",
    ] {
        assert!(
            stdout
                .lines()
                .any(|l| l == dir.join(file).to_str().unwrap()),
            "{file}: {stdout}"
        );
    }
    for next in [
        format!("ZENOH_ROUTER_CONFIG_URI={d}/ros2_router.json5 ros2 run rmw_zenoh_cpp rmw_zenohd"),
        format!("rex launch --deployment {DEPLOYMENT} --credentials {d} --ros2=tls/localhost:7447"),
        format!(
            "ZENOH_SESSION_CONFIG_URI={d}/ros2_session.json5 RMW_IMPLEMENTATION=rmw_zenoh_cpp ros2 topic echo /rex/pose"
        ),
    ] {
        assert!(stdout.contains(&next), "{next}: {stdout}");
    }
    let key = std::fs::read(dir.join("ca.key")).unwrap();
    let out = rex(&["credentials", "--deployment", DEPLOYMENT, d]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("ca.pem exists"), "{stderr}");
    assert_eq!(std::fs::read(dir.join("ca.key")).unwrap(), key);
}

#[test]
fn a_launch_shown_to_ros_2_without_credentials_is_refused_before_anything_starts() {
    let started = Instant::now();
    let out = rex(&[
        "launch",
        "--deployment",
        DEPLOYMENT,
        "--ros2=tls/127.0.0.1:7447",
        "--for",
        "5",
        "--quiet",
        "--no-report",
    ]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{stderr}");
    assert!(
        stderr.contains(
            "make them with `rex credentials --deployment split_secure DIR`, start the router with DIR/ros2_router.json5, and launch with --credentials DIR"
        ),
        "{stderr}"
    );
    // No process started, no credentials made for the launch.
    assert!(!stderr.contains("[world]"), "{stderr}");
    assert!(!stderr.contains("development authority"), "{stderr}");
    assert!(started.elapsed() < Duration::from_secs(5), "{stderr}");
}

#[test]
fn a_ros_2_node_with_the_credentials_rex_made_drives_the_secure_deployment_and_nothing_more() {
    let Some(python) = python() else { return };
    let world = WorldConfig::shipped().unwrap();
    assert_eq!(
        (world.start.x, world.start.y, world.start.phi),
        (0.0, 0.0, 0.0),
        "the plan drives ahead of the start"
    );
    let dir = folder("e2e");
    let d = dir.to_str().unwrap().to_owned();
    let endpoint = format!("tls/127.0.0.1:{}", free_port());
    let out = rex(&[
        "credentials",
        "--deployment",
        WITHOUT_VO,
        &d,
        "--ros2-listen",
        &endpoint,
    ]);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let router = Router::start(&python, SCRIPT, &dir.join("ros2_router.json5"));
    let points: Vec<Value> = PLAN.iter().map(|(x, y)| json!({"x": x, "y": y})).collect();
    let (plan, _) = bridge_plan(Mission::LISTEN, false);
    let mut node = Script::start(Command::new(&python).args([SCRIPT, "node"]), "the node");
    node.send(json!({
        "session_config": dir.join("ros2_session.json5"),
        "connect": endpoint,
        "ca": dir.join("ca.pem"),
        "domain": 0,
        "register": own_messages(&plan),
        "plan_topic": "/rex/plan",
        "ack_topic": "/rex/ack",
        "outcome_topic": "/rex/outcome",
        "estimate_topic": "/rex/estimate",
        "pose_topic": "/rex/pose",
        "plan": {"id": PLAN_ID, "points": points, "first": 0},
        "link_key": LINK,
    }));
    node.ready();
    let started = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_rex"))
        .args(["launch", "--deployment", WITHOUT_VO, "--credentials", &d])
        .arg(format!("--ros2={endpoint}"))
        .args(["--port", PORT, "--mission", "listen", "--no-vo"])
        .args(["--for", &RUN_SECONDS.to_string(), "--quiet", "--no-report"])
        .output()
        .unwrap();
    let took = started.elapsed();
    let answer = node.end("end");
    let log = router.stop();
    std::fs::write(dir.join("router.log"), log.join("\n")).unwrap();
    // Rex executed the plan from ROS 2.
    let (_, context) = listened("rex launch", &out, took, &answer);
    assert_eq!(answer["problems"], json!([]), "{context}");
    assert_eq!(answer["token"]["kind"], "MS", "{context}");
    // c1 runs in `locomotion`: that process's bridge is node `<node>_<process>`.
    assert_eq!(
        (&answer["token"]["node"], &answer["token"]["namespace"]),
        (&json!("rex_locomotion"), &json!("/rex")),
        "{context}"
    );

    plan_done(&answer);
    refused(&answer, &log);
}

/// What the node decoded: plan 1's acks, from received to done, and its
/// outcome, reached; and the poses Rex publishes.
fn plan_done(answer: &Value) {
    let samples = |topic: &str| -> Vec<Value> {
        answer["samples"][topic]
            .as_array()
            .unwrap_or_else(|| panic!("no samples of {topic}: {answer}"))
            .clone()
    };
    let (acks, outcomes) = (samples("/rex/ack"), samples("/rex/outcome"));
    for s in acks.iter().chain(&outcomes) {
        assert!(s.get("problem").is_none(), "{s}");
        assert_eq!(s["value"]["plan"], json!(PLAN_ID), "{s}");
    }
    let statuses: Vec<String> = acks
        .iter()
        .map(|a| a["value"]["status"].to_string().to_lowercase())
        .collect();
    assert!(
        statuses.first().is_some_and(|s| s.contains("received")),
        "{statuses:?}"
    );
    assert!(
        statuses.last().is_some_and(|s| s.contains("done")),
        "{statuses:?}"
    );
    assert_eq!(outcomes.len(), 1, "{outcomes:?}");
    assert!(
        outcomes[0]["value"]
            .to_string()
            .to_lowercase()
            .contains("reached"),
        "{outcomes:?}"
    );
    assert!(answer["plan_to_done_s"].as_f64().is_some(), "{answer}");
    // What the spec publishes reached the ROS 2 side.
    assert!(answer["counts"]["/rex/pose"].as_u64() > Some(0), "{answer}");
}

/// What the access control refused: the forged pose never came back, the
/// router said it refused the ROS 2 side's pose and link values (and never
/// a plan, nor a process's own topics), a client without certificate did
/// not connect.
fn refused(answer: &Value, log: &[String]) {
    assert_eq!(answer["forged_back"], json!([]), "{answer}");
    let anonymous = answer["anonymous"].as_str().unwrap();
    assert!(anonymous.starts_with("refused"), "{anonymous}");
    let ros2 = format!("ros2.{WITHOUT_VO}.rex");
    let refusals = refusals(log);
    let refused = |key: &str| {
        refusals
            .iter()
            .any(|r| r.0.as_deref() == Some(ros2.as_str()) && r.1 == "Put (ingress)" && r.2 == key)
    };
    let pose = answer["forged"]["pose"].as_str().unwrap();
    assert!(pose.starts_with("0/rex/pose/"), "{pose}");
    assert!(refused(pose), "{pose}: {refusals:#?}");
    assert!(refused(LINK), "{LINK}: {refusals:#?}");
    // Never the plan, nor a process's own topics.
    assert!(
        !refusals
            .iter()
            .any(|r| r.1 == "Put (ingress)" && r.2.starts_with("0/rex/plan/")),
        "{refusals:#?}"
    );
    for (process, topic) in [("world", "pose"), ("locomotion", "estimate")] {
        let cn = format!("{process}.{WITHOUT_VO}.rex");
        assert!(
            !refusals.iter().any(|r| r.0.as_deref() == Some(&cn)
                && r.1 == "Put (ingress)"
                && r.2.starts_with(&format!("0/rex/{topic}/"))),
            "{cn}: {refusals:#?}"
        );
    }
}
