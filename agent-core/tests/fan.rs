//! Fans: a control subsystem with one group per peer, as many as the system
//! has peers, linked by type (`port!(HubOut, robots[k].plan)`) and by name
//! (`hub.robots[k].plan`); an element the fan lacks is a build problem.

#![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

use agent_core::*;
use proptest::prelude::*;

// ---------------------------------------------------------------------------
// A hub (one agent's control subsystem) sending each robot its own plan and
// keeping every robot's last acknowledgement; a robot acknowledging plans.

struct Hub;

#[derive(Clone, Debug, Default)]
struct HubMemory {
    n: u64,
    /// `acks[k]`: the acknowledgements robot `k` sent, in order.
    acks: Vec<Vec<u64>>,
}

#[derive(Debug, Default)]
struct ToRobot {
    plan: Out<u64>,
}
impl Group for ToRobot {
    const PEER: NodeKind = NodeKind::Control;
    fn buffer_port<B: Send + 'static>(
        group_name: &'static str,
        group: impl Access<B, Self>,
        buffer: &str,
    ) -> Option<BufferPort> {
        (buffer == "plan")
            .then(|| BufferPort::out_group(group_name, group, "plan", |g: &mut Self| &mut g.plan))
    }
}

#[derive(Debug, Default)]
struct FromRobot {
    ack: In<u64>,
}
impl Group for FromRobot {
    const PEER: NodeKind = NodeKind::Control;
    fn buffer_port<B: Send + 'static>(
        group_name: &'static str,
        group: impl Access<B, Self>,
        buffer: &str,
    ) -> Option<BufferPort> {
        (buffer == "ack")
            .then(|| BufferPort::in_group(group_name, group, "ack", |g: &mut Self| &mut g.ack))
    }
}

#[derive(Debug, Default)]
struct HubOut {
    robots: Fan<ToRobot>,
}

#[derive(Debug, Default)]
struct HubIn {
    robots: Fan<FromRobot>,
}

impl Subsystem for Hub {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = HubMemory;
    type Input = HubIn;
    type Output = HubOut;
    fn ports() -> Option<PortTable> {
        Some(PortTable {
            inputs: |path| {
                let rest = path.strip_prefix("robots")?;
                <Fan<FromRobot> as Group>::buffer_port::<HubIn>(
                    "robots",
                    |x: &mut HubIn| &mut x.robots,
                    rest,
                )
            },
            outputs: |path| {
                let rest = path.strip_prefix("robots")?;
                <Fan<ToRobot> as Group>::buffer_port::<HubOut>(
                    "robots",
                    |y: &mut HubOut| &mut y.robots,
                    rest,
                )
            },
        })
    }
}

/// Robot `k` gets `1000 * k + n` at the hub's iteration `n`.
fn hub_fsm() -> Fsm<Hub> {
    Fsm::single(Behaviour::while_loop(
        "dispatch",
        Action::<Hub>::new()
            .output(
                |y| &mut y.robots,
                |m: &HubMemory, _: &HubIn, y: &mut Fan<ToRobot>| {
                    for (k, robot) in y.iter_mut().enumerate() {
                        robot.plan.set(1000 * k as u64 + m.n);
                    }
                },
            )
            .memory(|m: &mut HubMemory, x: &HubIn| {
                m.acks.resize(x.robots.len(), Vec::new());
                for (acks, robot) in m.acks.iter_mut().zip(x.robots.iter()) {
                    if let Some(&a) = robot.ack.fresh() {
                        acks.push(a);
                    }
                }
                m.n += 1;
            }),
        "false",
    ))
    .unwrap()
}

struct Robot;

#[derive(Debug, Default)]
struct FromHub {
    plan: In<u64>,
}
impl Group for FromHub {
    const PEER: NodeKind = NodeKind::Control;
    fn buffer_port<B: Send + 'static>(
        group_name: &'static str,
        group: impl Access<B, Self>,
        buffer: &str,
    ) -> Option<BufferPort> {
        (buffer == "plan")
            .then(|| BufferPort::in_group(group_name, group, "plan", |g: &mut Self| &mut g.plan))
    }
}

#[derive(Debug, Default)]
struct ToHub {
    ack: Out<u64>,
}
impl Group for ToHub {
    const PEER: NodeKind = NodeKind::Control;
    fn buffer_port<B: Send + 'static>(
        group_name: &'static str,
        group: impl Access<B, Self>,
        buffer: &str,
    ) -> Option<BufferPort> {
        (buffer == "ack")
            .then(|| BufferPort::out_group(group_name, group, "ack", |g: &mut Self| &mut g.ack))
    }
}

#[derive(Debug, Default)]
struct RobotIn {
    hub: FromHub,
}

#[derive(Debug, Default)]
struct RobotOut {
    hub: ToHub,
}

