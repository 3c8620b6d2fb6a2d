//! Each contract kind, violated and not, at its edges.

use super::*;
use agent_spec::contracts::{Bound, Contracts, Freshness, Invariant, Rate, Response, ValueRange};

const MINIMAL: &str = include_str!("../tests/minimal.ron");

fn monitors(contracts: Contracts) -> Monitors {
    let mut spec = match agent_spec::load("minimal.ron", MINIMAL) {
        Ok(l) => l.spec,
        Err(e) => panic!("the test spec loads: {e:?}"),
    };
    spec.contracts = Some(contracts);
    match Monitors::new(&spec) {
        Ok(m) => m,
        Err(e) => panic!("monitors: {e}"),
    }
}

fn ms(x: u64) -> Time {
    Time::from_nanos(x * 1_000_000)
}

/// Runs `f` with a sink and returns what it collected.
fn collect(f: impl FnOnce(&mut dyn FnMut(Violation))) -> Vec<Violation> {
    let mut out = Vec::new();
    f(&mut |v| out.push(v));
    out
}

#[test]
fn freshness_is_violated_only_past_its_bound() {
    let mut m = monitors(Contracts {
        freshness: vec![Freshness {
            input: "c1.e1.done".into(),
            max_age_ms: 50.0,
        }],
        ..Contracts::default()
    });
    let done = m.input("c1.e1.done").expect("named");
    let v = collect(|s| {
        // Values every 10 ms (c1's period), each read 50 ms after it was sent:
        // the bound itself, never past it.
        for k in 0..10 {
            m.read(done, ms(100 + 10 * k), ms(50 + 10 * k), &mut |v| s(v));
        }
        m.read(done, ms(200), ms(127), &mut |v| s(v)); // 73 > 50
        m.read(done, ms(300), ms(300), &mut |v| s(v));
    });
    assert_eq!(v.len(), 1, "{v:?}");
    assert_eq!(v[0].time, ms(200));
    assert_eq!(
        v[0].broke,
        Broke::Age {
            age: Duration::from_millis(73),
            max: Duration::from_millis(50)
        }
    );
    let c = m.contract(v[0].contract).expect("known");
    assert_eq!(
        (c.kind, c.subsystem.as_str()),
        (ContractKind::Freshness, "c1")
    );
    let line = m.display(&v[0]).to_string();
    assert!(line.contains("age 73.000 ms > 50.000 ms"), "{line}");
    assert!(line.contains("t=0.200000s subsystem=c1"), "{line}");
}

#[test]
fn a_value_that_is_not_renewed_is_too_old_at_the_readers_next_activation() {
    let mut m = monitors(Contracts {
        freshness: vec![Freshness {
            input: "c1.e1.done".into(),
            max_age_ms: 25.0,
        }],
        ..Contracts::default()
    });
    let done = m.input("c1.e1.done").expect("named");
    let v = collect(|s| {
        m.start(ms(0));
        m.read(done, ms(10), ms(5), &mut |v| s(v));
        // The sender stops. c1 (every 10 ms) reads the value stamped 5 ms at
        // 20 (age 15) and 30 (age 25: the bound), and at 40 (age 35) it is
        // too old; the instant 40 itself does not yet tell (another value
        // could arrive for it).
        m.advance(ms(40), &mut |v| s(v));
        assert!(m.next_deadline == Some(ms(40)));
    });
    assert!(v.is_empty(), "{v:?}");
    let v = collect(|s| {
        m.advance(ms(41), &mut |v| s(v));
        m.advance(ms(500), &mut |v| s(v)); // once per value held
    });
    assert_eq!(v.len(), 1, "{v:?}");
    assert_eq!(v[0].time, ms(40));
    assert_eq!(
        v[0].broke,
        Broke::Age {
            age: Duration::from_millis(35),
            max: Duration::from_millis(25)
        }
    );
    // A new value renews it; its own staleness is judged again.
    let v = collect(|s| {
        m.read(done, ms(510), ms(505), &mut |v| s(v));
        m.advance(ms(530), &mut |v| s(v));
        m.finish(ms(600), &mut |v| s(v));
    });
    assert_eq!(v.len(), 1, "{v:?}");
    assert_eq!(v[0].time, ms(540));
}

