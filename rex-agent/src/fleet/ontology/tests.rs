//! The fleet's `c2` against Rex's: each robot driven by a `c1` that crashes
//! (Rex's partner tests' `Crasher`), the fleet's one `c2` and one Rex `c2` a
//! robot given the same inputs, activation by activation.

use super::*;
use crate::payload::Point2;
use crate::world::partners::tests::Crasher;
use crate::world::partners::{OntologyInput, OntologyOutput, ontology_fsm};
use embodied::FsmState;

/// `plans` plans of `points` points, shifted by `robot` (each robot's own).
fn mission(robot: usize, plans: usize, points: usize) -> Mission {
    Mission {
        name: format!("robot_{robot}"),
        plans: (0..plans)
            .map(|i| {
                (0..points)
                    .map(|j| Point2 {
                        x: (10 * robot + i) as f64,
                        y: j as f64,
                    })
                    .collect()
            })
            .collect(),
    }
}

/// Rex's `c2` for one robot: its memory, FSM state and last output.
struct Rex {
    memory: OntologyMemory,
    state: FsmState,
    output: OntologyOutput,
}

#[test]
fn each_robot_is_dispatched_as_rexs_c2_dispatches_rex_activation_by_activation() {
    let rex = ontology_fsm().unwrap();
    let fleet = fleet_ontology_fsm().unwrap();
    let robots = 4;
    // Robot k crashes at `crash_at + 7k` (robot 3 never: after the end),
    // executes a point every 2 + k % 3 activations.
    for crash_at in 0..30 {
        let missions: Vec<Mission> = (0..robots).map(|k| mission(k, 2 + k % 2, 3)).collect();
        let mut envs: Vec<Crasher> = (0..robots)
            .map(|k| {
                let at = if k == 3 {
                    10_000
                } else {
                    crash_at + 7 * k as u64
                };
                Crasher::new(2 + k as u64 % 3, at, 4, 7 + k as u64)
            })
            .collect();
        let mut rexes: Vec<Rex> = missions
            .iter()
            .map(|m| Rex {
                memory: OntologyMemory::new(m.clone()),
                state: rex.start(),
                output: OntologyOutput::default(),
            })
            .collect();
        let mut memory = FleetOntologyMemory::new(missions.clone());
        let mut state = fleet.start();
        let mut k = 0;
        while !state.is_halted() {
            let mut x = FleetOntologyInput::new(robots);
            for (j, (env, r)) in envs.iter_mut().zip(&mut rexes).enumerate() {
                let mut rx = OntologyInput::default();
                env.inputs(k, &r.output, &mut rx);
                x.c1[j] = rx.c1.clone();
                r.output = OntologyOutput::default();
                rex.activate(&mut r.state, &mut r.memory, &rx, &mut r.output, |_| {})
                    .unwrap();
            }
            let mut y = FleetOntologyOutput::new(robots);
            fleet
                .activate(&mut state, &mut memory, &x, &mut y, |_| {})
                .unwrap();
            for (j, r) in rexes.iter().enumerate() {
                let at = format!("crash at {crash_at}, activation {k}, robot {j}");
                assert!(
                    y.c1[j].desired_plan.written() == r.output.c1.desired_plan.written(),
                    "{at}: the plans sent differ"
                );
                let dispatch = &memory.robots[j];
                assert_eq!(
                    format!("{:?}", dispatch.ontology),
                    format!("{:?}", r.memory),
                    "{at}"
                );
                let rex_done =
                    r.state.is_halted() || rex.behaviour_name(r.state.behaviour()) == "done";
                assert_eq!(dispatch.halted(), rex_done, "{at}");
            }
            k += 1;
            assert!(k < 300, "crash at {crash_at}: no end; {memory:?}");
        }
        // Every robot's every plan reached, each point executed once; the
        // crashed robots' plans sent again, the other's not.
        for (j, (env, dispatch)) in envs.iter().zip(&memory.robots).enumerate() {
            let m = &dispatch.ontology;
            env.every_plan_reached_once(m, 3, &format!("crash at {crash_at}, robot {j}"));
            if j == 3 {
                assert_eq!((m.restarts, m.resent), (0, 0), "crash at {crash_at}");
            }
        }
        let restarted = memory.robots.iter().filter(|d| d.ontology.restarts > 0);
        if (2..5).contains(&crash_at) {
            // Each crash after c2 first heard its c1 (at its second
            // activation: the first sends) and before its robot's end:
            // robots 0 to 2 restart.
            assert_eq!(restarted.count(), 3, "crash at {crash_at}");
        }
    }
}

