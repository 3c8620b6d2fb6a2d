//! The locomotion agent a1: c1's protocol with e11 and a2 under random plans (with the
//! termination helper of `embodied::testing`), and whole missions end to end.

#![allow(
    clippy::unwrap_used,
    reason = "a failing unwrap is a failing test (helpers included)"
)]

use std::time::Duration;

use embodied::testing::{Environment, Termination};
use embodied::{Activated, Fsm, OffloadMode, Recorder, Stamp, Step, Time};
use proptest::prelude::*;

use rex_agent::a1::c1::trajgen::{Runtime, TrajGen};
use rex_agent::a1::c1::{C1, C1Input, C1Memory, C1Output, C1Params, c1_fsm};
use rex_agent::a1::e11::{EstimatorKind, TrackerKind};
use rex_agent::algorithms::planner::{PlannerKind, PlannerSettings};
use rex_agent::mission::Mission;
use rex_agent::model::{Friction, Patch, Region};
use rex_agent::payload::{Ack, AckStatus, Execution, Plan, Point2, State};
use rex_agent::run::judge::Verdict;
use rex_agent::run::{Outcome, run_mission, run_mission_observed};
use rex_agent::system::{RexConfig, RunSettings, build};
use rex_agent::world::WorldConfig;

// ---------------------------------------------------------------------------
// c1 alone, driven by a model of e11 and a2.

fn stamp(iteration: u64) -> Stamp {
    Stamp::new(iteration, Time::from_nanos(iteration * 10_000_000))
}

/// What c1 sent to e11: `(plan, index, steps, notify)`.
type Handed = (u32, u32, u32, u32);

/// e11 and a2 as c1 sees them: a2 sends one plan at the start; e11 has a state
/// estimate, reports `ready` at start and `delay` iterations of c1 after each
/// fragment it receives (e11 is slower than c1 and counts `notify` steps).
#[derive(Clone, Debug)]
struct E11AndA2 {
    plan: Plan,
    delay: u64,
    ready_at: Option<u64>,
    handed: Vec<Handed>,
    acks: Vec<Ack>,
}

impl E11AndA2 {
    fn new(plan: Plan, delay: u64) -> Self {
        E11AndA2 {
            plan,
            delay,
            ready_at: Some(0),
            handed: Vec::new(),
            acks: Vec::new(),
        }
    }
}

impl Environment<C1> for E11AndA2 {
    fn inputs(&mut self, iteration: u64, previous: Option<&C1Output>, x: &mut C1Input) {
        x.c2.desired_plan.age();
        x.e11.ready.age();
        x.e11.q_est.age();
        x.c3.pose.age();
        x.r11.A4x4.age();
        if iteration == 0 {
            x.c2.desired_plan.deliver(self.plan.clone(), stamp(0));
            let state = State {
                q: [0.0; 7],
                q_dot: [0.0; 7],
                ground: None,
            };
            x.e11.q_est.deliver(state, stamp(0));
        }
        if let Some(y) = previous {
            if let Some(f) = y.e11.traj.written() {
                let steps = y.e11.steps.written().copied().unwrap_or(0);
                let notify = y.e11.notify.written().copied().unwrap_or(u32::MAX);
                self.handed.push((f.plan, f.index, steps, notify));
                self.ready_at = Some(iteration + self.delay);
            }
            if let Some(a) = y.c2.ack.written() {
                self.acks.push(a.clone());
            }
        }
        if self.ready_at == Some(iteration) {
            self.ready_at = None;
            x.e11.ready.deliver(true, stamp(iteration));
        }
    }
}

fn c1_memory() -> C1Memory {
    let settings = PlannerSettings {
        speed_max: 0.9,
        turn_rate_max: 1.2,
        ..PlannerSettings::default()
    };
    C1Memory::new(
        TrajGen::new(PlannerKind::Ecsa, settings, Runtime::Inline, 3),
        C1Params::default(),
    )
}