#[test]
fn a_rate_reports_each_silence_once_at_the_window_end() {
    let mut m = monitors(Contracts {
        rates: vec![Rate {
            input: "c1.e1.done".into(),
            min_hz: 10.0, // window 100 ms
        }],
        ..Contracts::default()
    });
    let done = m.input("c1.e1.done").expect("named");
    let v = collect(|s| {
        m.start(ms(0));
        m.arrived(done, ms(100), &mut |v| s(v)); // a gap of exactly the window
        m.arrived(done, ms(190), &mut |v| s(v));
        m.advance(ms(290), &mut |v| s(v)); // at the window's end: not yet
        m.advance(ms(400), &mut |v| s(v)); // silent since 190
        m.advance(ms(900), &mut |v| s(v)); // the same silence
        m.arrived(done, ms(950), &mut |v| s(v));
        m.finish(ms(1050), &mut |v| s(v)); // the end on the window's edge
    });
    assert_eq!(
        v,
        [Violation {
            time: ms(290),
            contract: ContractId(0),
            broke: Broke::Silent {
                since: ms(190),
                window: Duration::from_millis(100)
            }
        }]
    );
}

#[test]
fn a_rate_catches_an_input_that_never_receives() {
    let mut m = monitors(Contracts {
        rates: vec![Rate {
            input: "c1.e1.done".into(),
            min_hz: 10.0,
        }],
        ..Contracts::default()
    });
    let v = collect(|s| {
        m.start(ms(0));
        m.finish(ms(101), &mut |v| s(v));
    });
    assert_eq!(v.len(), 1);
    assert_eq!(v[0].time, ms(100));
}

#[test]
fn a_bound_judges_duration_and_iterations_per_run() {
    let mut m = monitors(Contracts {
        bounds: vec![Bound {
            behaviour: "c1.move".into(),
            max_s: Some(0.05),
            max_iterations: Some(3),
        }],
        ..Contracts::default()
    });
    let c1 = m.subsystem("c1").expect("c1");
    let mv = m.behaviour(c1, "move");
    let idle = m.behaviour(c1, "idle");
    let v = collect(|s| {
        // A run of 3 activations and 50 ms: within both.
        m.entered(c1, mv, ms(0), &mut |v| s(v));
        for t in [10, 20, 30] {
            m.activation(c1, ms(t), None, &mut |v| s(v));
        }
        m.entered(c1, idle, ms(50), &mut |v| s(v));
        // A run of 4 activations and 60 ms: both broken, each once.
        m.entered(c1, mv, ms(100), &mut |v| s(v));
        for t in [110, 120, 130, 140, 155] {
            m.activation(c1, ms(t), None, &mut |v| s(v));
        }
        m.entered(c1, idle, ms(160), &mut |v| s(v));
        // A run that never ends: judged at the end.
        m.entered(c1, mv, ms(200), &mut |v| s(v));
        m.finish(ms(300), &mut |v| s(v));
    });
    let got: Vec<_> = v.iter().map(|v| (v.time, v.broke)).collect();
    assert_eq!(
        got,
        [
            (
                ms(140),
                Broke::Iterations {
                    entered: ms(100),
                    iterations: 4,
                    max: 3
                }
            ),
            (
                ms(150),
                Broke::Lasted {
                    entered: ms(100),
                    max: Duration::from_millis(50)
                }
            ),
            (
                ms(250),
                Broke::Lasted {
                    entered: ms(200),
                    max: Duration::from_millis(50)
                }
            ),
        ]
    );
}

