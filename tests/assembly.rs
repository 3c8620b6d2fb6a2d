//! A system assembled from a spec: components placed in their agents with their
//! periods, links made by name from the spec's links, and every way the code and
//! the spec can disagree reported with the name of what differs.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::time::Duration;

use embodied::spec::{Assembly, AssemblyError, Spec};
use embodied::*;

const SPEC: &str = r#"(
    name: "pair",
    agents: [(
        name: "a",
        subsystems: [
            (
                name: "c",
                kind: Control,
                period_ms: 100.0,
                behaviours: [(name: "idle", kind: While, terminal: "false")],
                fsm: (initial: "idle"),
            ),
            (
                name: "e",
                kind: VirtualEffector,
                period_ms: 10.0,
                memory: [(name: "count", type: "u32")],
                inputs: [(peer: "E", buffers: [(name: "reading", type: "f64")])],
                outputs: [(peer: "E", buffers: [(name: "cmd", type: "f64")])],
                functions: [
                    (name: "drive", target: Output("E"), writes: ["cmd"]),
                    (name: "count_up", target: Memory, writes: ["count"]),
                ],
                behaviours: [(name: "run", kind: While, functions: ["drive", "count_up"], terminal: "false")],
                fsm: (initial: "run"),
            ),
        ],
        devices: [(
            name: "E",
            kind: Effector,
            period_ms: 5.0,
            inputs: [(peer: "e", buffers: [(name: "cmd", type: "f64")])],
            outputs: [(peer: "e", buffers: [(name: "reading", type: "f64")])],
        )],
    )],
    links: [
        (from: "e.E.cmd", to: "E.e.cmd", policy: Queue(2)),
        (from: "E.e.reading", to: "e.E.reading"),
    ],
    deployments: [
        (name: "one", hosts: [(name: "h", processes: [(name: "p", runs: ["c", "e", "E"])])]),
        (name: "no_device", hosts: [(name: "h", processes: [(name: "p", runs: ["c", "e"])])], omit: ["E"]),
    ],
)"#;

fn checked(text: &str) -> Spec {
    let (spec, report) = embodied::spec::check_source("pair.ron", text);
    assert!(report.is_ok(), "{}", report.short());
    spec.unwrap()
}

#[derive(Clone, Debug, Default, Group)]
#[group(peer = RealEffector)]
struct FromE {
    reading: In<f64>,
}
#[derive(Clone, Debug, Default, Buffers)]
#[expect(non_snake_case, reason = "the spec's names")]
struct CIn {
    E: FromE,
}
#[derive(Debug, Default, Group)]
#[group(peer = RealEffector)]
struct ToE {
    cmd: Out<f64>,
}
#[derive(Debug, Default, Buffers)]
#[expect(non_snake_case, reason = "the spec's names")]
struct COut {
    E: ToE,
}
#[derive(Clone, Debug, Default, Memory)]
struct CMem {
    count: u32,
}
#[derive(Subsystem)]
#[subsystem(kind = VirtualEffector, memory = CMem, input = CIn, output = COut)]
struct C;

/// The agent's control subsystem, idle.
#[derive(Subsystem)]
#[subsystem(kind = Control, memory = (), input = (), output = ())]
struct Idle;

fn idle() -> Fsm<Idle> {
    Fsm::single(Behaviour::while_loop(
        "idle",
        Action::<Idle>::new(),
        "false",
    ))
    .unwrap()
}

fn drive(m: &CMem, _: &CIn, y: &mut ToE) {
    y.cmd.set(f64::from(m.count));
}
fn count_up(m: &mut CMem, x: &CIn) {
    m.count += 1;
    if x.E.reading.is_new() {
        m.count += 100;
    }
}
fn c_fsm() -> Fsm<C> {
    Fsm::single(Behaviour::while_loop(
        "run",
        Action::<C>::new()
            .output(|y| &mut y.E, drive)
            .memory(count_up),
        "false",
    ))
    .unwrap()
}

#[derive(Clone, Debug, Default, Group)]
#[group(peer = VirtualEffector)]
struct FromC {
    cmd: In<f64>,
}
#[derive(Clone, Debug, Default, Buffers)]
struct EIn {
    e: FromC,
}
#[derive(Debug, Default, Group)]
#[group(peer = VirtualEffector)]
struct ToC {
    reading: Out<f64>,
}
#[derive(Debug, Default, Buffers)]
struct EOut {
    e: ToC,
}
/// Echoes each command as a reading; counts them.
#[derive(Default)]
struct Echo {
    got: std::sync::Arc<std::sync::atomic::AtomicU32>,
}
impl Driver for Echo {
    const KIND: DeviceKind = DeviceKind::Effector;
    type Input = EIn;
    type Output = EOut;
    fn step(&mut self, _: DriverContext<'_>, x: &EIn, y: &mut EOut) -> Result<(), DriverError> {
        if let Some(v) = x.e.cmd.fresh() {
            self.got.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
            y.e.reading.set(*v);
        }
        Ok(())
    }
}

