//! Unit tests of a run's watcher: plans `c1` took from another sender than
//! `a2` (ROS 2) are counted and judged; a listening run takes a plan fed into
//! `c1`'s input from outside the system, executes and acknowledges it.

use std::time::{Duration, Instant};

use embodied::app::Watcher;
use embodied::{Probes, RealTime, RtConfig, Stamp, Time, WireHeader};

use super::*;
use crate::mission::Mission;
use crate::payload::{Execution, Plan, Point2};
use crate::world::WorldConfig;

fn config(mission: &str) -> RexConfig {
    let world = WorldConfig::shipped().expect("the shipped world loads");
    let mission = Mission::shipped(mission).expect("the shipped mission loads");
    RexConfig::new(world, mission)
}

fn at(t: f64) -> Time {
    Time::from_nanos((t * 1e9).round() as u64)
}

/// e11 follows fragment `(plan, 0)` from `(0, 0)` to `(x_end, 0)` over
/// `[t0, t0 + 1)` (the truth `off` metres beside the reference), then
/// reports `outcome` and is idle.
fn drive(plan: u32, t0: f64, x_end: f64, off: f64, outcome: Execution) -> Vec<Seen> {
    let steps = 20;
    let mut seen = Vec::new();
    for k in 0..=steps {
        let t = t0 + f64::from(k) * 0.05;
        let x = x_end * f64::from(k) / f64::from(steps);
        let last = k == steps;
        seen.push(Seen::Truth {
            at: at(t),
            pose: [x, off, 0.0],
        });
        seen.push(Seen::E11 {
            t: at(t),
            sample: Sample {
                t,
                reference: (!last).then_some([x, 0.0, 0.0, 0.5, 0.0]),
                executing: !last,
                fragment: (!last).then_some((plan, 0)),
                estimate: [x, 0.0, 0.0],
                ..Sample::default()
            },
            event: last.then(|| PlanOutcome {
                plan,
                epoch: 0,
                result: outcome.clone(),
            }),
            idle: last,
        });
    }
    seen
}

fn took(plan: u32, end: Option<(f64, f64)>) -> Seen {
    Seen::C1 {
        behaviour: 1,
        took: Some((plan, end.map(|(x, y)| Point2 { x, y }))),
    }
}

fn acked(t: f64, plan: u32, status: AckStatus) -> Seen {
    Seen::C2 {
        t: at(t),
        acks: vec![Ack { plan, status }],
        halted: false,
        sent: 0,
    }
}