/// Plans of 1..=50 points on the map, with repeated points (the same point twice)
/// and collinear runs (a point on the line through the previous two).
fn plans() -> impl Strategy<Value = Plan> {
    prop::collection::vec((0u8..4, -4.5f64..4.5, -4.5f64..4.5), 1..=50).prop_map(|steps| {
        let mut points: Vec<Point2> = Vec::new();
        for (kind, x, y) in steps {
            let n = points.len();
            let p = match kind {
                0 if n >= 1 => points[n - 1],
                1 if n >= 2 => {
                    let (a, b) = (points[n - 2], points[n - 1]);
                    let ahead = Point2 {
                        x: b.x + 0.5 * (b.x - a.x),
                        y: b.y + 0.5 * (b.y - a.y),
                    };
                    let on_map = ahead.x.abs() <= 5.0 && ahead.y.abs() <= 5.0;
                    if on_map {
                        ahead
                    } else {
                        Point2 {
                            x: (a.x + b.x) / 2.0,
                            y: (a.y + b.y) / 2.0,
                        }
                    }
                }
                _ => Point2 { x, y },
            };
            points.push(p);
        }
        Plan {
            id: 1,
            points,
            first: 0,
        }
    })
}

fn environments() -> impl Strategy<Value = E11AndA2> {
    (plans(), 1u64..40).prop_map(|(plan, delay)| E11AndA2::new(plan, delay))
}

/// The bound: per point, planning (3 iterations) and e11's ready (< 40), twice over.
const BOUND: u64 = 50 * 2 * 43 + 20;

#[test]
fn c1_returns_to_b1_for_any_plan() {
    let fsm = c1_fsm().unwrap();
    Termination::within(BOUND)
        .cases(24)
        .returns_to(&fsm, "B1", Just(c1_memory()), environments())
        .unwrap();
}

/// Drive c1 until it is back in B1; the environment keeps what c1 sent.
fn drive(fsm: &Fsm<C1>, mut env: E11AndA2) -> Result<E11AndA2, String> {
    let mut memory = c1_memory();
    let mut state = fsm.start();
    let mut input = C1Input::default();
    let mut previous: Option<C1Output> = None;
    let b1 = fsm.behaviour_index("B1").ok_or("no B1")?;
    for iteration in 0..BOUND + 2 {
        env.inputs(iteration, previous.as_ref(), &mut input);
        let mut output = C1Output::default();
        let mut back = false;
        let r = fsm
            .activate(&mut state, &mut memory, &input, &mut output, |s| {
                back |= matches!(s, Step::Entered { to, .. } if *to == b1);
            })
            .map_err(|e| e.to_string())?;
        if back {
            // The ack of B3 was sent in the previous activation; keep it.
            env.inputs(iteration + 1, Some(&output), &mut input);
            return Ok(env);
        }
        if let Activated::Halted = r {
            return Err("halted".into());
        }
        previous = Some(output);
    }
    Err("did not return to B1".into())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, failure_persistence: None, ..ProptestConfig::default() })]

    /// Fragments reach e11 in order, none lost or duplicated, each with
    /// `notify < steps`; the plan is acknowledged exactly once (ack = true), after a
    /// first `ack = false` when it was taken.
    #[test]
    fn fragments_in_order_and_one_ack_per_plan(env in environments()) {
        let fsm = c1_fsm().unwrap();
        let points = env.plan.points.len();
        let env = drive(&fsm, env).map_err(TestCaseError::fail)?;
        let finals: Vec<&Ack> = env.acks.iter().filter(|a| a.ready()).collect();
        prop_assert_eq!(finals.len(), 1, "acks: {:?}", env.acks);
        prop_assert_eq!(env.acks.first().map(|a| &a.status), Some(&AckStatus::Received));
        let indices: Vec<u32> = env.handed.iter().map(|h| h.1).collect();
        let expected: Vec<u32> = (0..indices.len() as u32).collect();
        prop_assert_eq!(&indices, &expected, "in order, none lost or duplicated");
        for &(plan, _, steps, notify) in &env.handed {
            prop_assert_eq!(plan, 1);
            prop_assert!(notify < steps, "notify {} < steps {}", notify, steps);
        }
        match &finals[0].status {
            AckStatus::Done => prop_assert_eq!(indices.len(), points, "one fragment per point"),
            AckStatus::Failed(_) => prop_assert!(indices.len() < points),
            other => prop_assert!(false, "unexpected {:?}", other),
        }
    }
}