impl Subsystem for Robot {
    const KIND: SubsystemKind = SubsystemKind::Control;
    /// The plans received.
    type Memory = Vec<u64>;
    type Input = RobotIn;
    type Output = RobotOut;
    fn ports() -> Option<PortTable> {
        Some(PortTable {
            inputs: |path| {
                let buffer = path.strip_prefix("hub.")?;
                FromHub::buffer_port::<RobotIn>("hub", |x: &mut RobotIn| &mut x.hub, buffer)
            },
            outputs: |path| {
                let buffer = path.strip_prefix("hub.")?;
                ToHub::buffer_port::<RobotOut>("hub", |y: &mut RobotOut| &mut y.hub, buffer)
            },
        })
    }
}

/// A robot acknowledges each plan with the plan plus one.
fn robot_fsm() -> Fsm<Robot> {
    Fsm::single(Behaviour::while_loop(
        "ack",
        Action::<Robot>::new()
            .output(
                |y| &mut y.hub,
                |_: &Vec<u64>, x: &RobotIn, y: &mut ToHub| {
                    if let Some(&p) = x.hub.plan.fresh() {
                        y.ack.set(p + 1);
                    }
                },
            )
            .memory(|m: &mut Vec<u64>, x: &RobotIn| {
                if let Some(&p) = x.hub.plan.fresh() {
                    m.push(p);
                }
            }),
        "false",
    ))
    .unwrap()
}

fn ms(n: u64) -> Period {
    Period::from_millis(n).unwrap()
}

/// A hub with a fan of `fan` elements and `robots` robots, robot `k` linked to
/// element `k` by name (`by_name`) or by type.
fn fleet(
    fan: usize,
    robots: usize,
    by_name: bool,
) -> (
    SystemBuilder,
    SubsystemHandle<Hub>,
    Vec<SubsystemHandle<Robot>>,
) {
    let mut b = SystemBuilder::new();
    let a0 = b.agent("a0");
    let hub = b.subsystem_with_buffers(
        a0,
        "hub",
        ms(10),
        HubMemory::default(),
        hub_fsm(),
        HubIn {
            robots: Fan::new(fan),
        },
        HubOut {
            robots: Fan::new(fan),
        },
    );
    let mut handles = Vec::new();
    for k in 0..robots {
        let agent = b.agent(format!("a{}", k + 1));
        let name = format!("robot_{k}");
        let robot = b.subsystem(agent, name.as_str(), ms(10), Vec::new(), robot_fsm());
        if by_name {
            let plan = format!("robots[{k}].plan");
            let ack = format!("robots[{k}].ack");
            b.connect_named("hub", &plan, &name, "hub.plan", Policy::Sample);
            b.connect_named(&name, "hub.ack", "hub", &ack, Policy::Sample);
        } else {
            b.connect(
                hub.output(port!(HubOut, robots[k].plan)),
                robot.input(port!(RobotIn, hub.plan)),
                Policy::Sample,
            );
            b.connect(
                robot.output(port!(RobotOut, hub.ack)),
                hub.input(port!(HubIn, robots[k].ack)),
                Policy::Sample,
            );
        }
        handles.push(robot);
    }
    (b, hub, handles)
}

/// Every robot gets only its own element's plans, and the hub each robot's
/// acknowledgements in that robot's element.
fn check_dispatch(robots: usize, by_name: bool) {
    let (b, hub, handles) = fleet(robots, robots, by_name);
    let system = b.build().unwrap();
    let names: Vec<&str> = system
        .info()
        .links
        .iter()
        .map(|l| l.name.as_str())
        .collect();
    if robots > 0 {
        assert_eq!(names[0], "hub.robots[0].plan -> robot_0.hub.plan");
    }
    let mut x = Executor::new(system, ExecConfig::default());
    x.run_until(Time::from_nanos(50_000_000)).unwrap();
    for (k, robot) in handles.iter().enumerate() {
        let got = x.memory(robot).unwrap();
        assert!(got.len() >= 3, "robot {k} got {got:?}");
        let base = 1000 * k as u64;
        assert!(
            got.iter().all(|p| (base..base + 1000).contains(p)),
            "robot {k} got another robot's plans: {got:?}"
        );
        let acks = &x.memory(&hub).unwrap().acks[k];
        assert!(!acks.is_empty(), "no acknowledgement from robot {k}");
        assert!(
            acks.iter().all(|a| got.contains(&(a - 1))),
            "{acks:?} {got:?}"
        );
    }
    assert_eq!(x.memory(&hub).unwrap().acks.len(), robots);
}

#[test]
fn each_element_reaches_its_own_peer_by_type() {
    check_dispatch(3, false);
}

#[test]
fn each_element_reaches_its_own_peer_by_name() {
    check_dispatch(4, true);
}