#[test]
fn the_spec_places_and_links_the_components_and_they_run() {
    let spec = checked(SPEC);
    let mut asm = Assembly::new(&spec, "one").unwrap();
    assert!(asm.runs("E") && asm.runs("c"));
    asm.subsystem("c", (), idle()).unwrap();
    let c = asm.subsystem("e", CMem::default(), c_fsm()).unwrap();
    let echo = Echo::default();
    let got = echo.got.clone();
    asm.driver("E", echo).unwrap();
    let system = asm.build().unwrap();
    let info = system.info();
    assert_eq!(info.agents, ["a"]);
    let periods: Vec<(String, u64)> = info
        .nodes
        .iter()
        .map(|n| (n.name.clone(), n.period.as_nanos()))
        .collect();
    assert_eq!(
        periods,
        [
            ("c".to_owned(), 100_000_000),
            ("e".to_owned(), 10_000_000),
            ("E".to_owned(), 5_000_000)
        ]
    );
    let links: Vec<(String, Policy)> = info
        .links
        .iter()
        .map(|l| (l.name.clone(), l.policy))
        .collect();
    assert_eq!(
        links,
        [
            ("e.E.cmd -> E.e.cmd".to_owned(), Policy::queue(2)),
            ("E.e.reading -> e.E.reading".to_owned(), Policy::Sample),
        ]
    );
    // The exported structure is the spec's.
    let built = embodied::spec::export::spec_of("pair", info)
        .unwrap()
        .structure();
    let mut expected = spec.structure();
    expected.deployments.clear();
    assert_eq!(embodied::spec::export::difference(&expected, &built), None);
    // The links carry values both ways.
    let mut exec = Executor::new(system, ExecConfig::default());
    exec.run_for(Duration::from_millis(100)).unwrap();
    assert!(got.load(std::sync::atomic::Ordering::Relaxed) >= 5);
    assert!(exec.memory(&c).unwrap().count > 100, "a reading came back");
}

