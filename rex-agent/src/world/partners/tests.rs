//! Unit tests of the partner agents: a2's plans (with a crashing c1), a3's
//! plausibility checks.

use super::*;
use crate::payload::{AckStatus, Execution, Point2, Pose2};
use embodied::testing::{Environment, Termination};
use embodied::{Stamp, Time};
use proptest::prelude::*;

/// A `c1` that acknowledges each plan `delay` activations of `c2` after it was
/// sent (the early `Done`), and reports it reached `delay` activations later.
#[derive(Clone, Debug)]
struct Acker {
    delay: u64,
    pending: Option<(u32, u64)>,
    executing: Vec<(u32, u64)>,
}

impl Environment<Ontology> for Acker {
    fn inputs(&mut self, k: u64, previous: Option<&OntologyOutput>, x: &mut OntologyInput) {
        if let Some(plan) = previous.and_then(|y| y.c1.desired_plan.written()) {
            self.pending = Some((plan.id, k + self.delay));
        }
        match self.pending {
            Some((id, due)) if due <= k => {
                x.c1.ack.deliver(
                    Ack {
                        plan: id,
                        status: AckStatus::Done,
                    },
                    Stamp::new(k, Time::ZERO),
                );
                self.pending = None;
                self.executing.push((id, k + self.delay));
            }
            _ => x.c1.ack.age(),
        }
        // One outcome per activation at most (a queue link delivers one).
        match self.executing.first() {
            Some(&(id, due)) if due <= k => {
                x.c1.outcome.deliver(
                    PlanOutcome {
                        plan: id,
                        epoch: 0,
                        result: Execution::Reached { error_m: 0.01 },
                    },
                    Stamp::new(k, Time::ZERO),
                );
                self.executing.remove(0);
            }
            _ => x.c1.outcome.age(),
        }
    }
}

fn mission(plans: usize) -> Mission {
    Mission {
        name: "test".into(),
        plans: (0..plans)
            .map(|i| {
                vec![
                    Point2 {
                        x: i as f64,
                        y: 0.0,
                    },
                    Point2 { x: 0.0, y: 0.0 },
                ]
            })
            .collect(),
    }
}

#[test]
fn the_ontology_sends_every_plan_and_finishes() {
    let fsm = ontology_fsm().unwrap();
    // For any mission length and acknowledgement delay, `done` is reached within
    // one round (send + wait + decide) per plan.
    let memory = (1usize..6).prop_map(|n| OntologyMemory::new(mission(n)));
    let env = (0u64..10).prop_map(|delay| Acker {
        delay,
        pending: None,
        executing: Vec::new(),
    });
    // ... and the outcome of the last one, `delay` activations after its ack.
    Termination::within(6 * 13 + 2 + 12)
        .cases(64)
        .returns_to(&fsm, "done", memory, env)
        .unwrap();
}

/// A `c1` (with its `e11`) whose process crashes at activation `crash_at`
/// of `c2` and comes back `down` activations later as a new incarnation:
/// what it held is lost. It executes a plan's points one per `step`
/// activations, reporting each as progress, and reports the plan reached
/// after its last point; it acknowledges `Done` (early) when it starts the
/// last point. (The fleet's `c2` is driven by it too, robot by robot.)
pub(crate) struct Crasher {
    step: u64,
    crash_at: u64,
    down: u64,
    boot: u64,
    newest: u32,
    /// The plan being executed: id, next point (in the plan as first sent),
    /// points in all, when the next one is done.
    running: Option<(u32, u32, u32, u64)>,
    /// Plans received and not started.
    waiting: std::collections::VecDeque<Plan>,
    /// Every plan received, as received.
    received: Vec<Plan>,
    /// Points executed to their end, by plan and point.
    pub(crate) executed: Vec<(u32, u32)>,
}

impl Crasher {
    /// A `c1` executing a point every `step` activations, crashing at
    /// `crash_at` for `down` activations, in incarnation `boot` first.
    pub(crate) fn new(step: u64, crash_at: u64, down: u64, boot: u64) -> Self {
        Crasher {
            step,
            crash_at,
            down,
            boot,
            newest: 0,
            running: None,
            waiting: Default::default(),
            received: Vec::new(),
            executed: Vec::new(),
        }
    }

    /// Assert that every plan of `m`'s mission was reached (its outcome in
    /// `m`) and each of its `points` points executed once, in order, and no
    /// fragment reported twice; `at` says which case.
    pub(crate) fn every_plan_reached_once(&self, m: &OntologyMemory, points: u32, at: &str) {
        for id in 1..=m.mission.plans.len() as u32 {
            assert!(
                m.outcomes.iter().any(|o| o.plan == id && o.reached()),
                "{at}: plan {id} not reached; {m:?}"
            );
            let done: Vec<u32> = self
                .executed
                .iter()
                .filter(|e| e.0 == id)
                .map(|e| e.1)
                .collect();
            assert_eq!(done, (0..points).collect::<Vec<_>>(), "{at}, plan {id}");
        }
        assert_eq!(m.repeated, 0, "{at}");
    }

