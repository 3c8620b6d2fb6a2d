//! Unit tests of `e11`: the fragments' schedule (`steps`, `notify`, `ready`), the
//! safety monitor's stops and epochs, and each plan's outcome.

use super::*;
use crate::model::{Friction, PlatformParams, SlipParams};
use embodied::{Stamp, Time};

fn fragment(index: u32, x0: f64, n: usize) -> Fragment {
    Fragment {
        plan: 1,
        index,
        dt: 0.05,
        states: (0..=n)
            .map(|k| [x0 + 0.01 * k as f64, 0.0, 0.0, 0.2, 0.0])
            .collect(),
        ..Fragment::default()
    }
}

/// e11's memory with the baseline pair (backstepping, EKF), 50 ms steps and the
/// default safety limits.
fn memory() -> E11Memory {
    let params = PlatformParams::peer_default();
    E11Memory::new(
        TrackerKind::Backstepping
            .build(params.clone(), 0.05)
            .unwrap(),
        EstimatorKind::Ekf
            .build(params, SlipParams::NOMINAL, Friction::CONCRETE, 0.05, 0.01)
            .unwrap(),
        0.05,
        0.03,
    )
}

/// What e11 did at each iteration (ready sent, the fragment whose reference it
/// followed), and the fragments it rejected.
fn run(
    deliveries: &[(u64, Fragment, u32, u32)],
    iterations: u64,
) -> (Vec<(bool, Option<u32>)>, u32) {
    let mut m = memory();
    let fsm = e11_fsm().unwrap();
    let mut state = fsm.start();
    let mut x = E11Input::default();
    let stamp = Stamp::new(0, Time::ZERO);
    let mut out = Vec::new();
    for it in 0..iterations {
        x.c1.traj.age();
        x.c1.steps.age();
        x.c1.notify.age();
        x.c1.pose.age();
        if it == 0 {
            // Localise the estimator at the origin.
            let pose = MapPose {
                pose: crate::payload::Pose2::default(),
                time: 0.0,
            };
            x.c1.pose.deliver(pose, stamp);
        }
        for (at, f, steps, notify) in deliveries {
            if *at == it {
                x.c1.traj.deliver(f.clone(), stamp);
                x.c1.steps.deliver(*steps, stamp);
                x.c1.notify.deliver(*notify, stamp);
            }
        }
        let mut y = E11Output::default();
        fsm.activate(&mut state, &mut m, &x, &mut y, |_| {})
            .unwrap();
        out.push((y.c1.ready.is_written(), m.track.following.map(|(_, i)| i)));
    }
    (out, m.track.rejected)
}

/// What `e11` sent in each iteration: `ready`, and the outcome.
type Sent = Vec<(bool, Option<PlanOutcome>)>;

/// e11 with the baseline pair and default safety limits, fed a map pose at
/// `pose(iteration)` every iteration (the estimate follows it) and the
/// fragments `(iteration, fragment)` (steps from the fragment, notify 2).
fn drive(
    deliveries: &[(u64, Fragment)],
    pose: impl Fn(u64) -> (f64, f64),
    iterations: u64,
) -> (Sent, E11Memory) {
    let mut m = memory();
    let fsm = e11_fsm().unwrap();
    let mut state = fsm.start();
    let mut x = E11Input::default();
    let mut sent = Vec::new();
    for it in 0..iterations {
        let stamp = Stamp::new(it, Time::from_nanos(it * 50_000_000));
        x.c1.traj.age();
        x.c1.steps.age();
        x.c1.notify.age();
        let (px, py) = pose(it);
        let p = MapPose {
            pose: crate::payload::Pose2 {
                x: px,
                y: py,
                phi: 0.0,
            },
            time: it as f64 * 0.05,
        };
        x.c1.pose.deliver(p, stamp);
        for (at, f) in deliveries {
            if *at == it {
                x.c1.traj.deliver(f.clone(), stamp);
                x.c1.steps.deliver(f.steps() as u32, stamp);
                x.c1.notify.deliver(2, stamp);
            }
        }
        let mut y = E11Output::default();
        fsm.activate(&mut state, &mut m, &x, &mut y, |_| {})
            .unwrap();
        sent.push((y.c1.ready.is_written(), y.c1.outcome.written().cloned()));
    }
    (sent, m)
}

fn outcomes(sent: &Sent) -> Vec<(usize, PlanOutcome)> {
    sent.iter()
        .enumerate()
        .filter_map(|(i, (_, o))| o.clone().map(|o| (i, o)))
        .collect()
}

fn last(mut f: Fragment) -> Fragment {
    f.last = true;
    f
}

