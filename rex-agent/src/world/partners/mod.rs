//! The partner agents of the locomotion agent (the paper's Fig. 3), as real agents of
//! the framework:
//!
//! * `a2`, the ontology agent: its control subsystem `c2` sends the plans of a
//!   mission one by one, each after the previous one was acknowledged (`Done`, the
//!   paper's early acknowledgement, or a refusal or failure), keeps how each plan's
//!   execution ended (`outcome`), and ends when every plan sent has ended;
//! * `a3`, the map agent: the motion-capture system `R3` (a real receptor), its
//!   virtual receptor `r31` that rejects implausible poses, and the control subsystem
//!   `c3` that sends the pose on the map to `a1` and keeps `a1`'s state estimate.

use embodied::{
    Action, ActionError, Behaviour, Buffers, Fsm, FsmBuildError, Group, In, Memory, Out, Subsystem,
};

use crate::a1::payload::{Ack, AckStatus, MapPose, Plan, PlanOutcome, State};
use crate::mission::Mission;

// ---------------------------------------------------------------------------
// a2: the ontology agent

/// The control subsystem `c2` of the ontology agent.
#[derive(Subsystem)]
#[subsystem(kind = Control, memory = OntologyMemory, input = OntologyInput, output = OntologyOutput)]
pub struct Ontology;

/// `c2`'s memory.
#[derive(Clone, Debug, Default, Memory)]
pub struct OntologyMemory {
    /// The plans to send.
    pub mission: Mission,
    /// Index of the next plan to send.
    pub next: usize,
    /// The acknowledgements received, in order.
    pub acks: Vec<Ack>,
    /// How the execution of plans ended, in the order reported.
    pub outcomes: Vec<PlanOutcome>,
}

impl OntologyMemory {
    /// A memory holding `mission`, nothing sent yet.
    pub fn new(mission: Mission) -> Self {
        OntologyMemory {
            mission,
            next: 0,
            acks: Vec::new(),
            outcomes: Vec::new(),
        }
    }

    /// Whether every plan sent has ended: refused, failed, or its execution
    /// reported.
    pub fn settled(&self) -> bool {
        let sent = self.next as u32;
        (1..=sent).all(|id| {
            self.outcomes.iter().any(|o| o.plan == id)
                || self.acks.iter().any(|a| {
                    a.plan == id && matches!(a.status, AckStatus::Refused(_) | AckStatus::Failed(_))
                })
        })
    }

    /// The id of the last plan sent.
    fn last_sent(&self) -> Option<u32> {
        self.next.checked_sub(1).map(|k| k as u32 + 1)
    }
}

/// `c2`'s inputs from `c1`.
#[derive(Clone, Debug, Default, Group)]
#[group(peer = Control)]
pub struct OntologyFromC1 {
    /// The acknowledgement of a plan.
    pub ack: In<Ack>,
    /// How a plan's execution ended.
    pub outcome: In<PlanOutcome>,
}

/// `c2`'s inputs.
#[derive(Clone, Debug, Default, Buffers)]
pub struct OntologyInput {
    /// From `c1`.
    pub c1: OntologyFromC1,
}

/// `c2`'s outputs to `c1`.
#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub struct OntologyToC1 {
    /// The plan.
    pub desired_plan: Out<Plan>,
}

/// `c2`'s outputs.
#[derive(Debug, Default, Buffers)]
pub struct OntologyOutput {
    /// To `c1`.
    pub c1: OntologyToC1,
}

/// Keep a fresh final acknowledgement and a fresh outcome (every acting behaviour
/// runs it, so none is lost).
fn record(m: &mut OntologyMemory, x: &OntologyInput) {
    if let Some(ack) = x.c1.ack.fresh().filter(|a| a.ready()) {
        m.acks.push(ack.clone());
    }
    if let Some(o) = x.c1.outcome.fresh() {
        m.outcomes.push(o.clone());
    }
}

