//! The partner agents of the locomotion agent (the paper's Fig. 3), as real agents of
//! the framework:
//!
//! * `a2`, the ontology agent: its control subsystem `c2` sends the plans of a
//!   mission one by one, each after the previous one was acknowledged (`Done`, the
//!   paper's early acknowledgement, or a refusal or failure), keeps how each plan's
//!   execution ended (`outcome`), and ends when every plan sent has ended. It
//!   keeps how far each plan got (`progress`) and watches `c1`'s incarnation
//!   (`alive`): when `c1` restarts (its process crashed and was started again),
//!   the plans not yet settled are sent again, in order, each from its first
//!   point not known reached, so that no plan is lost and no fragment executed
//!   to its end is driven again. `c1` also takes plans from other senders
//!   (the ROS 2 topic `/rex/plan`): `c2` keeps every acknowledgement and
//!   outcome it receives (what the run's watcher reads), but counts as its
//!   own only those of its mission's plans (ids `1..=n`): a plan it did not
//!   send never ends a wait, settles the mission, or moves a resumption
//!   point ([`OntologyMemory::owns`]). A mission with no plans
//!   ([`Mission::listens`]) is never settled: `c2` does not halt, and keeps
//!   receiving what `c1` sends about the plans of others;
//! * `a3`, the map agent: the motion-capture system `R3` (a real receptor), its
//!   virtual receptor `r31` that rejects implausible poses, and the control subsystem
//!   `c3` that sends the pose on the map to `a1` and keeps `a1`'s state estimate.

use embodied::{
    Action, ActionError, Behaviour, Buffers, Fsm, FsmBuildError, Group, In, Memory, Out, Subsystem,
};

use std::collections::{BTreeMap, BTreeSet};

use crate::mission::Mission;
use crate::payload::{Ack, AckStatus, Alive, MapPose, Plan, PlanOutcome, Progress, State};

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
    /// Fragments executed to their end, by plan (the most reported).
    pub done: BTreeMap<u32, u32>,
    /// `c1`'s incarnation, once heard.
    pub boot: Option<u64>,
    /// `c1` restarted with plans not settled: they are sent again.
    pub lost: bool,
    /// Restarts of `c1` heard of.
    pub restarts: u32,
    /// Plans sent again after a restart of `c1`.
    pub resent: u32,
    /// Fragments reported executed to their end a second time (never, if
    /// resuming works).
    pub repeated: u32,
    /// Plans the current incarnation of `c1` acknowledged as ready (done,
    /// refused, failed): a copy of one sent again is ignored by `c1`, and its
    /// acknowledgement, already here, ends the wait.
    pub answered: BTreeSet<u32>,
}

impl OntologyMemory {
    /// A memory holding `mission`, nothing sent yet.
    pub fn new(mission: Mission) -> Self {
        OntologyMemory {
            mission,
            next: 0,
            acks: Vec::new(),
            outcomes: Vec::new(),
            done: BTreeMap::new(),
            boot: None,
            lost: false,
            restarts: 0,
            resent: 0,
            repeated: 0,
            answered: BTreeSet::new(),
        }
    }

    /// Whether plan `id` is one of the mission's (ids `1..=n`, as
    /// [`Mission::plan`] numbers them): `c1` also takes plans from other
    /// senders (ROS 2), numbered after the mission's.
    pub fn owns(&self, id: u32) -> bool {
        (1..=self.mission.plans.len()).contains(&(id as usize))
    }

    /// Whether plan `id` has ended: refused, failed, or its execution reported.
    fn plan_settled(&self, id: u32) -> bool {
        self.outcomes.iter().any(|o| o.plan == id)
            || self.acks.iter().any(|a| {
                a.plan == id && matches!(a.status, AckStatus::Refused(_) | AckStatus::Failed(_))
            })
    }

    /// The plan at index `k` of the mission, from its first point not known
    /// reached (at least its last point, so that `e11` judges the arrival).
    pub fn to_send(&self, k: usize) -> Option<Plan> {
        let mut plan = self.mission.plan(k)?;
        let done = self.done.get(&plan.id).copied().unwrap_or(0) as usize;
        let first = done.min(plan.points.len().saturating_sub(1));
        plan.points.drain(..first);
        plan.first = first as u32;
        Some(plan)
    }

    /// Whether every plan sent has ended: refused, failed, or its execution
    /// reported. Never for a mission that listens ([`Mission::listens`]):
    /// `c2` then waits in `settle` for as long as the run goes, receiving
    /// what `c1` says of the plans it takes from elsewhere (halted, it would
    /// read none of it).
    pub fn settled(&self) -> bool {
        !self.mission.listens() && (1..=self.next as u32).all(|id| self.plan_settled(id))
    }

    /// The id of the last plan sent.
    fn last_sent(&self) -> Option<u32> {
        self.next.checked_sub(1).map(|k| k as u32 + 1)
    }

    /// Whether a plan of the mission is left to send (the predicate `more`).
    pub fn more(&self) -> bool {
        self.next < self.mission.plans.len()
    }

    /// Whether the last plan sent was acknowledged as ready, now (`x`) or
    /// before by this incarnation of `c1` (the predicate `acked`).
    pub fn acked(&self, x: &OntologyFromC1) -> bool {
        self.last_sent().is_some_and(|id| {
            self.answered.contains(&id) || x.ack.fresh().is_some_and(|a| a.plan == id && a.ready())
        })
    }

