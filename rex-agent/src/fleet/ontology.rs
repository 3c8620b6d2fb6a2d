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
//! known reached. The per-robot logic is Rex's, not a copy, and so is its
//! FSM: each robot has Rex's `c2` memory ([`OntologyMemory`]) and its own
//! state in Rex's `c2` FSM ([`ontology_fsm`]), a machine per robot inside
//! the fleet's one `c2`. At every activation of the fleet's `c2` each robot's
//! machine takes one activation of Rex's FSM ([`Fsm::activate`]: its
//! decisions on Rex's predicates, then Rex's action) on the robot's element
//! of the fan, and the plan Rex's action sends goes out on the robot's
//! element of the output fan. A robot's plans and memory are then those
//! Rex's `c2` would have had with the same inputs, activation by activation
//! (the module's tests run both side by side).
//!
//! The fleet's `c2` has two behaviours: `dispatch` (every robot's
//! activation, until every robot's mission is settled) and the final `done`.

use embodied::{
    Action, ActionError, Behaviour, Buffers, Fan, Fsm, FsmBuildError, FsmState, Memory, Step,
    Subsystem,
};

use crate::mission::Mission;
use crate::payload::Plan;
use crate::world::partners::{
    Ontology, OntologyFromC1, OntologyInput, OntologyMemory, OntologyOutput, OntologyToC1,
    ontology_fsm,
};

/// The fleet's control subsystem `c2` of its ontology agent `a2`.
#[derive(Subsystem)]
#[subsystem(kind = Control, memory = FleetOntologyMemory, input = FleetOntologyInput, output = FleetOntologyOutput)]
pub struct FleetOntology;

/// One robot's dispatch: Rex's `c2` memory and its state in Rex's `c2` FSM.
#[derive(Clone, Debug, Default)]
pub struct Dispatch {
    /// What Rex's `c2` keeps of its robot: the mission, the plans sent, the
    /// acknowledgements and outcomes, `c1`'s incarnation.
    pub ontology: OntologyMemory,
    /// Its state in Rex's `c2` FSM; `None` before its first activation (the
    /// FSM's initial behaviour).
    pub state: Option<FsmState>,
    /// Whether Rex's `c2` has halted, or halts at its next decision (its
    /// final behaviour ends and no arc leaves it): nothing more for this
    /// robot.
    pub halted: bool,
    /// The plan Rex's action sent at the current activation.
    pub sending: Option<Plan>,
}

impl Dispatch {
    /// A robot with `mission`, nothing sent yet.
    pub fn new(mission: Mission) -> Self {
        Dispatch {
            ontology: OntologyMemory::new(mission),
            ..Dispatch::default()
        }
    }

    /// One activation of Rex's `c2` FSM `rex` for robot `robot`, on the
    /// robot's inputs `x`: Rex's decisions and Rex's action; the plan it
    /// sends kept in [`Dispatch::sending`].
    fn activate(
        &mut self,
        rex: &Fsm<Ontology>,
        robot: usize,
        x: &OntologyFromC1,
    ) -> Result<(), ActionError> {
        self.sending = None;
        let state = self.state.get_or_insert_with(|| rex.start());
        let input = OntologyInput { c1: x.clone() };
        let mut output = OntologyOutput::default();
        rex.activate(state, &mut self.ontology, &input, &mut output, |_| {})
            .map_err(|e| ActionError::failed(format!("robot {robot}: Rex's c2: {e}")))?;
        self.sending = output.c1.desired_plan.written().cloned();
        // A final behaviour that ends with no arc out halts at the next
        // decision, which changes nothing else: said now, so that the fleet
        // does not wait an activation more per robot. Decided on this
        // activation's input, which is the next one's only while the final
        // behaviour's end does not read its input: Rex's `done` ends after
        // one action whatever it reads (its terminal condition is `true`).
        let mut next = *state;
        self.halted = state.is_halted()
            || (rex.is_final(state.behaviour())
                && matches!(
                    rex.step(&mut next, &self.ontology, &input),
                    Ok(Step::Finished)
                ));
        Ok(())
    }

    /// Whether Rex's `c2` has halted or halts at its next decision.
    pub fn halted(&self) -> bool {
        self.halted
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

/// Every robot's activation of Rex's `c2` FSM `rex` (the common part
/// `activate_robots`): the fan must have a robot's element for every robot
/// of the memory.
fn activate_robots(
    rex: &Fsm<Ontology>,
    m: &mut FleetOntologyMemory,
    x: &FleetOntologyInput,
) -> Result<(), ActionError> {
    if x.c1.len() != m.robots.len() {
        return Err(ActionError::failed(format!(
            "{} robots to dispatch to, but {} elements in the fan from c1",
            m.robots.len(),
            x.c1.len()
        )));
    }
    // All or nothing: an error stops the action before its output part, so a
    // robot whose plan went into memory as sent would never see it written.
    // A failed activation changes no robot and is retried at the next period,
    // as a failed action of Rex's own `c2` is (its memory part comes last).
    let mut next = m.robots.clone();
    for (k, (robot, x)) in next.iter_mut().zip(x.c1.iter()).enumerate() {
        if !robot.halted {
            robot.activate(rex, k, x)?;
        }
    }
    m.robots = next;
    Ok(())
}

/// The plan each robot's activation sent (`send_plans`), to that robot.
fn send_plans(m: &FleetOntologyMemory, y: &mut Fan<OntologyToC1>) {
    for (robot, y) in m.robots.iter().zip(y.iter_mut()) {
        if let Some(plan) = &robot.sending {
            y.desired_plan.set(plan.clone());
        }
    }
}

/// The FSM of the fleet's `c2` (as the fleet's spec says,
/// [`super::spec::fleet_spec`]): `dispatch` activates every robot's machine
/// (Rex's `c2` FSM, [`ontology_fsm`]) until every robot's mission is
/// settled, then the final `done`.
pub fn fleet_ontology_fsm() -> Result<Fsm<FleetOntology>, FsmBuildError> {
    let rex = ontology_fsm()?;
    Fsm::builder()
        .predicate("settled", |m: &FleetOntologyMemory, _| m.settled())
        .behaviour(Behaviour::while_loop(
            "dispatch",
            Action::<FleetOntology>::new()
                .common(move |m: &mut FleetOntologyMemory, x: &FleetOntologyInput| {
                    activate_robots(&rex, m, x)
                })
                .named("activate_robots")
                .output(
                    |y| &mut y.c1,
                    |m: &FleetOntologyMemory, _: &FleetOntologyInput, y: &mut Fan<OntologyToC1>| {
                        send_plans(m, y);
                    },
                )
                .named("send_plans"),
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