#[test]
fn every_disagreement_between_code_and_spec_is_named() {
    let spec = checked(SPEC);
    // A deployment the spec does not have.
    let e = Assembly::new(&spec, "two").unwrap_err().to_string();
    assert!(
        e.contains("no deployment `two` (it has: one, no_device)"),
        "{e}"
    );
    let mut asm = Assembly::new(&spec, "no_device").unwrap();
    // A component the spec does not declare, with the name it probably meant.
    let e = asm
        .subsystem("ee", CMem::default(), c_fsm())
        .unwrap_err()
        .to_string();
    assert!(e.contains("no component `ee`; did you mean `e`?"), "{e}");
    // One the deployment does not run.
    let e = asm.driver("E", Echo::default()).unwrap_err().to_string();
    assert!(e.contains("deployment `no_device` does not run `E`"), "{e}");
    // A deployed component missing at build time.
    let e = asm.build().unwrap_err().to_string();
    assert!(
        e.contains("`c` is run by the deployment `no_device` but was not added"),
        "{e}"
    );
    assert!(
        e.contains("`e` is run by the deployment `no_device` but was not added"),
        "{e}"
    );
    // A component of another kind.
    let mut asm = Assembly::new(&spec, "one").unwrap();
    let e = asm.subsystem::<C>("E", CMem::default(), c_fsm());
    assert!(
        matches!(&e, Err(AssemblyError::Kind { name, .. }) if name == "E"),
        "{e:?}"
    );
    // A buffer the code does not have, and one of another type.
    let text = SPEC
        .replace(
            r#"outputs: [(peer: "E", buffers: [(name: "cmd""#,
            r#"outputs: [(peer: "E", buffers: [(name: "command""#,
        )
        .replace(r#"writes: ["cmd"]"#, r#"writes: ["command"]"#)
        .replace("e.E.cmd", "e.E.command");
    let renamed = checked(&text);
    let mut asm = Assembly::new(&renamed, "one").unwrap();
    asm.subsystem("c", (), idle()).unwrap();
    asm.subsystem("e", CMem::default(), c_fsm()).unwrap();
    asm.driver("E", Echo::default()).unwrap();
    let e = asm.build().unwrap_err().to_string();
    assert!(
        e.contains("`e` has no output buffer `E.command` (it has: E.cmd)"),
        "{e}"
    );
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let period = Period::from_millis(10).unwrap();
    b.subsystem(a, "e", period, CMem::default(), c_fsm());
    b.driver(a, "E", period, Echo::default());
    assert!(
        b.connect_named("e", "E.cmd", "E", "e.cmd", Policy::Sample)
            .is_some()
    );
    assert!(
        b.connect_named("E", "e.reading", "e", "E.nothing", Policy::Sample)
            .is_none()
    );
    assert!(
        b.connect_named("E", "e.reading", "x", "E.reading", Policy::Sample)
            .is_none()
    );
    let e = b.build().unwrap_err().to_string();
    assert!(
        e.contains("`e` has no input buffer `E.nothing` (it has: E.reading)"),
        "{e}"
    );
    assert!(e.contains("no component `x`"), "{e}");
}

/// A group whose payload differs from the spec's: the link is refused by type.
#[derive(Clone, Debug, Default, Group)]
#[group(peer = RealEffector)]
struct FromEInt {
    reading: In<u32>,
}
#[derive(Clone, Debug, Default, Buffers)]
#[expect(non_snake_case, reason = "the spec's names")]
struct CInInt {
    E: FromEInt,
}
#[derive(Subsystem)]
#[subsystem(kind = VirtualEffector, memory = CMem, input = CInInt, output = COut)]
struct CInt;

#[test]
fn a_link_between_different_types_is_refused() {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let period = Period::from_millis(10).unwrap();
    let fsm = Fsm::single(Behaviour::while_loop(
        "run",
        Action::<CInt>::new().memory(|_: &mut CMem, _: &CInInt| {}),
        "false",
    ))
    .unwrap();
    b.subsystem(a, "e", period, CMem::default(), fsm);
    b.driver(a, "E", period, Echo::default());
    assert!(
        b.connect_named("E", "e.reading", "e", "E.reading", Policy::Sample)
            .is_none()
    );
    let e = b.build().unwrap_err().to_string();
    assert!(
        e.contains("joins an output of type `f64` to an input of type `u32`"),
        "{e}"
    );
}

/// The spec gives the FSM's graph; the code its actions and predicates.
#[test]
fn the_spec_drives_the_fsm_graph_of_the_code() {
    // The code ping-pongs between two behaviours.
    let code = || {
        Fsm::builder()
            .behaviour(Behaviour::repeat_loop(
                "idle",
                Action::<Idle>::new(),
                "true",
            ))
            .behaviour(Behaviour::repeat_loop("nap", Action::<Idle>::new(), "true"))
            .initial("idle")
            .arc("idle", "nap", "true")
            .arc("nap", "idle", "true")
            .build()
            .unwrap()
    };
    // The spec: once in `nap`, stay there.
    let text = SPEC.replace(
        r#"behaviours: [(name: "idle", kind: While, terminal: "false")],
                fsm: (initial: "idle"),"#,
        r#"behaviours: [
                    (name: "idle", kind: Repeat, terminal: "true"),
                    (name: "nap", kind: Repeat, terminal: "false"),
                ],
                fsm: (initial: "idle", arcs: [(from: "idle", to: "nap", when: "true")]),"#,
    );
    assert_ne!(text, SPEC);
    let spec = checked(&text);
    let mut asm = Assembly::new(&spec, "no_device").unwrap();
    let c = asm.subsystem("c", (), code()).unwrap();
    asm.subsystem("e", CMem::default(), c_fsm()).unwrap();
    let system = asm.build().unwrap();
    let fsm = system.info().nodes[0].fsm.clone().unwrap();
    assert_eq!(fsm.arcs, [("idle".into(), "nap".into(), "true".into())]);

    struct Switches(u32);
    impl Observer for Switches {
        fn transition(&mut self, e: &TransitionEvent) {
            if e.node == 0 {
                self.0 += 1;
            }
        }
    }
    let mut exec = Executor::with_observer(system, ExecConfig::default(), Switches(0));
    exec.run_for(Duration::from_secs(2)).unwrap();
    assert_eq!(exec.behaviour(&c), Some("nap"));
    assert_eq!(exec.observer().0, 1, "one switch, then `nap` for good");

    // A behaviour the spec names and the code does not: named, both lists.
    let renamed = text
        .replace(r#"name: "nap""#, r#"name: "doze""#)
        .replace(r#"to: "nap""#, r#"to: "doze""#);
    let spec = checked(&renamed);
    let mut asm = Assembly::new(&spec, "no_device").unwrap();
    let e = asm.subsystem("c", (), code()).unwrap_err();
    assert!(matches!(e, AssemblyError::Fsm { .. }), "{e}");
    let e = e.to_string();
    assert!(
        e.contains("the spec's behaviours are [doze, idle], the code's [idle, nap]"),
        "{e}"
    );
}