#[test]
fn a_listening_run_counts_and_judges_the_plans_c1_took_from_elsewhere() {
    let config = config(Mission::LISTEN);
    let mut watch = MissionWatch::new(&config, Duration::MAX, |_: Progress<'_>| {});
    // Plan 7 from ROS 2: taken, driven to its end, acknowledged, reached.
    watch.see(took(7, Some((1.0, 0.0))));
    let reached = Execution::Reached { error_m: 0.01 };
    for s in drive(7, 0.0, 1.0, 0.002, reached.clone()) {
        watch.see(s);
    }
    watch.see(acked(0.9, 7, AckStatus::Done));
    // Never ended by the mission: a listening run goes to its limit.
    assert!(!watch.ended(false));
    // Plan 8: the platform stops 0.3 m short of its end, yet e11 says reached.
    watch.see(took(8, Some((1.3, 0.0))));
    for s in drive(8, 2.0, 1.0, 0.002, reached) {
        watch.see(s);
    }
    watch.see(acked(2.9, 8, AckStatus::Done));
    // Plan 9, off the map: refused as taken (no points kept).
    watch.see(took(9, None));
    watch.see(acked(3.5, 9, AckStatus::Refused("off the map".into())));
    // A report of plan 7 again (c1 restarted and took it again): counted once.
    watch.see(took(7, Some((1.0, 0.0))));
    assert!(!watch.ended(false));
    assert!(!watch.ended(true), "the run's end is its limit's");
    let out = watch.outcome(4.0, 4.0);
    assert!(out.completed, "every plan answered, e11 idle");
    assert_eq!(out.plans, 3);
    let foreign: Vec<u32> = out.foreign.iter().map(|f| f.0).collect();
    assert_eq!(foreign, [7, 8, 9]);
    let verdicts: Vec<(u32, bool, &Verdict)> = out
        .reports
        .iter()
        .map(|r| (r.plan, r.foreign, &r.verdict))
        .collect();
    assert!(
        matches!(
            verdicts[..],
            [
                (7, true, Verdict::Achieved),
                (8, true, Verdict::FalseSuccess(_)),
                (9, true, Verdict::Failed(_)),
            ]
        ),
        "{:#?}",
        out.reports
    );
    // Judged against the truth: plan 7 ended 2 mm from its last point,
    // plan 8 0.3 m from its own (not plan 7's).
    let end = |k: usize| out.reports[k].end_error_m.unwrap_or(f64::NAN);
    assert!((end(0) - 0.002).abs() < 1e-9, "{:?}", out.reports[0]);
    assert!((end(1) - 0.3).abs() < 1e-4, "{:?}", out.reports[1]);
    assert!((out.reports[0].max_tracking_m - 0.002).abs() < 1e-9);
    assert!(
        out.reports[0]
            .to_string()
            .starts_with("plan 7 (not a2's): achieved")
    );
    assert!(
        out.summary_line()
            .starts_with("mission=listen plans_acked=1/3 "),
        "{}",
        out.summary_line()
    );
    assert!(!out.succeeded());
}

#[test]
fn a_listening_run_with_a_plan_unanswered_or_none_at_all() {
    let config = config(Mission::LISTEN);
    // None taken: every plan it got (none) was executed: a success, 0/0.
    let mut watch = MissionWatch::new(&config, Duration::MAX, |_: Progress<'_>| {});
    watch.see(Seen::E11 {
        t: at(0.05),
        sample: Sample::default(),
        event: None,
        idle: true,
    });
    watch.ended(true);
    let out = watch.outcome(1.0, 1.0);
    assert!(out.completed && out.succeeded(), "{}", out.summary_line());
    assert!(
        out.summary_line()
            .starts_with("mission=listen plans_acked=0/0 ")
    );
    // Taken, and still executing when the run ended: not complete, unfinished.
    let mut watch = MissionWatch::new(&config, Duration::MAX, |_: Progress<'_>| {});
    watch.see(took(1, Some((1.0, 0.0))));
    watch.see(Seen::E11 {
        t: at(0.05),
        sample: Sample {
            fragment: Some((1, 0)),
            executing: true,
            ..Sample::default()
        },
        event: None,
        idle: false,
    });
    watch.ended(true);
    let out = watch.outcome(1.0, 1.0);
    assert!(!out.completed && !out.succeeded());
    assert_eq!(out.plans, 1);
    assert!(matches!(out.reports[0].verdict, Verdict::Unfinished(_)));
}

#[test]
fn a_plan_from_elsewhere_after_a_mission_is_judged_with_the_missions() {
    // The square's two plans are a2's (ids 1 and 2); plan 3 came from ROS 2.
    let config = config("square");
    let mut watch = MissionWatch::new(&config, Duration::MAX, |_: Progress<'_>| {});
    for id in [1, 2] {
        watch.see(took(id, Some((0.0, 0.0))));
    }
    watch.see(took(3, Some((1.0, 0.0))));
    for s in drive(3, 0.0, 1.0, 0.0, Execution::Reached { error_m: 0.0 }) {
        watch.see(s);
    }
    watch.see(acked(1.5, 3, AckStatus::Done));
    watch.ended(true);
    let out = watch.outcome(2.0, 2.0);
    assert_eq!(out.plans, 3, "the mission's two and one from elsewhere");
    let judged: Vec<(u32, bool)> = out.reports.iter().map(|r| (r.plan, r.foreign)).collect();
    assert_eq!(judged, [(1, false), (2, false), (3, true)]);
    assert_eq!(out.reports[0].verdict, Verdict::NotSent);
    assert_eq!(
        out.reports[2].verdict,
        Verdict::Achieved,
        "{:?}",
        out.reports[2]
    );
    assert!(!out.completed, "a2 did not end its mission");
}

/// Whether the watcher has plan `id`'s final acknowledgement and outcome.
fn answered<P>(w: &MissionWatch<P>, id: u32) -> bool {
    let out = &w.out;
    out.acks.iter().any(|(_, a)| a.plan == id && a.ready())
        && out.outcomes.iter().any(|(_, o)| o.plan == id)
}

/// The name of the link from `c2` into `c1`'s input `c2.desired_plan`.
const PLAN_LINK: &str = "c2.c1.desired_plan -> c1.c2.desired_plan";

/// The wire message a sender from outside the system (the ROS 2 bridge)
/// delivers to the inbox of `fingerprint`: the header, then the plan's
/// postcard bytes.
fn wire(fingerprint: u64, seq: u64, at: Time, plan: &Plan) -> Vec<u8> {
    let mut message = Vec::new();
    WireHeader {
        fingerprint,
        epoch: 1,
        seq,
        stamp: Stamp::new(0, at),
    }
    .write(&mut message);
    postcard::to_extend(plan, message).expect("a plan encodes")
}

#[test]
fn a_listening_rex_executes_and_acknowledges_a_plan_fed_into_c1_from_outside() {
    let mut config = config(Mission::LISTEN);
    // As in tests/realtime.rs: the camera and the VO are too slow in a test
    // build to keep their periods.
    config.visual_odometry = false;
    let (system, h) = build(&config).expect("Rex builds");
    let link = system
        .info()
        .links
        .iter()
        .position(|l| l.name == PLAN_LINK)
        .and_then(|i| embodied::LinkId::of(system.info(), i))
        .expect("c1's input from c2 has a link");
    let (mut probes, seen) = Probes::new(1 << 16);
    install_probes(&mut probes, &h, &|_| true);
    let mut rt = RealTime::new(
        system,
        RtConfig {
            exec: config.exec,
            ..RtConfig::default()
        },
    );
    rt.watch(probes);
    let inbox = rt.feed(link, "rex/plan").expect("c1's input can be fed");
    let limit = Duration::from_secs(60);
    let running = rt.start(limit).expect("the run starts");
    let started = Instant::now();
    let mut watch = MissionWatch::new(&config, Duration::MAX, |_: Progress<'_>| {});
    // Once e11 has an estimate, a plan numbered as no a2 would (any id is
    // taken first), stamped with the run's time now.
    std::thread::sleep(Duration::from_millis(500));
    let plan = Plan {
        id: 41,
        points: vec![Point2 { x: 1.0, y: 0.0 }, Point2 { x: 1.5, y: 0.5 }],
        first: 0,
    };
    let now = Time::ZERO.saturating_add(started.elapsed());
    inbox.deliver(&wire(inbox.fingerprint(), 1, now, &plan));
    // Until c1 acknowledged it done and e11 reported its outcome.
    while !answered(&watch, 41) && started.elapsed() < limit - Duration::from_secs(2) {
        for s in seen.try_iter() {
            watch.see(s);
        }
        assert!(!watch.ended(false), "a listening run ends at its limit");
        std::thread::sleep(Duration::from_millis(20));
    }
    // A moment for e11 to be seen idle.
    std::thread::sleep(Duration::from_millis(300));
    running.stop();
    let finished = running.join().expect("the run ends");
    for s in seen.try_iter() {
        watch.see(s);
    }
    for s in last_reports(&finished, &h) {
        watch.see(s);
    }
    watch.ended(true);
    let out = watch.outcome(
        started.elapsed().as_secs_f64(),
        finished.report().last_instant.as_secs_f64(),
    );
    let report = finished.report();
    assert_eq!(
        out.foreign,
        [(41, Some(Point2 { x: 1.5, y: 0.5 }))],
        "{}\n{report}",
        out.summary_line()
    );
    assert!(
        out.summary_line()
            .starts_with("mission=listen plans_acked=1/1 "),
        "{}\n{:#?}\n{report}",
        out.summary_line(),
        out.reports
    );
    assert!(out.completed && out.succeeded(), "{}", out.summary_line());
    let ack = out.reports[0].ack.clone();
    assert_eq!(ack, Some(AckStatus::Done));
    assert!(matches!(
        out.reports[0].outcome,
        Some((_, Execution::Reached { .. }))
    ));
    assert_eq!(out.counters.plans_out_of_sequence, 0);
    let s = inbox.stats();
    assert_eq!((s.delivered, s.refused), (1, 0), "{s:?}");
    assert_eq!(report.error_count, 0, "{report}");
    // a2 sent nothing and did not halt.
    let c2 = finished.memory(&h.c2).expect("c2 ran here");
    assert_eq!(c2.next, 0);
    assert!(c2.acks.iter().any(|a| a.plan == 41 && a.ready()));
    assert!(c2.answered.is_empty() && c2.done.is_empty());
}
