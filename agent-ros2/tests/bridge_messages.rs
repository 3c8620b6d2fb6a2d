//! One definition per message name across a plan: two buffer types of one
//! bare name (`a::State`, `b::State`), each using an `Item` helper of its
//! own, are published under distinct names, each topic's hash that of its
//! own messages.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use agent_core::{
    Action, Behaviour, Fsm, Group, In, NodeKind, Out, Period, Policy, Subsystem, SubsystemKind,
    SystemBuilder, port,
};
use agent_ros2::bridge::{Adapters, Plan};
use agent_ros2::types::{TypeDescription, type_hash};

mod a {
    /// Rows of any length: `Item` is `float64[] value`.
    #[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
    pub(crate) struct State {
        pub(crate) rows: Vec<Vec<f64>>,
    }
}

mod b {
    /// Rows of three: `Item` is `float32[3] value`.
    #[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
    pub(crate) struct State {
        pub(crate) rows: Vec<[f32; 3]>,
    }
}

#[derive(Debug, Default)]
struct ToE {
    first: Out<a::State>,
    second: Out<b::State>,
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
    type Memory = ();
    type Input = ();
    type Output = COut;
}

#[derive(Debug, Default, Clone)]
struct FromC {
    first: In<a::State>,
    second: In<b::State>,
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

const SPEC: &str = r#"(
    name: "clash",
    agents: [(name: "a", subsystems: [
        (name: "c", kind: Control, period_ms: 10.0,
         outputs: [(peer: "e", buffers: [(name: "first", type: "StateA"), (name: "second", type: "StateB")])],
         behaviours: [(name: "go", kind: While, terminal: "false")], fsm: (initial: "go")),
        (name: "e", kind: VirtualEffector, period_ms: 10.0,
         inputs: [(peer: "c", buffers: [(name: "first", type: "StateA"), (name: "second", type: "StateB")])],
         behaviours: [(name: "keep", kind: While, terminal: "false")], fsm: (initial: "keep")),
    ])],
    links: [
        (from: "c.e.first", to: "e.c.first", policy: Sample),
        (from: "c.e.second", to: "e.c.second", policy: Sample),
    ],
    ros2: (publish: [(buffer: "c.e.first", topic: "first"), (buffer: "c.e.second", topic: "second")]),
)"#;

#[test]
fn helpers_and_roots_defined_differently_get_distinct_names_and_their_own_hashes() {
    let mut builder = SystemBuilder::new();
    let agent = builder.agent("a");
    let period = Period::from_millis(10).unwrap();
    let go = Fsm::single(Behaviour::while_loop("go", Action::<C>::new(), "false"));
    let keep = Fsm::single(Behaviour::while_loop("keep", Action::<E>::new(), "false"));
    let c = builder.subsystem(agent, "c", period, (), go.unwrap());
    let e = builder.subsystem(agent, "e", period, (), keep.unwrap());
    builder.connect(
        c.output(port!(COut, e.first)),
        e.input(port!(EIn, c.first)),
        Policy::Sample,
    );
    builder.connect(
        c.output(port!(COut, e.second)),
        e.input(port!(EIn, c.second)),
        Policy::Sample,
    );
    let system = builder.build().unwrap();
    let spec = agent_spec::options().from_str(SPEC).unwrap();
    let plan = Plan::new(&spec, None, &system, &Adapters::new()).unwrap();
    let [first, second] = &plan.topics[..] else {
        panic!("{plan:?}")
    };
    assert_eq!(
        first.messages.msg_text(),
        "clash_msgs/Item[] rows\n\
         ================================================================================\n\
         MSG: clash_msgs/Item\nfloat64[] value\n"
    );
    assert_eq!(
        second.messages.msg_text(),
        "clash_msgs/Item2[] rows\n\
         ================================================================================\n\
         MSG: clash_msgs/Item2\nfloat32[3] value\n"
    );
    assert_eq!(first.key.type_name().to_string(), "clash_msgs/msg/State");
    assert_eq!(second.key.type_name().to_string(), "clash_msgs/msg/State2");
    for topic in [first, second] {
        // The hash announced is that of the messages (and text) published.
        let hash = type_hash(&topic.messages).unwrap();
        assert_eq!(*topic.key.type_hash(), hash);
        let description = TypeDescription::of(&topic.messages).unwrap();
        let names: Vec<_> = description
            .referenced_type_descriptions
            .iter()
            .map(|t| t.type_name.as_str())
            .collect();
        let item = &topic.messages.referenced[0].name;
        assert_eq!(names, [item.to_string()]);
    }
    assert_ne!(first.key.type_hash(), second.key.type_hash());
}