#[test]
fn a_failing_termination_property_is_shrunk_to_a_readable_trace() {
    // An e11 that never reports ready after the first fragment: c1 waits in B2.
    #[derive(Clone, Debug)]
    struct Silent(E11AndA2);
    impl Environment<C1> for Silent {
        fn inputs(&mut self, it: u64, prev: Option<&C1Output>, x: &mut C1Input) {
            self.0.inputs(it, prev, x);
            self.0.ready_at = None;
            if it > 0 {
                x.e11.ready.age();
            }
        }
    }
    let env = plans().prop_map(|p| Silent(E11AndA2::new(p, 1)));
    let fsm = c1_fsm().unwrap();
    let err = Termination::within(300)
        .cases(8)
        .returns_to(&fsm, "B1", Just(c1_memory()), env)
        .unwrap_err();
    let text = err.to_string();
    assert!(text.contains("did not enter `B1` within 300"), "{text}");
    // Shrunk to a plan of two points (one fragment is handed over at the start).
    assert!(text.contains("[(0.00, 0.00), (0.00, 0.00)]"), "{text}");
    assert!(text.contains("ι=299"), "{text}");
}

// ---------------------------------------------------------------------------
// Whole missions.

fn mission(name: &str, plans: Vec<Vec<(f64, f64)>>) -> Mission {
    Mission {
        name: name.into(),
        plans: plans
            .into_iter()
            .map(|p| p.into_iter().map(|(x, y)| Point2 { x, y }).collect())
            .collect(),
    }
}

/// The figure eight without visual odometry, the whole floor `surface` (no patches).
fn figure_eight_on(surface: &str) -> RexConfig {
    let mut config = RexConfig::new(
        WorldConfig::shipped().unwrap(),
        Mission::shipped("figure_eight").unwrap(),
    );
    config.world.surfaces.default = surface.into();
    config.world.surfaces.patches.clear();
    config.visual_odometry = false;
    config
}

fn run(config: &RexConfig, seconds: u64) -> Outcome {
    run_mission(
        config,
        Duration::from_secs(seconds),
        Duration::from_secs(3600),
        |_| {},
    )
    .unwrap()
}

fn short() -> RexConfig {
    let m = mission(
        "short",
        vec![
            vec![(1.0, 0.0), (1.5, 0.5)],
            vec![(1.0, 1.0), (0.0, 1.0), (0.0, 0.0)],
        ],
    );
    RexConfig::new(WorldConfig::shipped().unwrap(), m)
}

#[test]
fn a_short_mission_is_tracked_within_the_bound() {
    let out = run(&short(), 120);
    assert!(out.completed, "{}", out.summary_line());
    assert_eq!(out.plans_done(), 2, "{:?}", out.acks);
    assert_eq!(out.acks.len(), 2, "one final ack per plan");
    assert_eq!(out.counters.fragments_completed, 5);
    assert_eq!(out.counters.executor_errors, 0);
    // The baseline tracker's bound (the shipped missions give 2.3-3.1 cm RMS, at
    // most 8.6 cm). This plan is harder: its fragment 2.0 is nearly a turn in place,
    // where the kinematic tracking law has no authority over the cross-track error.
    assert!(out.rms() < 0.05, "{}", out.summary_line());
    assert!(out.max_error() < 0.10, "{}", out.summary_line());
    // Visual odometry ran on every pair the camera took, each after the first
    // gave a motion, but the last pair's may still be in the odometry when the
    // run ends (its motion leaves up to `vo_latency` steps later).
    let (pairs, motions, none) = out.counters.vo;
    assert!(pairs > 50, "{pairs} pairs");
    assert_eq!(none, 0);
    assert!(
        motions == pairs - 1 || motions == pairs - 2,
        "{motions} motions from {pairs} pairs"
    );
    // The platform ends at the last point of the last plan.
    let last = out.samples.last().unwrap();
    assert!(
        last.truth[0].hypot(last.truth[1]) < 0.05,
        "{:?}",
        last.truth
    );
}

