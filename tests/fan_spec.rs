//! A system with a fan, in its spec. Exported and read back it keeps the
//! fan: the hub's group is written with its `peers` (element `k`'s peer the
//! robot its links reach), its links name the elements `hub.robots[k].buffer`,
//! and the RON text parses and passes the checker with the same peers; an
//! element below the last linked one that is linked to nothing cannot be
//! named, and the export says which. Its contracts name one element
//! (`hub.robots[1].plan`) or every element (`hub.robots[*].plan`), and the
//! monitors judge each element on its own peer's values, live and over the
//! run's recording alike.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::time::Duration;

use embodied::monitor::live::Live;
use embodied::monitor::recording::{evaluate, needed};
use embodied::monitor::{Broke, Monitors, Violation};
use embodied::record::{McapRecorder, RecordOptions, Recording, Values};
use embodied::spec::contracts::{Contracts, ValueRange};
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
                // Robot k's plans count from 1000 k.
                for (k, r) in y.iter_mut().enumerate() {
                    r.plan.set(1000 * k as u64 + m.n);
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
        add_robot(&mut b, k, period);
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

/// A range of at most `max` on `buffer`, named `name`.
fn at_most(name: &str, buffer: &str, max: f64) -> ValueRange {
    ValueRange {
        name: name.into(),
        buffer: buffer.into(),
        field: None,
        min: None,
        max: Some(max),
    }
}

/// Each violation as (contract, value), in order.
fn shown(m: &Monitors, v: &[Violation]) -> Vec<(String, f64)> {
    v.iter()
        .map(|v| {
            let name = m.contract(v.contract).map_or("?", |c| c.name.as_str());
            let value = match v.broke {
                Broke::OutOfRange { value, .. } => value,
                _ => f64::NAN,
            };
            (name.to_owned(), value)
        })
        .collect()
}

#[test]
fn a_range_on_one_element_is_judged_on_that_peers_values_only_live_and_recorded() {
    // Robot k is sent 1000 k + n at the hub's n-th activation (10 ms): in
    // 1 s, n runs to about 100. At most 1050 on element 1 breaks from n = 51
    // on that element; at most 2050 on every element breaks on element 2
    // only (element 0 stays below 200, element 1 below 1200).
    let system = fleet(3, &[0, 1, 2]);
    let mut spec = spec_of("fleet", system.info()).expect("exports");
    spec.contracts = Some(Contracts {
        ranges: vec![
            at_most("one", "hub.robots[1].plan", 1050.0),
            at_most("every", "hub.robots[*].plan", 2050.0),
        ],
        ..Contracts::default()
    });
    let text = to_ron(&spec).expect("as RON");
    let (_, report) = embodied::spec::check_source("fleet.ron", text.as_str());
    assert!(report.is_ok(), "{}", report.render(100));

    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("fan_ranges.mcap");
    let options = RecordOptions {
        values: Values::Json,
        ..RecordOptions::default()
    };
    let recorder = McapRecorder::create(&path, &system, options).expect("a recording");
    let live = Live::new(Monitors::new(&spec).expect("monitors"), &system);
    let config = ExecConfig {
        on_error: OnError::Continue,
        ..ExecConfig::default()
    };
    let mut exec = Executor::with_observer(system, config, (recorder, live.watch()));
    exec.run_for(Duration::from_secs(1)).expect("runs");
    let (recorder, watch) = exec.into_observer();
    drop(watch);
    recorder.finish().expect("written");

    let verdicts = live.verdicts();
    assert!(verdicts.not_judged.is_empty(), "{:?}", verdicts.not_judged);
    let lines = shown(live.monitors(), &verdicts.violations);
    let names: std::collections::BTreeSet<&str> = lines.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        names.into_iter().collect::<Vec<_>>(),
        ["every[2]", "one"],
        "{lines:?}"
    );
    for (name, value) in &lines {
        let on = if name == "one" {
            1051.0..1200.0
        } else {
            2051.0..2200.0
        };
        assert!(on.contains(value), "{name}: {value} is not its peer's");
    }
    // Every activation from n = 51 on, on each broken element.
    let ones = lines.iter().filter(|(n, _)| n == "one").count();
    assert!(ones >= 40, "{ones} violations of `one`: {lines:?}");

    // `embodied monitor` over the recording: the same verdicts.
    let recorded = Recording::open_filtered(&path, needed).expect("opens");
    let mut monitors = Monitors::new(&spec).expect("monitors");
    let offline = evaluate(&mut monitors, &recorded).expect("evaluates");
    assert!(
        offline.not_evaluable.is_empty(),
        "{:?}",
        offline.not_evaluable
    );
    assert_eq!(shown(&monitors, &offline.violations), lines);
}

