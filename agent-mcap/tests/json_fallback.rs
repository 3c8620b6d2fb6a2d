//! A payload type with no ROS 2 message is recorded as JSON with its JSON
//! schema (a CDR recording otherwise), and the summary names its link.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::time::Duration;

use agent_core::*;
use agent_mcap::record::{McapRecorder, RecordOptions};
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

impl Subsystem for Grower {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = u32;
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

fn system() -> System {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let period = Period::from_millis(10).unwrap();
    let grow = Fsm::single(Behaviour::while_loop(
        "grow",
        Action::<Grower>::new()
            .output(
                |y| &mut y.e,
                |n: &u32, _: &(), y: &mut ToE| {
                    let leaf = Tree {
                        label: *n,
                        children: Vec::new(),
                    };
                    y.tree.set(Tree {
                        label: n + 100,
                        children: vec![leaf],
                    });
                    y.size.set(f64::from(*n) * 0.5);
                },
            )
            .memory(|n: &mut u32, _: &()| *n += 1),
        "false",
    ))
    .unwrap();
    let keep = Fsm::single(Behaviour::while_loop(
        "keep",
        Action::<Keeper>::new(),
        "false",
    ))
    .unwrap();
    let c = b.subsystem(a, "c", period, 0u32, grow);
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
    let s = system();
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
