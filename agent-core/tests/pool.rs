//! The real-time executor's worker pool ([`Threading::Pool`]): where each
//! subsystem runs (a worker per core and period, a bounded number of them),
//! in which order a worker runs its subsystems, that every subsystem keeps
//! every instant of its period, and that a subsystem that overruns delays but
//! does not starve the others. No test asserts a duration: the machine's
//! timing is not the code's.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

mod common;

use std::collections::BTreeMap;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use agent_core::*;
use common::*;

/// Per thread: its name and the (instant, node) of every action it ran, in
/// the order it ran them; one observer per thread, handed over when dropped.
type Actions = Arc<Mutex<BTreeMap<String, Vec<(Time, usize)>>>>;

struct Log {
    thread: String,
    actions: Vec<(Time, usize)>,
    out: Actions,
    /// Node whose every `every`-th action stalls the thread this long.
    stall: Option<(usize, u64, Duration)>,
}

impl Observer for Log {
    fn action(&mut self, e: &ActionEvent) {
        self.actions.push((e.time, e.node));
        if let Some((node, every, d)) = self.stall
            && e.node == node
            && e.iteration.is_multiple_of(every)
        {
            std::thread::sleep(d);
        }
    }
}

impl Drop for Log {
    fn drop(&mut self) {
        let actions = std::mem::take(&mut self.actions);
        self.out
            .lock()
            .unwrap()
            .insert(self.thread.clone(), actions);
    }
}

fn logged(rt: &mut RealTime, stall: Option<(usize, u64, Duration)>) -> Actions {
    let out: Actions = Arc::default();
    let given = out.clone();
    rt.observe(move |thread, _| {
        Box::new(Log {
            thread: thread.to_owned(),
            actions: Vec::new(),
            out: given.clone(),
            stall,
        })
    });
    out
}

fn pool(cores: u16) -> RtConfig {
    RtConfig {
        threading: Threading::Pool { cores, pin: false },
        ..RtConfig::default()
    }
}

#[test]
fn a_pool_runs_one_worker_per_core_and_period_and_deals_the_agents_over_the_cores() {
    let p = pairs(6, 2, 4);
    let mut rt = RealTime::new(p.system, pool(2));
    let actions = logged(&mut rt, None);
    let f = rt.start(Duration::from_millis(60)).unwrap().join().unwrap();
    let report = f.report();
    // 12 subsystems at 2 periods on 2 cores: 4 workers.
    let mut threads: Vec<&str> = report.threads.iter().map(|t| t.name.as_str()).collect();
    threads.sort_unstable();
    assert_eq!(
        threads,
        ["core0@2ms", "core0@4ms", "core1@2ms", "core1@4ms"]
    );
    // Each agent (a pair) to the core with the fewest subsystems so far, its
    // two subsystems together: the link between them stays on one core.
    let on = |name: &str| report.node(name).unwrap().thread.as_str();
    for i in 0..6 {
        assert_eq!(on(&format!("c{i}")), format!("core{}@2ms", i % 2));
        assert_eq!(on(&format!("e{i}")), format!("core{}@4ms", i % 2));
    }
    // Every instant of every subsystem ran, and the queues between workers
    // lost nothing.
    for (c, e) in p.cs.iter().zip(&p.es) {
        assert_eq!(f.activations(c.id()), Some(30));
        assert_eq!(f.activations(e.id()), Some(15));
        let got: Vec<u64> = f.memory(e).unwrap().got.iter().map(|g| g.1).collect();
        assert_eq!(got, (0..got.len() as u64).collect::<Vec<_>>());
        // One value a read, a read every other value sent.
        assert!(got.len() >= 10, "{} values in 15 reads", got.len());
    }
    // A worker runs its subsystems in declaration order, every instant, on
    // their nominal instants.
    let actions = actions.lock().unwrap();
    assert_eq!(actions.len(), 4);
    for (thread, seen) in actions.iter() {
        let period = if thread.ends_with("@2ms") { 2 } else { 4 };
        let mut by_instant: BTreeMap<Time, Vec<usize>> = BTreeMap::new();
        for (t, node) in seen {
            by_instant.entry(*t).or_default().push(*node);
        }
        let instants: Vec<Time> = by_instant.keys().copied().collect();
        let expected: Vec<Time> = (0..60 / period).map(|k| t_ms(k * period)).collect();
        assert_eq!(instants, expected, "{thread}");
        let first = &by_instant[&Time::ZERO];
        assert_eq!(first.len(), 3, "{thread}: {first:?}");
        assert!(first.is_sorted(), "{thread}: declaration order {first:?}");
        assert!(by_instant.values().all(|n| n == first), "{thread}");
    }
}