#[test]
fn runs_are_deterministic_with_the_planning_thread() {
    let mut config = short();
    config.mission.plans.truncate(1);
    let a = run(&config, 30);
    let b = run(&config, 30);
    assert!(a.completed);
    assert_eq!(a.samples, b.samples);
    assert_eq!(a.acks, b.acks);
    let mut inline = config.clone();
    inline.runtime = Runtime::Inline;
    assert_eq!(
        run(&inline, 30).samples,
        a.samples,
        "thread or inline: same run"
    );
}

#[test]
fn rendering_and_odometry_on_worker_threads_leave_the_trace_bit_identical() {
    // Every FSM step, action and buffer transfer (with its value: the images, the
    // motions, the torques), with the camera and r11 on worker threads or inline.
    let mut config = short();
    config.mission.plans.truncate(1);
    assert!(config.visual_odometry && config.vo_latency > 0);
    let trace = |vision| {
        let config = RexConfig {
            vision,
            ..config.clone()
        };
        let (out, recorder) = run_mission_observed(
            &config,
            Duration::from_secs(4),
            Duration::from_secs(3600),
            |_| Ok(Recorder::new()),
            |_| {},
        )
        .unwrap();
        assert!(out.counters.vo.1 > 10, "motions: {:?}", out.counters.vo);
        recorder.into_trace()
    };
    let worker = trace(OffloadMode::Worker);
    assert!(
        worker.events.len() > 10_000,
        "{} events",
        worker.events.len()
    );
    assert_eq!(worker.first_difference(&trace(OffloadMode::Inline)), None);
}

#[test]
fn bad_plans_are_refused_and_reported_to_a2() {
    let m = mission(
        "bad",
        vec![
            vec![],
            vec![(1.0, f64::NAN)],
            vec![(1.0, 0.0), (40.0, 0.0)],
            vec![(0.5, 0.0)],
        ],
    );
    let out = run(&RexConfig::new(WorldConfig::shipped().unwrap(), m), 60);
    assert!(out.completed, "{}", out.summary_line());
    let status: Vec<&AckStatus> = out.acks.iter().map(|(_, a)| &a.status).collect();
    assert_eq!(status.len(), 4);
    let refused =
        |s: &AckStatus, what: &str| matches!(s, AckStatus::Refused(r) if r.contains(what));
    assert!(refused(status[0], "no points"), "{:?}", status[0]);
    assert!(refused(status[1], "not finite"), "{:?}", status[1]);
    assert!(refused(status[2], "off the map"), "{:?}", status[2]);
    assert_eq!(status[3], &AckStatus::Done);
    assert_eq!(
        out.counters.fragments_completed, 1,
        "only the good plan moved"
    );
}

#[test]
fn a_planner_failure_holds_position_and_is_reported() {
    let mut config = RexConfig::new(
        WorldConfig::shipped().unwrap(),
        mission("fail", vec![vec![(2.0, 0.0)], vec![(1.0, 0.0)]]),
    );
    // A speed bound no fragment can respect: the planner gives up.
    config.planner_settings.speed_max = 1e-4;
    let out = run(&config, 30);
    assert!(out.completed, "{} {:?}", out.summary_line(), out.acks);
    assert_eq!(out.acks.len(), 2);
    for (_, ack) in &out.acks {
        assert!(
            matches!(&ack.status, AckStatus::Failed(m) if m.contains("more than the 60.0 s allowed")),
            "{ack:?}"
        );
    }
    assert_eq!(out.counters.planner_failures, 2);
    assert_eq!(out.counters.fragments_received, 0);
    let last = out.samples.last().unwrap();
    assert!(
        last.truth[0].hypot(last.truth[1]) < 0.02,
        "held at the start: {:?}",
        last.truth
    );
}

