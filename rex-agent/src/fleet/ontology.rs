//! The fleet's one ontology agent `a2`: a single control subsystem `c2`
//! dispatching plans to every robot (issue 57), its buffers to and from the
//! robots' `c1_k` a [`Fan`] of M peers (`c2.c1[k].desired_plan`,
//! `c2.c1[k].ack`...), M fixed when the fleet is built.
//!
//! Each robot is dispatched as Rex's `c2` dispatches Rex
//! ([`crate::world::partners`]): its mission's plans one by one, each after
//! the previous one was acknowledged, the outcome of every plan kept, and,
//! when its `c1` comes back as a new incarnation (its process was killed and
//! restarted), its plans not settled sent again from their first point not
//! known reached. The per-robot logic is Rex's, not a copy: each robot has an
//! [`OntologyMemory`] and the predicates and functions of Rex's `c2` run on
//! it ([`OntologyMemory::more`], [`OntologyMemory::acked`],
//! [`OntologyMemory::settled`], [`OntologyMemory::advance`],
//! [`OntologyMemory::record`]). What one FSM cannot be is in Rex's
//! behaviours for every robot at once, so each robot's place in Rex's FSM
//! (`next_plan`, `wait`, `settle`, `done`) is kept in memory ([`Phase`]),
//! and at every activation of the fleet's `c2` each robot takes the steps
//! Rex's `c2` takes in one activation: the same decisions on the same
//! predicates, then the same action (send its next plan, or record what
//! arrived). A robot's plans and memory are then those Rex's `c2` would have
//! had with the same inputs, activation by activation (the module's tests
//! run both side by side).
//!
//! The fleet's `c2` has two behaviours: `dispatch` (every robot's step,
//! until every robot's mission is settled) and the final `done`.

use embodied::{
    Action, ActionError, Behaviour, Buffers, Fan, Fsm, FsmBuildError, Memory, Subsystem,
};

use crate::mission::Mission;
use crate::world::partners::{OntologyFromC1, OntologyMemory, OntologyToC1};

/// The fleet's control subsystem `c2` of its ontology agent `a2`.
#[derive(Subsystem)]
#[subsystem(kind = Control, memory = FleetOntologyMemory, input = FleetOntologyInput, output = FleetOntologyOutput)]
pub struct FleetOntology;

/// Where a robot is in Rex's `c2` FSM (its behaviours).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Phase {
    /// `next_plan`: decide whether to send a plan or settle.
    #[default]
    NextPlan,
    /// `wait`: a plan was sent; wait for its acknowledgement.
    Wait,
    /// `settle`: every plan was sent; wait for every outcome.
    Settle,
    /// `done`: its one last record.
    Done,
    /// Rex's `c2` would have halted: nothing more for this robot.
    Halted,
}

/// What a robot's step does at this activation (Rex's action of the
/// behaviour it is in).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Step {
    /// Nothing (halted).
    #[default]
    Idle,
    /// `send`: its next plan goes out, then `advance`.
    Send,
    /// `record`: keep what arrived, watch `c1`'s incarnation.
    Record,
}

/// One robot's dispatch: Rex's `c2` memory and its place in Rex's FSM.
#[derive(Clone, Debug, Default)]
pub struct Dispatch {
    /// What Rex's `c2` keeps of its robot: the mission, the plans sent, the
    /// acknowledgements and outcomes, `c1`'s incarnation.
    pub ontology: OntologyMemory,
    /// Its place in Rex's FSM.
    pub phase: Phase,
    /// What it does at the current activation.
    pub step: Step,
}

impl Dispatch {
    /// A robot with `mission`, nothing sent yet.
    pub fn new(mission: Mission) -> Self {
        Dispatch {
            ontology: OntologyMemory::new(mission),
            phase: Phase::NextPlan,
            step: Step::Idle,
        }
    }

    /// The decisions of one activation of Rex's `c2` with input `x`: from
    /// behaviour to behaviour on the predicates until one acts, which sets
    /// [`Dispatch::step`]. Rex's graph has no cycle without an action (a
    /// plan lost means one to send); a robot that found one is an error, as
    /// Rex's FSM's livelock is.
    fn decide(&mut self, robot: usize, x: &OntologyFromC1) -> Result<(), ActionError> {
        let m = &self.ontology;
        // At most one transition out of each behaviour, as in Rex's FSM.
        for _ in 0..5 {
            let (phase, step) = match self.phase {
                Phase::NextPlan if m.more() => (Phase::Wait, Some(Step::Send)),
                Phase::NextPlan => (Phase::Settle, None),
                Phase::Wait if m.acked(x) || m.lost => (Phase::NextPlan, None),
                Phase::Settle if m.lost => (Phase::NextPlan, None),
                Phase::Settle if m.settled() => (Phase::Done, None),
                Phase::Wait | Phase::Settle => (self.phase, Some(Step::Record)),
                Phase::Done => (Phase::Halted, Some(Step::Record)),
                Phase::Halted => (Phase::Halted, Some(Step::Idle)),
            };
            self.phase = phase;
            if let Some(step) = step {
                self.step = step;
                return Ok(());
            }
        }
        Err(ActionError::failed(format!(
            "robot {robot}: Rex's c2 went round its behaviours without an action ({:?})",
            self.phase
        )))
    }

