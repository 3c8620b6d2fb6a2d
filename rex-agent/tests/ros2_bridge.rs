//! `rex --ros2` against a ROS 2 listener we did not write: Eclipse Zenoh's
//! Python API (PyPI `eclipse-zenoh` 1.10.2) as the router and rosbags' Kilted
//! type store decoding the CDR (tests/ros2_bridge.py). Rex flies its square
//! mission without the camera (`--no-vo`); the listener must discover the
//! publishers of `/rex/pose`, `/rex/estimate`, `/rex/ack`, `/rex/outcome`,
//! `/rex/imu` and `/rex/reference_path` with their types and hashes (as
//! rosbags computes them: the official ones for the standard messages), decode
//! at least one value of each (Rex's own messages registered from the .msg
//! text of the bridge's plan), and see the tokens vanish at the end; Rex says
//! what it published and that its deterministic run takes nothing from
//! `/rex/plan` (tests/ros2_plans.rs: a real-time run that does).
//!
//! `scripts/test -p rex-agent --test ros2_bridge` installs the clients and
//! sets `EMBODIED_INTEROP_PYTHON`; plain `cargo test` skips, saying so. The
//! refusals before anything runs (no router, no plan) are agent-app's tests.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::io::{BufRead, BufReader, Write as _};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};

use embodied::ros2::bridge::Plan;
use rex_agent::mission::Mission;
use rex_agent::system::{RexConfig, build};
use rex_agent::world::WorldConfig;
use serde_json::{Value, json};

/// The interpreter of the interoperability environment, if installed.
fn python() -> Option<PathBuf> {
    let python = std::env::var_os("EMBODIED_INTEROP_PYTHON").map(PathBuf::from);
    if python.is_none() {
        eprintln!(
            "skipped: EMBODIED_INTEROP_PYTHON is not set (`scripts/test` installs eclipse-zenoh and rosbags, and sets it)"
        );
    }
    python
}

/// A localhost TCP port free a moment ago.
fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// The topics Rex publishes without the camera, with their types.
const TOPICS: [(&str, &str); 6] = [
    ("/rex/pose", "geometry_msgs/msg/PoseStamped"),
    ("/rex/estimate", "rex_msgs/msg/"),
    ("/rex/reference_path", "nav_msgs/msg/Path"),
    ("/rex/imu", "sensor_msgs/msg/Imu"),
    ("/rex/ack", "rex_msgs/msg/"),
    ("/rex/outcome", "rex_msgs/msg/"),
];

/// Rex's own messages (`[name, .msg text]`), from the plan of its shipped
/// spec without the camera, for the listener to register.
fn own_messages() -> Vec<Value> {
    let mut config = RexConfig::new(
        WorldConfig::shipped().unwrap(),
        Mission::shipped("square").unwrap(),
    );
    config.visual_odometry = false;
    let (system, _) = build(&config).unwrap();
    let text = std::fs::read_to_string(&config.spec).unwrap();
    let mut spec: embodied::spec::Spec = embodied::spec::options().from_str(&text).unwrap();
    let section = spec.ros2.as_mut().unwrap();
    section.publish.retain(|t| !t.buffer.starts_with("R1."));
    let plan = Plan::new(&spec, None, &system, &rex_agent::ros2::adapters()).unwrap();
    plan.topics
        .iter()
        .filter(|t| t.messages.name().package == "rex_msgs")
        .map(|t| json!([t.messages.name().to_string(), t.messages.msg_text()]))
        .collect()
}

#[test]
fn a_ros_2_listener_discovers_rexs_topics_and_decodes_them() {
    let Some(python) = python() else { return };
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let listener = Listener::start(&python, &endpoint, &own_messages());
    let out = Command::new(env!("CARGO_BIN_EXE_rex"))
        .args(["--no-vo", "--mission", "square", "--no-report", "--quiet"])
        .arg(format!("--ros2={endpoint}"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{stderr}");
    let report = stderr
        .lines()
        .find(|l| l.starts_with("ros2: published="))
        .unwrap_or_else(|| panic!("no report line: {stderr}"));
    // The deterministic run goes ~50 times faster than real time: it waits
    // for the publishing thread rather than drop a value.
    assert!(
        report.contains(
            " dropped=0 encode_failures=0 put_failures=0 received=0 delivered=0 refused=0 lost=0"
        ),
        "{report}"
    );
    // A deterministic run takes nothing from ROS 2, and says so.
    assert!(
        stderr.contains("/rex/plan")
            && stderr.contains("a deterministic run is not on the wall clock"),
        "{stderr}"
    );
    let answer = listener.end();
    assert_eq!(answer["problems"], json!([]), "{answer}");
    assert_eq!(answer["all_vanished"], json!(true), "{answer}");
    for (topic, ty) in TOPICS {
        let publisher = answer["publishers"]
            .as_array()
            .unwrap()
            .iter()
            .find(|p| p["topic"] == topic)
            .unwrap_or_else(|| panic!("no publisher of {topic}: {answer}"));
        let name = publisher["type"].as_str().unwrap();
        assert!(name.starts_with(ty), "{topic}: {publisher}");
        assert_eq!(publisher["hash"], publisher["rosbags_hash"], "{topic}");
        let seen = &answer["topics"][topic];
        assert_eq!(seen["problems"], json!([]), "{topic}: {seen}");
        assert!(seen["samples"].as_u64() >= Some(1), "{topic}: {seen}");
        assert!(seen["first"].is_object(), "{topic}: {seen}");
    }
    let pose = &answer["topics"]["/rex/pose"]["first"];
    assert_eq!(pose["header"]["frame_id"], "map", "{pose}");
    let path = &answer["topics"]["/rex/reference_path"]["first"];
    assert!(!path["poses"].as_array().unwrap().is_empty(), "{path}");
}

/// The listener (tests/ros2_bridge.py), running; killed if the test fails
/// before its end.
struct Listener {
    child: Child,
    to: ChildStdin,
    from: BufReader<ChildStdout>,
}

impl Listener {
    /// Start it as the router at `endpoint`, with Rex's own messages
    /// `register` (`[name, .msg text]`), and wait until it listens.
    fn start(python: &Path, endpoint: &str, register: &[Value]) -> Self {
        let mut child = Command::new(python)
            .arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/ros2_bridge.py"))
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let mut to = child.stdin.take().unwrap();
        let mut from = BufReader::new(child.stdout.take().unwrap());
        writeln!(to, "{}", json!({"listen": endpoint, "register": register})).unwrap();
        let mut line = String::new();
        from.read_line(&mut line).unwrap();
        assert_eq!(line.trim(), "ready", "the listener did not start");
        Self { child, to, from }
    }

    /// Tell it Rex is done; what it saw.
    fn end(mut self) -> Value {
        writeln!(self.to, "end").unwrap();
        let mut line = String::new();
        self.from.read_line(&mut line).unwrap();
        assert!(self.child.wait().unwrap().success());
        serde_json::from_str(&line).unwrap()
    }
}

impl Drop for Listener {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