#[test]
fn the_baseline_pair_runs_the_same_mission() {
    // Tracker and estimator are a configuration value; nothing else changes. And
    // a1 without its virtual receptor (the spec's `simulation_without_vo`).
    let mut config = short();
    config.tracker = rex_agent::a1::e11::TrackerKind::Backstepping;
    config.estimator = rex_agent::a1::e11::EstimatorKind::Ekf;
    config.visual_odometry = false;
    let out = run(&config, 120);
    assert!(out.completed, "{}", out.summary_line());
    assert_eq!(out.plans_done(), 2);
    assert_eq!(
        out.parts[1..],
        ["backstepping".to_owned(), "ekf".to_owned()]
    );
    assert_eq!(out.counters.vo, (0, 0, 0), "no visual odometry");
    assert!(out.rms() < 0.05, "{}", out.summary_line());
}

#[test]
fn nmpc_and_mhe_ride_out_motion_capture_dropouts_of_seconds() {
    let mut config = short();
    // Dropouts of 3 s, starting often: the MHE bridges them on encoders and gyro.
    config.world.mocap.dropout_length = 3.0;
    config.world.mocap.dropout_rate = 0.02;
    let out = run(&config, 120);
    assert!(out.completed, "{}", out.summary_line());
    assert_eq!(out.plans_done(), 2);
    assert_eq!(out.parts[1..], ["nmpc".to_owned(), "mhe".to_owned()]);
    assert_eq!(out.counters.tracker.failures, 0);
    let (delivered, dropped) = out.counters.mocap;
    assert!(
        dropped > delivered / 2,
        "dropouts happened: {delivered} delivered, {dropped} dropped"
    );
    assert!(out.rms() < 0.08, "{}", out.summary_line());
    assert!(
        out.estimate_rms() < 0.05,
        "estimate rms {}",
        out.estimate_rms()
    );
}

// ---------------------------------------------------------------------------
// Outcomes: no success reported that was not achieved.

#[test]
fn a_platform_that_cannot_move_fails_its_plans_with_the_reason() {
    // A 1e30 kg platform never moves: before, both plans were acknowledged `Done`
    // and the run succeeded. e11 stops it (its reference runs away), every plan
    // fails with the reason, and the run does not succeed. The first plan is
    // stopped; by the second, the MHE has concluded from the wheels turning
    // without moving the platform that the ground takes almost no traction
    // (μ_x at its lower bound), and c1 fails the plan before handing it over.
    let mut config = short();
    config.world.platform.mass = 1e30;
    config.visual_odometry = false;
    let out = run(&config, 60);
    assert!(out.completed, "{}", out.summary_line());
    assert!(!out.succeeded());
    assert_eq!(out.plans_achieved(), 0, "{:#?}", out.reports);
    assert_eq!(out.false_done(), 0);
    assert_eq!(out.reports.len(), 2, "{:#?}", out.reports);
    assert!(
        matches!(&out.reports[0].verdict, Verdict::Failed(why) if why.contains("stopped")),
        "{}",
        out.reports[0]
    );
    assert!(
        matches!(&out.reports[1].verdict, Verdict::Failed(why)
            if why.contains("stopped") || why.contains("cannot deliver fragment")),
        "{}",
        out.reports[1]
    );
    assert!(!out.counters.stops.is_empty());
    assert!(
        out.summary_line().contains("plans_acked=0/2"),
        "{}",
        out.summary_line()
    );
}

