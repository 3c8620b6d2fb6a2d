//! The tank example, tested as a user tests their agent: the mission end to end,
//! determinism of the trace, and termination properties of the behaviours and the
//! FSM with the proptest helpers.

#![allow(clippy::expect_used, reason = "a failing expect is a failing test")]

#[path = "../examples/tank/agent.rs"]
mod agent;

use std::time::Duration;

use agent::*;
use embodied::testing::{Environment, Termination};
use embodied::*;
use proptest::prelude::*;

fn run_mission(mission: Vec<Order>, seed: u64) -> (Executor<Recorder>, Plant) {
    let (system, plant) = build(mission, 0.2, seed).expect("the example system builds");
    let mut exec = Executor::with_observer(system, ExecConfig::default(), Recorder::new());
    while !exec.is_halted(plant.operator.id()) && exec.now() < Time::from_nanos(600_000_000_000) {
        exec.run_for(Duration::from_secs(1))
            .expect("no error in the mission");
    }
    (exec, plant)
}

#[test]
fn mission_is_completed_and_bad_order_refused() {
    let mission = vec![
        Order { id: 1, level: 1.0 },
        Order {
            id: 2,
            level: f64::NAN,
        },
        Order { id: 3, level: 5.0 },
        Order { id: 4, level: 0.5 },
    ];
    let (exec, plant) = run_mission(mission.clone(), 3);
    let acks = &exec.memory(&plant.operator).unwrap().acks;
    assert_eq!(
        acks.len(),
        4,
        "every order acknowledged exactly once: {acks:?}"
    );
    assert_eq!(
        acks.iter().map(Ack::id).collect::<Vec<_>>(),
        vec![1, 2, 3, 4]
    );
    let tolerance = StationParams::default().tolerance;
    for (ack, order) in acks.iter().zip(&mission) {
        match ack {
            Ack::Done { level, .. } => assert!(
                (level - order.level).abs() <= tolerance,
                "order {order:?} acknowledged at {level}"
            ),
            Ack::Refused { reason, .. } => {
                assert!(
                    !(0.1..=1.9).contains(&order.level),
                    "{order:?} refused: {reason}"
                );
                assert!(reason.contains("outside"), "{reason}");
            }
        }
    }
    assert!(matches!(acks[1], Ack::Refused { .. }) && matches!(acks[2], Ack::Refused { .. }));
    let true_level = exec.environment::<Tank>().expect("the tank").level;
    assert!(
        (true_level - 0.5).abs() < 0.03,
        "tank ends at {true_level} m"
    );
    assert!(exec.report().errors.is_empty());
    // The station went through its FSM in the paper's way for each valid order.
    let station = exec.observer().trace().behaviours_of("c1");
    let mut visited: Vec<&str> = station.iter().map(|(_, b)| *b).collect();
    visited.dedup();
    assert_eq!(
        visited[..6],
        ["idle", "fill", "settle", "report", "idle", "report"],
        "first order filled, second refused straight from idle"
    );
    // Iterations are consecutive: one action per activation.
    assert!(station.windows(2).all(|w| w[1].0 == w[0].0 + 1));
}

#[test]
fn the_same_run_gives_the_same_trace() {
    let mission = default_mission();
    let (a, _) = run_mission(mission.clone(), 11);
    let (b, _) = run_mission(mission.clone(), 11);
    let (ta, tb) = (a.observer().trace(), b.observer().trace());
    assert!(
        ta.events.len() > 100_000,
        "a real trace: {} events",
        ta.events.len()
    );
    if let Some((i, x, y)) = ta.first_difference(tb) {
        panic!("traces differ at event {i}:\n  {x}\n  {y}");
    }
    assert_eq!(
        ta.to_bytes().unwrap(),
        tb.to_bytes().unwrap(),
        "bit-identical"
    );
    // The trace holds buffer contents: another noise seed gives another trace.
    let (c, _) = run_mission(mission, 12);
    assert!(ta.first_difference(c.observer().trace()).is_some());
    // A trace survives a round trip through bytes.
    assert_eq!(&Trace::from_bytes(&ta.to_bytes().unwrap()).unwrap(), ta);
}

// ---------------------------------------------------------------------------
// Termination properties with a reactive model of the station's environment.

/// The world as seen by c1: a tank that follows the commanded flow with an unknown
/// pump efficiency, a filter that reports the level, and an operator that sends
/// one order at some iteration.
#[derive(Clone, Debug)]
struct StationEnv {
    level: f64,
    efficiency: f64,
    flow: f64,
    order: Order,
    arrival: u64,
}