#[test]
fn a_pool_has_a_bounded_number_of_workers_however_many_subsystems() {
    let p = pairs(150, 5, 10);
    let f = RealTime::new(p.system, pool(2))
        .start(Duration::from_millis(40))
        .unwrap()
        .join()
        .unwrap();
    assert_eq!(f.report().threads.len(), 4, "{:?}", f.report().threads);
    for (c, e) in p.cs.iter().zip(&p.es) {
        assert_eq!(f.activations(c.id()), Some(8));
        assert_eq!(f.activations(e.id()), Some(4));
    }
    assert!(f.report().errors.is_empty(), "{:?}", f.report().errors);
}

#[test]
fn a_subsystem_that_overruns_delays_but_does_not_starve_the_others_of_its_worker() {
    // One core: the four c's share a worker; c1 stalls 6 ms (three of its
    // periods) at every 10th action.
    let p = pairs(4, 2, 4);
    let stalled = p.cs[1].id().index();
    let mut rt = RealTime::new(p.system, pool(1));
    let actions = logged(&mut rt, Some((stalled, 10, Duration::from_millis(6))));
    let f = rt
        .start(Duration::from_millis(100))
        .unwrap()
        .join()
        .unwrap();
    let report = f.report();
    assert_eq!(report.threads.len(), 2);
    assert!(report.node("c1").unwrap().overruns >= 5, "{report}");
    // Every subsystem ran every one of its instants, in order, none skipped:
    // the ones after c1 on its worker late, not lost.
    for (c, e) in p.cs.iter().zip(&p.es) {
        assert_eq!(f.activations(c.id()), Some(50));
        assert_eq!(f.activations(e.id()), Some(25));
    }
    let actions = actions.lock().unwrap();
    let c3 = p.cs[3].id().index();
    let seen: Vec<Time> = actions["core0@2ms"]
        .iter()
        .filter(|(_, n)| *n == c3)
        .map(|(t, _)| *t)
        .collect();
    assert_eq!(seen, (0..50).map(|k| t_ms(2 * k)).collect::<Vec<_>>());
    // c3 ran after c1 stalled: its response at those instants includes the
    // stall.
    assert!(
        report.node("c3").unwrap().response.max >= Duration::from_millis(6),
        "{report}"
    );
}

#[test]
fn one_thread_per_subsystem_remains_an_option() {
    let p = pairs(3, 2, 4);
    let config = RtConfig {
        threading: Threading::PerSubsystem,
        ..RtConfig::default()
    };
    let f = RealTime::new(p.system, config)
        .start(Duration::from_millis(20))
        .unwrap()
        .join()
        .unwrap();
    let mut threads: Vec<&str> = f.report().threads.iter().map(|t| t.name.as_str()).collect();
    threads.sort_unstable();
    assert_eq!(threads, ["c0", "c1", "c2", "e0", "e1", "e2"]);
    for n in &f.report().nodes {
        assert_eq!(n.thread, n.name);
    }
    assert!(f.report().threads.iter().all(|t| t.core.is_none()));
}

#[cfg(target_os = "linux")]
#[test]
fn pinned_workers_run_on_the_cpus_the_process_may_use() {
    let p = pairs(2, 2, 4);
    let config = RtConfig {
        threading: Threading::pinned(2),
        ..RtConfig::default()
    };
    let f = RealTime::new(p.system, config)
        .start(Duration::from_millis(20))
        .unwrap()
        .join()
        .unwrap();
    let report = f.report();
    assert_eq!(report.threads.len(), 4);
    let allowed = std::thread::available_parallelism().unwrap().get();
    let cpus: std::collections::BTreeSet<usize> = report
        .threads
        .iter()
        .map(|t| {
            assert!(t.pin_refused.is_none(), "{report}");
            t.pinned_to.expect("every worker pinned")
        })
        .collect();
    // Two cores asked: two CPUs, or one if the process may use one only.
    assert_eq!(cpus.len(), allowed.min(2), "{report}");
    assert!(report.to_string().contains("pinned to CPU"), "{report}");
}