#[test]
fn a_fan_of_no_peers_runs_alone() {
    check_dispatch(0, true);
}

#[test]
fn a_link_to_an_element_the_fan_lacks_is_a_build_problem() {
    for by_name in [false, true] {
        // Three robots, a fan of two: robot 2's links reach `robots[2]`.
        let (b, _, _) = fleet(2, 3, by_name);
        let err = b.build().unwrap_err();
        let lacking: Vec<_> = err
            .problems
            .iter()
            .filter_map(|p| match p {
                BuildProblem::NoFanElement {
                    node,
                    group,
                    index,
                    len,
                    ..
                } => Some((node.as_str(), group.as_str(), *index, *len)),
                _ => None,
            })
            .collect();
        assert_eq!(lacking, [("hub", "robots", 2, 2), ("hub", "robots", 2, 2)]);
        assert_eq!(err.problems.len(), 2, "{err}");
        assert!(err.to_string().contains("no `robots[2]`"), "{err}");
    }
}

#[test]
fn a_default_fan_has_no_element() {
    let mut b = SystemBuilder::new();
    let a0 = b.agent("a0");
    let a1 = b.agent("a1");
    b.subsystem(a0, "hub", ms(10), HubMemory::default(), hub_fsm());
    b.subsystem(a1, "robot_0", ms(10), Vec::new(), robot_fsm());
    b.connect_named(
        "hub",
        "robots[0].plan",
        "robot_0",
        "hub.plan",
        Policy::Sample,
    );
    let err = b.build().unwrap_err();
    assert!(
        matches!(
            err.problems[..],
            [BuildProblem::NoFanElement {
                index: 0,
                len: 0,
                ..
            }]
        ),
        "{err}"
    );
}

#[test]
fn malformed_element_names_are_unknown_buffers() {
    for path in [
        "robots[x].plan",
        "robots[].plan",
        "robots[01].plan",
        "robots[1]plan",
        "robots[1].",
        "robots.plan",
        "robots[1].nope",
        "robots[-1].plan",
        "robots[99999999999999999999999].plan",
    ] {
        let mut b = SystemBuilder::new();
        let a0 = b.agent("a0");
        let a1 = b.agent("a1");
        b.subsystem_with_buffers(
            a0,
            "hub",
            ms(10),
            HubMemory::default(),
            hub_fsm(),
            HubIn::default(),
            HubOut {
                robots: Fan::new(2),
            },
        );
        b.subsystem(a1, "robot_0", ms(10), Vec::new(), robot_fsm());
        b.connect_named("hub", path, "robot_0", "hub.plan", Policy::Sample);
        let err = b.build().unwrap_err();
        assert!(
            matches!(&err.problems[..], [BuildProblem::UnknownBuffer { buffer, .. }] if buffer == path),
            "{path}: {err}"
        );
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// A fan of `len` elements accepts exactly the links to indices below
    /// `len`, by type and by name.
    #[test]
    fn only_the_fans_elements_link(len in 0usize..6, index in 0usize..8, by_name: bool) {
        let mut b = SystemBuilder::new();
        let a0 = b.agent("a0");
        let a1 = b.agent("a1");
        let hub = b.subsystem_with_buffers(
            a0, "hub", ms(10), HubMemory::default(), hub_fsm(),
            HubIn { robots: Fan::new(len) }, HubOut { robots: Fan::new(len) },
        );
        let robot = b.subsystem(a1, "robot_0", ms(10), Vec::new(), robot_fsm());
        if by_name {
            b.connect_named("hub", &format!("robots[{index}].plan"), "robot_0", "hub.plan", Policy::Sample);
            b.connect_named("robot_0", "hub.ack", "hub", &format!("robots[{index}].ack"), Policy::Sample);
        } else {
            b.connect(
                hub.output(port!(HubOut, robots[index].plan)),
                robot.input(port!(RobotIn, hub.plan)),
                Policy::Sample,
            );
            b.connect(
                robot.output(port!(RobotOut, hub.ack)),
                hub.input(port!(HubIn, robots[index].ack)),
                Policy::Sample,
            );
        }
        let built = b.build();
        match &built {
            Ok(_) => prop_assert!(index < len),
            Err(e) => {
                prop_assert!(index >= len);
                prop_assert_eq!(e.problems.len(), 2, "{}", e);
            }
        }
        if let Ok(system) = built {
            let mut x = Executor::new(system, ExecConfig::default());
            x.run_until(Time::from_nanos(30_000_000)).unwrap();
            let acks = &x.memory(&hub).unwrap().acks;
            prop_assert_eq!(acks.len(), len);
            for (k, a) in acks.iter().enumerate() {
                // Only the linked element hears the robot.
                prop_assert_eq!(a.is_empty(), k != index, "{:?}", acks);
            }
        }
    }
}