#[test]
fn on_ice_no_plan_is_reported_achieved_that_was_not() {
    // On ice the trackers cannot follow the plans: the plans end as failures (or
    // achievements the truth confirms), never as unconfirmed successes.
    let config = figure_eight_on("ice");
    let out = run(&config, 300);
    assert!(out.completed, "{}", out.summary_line());
    assert_eq!(out.false_done(), 0, "{:#?}", out.reports);
    for r in &out.reports {
        assert!(
            matches!(r.verdict, Verdict::Achieved | Verdict::Failed(_)),
            "{r}"
        );
    }
    // A failure is reported as such, with the truth measured beside it.
    for r in out
        .reports
        .iter()
        .filter(|r| r.verdict != Verdict::Achieved)
    {
        assert!(r.ack.is_some() || r.outcome.is_some(), "{r}");
    }
}

#[test]
fn a_plan_that_ends_where_ice_begins_is_claimed_only_once_the_estimate_keeps_to_the_poses() {
    // The slalom on ice with concrete beyond x = 0, sensor seed 3 (one of
    // bench_friction's runs): plan 2 ends on the line, the platform slides on
    // past its end onto the ice, and the MHE, still on concrete's friction,
    // has its estimate stop with the wheels, 6.5 cm off. With the margin for
    // the estimate's error alone, e1,1 reported the plan reached there with
    // the platform 0.102 m from its end (the tolerance: 0.10 m). It waits now,
    // holding the point, until its estimate keeps to the motion capture.
    let settings = RunSettings {
        mission: "slalom".into(),
        surface: Some("ice".into()),
        tracker: TrackerKind::Nmpc,
        estimator: EstimatorKind::Mhe,
        visual_odometry: false,
        ..RunSettings::default()
    };
    let mut config = settings.resolve(std::path::Path::new(".")).unwrap();
    config.world.sensors.seed = 3;
    config.world.surfaces.patches = vec![Patch {
        surface: "concrete".into(),
        region: Region::Rect {
            x0: 0.0,
            y0: -50.0,
            x1: 50.0,
            y1: 50.0,
        },
    }];
    let out = run(&config, 600);
    assert_eq!(out.false_done(), 0, "{:#?}", out.reports);
    let report = out.reports.iter().find(|r| r.plan == 2).unwrap();
    assert!(
        matches!(report.outcome, Some((_, Execution::Reached { .. }))),
        "{report}"
    );
    assert!(report.end_error_m.is_some_and(|e| e < 0.1), "{report}");
}

#[test]
fn a_plan_the_ground_cannot_deliver_fails_with_the_reason() {
    // Fragments are timed for the cautious ground until the estimate settles.
    // On one of glass (μ 0.001) with fragments allowed 5% of the traction, the
    // first fragment would take about 25 times longer: more than the longest
    // fragment allowed (60 s). c1 fails the plan with the reason at hand-over,
    // before the platform moves, and does not acknowledge it done.
    let mut config = short();
    config.visual_odometry = false;
    config.limits.cautious_ground = Friction {
        mu_long: 0.001,
        mu_lat: 0.001,
        rolling: 0.0,
    };
    config.limits.traction_share = 0.05;
    let out = run(&config, 60);
    assert!(out.completed, "{}", out.summary_line());
    assert!(!out.succeeded());
    assert_eq!(out.plans_achieved(), 0, "{:#?}", out.reports);
    assert_eq!(out.false_done(), 0);
    for r in &out.reports {
        assert!(
            matches!(&r.verdict, Verdict::Failed(why)
                if why.contains("cannot deliver fragment") && why.contains("μ_x 0.00")),
            "{r}"
        );
    }
    // Nothing was handed to e11: the platform did not move.
    let moved = out
        .samples
        .iter()
        .map(|s| s.truth[0].hypot(s.truth[1]))
        .fold(0.0, f64::max);
    assert!(moved < 0.01, "moved {moved} m");
}

