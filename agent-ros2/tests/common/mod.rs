//! A small system shown to ROS 2, for the bridge's tests: `c` sends `e` a pose
//! (a sample link, published as `geometry_msgs/msg/PoseStamped` through an
//! adapter) and a status (a queue of 8, published as its own message) every
//! 10 ms.

#![allow(
    dead_code,
    unreachable_pub,
    clippy::unwrap_used,
    reason = "a module of test binaries, each using a part; a failing unwrap is a failing test"
)]

use agent_core::*;
use agent_ros2::bridge::Adapters;
use agent_ros2::types::standard::geometry_msgs::{Point, Pose, PoseStamped, Quaternion};
use agent_ros2::types::standard::std_msgs::Header;
use agent_spec::model::Spec;
use serde::{Deserialize, Serialize};

/// A pose on the map's floor: where \[m\] and which way \[rad\].
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct MapPose {
    pub x: f64,
    pub y: f64,
    pub heading: f64,
}

/// What `c` says of itself: a message of our own package.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Status {
    pub step: u32,
    pub label: String,
    pub speeds: Vec<f32>,
    pub ready: bool,
}

/// The pose `c` sends at step `k` (values exact in binary, for comparisons).
pub fn pose_at(k: u32) -> MapPose {
    MapPose {
        x: f64::from(k) * 0.5,
        y: -f64::from(k) * 0.25,
        heading: 0.0,
    }
}

/// The status `c` sends at step `k`.
pub fn status_at(k: u32) -> Status {
    Status {
        step: k,
        label: format!("step {k}"),
        speeds: (0..k % 4).map(|i| i as f32 * 0.25).collect(),
        ready: k.is_multiple_of(2),
    }
}

/// The adapter of the spec's PoseStamped: the pose in frame `map`, the
/// heading about z.
pub fn adapters() -> Adapters {
    Adapters::new().publish::<MapPose, PoseStamped>(|p, stamp| PoseStamped {
        header: Header {
            stamp,
            frame_id: "map".into(),
        },
        pose: Pose {
            position: Point {
                x: p.x,
                y: p.y,
                z: 0.0,
            },
            orientation: Quaternion {
                x: 0.0,
                y: 0.0,
                z: (p.heading / 2.0).sin(),
                w: (p.heading / 2.0).cos(),
            },
        },
    })
}

/// The spec of the system, with `ros2` as its `ros2` section (RON, `None`
/// for none). Its output `c.e.extra` is linked to nothing.
pub fn spec(ros2: &str) -> Spec {
    let text = format!(
        r#"(
    name: "bridge_test",
    agents: [(
        name: "a",
        subsystems: [
            (name: "c", kind: Control, period_ms: 10.0,
             outputs: [(peer: "e", buffers: [(name: "pose", type: "MapPose"), (name: "status", type: "Status"), (name: "extra", type: "f64")])],
             behaviours: [(name: "go", kind: While, terminal: "false")],
             fsm: (initial: "go")),
            (name: "e", kind: VirtualEffector, period_ms: 10.0,
             inputs: [(peer: "c", buffers: [(name: "pose", type: "MapPose"), (name: "status", type: "Status")])],
             behaviours: [(name: "keep", kind: While, terminal: "false")],
             fsm: (initial: "keep")),
        ],
    )],
    links: [
        (from: "c.e.pose", to: "e.c.pose", policy: Sample),
        (from: "c.e.status", to: "e.c.status", policy: Queue(8)),
    ],
    ros2: {ros2},
)"#
    );
    agent_spec::options().from_str(&text).unwrap()
}

/// The section the tests publish: the pose as a standard message, the
/// status as our own, in the node's private namespace.
pub const ROS2: &str = r#"(namespace: "/test", node: "bridge", package: "bridge_test_msgs", publish: [
    (buffer: "c.e.pose", topic: "pose", message: "geometry_msgs/msg/PoseStamped"),
    (buffer: "c.e.status", topic: "~/status"),
])"#;

#[derive(Debug, Default)]
pub struct ToE {
    pub pose: Out<MapPose>,
    pub status: Out<Status>,
}
impl Group for ToE {
    const PEER: NodeKind = NodeKind::VirtualEffector;
}

#[derive(Debug, Default)]
pub struct COut {
    pub e: ToE,
}

pub struct C;
impl Subsystem for C {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = u32;
    type Input = ();
    type Output = COut;
}

#[derive(Debug, Default, Clone)]
pub struct FromC {
    pub pose: In<MapPose>,
    pub status: In<Status>,
}
impl Group for FromC {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Debug, Default, Clone)]
pub struct EIn {
    pub c: FromC,
}

pub struct E;
impl Subsystem for E {
    const KIND: SubsystemKind = SubsystemKind::VirtualEffector;
    type Memory = ();
    type Input = EIn;
    type Output = ();
}

/// The system: `c` sends step `k`'s pose and status at `k` × 10 ms.
pub fn system() -> System {
    system_and_status_link().0
}

/// The system, as [`system`], and its status link.
pub fn system_and_status_link() -> (System, LinkId) {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let period = Period::from_millis(10).unwrap();
    let go = Fsm::single(Behaviour::while_loop(
        "go",
        Action::<C>::new()
            .output(
                |y| &mut y.e,
                |k: &u32, _: &(), y: &mut ToE| {
                    y.pose.set(pose_at(*k));
                    y.status.set(status_at(*k));
                },
            )
            .memory(|k: &mut u32, _: &()| *k += 1),
        "false",
    ))
    .unwrap();
    let keep = Fsm::single(Behaviour::while_loop("keep", Action::<E>::new(), "false")).unwrap();
    let c = b.subsystem(a, "c", period, 0u32, go);
    let e = b.subsystem(a, "e", period, (), keep);
    b.connect(
        c.output(port!(COut, e.pose)),
        e.input(port!(EIn, c.pose)),
        Policy::Sample,
    );
    let status = b.connect(
        c.output(port!(COut, e.status)),
        e.input(port!(EIn, c.status)),
        Policy::queue(8),
    );
    (b.build().unwrap(), status)
}
