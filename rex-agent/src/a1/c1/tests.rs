//! Unit tests of `c1`: Algorithms 4–8 and the FSM of Fig. 5 on scripted inputs.

use super::*;
use crate::a1::c1::trajgen::Runtime;
use crate::algorithms::planner::{PlannerKind, PlannerSettings};
use crate::payload::Point2;

fn pts(p: &[(f64, f64)]) -> Plan {
    Plan {
        id: 1,
        points: p.iter().map(|&(x, y)| Point2 { x, y }).collect(),
        first: 0,
    }
}

#[test]
fn proc_adds_orientations_and_refuses_bad_plans() {
    let params = C1Params::default();
    let w = proc(&pts(&[(1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]), &params).unwrap();
    let h: Vec<f64> = w.iter().map(|p| p.phi.unwrap()).collect();
    assert!(
        (h[0] - std::f64::consts::FRAC_PI_2).abs() < 1e-12,
        "first along the first segment"
    );
    assert!(
        (h[1] - 3.0 * std::f64::consts::FRAC_PI_4).abs() < 1e-12,
        "bisector"
    );
    assert!(
        (h[2] - std::f64::consts::PI).abs() < 1e-12,
        "last along the last segment"
    );
    // Repeated and collinear points.
    let w = proc(
        &pts(&[(1.0, 0.0), (1.0, 0.0), (2.0, 0.0), (3.0, 0.0)]),
        &params,
    )
    .unwrap();
    assert!(w.iter().all(|p| p.phi == Some(0.0)), "{w:?}");
    let w = proc(&pts(&[(1.0, 1.0), (1.0, 1.0)]), &params).unwrap();
    assert!(w.iter().all(|p| p.phi.is_none()), "all equal: free heading");
    assert!(proc(&pts(&[]), &params).unwrap_err().contains("no points"));
    assert!(
        proc(&pts(&[(f64::NAN, 0.0)]), &params)
            .unwrap_err()
            .contains("not finite")
    );
    assert!(
        proc(&pts(&[(0.0, 0.0), (9.0, 0.0)]), &params)
            .unwrap_err()
            .contains("off the map")
    );
    let absurd = Plan {
        first: u32::MAX,
        ..pts(&[(1.0, 0.0)])
    };
    assert!(
        proc(&absurd, &params)
            .unwrap_err()
            .contains("resumes from point")
    );
}

#[test]
fn notify_is_always_before_the_end() {
    let params = C1Params::default();
    for n in 1..60usize {
        let f = Fragment {
            plan: 1,
            index: 0,
            dt: 0.05,
            states: vec![[0.0; 5]; n + 1],
            ..Fragment::default()
        };
        let (steps, notify) = (traj_to_steps(&f), traj_to_notify(&f, &params));
        assert_eq!(steps as usize, n);
        assert!(notify < steps, "{notify} < {steps}");
        if n > 20 {
            assert_eq!(notify, steps - 20, "1 s before the end");
        }
    }
}

#[test]
fn the_fsm_builds() {
    let fsm = c1_fsm().unwrap();
    assert_eq!(fsm.len(), 3);
    let _ = TrajGen::new(
        PlannerKind::Ecsa,
        PlannerSettings::default(),
        Runtime::Inline,
        1,
    );
}

// -----------------------------------------------------------------------
// The transition subfunctions, case by case as in Algorithms 4-8.

fn stamp() -> embodied::Stamp {
    embodied::Stamp::new(0, embodied::Time::ZERO)
}

fn memory(latency: u32) -> C1Memory {
    C1Memory::new(
        TrajGen::new(
            PlannerKind::Polynomial,
            PlannerSettings::default(),
            Runtime::Inline,
            latency,
        ),
        C1Params::default(),
    )
}

fn state(x: f64, y: f64, phi: f64) -> State {
    State {
        q: [x, y, phi, 0.0, 0.0, 0.0, 0.0],
        q_dot: [0.0; 7],
        ground: None,
    }
}

/// Inputs: a fresh plan (or none), a state estimate (or none), a fresh `ready`.
fn input(plan: Option<Plan>, estimate: Option<State>, ready: bool) -> C1Input {
    let mut x = C1Input::default();
    if let Some(p) = plan {
        x.c2.desired_plan.deliver(p, stamp());
    }
    if let Some(s) = estimate {
        x.e11.q_est.deliver(s, stamp());
        x.e11.q_est.age();
    }
    if ready {
        x.e11.ready.deliver(true, stamp());
    }
    x
}

fn fragment(plan: u32, index: u32) -> Fragment {
    Fragment {
        plan,
        index,
        dt: 0.05,
        states: vec![[0.0; 5]; 41],
        ..Fragment::default()
    }
}

#[test]
fn algorithm_4_takes_a_new_plan_and_ignores_old_data() {
    let mut m = memory(1);
    m.traj.push_back(fragment(0, 0));
    let plan = Plan {
        id: 7,
        ..pts(&[(1.0, 0.0), (1.0, 1.0)])
    };
    // Not new: nothing happens.
    let mut x = input(Some(plan.clone()), Some(state(0.5, 0.0, 0.0)), false);
    x.c2.desired_plan.age();
    cc_1_tp(&mut m, &x);
    assert!(!m.new && m.plan.is_empty() && m.traj.len() == 1);
    // isnew(desired_plan): plan <- proc(desired_plan), traj <- {}, trajgenInit, new.
    cc_1_tp(
        &mut m,
        &input(Some(plan), Some(state(0.5, 0.0, 0.0)), false),
    );
    assert!(m.new);
    assert_eq!(m.plan_id, 7);
    assert_eq!(m.plan.len(), 2);
    assert!(m.plan.iter().all(|w| w.phi.is_some()), "orientations added");
    assert!(m.traj.is_empty());
    assert_eq!(m.trajgen.status(), &Status::Idle);
    assert_eq!(
        m.trajgen.from(),
        [0.5, 0.0, 0.0],
        "initialised from the state"
    );
    assert!(m.refusal.is_none());
}

#[test]
fn algorithm_4_waits_for_the_first_estimate_then_refuses() {
    let mut m = memory(1);
    m.params.estimate_wait_max = 3;
    cc_1_tp(&mut m, &input(Some(pts(&[(1.0, 0.0)])), None, false));
    assert!(!m.new && m.pending.is_some(), "waits for an estimate");
    // The estimate arrives: the plan is taken.
    cc_1_tp(&mut m, &input(None, Some(state(0.0, 0.0, 0.0)), false));
    assert!(m.new && m.refusal.is_none() && m.pending.is_none());
    // No estimate ever: refused after `estimate_wait_max` iterations.
    let mut m = memory(1);
    m.params.estimate_wait_max = 3;
    cc_1_tp(&mut m, &input(Some(pts(&[(1.0, 0.0)])), None, false));
    for _ in 0..3 {
        assert!(!m.new);
        cc_1_tp(&mut m, &input(None, None, false));
    }
    assert!(m.new);
    assert!(
        m.refusal
            .as_deref()
            .is_some_and(|r| r.contains("no state estimate"))
    );
}

#[test]
fn a_plan_sent_during_execution_waits_for_the_next_b1() {
    let mut m = memory(1);
    m.plan.push_back(Waypoint {
        x: 1.0,
        y: 0.0,
        phi: None,
    });
    cc_2_tp(&mut m, &input(Some(pts(&[(2.0, 0.0)])), None, false));
    assert!(m.pending.is_some(), "kept, not lost");
    cc_1_tp(&mut m, &input(None, Some(state(0.0, 0.0, 0.0)), false));
    assert!(m.new && m.plan.len() == 1 && m.plan[0].x == 2.0);
}

#[test]
fn algorithm_5_clears_ack_on_a_new_plan_only() {
    let m = memory(1);
    let mut y = C1ToC2::default();
    cT_1_tp(&m, &input(None, None, false), &mut y);
    assert!(!y.ack.is_written());
    cT_1_tp(&m, &input(Some(pts(&[(1.0, 0.0)])), None, false), &mut y);
    let ack = y.ack.written().expect("ack written");
    assert!(!ack.ready(), "ack = false");
    assert_eq!((ack.plan, &ack.status), (1, &AckStatus::Received));
}

/// c1 with plan `points` taken (Algorithm 4 done).
fn taken(points: &[(f64, f64)], latency: u32) -> C1Memory {
    let mut m = memory(latency);
    cc_1_tp(
        &mut m,
        &input(Some(pts(points)), Some(state(0.0, 0.0, 0.0)), false),
    );
    assert!(m.new);
    m
}

#[test]
fn algorithm_6_starts_the_first_point_when_new() {
    let mut m = taken(&[(1.0, 0.0), (2.0, 0.0)], 2);
    cc_2_tp(&mut m, &input(None, None, false));
    // new: new <- false, trajgenStart(first point), plan <- listDelFirst(plan).
    assert!(!m.new);
    assert_eq!(m.trajgen.status(), &Status::Planning);
    assert_eq!(m.plan.len(), 1);
    assert!(m.traj.is_empty());
    // Not ready yet: trajgenGetStat.
    cc_2_tp(&mut m, &input(None, None, false));
    assert_eq!(m.trajgen.status(), &Status::Planning);
    cc_2_tp(&mut m, &input(None, None, false));
    assert!(m.trajgen.is_ready());
}

#[test]
fn algorithm_6_collects_fragments_and_starts_the_next_point() {
    let mut m = taken(&[(1.0, 0.0), (2.0, 0.0)], 1);
    cc_2_tp(&mut m, &input(None, None, false)); // start point 1
    cc_2_tp(&mut m, &input(None, None, false)); // stat -> ready
    assert!(m.trajgen.is_ready());
    // trajgenIsReady, not ready: listAddLast; plan not empty: start the next point.
    cc_2_tp(&mut m, &input(None, None, false));
    assert_eq!(m.traj.iter().map(|f| f.index).collect::<Vec<_>>(), [0]);
    assert_eq!(m.trajgen.status(), &Status::Planning);
    assert!(m.plan.is_empty());
    cc_2_tp(&mut m, &input(None, None, false)); // stat -> ready
    // ready & traj not empty & trajgenIsReady: listAddLastDelFirst.
    cc_2_tp(&mut m, &input(None, None, true));
    assert_eq!(m.traj.iter().map(|f| f.index).collect::<Vec<_>>(), [1]);
    assert_eq!(m.handed, 1);
    // trajgenIsReady was true and the plan is empty: trajgenStop.
    assert_eq!(m.trajgen.status(), &Status::Stopped);
    // ready & traj not empty & not trajgenIsReady: listDelFirst.
    cc_2_tp(&mut m, &input(None, None, true));
    assert!(m.traj.is_empty());
    assert_eq!(m.handed, 2);
}

#[test]
fn algorithm_7_hands_over_the_first_fragment_only_when_ready() {
    let mut m = memory(1);
    let mut y = C1ToE11::default();
    ce_2_tp(&m, &input(None, None, true), &mut y);
    assert!(!y.traj.is_written(), "ready but nothing to hand over");
    m.traj.push_back(fragment(1, 0));
    m.traj.push_back(fragment(1, 1));
    ce_2_tp(&m, &input(None, None, false), &mut y);
    assert!(!y.traj.is_written(), "not ready");
    ce_2_tp(&m, &input(None, None, true), &mut y);
    assert_eq!(y.traj.written().map(|f| f.index), Some(0));
    let (steps, notify) = (y.steps.written().copied(), y.notify.written().copied());
    assert_eq!(steps, Some(40));
    assert_eq!(notify, Some(20), "1 s before the end at 0.05 s per step");
    // A ready event latched in memory counts as ready^i.
    let mut y = C1ToE11::default();
    m.ready_latch = true;
    ce_2_tp(&m, &input(None, None, false), &mut y);
    assert!(y.traj.is_written());
}

#[test]
fn algorithm_8_acknowledges_with_the_outcome() {
    let mut m = taken(&[(1.0, 0.0)], 1);
    let mut y = C1ToC2::default();
    cT_3_tp(&m, &input(None, None, false), &mut y);
    let ack = y.ack.written().cloned().expect("ack");
    assert!(ack.ready(), "ack = true");
    assert_eq!(ack.status, AckStatus::Done);
    m.refusal = Some("off the map".into());
    cT_3_tp(&m, &input(None, None, false), &mut y);
    assert_eq!(
        y.ack.written().map(|a| &a.status),
        Some(&AckStatus::Refused("off the map".into()))
    );
}

// -----------------------------------------------------------------------
// Outcomes, stops and the free space.

/// The FSM over a sequence of inputs; returns what went to `e11` and `c2`.
fn activate(
    fsm: &Fsm<C1>,
    fsm_state: &mut embodied::FsmState,
    m: &mut C1Memory,
    x: &C1Input,
) -> (Option<Fragment>, Option<Ack>, Option<PlanOutcome>) {
    let mut y = C1Output::default();
    fsm.activate(fsm_state, m, x, &mut y, |_| {}).unwrap();
    (
        y.e11.traj.written().cloned(),
        y.c2.ack.written().cloned(),
        y.c2.outcome.written().cloned(),
    )
}

fn outcome(plan: u32, epoch: u32, result: Execution) -> PlanOutcome {
    PlanOutcome {
        plan,
        epoch,
        result,
    }
}

#[test]
fn a_stop_fails_the_plan_and_the_next_one_starts_at_rest_from_the_estimate() {
    let fsm = c1_fsm().unwrap();
    let mut st = fsm.start();
    let mut m = memory(1);
    let plan = pts(&[(1.0, 0.0), (2.0, 0.0), (3.0, 0.0)]);
    let mut x = input(Some(plan), Some(state(0.0, 0.0, 0.0)), true);
    // Plan 1 taken; its first fragment handed over with e11's epoch (0) and
    // not marked last.
    let mut handed = Vec::new();
    for _ in 0..6 {
        let (f, _, _) = activate(&fsm, &mut st, &mut m, &x);
        handed.extend(f);
        x.c2.desired_plan.age();
        x.e11.ready.age();
    }
    assert_eq!(handed.len(), 1, "{handed:?}");
    assert_eq!((handed[0].epoch, handed[0].last), (0, false));
    // e11 stops the platform: B2 ends, plan 1 fails with the reason, and the
    // stop is relayed to a2.
    let why = "the platform is 0.31 m from its reference (at most 0.30 m)";
    x.e11
        .outcome
        .deliver(outcome(1, 1, Execution::Stopped(why.into())), stamp());
    let (_, ack, relayed) = activate(&fsm, &mut st, &mut m, &x);
    let ack = ack.expect("an ack");
    assert!(
        matches!(&ack.status, AckStatus::Failed(w) if w.contains(why)),
        "{ack:?}"
    );
    assert_eq!(relayed.map(|o| o.plan), Some(1));
    assert!(m.restart);
    x.e11.outcome.age();
    activate(&fsm, &mut st, &mut m, &x);
    assert_eq!(fsm.behaviour_name(st.behaviour()), "B1");
    // Plan 2 arrives while the platform still brakes: it waits, then starts
    // from where the platform came to rest, with the new epoch.
    let mut moving = state(1.4, 0.1, 0.2);
    moving.q_dot[0] = 0.3;
    x.c2.desired_plan.deliver(
        Plan {
            id: 2,
            ..pts(&[(2.0, 0.2)])
        },
        stamp(),
    );
    x.e11.q_est.deliver(moving, stamp());
    activate(&fsm, &mut st, &mut m, &x);
    x.c2.desired_plan.age();
    assert!(m.pending.is_some() && !m.new, "waits for rest");
    x.e11.q_est.deliver(state(1.5, 0.1, 0.2), stamp());
    x.e11.ready.deliver(true, stamp());
    let mut second = Vec::new();
    for _ in 0..8 {
        let (f, _, _) = activate(&fsm, &mut st, &mut m, &x);
        second.extend(f);
        x.e11.ready.age();
    }
    assert_eq!(second.len(), 1, "{second:?}");
    let start = second[0].states[0];
    assert!(
        (start[0] - 1.5).abs() < 1e-9 && (start[1] - 0.1).abs() < 1e-9,
        "{start:?}"
    );
    assert_eq!(
        (second[0].plan, second[0].epoch, second[0].last),
        (2, 1, true)
    );
}

#[test]
fn a_planned_fragment_that_leaves_the_free_space_fails_the_plan() {
    let fsm = c1_fsm().unwrap();
    let mut st = fsm.start();
    let mut m = memory(1);
    // A box at (0, 1): both points clear it, the path between them does not.
    m.params.map.obstacles.push(crate::a1::map::Rect {
        x0: -0.2,
        y0: 0.9,
        x1: 0.2,
        y1: 1.1,
    });
    let plan = pts(&[(0.0, 0.0), (0.0, 2.0)]);
    let mut x = input(
        Some(plan),
        Some(state(0.0, 0.0, std::f64::consts::FRAC_PI_2)),
        true,
    );
    let mut acks = Vec::new();
    let mut handed = 0;
    for _ in 0..10 {
        let (f, a, _) = activate(&fsm, &mut st, &mut m, &x);
        handed += usize::from(f.is_some());
        acks.extend(a.filter(Ack::ready));
        x.c2.desired_plan.age();
        x.e11.ready.age();
    }
    assert_eq!(acks.len(), 1, "{acks:?}");
    assert!(
        matches!(&acks[0].status, AckStatus::Failed(w)
                if w.contains("fragment 1 of plan 1 leaves the free space") && w.contains("obstacle 1")),
        "{acks:?}"
    );
    assert_eq!(handed, 1, "only the fragment before it");
}

#[test]
fn outcomes_are_relayed_in_every_behaviour() {
    let fsm = c1_fsm().unwrap();
    let mut st = fsm.start();
    let mut m = memory(1);
    let mut x = input(None, Some(state(0.0, 0.0, 0.0)), false);
    // B1.
    x.e11
        .outcome
        .deliver(outcome(4, 0, Execution::Reached { error_m: 0.01 }), stamp());
    let (_, _, relayed) = activate(&fsm, &mut st, &mut m, &x);
    assert_eq!(relayed.map(|o| o.plan), Some(4));
    // B2, with a plan being planned.
    x.c2.desired_plan
        .deliver(pts(&[(1.0, 0.0), (2.0, 0.0)]), stamp());
    x.e11.outcome.age();
    activate(&fsm, &mut st, &mut m, &x);
    x.c2.desired_plan.age();
    activate(&fsm, &mut st, &mut m, &x);
    assert_eq!(fsm.behaviour_name(st.behaviour()), "B2");
    x.e11
        .outcome
        .deliver(outcome(5, 0, Execution::Missed { error_m: 0.2 }), stamp());
    let (_, _, relayed) = activate(&fsm, &mut st, &mut m, &x);
    assert_eq!(relayed.map(|o| o.plan), Some(5));
    assert_eq!(
        fsm.behaviour_name(st.behaviour()),
        "B2",
        "a miss is no stop"
    );
}

#[test]
fn a_resumed_plan_keeps_its_numbers_and_a_copy_of_a_plan_taken_is_ignored() {
    let fsm = c1_fsm().unwrap();
    let mut st = fsm.start();
    let mut m = memory(1);
    m.params.boot = 42;
    // Plan 3 sent again from its point 2 (a2 knows fragments 0 and 1 done).
    let resumed = Plan {
        id: 3,
        first: 2,
        ..pts(&[(2.0, 0.0), (3.0, 0.0)])
    };
    let mut x = input(Some(resumed.clone()), Some(state(1.0, 0.0, 0.0)), true);
    let mut handed = Vec::new();
    let mut acks = Vec::new();
    for k in 0..12 {
        let mut y = C1Output::default();
        fsm.activate(&mut st, &mut m, &x, &mut y, |_| {}).unwrap();
        handed.extend(y.e11.traj.written().cloned());
        acks.extend(y.c2.ack.written().cloned());
        assert_eq!(
            y.c2.alive.written().map(|a| a.boot),
            Some(42),
            "alive in every iteration"
        );
        x.c2.desired_plan.age();
        x.e11.ready.age();
        if k == 3 {
            // The same plan again (a resend that crossed the ack): ignored.
            x.c2.desired_plan.deliver(resumed.clone(), stamp());
        }
        if handed.len() == 1 {
            x.e11.ready.deliver(true, stamp());
        }
    }
    let numbers: Vec<(u32, u32)> = handed.iter().map(|f| (f.plan, f.index)).collect();
    assert_eq!(numbers, [(3, 2), (3, 3)], "numbered from `first`");
    assert_eq!(
        acks.iter()
            .filter(|a| a.status == AckStatus::Received)
            .count(),
        1,
        "{acks:?}"
    );
    assert!(
        acks.iter()
            .any(|a| a.plan == 3 && a.status == AckStatus::Done),
        "{acks:?}"
    );
    assert!(m.pending.is_none() && m.taken == 3, "the copy was not kept");
    // Back in B1, a copy of plan 3 and an older plan are copies too: no
    // acknowledgement, nothing taken, nothing planned.
    for _ in 0..3 {
        activate(&fsm, &mut st, &mut m, &x);
    }
    assert_eq!(fsm.behaviour_name(st.behaviour()), "B1");
    for copy in [resumed.clone(), pts(&[(1.0, 1.0)])] {
        x.c2.desired_plan.deliver(copy, stamp());
        for _ in 0..3 {
            let (f, a, _) = activate(&fsm, &mut st, &mut m, &x);
            assert!(f.is_none() && a.is_none(), "{f:?} {a:?}");
            x.c2.desired_plan.age();
        }
        assert_eq!(fsm.behaviour_name(st.behaviour()), "B1");
        assert!(m.pending.is_none() && !m.new);
    }
}

#[test]
fn progress_is_relayed_while_waiting_and_executing() {
    let fsm = c1_fsm().unwrap();
    let mut st = fsm.start();
    let mut m = memory(1);
    let mut x = input(None, Some(state(0.0, 0.0, 0.0)), false);
    let relay = |x: &C1Input, st: &mut embodied::FsmState, m: &mut C1Memory| {
        let mut y = C1Output::default();
        fsm.activate(st, m, x, &mut y, |_| {}).unwrap();
        y.c2.progress.written().copied()
    };
    let p = Progress { plan: 7, done: 3 };
    x.e11.progress.deliver(p, stamp());
    assert_eq!(relay(&x, &mut st, &mut m), Some(p), "B1");
    x.e11.progress.age();
    x.c2.desired_plan
        .deliver(pts(&[(1.0, 0.0), (2.0, 0.0)]), stamp());
    relay(&x, &mut st, &mut m);
    x.c2.desired_plan.age();
    relay(&x, &mut st, &mut m);
    assert_eq!(fsm.behaviour_name(st.behaviour()), "B2");
    let p = Progress { plan: 1, done: 1 };
    x.e11.progress.deliver(p, stamp());
    assert_eq!(relay(&x, &mut st, &mut m), Some(p), "B2");
    x.e11.progress.age();
    assert_eq!(relay(&x, &mut st, &mut m), None, "once");
}
