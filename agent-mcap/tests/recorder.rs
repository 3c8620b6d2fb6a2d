//! The recorder on a small system: a payload type with no ROS 2 message is
//! recorded as JSON with its JSON schema (a CDR recording otherwise), and the
//! summary names its link; a writer slower than the run holds the executor
//! back at the queue's byte bound, and loses nothing.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::time::Duration;

use agent_core::trace::LinkInfo;
use agent_core::*;
use agent_mcap::record::{Derive, DerivedChannel, McapRecorder, RecordOptions};
use serde::{Deserialize, Serialize};

/// A type that contains itself: no ROS 2 message can say it.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
struct Tree {
    label: u32,
    children: Vec<Tree>,
}

struct Grower;

#[derive(Debug, Default)]
struct ToE {
    tree: Out<Tree>,
    size: Out<f64>,
}
impl Group for ToE {
    const PEER: NodeKind = NodeKind::VirtualEffector;
}

#[derive(Debug, Default)]
struct GrowerOut {
    e: ToE,
}

/// The count, and how many leaves each tree has.
#[derive(Clone, Debug)]
struct GrowerMemory {
    n: u32,
    leaves: u32,
}

impl Subsystem for Grower {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = GrowerMemory;
    type Input = ();
    type Output = GrowerOut;
}

struct Keeper;

#[derive(Debug, Default, Clone)]
struct FromC {
    tree: In<Tree>,
    size: In<f64>,
}
impl Group for FromC {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Debug, Default, Clone)]
struct KeeperIn {
    c: FromC,
}

impl Subsystem for Keeper {
    const KIND: SubsystemKind = SubsystemKind::VirtualEffector;
    type Memory = ();
    type Input = KeeperIn;
    type Output = ();
}

/// c sends e a tree of `leaves` leaves and a number every 10 ms.
fn system(leaves: u32) -> System {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let period = Period::from_millis(10).unwrap();
    let grow = Fsm::single(Behaviour::while_loop(
        "grow",
        Action::<Grower>::new()
            .output(
                |y| &mut y.e,
                |m: &GrowerMemory, _: &(), y: &mut ToE| {
                    let leaf = |label| Tree {
                        label,
                        children: Vec::new(),
                    };
                    y.tree.set(Tree {
                        label: m.n + 100,
                        children: (0..m.leaves).map(|k| leaf(m.n + k)).collect(),
                    });
                    y.size.set(f64::from(m.n) * 0.5);
                },
            )
            .memory(|m: &mut GrowerMemory, _: &()| m.n += 1),
        "false",
    ))
    .unwrap();
    let keep = Fsm::single(Behaviour::while_loop(
        "keep",
        Action::<Keeper>::new(),
        "false",
    ))
    .unwrap();
    let c = b.subsystem(a, "c", period, GrowerMemory { n: 0, leaves }, grow);
    let e = b.subsystem(a, "e", period, (), keep);
    b.connect(
        c.output(port!(GrowerOut, e.tree)),
        e.input(port!(KeeperIn, c.tree)),
        Policy::Sample,
    );
    b.connect(
        c.output(port!(GrowerOut, e.size)),
        e.input(port!(KeeperIn, c.size)),
        Policy::Sample,
    );
    b.build().unwrap()
}

#[test]
fn a_type_without_a_ros_2_message_is_recorded_as_json_and_named_in_the_summary() {
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("json_fallback.mcap");
    let s = system(1);
    let recorder = McapRecorder::create(&path, &s, RecordOptions::default()).unwrap();
    let mut exec = Executor::with_observer(s, ExecConfig::default(), recorder);
    exec.run_for(Duration::from_millis(100)).unwrap();
    let summary = exec.into_observer().finish().unwrap();
    assert_eq!(summary.json_values.len(), 1, "{summary:?}");
    assert!(
        summary.json_values[0].contains("tree") && summary.json_values[0].contains("itself"),
        "{summary:?}"
    );

    let bytes = std::fs::read(&path).unwrap();
    let (mut trees, mut sizes) = (Vec::new(), Vec::new());
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let schema = m.channel.schema.as_ref();
        match m.channel.topic.as_str() {
            "/links/c/e/tree/to/e" => {
                assert_eq!(m.channel.message_encoding, "json");
                assert_eq!(schema.unwrap().encoding, "jsonschema");
                trees.push(serde_json::from_slice::<Tree>(&m.data).unwrap());
            }
            "/links/c/e/size/to/e" => {
                assert_eq!(m.channel.message_encoding, "cdr");
                assert_eq!(schema.unwrap().encoding, "ros2msg");
                // The CDR header, then the double.
                assert_eq!(m.data.len(), 12);
                sizes.push(f64::from_le_bytes(m.data[4..].try_into().unwrap()));
            }
            _ => {}
        }
    }
    assert_eq!(trees.len(), 10, "{trees:?}");
    assert_eq!(trees[3].children[0].label, 3);
    assert_eq!(trees[3].label, 103);
    assert_eq!(sizes.len(), 10);
    assert_eq!(sizes[3], 1.5);
}

