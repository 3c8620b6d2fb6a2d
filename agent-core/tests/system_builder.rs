//! The system builder's checks: every structural problem of a system, reported at
//! once, before anything runs.

#![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

mod common;

use agent_core::*;
use common::*;

// ---------------------------------------------------------------------------
// Malformed systems.

#[test]
fn zero_period_is_a_typed_error() {
    assert_eq!(Period::from_millis(0), Err(PeriodError::Zero));
    assert_eq!(
        Period::from_hz(0.0).unwrap_err().to_string(),
        "a period needs a positive finite number, got 0"
    );
}

#[test]
fn every_structural_problem_is_reported_at_once() {
    let mut b = SystemBuilder::new();
    let a1 = b.agent("a1");
    let a2 = b.agent("a2");
    let a3 = b.agent("a3");
    let c1 = b.subsystem(
        a1,
        "c1",
        ms(10),
        CounterMemory { n: 0, every: 1 },
        counter_fsm(),
    );
    let e1 = b.subsystem(a1, "e1", ms(10), RecvMemory::default(), recv_fsm(false));
    let c2 = b.subsystem(
        a2,
        "c2",
        ms(10),
        CounterMemory { n: 0, every: 1 },
        counter_fsm(),
    );
    let _c2b = b.subsystem(
        a2,
        "c2b",
        ms(10),
        CounterMemory { n: 0, every: 1 },
        counter_fsm(),
    );
    let e3 = b.subsystem(a3, "e3", ms(10), RecvMemory::default(), recv_fsm(false));
    let _dup = b.subsystem(a1, "e1", ms(10), RecvMemory::default(), recv_fsm(false));
    // Fine.
    b.connect(
        c1.output(port!(CounterOut, e.count)),
        e1.input(port!(RecvIn, c.count)),
        Policy::Sample,
    );
    // Fed twice.
    b.connect(
        c2.output(port!(CounterOut, e.count)),
        e1.input(port!(RecvIn, c.count)),
        Policy::Sample,
    );
    // Across agents to an effector.
    b.connect(
        c1.output(port!(CounterOut, e.count)),
        e3.input(port!(RecvIn, c.count)),
        Policy::queue(0),
    );
    // Effector to a control subsystem of another agent.
    b.connect(
        e3.output(port!(RecvOut, c.echo)),
        c2.input(port!(CounterIn, e.echo)),
        Policy::Sample,
    );
    let err = b.build().unwrap_err();
    let p = &err.problems;
    let has = |f: &dyn Fn(&BuildProblem) -> bool| p.iter().any(f);
    assert!(
        has(&|x| x == &BuildProblem::DuplicateNode("e1".into())),
        "{err}"
    );
    assert!(
        has(&|x| matches!(x, BuildProblem::InputFedTwice { input, .. } if input == "e1.c.count")),
        "{err}"
    );
    assert!(
        has(
            &|x| matches!(x, BuildProblem::Structure { link, .. } if link == "c1.e.count -> e3.c.count")
        ),
        "{err}"
    );
    assert!(
        has(
            &|x| matches!(x, BuildProblem::Structure { link, .. } if link == "e3.c.echo -> c2.e.echo")
        ),
        "{err}"
    );
    assert!(
        has(&|x| x == &BuildProblem::ZeroQueueBound("c1.e.count -> e3.c.count".into())),
        "{err}"
    );
    assert!(
        has(
            &|x| matches!(x, BuildProblem::SeveralControls { agent, count: 2, .. } if agent == "a2")
        ),
        "{err}"
    );
    assert!(
        has(&|x| x == &BuildProblem::NoControl("a3".into())),
        "{err}"
    );
    assert!(
        has(
            &|x| matches!(x, BuildProblem::Structure { link, .. } if link == "c2.e.count -> e1.c.count")
        ),
        "{err}"
    );
    assert_eq!(p.len(), 8, "{err}");
}