#[test]
fn a_fan_that_does_not_match_the_robots_is_an_error_not_a_silent_robot() {
    let fleet = fleet_ontology_fsm().unwrap();
    let mut memory = FleetOntologyMemory::new((0..3).map(|k| mission(k, 1, 2)));
    let mut state = fleet.start();
    let x = FleetOntologyInput::new(2);
    let mut y = FleetOntologyOutput::new(2);
    let e = fleet
        .activate(&mut state, &mut memory, &x, &mut y, |_| {})
        .expect_err("3 robots, 2 elements");
    assert!(e.to_string().contains("3 robots"), "{e}");
}

#[test]
fn the_first_activation_sends_every_robot_its_first_plan() {
    let fleet = fleet_ontology_fsm().unwrap();
    let mut memory = FleetOntologyMemory::new((0..5).map(|k| mission(k, 2, 2)));
    let mut state = fleet.start();
    let x = FleetOntologyInput::new(5);
    let mut y = FleetOntologyOutput::new(5);
    fleet
        .activate(&mut state, &mut memory, &x, &mut y, |_| {})
        .unwrap();
    for (k, robot) in y.c1.iter().enumerate() {
        let plan = robot
            .desired_plan
            .written()
            .expect("a plan for every robot");
        assert_eq!(plan.id, 1);
        assert_eq!(plan.points[0].x, (10 * k) as f64, "robot {k}'s own plan");
    }
    // Each robot's machine in Rex's `send`, its action done (it goes on to
    // `wait` at its next decision).
    let rex = ontology_fsm().unwrap();
    assert!(memory.robots.iter().all(|r| {
        r.state
            .is_some_and(|s| rex.behaviour_name(s.behaviour()) == "send" && s.actions_done())
    }));
    assert!(!memory.settled());
}

#[test]
fn a_failed_robot_activation_changes_no_robot_and_is_retried() {
    // Rex's c2 cannot fail on a valid memory; an FSM of Rex's c2 type whose
    // action fails for the robot of mission `bad` stands in for a failure.
    let failing = Fsm::<Ontology>::builder()
        .behaviour(Behaviour::while_loop(
            "count",
            Action::<Ontology>::new().memory(|m: &mut OntologyMemory, _: &OntologyInput| {
                if m.mission.name == "bad" && m.next > 0 {
                    return Err(ActionError::failed("bad robot"));
                }
                m.next += 1;
                Ok(())
            }),
            "false",
        ))
        .initial("count")
        .build()
        .unwrap();
    let mut missions: Vec<Mission> = (0..3).map(|k| mission(k, 2, 2)).collect();
    missions[2].name = "bad".into();
    let mut memory = FleetOntologyMemory::new(missions);
    let x = FleetOntologyInput::new(3);
    activate_robots(&failing, &mut memory, &x).unwrap();
    let before: Vec<usize> = memory.robots.iter().map(|r| r.ontology.next).collect();
    assert_eq!(before, [1, 1, 1]);
    let e = activate_robots(&failing, &mut memory, &x).expect_err("robot 2 fails");
    assert!(e.to_string().contains("robot 2"), "{e}");
    let after: Vec<usize> = memory.robots.iter().map(|r| r.ontology.next).collect();
    assert_eq!(after, before, "robots 0 and 1 are not half-activated");
}
