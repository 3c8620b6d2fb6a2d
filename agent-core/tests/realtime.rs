//! The real-time executor runs the same systems as the deterministic one, on
//! threads against the wall clock: link semantics between threads, the world's
//! drivers together on one thread, every instant before the limit executed,
//! probes, stopping, errors, and what the OS granted. No test asserts a duration:
//! the machine's timing is not the code's.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

mod common;

use std::time::Duration;

use agent_core::*;
use common::*;

fn run(system: System, limit_ms: u64) -> Finished {
    RealTime::new(system, RtConfig::default())
        .start(Duration::from_millis(limit_ms))
        .unwrap()
        .join()
        .unwrap()
}

#[test]
fn a_queue_between_threads_delivers_every_value_in_order() {
    let p = pair(1, 1, 1, Policy::queue(1024), false);
    let f = run(p.system, 150);
    // Every instant before the limit runs, late or not (absolute deadlines catch
    // up): 0, 1, ..., 149 ms.
    assert_eq!(f.activations(p.c.id()), Some(150));
    assert_eq!(f.activations(p.e.id()), Some(150));
    let got: Vec<u64> = f.memory(&p.e).unwrap().got.iter().map(|g| g.1).collect();
    assert!(!got.is_empty());
    assert_eq!(
        got,
        (0..got.len() as u64).collect::<Vec<_>>(),
        "lossless and in order"
    );
    let s = f.link_stats(p.down).unwrap();
    assert_eq!(s.sent, 150);
    assert_eq!(s.delivered, got.len() as u64);
    assert_eq!(s.overflowed, 0);
    assert!(
        s.sent - s.delivered <= 1024,
        "the rest waits in the queue: {s:?}"
    );
    assert!(f.report().errors.is_empty(), "{:?}", f.report().errors);
}

#[test]
fn a_sample_link_between_threads_delivers_the_latest_value() {
    let p = pair(1, 3, 1, Policy::Sample, false);
    let f = run(p.system, 150);
    assert_eq!(f.activations(p.c.id()), Some(150));
    assert_eq!(f.activations(p.e.id()), Some(50));
    let got = &f.memory(&p.e).unwrap().got;
    assert!(!got.is_empty());
    for w in got.windows(2) {
        assert!(w[1].1 > w[0].1, "newer values only: {w:?}");
        assert!(w[1].2 > w[0].2, "stamps increase: {w:?}");
    }
    let s = f.link_stats(p.down).unwrap();
    assert_eq!(s.sent, 150);
    assert_eq!(s.delivered, got.len() as u64);
    // Each value sent was read, overwritten, or is still in the link at the
    // stop: at most two if e woke late for its last instant (one held, stamped
    // after that instant, and a newer one published after its last read).
    assert!(s.delivered + s.overwritten <= s.sent && s.sent <= s.delivered + s.overwritten + 2);
    assert!(s.overwritten > 0, "e reads every third value: {s:?}");
}

/// An idle subsystem `c` (every 5 ms) beside a receptor `R` and an effector `E`
/// (every 10 ms) sharing a rail: the system, `c` and `R`.
fn rail_system() -> (System, SubsystemHandle<Counter>, DriverHandle<Encoder>) {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let idle = Fsm::single(Behaviour::while_loop(
        "idle",
        Action::<Counter>::new(),
        "false",
    ))
    .unwrap();
    let c = b.subsystem(a, "c", ms(5), CounterMemory { n: 0, every: 1 }, idle);
    let encoder = b.driver(a, "R", ms(10), Encoder::default());
    b.driver(a, "E", ms(10), Motor);
    b.environment(Rail::default());
    (b.build().unwrap(), c, encoder)
}