#[test]
fn a_plan_whose_end_the_platform_reaches_is_reported_reached() {
    // 10 steps from 0 to 0.1 m, running at iterations 2..=11; the platform
    // follows the reference.
    let follow = |it: u64| (0.01 * it.saturating_sub(2).min(10) as f64, 0.0);
    let (sent, m) = drive(&[(1, last(fragment(0, 0.0, 10)))], follow, 20);
    let o = outcomes(&sent);
    assert_eq!(o.len(), 1, "{o:?}");
    let (at, o) = &o[0];
    assert_eq!(*at, 12, "the iteration after the last fragment ended");
    assert_eq!(o.plan, 1);
    assert!(
        matches!(o.result, Execution::Reached { error_m } if error_m < 0.02),
        "{o:?}"
    );
    assert!(m.stops.is_empty());
}

#[test]
fn a_plan_whose_end_the_platform_does_not_reach_is_reported_missed() {
    // 20 steps to 0.2 m; the platform does not move (the error stays under the
    // 0.3 m limit): after the last fragment, e11 holds and waits 3 s.
    let (sent, m) = drive(&[(1, last(fragment(0, 0.0, 20)))], |_| (0.0, 0.0), 100);
    let o = outcomes(&sent);
    assert_eq!(o.len(), 1, "{o:?}");
    let (at, o) = &o[0];
    // The last fragment runs at iterations 2..=21.
    assert_eq!(*at, 21 + 60, "3 s after the end");
    assert!(
        matches!(o.result, Execution::Missed { error_m } if (error_m - 0.2).abs() < 0.03),
        "{o:?}"
    );
    assert!(m.stops.is_empty(), "a miss is not a stop");
    // An intermediate fragment's end is not judged.
    let (sent, _) = drive(&[(1, fragment(0, 0.0, 20))], |_| (0.0, 0.0), 100);
    assert!(outcomes(&sent).is_empty());
}

#[test]
fn a_platform_far_from_its_reference_is_stopped_and_stale_fragments_refused() {
    // 40 steps to 0.4 m; the platform does not move: at 0.3 m of error e11 stops,
    // reports why and `ready`, drops the queued fragment of plan 2. A fragment
    // c1 handed over before it heard of the stop (epoch 0) is refused; one
    // stamped with the new epoch runs.
    let mut queued = fragment(0, 0.0, 10);
    queued.plan = 2;
    let mut stale = fragment(1, 0.0, 10);
    stale.plan = 3;
    let mut fresh = stale.clone();
    fresh.plan = 4;
    fresh.epoch = 1;
    let (sent, m) = drive(
        &[
            (1, fragment(0, 0.0, 40)),
            (3, last(queued)),
            (40, stale),
            (45, fresh),
        ],
        |_| (0.0, 0.0),
        50,
    );
    let o = outcomes(&sent);
    assert!(o.len() >= 3, "{o:?}");
    let (at, first) = &o[0];
    // The reference passes 0.3 m at iteration 32; the estimate, predicted with
    // the torques between poses, lags the poses a little.
    assert!((32..=38).contains(at), "stopped at {at}");
    assert!(sent[*at].0, "ready goes out with the stop");
    assert_eq!((first.plan, first.epoch), (1, 1));
    assert!(
        matches!(&first.result, Execution::Stopped(why) if why.contains("from its reference")),
        "{first:?}"
    );
    assert_eq!(o[1].1.plan, 2, "the queued plan ended too: {o:?}");
    assert!(matches!(o[1].1.result, Execution::Stopped(_)));
    assert_eq!(o[2].1.plan, 3, "the stale fragment's plan: {o:?}");
    assert!(
        matches!(&o[2].1.result, Execution::Stopped(why) if why.contains("before c1 heard of stop 1")),
        "{o:?}"
    );
    assert_eq!((m.epoch, m.track.stale), (1, 1));
    assert_eq!(m.track.running.as_ref().map(|r| r.fragment.plan), Some(4));
    assert_eq!(m.stops.len(), 1);
}

#[test]
fn a_map_pose_outside_the_free_space_stops_the_platform() {
    // The default map: a 12 m room, 0.5 m of clearance. The motion capture puts
    // the platform at x = 5.7 m while it drives.
    let (sent, m) = drive(
        &[(1, fragment(0, 5.3, 40))],
        |it| (if it < 10 { 5.3 } else { 5.7 }, 0.0),
        20,
    );
    let o = outcomes(&sent);
    assert_eq!(o.len(), 1, "{o:?}");
    assert_eq!(o[0].0, 10);
    assert!(
        matches!(&o[0].1.result, Execution::Stopped(why)
                if why.contains("motion capture puts the platform at (5.70, 0.00)")),
        "{o:?}"
    );
    assert!(m.track.running.is_none() && m.track.queue.is_empty());
}

