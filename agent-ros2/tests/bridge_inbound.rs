//! The bridge's inbound side: ROS 2 topics feeding input buffers. A value
//! put on a subscribed topic with rmw_zenoh's attachment arrives in the
//! input's inbox (`endpoint::fed`'s receiving end here, as `RealTime::feed`'s
//! in a run) equal to what was sent; what is malformed, of another type, a
//! repeat or without attachment is refused and counted, never delivered.
//!
//! Two publishers: a Zenoh session of ours writing rmw_zenoh's format with
//! our wire module (plain `cargo test` runs it), and one we did not write,
//! Eclipse Zenoh's Python API (PyPI `eclipse-zenoh` 1.10.2) with rosbags'
//! Kilted type store serializing the CDR (tests/bridge_inbound.py), which
//! finds our subscriptions by their `MS` tokens. `scripts/test -p agent-ros2
//! --test bridge_inbound` installs the Python clients and sets
//! `EMBODIED_INTEROP_PYTHON`; plain `cargo test` skips that test, saying so.

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

use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant, SystemTime};

use agent_core::link::endpoint::{self, Receiver};
use agent_core::trace::{ErasedPayload, ReadEvent};
use agent_core::{Inbox, Observer, Payload, Policy, RealTime, RtConfig};
use agent_ros2::bridge::{
    Adapters, Bridge, BridgeError, BridgeOptions, BridgeReport, Mode, Plan, SessionOptions,
};
use agent_ros2::types::encode_cdr;
use agent_ros2::types::standard::geometry_msgs::{Point, Pose, PoseStamped, Quaternion};
use agent_ros2::types::standard::std_msgs::Header;
use agent_ros2::wire::{Attachment, Gid, Qos};
use common::{MapPose, Status, pose_at, spec, status_at, system, system_and_status_link};
use python::python;
use script::{Script, free_port};
use serde_json::{Value, json};
use zenoh::Wait;

/// The section of these tests: the status fed by its own message, the pose
/// by a standard one; nothing published.
const SECTION: &str = r#"(namespace: "/test", node: "bridge", package: "bridge_test_msgs",
    subscribe: [
        (buffer: "e.c.status", topic: "status_in"),
        (buffer: "e.c.pose", topic: "pose_in", message: "geometry_msgs/msg/PoseStamped"),
    ])"#;

/// The pose read from a PoseStamped: the heading about z; a position that
/// is not finite is refused.
fn adapters() -> Adapters {
    Adapters::new().subscribe::<PoseStamped, MapPose>(|m| {
        let p = m.pose.position;
        if !(p.x.is_finite() && p.y.is_finite()) {
            return Err(format!("a position off the map: ({}, {})", p.x, p.y));
        }
        let q = m.pose.orientation;
        Ok(MapPose {
            x: p.x,
            y: p.y,
            heading: 2.0 * q.z.atan2(q.w),
        })
    })
}

/// The PoseStamped a ROS 2 node would send for `pose` (heading 0).
fn pose_message(pose: &MapPose) -> PoseStamped {
    PoseStamped {
        header: Header {
            frame_id: "map".into(),
            ..Header::default()
        },
        pose: Pose {
            position: Point {
                x: pose.x,
                y: pose.y,
                z: 0.0,
            },
            orientation: Quaternion {
                x: 0.0,
                y: 0.0,
                z: 0.0,
                w: 1.0,
            },
        },
    }
}

fn plan() -> Plan {
    Plan::new(&spec(SECTION), None, &system(), &adapters()).unwrap()
}

/// A peer session listening on (or connecting to) `endpoint`.
fn peer(listen: bool, endpoint: &str) -> zenoh::Session {
    let endpoints = vec![endpoint.to_owned()];
    let (listen, connect) = if listen {
        (endpoints, vec![])
    } else {
        (vec![], endpoints)
    };
    SessionOptions {
        mode: Mode::Peer,
        connect,
        listen,
    }
    .open()
    .unwrap()
}