    /// The plan [`OntologyMemory::to_send`] gave was sent: keep what arrived
    /// with `x`, and go on to the next plan (the function `advance`).
    pub fn advance(&mut self, x: &OntologyFromC1) {
        keep(self, x);
        self.lost = false;
        self.next += 1;
    }

    /// Keep a fresh final acknowledgement, a fresh outcome and progress; when
    /// `c1` is a new incarnation, go back to the first plan it does not have
    /// (the function `record`, run by every behaviour that waits).
    pub fn record(&mut self, x: &OntologyFromC1) {
        keep(self, x);
        watch(self, x);
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
    /// Fragments executed to their end.
    pub progress: In<Progress>,
    /// `c1`'s incarnation and the newest plan it received.
    pub alive: In<Alive>,
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

/// Keep a fresh final acknowledgement, a fresh outcome and progress (every
/// acting behaviour runs it, so none is lost); when `c1` is a new incarnation,
/// go back to the first plan it does not have ([`watch`]).
fn record(m: &mut OntologyMemory, x: &OntologyInput) {
    m.record(&x.c1);
}

/// Keep a fresh final acknowledgement, a fresh outcome and progress. Those of
/// a plan `c2` does not own (another sender's) are kept in `acks` and
/// `outcomes` for the watcher, but never answer a wait, and their progress
/// is not a resumption point ([`OntologyMemory::owns`]).
fn keep(m: &mut OntologyMemory, x: &OntologyFromC1) {
    if let Some(ack) = x.ack.fresh().filter(|a| a.ready()) {
        if m.owns(ack.plan) {
            m.answered.insert(ack.plan);
        }
        m.acks.push(ack.clone());
    }
    if let Some(o) = x.outcome.fresh() {
        m.outcomes.push(o.clone());
    }
    if let Some(p) = x.progress.fresh().filter(|p| m.owns(p.plan)) {
        let points = m
            .mission
            .plans
            .get((p.plan as usize).wrapping_sub(1))
            .map_or(0, Vec::len) as u32;
        let done = m.done.entry(p.plan).or_insert(0);
        // A plan whose every fragment was done, and whose outcome was lost, is
        // sent again as its last point to have its arrival judged: that
        // fragment, planned from where the platform stands, is not a repeat.
        let confirmation = p.done == points && *done == points;
        if p.done <= *done && !confirmation {
            m.repeated += 1;
        }
        *done = (*done).max(p.done);
    }
}

/// When `c1` is a new incarnation, go back to the first plan it does not have
/// and is not settled: it will be sent again. Not while a plan is being sent
/// (`send`): `c1`'s `alive` read then was written before it could have the
/// plan; the next activation looks.
fn watch(m: &mut OntologyMemory, x: &OntologyFromC1) {
    if let Some(&alive) = x.alive.get()
        && m.boot != Some(alive.boot)
    {
        // A new incarnation has none of the plans sent before; the first one
        // heard has those up to its newest (the later ones were sent while it
        // was not there, or are on their way: a copy is ignored).
        let restarted = m.boot.is_some();
        let held = if restarted { 0 } else { alive.newest as usize };
        m.restarts += u32::from(restarted);
        if restarted {
            m.answered.clear();
        }
        m.boot = Some(alive.boot);
        // Plans are settled in order: send again from the first that is not.
        if let Some(k) = (held..m.next).find(|&k| !m.plan_settled(k as u32 + 1)) {
            m.resent += (m.next - k) as u32;
            m.next = k;
            m.lost = true;
        }
    }
}

/// The FSM of `c2` (as in `specs/rex.ron`): `next_plan` decides, `send` sends one
/// plan, `wait` waits for its acknowledgement, `settle` waits for every plan's
/// outcome after the last one is sent, `done` is final.
pub fn ontology_fsm() -> Result<Fsm<Ontology>, FsmBuildError> {
    Fsm::builder()
        .predicate("more", |m: &OntologyMemory, _| m.more())
        .predicate("acked", |m: &OntologyMemory, x: &OntologyInput| {
            m.acked(&x.c1)
        })
        .predicate("lost", |m: &OntologyMemory, _| m.lost)
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
                            .to_send(m.next)
                            .ok_or_else(|| ActionError::failed("no plan left to send"))?;
                        y.desired_plan.set(plan);
                        Ok::<(), ActionError>(())
                    },
                )
                .named("send_plan")
                .memory(|m: &mut OntologyMemory, x: &OntologyInput| m.advance(&x.c1))
                .named("advance"),
            "true",
        ))
        .predicate("settled", |m: &OntologyMemory, _| m.settled())
        .behaviour(Behaviour::while_loop(
            "wait",
            Action::<Ontology>::new().memory(record),
            "acked || lost",
        ))
        .behaviour(Behaviour::while_loop(
            "settle",
            Action::<Ontology>::new().memory(record),
            "settled || lost",
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
        .arc("settle", "done", "!lost")
        .arc("settle", "next_plan", "lost")
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
    /// Largest plausible speed \[m/s\]: a faster jump is rejected.
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
pub(crate) mod tests;
