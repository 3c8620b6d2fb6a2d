//! Rex in real time: the same system as the simulation, on threads against the wall
//! clock (the world on one thread, each subsystem on its own), completes a mission
//! with every plan achieved, tracking as well as the deterministic run. Ordinary
//! thread priority: the test shares the machine with the other tests.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::time::Duration;

use embodied::RtConfig;
use rex_agent::mission::Mission;
use rex_agent::payload::Point2;
use rex_agent::run::{run_mission, run_mission_realtime};
use rex_agent::system::RexConfig;
use rex_agent::world::WorldConfig;

fn short() -> RexConfig {
    let plans = [vec![(1.0, 0.0), (1.5, 0.5)], vec![(1.0, 1.0), (0.0, 1.0)]];
    let mut config = RexConfig::new(
        WorldConfig::shipped().unwrap(),
        Mission {
            name: "short".into(),
            plans: plans
                .iter()
                .map(|p| p.iter().map(|&(x, y)| Point2 { x, y }).collect())
                .collect(),
        },
    );
    // The camera's ray casting and the VO take more than their periods in a test
    // build; the deployment without them is the one measured here.
    config.visual_odometry = false;
    config
}

#[test]
fn rex_completes_a_mission_in_real_time_as_well_as_in_simulation() {
    let config = short();
    let simulated = run_mission(&config, Duration::from_secs(60), Duration::MAX, |_| {}).unwrap();
    assert!(simulated.succeeded(), "{}", simulated.summary_line());
    let (real, report) = run_mission_realtime(
        &config,
        Duration::from_secs(60),
        Duration::MAX,
        RtConfig::default(),
        |_| {},
    )
    .unwrap();
    assert!(real.completed, "{}\n{report}", real.summary_line());
    assert_eq!(real.plans_achieved(), real.plans, "{}", real.summary_line());
    assert_eq!(real.false_done(), 0);
    assert_eq!(report.error_count, 0, "{report}");
    let (a, b) = (real.rms(), simulated.rms());
    assert!(
        a <= 1.25 * b,
        "real-time tracking rms {a:.4} m vs simulated {b:.4} m\n{report}"
    );
    // Every node of the deployment ran on its thread, the plant on the world's.
    let plant = report.node("E1").unwrap();
    assert_eq!(plant.thread, "world");
    assert!(plant.activations > 1000, "{report}");
    assert!(report.node("e11").is_some_and(|n| n.activations > 10));
    assert!(!real.samples.is_empty() && real.samples.iter().all(|s| s.truth[0].is_finite()));
}