#[test]
fn the_drivers_of_an_environment_share_one_thread_and_keep_their_order() {
    let (system, _, encoder) = rail_system();
    let f = run(system, 100);
    assert_eq!(f.environment::<Rail>().map(|r| r.position), Some(10.0));
    // As in the deterministic executor: the receptor senses the motor's step of
    // the same instant, although it was declared first.
    let sensed = &f.driver(&encoder).unwrap().sensed;
    assert_eq!(sensed, &(1..=10).map(f64::from).collect::<Vec<_>>());
    let threads: Vec<&str> = f.report().threads.iter().map(|t| t.name.as_str()).collect();
    assert_eq!(threads.len(), 2, "{threads:?}");
    assert!(
        threads.contains(&"world") && threads.contains(&"c"),
        "{threads:?}"
    );
    let r = f.report().node("R").unwrap();
    assert_eq!((r.thread.as_str(), r.activations), ("world", 10));
}

#[test]
fn probes_watch_a_running_system_and_a_stop_ends_it() {
    let p = pair(1, 1, 1, Policy::queue(8), false);
    let mut rt = RealTime::new(p.system, RtConfig::default());
    let counts = rt.probe(&p.c, |c| Some(c.memory.n));
    let running = rt.start(Duration::from_secs(60)).unwrap();
    let mut seen = Vec::new();
    while let Ok(n) = counts.recv_timeout(Duration::from_secs(10)) {
        seen.push(n);
        if n >= 20 {
            running.stop();
            break;
        }
    }
    let f = running.join().unwrap();
    assert_eq!(
        seen,
        (1..=20).collect::<Vec<_>>(),
        "one result per activation"
    );
    let runs = f.activations(p.c.id()).unwrap();
    assert!(
        (20..60_000).contains(&runs),
        "stopped long before the limit: {runs}"
    );
    assert_eq!(f.report().probe_dropped, 0);
}

#[test]
fn an_error_stops_every_thread_and_is_reported() {
    // c sends every millisecond into a queue of 2 that e empties every 10 ms: the
    // queue overflows within a few periods, and an overflow is an error.
    let p = pair(1, 10, 1, Policy::queue(2), false);
    let f = RealTime::new(p.system, RtConfig::default())
        .start(Duration::from_secs(60))
        .unwrap()
        .join()
        .unwrap();
    let report = f.report();
    assert_eq!(report.errors.len(), 1, "{:?}", report.errors);
    assert!(
        matches!(
            &report.errors[0],
            ExecError::Link(LinkError::QueueOverflow { bound: 2, .. })
        ),
        "{}",
        report.errors[0]
    );
    assert!(
        report.errors[0].to_string().contains("c.e.count"),
        "{}",
        report.errors[0]
    );
    assert!(f.activations(p.c.id()).unwrap() < 1000, "the run stopped");
    assert_eq!(f.link_stats(p.down).unwrap().overflowed, 1);
}

#[test]
fn threads_started_after_instant_zero_still_run_it() {
    // With no lead, every thread is spawned after the clock's instant zero (as
    // on a loaded machine with the default lead): each still runs every instant
    // from zero, catching up, and the drivers' rail moves once per instant.
    let (system, c, _) = rail_system();
    let config = RtConfig {
        lead: Duration::ZERO,
        ..RtConfig::default()
    };
    let f = RealTime::new(system, config)
        .start(Duration::from_millis(50))
        .unwrap()
        .join()
        .unwrap();
    assert_eq!(f.activations(c.id()), Some(10));
    assert_eq!(f.environment::<Rail>().map(|r| r.position), Some(5.0));
}

#[test]
fn what_the_os_grants_is_reported_and_the_run_goes_on_without_it() {
    let p = pair(1, 2, 1, Policy::Sample, false);
    let f = RealTime::new(p.system, RtConfig::realtime())
        .start(Duration::from_millis(50))
        .unwrap()
        .join()
        .unwrap();
    let report = f.report();
    assert!(report.errors.is_empty(), "{:?}", report.errors);
    assert_eq!(f.activations(p.c.id()), Some(50));
    for t in &report.threads {
        assert!(t.priority_asked.is_some(), "{t:?}");
        // A refusal is for the priority asked (this machine may not grant it).
        match &t.priority_refused {
            None => {}
            Some(Refused::Priority { priority, reason }) => {
                assert_eq!(Some(*priority), t.priority_asked, "{t:?}");
                assert!(!reason.is_empty(), "{t:?}");
            }
            Some(other) => panic!("{}: refused {other:?}", t.name),
        }
    }
    // The shorter period gets the higher priority.
    let asked = |name: &str| {
        report
            .threads
            .iter()
            .find(|t| t.name == name)
            .and_then(|t| t.priority_asked)
    };
    assert_eq!((asked("c"), asked("e")), (Some(80), Some(79)));
    assert!(report.memory_locked.is_some());
    let shown = report.to_string();
    assert!(
        shown.contains("SCHED_FIFO 80") || shown.contains("fallback"),
        "{shown}"
    );
    assert!(shown.contains("jit_p99"), "{shown}");
}

