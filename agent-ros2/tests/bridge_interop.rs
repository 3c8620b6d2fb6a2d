//! The bridge against a ROS 2 listener we did not write: Eclipse Zenoh's
//! Python API (PyPI `eclipse-zenoh` 1.10.2) as the router, rosbags' Kilted
//! type store decoding the CDR (tests/bridge_interop.py). A small system runs
//! in the deterministic executor with the bridge as its observer (and in the
//! real-time one, each thread with its own tap); the
//! listener must discover the node and each publisher (topic, type, hash as
//! rosbags computes it, QoS), see them vanish at the end, and decode every
//! value sent, numbered 1..n without a gap, each with a 33-byte attachment
//! carrying its publisher's GID.
//!
//! `scripts/test -p agent-ros2 --test bridge_interop` installs the clients
//! and sets `EMBODIED_INTEROP_PYTHON`; plain `cargo test` skips, saying so.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

mod common;
#[path = "interop/python.rs"]
mod python;
#[path = "interop/script.rs"]
mod script;

use std::path::Path;
use std::process::Command;
use std::time::{Duration, SystemTime};

use agent_core::{ExecConfig, Executor, RealTime, RtConfig, System};
use agent_ros2::bridge::{Bridge, BridgeOptions, BridgeReport, Plan, SessionOptions};
use agent_ros2::types::standard::builtin_interfaces::Time;
use common::{adapters, pose_at, spec, status_at, system};
use python::python;
use script::{Script, free_port};
use serde_json::{Value, json};

/// The run's instant zero on the wall clock: 1.7e9 s after the epoch.
const EPOCH_S: u64 = 1_700_000_000;

#[test]
fn a_ros_2_listener_discovers_the_publishers_and_decodes_every_value() {
    let Some(python) = python() else { return };
    let seen = exchange(&python, |system, bridge| {
        let mut exec = Executor::with_observer(system, ExecConfig::default(), bridge);
        exec.run_for(Duration::from_millis(200)).unwrap();
        exec.into_observer().finish().unwrap()
    });
    for (k, value) in seen.values[0].iter().enumerate() {
        assert_eq!(value, &pose_message(u32::try_from(k).unwrap()), "pose {k}");
    }
    statuses_in_order(&seen.values[1]);
}

/// The same from a real-time run: the nodes' threads each hand their values
/// to the bridge through a tap of their own.
#[test]
fn a_real_time_run_is_published_from_its_threads() {
    let Some(python) = python() else { return };
    let seen = exchange(&python, |system, bridge| {
        let mut rt = RealTime::new(system, RtConfig::default());
        rt.observe(bridge.threads());
        rt.start(Duration::from_millis(300))
            .unwrap()
            .join()
            .unwrap();
        bridge.finish().unwrap()
    });
    for (k, value) in seen.values[0].iter().enumerate() {
        let expected = pose_message(u32::try_from(k).unwrap());
        assert_eq!(value["pose"], expected["pose"], "pose {k}");
        assert_eq!(value["header"]["frame_id"], "map");
        assert!(value["header"]["stamp"]["sec"].as_u64() >= Some(EPOCH_S));
    }
    statuses_in_order(&seen.values[1]);
}

/// The status messages are `status_at(0..)`, in order.
fn statuses_in_order(values: &[Value]) {
    for (k, value) in values.iter().enumerate() {
        let k = u32::try_from(k).unwrap();
        let expected = serde_json::to_value(status_at(k)).unwrap();
        assert_eq!(value, &expected, "status {k}");
    }
}

/// What the listener decoded, per topic of the plan (pose, status).
struct Seen {
    values: Vec<Vec<Value>>,
}

/// Start the listener and a bridge connected to it, `run` the system with
/// the bridge, and check what the listener saw: our tokens, with their names,
/// types, hashes and QoS, gone at the end; on each topic every value
/// published, numbered 1..n, from the topic's GID, stamped within the run.
fn exchange(python: &Path, run: impl FnOnce(System, Bridge) -> BridgeReport) -> Seen {
    let system = system();
    let plan = Plan::new(&spec(common::ROS2), None, &system, &adapters()).unwrap();
    let register: Vec<Value> = plan
        .topics
        .iter()
        .filter(|t| t.messages.name().package == "bridge_test_msgs")
        .map(|t| json!([t.messages.name().to_string(), t.messages.msg_text()]))
        .collect();
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut listener = Script::start(
        Command::new(python).arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/bridge_interop.py"
        )),
        "the listener",
    );
    listener.send(json!({"listen": endpoint, "domain": 0, "register": register}));
    listener.ready();
    let options = BridgeOptions {
        session: SessionOptions::client(&endpoint),
        epoch: Some(SystemTime::UNIX_EPOCH + Duration::from_secs(EPOCH_S)),
        ..BridgeOptions::default()
    };
    let before = wall_ns();
    let bridge = Bridge::start(plan, options).unwrap();
    assert!(bridge.wait_for_subscribers(Duration::from_secs(10)));
    let tokens: Vec<String> = std::iter::once(bridge.node_token().key_expr())
        .chain(bridge.publisher_tokens().iter().map(|t| t.key_expr()))
        .collect();
    let topics: Vec<(String, String)> = bridge
        .plan()
        .topics
        .iter()
        .zip(bridge.publisher_tokens())
        .map(|(t, token)| (t.key.to_string(), token.gid().to_string()))
        .collect();
    let report = run(system, bridge);
    let after = wall_ns();
    eprintln!("{report:?}");
    assert_eq!(report.dropped(), 0);
    assert_eq!(report.encode_failures(), 0);
    assert_eq!(report.put_failures(), 0);
    let counts: Vec<u64> = report.topics.iter().map(|t| t.published).collect();
    assert!(counts.iter().all(|&n| n >= 20), "{counts:?}");
    let expect: serde_json::Map<String, Value> = topics
        .iter()
        .map(|(key, _)| key.clone())
        .zip(counts.iter().map(|&n| json!(n)))
        .collect();
    let answer = listener.end(json!({"expect": expect, "tokens": tokens.len()}));
    assert_eq!(answer["problems"], json!([]), "{answer}");
    discovered(&answer, &tokens);
    let values = topics
        .iter()
        .zip(&counts)
        .map(|((key, gid), &n)| received(&answer["samples"][key], n, gid, (before, after)))
        .collect();
    Seen { values }
}