#[test]
fn a_range_includes_its_limits_and_excludes_nan() {
    let mut m = monitors(Contracts {
        ranges: vec![ValueRange {
            name: "speed".into(),
            buffer: "c1.e1.speed".into(),
            field: None,
            min: Some(-1.0),
            max: Some(1.0),
        }],
        ..Contracts::default()
    });
    let (id, buffer, field) = m.ranges().next().expect("one");
    assert_eq!((buffer, field), ("c1.e1.speed", None));
    let v = collect(|s| {
        for (t, x) in [(1, -1.0), (2, 1.0), (3, 1.0001), (4, f64::NAN), (5, 0.0)] {
            m.value(id, ms(t), x, &mut |v| s(v));
        }
    });
    assert_eq!(v.len(), 2);
    assert_eq!(v[0].time, ms(3));
    assert!(matches!(v[1].broke, Broke::OutOfRange { value, .. } if value.is_nan()));
}

#[test]
fn a_response_is_due_within_its_deadline_inclusive() {
    let mut m = monitors(Contracts {
        responses: vec![Response {
            name: "ack".into(),
            trigger: "c2.c1.order".into(),
            response: "c1.c2.ack".into(),
            within_s: 0.1,
        }],
        ..Contracts::default()
    });
    let order = m.output("c2.c1.order").expect("trigger");
    let ack = m.output("c1.c2.ack").expect("response");
    let v = collect(|s| {
        // Answered on the deadline itself.
        m.sent(order, ms(0), &mut |v| s(v));
        m.sent(ack, ms(100), &mut |v| s(v));
        // Answered at the same instant, the response seen first.
        m.sent(ack, ms(150), &mut |v| s(v));
        m.sent(order, ms(150), &mut |v| s(v));
        // Repeated triggers, one late response: 200 and 250 missed (reported
        // at their deadlines), 320 answered.
        m.sent(order, ms(200), &mut |v| s(v));
        m.sent(order, ms(250), &mut |v| s(v));
        m.sent(order, ms(320), &mut |v| s(v));
        m.sent(ack, ms(400), &mut |v| s(v));
        // A trigger at the end with its deadline after it: not judged.
        m.sent(order, ms(500), &mut |v| s(v));
        m.finish(ms(550), &mut |v| s(v));
    });
    let missed: Vec<_> = v
        .iter()
        .map(|v| match v.broke {
            Broke::Unanswered { trigger, within } => {
                assert_eq!(within, Duration::from_millis(100));
                (v.time, trigger)
            }
            other => panic!("{other:?}"),
        })
        .collect();
    assert_eq!(missed, [(ms(300), ms(200)), (ms(350), ms(250))]);
}

#[test]
fn an_unanswered_newest_trigger_is_reported_too() {
    let mut m = monitors(Contracts {
        responses: vec![Response {
            name: "ack".into(),
            trigger: "c2.c1.order".into(),
            response: "c1.c2.ack".into(),
            within_s: 0.1,
        }],
        ..Contracts::default()
    });
    let order = m.output("c2.c1.order").expect("trigger");
    let v = collect(|s| {
        m.sent(order, ms(0), &mut |v| s(v));
        m.sent(order, ms(50), &mut |v| s(v));
        m.finish(ms(1000), &mut |v| s(v));
    });
    let times: Vec<_> = v.iter().map(|v| v.time).collect();
    assert_eq!(times, [ms(100), ms(150)]);
}

#[test]
fn an_invariant_is_judged_on_the_predicates_given() {
    let mut m = monitors(Contracts {
        invariants: vec![Invariant {
            name: "no_order_when_done".into(),
            subsystem: "c1".into(),
            holds: "!(got_order && finished)".into(),
        }],
        ..Contracts::default()
    });
    let c1 = m.subsystem("c1").expect("c1");
    let v = collect(|s| {
        m.activation(c1, ms(1), Some(&[true, false]), &mut |v| s(v));
        m.activation(c1, ms(2), Some(&[true, true]), &mut |v| s(v));
        m.activation(c1, ms(3), None, &mut |v| s(v)); // not evaluable: nothing
        // By bits: `finished` unknown judges nothing; known, it breaks it.
        m.predicates(c1, ms(4), 0b01, 0b01, &mut |v| s(v));
        m.predicates(c1, ms(5), 0b11, 0b11, &mut |v| s(v));
        m.predicates(c1, ms(6), 0b11, 0b01, &mut |v| s(v));
    });
    let times: Vec<_> = v.iter().map(|v| v.time).collect();
    assert_eq!(times, [ms(2), ms(5)]);
    assert_eq!(
        v[0].broke,
        Broke::False {
            predicates: 0b11,
            reads: 0b11
        }
    );
    assert_eq!(
        m.display(&v[1]).to_string(),
        "t=0.005000s subsystem=c1 contract=invariant:no_order_when_done: \
         false with got_order=true finished=true"
    );
}