#[test]
fn braking_that_would_end_outside_the_free_space_stops_the_platform() {
    let mut m = memory();
    m.track.running = Some(Running {
        fragment: fragment(0, 5.0, 10),
        k: 0,
    });
    let x = E11Input::default();
    let at = |v: f64, phi: f64| Estimate {
        x: [5.0, 0.0, phi, v, 0.0],
        localised: true,
        ..Estimate::default()
    };
    // 1 m/s² of braking: from 1.5 m/s, 1.125 m to a stop, past the 5.5 m line.
    let why = hazard(&m, &x, &at(1.5, 0.0)).unwrap();
    assert!(
        why.contains("heading out of the free space at 1.50 m/s"),
        "{why}"
    );
    // Slower, or away from the wall: free to go.
    assert_eq!(hazard(&m, &x, &at(0.3, 0.0)), None);
    assert_eq!(hazard(&m, &x, &at(1.5, std::f64::consts::PI)), None);
    // Reversing towards the wall.
    assert!(hazard(&m, &x, &at(-1.5, std::f64::consts::PI)).is_some());
}

#[test]
fn fragments_run_steps_iterations_ready_after_notify_then_hold() {
    let (out, rejected) = run(
        &[
            (1, fragment(0, 0.0, 10), 10, 6),
            (4, fragment(1, 0.1, 4), 4, 2),
        ],
        24,
    );
    assert_eq!(rejected, 0);
    let ready: Vec<usize> = (0..out.len()).filter(|&i| out[i].0).collect();
    let following: Vec<Option<u32>> = out.iter().map(|o| o.1).collect();
    // Ready once at start, then once per fragment after `notify` iterations of it.
    // Fragment 0 arrives at 1 and runs 2..=11; fragment 1 arrives early (at 4),
    // waits, and runs 12..=15; then e11 holds the last point.
    assert_eq!(ready, [0, 8, 14], "{out:?}");
    assert_eq!(&following[2..12], &[Some(0); 10]);
    assert_eq!(&following[12..16], &[Some(1); 4]);
    assert!(following[16..].iter().all(Option::is_none), "holding");
    assert_eq!(following[..2], [None, None]);
}

#[test]
fn bad_fragments_are_rejected_and_counted() {
    let mut bad = fragment(0, 0.0, 5);
    bad.states[3][1] = f64::NAN;
    let (out, rejected) = run(&[(1, bad, 5, 2)], 10);
    assert_eq!(rejected, 1);
    assert!(out.iter().all(|o| o.1.is_none()), "never followed: {out:?}");
}

#[test]
fn each_fragment_executed_to_its_end_is_reported_once_as_progress() {
    let mut m = memory();
    let fsm = e11_fsm().unwrap();
    let mut state = fsm.start();
    let mut x = E11Input::default();
    let stamp = Stamp::new(0, Time::ZERO);
    let mut progress = Vec::new();
    for it in 0..24u64 {
        x.c1.traj.age();
        x.c1.steps.age();
        x.c1.notify.age();
        x.c1.pose.age();
        if it == 0 {
            x.c1.pose.deliver(MapPose::default(), stamp);
        }
        // Fragments 3 and 4 of plan 1 (a plan resumed from its point 3).
        for (at, index, x0, steps) in [(1, 3, 0.0, 10), (4, 4, 0.1, 4)] {
            if at == it {
                x.c1.traj
                    .deliver(fragment(index, x0, steps as usize), stamp);
                x.c1.steps.deliver(steps, stamp);
                x.c1.notify.deliver(2, stamp);
            }
        }
        let mut y = E11Output::default();
        fsm.activate(&mut state, &mut m, &x, &mut y, |_| {})
            .unwrap();
        progress.extend(y.c1.progress.written().map(|p| (it, *p)));
    }
    // Fragment 3 runs 2..=11 and fragment 4 12..=15: each is reported in the
    // iteration after its last step.
    assert_eq!(
        progress,
        [
            (12, Progress { plan: 1, done: 4 }),
            (16, Progress { plan: 1, done: 5 })
        ]
    );
}

#[test]
fn an_e11_started_late_takes_its_clock_from_the_platform() {
    let reading = |time: f64| Encoders {
        time,
        ..Encoders::default()
    };
    // Started at 12.3 s (its process restarted): iteration 0 is that instant.
    let mut m = memory();
    m.set_clock(Some(&reading(12.3005)));
    assert_eq!(m.start, Some(246));
    assert!((m.now() - 12.3).abs() < 1e-9);
    // Taken once: a later reading does not move it.
    m.iteration = 5;
    m.set_clock(Some(&reading(99.0)));
    assert!((m.now() - 12.55).abs() < 1e-9);
    // A stamp that is no clock is ignored: the count goes on from zero.
    for bad in [f64::NAN, -1.0, f64::INFINITY, 1e300] {
        let mut m = memory();
        m.set_clock(Some(&reading(bad)));
        assert_eq!(m.start, None, "{bad}");
        assert_eq!(m.now(), 0.0);
    }
    // Started with the world: the clock and the count agree.
    let mut m = memory();
    m.set_clock(Some(&reading(0.001)));
    assert_eq!(m.start, Some(0));
}