const DT: f64 = 0.05;

impl Environment<Station> for StationEnv {
    fn inputs(&mut self, k: u64, previous: Option<&StationOutput>, x: &mut StationInput) {
        if let Some(&q) = previous.and_then(|y| y.pump.flow.written()) {
            self.flow = q;
        }
        let area = TankParams::default().area;
        self.level = (self.level + self.flow * self.efficiency / area * DT).clamp(0.0, 2.0);
        let stamp = Stamp::new(k, Time::from_nanos(k * 50_000_000));
        x.filter.level.deliver(self.level, stamp);
        x.pump.flow.deliver(self.flow * self.efficiency, stamp);
        if k == self.arrival {
            x.operator.order.deliver(self.order, stamp);
        } else {
            x.operator.order.age();
        }
    }
}

fn any_target() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => 0.1f64..=1.9,
        1 => Just(f64::NAN),
        1 => -5.0f64..0.1,
        1 => 1.9f64..10.0,
        1 => Just(f64::INFINITY),
    ]
}

fn station_env(
    target: impl Strategy<Value = f64>,
    efficiency: std::ops::RangeInclusive<f64>,
) -> impl Strategy<Value = StationEnv> {
    (0.0f64..=2.0, efficiency, target, 0u64..40).prop_map(|(level, efficiency, t, arrival)| {
        StationEnv {
            level,
            efficiency,
            flow: 0.0,
            order: Order { id: 1, level: t },
            arrival,
        }
    })
}

fn memory_with_order(target: f64) -> StationMemory {
    StationMemory {
        order: Some(Order {
            id: 1,
            level: target,
        }),
        ..StationMemory::new(StationParams::default())
    }
}

#[test]
fn fill_reaches_the_target_for_any_valid_order_and_pump() {
    let fsm = station_fsm().unwrap();
    // Bound: 1.9 m at the flow limit with the weakest pump (76 s), then the
    // proportional tail (about 40 s), at 20 iterations per second.
    let memory = (0.1f64..=1.9).prop_map(memory_with_order);
    Termination::within(2_600)
        .cases(128)
        .behaviour(&fsm, "fill", memory, station_env(Just(0.0), 0.5..=1.0))
        .unwrap();
}

#[test]
fn idle_ends_as_soon_as_an_order_arrives() {
    let fsm = station_fsm().unwrap();
    // While-type: the order read at iteration `arrival` (at most 39) is stored by
    // that iteration's action; the test before the next iteration ends the
    // behaviour. 40 is the exact bound: 39 fails (the helper finds arrival = 39).
    let idle = |bound: u64| {
        // Enough cases that an arrival of 39 (1 in 40) is drawn: a miss is
        // (39/40)^1024 ≈ 6e-12.
        Termination::within(bound).cases(1024).behaviour(
            &fsm,
            "idle",
            Just(StationMemory::new(StationParams::default())),
            station_env(any_target(), 0.5..=1.0),
        )
    };
    idle(40).unwrap();
    let msg = idle(39).unwrap_err().to_string();
    assert!(
        msg.starts_with(
            "behaviour `idle` (while-type) did not reach its terminal condition `has_order` within 39 iterations\n"
        ),
        "{msg}"
    );
    assert!(
        msg.contains(
            "environment:    StationEnv { level: 0.0, efficiency: 0.5, flow: 0.0, order: Order { id: 1, level: 0.1 }, arrival: 39 }"
        ),
        "shrunk to the simplest environment whose order comes last:\n{msg}"
    );
    // 39 actions of `idle` without an order (ι=0..38); the order read at ι=39 is
    // only in the inputs at the last terminal test, not yet in the memory.
    let lines: Vec<&str> = msg.lines().collect();
    let at = |k: u64| {
        let prefix = format!("  ι={k}: inputs ");
        lines
            .iter()
            .find(|l| l.starts_with(&prefix))
            .unwrap_or_else(|| panic!("no line for ι={k}:\n{msg}"))
    };
    assert!(at(0).contains("order: ∅ } } -> outputs"), "{msg}");
    assert!(at(38).contains("order: ∅ } } -> outputs"), "{msg}");
    assert!(
        at(39).ends_with("order: new Order { id: 1, level: 0.1 } } } -> not ended, bound reached"),
        "{msg}"
    );
    assert!(msg.contains("… 16 iterations not shown …"), "{msg}");
}