#[test]
fn a_platform_pushed_out_of_the_free_space_is_stopped_and_its_plan_failed() {
    // Four seconds into the square, something pushes the platform to 0.35 m from
    // the wall at x = 6 m (e11 keeps 0.45 m): e11 stops it as soon as the motion
    // capture shows it there, plan 1 fails with the reason, and the next plan,
    // which would start from there, is refused by c1's map.
    let mut config = short();
    config.visual_odometry = false;
    let (system, h) = build(&config).unwrap();
    let mut exec = embodied::Executor::new(system, config.exec);
    exec.run_for(Duration::from_secs(4)).unwrap();
    let p = exec.driver_mut(&h.platform).unwrap().plant_mut();
    p.state.x = 5.65;
    p.state.y = 0.0;
    exec.run_for(Duration::from_secs(20)).unwrap();
    let e11 = exec.memory(&h.e11).unwrap();
    let (at, why) = e11.stops.first().cloned().expect("a stop");
    assert!(at < 4.5, "stopped at {at} s");
    assert!(why.contains("not 0.45 m inside the room"), "{why}");
    let c2 = exec.memory(&h.c2).unwrap();
    let failed = |plan: u32| {
        c2.acks
            .iter()
            .any(|a| a.plan == plan && matches!(a.status, AckStatus::Failed(_)))
            || c2.outcomes.iter().any(|o| o.plan == plan && !o.reached())
    };
    assert!(failed(1), "{:?} {:?}", c2.acks, c2.outcomes);
    assert!(failed(2), "{:?} {:?}", c2.acks, c2.outcomes);
    // The platform did not drive on into the wall.
    let x = exec.driver(&h.platform).unwrap().plant().state.x;
    assert!(x < 5.8, "x = {x}");
}

