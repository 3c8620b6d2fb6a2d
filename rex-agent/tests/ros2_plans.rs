//! A ROS 2 node publishes a plan that Rex executes and acknowledges (issue
//! 55): `rex --realtime --ros2 --mission listen` against a node we did not
//! write, Eclipse Zenoh's Python API (PyPI `eclipse-zenoh` 1.10.2) as the
//! router and rosbags' Kilted type store (de)serializing the CDR
//! (tests/ros2_plans.py), Rex's own messages registered from the .msg text of
//! the bridge's plan.
//!
//! The node finds Rex's subscription to `/rex/plan` by its `MS` token (type
//! `rex_msgs/msg/...`, hash equal to rosbags'), then puts on it a truncated
//! CDR, a plan on the topic with another type hash, a plan without
//! attachment, each refused and counted by Rex, never executed, and then the
//! plan 1, a short drive ahead of Rex's start. Rex executes it: it exits 0
//! with `plans_acked=1/1`, says what it received, delivered and refused (and
//! why), and the node decodes the plan's acks and outcome. What the node
//! received on `/rex/ack` is, byte for byte, what Rex's recording holds on
//! c1's ack link, and the recording holds the plan c1 took from ROS 2.
//!
//! `scripts/test -p rex-agent --test ros2_plans` installs the clients and
//! sets `EMBODIED_INTEROP_PYTHON`; plain `cargo test` skips, saying so.

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
#[path = "../../agent-ros2/tests/interop/script.rs"]
mod script;

use std::path::Path;
use std::process::Command;
use std::time::Instant;

use common::{bridge_plan, own_messages};
use embodied::record::{mcap, raw_values};
use listen::listened;
use python::python;
use rex_agent::mission::Mission;
use rex_agent::payload::{self, Point2};
use rex_agent::world::WorldConfig;
use script::{Script, free_port};
use serde_json::{Value, json};

/// How long Rex runs \[s\]: the node puts the plan a fraction of a second
/// after Rex starts, and sees its final ack and outcome about 5.5 s later;
/// the rest is for a loaded machine (the run must end with e11 idle).
const RUN_SECONDS: u32 = 15;

/// The plan the node sends: 1.5 m straight ahead of Rex's start (the
/// shipped world's, checked below).
const PLAN: [(f64, f64); 3] = [(0.5, 0.0), (1.0, 0.0), (1.5, 0.0)];

/// The plan's id (taken first, as any id is).
const PLAN_ID: u32 = 1;

/// The ids of the truncated, the wrong-hash and the attachment-less plans:
/// were one taken, its acks would name it.
const ODD_IDS: [u32; 3] = [7, 8, 9];

/// c1's acknowledgements to c2 and the plans c1 takes from c2 (and from ROS
/// 2), as the recording names their links.
const ACK_LINK: &str = "/links/c1/c2/ack/to/c2";
const PLAN_LINK: &str = "/links/c2/c1/desired_plan/to/c1";

#[test]
fn a_ros_2_node_publishes_a_plan_that_rex_executes_and_acknowledges() {
    let Some(python) = python() else { return };
    let world = WorldConfig::shipped().unwrap();
    assert_eq!(
        (world.start.x, world.start.y, world.start.phi),
        (0.0, 0.0, 0.0),
        "the plan drives ahead of the start"
    );
    let (plan, config) = bridge_plan(Mission::LISTEN, false);
    let final_m = config.limits.final_m;
    let subscribed: Vec<&str> = plan.subscriptions.iter().map(|s| s.key.topic()).collect();
    assert_eq!(subscribed, ["/rex/plan"]);
    let register = own_messages(&plan);
    let points: Vec<Value> = PLAN.iter().map(|(x, y)| json!({"x": x, "y": y})).collect();
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut node = Script::start(
        Command::new(&python).arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/ros2_plans.py")),
        "the node",
    );
    node.send(json!({
        "listen": endpoint,
        "domain": 0,
        "register": register,
        "plan_topic": "/rex/plan",
        "ack_topic": "/rex/ack",
        "outcome_topic": "/rex/outcome",
        "estimate_topic": "/rex/estimate",
        "plan": {"id": PLAN_ID, "points": points, "first": 0},
        "odd_ids": ODD_IDS,
    }));
    node.ready();
    let recording = Path::new(env!("CARGO_TARGET_TMPDIR")).join("ros2_plans_listen.mcap");
    let _ = std::fs::remove_file(&recording);
    let started = Instant::now();
    let out = Command::new(env!("CARGO_BIN_EXE_rex"))
        .args(["--realtime", "--no-vo", "--mission", "listen", "--quiet"])
        .args(["--no-report", "--for", &RUN_SECONDS.to_string()])
        .arg(format!("--ros2={endpoint}"))
        .arg("--record")
        .arg(&recording)
        .output()
        .unwrap();
    let took = started.elapsed();
    let answer = node.end("end");
    // Rex executed the plan and only it.
    let (stderr, context) = listened("rex", &out, took, &answer);

    announced(&answer);
    counted(&stderr);
    let acks = answered(&answer, final_m);

    // The recording holds what the node received, and the plan c1 took.
    let (recorded_acks, taken) = recorded(&recording);
    assert_eq!(acks, recorded_acks, "{context}");
    let sent = payload::Plan {
        id: PLAN_ID,
        points: PLAN.iter().map(|&(x, y)| Point2 { x, y }).collect(),
        first: 0,
    };
    assert_eq!(taken, [sent]);
}