/// What one thread's observer saw, handed over when it is dropped.
#[derive(Debug, Default)]
struct Seen {
    thread: String,
    nodes: Vec<usize>,
    actions: Vec<usize>,
    transfers: Vec<TransferEvent>,
    reads: Vec<ReadEvent>,
}

struct PerThread {
    seen: Seen,
    out: std::sync::Arc<std::sync::Mutex<Vec<Seen>>>,
    /// Hold the thread this long after its first action (once), so that its
    /// next instants run late.
    stall: Duration,
}

impl Observer for PerThread {
    fn action(&mut self, e: &ActionEvent) {
        self.seen.actions.push(e.node);
        if !self.stall.is_zero() {
            std::thread::sleep(std::mem::take(&mut self.stall));
        }
    }
    fn transfer(&mut self, e: &TransferEvent, _value: &dyn ErasedPayload) {
        self.seen.transfers.push(*e);
    }
    fn read(&mut self, e: &ReadEvent) {
        self.seen.reads.push(*e);
    }
}

impl Drop for PerThread {
    fn drop(&mut self) {
        self.out
            .lock()
            .unwrap()
            .push(std::mem::take(&mut self.seen));
    }
}

/// A [`PerThread`] observer on each of `rt`'s threads (stalling as `stall`
/// says for the thread's name); what each saw, once the run is joined.
fn observe_each_thread(
    rt: &mut RealTime,
    stall: fn(&str) -> Duration,
) -> std::sync::Arc<std::sync::Mutex<Vec<Seen>>> {
    let out = std::sync::Arc::new(std::sync::Mutex::new(Vec::new()));
    let given = out.clone();
    rt.observe(move |thread, nodes| {
        Box::new(PerThread {
            seen: Seen {
                thread: thread.to_owned(),
                nodes: nodes.to_vec(),
                ..Seen::default()
            },
            out: given.clone(),
            stall: stall(thread),
        })
    });
    out
}

#[test]
fn each_thread_has_its_observer_which_sees_what_its_nodes_send_and_read() {
    let p = pair(1, 3, 1, Policy::Sample, false);
    let info = p.system.info().clone();
    let mut rt = RealTime::new(p.system, RtConfig::default());
    let out = observe_each_thread(&mut rt, |_| Duration::ZERO);
    let f = rt
        .start(Duration::from_millis(150))
        .unwrap()
        .join()
        .unwrap();
    // Every observer was dropped on its thread before `join` returned.
    let mut seen = std::mem::take(&mut *out.lock().unwrap());
    seen.sort_by(|a, b| a.thread.cmp(&b.thread));
    let threads: Vec<(&str, &[usize])> = seen
        .iter()
        .map(|s| (s.thread.as_str(), s.nodes.as_slice()))
        .collect();
    assert_eq!(threads, [("c", &[0][..]), ("e", &[1][..])]);
    for s in &seen {
        // Only its own nodes' actions, values sent and values read.
        assert!(s.actions.iter().all(|n| s.nodes.contains(n)), "{s:?}");
        assert!(
            s.transfers
                .iter()
                .all(|t| s.nodes.contains(&info.links[t.link].from))
        );
        assert!(
            s.reads
                .iter()
                .all(|r| s.nodes.contains(&info.links[r.link].to))
        );
    }
    let (c, e) = (&seen[0], &seen[1]);
    assert_eq!(c.actions.len() as u64, f.activations(p.c.id()).unwrap());
    assert_eq!(e.actions.len() as u64, f.activations(p.e.id()).unwrap());
    // Each value e read is one c sent (by its stamp), read at or after its
    // instant at one of e's instants, newer than the one before.
    let down = p.down.index();
    let sent: Vec<Stamp> = c
        .transfers
        .iter()
        .filter(|t| t.link == down)
        .map(|t| t.stamp)
        .collect();
    let read: Vec<&ReadEvent> = e.reads.iter().filter(|r| r.link == down).collect();
    let s = f.link_stats(p.down).unwrap();
    assert_eq!(sent.len() as u64, s.sent);
    assert_eq!(read.len() as u64, s.delivered);
    assert!(!read.is_empty());
    for r in &read {
        assert!(sent.contains(&r.stamp), "{r:?}");
        assert!(r.time >= r.stamp.time, "{r:?}");
        assert_eq!(r.time.as_nanos() % 3_000_000, 0, "{r:?}");
    }
    for w in read.windows(2) {
        assert!(w[1].stamp.iteration > w[0].stamp.iteration, "{w:?}");
    }
}