#[test]
fn settle_and_report_end_by_themselves() {
    let fsm = station_fsm().unwrap();
    let params = StationParams::default();
    let settle_memory =
        (0..=params.settle_iterations, any_target()).prop_map(|(settled, t)| StationMemory {
            settled,
            ..memory_with_order(t)
        });
    Termination::within(u64::from(params.settle_iterations))
        .behaviour(
            &fsm,
            "settle",
            settle_memory,
            station_env(any_target(), 0.5..=1.0),
        )
        .unwrap();
    Termination::within(1)
        .behaviour(
            &fsm,
            "report",
            any_target().prop_map(memory_with_order),
            station_env(any_target(), 0.5..=1.0),
        )
        .unwrap();
}

#[test]
fn station_returns_to_idle_after_any_order() {
    let fsm = station_fsm().unwrap();
    // Arrival (≤ 40) + fill (≤ 2 600) + settle (10) + report (1), with slack for a
    // settle that sends the FSM back to fill.
    Termination::within(3_000)
        .cases(128)
        .returns_to(
            &fsm,
            "idle",
            Just(StationMemory::new(StationParams::default())),
            station_env(any_target(), 0.5..=1.0),
        )
        .unwrap();
}

#[test]
fn a_dead_pump_is_caught_and_shrunk_to_a_readable_trace() {
    // With a pump that may deliver nothing, `fill` cannot terminate: the helper must
    // find it, shrink the efficiency to 0 and print the iterations.
    let fsm = station_fsm().unwrap();
    let err = Termination::within(200)
        .cases(64)
        .shown(3)
        .behaviour(
            &fsm,
            "fill",
            (0.1f64..=1.9).prop_map(memory_with_order),
            station_env(Just(0.0), 0.0..=1.0),
        )
        .unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.contains("behaviour `fill` (repeat-type) did not reach its terminal condition `reached` within 200 iterations"),
        "{msg}"
    );
    assert!(msg.contains("minimal counterexample"), "{msg}");
    assert!(
        msg.contains("efficiency: 0.0"),
        "shrunk to a dead pump:\n{msg}"
    );
    assert!(
        msg.contains("ι=0: inputs") && msg.contains("ι=199"),
        "{msg}"
    );
    assert!(msg.contains("iterations not shown"), "{msg}");
}

#[test]
fn a_station_that_cannot_come_back_to_idle_is_caught_and_shrunk() {
    // Valid orders but a pump that may deliver nothing: the FSM can be stuck in
    // `fill`, so it never comes back to `idle`. The helper must find it, shrink every
    // parameter of the environment to its simplest failing value and print the
    // activations.
    let fsm = station_fsm().unwrap();
    let err = Termination::within(200)
        .cases(64)
        .shown(3)
        .returns_to(
            &fsm,
            "idle",
            Just(StationMemory::new(StationParams::default())),
            station_env(0.1f64..=1.9, 0.0..=1.0),
        )
        .unwrap_err();
    let msg = err.to_string();
    assert!(
        msg.starts_with("the FSM did not enter `idle` within 200 activations\n"),
        "{msg}"
    );
    assert!(
        msg.contains(
            "environment:    StationEnv { level: 0.0, efficiency: 0.0, flow: 0.0, order: Order { id: 1, level: 0.1 }, arrival: 0 }"
        ),
        "shrunk to an empty tank, a dead pump, the lowest target, the first iteration:\n{msg}"
    );
    // The order read at ι=0 is taken by `idle`, `fill` starts at ι=1 and never ends.
    let lines: Vec<&str> = msg.lines().collect();
    let at = |k: u64| {
        let prefix = format!("  ι={k}: inputs ");
        lines
            .iter()
            .find(|l| l.starts_with(&prefix))
            .unwrap_or_else(|| panic!("no line for ι={k}:\n{msg}"))
    };
    assert!(at(0).contains(" | idle: outputs"), "{msg}");
    assert!(at(1).contains(" -> fill | fill: outputs"), "{msg}");
    assert!(at(2).contains(" | fill: outputs"), "{msg}");
    assert!(at(199).contains(" | fill: outputs"), "{msg}");
    assert!(msg.contains("… 194 iterations not shown …"), "{msg}");
    assert_eq!(
        lines.iter().filter(|l| l.starts_with("  ι=")).count(),
        6,
        "3 first and 3 last activations:\n{msg}"
    );
}
