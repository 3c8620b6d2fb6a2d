//! A sample link between two processes over real Zenoh sessions carries only
//! the values its reader can see, and a fallback a read: a 1 ms writer read
//! every 50 ms publishes about 40 values a second, not 1,000, and the reader
//! takes what a link in one process gives it at the same instants.
//!
//! The two processes are two members of deployment `two` in this test
//! process, each with its own Zenoh session on loopback and its own real-time
//! run; a third session counts the messages that cross.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

mod common;

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use agent_core::*;
use agent_spec::model::Spec;
use agent_zenoh::zenoh::Wait;
use agent_zenoh::zenoh::sample::Sample;
use agent_zenoh::{Member, Options, open_peer};
use common::*;

/// The counter `c` (1 ms) in process `p1`, the recorder `e` (50 ms) in `p2`.
fn spec() -> Spec {
    agent_spec::options()
        .from_str(
            r#"(name: "relay", agents: [], deployments: [(
                name: "two", timeout_ms: 10000, secure: false,
                hosts: [(name: "local", processes: [(name: "p1", runs: ["c"]), (name: "p2", runs: ["e"])])],
            )])"#,
        )
        .unwrap()
}

/// The key of `c`'s values (`agent_core::link::remote::link_key`).
const KEY: &str = "relay/a/c/e/count";
const RUN: Duration = Duration::from_millis(3_000);

/// What one process's run gave: its finished system, `e`'s handle and the
/// link from `c` to `e`.
struct Run {
    finished: Finished,
    e: SubsystemHandle<Recv>,
    down: LinkId,
}

/// Process `process` of the pair (`c` writing every `every`-th ms), on `port`.
fn process(process: &'static str, port: u16, every: u64) -> std::thread::JoinHandle<Run> {
    std::thread::spawn(move || {
        let Pair {
            system, e, down, ..
        } = pair(1, 50, every, Policy::Sample, false);
        let options = Options {
            port: Some(port),
            timeout: Some(Duration::from_secs(10)),
            ..Options::default()
        };
        let mut member = Member::join(&spec(), "two", process, &options).unwrap();
        let rt = placed(system, &mut member);
        let running = rt
            .start_when(RUN, || member.ready(Duration::from_millis(300)))
            .unwrap();
        let finished = running.join().unwrap();
        member.close().unwrap();
        Run { finished, e, down }
    })
}

/// What `e` read at each of its instants, in one process (the deterministic
/// executor over an in-process link) for `iterations` reads.
fn in_one_process(every: u64, iterations: usize) -> Vec<Option<u64>> {
    let p = pair(1, 50, every, Policy::Sample, false);
    let mut exec = Executor::new(p.system, ExecConfig::default());
    exec.run_until(Time::from_nanos(50_000_000 * (iterations as u64 + 1)))
        .unwrap();
    let memory = exec.memory(&p.e).unwrap();
    let mut read = vec![None; memory.fresh.len()];
    for &(i, v, _) in &memory.got {
        read[i as usize] = Some(v);
    }
    read
}

/// Run both processes with a counting tap on `c`'s key; `e`'s reads (one
/// per instant, `None` where nothing new came), the messages that crossed,
/// and the link's counters on the writer's side and on the reader's.
fn over_zenoh(port: u16, every: u64) -> (Vec<Option<u64>>, u64, LinkStats, LinkStats) {
    let crossed = Arc::new(AtomicU64::new(0));
    let tap = open_peer(
        None,
        &[
            &format!("tcp/127.0.0.1:{port}"),
            &format!("tcp/127.0.0.1:{}", port + 1),
        ],
    )
    .unwrap();
    let counter = crossed.clone();
    let _subscriber = tap
        .declare_subscriber(KEY)
        .callback(move |_: Sample| {
            counter.fetch_add(1, Ordering::Relaxed);
        })
        .wait()
        .unwrap();
    let p1 = process("p1", port, every);
    let p2 = process("p2", port, every);
    let (writer, reader) = (p1.join().unwrap(), p2.join().unwrap());
    for run in [&writer, &reader] {
        assert!(
            run.finished.report().errors.is_empty(),
            "{:?}",
            run.finished.report().errors
        );
    }
    let memory = reader.finished.memory(&reader.e).unwrap();
    let mut read = vec![None; memory.fresh.len()];
    for &(i, v, _) in &memory.got {
        read[i as usize] = Some(v);
    }
    let sent = writer.finished.link_stats(writer.down).unwrap();
    let received = reader.finished.link_stats(reader.down).unwrap();
    (read, crossed.load(Ordering::Relaxed), sent, received)
}

/// `e`'s reads over Zenoh against those in one process: the same value at
/// the same instant, but where it arrived after the read, which then took the
/// fallback (written after the previous read's value, before this one's) or
/// nothing new: at most a third of the reads. How many differ.
fn assert_as_in_one_process(read: &[Option<u64>], every: u64) -> usize {
    let reference = in_one_process(every, read.len());
    let mut late = 0;
    for (i, got) in read.iter().enumerate() {
        if *got == reference[i] {
            continue;
        }
        let previous = reference[..i].iter().rev().find_map(|r| *r);
        let fallback = matches!(
            (got, reference[i]),
            (Some(v), Some(r)) if *v < r && previous.is_none_or(|p| *v > p)
        );
        assert!(
            got.is_none() || fallback,
            "read {i}: {got:?}, in one process {:?}\nover Zenoh {read:?}\nin one process {reference:?}",
            reference[i]
        );
        late += 1;
    }
    assert!(
        late * 3 <= read.len(),
        "{late} of {} reads differ\nover Zenoh {read:?}\nin one process {reference:?}",
        read.len()
    );
    late
}

#[test]
fn a_1_ms_writer_read_every_50_ms_crosses_40_values_a_second_and_the_reads_are_as_in_one_process() {
    let (read, crossed, sent, received) = over_zenoh(17_470, 1);
    assert!(read.len() >= 55, "{} reads in 3 s", read.len());
    let late = assert_as_in_one_process(&read, 1);
    eprintln!(
        "reads={} differing={late} crossed={crossed} written={} withheld={} arrived_late={}",
        read.len(),
        sent.sent,
        sent.overwritten,
        received.late
    );
    // 3 s: about 120 values cross (a read's and its fallback), where every
    // write (about 3,000) crossed before.
    let reads = read.len() as u64;
    assert!(
        crossed <= 2 * reads + 2 && crossed + 10 >= 2 * reads,
        "{crossed} messages for {reads} reads"
    );
    assert!(sent.sent >= 2_900, "{sent:?}");
    assert!(sent.overwritten >= sent.sent - 2 * reads - 2, "{sent:?}");
}

#[test]
fn a_writer_that_writes_now_and_then_is_read_as_in_one_process() {
    // c writes every 7 ms: the value is held through the activations without
    // a write and goes at the last before each read.
    let (read, crossed, _, _) = over_zenoh(17_480, 7);
    assert!(read.len() >= 55, "{} reads in 3 s", read.len());
    let late = assert_as_in_one_process(&read, 7);
    eprintln!("reads={} differing={late} crossed={crossed}", read.len());
    assert!(crossed <= 2 * read.len() as u64 + 2, "{crossed} messages");
}
