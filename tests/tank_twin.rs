//! The tank example and its twin written with the macros: the same run gives the same
//! trace, and the twin's exported spec is `specs/tank.ron`, which the checker accepts.

#![allow(clippy::expect_used, reason = "a failing expect is a failing test")]

#[path = "../examples/tank/agent.rs"]
mod agent;
#[path = "../examples/tank/twin.rs"]
mod twin;

use std::time::Duration;

use embodied::spec::export::{spec_of, to_ron};
use embodied::*;

const HORIZON: Time = Time::from_nanos(600_000_000_000);

fn hand_written(mission: Vec<agent::Order>, seed: u64) -> Trace {
    let (system, plant) = agent::build(mission, 0.2, seed).expect("the example builds");
    let mut exec = Executor::with_observer(system, ExecConfig::default(), Recorder::new());
    while !exec.is_halted(plant.operator.id()) && exec.now() < HORIZON {
        exec.run_for(Duration::from_secs(1)).expect("no error");
    }
    exec.into_observer().into_trace()
}

fn with_macros(mission: Vec<agent::Order>, seed: u64) -> (Trace, Vec<agent::Ack>) {
    let (system, plant) = twin::build(mission, 0.2, seed).expect("the twin builds");
    let mut exec = Executor::with_observer(system, ExecConfig::default(), Recorder::new());
    while !exec.is_halted(plant.operator.id()) && exec.now() < HORIZON {
        exec.run_for(Duration::from_secs(1)).expect("no error");
    }
    let acks = exec
        .memory(&plant.operator)
        .expect("the operator's memory")
        .acks
        .clone();
    (exec.into_observer().into_trace(), acks)
}

#[test]
fn the_twin_gives_the_identical_trace() {
    let mission = agent::default_mission();
    let a = hand_written(mission.clone(), 5);
    let (b, acks) = with_macros(mission.clone(), 5);
    assert_eq!(acks.len(), mission.len(), "the twin completes the mission");
    assert!(
        a.events.len() > 100_000,
        "a real run: {} events",
        a.events.len()
    );
    if let Some((i, x, y)) = a.first_difference(&b) {
        panic!("the traces part at event {i}:\n  hand-written: {x}\n  macros:       {y}");
    }
    assert_eq!(a, b, "names, links and every event are identical");
}

#[test]
fn the_twin_exports_specs_tank_ron() {
    let (system, _) = twin::build(agent::default_mission(), 0.2, 1).expect("builds");
    let exported = spec_of("tank", system.info()).expect("every component is described");
    let text = to_ron(&exported).expect("writes");
    let (parsed, report) = embodied::spec::check_source("exported", text.clone());
    assert_eq!(
        parsed.as_ref(),
        Some(&exported),
        "the text reads back as the same spec"
    );
    assert!(
        report.is_ok(),
        "the checker accepts the export:\n{}",
        report.short()
    );

    // The committed spec is the export plus documentation: the code and the spec
    // cannot drift apart.
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/specs/tank.ron");
    let source = std::fs::read_to_string(path).expect("specs/tank.ron");
    let (committed, report) = embodied::spec::check_source("specs/tank.ron", source);
    assert!(report.is_ok(), "{}", report.short());
    let committed = committed.expect("parses");
    assert_eq!(
        committed.structure(),
        exported.structure(),
        "specs/tank.ron differs from the twin's export; the export is:\n{text}"
    );
}

#[test]
fn hand_written_components_without_descriptions_cannot_be_exported() {
    let (system, _) = agent::build(agent::default_mission(), 0.2, 1).expect("builds");
    let e = spec_of("tank", system.info()).expect_err("c1 is not described");
    assert_eq!(e.to_string().split('`').nth(1), Some("c1"), "{e}");
}

#[test]
fn derives_describe_names_types_and_freshness() {
    use twin::{StationInput, StationMemory};
    assert_eq!(
        StationMemory::FIELDS
            .iter()
            .map(|f| (f.name, f.ty))
            .collect::<Vec<_>>(),
        [
            ("params", "StationParams"),
            ("order", "Option<Order>"),
            ("settled", "u32")
        ]
    );
    let groups = StationInput::GROUPS;
    assert_eq!(
        groups.iter().map(|g| (g.name, g.peer)).collect::<Vec<_>>(),
        [
            ("filter", Some(NodeKind::VirtualReceptor)),
            ("pump", Some(NodeKind::VirtualEffector)),
            ("operator", Some(NodeKind::Control)),
        ]
    );
    assert_eq!(groups[2].buffers[0].ty, "Order");
    let mut x = StationInput::default();
    assert!(x.fresh().is_empty());
    let stamp = Stamp::new(0, Time::ZERO);
    x.operator
        .order
        .deliver(agent::Order { id: 1, level: 1.0 }, stamp);
    x.filter.level.deliver(0.5, stamp);
    assert_eq!(
        x.fresh().names(groups).collect::<Vec<_>>(),
        [("filter", "level"), ("operator", "order")]
    );
    x.filter.level.age();
    assert_eq!(x.fresh().count(), 1);
}

#[test]
fn fsm_parts_carry_their_function_names() {
    let fsm = twin::station_fsm().expect("builds");
    let shape = fsm.describe();
    let report = &shape.behaviours[3];
    assert_eq!(report.name, "report");
    let names: Vec<_> = report
        .parts
        .iter()
        .map(|p| p.name.as_deref().unwrap_or("?"))
        .collect();
    assert_eq!(names, ["acknowledge", "stop_pump", "forget_order"]);
    assert_eq!(shape.relations.len(), 1);
}

#[test]
fn a_group_without_links_is_exported_under_its_field_name() {
    // The station and the operator alone: the station's groups towards its filter and
    // pump controller are linked to nothing, so the export names their peers by the
    // fields (`filter`, `pump`) and the checker says these are no components.
    let mut sys = SystemBuilder::new();
    let (station_agent, operator_agent) = (sys.agent("station"), sys.agent("operator"));
    let period = Period::from_millis(50).expect("a period");
    let station = sys.subsystem(
        station_agent,
        "c1",
        period,
        twin::StationMemory::new(agent::StationParams::default()),
        twin::station_fsm().expect("builds"),
    );
    let operator = sys.subsystem(
        operator_agent,
        "c2",
        period,
        twin::OperatorMemory::default(),
        twin::operator_fsm().expect("builds"),
    );
    sys.connect(
        operator.output(port!(twin::OperatorOutput, station.order)),
        station.input(port!(twin::StationInput, operator.order)),
        Policy::queue(4),
    );
    let system = sys.build().expect("an incomplete system still builds");
    let spec = spec_of("partial", system.info()).expect("exports");
    let c1 = spec.subsystem("c1").expect("c1");
    let peers: Vec<&str> = c1.inputs.iter().map(|g| g.peer.as_str()).collect();
    assert_eq!(peers, ["filter", "pump", "c2"]);
    let (_, report) = embodied::spec::check_source("partial", to_ron(&spec).expect("writes"));
    assert!(
        report.short().contains("spec::unknown_component"),
        "{}",
        report.short()
    );
}