/// The FSM of `c2` (as in `specs/rex.ron`): `next_plan` decides, `send` sends one
/// plan, `wait` waits for its acknowledgement, `settle` waits for every plan's
/// outcome after the last one is sent, `done` is final.
pub fn ontology_fsm() -> Result<Fsm<Ontology>, FsmBuildError> {
    Fsm::builder()
        .predicate("more", |m: &OntologyMemory, _| {
            m.next < m.mission.plans.len()
        })
        .predicate("acked", |m: &OntologyMemory, x: &OntologyInput| {
            x.c1.ack
                .fresh()
                .zip(m.last_sent())
                .is_some_and(|(a, id)| a.plan == id && a.ready())
        })
        .behaviour(Behaviour::while_loop(
            "next_plan",
            Action::<Ontology>::new(),
            "true",
        ))
        .behaviour(Behaviour::repeat_loop(
            "send",
            Action::<Ontology>::new()
                .output(
                    |y| &mut y.c1,
                    |m: &OntologyMemory, _: &OntologyInput, y: &mut OntologyToC1| {
                        let plan = m
                            .mission
                            .plan(m.next)
                            .ok_or_else(|| ActionError::failed("no plan left to send"))?;
                        y.desired_plan.set(plan);
                        Ok::<(), ActionError>(())
                    },
                )
                .named("send_plan")
                .memory(|m: &mut OntologyMemory, x: &OntologyInput| {
                    record(m, x);
                    m.next += 1;
                })
                .named("advance"),
            "true",
        ))
        .predicate("settled", |m: &OntologyMemory, _| m.settled())
        .behaviour(Behaviour::while_loop(
            "wait",
            Action::<Ontology>::new().memory(record),
            "acked",
        ))
        .behaviour(Behaviour::while_loop(
            "settle",
            Action::<Ontology>::new().memory(record),
            "settled",
        ))
        .behaviour(Behaviour::repeat_loop(
            "done",
            Action::<Ontology>::new().memory(record),
            "true",
        ))
        .initial("next_plan")
        .arc("next_plan", "send", "more")
        .arc("next_plan", "settle", "!more")
        .arc("send", "wait", "true")
        .arc("wait", "next_plan", "true")
        .arc("settle", "done", "true")
        .final_behaviour("done")
        .build()
}

// ---------------------------------------------------------------------------
// a3: the map agent

/// The virtual receptor `r31` of the map agent: passes on plausible motion-capture
/// poses, rejects and counts the others (non-finite, or a jump no robot makes). A
/// jump that the next poses confirm (`confirm` in a row, consistent with each
/// other) is believed: the robot was moved, the measurement was not wrong.
#[derive(Subsystem)]
#[subsystem(kind = VirtualReceptor, memory = MocapMemory, input = MocapReceptorInput, output = MocapReceptorOutput)]
pub struct MocapReceptor;

/// `r31`'s memory.
#[derive(Clone, Debug, Memory)]
pub struct MocapMemory {
    /// The last pose passed on.
    pub last: Option<MapPose>,
    /// Poses rejected.
    pub rejected: u64,
    /// Largest plausible speed [m/s]: a faster jump is rejected.
    pub max_speed: f64,
    /// The latest pose rejected as a jump, and how many consistent ones in a row.
    pub candidate: Option<(MapPose, u32)>,
    /// A jump confirmed by this many consistent poses in a row is passed on.
    pub confirm: u32,
}

impl Default for MocapMemory {
    fn default() -> Self {
        MocapMemory {
            last: None,
            rejected: 0,
            max_speed: 0.0,
            candidate: None,
            confirm: 3,
        }
    }
}

/// `r31`'s input from `R3`.
#[derive(Clone, Debug, Default, Group)]
#[group(peer = RealReceptor)]
pub struct MocapFromR3 {
    /// A measured pose.
    pub pose: In<MapPose>,
}

/// `r31`'s inputs.
#[derive(Clone, Debug, Default, Buffers)]
#[expect(
    non_snake_case,
    reason = "groups are named after their peer component, R3"
)]
pub struct MocapReceptorInput {
    /// From `R3`.
    pub R3: MocapFromR3,
}

/// `r31`'s output to `c3`.
#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub struct MocapToC3 {
    /// A plausible pose.
    pub pose: Out<MapPose>,
}

/// `r31`'s outputs.
#[derive(Debug, Default, Buffers)]
pub struct MocapReceptorOutput {
    /// To `c3`.
    pub c3: MocapToC3,
}

impl MocapMemory {
    /// Whether `p` follows `from` as a robot can move.
    fn follows(&self, from: &MapPose, p: &MapPose) -> bool {
        let d = (p.pose.x - from.pose.x).hypot(p.pose.y - from.pose.y);
        p.time > from.time && d <= self.max_speed * (p.time - from.time) + 0.05
    }