/// A localhost TCP endpoint free a moment ago.
fn free_endpoint() -> String {
    format!("tcp/127.0.0.1:{}", free_port())
}

/// Wait until `publisher` has a subscriber: the bridge's (10 s at most).
fn matched(publisher: &zenoh::pubsub::Publisher<'_>) {
    let deadline = Instant::now() + Duration::from_secs(10);
    while !publisher.matching_status().wait().unwrap().matching() {
        assert!(
            Instant::now() < deadline,
            "the bridge's subscriber is not seen"
        );
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// An inbox and its receiving end.
type Fed<T> = (Arc<Inbox>, Receiver<T>);

/// The inboxes of the section's inputs (queues, so every value is seen) and
/// their receiving ends.
fn inboxes() -> (Fed<Status>, Fed<MapPose>) {
    (
        endpoint::fed::<Status>("ros2 /test/status_in", Policy::queue(64)),
        endpoint::fed::<MapPose>("ros2 /test/pose_in", Policy::queue(64)),
    )
}

/// Wait until every sample of each subscription the bridge received is
/// accounted for and there are at least `counts` (10 s at most).
fn settled(bridge: &Bridge, counts: &[u64]) -> BridgeReport {
    let deadline = Instant::now() + Duration::from_secs(10);
    loop {
        let report = bridge.report();
        let done =
            report.subscriptions.iter().zip(counts).all(|(s, &n)| {
                s.received >= n && s.received == s.delivered + s.dropped + s.refused()
            });
        if done || Instant::now() > deadline {
            return report;
        }
        std::thread::sleep(Duration::from_millis(10));
    }
}

/// Every value waiting at `rx`, and the instants they stand for.
fn drain<T: Payload>(rx: &mut Receiver<T>) -> Vec<(T, agent_core::Time)> {
    let mut out = Vec::new();
    while let Some(value) = rx.recv().unwrap() {
        let value = value.clone();
        out.push((value, rx.stamp().unwrap().time));
    }
    out
}

#[test]
fn the_plan_feeds_each_input_from_its_topic() {
    let plan = plan();
    let [status, pose] = &plan.subscriptions[..] else {
        panic!("{plan:?}")
    };
    assert_eq!(status.buffer, "e.c.status");
    assert_eq!(status.key.topic(), "/test/status_in");
    assert_eq!(
        status.key.type_name().to_string(),
        "bridge_test_msgs/msg/Status"
    );
    assert_eq!(status.qos, Qos::keep_last(8));
    assert_eq!(
        pose.key.type_name().to_string(),
        "geometry_msgs/msg/PoseStamped"
    );
    assert_eq!(pose.qos, Qos::keep_last(1).best_effort());
    let info = system();
    let links = &info.info().links;
    assert_eq!(links[status.link].to_port, "c.status");
    assert_eq!(links[pose.link].to_port, "c.pose");
}

#[test]
fn subscribe_refuses_an_unknown_index_another_type_and_a_second_call() {
    let session = peer(false, &free_endpoint());
    let mut bridge = Bridge::on_session(plan(), session, &BridgeOptions::default()).unwrap();
    let ((status, _rx), (pose, _pose_rx)) = inboxes();
    let error = bridge.subscribe(2, status.clone()).unwrap_err();
    assert!(
        matches!(error, BridgeError::NoSubscription { index: 2, count: 2 }),
        "{error}"
    );
    // The pose's inbox for the status topic: every value would be refused.
    let error = bridge.subscribe(0, pose).unwrap_err();
    let BridgeError::WrongInbox { buffer, inbox, .. } = &error else {
        panic!("{error}")
    };
    assert_eq!(
        (buffer.as_str(), inbox.as_str()),
        ("e.c.status", "ros2 /test/pose_in")
    );
    bridge.subscribe(0, status.clone()).unwrap();
    let error = bridge.subscribe(0, status).unwrap_err();
    assert!(matches!(error, BridgeError::Subscribed { .. }), "{error}");
    assert_eq!(bridge.subscription_tokens().len(), 1);
    let report = bridge.finish().unwrap();
    let subscribed: Vec<bool> = report.subscriptions.iter().map(|s| s.subscribed).collect();
    assert_eq!(subscribed, [true, false]);
    assert_eq!(report.received(), 0);
}

/// A publisher of ours in rmw_zenoh's format, on another session: values
/// arrive equal, stamped with when they arrived since the run's instant
/// zero; a repeat, a sample without attachment and one of another hash are
/// refused, a gap is counted as lost.
#[test]
fn a_publisher_in_rmw_zenohs_format_feeds_the_input() {
    let endpoint = free_endpoint();
    let ours = peer(true, &endpoint);
    let theirs = peer(false, &endpoint);
    let zero = SystemTime::now();
    let options = BridgeOptions {
        epoch: Some(zero),
        ..BridgeOptions::default()
    };
    let mut bridge = Bridge::on_session(plan(), ours, &options).unwrap();
    let ((status, mut status_rx), _) = inboxes();
    bridge.subscribe(0, status.clone()).unwrap();
    let key = bridge.plan().subscriptions[0].key.to_string();
    let publisher = theirs.declare_publisher(key.clone()).wait().unwrap();
    matched(&publisher);
    let shape = agent_core::reflect::<Status>().unwrap();
    let cdr = |k: u32| {
        let mut out = Vec::new();
        encode_cdr(&status_at(k), &shape, &mut out).unwrap();
        out
    };
    let gid = Gid::from_bytes([7; 16]);
    let put = |k: u32, seq: i64| {
        let attachment = Attachment {
            sequence_number: seq,
            source_timestamp_ns: 0,
            gid,
        }
        .encode();
        publisher
            .put(cdr(k))
            .attachment(attachment.as_slice())
            .wait()
            .unwrap();
    };
    for k in 0..4 {
        put(k, i64::from(k) + 1);
    }
    put(9, 2);
    publisher.put(cdr(9)).wait().unwrap();
    // The topic's key with another type hash.
    let other = format!(
        "{}/RIHS01_{}",
        &key[..key.rfind('/').unwrap()],
        "0".repeat(64)
    );
    let attachment = Attachment {
        sequence_number: 5,
        source_timestamp_ns: 0,
        gid,
    };
    theirs
        .put(other, cdr(9))
        .attachment(attachment.encode().as_slice())
        .wait()
        .unwrap();
    put(4, 7);
    let report = settled(&bridge, &[8]);
    let values = drain(&mut status_rx);
    let elapsed =
        agent_core::Time::from_nanos(u64::try_from(zero.elapsed().unwrap().as_nanos()).unwrap());
    let report = {
        let s = &report.subscriptions[0];
        assert_eq!(
            (
                s.received,
                s.delivered,
                s.duplicate,
                s.bad_attachment,
                s.wrong_type,
                s.lost
            ),
            (8, 5, 1, 1, 1, 2),
            "{s:?}"
        );
        assert_eq!(
            (s.undecodable, s.rejected, s.dropped, s.inbox_problems),
            (0, 0, 0, 0)
        );
        assert!(s.last_refusal.is_some());
        report
    };
    let got: Vec<Status> = values.iter().map(|(v, _)| v.clone()).collect();
    assert_eq!(got, (0..5).map(status_at).collect::<Vec<_>>());
    assert!(values.iter().all(|(_, t)| *t <= elapsed), "{values:?}");
    assert_eq!(report.refused(), 3);
    let report = bridge.finish().unwrap();
    assert_eq!(report.delivered(), 5);
    assert!(report.close_errors.is_empty(), "{report:?}");
    assert_eq!(status.problem_count(), 0);
}

#[test]
fn a_ros_2_publisher_feeds_the_inputs_and_odd_samples_are_refused() {
    let Some(python) = python() else { return };
    let plan = plan();
    let own = &plan.subscriptions[0].messages;
    let register = [json!([own.name().to_string(), own.msg_text()])];
    let endpoint = free_endpoint();
    let mut talker = Script::start(
        Command::new(&python).arg(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/tests/bridge_inbound.py"
        )),
        "the talker",
    );
    talker.send(json!({"listen": endpoint, "domain": 0, "register": register}));
    talker.ready();
    let options = BridgeOptions {
        session: SessionOptions::client(&endpoint),
        ..BridgeOptions::default()
    };
    let mut bridge = Bridge::start(plan, options).unwrap();
    let ((status, mut status_rx), (pose, mut pose_rx)) = inboxes();
    bridge.subscribe(0, status.clone()).unwrap();
    bridge.subscribe(1, pose.clone()).unwrap();
    let tokens: Vec<String> = std::iter::once(bridge.node_token().key_expr())
        .chain(bridge.subscription_tokens().iter().map(|t| t.key_expr()))
        .collect();

    let statuses: Vec<Value> = (0..5)
        .map(|k| serde_json::to_value(status_at(k)).unwrap())
        .collect();
    let poses: Vec<Value> = (0..5)
        .map(|k| serde_json::to_value(pose_message(&pose_at(k))).unwrap())
        .collect();
    let odd = ["malformed", "wrong_hash", "repeat", "no_attachment", "skip"];
    let answer = talker.ask(json!({"topics": [
        {"topic": "/test/status_in", "values": statuses, "odd": odd},
        {"topic": "/test/pose_in", "values": poses, "odd": ["nan"]},
    ]}));
    assert_eq!(answer["problems"], json!([]), "{answer}");
    announced(&answer);

    // 5 values and 5 odd samples on the status topic, 5 and a NaN on the pose's.
    let report = settled(&bridge, &[10, 6]);
    let statuses: Vec<Status> = drain(&mut status_rx).into_iter().map(|(v, _)| v).collect();
    let poses: Vec<MapPose> = drain(&mut pose_rx).into_iter().map(|(v, _)| v).collect();
    let s = report.subscription("/test/status_in").unwrap();
    assert_eq!(
        (s.received, s.delivered, s.dropped, s.inbox_problems),
        (10, 6, 0, 0),
        "{s:?}"
    );
    assert_eq!(
        (
            s.undecodable,
            s.wrong_type,
            s.duplicate,
            s.bad_attachment,
            s.rejected
        ),
        (1, 1, 1, 1, 0),
        "{s:?}"
    );
    // The sample numbered 8 came after 6: the 7th, put on another key, is lost.
    assert_eq!(s.lost, 1, "{s:?}");
    let mut expected: Vec<Status> = (0..5).map(status_at).collect();
    expected.push(status_at(0));
    assert_eq!(statuses, expected);
    let p = report.subscription("/test/pose_in").unwrap();
    assert_eq!((p.received, p.delivered, p.rejected), (6, 5, 1), "{p:?}");
    assert!(
        p.last_refusal
            .as_deref()
            .is_some_and(|r| r.contains("off the map")),
        "{p:?}"
    );
    assert_eq!(poses, (0..5).map(pose_at).collect::<Vec<_>>());
    assert_eq!(
        (report.received(), report.refused(), report.lost()),
        (16, 5, 1)
    );

    bridge.finish().unwrap();
    let answer = talker.end(json!({"end": true}));
    let vanished: Vec<&str> = answer["vanished"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k.as_str().unwrap())
        .collect();
    assert!(
        tokens.iter().all(|k| vanished.contains(&k.as_str())),
        "{vanished:?}"
    );
}

/// The talker found our subscriptions as rmw_zenoh announces them: topics,
/// types, QoS, node, and hashes equal to rosbags'.
fn announced(answer: &Value) {
    let subscriptions: Vec<&Value> = answer["tokens"]
        .as_array()
        .unwrap()
        .iter()
        .filter(|t| t["kind"] == "MS")
        .collect();
    assert_eq!(subscriptions.len(), 2, "{answer}");
    let token = |topic: &str| *subscriptions.iter().find(|t| t["topic"] == topic).unwrap();
    let status_token = token("/test/status_in");
    assert_eq!(status_token["type"], "bridge_test_msgs/msg/Status");
    // A queue of 8: reliable (1), keep-last 8, volatile (2).
    assert_eq!(
        status_token["qos"],
        json!({"reliability": 1, "durability": 2, "history": 1, "depth": 8})
    );
    let pose_token = token("/test/pose_in");
    assert_eq!(pose_token["type"], "geometry_msgs/msg/PoseStamped");
    assert_eq!(
        pose_token["qos"],
        json!({"reliability": 2, "durability": 2, "history": 1, "depth": 1})
    );
    for t in &subscriptions {
        assert_eq!(t["hash"], t["rosbags_hash"], "{t}");
        assert_eq!(
            (&t["node"], &t["namespace"]),
            (&json!("bridge"), &json!("/test"))
        );
    }
}

/// The values of the links fed from outside the system that a run's nodes
/// took (`Observer::received`), as postcard bytes, over every thread.
#[derive(Clone, Default)]
struct Received(Arc<Mutex<Vec<Vec<u8>>>>);

impl Observer for Received {
    fn received(&mut self, _event: &ReadEvent, value: &dyn ErasedPayload) {
        let mut bytes = Vec::new();
        value.encode(&mut bytes).unwrap();
        self.0.lock().unwrap().push(bytes);
    }
}

/// A real-time run's input fed by the bridge (`RealTime::feed`) beside its
/// link: the node takes every value put on the topic, and they are stamped
/// against the run's instant zero (the bridge's epoch, an hour before, would
/// stamp them an hour ahead: refused by the inbox).
#[test]
fn a_real_time_runs_input_takes_the_values_of_its_topic() {
    let endpoint = free_endpoint();
    let ours = peer(true, &endpoint);
    let theirs = peer(false, &endpoint);
    let (system, status_link) = system_and_status_link();
    let section = r#"(namespace: "/test", node: "bridge", package: "bridge_test_msgs",
        subscribe: [(buffer: "e.c.status", topic: "status_in")])"#;
    let plan = Plan::new(&spec(section), None, &system, &Adapters::new()).unwrap();
    let options = BridgeOptions {
        epoch: Some(SystemTime::now() - Duration::from_secs(3600)),
        ..BridgeOptions::default()
    };
    let mut bridge = Bridge::on_session(plan, ours, &options).unwrap();
    let key = bridge.plan().subscriptions[0].key.to_string();
    let mut rt = RealTime::new(system, RtConfig::default());
    let inbox = rt.feed(status_link, "ros2 /test/status_in").unwrap();
    bridge.subscribe(0, inbox.clone()).unwrap();
    let received = Received::default();
    let theirs_too = received.clone();
    rt.observe(move |_, _| Box::new(theirs_too.clone()));
    let running = rt.start(Duration::from_millis(400)).unwrap();
    bridge.set_inbound_zero(running.zero());

    let publisher = theirs.declare_publisher(key).wait().unwrap();
    matched(&publisher);
    let shape = agent_core::reflect::<Status>().unwrap();
    for k in 0..5 {
        let mut cdr = Vec::new();
        encode_cdr(&status_at(100 + k), &shape, &mut cdr).unwrap();
        let attachment = Attachment {
            sequence_number: i64::from(k) + 1,
            source_timestamp_ns: 0,
            gid: Gid::from_bytes([3; 16]),
        };
        publisher
            .put(cdr)
            .attachment(attachment.encode().as_slice())
            .wait()
            .unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }
    running.join().unwrap();
    let report = bridge.finish().unwrap();
    let s = &report.subscriptions[0];
    assert_eq!(
        (s.received, s.delivered, s.inbox_problems),
        (5, 5, 0),
        "{s:?}"
    );
    let expected: Vec<Vec<u8>> = (100..105)
        .map(|k| postcard::to_allocvec(&status_at(k)).unwrap())
        .collect();
    assert_eq!(*received.0.lock().unwrap(), expected);
}