#[test]
fn the_main_job_exits_non_zero_and_names_the_failed_plans() {
    let dir = std::env::temp_dir().join(format!("rex-exit-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let world = dir.join("heavy.ron");
    let shipped = std::fs::read_to_string(
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("config/world.ron"),
    )
    .unwrap();
    std::fs::write(&world, shipped.replace("mass: 40.0,", "mass: 1e30,")).unwrap();
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_rex"))
        .args([
            "--mission",
            "square",
            "--no-vo",
            "--quiet",
            "--no-report",
            "--world",
        ])
        .arg(&world)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert_eq!(out.status.code(), Some(1), "{text}");
    assert!(
        text.contains("plan 1: FAILED: e11 stopped the platform"),
        "{text}"
    );
    assert!(text.contains("2 of 2 plans not achieved"), "{text}");
    assert!(text.contains("mission=square plans_acked=0/2"), "{text}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn the_mhe_learns_the_friction_of_each_ground_within_five_seconds() {
    // On a uniform floor, from a cautious prior (ice's values) on every ground,
    // the MHE's longitudinal and lateral friction and its rolling resistance
    // come within 15% of the plant's after 5 s of the figure eight, and stay
    // there, sample by sample. Measured (every sample after 5 s): concrete 4.3%,
    // grass 6.6%, ice 4.3%; on ice `μ_x` is biased up, 0.6% on average (1.0%
    // before the wheels' spin-up was read from their encoders, 3.5% before the
    // rolling resistance took its direction from the wheels' spin, 6.1% and
    // single samples 10.4% before the encoders were predicted from the slip of
    // the reading before: see docs/measurements.md); the average is
    // asserted within 5% there. The rolling resistance (a force of 2-8 N on a
    // 40 kg platform): on average −0.8%, −0.3%, −4.3%, single samples within
    // 1.3%, 2.4%, 5.1% (on ice 6.4% before the spin-up was read, up to 53% off
    // before the model took its direction from the wheels' spin, its walk
    // became relative and the encoders were predicted as they count, over
    // their window).
    for surface in ["concrete", "grass", "ice"] {
        let mut config = figure_eight_on(surface);
        config.tracker = rex_agent::a1::e11::TrackerKind::Nmpc;
        config.estimator = rex_agent::a1::e11::EstimatorKind::Mhe;
        let plant = config
            .world
            .surfaces
            .surfaces
            .iter()
            .find(|s| s.name == surface)
            .map(|s| s.friction())
            .unwrap();
        let out = run(&config, 120);
        let start = out
            .samples
            .iter()
            .find(|s| s.tau.iter().any(|t| *t != 0.0))
            .map_or(0.0, |s| s.t);
        let after: Vec<Friction> = out
            .samples
            .iter()
            .filter(|s| s.t >= start + 5.0)
            .map(|s| Friction::from_array(s.friction))
            .collect();
        assert!(after.len() > 200, "{surface}: {} samples", after.len());
        for (k, e) in after.iter().enumerate() {
            assert!(
                e.friction_error(&plant) <= 0.15,
                "{surface}: {e:?} at sample {k} after 5 s, the plant's {plant:?}"
            );
            assert!(
                (e.rolling / plant.rolling - 1.0).abs() <= 0.15,
                "{surface}: rolling resistance {e:?} at sample {k} after 5 s, the plant's {plant:?}"
            );
        }
        let n = after.len() as f64;
        let mean = Friction::from_array(std::array::from_fn(|i| {
            after.iter().map(|e| e.to_array()[i]).sum::<f64>() / n
        }));
        let average = if surface == "ice" { 0.05 } else { 0.15 };
        assert!(
            mean.friction_error(&plant) <= average,
            "{surface}: on average {mean:?}, the plant's {plant:?}"
        );
        // The summary reports the estimate.
        let summary = rex_agent::report::summary(&out);
        assert!(summary.contains("friction_estimate mu_long="), "{summary}");
    }
}

#[test]
fn the_mhe_follows_a_change_of_ground_and_no_plan_is_reported_achieved_that_was_not() {
    // Ice, and concrete beyond x = 1 m: the figure eight settles on the ice
    // for 5 s, then runs onto the concrete, the direction the friction's walk
    // (relative to the estimate, 1% of ice's 0.1 a sample) would follow
    // slowest. The encoders then disagree with the model and the walk widens
    // until the estimate has followed: measured within 15% of concrete's
    // 2.35 s after the robot's centre crossed (its wheels cross over a while);
    // with the walk not widened (`FrictionWalk::GAIN` 0) it never came within
    // 15% and both plans failed.
    let mut config = figure_eight_on("ice");
    config.world.surfaces.patches = vec![Patch {
        surface: "concrete".into(),
        region: Region::Rect {
            x0: 1.0,
            y0: -50.0,
            x1: 50.0,
            y1: 50.0,
        },
    }];
    config.tracker = rex_agent::a1::e11::TrackerKind::Nmpc;
    config.estimator = rex_agent::a1::e11::EstimatorKind::Mhe;
    let map = config.world.surfaces.clone();
    let concrete = map
        .surfaces
        .iter()
        .find(|s| s.name == "concrete")
        .unwrap()
        .friction();
    let out = run(&config, 150);
    assert_eq!(out.false_done(), 0, "{:#?}", out.reports);
    let ground =
        |s: &rex_agent::run::Sample| map.at(s.truth[0], s.truth[1]).map(|g| g.name.clone());
    let crossed = out
        .samples
        .iter()
        .find(|s| ground(s).as_deref() == Some("concrete"))
        .expect("the robot reaches the concrete")
        .t;
    assert!(crossed > 5.0, "{crossed}");
    let followed = out
        .samples
        .iter()
        .filter(|s| s.t >= crossed)
        .find(|s| Friction::from_array(s.friction).friction_error(&concrete) <= 0.15)
        .map(|s| s.t - crossed);
    assert!(
        followed.is_some_and(|dt| dt <= 3.0),
        "the estimate came within 15% of concrete's {followed:?} s after the crossing"
    );
}