#[test]
fn visual_odometry_is_lost_after_its_patience_and_back_with_the_next_motion() {
    let mut w = VoWatch::new(10);
    // Never received: not expected, never lost.
    for k in 0..50 {
        w.see(k, false);
    }
    assert!(!w.lost && w.outages == 0);
    w.see(50, true);
    for k in 51..60 {
        w.see(k, false);
    }
    assert!(!w.lost, "9 iterations without a motion are within patience");
    w.see(60, false);
    assert!(w.lost && w.outages == 1);
    for k in 61..100 {
        w.see(k, false);
    }
    assert_eq!(w.outages, 1, "one outage, however long");
    w.see(100, true);
    assert!(!w.lost && w.received == 2);
    for k in 101..120 {
        w.see(k, false);
    }
    assert_eq!(w.outages, 2);
}

#[test]
fn a_success_is_reported_only_with_a_margin_for_the_estimates_error() {
    // The platform stops 0.09 m short of the end of a 0.2 m fragment: within
    // the tolerance (0.1 m), but not with the margin for the estimate's own
    // error (0.03 m), so e11 does not claim it: it holds for 3 s and reports
    // a miss. 0.03 m short, it is reached.
    for (short, reached) in [(0.09, false), (0.03, true)] {
        let follow = move |it: u64| ((0.01 * it.saturating_sub(2) as f64).min(0.2 - short), 0.0);
        let (sent, _) = drive(&[(1, last(fragment(0, 0.0, 20)))], follow, 100);
        let o = outcomes(&sent);
        assert_eq!(o.len(), 1, "{o:?}");
        let (at, o) = &o[0];
        if reached {
            assert_eq!(*at, 22, "{o:?}");
            assert!(
                matches!(o.result, Execution::Reached { error_m } if error_m < 0.07),
                "{o:?}"
            );
        } else {
            assert_eq!(*at, 21 + 60, "3 s after the end");
            assert!(
                matches!(o.result, Execution::Missed { error_m } if (error_m - short).abs() < 0.02),
                "{o:?}"
            );
        }
    }
}

#[test]
fn a_success_is_not_reported_while_the_estimate_strays_from_the_map_poses() {
    // The estimate 1 cm from the end: reached, unless it is farther from the
    // latest map poses than the margin it is allowed (0.03 m): then its own
    // error may be larger too, and e11 waits for it to keep to the poses
    // again, or for `settle` (3 s) to pass.
    let at = |d: Option<f64>| Estimate {
        x: [1.01, 0.0, 0.0, 0.0, 0.0],
        localised: true,
        pose_disagreement: d,
        ..Estimate::default()
    };
    let arrival = Arrival {
        plan: 1,
        end: [1.0, 0.0],
        since: 0.0,
    };
    let mut m = memory();
    m.arrival = Some(arrival);
    for d in [0.05, 0.031, f64::NAN] {
        judge_arrival(&mut m, &at(Some(d)));
        assert!(m.outbox.is_empty(), "{d}: {:?}", m.outbox);
        m.iteration += 1;
    }
    judge_arrival(&mut m, &at(Some(0.02)));
    let o = m.outbox.pop_front().unwrap();
    assert!(
        matches!(o.result, Execution::Reached { error_m } if (error_m - 0.01).abs() < 1e-9),
        "{o:?}"
    );
    // No pose in the last half second: the margin alone (as before poses).
    let mut m = memory();
    m.arrival = Some(arrival);
    judge_arrival(&mut m, &at(None));
    assert!(matches!(
        m.outbox.pop_front().map(|o| o.result),
        Some(Execution::Reached { .. })
    ));
    // Straying for longer than `settle`: missed, with the estimate's distance.
    let mut m = memory();
    m.arrival = Some(arrival);
    judge_arrival(&mut m, &at(Some(0.05)));
    assert!(m.outbox.is_empty());
    m.iteration = 60;
    judge_arrival(&mut m, &at(Some(0.05)));
    let o = m.outbox.pop_front().unwrap();
    assert!(
        matches!(o.result, Execution::Missed { error_m } if (error_m - 0.01).abs() < 1e-9),
        "{o:?}"
    );
}
