//! A small fleet of Rex robots (issue 57): its generated spec passes the
//! checker, one ontology agent dispatches plans to every robot, every plan is
//! achieved as judged against the simulation's truth, and the robots keep
//! apart.

use std::time::Duration;

use embodied::{ExecConfig, Executor, Time};
use rex_agent::fleet::{self, Fleet, Warehouse};

#[test]
fn the_fleets_spec_names_each_robots_parts_and_passes_the_checker() {
    let fleet = Fleet::in_warehouse(Warehouse::short(3), true).unwrap();
    let spec = fleet.spec();
    let (checked, report) = fleet::spec::check(&spec);
    assert!(report.is_ok(), "{}", report.short());
    let checked = checked.expect("a spec");
    // a1 and a3 once a robot, one a2 for the fleet.
    assert_eq!(checked.agents.len(), 3 * 2 + 1);
    let a2: Vec<_> = checked
        .agents
        .iter()
        .filter(|a| a.name.starts_with("a2"))
        .collect();
    assert_eq!(a2.len(), 1, "one ontology agent");
    assert_eq!(a2[0].name, "a2");
    let c2 = &a2[0].subsystems[0];
    assert_eq!(c2.name, "c2");
    let fan = ["c1_0", "c1_1", "c1_2"];
    for g in c2.inputs.iter().chain(&c2.outputs) {
        assert_eq!(g.peer, "c1", "the fan's name");
        assert_eq!(g.peers, fan, "one element a robot, in order");
    }
    for i in 0..3 {
        for (from, to) in [
            (
                format!("c2.c1[{i}].desired_plan"),
                format!("c1_{i}.c2.desired_plan"),
            ),
            (format!("c1_{i}.c2.ack"), format!("c2.c1[{i}].ack")),
            (format!("c1_{i}.c2.alive"), format!("c2.c1[{i}].alive")),
        ] {
            assert!(
                checked.links.iter().any(|l| l.from == from && l.to == to),
                "{from} -> {to}"
            );
        }
    }
    for i in 0..3 {
        let a1 = checked
            .agents
            .iter()
            .find(|a| a.name == format!("a1_{i}"))
            .expect("a1 of each robot");
        let names: Vec<&str> = a1.subsystems.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(
            names,
            [format!("c1_{i}"), format!("e11_{i}"), format!("r11_{i}")]
        );
        assert!(a1.devices.iter().any(|d| d.name == format!("E1_{i}")));
    }
    for deployment in ["simulation", "simulation_without_vo", "grouped_without_vo"] {
        let d = checked.deployment(deployment).expect(deployment);
        assert!(d.runs().any(|c| c == "c2"), "{deployment} runs the one c2");
        assert!(!d.runs().any(|c| c.starts_with("c2_")), "{deployment}");
    }
    // The robots' links are Rex's, once a robot.
    assert_eq!(checked.links.len(), 3 * fleet.rex.links.len());
}

#[test]
fn two_robots_achieve_every_plan_in_their_aisles_and_keep_apart() {
    let fleet = Fleet::in_warehouse(Warehouse::short(2), false).unwrap();
    let out = fleet::run_fleet(&fleet, Duration::from_secs(40)).unwrap();
    for (i, robot) in out.robots.iter().enumerate() {
        for r in &robot.reports {
            eprintln!("robot {i}: {r}");
        }
    }
    eprintln!("{}", out.line(1.0));
    assert!(out.completed, "every mission ended before the limit");
    assert_eq!(out.plans(), 4);
    assert_eq!(out.achieved(), out.plans(), "every plan achieved");
    assert!(
        out.min_separation_m >= fleet.safety_m(),
        "robots came {:.3} m close ({:?})",
        out.min_separation_m,
        out.closest
    );
    // Each robot stayed in its own aisle (the truth's last pose).
    for (i, robot) in out.robots.iter().enumerate() {
        let last = robot.samples.last().expect("samples");
        let y = fleet.warehouse.aisle_y(i);
        assert!(
            (last.truth[1] - y).abs() < 0.5,
            "robot {i} at {:?}",
            last.truth
        );
    }
}

#[test]
fn one_c2_dispatches_every_robots_plans_and_each_robot_achieves_them() {
    let fleet = Fleet::in_warehouse(Warehouse::short(3), false).unwrap();
    let spec = fleet.spec();
    let configs = fleet.configs().unwrap();
    let (system, handles) = fleet::build(&spec, fleet.deployment(), &configs).unwrap();
    // One c2 in the system, linked to every robot's c1 through its fan.
    let info = system.info().clone();
    let c2s: Vec<_> = info
        .nodes
        .iter()
        .filter(|n| n.name.starts_with("c2"))
        .collect();
    assert_eq!(c2s.len(), 1, "{c2s:?}");
    assert!(handles.robots.iter().all(|h| h.c2.is_none()));
    for k in 0..3 {
        let to_c1 = info.links.iter().find(|l| {
            info.nodes[l.from].name == "c2" && l.from_port == format!("c1[{k}].desired_plan")
        });
        let to = to_c1.map(|l| info.nodes[l.to].name.as_str());
        assert_eq!(to, Some(format!("c1_{k}").as_str()), "robot {k}'s plans");
    }
    let mut exec = Executor::new(system, ExecConfig::default());
    exec.run_until(Time::from_nanos(40_000_000_000)).unwrap();
    let c2 = exec.memory(&handles.c2).expect("the fleet's c2");
    assert_eq!(c2.robots.len(), 3);
    assert_eq!(
        exec.behaviour(&handles.c2),
        Some("done"),
        "every mission settled"
    );
    for (k, robot) in c2.robots.iter().enumerate() {
        let m = &robot.ontology;
        // Robot k's mission (its own aisle's plans), every plan sent to it
        // and reached, as its c1 reported.
        assert_eq!(m.mission, fleet.warehouse.mission(k), "robot {k}");
        assert_eq!(m.next, m.mission.plans.len(), "robot {k}");
        for id in 1..=m.mission.plans.len() as u32 {
            assert!(
                m.outcomes.iter().any(|o| o.plan == id && o.reached()),
                "robot {k}'s plan {id}: {:?}",
                m.outcomes
            );
        }
        assert_eq!((m.restarts, m.resent, m.repeated), (0, 0, 0), "robot {k}");
    }
}

#[test]
fn each_of_64_robots_has_an_aisle_of_its_own_with_its_plans_on_its_map() {
    let fleet = Fleet::new(64, false).unwrap();
    let configs = fleet.configs().expect("every plan on its robot's aisle");
    let w = &fleet.warehouse;
    let clearance = fleet.base.limits.clearance_m;
    for (i, c) in configs.iter().enumerate() {
        let room = &c.world.scene.room;
        // The robot's free space: its aisle between two rows of shelves.
        let (y0, y1) = (room.y0 + w.shelf_depth, room.y1 - w.shelf_depth);
        assert!((y1 - y0 - w.aisle_width).abs() < 1e-9);
        assert!(y0 <= c.world.start.y && c.world.start.y <= y1);
        if let Some(next) = configs.get(i + 1) {
            let next_y0 = next.world.scene.room.y0 + w.shelf_depth;
            // Two centres each `clearance` inside their aisles: a row of
            // shelves and two clearances apart, more than the safety distance.
            assert!(next_y0 - y1 + 2.0 * clearance >= fleet.safety_m() + w.shelf_depth - 1e-9);
        }
    }
    let (_, report) = fleet::spec::check(&fleet.spec());
    assert!(report.is_ok(), "{}", report.short());
}