#[test]
fn a_group_peer_must_match_the_linked_kind() {
    // A control subsystem's effector group linked to a virtual receptor.
    struct Rx;
    impl Subsystem for Rx {
        const KIND: SubsystemKind = SubsystemKind::VirtualReceptor;
        type Memory = ();
        type Input = RecvIn;
        type Output = ();
    }
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let c = b.subsystem(
        a,
        "c",
        ms(10),
        CounterMemory { n: 0, every: 1 },
        counter_fsm(),
    );
    let r = b.subsystem(
        a,
        "r",
        ms(10),
        (),
        Fsm::single(Behaviour::while_loop("idle", Action::<Rx>::new(), "false")).unwrap(),
    );
    b.connect(
        c.output(port!(CounterOut, e.count)),
        r.input(port!(RecvIn, c.count)),
        Policy::Sample,
    );
    let err = b.build().unwrap_err();
    assert_eq!(
        err.problems,
        vec![BuildProblem::PeerMismatch {
            link: "c.e.count -> r.c.count".into(),
            port: "e.count".into(),
            declared: NodeKind::VirtualEffector,
            actual: NodeKind::VirtualReceptor,
        }]
    );
}

#[test]
fn handles_from_another_builder_are_refused() {
    let mut other = SystemBuilder::new();
    let oa = other.agent("x");
    let foreign = other.subsystem(
        oa,
        "r",
        ms(10),
        Vec::<u64>::new(),
        Fsm::single(Behaviour::while_loop(
            "read",
            Action::<Reader>::new(),
            "false",
        ))
        .unwrap(),
    );
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let c = b.subsystem(
        a,
        "c",
        ms(10),
        CounterMemory { n: 0, every: 1 },
        counter_fsm(),
    );
    // Node 0 of `b` is a Counter, not a Reader: the handle is caught.
    b.connect(
        c.output(port!(CounterOut, e.count)),
        foreign.input(port!(ReaderIn, r.value)),
        Policy::Sample,
    );
    let err = b.build().unwrap_err();
    assert!(
        matches!(&err.problems[0], BuildProblem::ForeignHandle(_)),
        "{err}"
    );
}

#[test]
fn the_system_builder_refuses_names_the_spec_checker_refuses() {
    let mut sys = SystemBuilder::new();
    let a = sys.agent("self");
    let _ = sys.agent("a b");
    let _ = a;
    let err = sys.build().unwrap_err();
    let text = err.to_string();
    assert!(
        text.contains("agent name `self` can be no Rust identifier"),
        "{text}"
    );
    assert!(
        text.contains("agent name `a b` is not an identifier"),
        "{text}"
    );
}

// ---------------------------------------------------------------------------
// What the nodes' descriptions share.

/// The subsystems that run one FSM (clones of it, as the copies of an agent
/// in a large system or the robots of a fleet) share its description and its
/// behaviours' names rather than holding a copy each; an FSM built again from
/// the same definition is described alike but not shared.
#[test]
fn subsystems_of_one_fsm_share_its_description() {
    let mut b = SystemBuilder::new();
    let (a1, a2, a3) = (b.agent("a1"), b.agent("a2"), b.agent("a3"));
    let fsm = counter_fsm();
    let memory = || CounterMemory { n: 0, every: 1 };
    b.subsystem(a1, "c1", ms(10), memory(), fsm.clone());
    b.subsystem(a2, "c2", ms(10), memory(), fsm);
    b.subsystem(a3, "c3", ms(10), memory(), counter_fsm());
    let system = b.build().unwrap();
    let nodes = &system.info().nodes;
    let (c1, c2, c3) = (&nodes[0], &nodes[1], &nodes[2]);
    let (f1, f2, f3) = (c1.fsm.as_ref(), c2.fsm.as_ref(), c3.fsm.as_ref());
    let (f1, f2, f3) = (f1.unwrap(), f2.unwrap(), f3.unwrap());
    assert!(
        std::sync::Arc::ptr_eq(f1, f2),
        "one description for c1 and c2"
    );
    assert!(std::sync::Arc::ptr_eq(&c1.behaviours, &c2.behaviours));
    assert!(!std::sync::Arc::ptr_eq(f1, f3), "c3's FSM was built apart");
    assert_eq!(f1, f3, "and is described alike");
    assert_eq!(**f1, counter_fsm().describe());
    let names: Vec<&str> = f1.behaviours.iter().map(|b| b.name.as_str()).collect();
    assert_eq!(*c1.behaviours, names, "the names are the description's");
    assert!(!c1.behaviours.is_empty());
}
