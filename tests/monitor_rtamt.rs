//! The monitors' verdicts against an independent monitor's on the same
//! signals: PyPI rtamt (discrete-time STL, tests/interop/rtamt_verdicts.py).
//!
//! Signals sampled every 10 ms (step `k` at `k * 10 ms`), generated from a
//! seed, each family in cases that hold and cases that do not (asserted, so
//! that agreement is not on one verdict only):
//!
//! * freshness: the age of the value each activation reads, `always (age <= 50)`
//!   against a freshness of 50 ms (ages on the bound included);
//! * range: a numeric value, `always (x <= 1.5 and x >= -1.5)` against a range
//!   \[-1.5, 1.5\] (values on the limits included);
//! * response: a trigger and a response sent at some steps,
//!   `always ((trigger >= 0.5) -> (eventually[0:S] (response >= 0.5)))` against
//!   a response within `S * 10 ms` (no trigger in the last `S` steps: past
//!   the end, rtamt judges the missing future, ours does not judge a deadline
//!   after the run).
//!
//! `scripts/test --features monitor --test monitor_rtamt` installs rtamt and sets
//! `EMBODIED_INTEROP_PYTHON`; plain `cargo test` skips, saying so.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::io::Write;
use std::process::{Command, Stdio};

use embodied::Time;
use embodied::monitor::{Monitors, Violation};
use embodied::spec::contracts::{Contracts, Freshness, Response, ValueRange};

const STEP_NS: u64 = 10_000_000;
const STEPS: usize = 200;

/// A small deterministic generator (xorshift64*).
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        self.0.wrapping_mul(0x2545_f491_4f6c_dd1d)
    }

    fn below(&mut self, n: u64) -> u64 {
        self.next() % n
    }
}

fn monitors(contracts: Contracts) -> Monitors {
    let text = std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/specs/valid/minimal.ron"
    ))
    .unwrap();
    let mut spec = embodied::spec::load("minimal.ron", text).unwrap().spec;
    spec.contracts = Some(contracts);
    Monitors::new(&spec).unwrap()
}

fn at(k: usize) -> Time {
    Time::from_nanos(k as u64 * STEP_NS)
}

