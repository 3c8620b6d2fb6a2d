//! The executor's semantics and its reaction to every kind of bad input: multi-rate
//! timing, sample and queue links, FSM contract violations, missing data, failing
//! drivers. (Malformed systems: `system_builder.rs`.)

#![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

mod common;

use agent_core::*;
use common::*;

#[test]
fn multi_rate_timing_and_one_period_latency() {
    let p = pair(10, 30, 1, Policy::Sample, false);
    let mut x = Executor::new(p.system, ExecConfig::default());
    x.run_until(t_ms(300)).unwrap();
    assert_eq!(
        x.iteration(p.c.id()),
        Some(30),
        "c runs at 0, 10, ..., 290 ms"
    );
    assert_eq!(
        x.iteration(p.e.id()),
        Some(10),
        "e runs at 0, 30, ..., 270 ms"
    );
    let got = &x.memory(&p.e).unwrap().got;
    // e's iteration k (at 30k ms) reads the latest value sent strictly before: c's
    // iteration 3k-1, sent at 30k-10 ms. Nothing is read at k = 0.
    let expected: Vec<(u64, u64, Stamp)> = (1..10)
        .map(|k| (k, 3 * k - 1, Stamp::new(3 * k - 1, t_ms(30 * k - 10))))
        .collect();
    assert_eq!(got, &expected);
    let stats = x.link_stats(p.down).unwrap();
    assert_eq!(stats.sent, 30);
    assert_eq!(stats.delivered, 9);
    assert_eq!(
        stats.overwritten, 20,
        "two of every three values are replaced unread"
    );
    assert_eq!(x.now(), t_ms(300));
}

#[test]
fn is_new_only_in_the_iteration_that_brought_the_value() {
    // c sends every 3rd iteration at the same rate as e.
    let p = pair(10, 10, 3, Policy::Sample, false);
    let mut x = Executor::new(p.system, ExecConfig::default());
    x.run_until(t_ms(100)).unwrap();
    let m = x.memory(&p.e).unwrap();
    // c sends at iterations 0, 3, 6, 9 (t = 0, 30, 60, 90 ms); e reads them at 10,
    // 40, 70 ms.
    assert_eq!(
        m.fresh,
        vec![
            false, true, false, false, true, false, false, true, false, false
        ]
    );
    assert_eq!(
        m.got.iter().map(|g| g.1).collect::<Vec<_>>(),
        vec![0, 3, 6],
        "values"
    );
    // The last value stays readable but is no longer new.
    let input = x.input(&p.e).unwrap();
    assert_eq!(
        (input.c.count.get(), input.c.count.is_new()),
        (Some(&6), false)
    );
}

#[test]
fn queue_overflow_stops_the_run_when_configured_to() {
    let p = pair(10, 100, 1, Policy::queue(3), false);
    let mut x = Executor::new(p.system, ExecConfig::default());
    let err = x.run_until(t_ms(1000)).unwrap_err();
    // Sends at 0, 10, 20 ms fill the queue; e has not read yet (its next read is at
    // 100 ms); the send at 30 ms is refused.
    match &err {
        ExecError::Link(LinkError::QueueOverflow {
            link,
            bound,
            iteration,
            time,
        }) => {
            assert_eq!(link, "c.e.count -> e.c.count");
            assert_eq!((*bound, *iteration, *time), (3, 3, t_ms(30)));
        }
        other => panic!("expected a queue overflow, got {other:?}"),
    }
    assert!(err.to_string().contains("refused"), "{err}");
    assert!(matches!(x.step(), Err(ExecError::Stopped)));
    assert!(matches!(x.run_until(t_ms(2000)), Err(ExecError::Stopped)));
}

#[test]
fn queue_is_lossless_and_overflow_is_counted_when_continuing() {
    let p = pair(10, 100, 1, Policy::queue(3), false);
    let mut x = Executor::new(p.system, ExecConfig::continue_on_error());
    x.run_until(t_ms(1000)).unwrap();
    let stats = x.link_stats(p.down).unwrap();
    let received: Vec<u64> = x.memory(&p.e).unwrap().got.iter().map(|g| g.1).collect();
    assert_eq!(
        stats.sent + stats.overflowed,
        100,
        "every send is accounted for"
    );
    assert_eq!(stats.delivered as usize, received.len());
    assert_eq!(
        stats.sent,
        stats.delivered + x.pending(p.down).unwrap() as u64,
        "accepted values are delivered or still waiting"
    );
    assert!(
        received.windows(2).all(|w| w[0] < w[1]),
        "in order: {received:?}"
    );
    assert_eq!(
        &received[..3],
        &[0, 1, 2],
        "the first values arrive in full"
    );
    assert_eq!(x.report().error_count, stats.overflowed);
    assert!(
        x.report()
            .errors
            .iter()
            .all(|e| matches!(e, ExecError::Link(LinkError::QueueOverflow { .. })))
    );
    assert_eq!(stats.max_pending, 3);
}

