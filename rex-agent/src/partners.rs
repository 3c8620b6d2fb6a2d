//! The partner agents of the locomotion agent (the paper's Fig. 3), as real agents of
//! the framework:
//!
//! * `a2`, the ontology agent: its control subsystem `c2` sends the plans of a
//!   mission one by one, each after the previous one was acknowledged;
//! * `a3`, the map agent: the motion-capture system `R3` (a real receptor), its
//!   virtual receptor `r31` that rejects implausible poses, and the control subsystem
//!   `c3` that sends the pose on the map to `a1` and keeps `a1`'s state estimate.

use embodied::{
    Action, ActionError, Behaviour, Fsm, FsmBuildError, Group, In, NodeKind, Out, Subsystem,
    SubsystemKind,
};

use crate::mission::Mission;
use crate::types::{Ack, MapPose, Plan, State};

// ---------------------------------------------------------------------------
// a2: the ontology agent

/// The control subsystem `c2` of the ontology agent.
pub struct Ontology;

/// `c2`'s memory.
#[derive(Clone, Debug, Default)]
pub struct OntologyMemory {
    /// The plans to send.
    pub mission: Mission,
    /// Index of the next plan to send.
    pub next: usize,
    /// The acknowledgements received, in order.
    pub acks: Vec<Ack>,
}

impl OntologyMemory {
    /// A memory holding `mission`, nothing sent yet.
    pub fn new(mission: Mission) -> Self {
        OntologyMemory {
            mission,
            next: 0,
            acks: Vec::new(),
        }
    }

    /// The id of the last plan sent.
    fn last_sent(&self) -> Option<u32> {
        self.next.checked_sub(1).map(|k| k as u32 + 1)
    }
}

/// `c2`'s inputs from `c1`.
#[derive(Clone, Debug, Default)]
pub struct OntologyFromC1 {
    /// The acknowledgement of a plan.
    pub ack: In<Ack>,
}
impl Group for OntologyFromC1 {
    const PEER: NodeKind = NodeKind::Control;
}

/// `c2`'s inputs.
#[derive(Clone, Debug, Default)]
pub struct OntologyInput {
    /// From `c1`.
    pub c1: OntologyFromC1,
}

/// `c2`'s outputs to `c1`.
#[derive(Debug, Default)]
pub struct OntologyToC1 {
    /// The plan.
    pub desired_plan: Out<Plan>,
}
impl Group for OntologyToC1 {
    const PEER: NodeKind = NodeKind::Control;
}

/// `c2`'s outputs.
#[derive(Debug, Default)]
pub struct OntologyOutput {
    /// To `c1`.
    pub c1: OntologyToC1,
}

impl Subsystem for Ontology {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = OntologyMemory;
    type Input = OntologyInput;
    type Output = OntologyOutput;
}

/// Keep a fresh final acknowledgement (run by the behaviour that follows `wait`, in
/// the activation in which the acknowledgement arrives).
fn record(m: &mut OntologyMemory, x: &OntologyInput) {
    if let Some(ack) = x.c1.ack.fresh().filter(|a| a.ready()) {
        m.acks.push(ack.clone());
    }
}

/// The FSM of `c2` (as in `specs/rex.ron`): `next_plan` decides, `send` sends one
/// plan, `wait` waits for its acknowledgement, `done` is final.
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
                .memory(|m: &mut OntologyMemory, x: &OntologyInput| {
                    record(m, x);
                    m.next += 1;
                }),
            "true",
        ))
        .behaviour(Behaviour::while_loop(
            "wait",
            Action::<Ontology>::new(),
            "acked",
        ))
        .behaviour(Behaviour::repeat_loop(
            "done",
            Action::<Ontology>::new().memory(record),
            "true",
        ))
        .initial("next_plan")
        .arc("next_plan", "send", "more")
        .arc("next_plan", "done", "!more")
        .arc("send", "wait", "true")
        .arc("wait", "next_plan", "true")
        .final_behaviour("done")
        .build()
}

// ---------------------------------------------------------------------------
// a3: the map agent

/// The virtual receptor `r31` of the map agent: passes on plausible motion-capture
/// poses, rejects and counts the others (non-finite, or a jump no robot makes).
pub struct MocapReceptor;

/// `r31`'s memory.
#[derive(Clone, Debug, Default)]
pub struct MocapMemory {
    /// The last pose passed on.
    pub last: Option<MapPose>,
    /// Poses rejected.
    pub rejected: u64,
    /// Largest plausible speed [m/s]: a faster jump is rejected.
    pub max_speed: f64,
}

/// `r31`'s input from `R3`.
#[derive(Clone, Debug, Default)]
pub struct MocapFromR3 {
    /// A measured pose.
    pub pose: In<MapPose>,
}
impl Group for MocapFromR3 {
    const PEER: NodeKind = NodeKind::RealReceptor;
}

/// `r31`'s inputs.
#[derive(Clone, Debug, Default)]
#[expect(
    non_snake_case,
    reason = "groups are named after their peer component, R3"
)]
pub struct MocapReceptorInput {
    /// From `R3`.
    pub R3: MocapFromR3,
}