#[test]
fn a_thread_running_late_never_reads_a_value_stamped_after_its_instant() {
    // e (every 3 ms) stalls 12 ms after its first action; its instants 3, 6, 9
    // and 12 then run at once, when c (every 1 ms) has already sent values
    // stamped up to about 12 ms. Each activation takes only what was sent at or
    // before its own instant.
    for policy in [Policy::Sample, Policy::queue(64)] {
        let p = pair(1, 3, 1, policy, false);
        let mut rt = RealTime::new(p.system, RtConfig::default());
        let out = observe_each_thread(&mut rt, |thread| {
            if thread == "e" {
                Duration::from_millis(12)
            } else {
                Duration::ZERO
            }
        });
        let f = rt.start(Duration::from_millis(60)).unwrap().join().unwrap();
        assert_eq!(f.activations(p.e.id()), Some(20), "{policy:?}");
        let seen = std::mem::take(&mut *out.lock().unwrap());
        let e = seen.iter().find(|s| s.thread == "e").unwrap();
        let down = p.down.index();
        let read: Vec<&ReadEvent> = e.reads.iter().filter(|r| r.link == down).collect();
        assert!(read.len() >= 5, "{policy:?}: {read:?}");
        for r in &read {
            assert!(r.time >= r.stamp.time, "{policy:?}: {r:?}");
        }
        for w in read.windows(2) {
            assert!(w[1].stamp.iteration > w[0].stamp.iteration, "{w:?}");
        }
        let s = f.link_stats(p.down).unwrap();
        assert_eq!(s.delivered, read.len() as u64, "{policy:?}");
        if policy == Policy::Sample {
            // Each value was read, overwritten (in the link or while held), or
            // is still in the link at the stop: at most two, one held by the
            // reader (stamped after its last instant) and a newer one published
            // after its last read. No value is counted twice.
            let accounted = s.delivered + s.overwritten;
            assert!(accounted <= s.sent, "{s:?}");
            assert!(s.sent - accounted <= 2, "{s:?}");
        }
    }
}

/// A wire message of `value` for an inbox of `fingerprint`: the header, then
/// the value's postcard bytes (what a bridge from another middleware writes).
fn wire(fingerprint: u64, epoch: u64, seq: u64, at: Time, value: u64) -> Vec<u8> {
    let mut message = Vec::new();
    WireHeader {
        fingerprint,
        epoch,
        seq,
        stamp: Stamp::new(0, at),
    }
    .write(&mut message);
    postcard::to_extend(&value, message).unwrap()
}

