//! The monitors allocate nothing per event in the steady state.

use agent_core::Time;
use agent_core::allocations::{CountingAllocator, count};
use agent_monitor::Monitors;
use agent_spec::contracts::{Bound, Contracts, Freshness, Invariant, Rate, Response, ValueRange};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

#[test]
fn events_and_violations_allocate_nothing() {
    let mut spec = agent_spec::load("minimal.ron", include_str!("minimal.ron"))
        .expect("loads")
        .spec;
    spec.contracts = Some(Contracts {
        freshness: vec![Freshness {
            input: "c1.e1.done".into(),
            max_age_ms: 5.0,
        }],
        rates: vec![Rate {
            input: "c1.e1.done".into(),
            min_hz: 500.0,
        }],
        bounds: vec![Bound {
            behaviour: "c1.move".into(),
            max_s: Some(0.01),
            max_iterations: Some(2),
        }],
        ranges: vec![ValueRange {
            name: "speed".into(),
            buffer: "c1.e1.speed".into(),
            field: None,
            min: Some(0.0),
            max: Some(1.0),
        }],
        responses: vec![Response {
            name: "ack".into(),
            trigger: "c2.c1.order".into(),
            response: "c1.c2.ack".into(),
            within_s: 0.002,
        }],
        invariants: vec![Invariant {
            name: "i".into(),
            subsystem: "c1".into(),
            holds: "!finished".into(),
        }],
        ..Contracts::default()
    });
    let mut m = Monitors::new(&spec).expect("monitors");
    let done = m.input("c1.e1.done").expect("done");
    let order = m.output("c2.c1.order").expect("order");
    let ack = m.output("c1.c2.ack").expect("ack");
    let c1 = m.subsystem("c1").expect("c1");
    let (mv, idle) = (m.behaviour(c1, "move"), m.behaviour(c1, "idle"));
    let (range, _, _) = m.ranges().next().expect("range");
    let mut violations = 0u64;
    let mut cycle = |m: &mut Monitors, k: u64| {
        let t = Time::from_nanos(k * 1_000_000);
        let mut sink = |_| violations += 1;
        // Every kind fed, and every kind broken now and then.
        if !k.is_multiple_of(7) {
            m.arrived(done, t, &mut sink);
        }
        m.read(
            done,
            t,
            Time::from_nanos(t.as_nanos().saturating_sub((k % 9) * 1_000_000)),
            &mut sink,
        );
        m.value(range, t, (k % 5) as f64 * 0.3, &mut sink);
        m.sent(order, t, &mut sink);
        if k.is_multiple_of(4) {
            m.sent(ack, t, &mut sink);
        }
        match k % 20 {
            0 => m.entered(c1, mv, t, &mut sink),
            15 => m.entered(c1, idle, t, &mut sink),
            _ => {}
        }
        m.activation(
            c1,
            t,
            Some(&[k.is_multiple_of(3), k.is_multiple_of(11)]),
            &mut sink,
        );
        // As a running executor's watch gives them: bits.
        m.predicates(c1, t, 0b11, u64::from(k.is_multiple_of(5)) << 1, &mut sink);
    };
    m.start(Time::ZERO);
    for k in 0..100 {
        cycle(&mut m, k);
    }
    let (n, ()) = count(|| {
        for k in 100..10_100 {
            cycle(&mut m, k);
        }
    })
    .expect("the counting allocator is installed");
    assert_eq!(n, 0, "allocations in 10 000 cycles");
    assert!(
        violations > 1000,
        "every kind broken now and then: {violations}"
    );
}
