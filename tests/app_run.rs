//! A run driven by the program (`embodied::app::Watched::new`), not by the
//! command line: the tank's mission in the deterministic executor to its end
//! rule, the filter's estimate paired with the tank's true level at each of
//! its activations (`Pairs`), and a real-time run recorded without a word on
//! standard output (`Watched::realtime_recorded`), each concluded by
//! `Ran::conclude`.

#![allow(clippy::expect_used, reason = "a failing expect is a failing test")]

#[path = "../examples/tank/agent.rs"]
mod agent;

use std::time::Duration;

use agent::{Order, Tank, build};
use embodied::app::{End, Ended, Pairs, Watched, Watcher};
use embodied::record::RecordOptions;
use embodied::{ExecConfig, NoObserver, RtConfig, Time};

/// What the probes report: the operator's acknowledgements so far, the
/// filter's estimate, the tank's true level.
enum Seen {
    Acks(usize),
    Estimate(Time, f64),
    Level(Time, f64),
}

/// Counts acknowledgements and measures the filter's error against the
/// truth of the same instant.
#[derive(Default)]
struct Filtered {
    acks: usize,
    pairs: Pairs<f64, f64>,
    paired: usize,
    unpaired: usize,
    worst: f64,
}

impl Watcher<Seen> for Filtered {
    fn see(&mut self, seen: Seen) {
        match seen {
            Seen::Acks(n) => self.acks = n,
            Seen::Estimate(t, level) => self.pairs.sample(t, level),
            Seen::Level(t, level) => self.pairs.reference(t, level),
        }
    }

    fn ended(&mut self, finished: bool) -> bool {
        for (_, estimate, truth) in self.pairs.take(finished) {
            match truth {
                Some(truth) => {
                    self.paired += 1;
                    self.worst = self.worst.max((estimate - truth).abs());
                }
                None => self.unpaired += 1,
            }
        }
        false
    }
}

fn mission() -> Vec<Order> {
    vec![Order { id: 1, level: 1.0 }, Order { id: 2, level: 0.5 }]
}

/// `run` with the tank's probes on it: the operator's acknowledgements, the
/// filter's estimate and the tank's level.
fn probe(run: &mut Watched<'_, Seen>, plant: &agent::Plant) {
    run.probes
        .subsystem(&plant.operator, |p| Some(Seen::Acks(p.memory.acks.len())))
        .subsystem(&plant.filter, |p| {
            p.memory.estimate.map(|e| Seen::Estimate(p.time, e))
        })
        .environment(|t, tank: &Tank| Some(Seen::Level(t, tank.level)));
}

#[test]
fn a_program_runs_the_tank_to_its_end_and_pairs_estimates_with_the_truth() {
    let (system, plant) = build(mission(), 0.2, 3).expect("the tank builds");
    let mut watcher = Filtered::default();
    let mut run = Watched::new(&mut watcher, Duration::from_secs(600));
    run.end = End::halted(["c2"]);
    probe(&mut run, &plant);
    let (ran, NoObserver) = run
        .simulate(system, ExecConfig::default(), NoObserver)
        .expect("the tank runs");
    ran.conclude(&mut watcher, []);
    assert_eq!(ran.ended, Ended::Rule("c2 halted".into()));
    assert!(ran.finished.report().last_instant < Time::from_nanos(600_000_000_000));
    assert_eq!(watcher.acks, 2, "both orders acknowledged");
    // Every estimate has the truth of its instant (the gauge and the pump
    // share the tank), and the filter follows it.
    assert!(watcher.paired > 100, "{} paired", watcher.paired);
    assert_eq!(watcher.unpaired, 0);
    assert!(watcher.worst < 0.2, "estimate off by {} m", watcher.worst);
}

#[test]
fn a_program_records_a_real_time_run_quietly() {
    let (system, plant) = build(mission(), 0.2, 3).expect("the tank builds");
    let file = std::env::temp_dir().join(format!("app-run-{}.mcap", std::process::id()));
    let mut watcher = Filtered::default();
    let mut run = Watched::new(&mut watcher, Duration::from_millis(500));
    probe(&mut run, &plant);
    let (ran, summary) = run
        .realtime_recorded(
            system,
            RtConfig::default(),
            Some((&file, RecordOptions::default())),
        )
        .expect("the tank runs in real time");
    ran.conclude(&mut watcher, []);
    assert_eq!(ran.ended, Ended::Limit);
    let summary = summary.expect("a recording was asked for");
    assert!(summary.messages > 0 && summary.channels > 0, "{summary:?}");
    assert!(std::fs::metadata(&file).is_ok_and(|m| m.len() > 0));
    assert!(watcher.paired > 0, "the threads' reports were paired");
    std::fs::remove_file(&file).ok();
    // Without a file, nothing is recorded.
    let (system, _) = build(mission(), 0.2, 3).expect("the tank builds");
    let mut quiet = embodied::app::Quiet;
    let run = Watched::<Seen>::new(&mut quiet, Duration::from_millis(100));
    let (_, summary) = run
        .realtime_recorded(system, RtConfig::default(), None)
        .expect("the tank runs in real time");
    assert!(summary.is_none());
}
