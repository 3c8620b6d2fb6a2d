//! A small fleet of Rex robots (issue 57): its generated spec passes the
//! checker, every plan is achieved as judged against the simulation's truth,
//! and the robots keep apart.

use std::time::Duration;

use rex_agent::fleet::{self, Fleet, Warehouse};

#[test]
fn the_fleets_spec_names_each_robots_parts_and_passes_the_checker() {
    let fleet = Fleet::in_warehouse(Warehouse::short(3), true).unwrap();
    let spec = fleet.spec();
    let (checked, report) = fleet::spec::check(&spec);
    assert!(report.is_ok(), "{}", report.short());
    let checked = checked.expect("a spec");
    assert_eq!(checked.agents.len(), 3 * 3);
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
        assert!(checked.deployment(deployment).is_some(), "{deployment}");
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
