//! The bridge's plan from a spec and a built system: the keys, types, hashes
//! and QoS it will publish, and each reason it refuses to, said before
//! anything runs, naming the buffer and topic.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

mod common;

use agent_ros2::bridge::{Adapters, Plan, PlanError};
use agent_ros2::types::standard::StandardMessage;
use agent_ros2::types::standard::geometry_msgs::PoseStamped;
use agent_ros2::types::standard::sensor_msgs::Imu;
use agent_ros2::types::type_hash;
use agent_ros2::wire::Qos;
use common::{MapPose, Status, adapters, spec, system};

#[test]
fn the_plan_names_each_topic_with_its_key_message_hash_and_qos() {
    let plan = Plan::new(&spec(common::ROS2), None, &system(), &adapters()).unwrap();
    assert_eq!(
        (plan.domain, plan.node.as_str(), plan.namespace.as_str()),
        (0, "bridge", "/test")
    );
    let [pose, status] = &plan.topics[..] else {
        panic!("{plan:?}")
    };
    let pose_hash = type_hash(&PoseStamped::messages()).unwrap();
    assert_eq!(
        pose.key.to_string(),
        format!("0/test/pose/geometry_msgs::msg::dds_::PoseStamped_/{pose_hash}")
    );
    // A sample link: best effort, keep-last 1.
    assert_eq!(pose.qos, Qos::keep_last(1).best_effort());
    assert_eq!(pose.buffer, "c.e.pose");
    let status_hash = type_hash(&status.messages).unwrap();
    assert_eq!(
        status.key.to_string(),
        format!("0/test/bridge/status/bridge_test_msgs::msg::dds_::Status_/{status_hash}")
    );
    // A queue of 8: reliable, keep-last 8.
    assert_eq!(status.qos, Qos::keep_last(8));
    assert_eq!(
        status.messages.msg_text(),
        "uint32 step\nstring label\nfloat32[] speeds\nbool ready\n"
    );
}

#[test]
fn the_spec_overrides_the_links_qos() {
    let section = r#"(publish: [(buffer: "c.e.pose", topic: "pose", message: "geometry_msgs/msg/PoseStamped", qos: (reliability: Reliable, depth: 5))])"#;
    let plan = Plan::new(&spec(section), None, &system(), &adapters()).unwrap();
    assert_eq!(plan.topics[0].qos, Qos::keep_last(5));
    // The defaults: the system's name, the root namespace, `<name>_msgs`.
    assert_eq!(plan.node, "bridge_test");
    assert_eq!(plan.namespace, "/");
    assert_eq!(plan.package, "bridge_test_msgs");
    assert_eq!(plan.topics[0].key.topic(), "/pose");
}

#[test]
fn a_standard_message_without_an_adapter_is_refused_naming_buffer_and_topic() {
    let error = Plan::new(&spec(common::ROS2), None, &system(), &Adapters::new()).unwrap_err();
    assert_eq!(
        error,
        PlanError::NoAdapter {
            buffer: "c.e.pose".into(),
            topic: "/test/pose".into(),
            payload: std::any::type_name::<MapPose>().into(),
            message: "geometry_msgs/msg/PoseStamped".into(),
            available: vec![],
        }
    );
    // An adapter of the type to another message is named.
    let imu = Adapters::new().publish::<MapPose, Imu>(|_, _| Imu::default());
    let error = Plan::new(&spec(common::ROS2), None, &system(), &imu).unwrap_err();
    let text = error.to_string();
    assert!(
        text.contains("c.e.pose") && text.contains("/test/pose"),
        "{text}"
    );
    assert!(text.contains("sensor_msgs/msg/Imu"), "{text}");
}

#[test]
fn an_adapter_of_another_type_does_not_serve() {
    // The same message, made of `f64`: not the pose's type.
    let other = Adapters::new().publish::<f64, PoseStamped>(|_, _| PoseStamped::default());
    let error = Plan::new(&spec(common::ROS2), None, &system(), &other).unwrap_err();
    assert!(matches!(error, PlanError::NoAdapter { .. }), "{error}");
}

#[test]
fn a_buffer_without_link_or_spec_entry_is_refused() {
    let unlinked = r#"(publish: [(buffer: "c.e.extra", topic: "extra")])"#;
    let error = Plan::new(&spec(unlinked), None, &system(), &adapters()).unwrap_err();
    assert_eq!(
        error,
        PlanError::NoLink {
            buffer: "c.e.extra".into(),
            topic: "/extra".into()
        }
    );
    let unknown = r#"(publish: [(buffer: "c.e.nothing", topic: "nothing")])"#;
    let error = Plan::new(&spec(unknown), None, &system(), &adapters()).unwrap_err();
    assert_eq!(
        error,
        PlanError::UnknownBuffer {
            buffer: "c.e.nothing".into(),
            topic: "nothing".into()
        }
    );
}