    /// What `c1` sends at activation `k` of `c2`, given what `c2` sent at the
    /// previous one.
    pub(crate) fn inputs(&mut self, k: u64, previous: &OntologyOutput, x: &mut OntologyInput) {
        let up = !(self.crash_at..self.crash_at + self.down).contains(&k);
        if k == self.crash_at {
            self.boot += 1;
            self.newest = 0;
            self.running = None;
            self.waiting.clear();
        }
        x.c1.ack.age();
        x.c1.outcome.age();
        x.c1.progress.age();
        if !up {
            return;
        }
        // As c1 does, a plan id is taken once (a copy is ignored); c1 runs ten
        // times for each activation of c2, so its `alive` has the plan sent in
        // c2's previous activation.
        if let Some(plan) = previous.c1.desired_plan.written() {
            self.received.push(plan.clone());
            if plan.id > self.newest {
                self.newest = plan.id;
                self.waiting.push_back(plan.clone());
            }
        }
        let stamp = Stamp::new(k, Time::ZERO);
        x.c1.alive.deliver(
            Alive {
                boot: self.boot,
                newest: self.newest,
            },
            stamp,
        );
        match self.running {
            None => {
                if let Some(p) = self.waiting.pop_front() {
                    let total = p.first + p.points.len() as u32;
                    self.running = Some((p.id, p.first, total, k + self.step));
                    if p.points.len() == 1 {
                        x.c1.ack.deliver(
                            Ack {
                                plan: p.id,
                                status: AckStatus::Done,
                            },
                            stamp,
                        );
                    }
                }
            }
            Some((id, next, total, due)) if due <= k => {
                self.executed.push((id, next));
                x.c1.progress.deliver(
                    Progress {
                        plan: id,
                        done: next + 1,
                    },
                    stamp,
                );
                if next + 1 == total {
                    self.running = None;
                    x.c1.outcome.deliver(
                        PlanOutcome {
                            plan: id,
                            epoch: 0,
                            result: Execution::Reached { error_m: 0.01 },
                        },
                        stamp,
                    );
                } else {
                    self.running = Some((id, next + 1, total, k + self.step));
                    if next + 2 == total {
                        x.c1.ack.deliver(
                            Ack {
                                plan: id,
                                status: AckStatus::Done,
                            },
                            stamp,
                        );
                    }
                }
            }
            Some(_) => {}
        }
    }
}

#[test]
fn plans_lost_with_a_crashed_c1_are_sent_again_from_where_they_got_to() {
    let fsm = ontology_fsm().unwrap();
    let plans = 3;
    let points = 3;
    let mission = Mission {
        name: "test".into(),
        plans: (0..plans)
            .map(|i| {
                (0..points)
                    .map(|j| Point2 {
                        x: i as f64,
                        y: j as f64,
                    })
                    .collect()
            })
            .collect(),
    };
    // A crash at every moment of the mission (and one after it).
    for crash_at in 0..40 {
        let mut env = Crasher::new(3, crash_at, 4, 7);
        let mut m = OntologyMemory::new(mission.clone());
        let mut st = fsm.start();
        let mut y = OntologyOutput::default();
        let mut k = 0;
        while !st.is_halted() {
            let mut x = OntologyInput::default();
            env.inputs(k, &y, &mut x);
            y = OntologyOutput::default();
            fsm.activate(&mut st, &mut m, &x, &mut y, |_| {}).unwrap();
            k += 1;
            assert!(k < 200, "crash at {crash_at}: no end; {m:?}");
        }
        assert_eq!(m.mission.plans.len(), plans);
        env.every_plan_reached_once(&m, points, &format!("crash at {crash_at}"));
        let crashed = m.restarts > 0;
        assert_eq!(m.restarts, u32::from(crashed));
        // A plan sent again starts after the points known done.
        for p in env.received.iter().filter(|p| p.first > 0) {
            assert!(
                env.executed.contains(&(p.id, p.first - 1)),
                "crash at {crash_at}: {p:?} skips a point not done"
            );
        }
        if crash_at >= k {
            // No crash before the end: nothing was sent twice.
            assert_eq!((m.restarts, m.resent), (0, 0), "crash at {crash_at}");
        }
    }
}