/// A derived channel that takes 1 ms per tree: a writer slower than the run.
struct Slow;

impl Derive for Slow {
    fn channel(&mut self, _link: usize, info: &LinkInfo) -> Option<DerivedChannel> {
        info.name.contains("tree").then(|| DerivedChannel {
            topic: "/slow".into(),
            schema_name: "slow".into(),
            schema_encoding: "jsonschema".into(),
            schema: b"{}".to_vec(),
            message_encoding: "json".into(),
        })
    }

    fn message(&mut self, _link: usize, _time: Time, _body: &[u8], out: &mut Vec<u8>) -> bool {
        std::thread::sleep(Duration::from_millis(1));
        out.extend_from_slice(b"{}");
        true
    }
}

/// Record 10 s of c sending trees of 1000 leaves (about 6 KB each: a batch
/// every ten trees) through the slow writer, with at most `queue_bytes`
/// queued: (summary, messages in the file, records in them: a raw message
/// holds several values).
fn slow_recording(
    queue_bytes: usize,
    name: &str,
) -> (agent_mcap::record::RecordSummary, usize, usize) {
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    let s = system(1000);
    let options = RecordOptions {
        queue_bytes,
        derived: vec![Box::new(Slow)],
        ..RecordOptions::default()
    };
    let recorder = McapRecorder::create(&path, &s, options).unwrap();
    let mut exec = Executor::with_observer(s, ExecConfig::default(), recorder);
    exec.run_for(Duration::from_secs(10)).unwrap();
    let summary = exec.into_observer().finish().unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let (mut messages, mut records) = (0, 0);
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        messages += 1;
        records += if m.channel.topic.starts_with("/raw/") {
            agent_mcap::raw_values(&m.channel.message_encoding, &m.data).count()
        } else {
            1
        };
    }
    (summary, messages, records)
}

#[test]
fn a_writer_slower_than_the_run_holds_it_at_the_byte_bound_and_loses_nothing() {
    let (free, free_messages, free_records) = slow_recording(usize::MAX, "slow_free.mcap");
    let (bound, bound_messages, bound_records) = slow_recording(100_000, "slow_bound.mcap");
    // 1000 trees and numbers: each a value, a raw copy and a read (but the
    // last, sent as the run ends); each tree a slow message too. The raw
    // copies share messages, a batch's to one.
    for (s, m, r) in [
        (&free, free_messages, free_records),
        (&bound, bound_messages, bound_records),
    ] {
        assert_eq!(s.messages as usize, m, "{s:?}");
        assert_eq!(r, 1000 * 7 - 2, "{s:?}");
        assert!(m < r - 1000, "{m} messages for {r} records");
    }
    assert_eq!(free_records, bound_records, "nothing lost waiting");
    // Unbounded, the run outpaces the writer (1 s): most of the 6 MB of
    // trees wait in the queue. Bounded, the executor waits instead,
    // and the queue holds at most the bound and one batch.
    assert_eq!(free.waits, 0, "{free:?}");
    assert!(free.backlog_peak_bytes > 1_000_000, "{free:?}");
    assert!(bound.waits > 10, "{bound:?}");
    assert!(
        bound.backlog_peak_bytes <= 100_000 + 64 * 1024 + 8 * 1024,
        "{bound:?}"
    );
}
