//! The environment: the world real effectors act on and real receptors sense,
//! reached by drivers through their context, never through a side channel.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

mod common;

use std::time::Duration;

use agent_core::*;
use common::{Encoder, Motor, Rail};

struct Idle;

impl Subsystem for Idle {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = ();
    type Input = ();
    type Output = ();
}

fn ms(n: u64) -> Period {
    Period::from_millis(n).unwrap()
}

/// An agent with the encoder declared before the motor; the world if `rail`.
fn system(rail: Option<Rail>) -> (SystemBuilder, DriverHandle<Encoder>) {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let idle = Fsm::single(Behaviour::while_loop(
        "idle",
        Action::<Idle>::new(),
        "false",
    ))
    .unwrap();
    b.subsystem(a, "c", ms(10), (), idle);
    let encoder = b.driver(a, "R", ms(10), Encoder::default());
    b.driver(a, "E", ms(10), Motor);
    if let Some(rail) = rail {
        b.environment(rail);
    }
    (b, encoder)
}

#[test]
fn receptors_sense_what_effectors_did_in_the_same_instant_whatever_the_declaration_order() {
    let (b, encoder) = system(Some(Rail::default()));
    let mut x = Executor::new(b.build().unwrap(), ExecConfig::default());
    x.run_for(Duration::from_millis(100)).unwrap();
    assert_eq!(x.environment::<Rail>().map(|r| r.position), Some(10.0));
    let sensed = &x.driver(&encoder).unwrap().sensed;
    assert_eq!(sensed, &(1..=10).map(f64::from).collect::<Vec<_>>());
    // The environment can be disturbed between instants, and the encoder senses it.
    x.environment_mut::<Rail>().unwrap().position = -100.0;
    x.step().unwrap();
    assert_eq!(x.driver(&encoder).unwrap().sensed.last(), Some(&-99.0));
    assert!(
        x.environment::<String>().is_none(),
        "another type is not the environment"
    );
}

#[test]
fn a_driver_without_its_environment_fails_with_a_clear_error() {
    let (b, _) = system(None);
    let mut x = Executor::new(b.build().unwrap(), ExecConfig::default());
    let err = x.run_for(Duration::from_millis(10)).unwrap_err();
    assert!(matches!(err, ExecError::Driver { .. }), "{err:?}");
    assert!(
        err.to_string().contains("needs an environment of type"),
        "{err}"
    );
    // Tested alone, a driver gets its environment through the context.
    let mut rail = Rail::default();
    let cx = DriverContext::new(Time::ZERO, 0, ms(10)).with_environment(&mut rail);
    Motor.step(cx, &(), &mut ()).unwrap();
    assert_eq!(rail.position, 1.0);
}

#[test]
fn a_system_has_one_environment() {
    let (mut b, _) = system(Some(Rail::default()));
    b.environment(0_u8);
    let err = b.build().unwrap_err();
    assert_eq!(err.problems, vec![BuildProblem::SeveralEnvironments]);
}