#[test]
fn a_plan_sent_again_that_c1_already_answered_ends_the_wait() {
    // a2 first hears c1 from an `alive` written before c1 had plan 1 (a late
    // message): it sends plan 1 again, c1 ignores the copy, and the
    // acknowledgement c1 sent for the original, arriving while the copy goes
    // out, ends the wait.
    let fsm = ontology_fsm().unwrap();
    let mut m = OntologyMemory::new(mission(2));
    let mut st = fsm.start();
    let stamp = Stamp::new(0, Time::ZERO);
    let mut sent = Vec::new();
    let mut step = |x: &OntologyInput, m: &mut OntologyMemory, st: &mut embodied::FsmState| {
        let mut y = OntologyOutput::default();
        fsm.activate(st, m, x, &mut y, |_| {}).unwrap();
        sent.extend(y.c1.desired_plan.written().map(|p| p.id));
    };
    let mut x = OntologyInput::default();
    step(&x, &mut m, &mut st); // plan 1 sent
    let stale = Alive { boot: 5, newest: 0 };
    x.c1.alive.deliver(stale, stamp);
    step(&x, &mut m, &mut st); // heard: c1 has no plan; plan 1 is lost
    assert!(m.lost && m.next == 0, "{m:?}");
    x.c1.ack.deliver(
        Ack {
            plan: 1,
            status: AckStatus::Done,
        },
        stamp,
    );
    step(&x, &mut m, &mut st); // plan 1 again; the original's ack arrives
    x.c1.ack.age();
    for _ in 0..4 {
        step(&x, &mut m, &mut st);
    }
    assert_eq!(sent, [1, 1, 2], "the wait for plan 1 ended: {m:?}");
    assert_eq!((m.restarts, m.resent), (0, 1));
}

/// What `c1` says of a plan another sender (ROS 2) gave it: its
/// acknowledgements, progress and outcome, one kind per activation of `c2`,
/// as the queue links deliver them.
fn foreign_reports(id: u32) -> Vec<OntologyInput> {
    let stamp = Stamp::new(0, Time::ZERO);
    let mut xs = Vec::new();
    let mut with = |f: &dyn Fn(&mut OntologyInput)| {
        let mut x = OntologyInput::default();
        x.c1.alive.deliver(
            Alive {
                boot: 0,
                newest: id,
            },
            stamp,
        );
        f(&mut x);
        xs.push(x);
    };
    let ack = |status: AckStatus| Ack { plan: id, status };
    with(&|x| x.c1.ack.deliver(ack(AckStatus::Received), stamp));
    with(&|x| x.c1.progress.deliver(Progress { plan: id, done: 1 }, stamp));
    with(&|x| x.c1.ack.deliver(ack(AckStatus::Done), stamp));
    // The same progress twice (a repeat, were the plan a2's).
    with(&|x| x.c1.progress.deliver(Progress { plan: id, done: 1 }, stamp));
    with(&|x| {
        x.c1.outcome.deliver(
            PlanOutcome {
                plan: id,
                epoch: 0,
                result: Execution::Reached { error_m: 0.02 },
            },
            stamp,
        );
    });
    xs
}

#[test]
fn a_listening_c2_sends_nothing_never_halts_and_keeps_what_c1_says_of_others_plans() {
    let fsm = ontology_fsm().unwrap();
    let mut m = OntologyMemory::new(Mission::shipped(Mission::LISTEN).unwrap());
    let mut st = fsm.start();
    let quiet = OntologyInput::default();
    let mut inputs: Vec<OntologyInput> = (0..5).map(|_| quiet.clone()).collect();
    inputs.extend(foreign_reports(7));
    inputs.extend((0..5).map(|_| quiet.clone()));
    inputs.extend(foreign_reports(8));
    inputs.extend((0..50).map(|_| quiet.clone()));
    for (k, x) in inputs.iter().enumerate() {
        let mut y = OntologyOutput::default();
        fsm.activate(&mut st, &mut m, x, &mut y, |_| {}).unwrap();
        assert_eq!(y.c1.desired_plan.written(), None, "activation {k}: {m:?}");
        assert!(!st.is_halted(), "activation {k}: a listening c2 halted");
        assert_eq!(
            fsm.behaviour_name(st.behaviour()),
            "settle",
            "activation {k}"
        );
    }
    // Kept for the watcher, in order (the final acknowledgements only)...
    let acks: Vec<(u32, AckStatus)> = m.acks.iter().map(|a| (a.plan, a.status.clone())).collect();
    assert_eq!(acks, [(7, AckStatus::Done), (8, AckStatus::Done)]);
    let outcomes: Vec<u32> = m.outcomes.iter().map(|o| o.plan).collect();
    assert_eq!(outcomes, [7, 8]);
    // ... but never counted as a2's: no plan sent, answered, or to resume.
    assert_eq!(m.next, 0);
    assert!(m.answered.is_empty() && m.done.is_empty(), "{m:?}");
    assert_eq!((m.repeated, m.restarts, m.resent), (0, 0, 0));
    assert!(!m.lost && !m.settled());
}