    /// Whether `p` is consistent with the run of rejected poses before it.
    fn continues_jump(&self, p: &MapPose) -> Option<u32> {
        self.candidate
            .filter(|(c, _)| self.follows(c, p))
            .map(|(_, n)| n + 1)
    }

    fn plausible(&self, p: &MapPose) -> bool {
        if !(p.pose.is_finite() && p.time.is_finite()) {
            return false;
        }
        match &self.last {
            Some(last) => {
                self.follows(last, p) || self.continues_jump(p).is_some_and(|n| n >= self.confirm)
            }
            None => true,
        }
    }

    /// Keep what `p` teaches (run after `plausible` decided what to pass on).
    fn learn(&mut self, p: &MapPose) {
        if self.plausible(p) {
            self.last = Some(*p);
            self.candidate = None;
        } else {
            self.rejected += 1;
            if p.pose.is_finite() && p.time.is_finite() {
                self.candidate = Some((*p, self.continues_jump(p).unwrap_or(1)));
            }
        }
    }
}

/// The FSM of `r31`: one behaviour that never ends.
pub fn mocap_receptor_fsm() -> Result<Fsm<MocapReceptor>, FsmBuildError> {
    Fsm::single(Behaviour::while_loop(
        "filter",
        Action::<MocapReceptor>::new()
            .output(
                |y| &mut y.c3,
                |m: &MocapMemory, x: &MocapReceptorInput, y: &mut MocapToC3| {
                    if let Some(p) = x.R3.pose.fresh().filter(|p| m.plausible(p)) {
                        y.pose.set(*p);
                    }
                },
            )
            .named("pass")
            .memory(|m: &mut MocapMemory, x: &MocapReceptorInput| {
                if let Some(p) = x.R3.pose.fresh() {
                    m.learn(p);
                }
            })
            .named("check"),
        "false",
    ))
}

/// The control subsystem `c3` of the map agent.
#[derive(Subsystem)]
#[subsystem(kind = Control, memory = MapMemory, input = MapInput, output = MapOutput)]
pub struct MapAgent;

/// `c3`'s memory.
#[derive(Clone, Debug, Default, Memory)]
pub struct MapMemory {
    /// The last pose sent to `a1`.
    pub pose: Option<MapPose>,
    /// The last state estimate received from `a1`.
    pub estimate: Option<State>,
    /// Poses sent.
    pub sent: u64,
}

/// `c3`'s inputs from `r31`.
#[derive(Clone, Debug, Default, Group)]
#[group(peer = VirtualReceptor)]
pub struct MapFromR31 {
    /// A plausible pose.
    pub pose: In<MapPose>,
}

/// `c3`'s inputs from `c1`.
#[derive(Clone, Debug, Default, Group)]
#[group(peer = Control)]
pub struct MapFromC1 {
    /// `a1`'s state estimate.
    pub q_est: In<State>,
}

/// `c3`'s inputs.
#[derive(Clone, Debug, Default, Buffers)]
pub struct MapInput {
    /// From `r31`.
    pub r31: MapFromR31,
    /// From `c1`.
    pub c1: MapFromC1,
}

/// `c3`'s outputs to `c1`.
#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub struct MapToC1 {
    /// The robot's pose on the map.
    pub pose: Out<MapPose>,
}

/// `c3`'s outputs.
#[derive(Debug, Default, Buffers)]
pub struct MapOutput {
    /// To `c1`.
    pub c1: MapToC1,
}

/// The FSM of `c3`: one behaviour that never ends.
pub fn map_fsm() -> Result<Fsm<MapAgent>, FsmBuildError> {
    Fsm::single(Behaviour::while_loop(
        "publish",
        Action::<MapAgent>::new()
            .output(
                |y| &mut y.c1,
                |_: &MapMemory, x: &MapInput, y: &mut MapToC1| {
                    if let Some(p) = x.r31.pose.fresh() {
                        y.pose.set(*p);
                    }
                },
            )
            .named("send_pose")
            .memory(|m: &mut MapMemory, x: &MapInput| {
                if let Some(p) = x.r31.pose.fresh() {
                    m.pose = Some(*p);
                    m.sent += 1;
                }
                if let Some(q) = x.c1.q_est.fresh().filter(|q| q.is_finite()) {
                    m.estimate = Some(*q);
                }
            })
            .named("keep"),
        "false",
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::a1::payload::{AckStatus, Execution, Point2, Pose2};
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
}
