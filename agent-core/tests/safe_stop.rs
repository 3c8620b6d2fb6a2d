//! Errors an observer raises (a contract monitor's violations) go through the
//! executor's error policy like a node's own: stop, continue, or safe-stop
//! (every subsystem halted, every driver's device made safe, the drivers
//! stepping on), in both executors.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

mod common;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use agent_core::*;
use common::{Rail, ms, t_ms};

struct Idle;

impl Subsystem for Idle {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = ();
    type Input = ();
    type Output = ();
}

/// E: a motor that moves the cart one unit per step until it is safe-stopped,
/// then holds it (whatever it is told).
#[derive(Default)]
struct Brake {
    held: bool,
    safe_stops: u32,
    steps: u64,
}

impl Driver for Brake {
    const KIND: DeviceKind = DeviceKind::Effector;
    type Input = ();
    type Output = ();
    fn step(&mut self, mut cx: DriverContext<'_>, _: &(), _: &mut ()) -> Result<(), DriverError> {
        self.steps += 1;
        if !self.held {
            cx.environment::<Rail>()?.position += 1.0;
        }
        Ok(())
    }
    fn safe_stop(&mut self) {
        self.held = true;
        self.safe_stops += 1;
    }
}

#[derive(Debug, thiserror::Error)]
#[error("the cart moved {0} times: too far")]
struct TooFar(u64);

/// Raises one contract error at the `after`-th action of node `c`, and keeps
/// every error the executor gives it.
struct Alarm {
    after: u64,
    seen: u64,
    c: Option<usize>,
    pending: bool,
    errors: Arc<Mutex<Vec<String>>>,
}

impl Alarm {
    fn new(after: u64) -> (Alarm, Arc<Mutex<Vec<String>>>) {
        let errors = Arc::new(Mutex::new(Vec::new()));
        let alarm = Alarm {
            after,
            seen: 0,
            c: None,
            pending: false,
            errors: errors.clone(),
        };
        (alarm, errors)
    }
}

impl Observer for Alarm {
    fn start(&mut self, system: &SystemInfo) {
        self.c = system.nodes.iter().position(|n| n.name == "c");
    }
    fn action(&mut self, event: &ActionEvent) {
        if Some(event.node) == self.c {
            self.seen += 1;
            self.pending |= self.seen == self.after;
        }
    }
    fn error(&mut self, time: Time, error: &ExecError) {
        self.errors.lock().unwrap().push(format!("{time}: {error}"));
    }
    fn raised(&mut self) -> Option<ExecError> {
        std::mem::take(&mut self.pending).then(|| ExecError::Contract {
            subsystem: "c".into(),
            time: Time::ZERO,
            source: Box::new(TooFar(self.seen)),
        })
    }
}

struct Cart {
    system: System,
    c: SubsystemHandle<Idle>,
    e: DriverHandle<Brake>,
}

/// `c` (idle), then the motor, both every 10 ms, on a rail.
fn cart() -> Cart {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let idle = Fsm::single(Behaviour::while_loop(
        "idle",
        Action::<Idle>::new(),
        "false",
    ))
    .unwrap();
    let c = b.subsystem(a, "c", ms(10), (), idle);
    let e = b.driver(a, "E", ms(10), Brake::default());
    b.environment(Rail::default());
    Cart {
        system: b.build().unwrap(),
        c,
        e,
    }
}

fn policy(on_error: OnError) -> ExecConfig {
    ExecConfig {
        on_error,
        ..ExecConfig::default()
    }
}

#[test]
fn a_raised_error_stops_the_run_under_stop() {
    let p = cart();
    let (alarm, seen) = Alarm::new(3);
    let mut x = Executor::with_observer(p.system, policy(OnError::Stop), alarm);
    let err = x.run_for(Duration::from_millis(100)).unwrap_err();
    assert!(
        matches!(&err, ExecError::Contract { subsystem, .. } if subsystem == "c"),
        "{err:?}"
    );
    assert!(err.to_string().contains("too far"), "{err}");
    assert_eq!(x.now(), t_ms(20), "stopped at the third activation");
    assert!(matches!(x.step(), Err(ExecError::Stopped)));
    assert_eq!(seen.lock().unwrap().len(), 1, "the observer is told");
}