#[test]
fn transient_local_and_a_missing_section_are_refused() {
    let late = r#"(publish: [(buffer: "c.e.status", topic: "status", qos: (durability: TransientLocal))])"#;
    let error = Plan::new(&spec(late), None, &system(), &adapters()).unwrap_err();
    assert_eq!(
        error,
        PlanError::TransientLocal {
            buffer: "c.e.status".into(),
            topic: "/status".into()
        }
    );
    let error = Plan::new(&spec("None"), None, &system(), &adapters()).unwrap_err();
    assert_eq!(error, PlanError::NoSection);
}

/// A field named as Rust allows and ROS 2 does not (a trailing `_`).
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
struct Odd {
    type_: u8,
}

#[derive(Debug, Default)]
struct ToE {
    odd: agent_core::Out<Odd>,
}
impl agent_core::Group for ToE {
    const PEER: agent_core::NodeKind = agent_core::NodeKind::VirtualEffector;
}

#[derive(Debug, Default)]
struct GOut {
    e: ToE,
}

struct G;
impl agent_core::Subsystem for G {
    const KIND: agent_core::SubsystemKind = agent_core::SubsystemKind::Control;
    type Memory = ();
    type Input = ();
    type Output = GOut;
}

#[derive(Debug, Default, Clone)]
struct FromG {
    odd: agent_core::In<Odd>,
}
impl agent_core::Group for FromG {
    const PEER: agent_core::NodeKind = agent_core::NodeKind::Control;
}

#[derive(Debug, Default, Clone)]
struct FIn {
    c: FromG,
}

struct F;
impl agent_core::Subsystem for F {
    const KIND: agent_core::SubsystemKind = agent_core::SubsystemKind::VirtualEffector;
    type Memory = ();
    type Input = FIn;
    type Output = ();
}

#[test]
fn a_buffer_type_that_cannot_be_a_message_is_refused_with_the_reason() {
    use agent_core::{Action, Behaviour, Fsm, Period, Policy, SystemBuilder, port};
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let period = Period::from_millis(10).unwrap();
    let idle = |name| Fsm::single(Behaviour::while_loop(name, Action::<G>::new(), "false"));
    let keep = Fsm::single(Behaviour::while_loop("keep", Action::<F>::new(), "false"));
    let c = b.subsystem(a, "c", period, (), idle("go").unwrap());
    let e = b.subsystem(a, "e", period, (), keep.unwrap());
    b.connect(
        c.output(port!(GOut, e.odd)),
        e.input(port!(FIn, c.odd)),
        Policy::Sample,
    );
    let system = b.build().unwrap();
    let text = r#"(
        name: "odd",
        agents: [(name: "a", subsystems: [
            (name: "c", kind: Control, period_ms: 10.0,
             outputs: [(peer: "e", buffers: [(name: "odd", type: "Odd")])],
             behaviours: [(name: "go", kind: While, terminal: "false")], fsm: (initial: "go")),
            (name: "e", kind: VirtualEffector, period_ms: 10.0,
             inputs: [(peer: "c", buffers: [(name: "odd", type: "Odd")])],
             behaviours: [(name: "keep", kind: While, terminal: "false")], fsm: (initial: "keep")),
        ])],
        links: [(from: "c.e.odd", to: "e.c.odd", policy: Sample)],
        ros2: (publish: [(buffer: "c.e.odd", topic: "odd")]),
    )"#;
    let spec = agent_spec::options().from_str(text).unwrap();
    let error = Plan::new(&spec, None, &system, &Adapters::new()).unwrap_err();
    let PlanError::NotAMessage {
        buffer,
        topic,
        reason,
        ..
    } = &error
    else {
        panic!("{error}")
    };
    assert_eq!((buffer.as_str(), topic.as_str()), ("c.e.odd", "/odd"));
    assert!(reason.contains("type_"), "{error}");
}

#[test]
fn a_process_publishes_the_buffers_of_the_components_it_runs() {
    let plan = Plan::new(&spec(common::ROS2), None, &system(), &adapters()).unwrap();
    assert_eq!(plan.clone().only_components(&["c"]).topics.len(), 2);
    assert!(plan.clone().only_components(&["e"]).topics.is_empty());
    let named = plan.named("bridge_e").unwrap();
    assert_eq!(named.node, "bridge_e");
    assert!(matches!(named.named("2nd"), Err(PlanError::Name { .. })));
}