#[test]
fn reading_a_buffer_that_never_received_data_is_an_action_error() {
    // e requires c's count, but c only sends from iteration 0 at 100 ms periods
    // while e runs at 10 ms: e's first activation (t = 0) has no data.
    let p = pair(100, 10, 1, Policy::Sample, true);
    let mut x = Executor::new(p.system, ExecConfig::default());
    let err = x.run_until(t_ms(100)).unwrap_err();
    match &err {
        ExecError::Fsm {
            subsystem,
            iteration,
            time,
            error:
                FsmError::Action {
                    behaviour,
                    source: ActionError::Buffer(BufferError::NoData { buffer }),
                },
        } => {
            assert_eq!((subsystem.as_str(), behaviour.as_str()), ("e", "record"));
            assert_eq!((*iteration, *time), (0, Time::ZERO));
            assert_eq!(buffer, "e.c.count");
        }
        other => panic!("expected a missing-data error, got {other:?}"),
    }
    assert_eq!(
        err.to_string(),
        "subsystem `e`, iteration 0 at 0.000000 s: the action of behaviour `record` failed: input buffer `e.c.count` has not received any data yet"
    );
}

#[test]
fn a_failed_action_sends_nothing_and_is_retried_when_continuing() {
    let p = pair(100, 10, 1, Policy::Sample, true);
    let mut x = Executor::new(p.system, ExecConfig::continue_on_error());
    x.run_until(t_ms(50)).unwrap();
    // e failed at 0 ms (no data yet); from 10 ms on it has c's first value.
    assert_eq!(x.report().error_count, 1);
    assert_eq!(
        x.iteration(p.e.id()),
        Some(4),
        "actions at 10..40 ms completed"
    );
    // The echo written before the failure at 0 ms was not sent: c's first echo is
    // e's memory iteration 0 (first successful action), sent at 10 ms.
    x.run_until(t_ms(250)).unwrap();
    let echo = x.input(&p.c).unwrap().e.echo.stamp().unwrap();
    assert!(echo.time > Time::ZERO);
    assert_eq!(x.report().error_count, 1);
}

// ---------------------------------------------------------------------------
// FSM contract violations.

struct Chooser;

#[derive(Clone, Debug, Default)]
struct ChooserMemory {
    n: u32,
}

impl Subsystem for Chooser {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = ChooserMemory;
    type Input = ();
    type Output = ();
}

/// `work` counts to 3 and ends; the arcs leaving it are given by the test.
fn chooser_fsm(arcs: &[(&'static str, &'static str)]) -> Fsm<Chooser> {
    let mut b = Fsm::<Chooser>::builder()
        .predicate("three", |m: &ChooserMemory, _| m.n >= 3)
        .predicate("odd", |m: &ChooserMemory, _| m.n % 2 == 1)
        .predicate("big", |m: &ChooserMemory, _| m.n > 100)
        .behaviour(Behaviour::repeat_loop(
            "work",
            Action::<Chooser>::new().memory(|m: &mut ChooserMemory, _: &()| m.n += 1),
            "three",
        ))
        .behaviour(Behaviour::while_loop("left", Action::new(), "false"))
        .behaviour(Behaviour::while_loop("right", Action::new(), "false"))
        .initial("work");
    for (to, cond) in arcs {
        b = b.arc("work", *to, *cond);
    }
    b.build().unwrap()
}

fn chooser_system(
    arcs: &[(&'static str, &'static str)],
) -> (System, SubsystemHandle<Chooser>, SubsystemHandle<Counter>) {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let c = b.subsystem(
        a,
        "chooser",
        ms(10),
        ChooserMemory::default(),
        chooser_fsm(arcs),
    );
    // An independent agent that must keep running after the chooser fails.
    let a2 = b.agent("b");
    let other = b.subsystem(
        a2,
        "other",
        ms(10),
        CounterMemory { n: 0, every: 1 },
        counter_fsm(),
    );
    (b.build().unwrap(), c, other)
}