/// The node found Rex's subscription to the plans as rmw_zenoh announces it,
/// published what it meant to and saw every token vanish.
fn announced(answer: &Value) {
    assert_eq!(answer["problems"], json!([]), "{answer}");
    assert_eq!(answer["all_vanished"], json!(true), "{answer}");
    let token = &answer["token"];
    assert_eq!(token["kind"], "MS", "{token}");
    assert_eq!(token["topic"], "/rex/plan", "{token}");
    assert!(
        token["type"]
            .as_str()
            .is_some_and(|t| t.starts_with("rex_msgs/msg/")),
        "{token}"
    );
    assert_eq!(token["hash"], token["rosbags_hash"], "{token}");
    assert_eq!(answer["published"]["type"], token["type"], "{answer}");
}

/// Rex received the four samples, delivered the plan and refused the rest,
/// each for its reason, and says so.
fn counted(stderr: &str) {
    let report = stderr
        .lines()
        .find(|l| l.starts_with("ros2: published="))
        .unwrap_or_else(|| panic!("no report line: {stderr}"));
    let count = |name: &str| -> u64 {
        let field = report
            .split(' ')
            .find_map(|f| f.strip_prefix(&format!("{name}=")))
            .unwrap_or_else(|| panic!("no {name} in {report}"));
        field.parse().unwrap()
    };
    assert_eq!(
        (
            count("received"),
            count("delivered"),
            count("refused"),
            count("lost")
        ),
        (4, 1, 3, 0),
        "{report}"
    );
    assert_eq!(
        (count("encode_failures"), count("put_failures")),
        (0, 0),
        "{report}"
    );
    let refusals = stderr
        .lines()
        .find(|l| l.contains("ros2: /rex/plan (into c1.c2.desired_plan): refused 3 of 4 received"))
        .unwrap_or_else(|| panic!("no refusals said: {stderr}"));
    for reason in [
        "wrong_type=1",
        "bad_attachment=1",
        "duplicate=0",
        "undecodable=1",
        "rejected=0",
    ] {
        assert!(refusals.contains(reason), "{reason}: {refusals}");
    }
}

/// The acks and the outcome the node decoded: plan 1's only, received, then
/// done, then reached within `final_m`; the acks' CDR (hex, in order).
fn answered(answer: &Value, final_m: f64) -> Vec<String> {
    let acks = samples(answer, "/rex/ack");
    let outcomes = samples(answer, "/rex/outcome");
    for s in acks.iter().chain(&outcomes) {
        assert!(s.get("problem").is_none(), "{s}");
        assert_eq!(s["value"]["plan"], json!(PLAN_ID), "{s}");
    }
    assert!(
        acks.iter().all(|a| a["type"] == "rex_msgs/msg/Ack"),
        "{acks:?}"
    );
    let statuses: Vec<&Value> = acks.iter().map(|a| &a["value"]["status"]).collect();
    assert!(statuses.len() >= 2, "{statuses:?}");
    assert!(is(statuses[0], "RECEIVED"), "{statuses:?}");
    assert!(is(statuses.last().unwrap(), "DONE"), "{statuses:?}");
    for s in &statuses {
        assert!(is(s, "RECEIVED") || is(s, "DONE"), "{statuses:?}");
        assert_eq!(
            (&s["refused"], &s["failed"]),
            (&json!([]), &json!([])),
            "{s}"
        );
    }
    assert_eq!(outcomes.len(), 1, "{outcomes:?}");
    assert_eq!(outcomes[0]["type"], "rex_msgs/msg/PlanOutcome");
    let result = &outcomes[0]["value"]["result"];
    assert!(is(result, "REACHED"), "{result}");
    let error = result["reached"][0]["error_m"].as_f64().unwrap();
    assert!((0.0..=final_m).contains(&error), "{result}");
    assert_eq!(
        (&result["missed"], &result["stopped"]),
        (&json!([]), &json!([])),
        "{result}"
    );
    assert!(
        answer["plan_to_done_s"].as_f64().is_some(),
        "the node saw no final ack and outcome: {answer}"
    );

    acks.iter()
        .map(|a| a["hex"].as_str().unwrap().to_owned())
        .collect()
}

/// The samples the node received on `topic`, in order.
fn samples<'a>(answer: &'a Value, topic: &str) -> Vec<&'a Value> {
    answer["samples"][topic]
        .as_array()
        .unwrap_or_else(|| panic!("no samples of {topic}: {answer}"))
        .iter()
        .collect()
}

/// Whether an enum as rosbags decodes Rex's messages of one (the constants
/// of its variants, the variant's number, a field per variant with data) is
/// the `variant` (the name of its constant).
fn is(value: &Value, variant: &str) -> bool {
    value[variant].is_u64() && value["variant"] == value[variant]
}

/// What `path` records: the CDR of each ack c1 sent (hex, in order), and the
/// plans c1 took from outside the system.
fn recorded(path: &Path) -> (Vec<String>, Vec<payload::Plan>) {
    let bytes = std::fs::read(path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let topics: Vec<(&str, &str)> = summary
        .channels
        .values()
        .map(|c| (c.topic.as_str(), c.message_encoding.as_str()))
        .collect();
    assert!(topics.contains(&(ACK_LINK, "cdr")), "{topics:?}");
    let received = format!("/received{PLAN_LINK}");
    assert!(
        topics.iter().any(|(t, _)| *t == received),
        "{received} not in {topics:?}"
    );
    let (mut acks, mut taken) = (Vec::new(), Vec::new());
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic == ACK_LINK {
            acks.push(hex(&m.data));
        } else if m.channel.topic == received {
            for value in raw_values(&m.channel.message_encoding, &m.data) {
                let (_, body) = embodied::WireHeader::read(value.unwrap()).unwrap();
                taken.push(postcard::from_bytes::<payload::Plan>(body).unwrap());
            }
        }
    }
    (acks, taken)
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}