/// One case: the STL formula and its signals, and our verdict.
struct Case {
    family: &'static str,
    stl: String,
    vars: Vec<(&'static str, Vec<f64>)>,
    ours: bool,
}

fn freshness(rng: &mut Rng, late: bool) -> Case {
    let mut m = monitors(Contracts {
        freshness: vec![Freshness {
            input: "c1.e1.done".into(),
            max_age_ms: 50.0,
        }],
        ..Contracts::default()
    });
    let input = m.input("c1.e1.done").unwrap();
    // Ages in whole ms, 50 (the bound) now and then; over it only if `late`.
    let ages: Vec<f64> = (0..STEPS)
        .map(|_| match rng.below(20) {
            0 => 50.0,
            1 if late => 51.0 + rng.below(30) as f64,
            _ => rng.below(50) as f64,
        })
        .collect();
    let mut broken: Vec<Violation> = Vec::new();
    for (k, age) in ages.iter().enumerate() {
        let stamp = Time::from_nanos((at(k).as_nanos() + 1_000_000_000) - *age as u64 * 1_000_000);
        let t = Time::from_nanos(at(k).as_nanos() + 1_000_000_000);
        m.read(input, t, stamp, &mut |v| broken.push(v));
    }
    Case {
        family: "freshness",
        stl: "always (age <= 50)".into(),
        vars: vec![("age", ages)],
        ours: broken.is_empty(),
    }
}

fn range(rng: &mut Rng, wild: bool) -> Case {
    let mut m = monitors(Contracts {
        ranges: vec![ValueRange {
            name: "speed".into(),
            buffer: "c1.e1.speed".into(),
            field: None,
            min: Some(-1.5),
            max: Some(1.5),
        }],
        ..Contracts::default()
    });
    let (id, _, _) = m.ranges().next().unwrap();
    let xs: Vec<f64> = (0..STEPS)
        .map(|_| match rng.below(40) {
            0 => 1.5,
            1 => -1.5,
            2 if wild => 1.5 + (1 + rng.below(100)) as f64 / 64.0,
            3 if wild => -1.5 - (1 + rng.below(100)) as f64 / 64.0,
            _ => (rng.below(193) as f64 - 96.0) / 64.0,
        })
        .collect();
    let mut broken: Vec<Violation> = Vec::new();
    for (k, x) in xs.iter().enumerate() {
        m.value(id, at(k), *x, &mut |v| broken.push(v));
    }
    Case {
        family: "range",
        stl: "always ((x <= 1.5) and (x >= -1.5))".into(),
        vars: vec![("x", xs)],
        ours: broken.is_empty(),
    }
}

fn response(rng: &mut Rng, within: usize, answer_rate: u64) -> Case {
    let mut m = monitors(Contracts {
        responses: vec![Response {
            name: "ack".into(),
            trigger: "c2.c1.order".into(),
            response: "c1.c2.ack".into(),
            within_s: within as f64 * STEP_NS as f64 / 1e9,
        }],
        ..Contracts::default()
    });
    let (trigger, response) = (
        m.output("c2.c1.order").unwrap(),
        m.output("c1.c2.ack").unwrap(),
    );
    let mut triggers = vec![0.0; STEPS];
    let mut responses = vec![0.0; STEPS];
    for k in 0..STEPS - within {
        if rng.below(8) == 0 {
            triggers[k] = 1.0;
            // Answered after 0..=within steps, or (1 in answer_rate) a step late.
            let delay = if rng.below(answer_rate) == 0 {
                within + 1
            } else {
                rng.below(within as u64 + 1) as usize
            };
            if k + delay < STEPS {
                responses[k + delay] = 1.0;
            }
        }
    }
    let mut broken: Vec<Violation> = Vec::new();
    m.start(at(0));
    for k in 0..STEPS {
        // Within a step, the order of the two sends does not matter.
        if rng.below(2) == 0 {
            if responses[k] > 0.0 {
                m.sent(response, at(k), &mut |v| broken.push(v));
            }
            if triggers[k] > 0.0 {
                m.sent(trigger, at(k), &mut |v| broken.push(v));
            }
        } else {
            if triggers[k] > 0.0 {
                m.sent(trigger, at(k), &mut |v| broken.push(v));
            }
            if responses[k] > 0.0 {
                m.sent(response, at(k), &mut |v| broken.push(v));
            }
        }
    }
    m.finish(at(STEPS - 1), &mut |v| broken.push(v));
    Case {
        family: "response",
        stl: format!("always ((trigger >= 0.5) -> (eventually[0:{within}] (response >= 0.5)))"),
        vars: vec![("trigger", triggers), ("response", responses)],
        ours: broken.is_empty(),
    }
}

/// rtamt's verdicts on `cases`, in order.
fn rtamt(python: &str, cases: &[Case]) -> Vec<bool> {
    let json: Vec<String> = cases
        .iter()
        .map(|c| {
            let vars: Vec<String> = c
                .vars
                .iter()
                .map(|(n, xs)| {
                    let xs: Vec<String> = xs.iter().map(|x| format!("{x:?}")).collect();
                    format!("\"{n}\": [{}]", xs.join(", "))
                })
                .collect();
            format!(
                "{{\"spec\": \"{}\", \"vars\": {{{}}}}}",
                c.stl,
                vars.join(", ")
            )
        })
        .collect();
    let script = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/interop/rtamt_verdicts.py"
    );
    let mut child = Command::new(python)
        .arg(script)
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap();
    child
        .stdin
        .take()
        .unwrap()
        .write_all(format!("[{}]", json.join(", ")).as_bytes())
        .unwrap();
    let out = child.wait_with_output().unwrap();
    assert!(out.status.success(), "rtamt_verdicts.py failed");
    let text = String::from_utf8(out.stdout).unwrap();
    text.trim()
        .trim_start_matches('[')
        .trim_end_matches(']')
        .split(',')
        .map(|v| match v.trim() {
            "true" => true,
            "false" => false,
            other => panic!("not a verdict: {other}"),
        })
        .collect()
}

#[test]
fn our_verdicts_are_rtamts_on_the_same_signals() {
    let Ok(python) = std::env::var("EMBODIED_INTEROP_PYTHON") else {
        eprintln!(
            "skipped: EMBODIED_INTEROP_PYTHON is not set (scripts/test --features monitor --test monitor_rtamt installs rtamt and sets it)"
        );
        return;
    };
    let mut rng = Rng(0x005e_ed0f_c047_ac75);
    let mut cases = Vec::new();
    for k in 0..12 {
        cases.push(freshness(&mut rng, k % 2 == 1));
        cases.push(range(&mut rng, k % 2 == 1));
        cases.push(response(
            &mut rng,
            1 + k % 4,
            if k % 2 == 1 { 6 } else { 1000 },
        ));
    }
    let theirs = rtamt(&python, &cases);
    assert_eq!(theirs.len(), cases.len());
    for (c, t) in cases.iter().zip(&theirs) {
        assert_eq!(
            c.ours, *t,
            "{}: {} ours {} rtamt {}",
            c.family, c.stl, c.ours, t
        );
    }
    for family in ["freshness", "range", "response"] {
        let verdicts: Vec<bool> = cases
            .iter()
            .filter(|c| c.family == family)
            .map(|c| c.ours)
            .collect();
        assert!(
            verdicts.contains(&true) && verdicts.contains(&false),
            "{family}: both verdicts among the cases: {verdicts:?}"
        );
    }
}
