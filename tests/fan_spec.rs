//! A system with a fan exported to a spec and read back keeps the fan: the
//! hub's group is written with its `peers` (element `k`'s peer the robot its
//! links reach), its links name the elements `hub.robots[k].buffer`, and the
//! RON text parses and passes the checker with the same peers. An element
//! below the last linked one that is linked to nothing cannot be named: the
//! export says which.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use embodied::spec::export::{ExportError, spec_of, to_ron};
use embodied::*;

#[derive(Debug, Default, Group)]
#[group(peer = Control)]
struct FromRobot {
    ack: In<u64>,
}

#[derive(Debug, Default, Group)]
#[group(peer = Control)]
struct ToRobot {
    plan: Out<u64>,
}

#[derive(Debug, Default, Buffers)]
struct HubIn {
    robots: Fan<FromRobot>,
}

#[derive(Debug, Default, Buffers)]
struct HubOut {
    robots: Fan<ToRobot>,
}

#[derive(Debug, Default, Memory)]
struct HubMemory {
    n: u64,
}

#[derive(Subsystem)]
#[subsystem(kind = Control, memory = HubMemory, input = HubIn, output = HubOut)]
struct Hub;

#[derive(Debug, Default, Group)]
#[group(peer = Control)]
struct FromHub {
    plan: In<u64>,
}

#[derive(Debug, Default, Group)]
#[group(peer = Control)]
struct ToHub {
    ack: Out<u64>,
}

#[derive(Debug, Default, Buffers)]
struct RobotIn {
    hub: FromHub,
}

#[derive(Debug, Default, Buffers)]
struct RobotOut {
    hub: ToHub,
}

#[derive(Debug, Default, Memory)]
struct RobotMemory {
    plans: u64,
}

#[derive(Subsystem)]
#[subsystem(kind = Control, memory = RobotMemory, input = RobotIn, output = RobotOut)]
struct Robot;

fn hub_fsm() -> Fsm<Hub> {
    let act = Action::<Hub>::new()
        .output(
            |y| &mut y.robots,
            |m: &HubMemory, _: &HubIn, y: &mut Fan<ToRobot>| {
                for r in y.iter_mut() {
                    r.plan.set(m.n);
                }
            },
        )
        .memory(|m: &mut HubMemory, _: &HubIn| m.n += 1);
    Fsm::single(Behaviour::while_loop("dispatch", act, "false")).expect("one behaviour")
}

fn robot_fsm() -> Fsm<Robot> {
    let act = Action::<Robot>::new()
        .output(
            |y| &mut y.hub,
            |_: &RobotMemory, x: &RobotIn, y: &mut ToHub| {
                if let Some(&p) = x.hub.plan.fresh() {
                    y.ack.set(p);
                }
            },
        )
        .memory(|m: &mut RobotMemory, x: &RobotIn| m.plans += u64::from(x.hub.plan.is_new()));
    Fsm::single(Behaviour::while_loop("ack", act, "false")).expect("one behaviour")
}

/// A hub with a fan of `fan` elements; robot `k` (named `robot_<names[k]>`)
/// linked to element `k` for each `k` in `linked`.
fn fleet(fan: usize, linked: &[usize]) -> System {
    let period = Period::from_millis(10).expect("a period");
    let mut b = SystemBuilder::new();
    let a0 = b.agent("a0");
    b.subsystem_with_buffers(
        a0,
        "hub",
        period,
        HubMemory::default(),
        hub_fsm(),
        HubIn {
            robots: Fan::new(fan),
        },
        HubOut {
            robots: Fan::new(fan),
        },
    );
    // Robots named against their order, so that a peer taken from the
    // wrong element shows.
    for &k in linked {
        let agent = b.agent(format!("a{}", k + 1));
        let name = format!("robot_{}", 10 - k);
        b.subsystem(
            agent,
            name.as_str(),
            period,
            RobotMemory::default(),
            robot_fsm(),
        );
        let element = format!("robots[{k}]");
        b.connect_named(
            "hub",
            &format!("{element}.plan"),
            &name,
            "hub.plan",
            Policy::Sample,
        );
        b.connect_named(
            &name,
            "hub.ack",
            "hub",
            &format!("{element}.ack"),
            Policy::Sample,
        );
    }
    b.build().expect("a fleet")
}

#[test]
fn a_fan_exported_and_read_back_keeps_its_peers_and_passes_the_checker() {
    let system = fleet(3, &[2, 0, 1]);
    let exported = spec_of("fleet", system.info()).expect("exports");
    let text = to_ron(&exported).expect("as RON");
    let (parsed, report) = embodied::spec::check_source("fleet.ron", text.as_str());
    assert!(report.is_ok(), "{}\n{text}", report.render(100));
    let parsed = parsed.expect("parses");
    assert_eq!(parsed, exported, "the text reads back as what was written");
    let hub = &parsed.agents[0].subsystems[0];
    assert_eq!(hub.name, "hub");
    let peers = ["robot_10", "robot_9", "robot_8"];
    for groups in [&hub.inputs, &hub.outputs] {
        assert_eq!(groups.len(), 1, "{text}");
        assert_eq!(groups[0].peer, "robots");
        assert_eq!(groups[0].peers, peers, "element k's peer is robot k");
    }
    let ends: Vec<(&str, &str)> = parsed
        .links
        .iter()
        .map(|l| (l.from.as_str(), l.to.as_str()))
        .collect();
    assert!(
        ends.contains(&("hub.robots[1].plan", "robot_9.hub.plan")),
        "{ends:?}"
    );
    assert!(
        ends.contains(&("robot_8.hub.ack", "hub.robots[2].ack")),
        "{ends:?}"
    );
    // Every robot's group names the hub, whose fan's function writes `robots`.
    let robot = &parsed.agents[1].subsystems[0];
    assert_eq!(robot.inputs[0].peer, "hub");
    let fan = embodied::spec::model::Target::Output("robots".into());
    assert!(hub.functions.iter().any(|f| f.target == fan), "{text}");
}

#[test]
fn an_element_linked_to_nothing_below_a_linked_one_is_named() {
    let system = fleet(3, &[0, 2]);
    let err = spec_of("fleet", system.info()).expect_err("element 1 has no peer");
    assert!(
        matches!(&err, ExportError::Unlinked { node, group } if node == "hub" && group == "robots[1]"),
        "{err}"
    );
}
