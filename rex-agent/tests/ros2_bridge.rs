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

mod common;
#[path = "../../agent-ros2/tests/interop/python.rs"]
mod python;
#[path = "../../agent-ros2/tests/interop/script.rs"]
mod script;

use std::process::Command;

use common::{bridge_plan, own_messages};
use python::python;
use script::{Script, free_port};
use serde_json::json;

/// The topics Rex publishes without the camera, with their types.
const TOPICS: [(&str, &str); 6] = [
    ("/rex/pose", "geometry_msgs/msg/PoseStamped"),
    ("/rex/estimate", "rex_msgs/msg/"),
    ("/rex/reference_path", "nav_msgs/msg/Path"),
    ("/rex/imu", "sensor_msgs/msg/Imu"),
    ("/rex/ack", "rex_msgs/msg/"),
    ("/rex/outcome", "rex_msgs/msg/"),
];

#[test]
fn a_ros_2_listener_discovers_rexs_topics_and_decodes_them() {
    let Some(python) = python() else { return };
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let (plan, _) = bridge_plan("square", false);
    let mut listener = Script::start(
        Command::new(&python).arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/ros2_bridge.py")),
        "the listener",
    );
    listener.send(json!({"listen": endpoint, "register": own_messages(&plan)}));
    listener.ready();
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
    let answer = listener.end("end");
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