#[test]
fn a_subscribed_topic_feeds_the_input_through_its_link() {
    let section = r#"(node: "bridge", publish: [(buffer: "c.e.status", topic: "status")],
        subscribe: [(buffer: "e.c.status", topic: "~/status_in", qos: (depth: 3))])"#;
    let plan = Plan::new(&spec(section), None, &system(), &adapters()).unwrap();
    assert!(plan.unserved().is_empty());
    let [status] = &plan.subscriptions[..] else {
        panic!("{plan:?}")
    };
    assert_eq!(status.buffer, "e.c.status");
    // The status link, declared second, feeds `e`'s input `c.status`.
    assert_eq!(status.link, 1);
    assert_eq!(status.payload, std::any::type_name::<Status>());
    assert_eq!(
        status.fingerprint,
        agent_core::link::remote::fingerprint::<Status>()
    );
    // The link's queue of 8, its depth overridden by the spec.
    assert_eq!(status.qos, Qos::keep_last(3));
    // The same type published and subscribed: one message, one name and hash.
    assert_eq!(status.key.topic(), "/bridge/status_in");
    assert_eq!(status.key.type_name(), plan.topics[0].key.type_name());
    assert_eq!(status.key.type_hash(), plan.topics[0].key.type_hash());
    assert_eq!(status.messages, plan.topics[0].messages);
}

#[test]
fn a_standard_message_in_needs_an_adapter_into_the_buffer_type() {
    let section = r#"(subscribe: [(buffer: "e.c.pose", topic: "pose_in", message: "geometry_msgs/msg/PoseStamped")])"#;
    // An adapter out of the type does not read the message in.
    let error = Plan::new(&spec(section), None, &system(), &adapters()).unwrap_err();
    assert_eq!(
        error,
        PlanError::NoInboundAdapter {
            buffer: "e.c.pose".into(),
            topic: "/pose_in".into(),
            payload: std::any::type_name::<MapPose>().into(),
            message: "geometry_msgs/msg/PoseStamped".into(),
            available: vec![],
        }
    );
    let imu = Adapters::new().subscribe::<Imu, MapPose>(|_| Ok(MapPose::default()));
    let error = Plan::new(&spec(section), None, &system(), &imu).unwrap_err();
    assert!(error.to_string().contains("sensor_msgs/msg/Imu"), "{error}");
    let reads = Adapters::new().subscribe::<PoseStamped, MapPose>(|m| {
        Ok(MapPose {
            x: m.pose.position.x,
            y: m.pose.position.y,
            heading: 0.0,
        })
    });
    let plan = Plan::new(&spec(section), None, &system(), &reads).unwrap();
    let pose_hash = type_hash(&PoseStamped::messages()).unwrap();
    assert_eq!(
        plan.subscriptions[0].key.to_string(),
        format!("0/pose_in/geometry_msgs::msg::dds_::PoseStamped_/{pose_hash}")
    );
    // A sample link: best effort, keep-last 1.
    assert_eq!(plan.subscriptions[0].qos, Qos::keep_last(1).best_effort());
}

#[test]
fn a_subscribed_buffer_that_is_no_linked_input_is_refused() {
    // An output is no input.
    let output = r#"(subscribe: [(buffer: "c.e.pose", topic: "pose_in")])"#;
    let error = Plan::new(&spec(output), None, &system(), &adapters()).unwrap_err();
    assert_eq!(
        error,
        PlanError::UnknownInput {
            buffer: "c.e.pose".into(),
            topic: "pose_in".into()
        }
    );
    // The spec's input, in a system without its link.
    let section = r#"(subscribe: [(buffer: "e.c.status", topic: "status_in")])"#;
    let error = Plan::new(&spec(section), None, &only_pose(), &adapters()).unwrap_err();
    assert_eq!(
        error,
        PlanError::NoInputLink {
            buffer: "e.c.status".into(),
            topic: "/status_in".into()
        }
    );
}

