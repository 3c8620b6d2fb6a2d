//! `--ros2` on a small application (`c` sends `e` a status every 10 ms,
//! published as a message of its own package): what is refused before
//! anything runs. The bridge against a ROS 2 listener is tested from Rex
//! (rex-agent's tests/ros2_bridge.rs) and in agent-ros2.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use agent_core::*;
use clap::Parser as _;
use serde::{Deserialize, Serialize};

#[cfg(feature = "ros2")]
use super::Ros2Out;
#[cfg(feature = "ros2")]
use crate::SpecFile;
use crate::{App, Cli, NoFlags, Status as Exit};

/// What `c` says of itself.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
struct Status {
    step: u32,
    ready: bool,
}

#[derive(Debug, Default)]
struct ToE {
    status: Out<Status>,
}
impl Group for ToE {
    const PEER: NodeKind = NodeKind::VirtualEffector;
}

#[derive(Debug, Default)]
struct COut {
    e: ToE,
}

struct C;
impl Subsystem for C {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = u32;
    type Input = ();
    type Output = COut;
}

#[derive(Debug, Default, Clone)]
struct FromC {
    status: In<Status>,
}
impl Group for FromC {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Debug, Default, Clone)]
struct EIn {
    c: FromC,
}

struct E;
impl Subsystem for E {
    const KIND: SubsystemKind = SubsystemKind::VirtualEffector;
    type Memory = ();
    type Input = EIn;
    type Output = ();
}

/// The spec, with `ros2` as its `ros2` section (RON, `None` for none).
fn spec(ros2: &str) -> String {
    format!(
        r#"(
    name: "small",
    agents: [(
        name: "a",
        subsystems: [
            (name: "c", kind: Control, period_ms: 10.0,
             outputs: [(peer: "e", buffers: [(name: "status", type: "Status")])],
             behaviours: [(name: "go", kind: While, terminal: "false")],
             fsm: (initial: "go")),
            (name: "e", kind: VirtualEffector, period_ms: 10.0,
             inputs: [(peer: "c", buffers: [(name: "status", type: "Status")])],
             behaviours: [(name: "keep", kind: While, terminal: "false")],
             fsm: (initial: "keep")),
        ],
    )],
    links: [(from: "c.e.status", to: "e.c.status", policy: Queue(8))],
    ros2: {ros2},
)"#
    )
}

const SECTION: &str = r#"(node: "small", publish: [(buffer: "c.e.status", topic: "status")])"#;

