//! `embodied check --timing --wcet-from FILE.mcap`: the WCETs and wake-up
//! latenesses measured in a recording's `/timing` channel (times the margin
//! 1.2) replace the declared WCETs and release jitters; a component the recording lacks keeps its declaration, said; a
//! recording without the channel, or unreadable, is refused with status 2.
//! Needs the `cli` feature:
//! `cargo test --features cli --test spec_wcet_from`.

#![cfg(feature = "cli")]
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

#[path = "common/binary.rs"]
mod binary;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use embodied::record::TimingStats;
use embodied::record::mcap;
use embodied::record::timing::NodeStats;

use binary::embodied;

fn node(name: &str, exec_max_ns: u64) -> NodeStats {
    NodeStats {
        node: name.into(),
        thread: name.into(),
        period_ns: 10_000_000,
        activations: 100,
        exec_max_ns,
        exec_p99_ns: exec_max_ns / 2,
        exec_p50_ns: exec_max_ns / 4,
        lateness_max_ns: 50_000,
        lateness_p99_ns: 20_000,
        response_max_ns: 0,
        response_p99_ns: 0,
        overruns: 0,
        priority_asked: Some(79),
        priority_granted: Some(79),
    }
}

/// A recording holding `stats` on `/timing` (or no such channel: `None`).
fn recording(name: &str, stats: Option<&TimingStats>) -> PathBuf {
    let path = std::env::temp_dir().join(format!("{name}-{}.mcap", std::process::id()));
    let file = std::io::BufWriter::new(std::fs::File::create(&path).unwrap());
    let mut w = mcap::Writer::new(file).unwrap();
    let topic = if stats.is_some() {
        "/timing"
    } else {
        "/errors"
    };
    let channel = w.add_channel(0, topic, "json", &BTreeMap::new()).unwrap();
    let data = stats.map_or_else(|| b"{}".to_vec(), |s| s.to_json().into_bytes());
    w.write_to_known_channel(
        &mcap::records::MessageHeader {
            channel_id: channel,
            sequence: 0,
            log_time: 1,
            publish_time: 1,
        },
        &data,
    )
    .unwrap();
    w.finish().unwrap();
    path
}

fn stats(nodes: Vec<NodeStats>) -> TimingStats {
    TimingStats {
        version: 1,
        host: "h".into(),
        process: "local".into(),
        rt_priority: true,
        wall_ns: 1,
        last_instant_ns: 1,
        nodes,
    }
}

fn check(file: &Path) -> (i32, String, String) {
    embodied(&[
        "check",
        "--timing",
        "specs/rex.ron",
        "--deployment",
        "simulation_without_vo",
        "--wcet-from",
        file.to_str().unwrap(),
    ])
}

#[test]
fn measured_wcets_replace_the_declared_ones_with_the_margin() {
    // c1 measured at 1 ms (declared 3 ms): the analysis takes 1.2 ms.
    let file = recording("wcet-from", Some(&stats(vec![node("c1", 1_000_000)])));
    let (code, out, err) = check(&file);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("measured max x 1.2"), "{out}");
    assert!(
        out.contains(
            "wcet c1         declared_ms=3.0000 measured_max_ms=1.0000 used_ms=1.2000 from=measured"
        ),
        "{out}"
    );
    assert!(
        out.contains("wcet e11        declared_ms=5.0000 measured_max_ms=- used_ms=5.0000 from=declared (not in the recording)"),
        "{out}"
    );
    assert!(
        out.contains("c1           T =       10 ms  C =      1.2 ms"),
        "{out}"
    );
    let _ = std::fs::remove_file(file);
}

#[test]
fn a_measured_time_that_breaks_the_schedule_is_a_finding() {
    // e11 measured at 60 ms: more than its 50 ms period.
    let file = recording(
        "wcet-from-slow",
        Some(&stats(vec![node("e11", 60_000_000)])),
    );
    let (code, out, err) = check(&file);
    assert_eq!(code, 1, "{out}{err}");
    assert!(err.contains("spec::unschedulable"), "{err}");
    assert!(err.contains("`e11`"), "{err}");
    let _ = std::fs::remove_file(file);
}

#[test]
fn measured_wake_up_lateness_is_the_release_jitter() {
    // c1 woke at most 0.05 ms late: J = 0.06 ms, in the certificate; then
    // 9.5 ms late (of a 10 ms period): J + C passes the period.
    let file = recording("wcet-from-late", Some(&stats(vec![node("c1", 1_000_000)])));
    let (code, out, err) = check(&file);
    assert_eq!(code, 0, "{out}{err}");
    assert!(out.contains("largest wake-up lateness x 1.2"), "{out}");
    assert!(
        out.contains(
            "release_jitter c1         declared_ms=0.5000 measured_max_ms=0.0500 used_ms=0.0600 from=measured"
        ),
        "{out}"
    );
    assert!(out.contains("C =      1.2 ms  J =     0.06 ms"), "{out}");
    let mut late = node("c1", 1_000_000);
    late.lateness_max_ns = 9_500_000;
    let file2 = recording("wcet-from-later", Some(&stats(vec![late])));
    let (code, out, err) = check(&file2);
    assert_eq!(code, 1, "{out}{err}");
    assert!(err.contains("spec::unschedulable"), "{err}");
    assert!(err.contains("J = 11.4 ms"), "{err}");
    let _ = std::fs::remove_file(file);
    let _ = std::fs::remove_file(file2);
}

#[test]
fn a_recording_without_timing_statistics_is_refused() {
    // Status 2: the timing could not be evaluated (not 1: a broken promise).
    let file = recording("wcet-from-none", None);
    let (code, out, err) = check(&file);
    assert_eq!(code, 2, "{out}{err}");
    assert!(
        err.contains(&format!(
            "--wcet-from {}: the recording has no `/timing` channel",
            file.display()
        )),
        "{err}"
    );
    assert!(err.contains("made without `--realtime`"), "{err}");
    assert!(err.contains("deterministic run"), "{err}");
    assert!(
        !out.contains("certified") && !out.contains("FAILED"),
        "{out}"
    );
    let _ = std::fs::remove_file(file);
}

#[test]
fn a_recording_that_cannot_be_read_is_refused() {
    let file = std::env::temp_dir().join(format!("wcet-from-missing-{}.mcap", std::process::id()));
    let (code, out, err) = check(&file);
    assert_eq!(code, 2, "{out}{err}");
    assert!(
        err.contains(&format!("--wcet-from {}", file.display())),
        "{err}"
    );
}