/// The test system with its pose link only.
fn only_pose() -> agent_core::System {
    use agent_core::{Action, Behaviour, Fsm, Period, Policy, SystemBuilder, port};
    use common::{C, COut, E, EIn};
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let period = Period::from_millis(10).unwrap();
    let go = Fsm::single(Behaviour::while_loop("go", Action::<C>::new(), "false")).unwrap();
    let keep = Fsm::single(Behaviour::while_loop("keep", Action::<E>::new(), "false")).unwrap();
    let c = b.subsystem(a, "c", period, 0u32, go);
    let e = b.subsystem(a, "e", period, (), keep);
    b.connect(
        c.output(port!(COut, e.pose)),
        e.input(port!(EIn, c.pose)),
        Policy::Sample,
    );
    b.build().unwrap()
}

#[test]
fn subscriptions_a_run_cannot_serve_are_listed_as_unserved_with_the_reason() {
    let section = r#"(node: "bridge", publish: [(buffer: "c.e.status", topic: "status")],
        subscribe: [(buffer: "e.c.pose", topic: "~/pose_in")])"#;
    let plan = Plan::new(&spec(section), None, &system(), &adapters()).unwrap();
    assert_eq!(plan.subscriptions.len(), 1);
    let reason = "a deterministic run is not on the wall clock";
    let plan = plan.unserve_subscriptions(reason);
    assert!(plan.subscriptions.is_empty());
    assert_eq!(plan.topics.len(), 1);
    let [unserved] = plan.unserved() else {
        panic!("{:?}", plan.unserved())
    };
    assert_eq!(
        (unserved.buffer.as_str(), unserved.topic.as_str()),
        ("e.c.pose", "/bridge/pose_in")
    );
    assert_eq!(unserved.reason, reason);
    assert_eq!(
        unserved.to_string(),
        "topic `/bridge/pose_in` (buffer `e.c.pose`) is not subscribed: \
         a deterministic run is not on the wall clock"
    );
    // A process that does not run `e` has nothing unserved.
    assert!(plan.clone().only_components(&["c"]).unserved().is_empty());
    assert_eq!(plan.only_components(&["e"]).unserved().len(), 1);
}

#[test]
fn a_process_feeds_the_inputs_of_the_components_it_runs() {
    let section = r#"(publish: [(buffer: "c.e.status", topic: "status")],
        subscribe: [(buffer: "e.c.pose", topic: "pose_in")])"#;
    let plan = Plan::new(&spec(section), None, &system(), &adapters()).unwrap();
    let c = plan.clone().only_components(&["c"]);
    assert_eq!((c.topics.len(), c.subscriptions.len()), (1, 0));
    let e = plan.only_components(&["e"]);
    assert_eq!((e.topics.len(), e.subscriptions.len()), (0, 1));
}

/// The entry and name a plan of `section` is refused for.
fn refused(section: &str) -> (String, String) {
    match Plan::new(&spec(section), None, &system(), &adapters()) {
        Err(PlanError::Name { entry, name, .. }) => (entry, name),
        other => panic!("{other:?}"),
    }
}

#[test]
fn names_the_spec_checker_refuses_are_refused_naming_the_entry() {
    // Each breaks a rule of the checker's that the wire's checks lack.
    let status = |topic: &str| format!(r#"(publish: [(buffer: "c.e.status", topic: "{topic}")]"#);
    let (entry, name) = refused(&(status("a__b") + ")"));
    assert_eq!(
        (entry.as_str(), name.as_str()),
        ("topic of buffer `c.e.status`", "/a__b")
    );
    let (entry, name) = refused(&(status("a_/b") + ")"));
    assert_eq!(
        (entry.as_str(), name.as_str()),
        ("topic of buffer `c.e.status`", "/a_/b")
    );
    let long = "x".repeat(250);
    assert_eq!(refused(&(status(&long) + ")")).1, format!("/{long}"));
    let (entry, _) = refused(&(status("s") + r#", namespace: "/ns_")"#));
    assert_eq!(entry, "namespace");
    let (entry, _) = refused(&(status("s") + r#", package: "Bad_msgs")"#));
    assert_eq!(entry, "package");
    let (entry, _) = refused(&(status("s") + &format!(r#", node: "{}")"#, "n".repeat(256))));
    assert_eq!(entry, "node name");
    // A subscribed topic too.
    let (entry, name) =
        refused(&(status("s") + r#", subscribe: [(buffer: "e.c.pose", topic: "in__put")])"#));
    assert_eq!(
        (entry.as_str(), name.as_str()),
        ("topic of buffer `e.c.pose`", "/in__put")
    );
    let error =
        Plan::new(&spec(&(status("a__b") + ")")), None, &system(), &adapters()).unwrap_err();
    assert!(error.to_string().contains("`__`"), "{error}");
}