/// The system: `c` sends step `k`'s status at `k` × 10 ms.
fn system() -> System {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let period = Period::from_millis(10).unwrap();
    let go = Fsm::single(Behaviour::while_loop(
        "go",
        Action::<C>::new()
            .output(
                |y| &mut y.e,
                |k: &u32, _: &(), y: &mut ToE| {
                    y.status.set(Status {
                        step: *k,
                        ready: k.is_multiple_of(2),
                    });
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
        c.output(port!(COut, e.status)),
        e.input(port!(EIn, c.status)),
        Policy::queue(8),
    );
    b.build().unwrap()
}

fn app(ros2: &str) -> App {
    App::new("small.ron", spec(ros2)).build(|_| Ok(system()))
}

/// A localhost TCP endpoint free a moment ago (no router listens there).
fn free_endpoint() -> String {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    format!("tcp/127.0.0.1:{port}")
}

fn cli(args: &[&str]) -> Cli<NoFlags> {
    Cli::<NoFlags>::try_parse_from(["small", "--quiet", "--for", "0.1"].iter().chain(args)).unwrap()
}

#[test]
fn the_flag_takes_an_endpoint_or_the_routers_default() {
    assert_eq!(cli(&[]).common.ros2, None);
    assert_eq!(
        cli(&["--ros2"]).common.ros2.as_deref(),
        Some(crate::ROS2_ENDPOINT)
    );
    assert_eq!(
        cli(&["--ros2=tcp/10.0.0.2:7447"]).common.ros2.as_deref(),
        Some("tcp/10.0.0.2:7447")
    );
    // Followed by a command, the flag takes no value: `launch` is the command.
    let launch = cli(&["--ros2", "launch"]);
    assert_eq!(launch.common.ros2.as_deref(), Some(crate::ROS2_ENDPOINT));
    assert!(
        matches!(launch.command, Some(crate::Command::Launch { .. })),
        "{:?}",
        launch.command
    );
}

#[test]
fn a_run_without_the_flag_runs_without_a_bridge() {
    assert_eq!(crate::run(&mut app(SECTION), &cli(&[])), Exit::Success);
}

#[cfg(feature = "ros2")]
#[test]
fn no_router_at_the_endpoint_is_invalid_input_naming_it() {
    let endpoint = free_endpoint();
    for realtime in [false, true] {
        let flag = format!("--ros2={endpoint}");
        let mut args = vec![flag.as_str()];
        if realtime {
            args.push("--realtime");
        }
        assert_eq!(crate::run(&mut app(SECTION), &cli(&args)), Exit::Invalid);
    }
    let spec = SpecFile::parse("small.ron", spec(SECTION)).unwrap();
    let common = cli(&[&format!("--ros2={endpoint}")]).common;
    let e = Ros2Out::start(&app(SECTION), &common, &spec, &system(), None).unwrap_err();
    assert_eq!(e.status(), Exit::Invalid);
    let message = e.to_string();
    assert!(
        message.starts_with(&format!("--ros2 {endpoint}: ")),
        "{message}"
    );
    assert!(
        message.matches(&endpoint).count() >= 2,
        "the session's error too: {message}"
    );
}

#[cfg(feature = "ros2")]
#[test]
fn a_spec_that_shows_nothing_to_ros_2_is_invalid_input() {
    let endpoint = free_endpoint();
    let none = app("None");
    assert_eq!(
        crate::run(&mut app("None"), &cli(&[&format!("--ros2={endpoint}")])),
        Exit::Invalid
    );
    let spec = SpecFile::parse("small.ron", spec("None")).unwrap();
    let common = cli(&[&format!("--ros2={endpoint}")]).common;
    let e = Ros2Out::start(&none, &common, &spec, &system(), None).unwrap_err();
    assert!(e.to_string().contains("no `ros2` section"), "{e}");
    // A buffer the system does not send on: named.
    let ghost = r#"(publish: [(buffer: "c.e.ghost", topic: "ghost")])"#;
    assert_eq!(
        crate::run(&mut app(ghost), &cli(&[&format!("--ros2={endpoint}")])),
        Exit::Invalid
    );
}

#[cfg(feature = "ros2")]
#[test]
fn a_buffer_type_that_cannot_be_the_message_is_said_at_the_specs_entry() {
    let endpoint = free_endpoint();
    // `Status` is no pose, and the small program gives no adapter.
    let pose = r#"(node: "small", publish: [(buffer: "c.e.status", topic: "status", message: "geometry_msgs/msg/PoseStamped")])"#;
    assert_eq!(
        crate::run(&mut app(pose), &cli(&[&format!("--ros2={endpoint}")])),
        Exit::Invalid
    );
    let text = spec(pose);
    let file = SpecFile::parse("small.ron", text.clone()).unwrap();
    let common = cli(&[&format!("--ros2={endpoint}")]).common;
    let e = Ros2Out::start(&app(pose), &common, &file, &system(), None).unwrap_err();
    assert_eq!(e.status(), Exit::Invalid);
    let message = e.to_string();
    // The checker's format: the file, the entry's line and column, the code.
    let at = text.find("buffer: \"c.e.status\", topic").unwrap() + "buffer: \"".len();
    let (line, col) = agent_spec::diag::line_col(&text, at);
    assert!(
        message.contains(&format!("small.ron:{line}:{col}")),
        "{message}"
    );
    assert!(message.contains("spec::ros2_type"), "{message}");
    assert!(
        message.contains("geometry_msgs/msg/PoseStamped"),
        "{message}"
    );
    // A buffer whose entry is not the type's fault is said as before.
    let ghost = r#"(publish: [(buffer: "c.e.ghost", topic: "ghost")])"#;
    let file = SpecFile::parse("small.ron", spec(ghost));
    if let Ok(file) = file {
        let e = Ros2Out::start(&app(ghost), &common, &file, &system(), None).unwrap_err();
        assert!(!e.to_string().contains("spec::"), "{e}");
    }
}

#[cfg(not(feature = "ros2"))]
#[test]
fn without_the_feature_the_flag_is_refused() {
    let endpoint = free_endpoint();
    assert_eq!(
        crate::run(&mut app(SECTION), &cli(&[&format!("--ros2={endpoint}")])),
        Exit::Invalid
    );
}