#[cfg(feature = "ros2")]
#[test]
fn a_whole_fan_published_to_ros_2_is_one_topic_per_element_on_its_own_link() {
    use embodied::ros2::bridge::{Adapters, Plan};
    let system = fleet(3, &[0, 1, 2]);
    let spec = spec_of("fleet", system.info()).expect("exports");
    let text = to_ron(&spec).expect("as RON");
    let body = text.trim_end().strip_suffix(')').expect("a struct");
    let text = format!(
        "{},\n    ros2: (publish: [(buffer: \"hub.robots[*].plan\", topic: \"plans\")], subscribe: [(buffer: \"hub.robots[*].ack\", topic: \"acks\")]),\n)",
        body.trim_end().trim_end_matches(',')
    );
    let (spec, report) = embodied::spec::check_source("fleet.ron", text.as_str());
    assert!(report.is_ok(), "{}", report.render(100));
    let spec = spec.expect("parses");
    let plan = Plan::new(&spec, None, &system, &Adapters::new()).expect("a plan");
    let info = system.info();
    for k in 0..3 {
        let topic = &plan.topics[k];
        assert_eq!(topic.buffer, format!("hub.robots[{k}].plan"));
        assert_eq!(topic.key.topic(), format!("/plans_{k}"));
        // Its own element's link: to robot k (named 10 - k).
        let link = &info.links[topic.link];
        assert_eq!(info.nodes[link.to].name, format!("robot_{}", 10 - k));
        let inbound = &plan.subscriptions[k];
        assert_eq!(inbound.buffer, format!("hub.robots[{k}].ack"));
        assert_eq!(inbound.key.topic(), format!("/acks_{k}"));
    }
    assert_eq!((plan.topics.len(), plan.subscriptions.len()), (3, 3));
}

/// The hub of `tests/fan_hub.ron`, generated by `agent!`: its fans are
/// `Fan`s, its output function writes every element.
mod generated {
    use embodied::*;

    embodied::agent!(spec = "tests/fan_hub.ron", agent = "a0");

    /// Robot k's plans count from 1000 k; acknowledgements counted.
    pub(crate) struct Dispatcher;

    impl hub::Functions for Dispatcher {
        fn send(
            m: &hub::Memory,
            _: &hub::Input,
            y: &mut Fan<hub::ToRobots>,
        ) -> Result<(), ActionError> {
            for (k, r) in y.iter_mut().enumerate() {
                r.plan.set(1000 * k as u64 + m.n);
            }
            Ok(())
        }

        fn count(m: &mut hub::Memory, x: &hub::Input) -> Result<(), ActionError> {
            m.n += 1;
            m.acks += x.robots.iter().filter(|r| r.ack.is_new()).count() as u64;
            Ok(())
        }
    }
}

#[test]
fn a_hub_generated_by_agent_from_a_spec_with_a_fan_runs_and_exports_the_same_fan() {
    use generated::{Dispatcher, hub};
    let text = include_str!("fan_hub.ron");
    let (file, report) = embodied::spec::check_source("fan_hub.ron", text);
    assert!(report.is_ok(), "{}", report.render(100));
    let file = file.expect("parses");

    let period = Period::from_millis(10).expect("a period");
    let mut b = SystemBuilder::new();
    let a0 = b.agent("a0");
    let h = b.subsystem_with_buffers(
        a0,
        "hub",
        period,
        hub::Memory { n: 0, acks: 0 },
        hub::fsm::<Dispatcher>().expect("the spec's FSM"),
        hub::Input {
            robots: Fan::new(3),
        },
        hub::Output {
            robots: Fan::new(3),
        },
    );
    for k in 0..3 {
        add_robot(&mut b, k, period);
    }
    let system = b.build().expect("the hub and its robots");
    let exported = spec_of("hub_fleet", system.info()).expect("exports");
    let ours = exported.subsystem("hub").expect("the hub");
    let theirs = file.subsystem("hub").expect("the hub");
    assert_eq!(ours.inputs, theirs.inputs, "the fan of inputs");
    assert_eq!(ours.outputs, theirs.outputs, "the fan of outputs");
    let target = |s: &embodied::spec::model::Subsystem| {
        s.functions
            .iter()
            .find(|f| f.name == "send")
            .map(|f| f.target.clone())
    };
    assert_eq!(target(ours), target(theirs));

    let mut exec = Executor::new(system, ExecConfig::default());
    exec.run_until(Time::from_nanos(100_000_000)).expect("runs");
    let acks = exec.memory(&h).expect("the hub").acks;
    assert!(acks >= 3 * 5, "{acks} acknowledgements from three robots");
}

/// Robot `k` (named against its order, `robot_{10 - k}`, so that a peer taken
/// from the wrong element shows) in agent `a{k + 1}`, linked to the hub's
/// element `robots[k]` both ways.
fn add_robot(b: &mut SystemBuilder, k: usize, period: Period) {
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
