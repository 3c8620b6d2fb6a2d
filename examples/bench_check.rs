//! How long the checker takes on large specs.
//!
//! ```text
//! cargo run --release --example bench_check
//! ```
//!
//! Generates valid specs of growing size, without warnings (agents of a control
//! subsystem and a virtual effector with five behaviours each, 100 buffers per agent,
//! 40 links per agent) and times loading + checking (RON parsing, span index, every
//! rule, the arc proofs), the work `embodied check` does; every run asserts that the
//! spec checks with 0 findings. The last line reads
//! `check_ms_1k=<ms for 1,000 behaviours and 10,000 buffers> growth=<time at 10x / time at 1x>`.

use std::fmt::Write as _;
use std::time::Instant;

/// Buffers in each group (there are five groups of them per agent: memory of c,
/// c's inputs and outputs, e's inputs and outputs).
const PER_GROUP: usize = 20;
/// Behaviours per subsystem.
const BEHAVIOURS: usize = 5;

fn subsystem(out: &mut String, name: &str, kind: &str, peer: &str, memory: bool) {
    let buffers = |prefix: &str| {
        (0..PER_GROUP)
            .map(|k| format!("(name: \"{prefix}{k}\", type: \"f64\")"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let _ = write!(out, "(name: \"{name}\", kind: {kind}, period_ms: 10.0, ");
    if memory {
        let _ = write!(out, "memory: [{}], ", buffers("m"));
    }
    let _ = write!(
        out,
        "inputs: [(peer: \"{peer}\", buffers: [{}])], ",
        buffers("x")
    );
    let _ = write!(
        out,
        "outputs: [(peer: \"{peer}\", buffers: [{}])], ",
        buffers("y")
    );
    // `p{k}` ends behaviour k; `q{k}` picks the arc out of it (the last behaviour has a
    // single unconditional arc, so it has no `q`: every predicate is used).
    out.push_str("predicates: [");
    for k in 0..BEHAVIOURS {
        let _ = write!(out, "(name: \"p{k}\", reads: [\"x{k}\"]), ");
        if k < BEHAVIOURS - 1 {
            let _ = write!(out, "(name: \"q{k}\", reads: [\"x{k}\"]), ");
        }
    }
    out.push_str("], functions: [");
    for k in 0..BEHAVIOURS {
        let reads = format!("\"x{k}\", \"x{}\"", k + 1);
        let _ = write!(
            out,
            "(name: \"out{k}\", target: Output(\"{peer}\"), reads: [{reads}], writes: [\"y{k}\", \"y{}\"]), ",
            k + BEHAVIOURS
        );
        if memory {
            let _ = write!(
                out,
                "(name: \"mem{k}\", target: Memory, reads: [\"m{k}\", {reads}], writes: [\"m{k}\"]), "
            );
        }
    }
    out.push_str("], behaviours: [");
    for k in 0..BEHAVIOURS {
        let functions = if memory {
            format!("\"out{k}\", \"mem{k}\"")
        } else {
            format!("\"out{k}\"")
        };
        let _ = write!(
            out,
            "(name: \"b{k}\", kind: Repeat, functions: [{functions}], terminal: \"p{k}\"), "
        );
    }
    out.push_str("], fsm: (initial: \"b0\", arcs: [");
    for k in 0..BEHAVIOURS - 1 {
        let _ = write!(
            out,
            "(from: \"b{k}\", to: \"b{}\", when: \"q{k}\"), (from: \"b{k}\", to: \"b0\", when: \"!q{k}\"), ",
            k + 1
        );
    }
    let _ = write!(
        out,
        "(from: \"b{}\", to: \"b0\", when: \"true\")])),",
        BEHAVIOURS - 1
    );
}

/// A valid spec, without warnings, with `agents` agents: `10 * agents` behaviours,
/// `100 * agents` buffers.
fn spec(agents: usize) -> String {
    let mut out = String::from("(name: \"bench\", agents: [");
    for a in 0..agents {
        let _ = write!(out, "(name: \"a{a}\", subsystems: [");
        subsystem(
            &mut out,
            &format!("c{a}"),
            "Control",
            &format!("e{a}"),
            true,
        );
        subsystem(
            &mut out,
            &format!("e{a}"),
            "VirtualEffector",
            &format!("c{a}"),
            false,
        );
        out.push_str("]),");
    }
    out.push_str("], links: [");
    for a in 0..agents {
        for k in 0..PER_GROUP {
            let _ = write!(out, "(from: \"c{a}.e{a}.y{k}\", to: \"e{a}.c{a}.x{k}\"), ");
            let _ = write!(out, "(from: \"e{a}.c{a}.y{k}\", to: \"c{a}.e{a}.x{k}\"), ");
        }
    }
    out.push_str("])");
    out
}

fn median_ms(text: &str, runs: usize) -> f64 {
    let mut times: Vec<f64> = (0..runs)
        .map(|_| {
            let start = Instant::now();
            let (spec, report) = embodied::spec::check_source("bench.ron", text);
            let ms = start.elapsed().as_secs_f64() * 1e3;
            // The checker does all its work on a clean spec; a finding (even a warning)
            // would mean the generator is wrong and the timings measure something else.
            assert!(
                spec.is_some() && report.findings.is_empty(),
                "the generated spec must check with 0 findings:\n{}",
                report.short()
            );
            ms
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

fn main() {
    let mut one = 0.0;
    let mut ten = 0.0;
    for agents in [10, 30, 100, 300, 1000] {
        let text = spec(agents);
        let runs = if agents >= 1000 { 5 } else { 9 };
        let ms = median_ms(&text, runs);
        println!(
            "{:>6} behaviours {:>7} buffers {:>5} KiB: {ms:>8.2} ms ({:.1} us per behaviour)",
            agents * 2 * BEHAVIOURS,
            agents * 5 * PER_GROUP,
            text.len() / 1024,
            ms * 1e3 / (agents * 2 * BEHAVIOURS) as f64
        );
        if agents == 100 {
            one = ms;
        }
        if agents == 1000 {
            ten = ms;
        }
    }
    println!(
        "against the target: {:.2}x of 100 ms at 1,000 behaviours; growth {:.1} for 10x the size (10 is linear)",
        one / 100.0,
        ten / one
    );
    println!("check_ms_1k={one:.1} growth={:.1}", ten / one);
}