/// The PoseStamped of step `k`: the adapter's, stamped with the epoch plus
/// the value's instant (k × 10 ms), as plain JSON.
fn pose_message(k: u32) -> Value {
    let pose = pose_at(k);
    let stamp = Time {
        sec: i32::try_from(EPOCH_S).unwrap(),
        nanosec: k * 10_000_000,
    };
    json!({
        "header": {"stamp": stamp, "frame_id": "map"},
        "pose": {
            "position": {"x": pose.x, "y": pose.y, "z": 0.0},
            "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
        },
    })
}

/// The wall clock \[ns since the UNIX epoch\].
fn wall_ns() -> i64 {
    let since = SystemTime::now()
        .duration_since(SystemTime::UNIX_EPOCH)
        .unwrap();
    i64::try_from(since.as_nanos()).unwrap()
}

/// The listener saw exactly our tokens, with the names, types, rosbags'
/// hashes and QoS of the plan, and saw each vanish.
fn discovered(answer: &Value, tokens: &[String]) {
    let seen = answer["tokens"].as_array().unwrap();
    let mut keys: Vec<&str> = seen.iter().map(|t| t["key"].as_str().unwrap()).collect();
    keys.sort_unstable();
    let mut ours: Vec<&str> = tokens.iter().map(String::as_str).collect();
    ours.sort_unstable();
    assert_eq!(keys, ours);
    let vanished: Vec<&str> = answer["vanished"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k.as_str().unwrap())
        .collect();
    assert!(ours.iter().all(|k| vanished.contains(k)), "{vanished:?}");
    let by_kind =
        |kind: &str| -> Vec<&Value> { seen.iter().filter(|t| t["kind"] == kind).collect() };
    let node = by_kind("NN");
    assert_eq!(node.len(), 1);
    assert_eq!(node[0]["node"], "bridge");
    assert_eq!(node[0]["namespace"], "/test");
    let publishers = by_kind("MP");
    assert_eq!(publishers.len(), 2);
    let topic = |name: &str| *publishers.iter().find(|t| t["topic"] == name).unwrap();
    let pose = topic("/test/pose");
    assert_eq!(pose["type"], "geometry_msgs/msg/PoseStamped");
    // A sample link: best effort (2), keep-last 1, volatile (2).
    assert_eq!(
        pose["qos"],
        json!({"reliability": 2, "durability": 2, "history": 1, "depth": 1})
    );
    let status = topic("/test/bridge/status");
    assert_eq!(status["type"], "bridge_test_msgs/msg/Status");
    // A queue of 8: reliable (1), keep-last 8.
    assert_eq!(
        status["qos"],
        json!({"reliability": 1, "durability": 2, "history": 1, "depth": 8})
    );
    for p in publishers {
        assert_eq!(p["hash"], p["rosbags_hash"], "{p}");
        assert_eq!(p["node"], "bridge");
        assert_eq!(p["node_id"], node[0]["node_id"]);
        assert_eq!(p["zid"], node[0]["zid"]);
    }
}

/// The values of one topic's samples, after checking that there are `n`,
/// numbered 1..=n in order, each from `gid`, stamped within `window`, on a
/// key whose hash is rosbags' own.
fn received(samples: &Value, n: u64, gid: &str, window: (i64, i64)) -> Vec<Value> {
    let samples = samples.as_array().unwrap();
    let seqs: Vec<&Value> = samples.iter().map(|s| &s["seq"]).collect();
    assert_eq!(
        samples.len() as u64,
        n,
        "sequence numbers received: {seqs:?}"
    );
    samples
        .iter()
        .zip(1..)
        .map(|(s, seq)| {
            assert_eq!(s["seq"], seq, "{s}");
            assert_eq!(s["gid"], gid, "{s}");
            assert_eq!(s["key_hash_ok"], true, "{s}");
            let stamp = s["stamp"].as_i64().unwrap();
            assert!(window.0 <= stamp && stamp <= window.1, "{s}");
            s["value"].clone()
        })
        .collect()
}