/// `r31`'s output to `c3`.
#[derive(Debug, Default)]
pub struct MocapToC3 {
    /// A plausible pose.
    pub pose: Out<MapPose>,
}
impl Group for MocapToC3 {
    const PEER: NodeKind = NodeKind::Control;
}

/// `r31`'s outputs.
#[derive(Debug, Default)]
pub struct MocapReceptorOutput {
    /// To `c3`.
    pub c3: MocapToC3,
}

impl Subsystem for MocapReceptor {
    const KIND: SubsystemKind = SubsystemKind::VirtualReceptor;
    type Memory = MocapMemory;
    type Input = MocapReceptorInput;
    type Output = MocapReceptorOutput;
}

impl MocapMemory {
    fn plausible(&self, p: &MapPose) -> bool {
        if !(p.pose.is_finite() && p.time.is_finite()) {
            return false;
        }
        match self.last {
            Some(last) if p.time > last.time => {
                let d =
                    ((p.pose.x - last.pose.x).powi(2) + (p.pose.y - last.pose.y).powi(2)).sqrt();
                d <= self.max_speed * (p.time - last.time) + 0.05
            }
            Some(_) => false,
            None => true,
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
            .memory(|m: &mut MocapMemory, x: &MocapReceptorInput| {
                if let Some(p) = x.R3.pose.fresh() {
                    if m.plausible(p) {
                        m.last = Some(*p);
                    } else {
                        m.rejected += 1;
                    }
                }
            }),
        "false",
    ))
}

/// The control subsystem `c3` of the map agent.
pub struct MapAgent;

/// `c3`'s memory.
#[derive(Clone, Debug, Default)]
pub struct MapMemory {
    /// The last pose sent to `a1`.
    pub pose: Option<MapPose>,
    /// The last state estimate received from `a1`.
    pub estimate: Option<State>,
    /// Poses sent.
    pub sent: u64,
}

/// `c3`'s inputs from `r31`.
#[derive(Clone, Debug, Default)]
pub struct MapFromR31 {
    /// A plausible pose.
    pub pose: In<MapPose>,
}
impl Group for MapFromR31 {
    const PEER: NodeKind = NodeKind::VirtualReceptor;
}

/// `c3`'s inputs from `c1`.
#[derive(Clone, Debug, Default)]
pub struct MapFromC1 {
    /// `a1`'s state estimate.
    pub q_est: In<State>,
}
impl Group for MapFromC1 {
    const PEER: NodeKind = NodeKind::Control;
}

/// `c3`'s inputs.
#[derive(Clone, Debug, Default)]
pub struct MapInput {
    /// From `r31`.
    pub r31: MapFromR31,
    /// From `c1`.
    pub c1: MapFromC1,
}

/// `c3`'s outputs to `c1`.
#[derive(Debug, Default)]
pub struct MapToC1 {
    /// The robot's pose on the map.
    pub pose: Out<MapPose>,
}
impl Group for MapToC1 {
    const PEER: NodeKind = NodeKind::Control;
}

/// `c3`'s outputs.
#[derive(Debug, Default)]
pub struct MapOutput {
    /// To `c1`.
    pub c1: MapToC1,
}

impl Subsystem for MapAgent {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = MapMemory;
    type Input = MapInput;
    type Output = MapOutput;
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
            .memory(|m: &mut MapMemory, x: &MapInput| {
                if let Some(p) = x.r31.pose.fresh() {
                    m.pose = Some(*p);
                    m.sent += 1;
                }
                if let Some(q) = x.c1.q_est.fresh().filter(|q| q.is_finite()) {
                    m.estimate = Some(*q);
                }
            }),
        "false",
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::types::{AckStatus, Point2, Pose2};
    use embodied::testing::{Environment, Termination};
    use embodied::{Stamp, Time};
    use proptest::prelude::*;

    /// A `c1` that acknowledges each plan `delay` activations of `c2` after it was sent.
    #[derive(Clone, Debug)]
    struct Acker {
        delay: u64,
        pending: Option<(u32, u64)>,
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
                }
                _ => x.c1.ack.age(),
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
        });
        Termination::within(6 * 13 + 2)
            .cases(64)
            .returns_to(&fsm, "done", memory, env)
            .unwrap();
    }

    #[test]
    fn implausible_poses_are_rejected() {
        let mut m = MocapMemory {
            max_speed: 2.0,
            ..MocapMemory::default()
        };
        let at = |x: f64, time: f64| MapPose {
            pose: Pose2 {
                x,
                y: 0.0,
                phi: 0.0,
            },
            time,
        };
        assert!(m.plausible(&at(0.0, 0.0)));
        m.last = Some(at(0.0, 0.0));
        assert!(m.plausible(&at(0.1, 0.1)));
        assert!(!m.plausible(&at(5.0, 0.1)), "50 m/s");
        assert!(!m.plausible(&at(f64::NAN, 0.2)));
        assert!(!m.plausible(&at(0.0, -1.0)), "older than the last");
    }
}