#[test]
fn no_arc_holding_is_an_error_with_the_predicate_values() {
    let (system, _, _) = chooser_system(&[("left", "big"), ("right", "big && odd")]);
    let mut x = Executor::new(system, ExecConfig::default());
    let err = x.run_until(t_ms(100)).unwrap_err();
    let ExecError::Fsm {
        subsystem,
        iteration,
        time,
        error,
    } = &err
    else {
        panic!("expected an FSM error, got {err:?}");
    };
    assert_eq!(
        (subsystem.as_str(), *iteration, *time),
        ("chooser", 3, t_ms(30))
    );
    let FsmError::NoArcHolds {
        behaviour,
        arcs,
        assignment,
    } = error
    else {
        panic!("expected no arc holding, got {error:?}");
    };
    assert_eq!(
        (behaviour.as_str(), arcs.as_str(), assignment.as_str()),
        (
            "work",
            "-> left [big], -> right [big && odd]",
            "three=true, odd=true, big=false"
        )
    );
}

#[test]
fn several_arcs_holding_is_an_error_never_a_silent_choice() {
    let (system, _, _) = chooser_system(&[("left", "three"), ("right", "odd")]);
    let mut x = Executor::new(system, ExecConfig::default());
    let err = x.run_until(t_ms(100)).unwrap_err();
    let ExecError::Fsm { error, .. } = &err else {
        panic!("expected an FSM error, got {err:?}");
    };
    let FsmError::SeveralArcsHold { count, held, .. } = error else {
        panic!("expected several arcs, got {error:?}");
    };
    assert_eq!(
        (*count, held.as_str()),
        (2, "-> left [three], -> right [odd]")
    );
    assert!(err.to_string().contains("2 arcs hold at once"), "{err}");
}

#[test]
fn a_failed_fsm_halts_its_subsystem_and_the_rest_continues() {
    let (system, chooser, other) = chooser_system(&[("left", "big"), ("right", "big")]);
    let mut x = Executor::with_observer(system, ExecConfig::continue_on_error(), Recorder::new());
    x.run_until(t_ms(100)).unwrap();
    assert!(x.is_halted(chooser.id()));
    assert_eq!(x.iteration(chooser.id()), Some(3));
    assert_eq!(x.iteration(other.id()), Some(10), "the other agent ran on");
    assert_eq!(x.report().errors.len(), 1);
    assert!(matches!(x.report().errors[0], ExecError::Fsm { .. }));
    let errors: Vec<_> = x
        .observer()
        .trace()
        .events
        .iter()
        .filter(|e| matches!(e, TraceEvent::Error { .. }))
        .collect();
    assert_eq!(errors.len(), 1, "the observer saw the error");
}

#[test]
fn exactly_one_arc_is_followed() {
    let (system, chooser, _) = chooser_system(&[("left", "odd"), ("right", "!odd")]);
    let mut x = Executor::with_observer(system, ExecConfig::default(), Recorder::new());
    x.run_until(t_ms(100)).unwrap();
    assert_eq!(x.behaviour(&chooser), Some("left"));
    let trace = x.observer().trace();
    let seq: Vec<(u64, &str)> = trace.behaviours_of("chooser");
    assert_eq!(
        seq,
        (0..10)
            .map(|i| (i, if i < 3 { "work" } else { "left" }))
            .collect::<Vec<_>>()
    );
    assert!(trace.events.iter().any(|e| matches!(
        e,
        TraceEvent::Transition {
            from: 0,
            to: 1,
            arc: 0,
            iteration: 3,
            ..
        }
    )));
}

// ---------------------------------------------------------------------------
// Drivers.

/// Fails once, at iteration `fail_at`.
struct Flaky {
    fail_at: u64,
    failed: bool,
}

#[derive(Debug, Default)]
struct FlakyOut {
    value: Out<u64>,
}

// What `#[derive(Buffers)]` writes for a driver's flat struct (the derive's code
// names the `embodied` facade, which this crate's tests do not have).
impl Buffers for FlakyOut {
    const GROUPS: &'static [GroupShape] = &[GroupShape {
        name: "",
        peer: None,
        ty: "",
        direction: Direction::Out,
        buffers: &[Field {
            name: "value",
            ty: "u64",
        }],
    }];
    fn fresh(&self) -> Fresh {
        Fresh(u128::from(self.value.is_written()))
    }
}