    /// Whether Rex's `c2` would have halted: every plan settled, its last
    /// record made.
    pub fn halted(&self) -> bool {
        self.phase == Phase::Halted
    }
}

/// The fleet's `c2` memory: every robot's dispatch, in robot order (robot
/// `k` is reached through `c1[k]`).
#[derive(Clone, Debug, Default, Memory)]
pub struct FleetOntologyMemory {
    /// Each robot's dispatch.
    pub robots: Vec<Dispatch>,
}

impl FleetOntologyMemory {
    /// A memory dispatching `missions[k]` to robot `k`, nothing sent yet.
    pub fn new(missions: impl IntoIterator<Item = Mission>) -> Self {
        FleetOntologyMemory {
            robots: missions.into_iter().map(Dispatch::new).collect(),
        }
    }

    /// Whether every robot's mission is settled and its last record made
    /// (the predicate `settled`).
    pub fn settled(&self) -> bool {
        self.robots.iter().all(Dispatch::halted)
    }
}

/// The fleet's `c2` inputs: from every robot's `c1`, Rex's group once a robot.
#[derive(Debug, Default, Buffers)]
pub struct FleetOntologyInput {
    /// From `c1_k`, element `k`.
    pub c1: Fan<OntologyFromC1>,
}

/// The fleet's `c2` outputs: to every robot's `c1`, Rex's group once a robot.
#[derive(Debug, Default, Buffers)]
pub struct FleetOntologyOutput {
    /// To `c1_k`, element `k`.
    pub c1: Fan<OntologyToC1>,
}

impl FleetOntologyInput {
    /// Inputs from `robots` robots (the fan's length).
    pub fn new(robots: usize) -> Self {
        FleetOntologyInput {
            c1: Fan::new(robots),
        }
    }
}

impl FleetOntologyOutput {
    /// Outputs to `robots` robots (the fan's length).
    pub fn new(robots: usize) -> Self {
        FleetOntologyOutput {
            c1: Fan::new(robots),
        }
    }
}

/// Every robot's decisions (the common part `decide`): the fan must have a
/// robot's element for every robot of the memory.
fn decide(m: &mut FleetOntologyMemory, x: &FleetOntologyInput) -> Result<(), ActionError> {
    if x.c1.len() != m.robots.len() {
        return Err(ActionError::failed(format!(
            "{} robots to dispatch to, but {} elements in the fan from c1",
            m.robots.len(),
            x.c1.len()
        )));
    }
    for (k, (robot, x)) in m.robots.iter_mut().zip(x.c1.iter()).enumerate() {
        robot.decide(k, x)?;
    }
    Ok(())
}

/// The next plan of every robot that sends one (`send_plans`), from its
/// first point not known reached.
fn send_plans(m: &FleetOntologyMemory, y: &mut Fan<OntologyToC1>) -> Result<(), ActionError> {
    for (k, (robot, y)) in m.robots.iter().zip(y.iter_mut()).enumerate() {
        if robot.step == Step::Send {
            let plan = robot
                .ontology
                .to_send(robot.ontology.next)
                .ok_or_else(|| ActionError::failed(format!("robot {k}: no plan left to send")))?;
            y.desired_plan.set(plan);
        }
    }
    Ok(())
}

/// Every robot's memory after its step (`advance`): Rex's `advance` after a
/// plan was sent, Rex's `record` while it waits.
fn advance(m: &mut FleetOntologyMemory, x: &FleetOntologyInput) {
    for (robot, x) in m.robots.iter_mut().zip(x.c1.iter()) {
        match robot.step {
            Step::Send => robot.ontology.advance(x),
            Step::Record => robot.ontology.record(x),
            Step::Idle => {}
        }
    }
}

/// The FSM of the fleet's `c2` (as the fleet's spec says,
/// [`super::spec::fleet_spec`]): `dispatch` steps every robot until every
/// robot's mission is settled, then the final `done`.
pub fn fleet_ontology_fsm() -> Result<Fsm<FleetOntology>, FsmBuildError> {
    Fsm::builder()
        .predicate("settled", |m: &FleetOntologyMemory, _| m.settled())
        .behaviour(Behaviour::while_loop(
            "dispatch",
            Action::<FleetOntology>::new()
                .common(decide)
                .named("decide")
                .output(
                    |y| &mut y.c1,
                    |m: &FleetOntologyMemory, _: &FleetOntologyInput, y: &mut Fan<OntologyToC1>| {
                        send_plans(m, y)
                    },
                )
                .named("send_plans")
                .memory(advance)
                .named("advance"),
            "settled",
        ))
        .behaviour(Behaviour::repeat_loop(
            "done",
            Action::<FleetOntology>::new(),
            "true",
        ))
        .initial("dispatch")
        .arc("dispatch", "done", "true")
        .final_behaviour("done")
        .build()
}

#[cfg(test)]
mod tests;