#[test]
fn a_raised_error_is_reported_and_the_run_goes_on_under_continue() {
    let p = cart();
    let (alarm, seen) = Alarm::new(3);
    let mut x = Executor::with_observer(p.system, policy(OnError::Continue), alarm);
    x.run_for(Duration::from_millis(100)).unwrap();
    assert_eq!(x.report().error_count, 1);
    assert!(matches!(
        x.report().errors.as_slice(),
        [ExecError::Contract { .. }]
    ));
    assert_eq!(x.report().safe_stopped, None);
    assert!(!x.is_halted(p.c.id()));
    assert_eq!(x.environment::<Rail>().unwrap().position, 10.0);
    assert_eq!(x.driver(&p.e).unwrap().safe_stops, 0);
    assert_eq!(seen.lock().unwrap().len(), 1);
}

#[test]
fn a_raised_error_safe_stops_the_run_under_safe_stop() {
    let p = cart();
    let (alarm, seen) = Alarm::new(3);
    let mut x = Executor::with_observer(p.system, policy(OnError::SafeStop), alarm);
    x.run_for(Duration::from_millis(100)).unwrap();
    assert_eq!(x.report().safe_stopped, Some(t_ms(20)));
    assert!(x.is_halted(p.c.id()), "every subsystem halts");
    assert_eq!(x.iteration(p.c.id()), Some(3));
    let e = x.driver(&p.e).unwrap();
    assert_eq!(e.safe_stops, 1, "each driver made safe once");
    assert_eq!(e.steps, 10, "drivers step on to the end");
    // The motor moved at 0 ms and 10 ms, and held from the alarm at 20 ms.
    assert_eq!(x.environment::<Rail>().unwrap().position, 2.0);
    assert_eq!(seen.lock().unwrap().len(), 1);
    // A node's own error later does not safe-stop again.
    x.run_for(Duration::from_millis(50)).unwrap();
    assert_eq!(x.driver(&p.e).unwrap().safe_stops, 1);
}

/// `cart()` in real time for 200 ms under `on_error`, the alarm raised at
/// `c`'s fifth activation, in the thread that runs it (the motor may run in
/// another).
fn in_real_time(on_error: OnError) -> (SubsystemHandle<Idle>, DriverHandle<Brake>, Finished) {
    let Cart { system, c, e } = cart();
    let config = RtConfig {
        exec: policy(on_error),
        ..RtConfig::default()
    };
    let mut rt = RealTime::new(system, config);
    rt.observe(move |_, nodes| {
        let (alarm, _) = Alarm::new(if nodes.contains(&0) { 5 } else { u64::MAX });
        Box::new(alarm)
    });
    let f = rt
        .start(Duration::from_millis(200))
        .unwrap()
        .join()
        .unwrap();
    (c, e, f)
}

#[test]
fn the_real_time_executor_safe_stops_every_thread() {
    let (_, _, f) = in_real_time(OnError::Stop);
    let report = f.report();
    assert_eq!(report.safe_stopped, None, "stop does not safe-stop");
    assert!(
        matches!(report.errors.as_slice(), [ExecError::Contract { .. }]),
        "{:?}",
        report.errors
    );

    let (c, e, f) = in_real_time(OnError::SafeStop);
    let report = f.report();
    assert_eq!(report.safe_stopped, Some(t_ms(40)), "{report}");
    assert!(f.is_halted(&c));
    assert_eq!(f.activations(c.id()), Some(5));
    let e = f.driver(&e).unwrap();
    assert_eq!(e.safe_stops, 1);
    assert_eq!(e.steps, 20, "the motor steps on to the end");
    let held = f.environment::<Rail>().unwrap().position;
    assert!(
        (4.0..=6.0).contains(&held),
        "held from about the alarm: {held}"
    );
}