impl Driver for Flaky {
    const KIND: DeviceKind = DeviceKind::Receptor;
    type Input = ();
    type Output = FlakyOut;
    fn step(&mut self, cx: DriverContext<'_>, _: &(), y: &mut FlakyOut) -> Result<(), DriverError> {
        y.value.set(cx.iteration);
        if cx.iteration == self.fail_at && !self.failed {
            self.failed = true;
            return Err(DriverError::new("sensor bus timeout"));
        }
        Ok(())
    }
}

fn reader_system() -> (System, SubsystemHandle<Reader>) {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    b.subsystem(
        a,
        "c",
        ms(10),
        CounterMemory { n: 0, every: 1 },
        counter_fsm(),
    );
    let r = b.subsystem(
        a,
        "r",
        ms(10),
        Vec::new(),
        Fsm::single(Behaviour::while_loop(
            "read",
            Action::<Reader>::new().memory(|m: &mut Vec<u64>, x: &ReaderIn| {
                if let Some(&v) = x.r.value.fresh() {
                    m.push(v);
                }
            }),
            "false",
        ))
        .unwrap(),
    );
    let dev = b.driver(
        a,
        "R",
        ms(10),
        Flaky {
            fail_at: 2,
            failed: false,
        },
    );
    b.connect(
        dev.output(port!(FlakyOut, value)),
        r.input(port!(ReaderIn, r.value)),
        Policy::Sample,
    );
    (b.build().unwrap(), r)
}

#[test]
fn driver_failure_stops_or_is_retried() {
    let (system, _) = reader_system();
    let mut x = Executor::new(system, ExecConfig::default());
    let err = x.run_until(t_ms(100)).unwrap_err();
    assert_eq!(
        err.to_string(),
        "driver `R`, iteration 2 at 0.020000 s: sensor bus timeout"
    );

    let (system, r) = reader_system();
    let mut x = Executor::new(system, ExecConfig::continue_on_error());
    x.run_until(t_ms(60)).unwrap();
    // The failed step sent nothing; the retry at 30 ms is iteration 2 again.
    assert_eq!(x.memory(&r).unwrap(), &vec![0, 1, 2, 3]);
    assert_eq!(x.report().error_count, 1);
}

/// The default settings, with the huge pages on or off.
fn with_huge_pages(huge_pages: bool) -> ExecConfig {
    ExecConfig {
        huge_pages,
        ..ExecConfig::default()
    }
}

/// A large system's memory backed with huge pages (`ExecConfig::huge_pages`,
/// on by default) runs the same, event for event, as on the pages the
/// allocator gave.
#[test]
fn memory_made_huge_changes_nothing_the_system_does() {
    // 6,000 subsystems: several megabytes, regions of 2 MiB wholly theirs.
    let run = |huge_pages: bool| {
        let config = with_huge_pages(huge_pages);
        let mut x = Executor::with_observer(pairs(3000, 10, 10).system, config, Recorder::new());
        x.run_until(t_ms(100)).unwrap();
        x.observer().trace().clone()
    };
    let (on, off) = (run(true), run(false));
    assert_eq!(on.first_difference(&off), None);
    assert_eq!(on, off);
    assert!(on.events.len() > 6000 * 10, "every subsystem ran");
}

/// A large system's huge pages are asked for beside its first instants (on
/// the executor's thread for them), told when waited for, and none are asked
/// for when the setting is off.
#[test]
fn the_huge_pages_of_a_large_system_are_waited_for_and_told() {
    let executor =
        |huge_pages: bool| Executor::new(pairs(3000, 10, 10).system, with_huge_pages(huge_pages));
    let mut x = executor(true);
    x.run_until(t_ms(20)).unwrap();
    let done = x.wait_for_huge_pages();
    // Several megabytes: more regions than are asked for in place. The
    // kernel may refuse them all (an older one, no huge page free).
    assert!(done.regions > 2, "{done:?}");
    assert!(done.collapsed <= done.regions, "{done:?}");
    assert_eq!(x.wait_for_huge_pages(), done, "told again, the same");
    x.run_until(t_ms(40)).unwrap();
    assert_eq!(x.report().error_count, 0);
    let mut off = executor(false);
    assert_eq!(off.wait_for_huge_pages(), HugePages::default());
    // Dropped at once, while the kernel may still be copying: the drop
    // waits for it, and nothing else is asked of the test.
    drop(executor(true));
}