#[test]
fn unknown_names_and_bad_bounds_are_refused() {
    let mut spec = agent_spec::load("minimal.ron", MINIMAL)
        .expect("loads")
        .spec;
    spec.contracts = Some(Contracts {
        bounds: vec![Bound {
            behaviour: "c1.flying".into(),
            max_s: Some(1.0),
            max_iterations: None,
        }],
        ..Contracts::default()
    });
    let e = Monitors::new(&spec).expect_err("no such behaviour");
    assert!(e.to_string().contains("no behaviour `flying`"), "{e}");
    spec.contracts = Some(Contracts {
        invariants: vec![Invariant {
            name: "i".into(),
            subsystem: "c1".into(),
            holds: "flying".into(),
        }],
        ..Contracts::default()
    });
    let e = Monitors::new(&spec).expect_err("no such predicate");
    assert!(e.to_string().contains("no predicate `flying`"), "{e}");
    spec.contracts = Some(Contracts {
        freshness: vec![Freshness {
            input: "c1.e1.done".into(),
            max_age_ms: 0.0,
        }],
        ..Contracts::default()
    });
    assert!(matches!(
        Monitors::new(&spec),
        Err(BuildError::Bound { .. })
    ));
}

/// The reads a watch is told when it asks for the old values only
/// ([`Monitors::freshness_bound`]: a new value through [`Monitors::read`]
/// when older than the bound, one still held through [`Monitors::held`])
/// give the violations, times and ages of every read told, whatever the
/// pattern of sends, ages and activations left out after a read.
#[test]
fn a_freshness_told_only_of_old_values_judges_as_one_told_every_read() {
    let contracts = || Contracts {
        freshness: vec![Freshness {
            input: "c1.e1.done".into(),
            max_age_ms: 25.0,
        }],
        ..Contracts::default()
    };
    let (mut every, mut old) = (monitors(contracts()), monitors(contracts()));
    every.at_activations();
    old.at_activations();
    let done = every.input("c1.e1.done").expect("named");
    let c1 = every.subsystem("c1").expect("named");
    assert_eq!(old.freshness_bound(done), Some(25_000_000));
    let mut seed = 0x2545_f491_4f6c_dd1du64;
    let mut next = |n: u64| {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        seed % n
    };
    let (mut a, mut b) = (Vec::new(), Vec::new());
    let mut stamp: Option<Time> = None;
    every.start(ms(0));
    old.start(ms(0));
    for k in 1..2000u64 {
        let t = ms(10 * k);
        let new = next(3) == 0;
        if new {
            let lag = ms(next(40));
            let s = Time::from_nanos(t.as_nanos() - lag.as_nanos());
            stamp = Some(stamp.map_or(s, |p| p.max(s)));
        }
        let Some(s) = stamp else { continue };
        let age = t.as_nanos() - s.as_nanos();
        if new {
            every.read(done, t, s, &mut |v| a.push(v));
            if age > 25_000_000 {
                old.read(done, t, s, &mut |v| b.push(v));
            }
        } else if age > 25_000_000 {
            old.held(done, t, s);
        }
        // Now and then the reader reads but does not act (an error).
        if next(10) != 0 {
            every.activation(c1, t, None, &mut |v| a.push(v));
            old.activation(c1, t, None, &mut |v| b.push(v));
        }
    }
    assert!(
        a.len() > 20,
        "the pattern breaks the bound often: {}",
        a.len()
    );
    assert_eq!(a, b);
}
