//! The monitors' cost per event: a plain timing loop (the workspace has no
//! criterion or divan), printing `ns_per_event=` for Rex-sized contract sets.
//!
//! `cargo bench -p agent-monitor --bench events`

use std::hint::black_box;
use std::time::Instant;

use agent_core::Time;
use agent_monitor::Monitors;
use agent_spec::contracts::{Bound, Contracts, Freshness, Rate, Response, ValueRange};

fn main() {
    let Ok(loaded) = agent_spec::load("minimal.ron", include_str!("../tests/minimal.ron")) else {
        eprintln!("the bench's spec does not load");
        std::process::exit(2);
    };
    let mut spec = loaded.spec;
    // Rex's contract set has 4 freshness, 2 rates, 1 bound, 4 ranges, 1 response.
    spec.contracts = Some(Contracts {
        freshness: (0..4)
            .map(|_| Freshness {
                input: "c1.e1.done".into(),
                max_age_ms: 50.0,
            })
            .collect(),
        rates: (0..2)
            .map(|_| Rate {
                input: "c1.e1.done".into(),
                min_hz: 10.0,
            })
            .collect(),
        bounds: vec![Bound {
            behaviour: "c1.move".into(),
            max_s: Some(1.0),
            max_iterations: None,
        }],
        ranges: (0..4)
            .map(|k| ValueRange {
                name: format!("r{k}"),
                buffer: "c1.e1.speed".into(),
                field: None,
                min: Some(-10.0),
                max: Some(10.0),
            })
            .collect(),
        responses: vec![Response {
            name: "ack".into(),
            trigger: "c2.c1.order".into(),
            response: "c1.c2.ack".into(),
            within_s: 2.0,
        }],
        ..Contracts::default()
    });
    let Ok(mut m) = Monitors::new(&spec) else {
        eprintln!("the bench's contracts do not make monitors");
        std::process::exit(2);
    };
    let (Some(done), Some(order), Some(ack), Some(c1)) = (
        m.input("c1.e1.done"),
        m.output("c2.c1.order"),
        m.output("c1.c2.ack"),
        m.subsystem("c1"),
    ) else {
        std::process::exit(2);
    };
    let ranges: Vec<_> = m.ranges().map(|(id, _, _)| id).collect();
    let cycles = 2_000_000u64;
    // One cycle: an arrival, a read, 4 range values, 2 sends, an activation: 9 events.
    let events_per_cycle = 9u64;
    let mut violations = 0u64;
    m.start(Time::ZERO);
    let started = Instant::now();
    for k in 0..cycles {
        let t = Time::from_nanos(k * 1_000_000);
        let mut sink = |_| violations += 1;
        m.arrived(done, t, &mut sink);
        m.read(
            done,
            t,
            Time::from_nanos(t.as_nanos().saturating_sub(3_000_000)),
            &mut sink,
        );
        for &r in &ranges {
            m.value(r, t, black_box(1.5), &mut sink);
        }
        m.sent(order, t, &mut sink);
        m.sent(ack, t, &mut sink);
        m.activation(c1, t, None, &mut sink);
    }
    let ns = started.elapsed().as_nanos() as f64 / (cycles * events_per_cycle) as f64;
    println!(
        "contracts={} events={} violations={violations} ns_per_event={ns:.1} ns_per_cycle={:.1}",
        m.contracts().len(),
        cycles * events_per_cycle,
        ns * events_per_cycle as f64
    );
}