#[test]
fn a_foreign_plans_reports_do_not_end_a2s_wait_or_count_as_its_own() {
    // a2 sends plan 1 of 2 and waits; c1 reports on plan 3, another sender's
    // (the reports cross a2's wait): a2 still waits for plan 1, then sends
    // plan 2 after plan 1's own acknowledgement, and settles on its own plans.
    let fsm = ontology_fsm().unwrap();
    let mut m = OntologyMemory::new(mission(2));
    let mut st = fsm.start();
    let stamp = Stamp::new(0, Time::ZERO);
    let sent = std::cell::RefCell::new(Vec::new());
    let step = |x: &OntologyInput, m: &mut OntologyMemory, st: &mut embodied::FsmState| {
        let mut y = OntologyOutput::default();
        fsm.activate(st, m, x, &mut y, |_| {}).unwrap();
        sent.borrow_mut()
            .extend(y.c1.desired_plan.written().map(|p| p.id));
    };
    step(&OntologyInput::default(), &mut m, &mut st); // plan 1 sent
    for x in foreign_reports(3) {
        step(&x, &mut m, &mut st);
    }
    assert_eq!(*sent.borrow(), [1], "a2 waits for plan 1: {m:?}");
    assert!(m.answered.is_empty() && m.done.is_empty() && m.repeated == 0);
    let own = |plan: u32| {
        let mut x = OntologyInput::default();
        x.c1.ack.deliver(
            Ack {
                plan,
                status: AckStatus::Done,
            },
            stamp,
        );
        x
    };
    step(&own(1), &mut m, &mut st);
    for _ in 0..3 {
        step(&OntologyInput::default(), &mut m, &mut st);
    }
    assert_eq!(*sent.borrow(), [1, 2], "{m:?}");
    // Plan 3's outcome is in, a2's are not: not settled.
    assert!(!m.settled() && !st.is_halted());
    step(&own(2), &mut m, &mut st);
    for plan in [1, 2] {
        let mut x = OntologyInput::default();
        x.c1.outcome.deliver(
            PlanOutcome {
                plan,
                epoch: 0,
                result: Execution::Reached { error_m: 0.01 },
            },
            stamp,
        );
        step(&x, &mut m, &mut st);
    }
    for _ in 0..3 {
        step(&OntologyInput::default(), &mut m, &mut st);
    }
    assert!(m.settled() && st.is_halted(), "{m:?}");
    assert_eq!(m.answered, BTreeSet::from([1, 2]));
    let acked: Vec<u32> = m.acks.iter().map(|a| a.plan).collect();
    assert_eq!(acked, [3, 1, 2], "every final acknowledgement is kept");
}

/// A pose at `(x, 0, 0)` describing `time`.
fn at(x: f64, time: f64) -> MapPose {
    MapPose {
        pose: Pose2 {
            x,
            y: 0.0,
            phi: 0.0,
        },
        time,
    }
}

#[test]
fn implausible_poses_are_rejected() {
    let mut m = MocapMemory {
        max_speed: 2.0,
        ..MocapMemory::default()
    };
    assert!(m.plausible(&at(0.0, 0.0)));
    m.last = Some(at(0.0, 0.0));
    assert!(m.plausible(&at(0.1, 0.1)));
    assert!(!m.plausible(&at(5.0, 0.1)), "50 m/s");
    assert!(!m.plausible(&at(f64::NAN, 0.2)));
    assert!(!m.plausible(&at(0.0, -1.0)), "older than the last");
}

#[test]
fn a_jump_the_next_poses_confirm_is_believed() {
    // A robot carried 4 m away: the first poses there are rejected, the third
    // in a row that agree with each other is passed on; a lone outlier is not.
    let mut m = MocapMemory {
        max_speed: 2.0,
        ..MocapMemory::default()
    };
    m.learn(&at(0.0, 0.0));
    m.learn(&at(9.0, 0.01));
    assert!(m.plausible(&at(0.01, 0.02)), "a lone outlier");
    m.learn(&at(0.01, 0.02));
    let passed: Vec<bool> = (3..8)
        .map(|k| {
            let p = at(4.0 + 0.001 * f64::from(k), 0.01 * f64::from(k));
            let pass = m.plausible(&p);
            m.learn(&p);
            pass
        })
        .collect();
    assert_eq!(passed, [false, false, true, true, true]);
    assert_eq!(m.rejected, 3);
}