#[test]
fn a_fed_input_takes_the_feeds_values_beside_its_links_in_order_and_neither_starves() {
    // c sends every millisecond on a queue; a feeder from outside the system
    // sends 1000, 1001, ... into the same input, all at once, while it runs.
    let p = pair(1, 1, 1, Policy::queue(1024), false);
    let mut rt = RealTime::new(p.system, RtConfig::default());
    let inbox = rt.feed(p.down, "outside/count").unwrap();
    assert_eq!(
        rt.feed(p.down, "again").unwrap_err().to_string(),
        "link `c.e.count -> e.c.count` cannot be fed from outside the system: the link is fed already"
    );
    assert_eq!(inbox.key(), "outside/count");
    let running = rt.start(Duration::from_millis(300)).unwrap();
    std::thread::sleep(Duration::from_millis(50));
    for k in 0..20 {
        inbox.deliver(&wire(inbox.fingerprint(), 7, k + 1, Time::ZERO, 1000 + k));
    }
    let f = running.join().unwrap();
    let got: Vec<u64> = f.memory(&p.e).unwrap().got.iter().map(|g| g.1).collect();
    let (fed, own): (Vec<u64>, Vec<u64>) = got.iter().partition(|v| **v >= 1000);
    assert_eq!(
        fed,
        (1000..1020).collect::<Vec<_>>(),
        "every fed value, in order"
    );
    assert_eq!(own, (0..own.len() as u64).collect::<Vec<_>>(), "c's too");
    // Taken in turn: the first fed values arrive between c's, not after them.
    let first_fed = got.iter().position(|v| *v >= 1000).unwrap();
    let last_fed = got.iter().rposition(|v| *v >= 1000).unwrap();
    let between = got[first_fed..=last_fed]
        .iter()
        .filter(|v| **v < 1000)
        .count();
    assert!(
        between >= 19,
        "c's values alternate with the feed's: {got:?}"
    );
    let s = inbox.stats();
    assert_eq!((s.delivered, s.refused), (20, 0), "{s:?}");
    assert_eq!(f.link_stats(p.down).unwrap().delivered, own.len() as u64);
    assert!(f.report().errors.is_empty(), "{:?}", f.report().errors);
}

#[test]
fn a_fed_value_from_its_future_or_of_another_type_is_not_taken() {
    // Refused values are errors of e's reads: reported, and the run goes on.
    let p = pair(1, 1, 1_000_000, Policy::queue(8), false);
    let config = RtConfig {
        exec: ExecConfig {
            on_error: OnError::Continue,
            ..ExecConfig::default()
        },
        ..RtConfig::default()
    };
    let mut rt = RealTime::new(p.system, config);
    let inbox = rt.feed(p.down, "outside/count").unwrap();
    let running = rt.start(Duration::from_millis(200)).unwrap();
    std::thread::sleep(Duration::from_millis(20));
    // Another type's fingerprint: refused, and reported at e's read.
    inbox.deliver(&wire(inbox.fingerprint() ^ 1, 7, 1, Time::ZERO, 5));
    inbox.deliver(&wire(inbox.fingerprint(), 7, 1, Time::ZERO, 1001));
    // Stamped an hour ahead: refused at the read, never taken.
    inbox.deliver(&wire(
        inbox.fingerprint(),
        7,
        2,
        Time::from_nanos(3_600_000_000_000),
        1002,
    ));
    let f = running.join().unwrap();
    let got: Vec<u64> = f.memory(&p.e).unwrap().got.iter().map(|g| g.1).collect();
    assert!(got.contains(&1001), "{got:?}");
    assert!(!got.contains(&5) && !got.contains(&1002), "{got:?}");
    assert_eq!(inbox.stats().refused, 2);
    let errors: Vec<String> = f.report().errors.iter().map(ToString::to_string).collect();
    assert_eq!(errors.len(), 2, "{errors:?}");
    assert!(errors[0].contains("outside/count"), "{errors:?}");
}

#[test]
fn a_start_whose_agreement_fails_ends_every_thread_and_says_why() {
    let p = pair(1, 3, 1, Policy::Sample, false);
    let started = RealTime::new(p.system, RtConfig::default())
        .start_when(Duration::from_secs(60), || Err("no other process answered"));
    // Every thread had built its nodes and waited at the gate: closed, they
    // end without running an instant (a deadlock would hang here).
    match started {
        Err(RtError::Sync(why)) => assert!(why.contains("no other process"), "{why}"),
        other => panic!("expected a sync error, got {other:?}"),
    }
}
