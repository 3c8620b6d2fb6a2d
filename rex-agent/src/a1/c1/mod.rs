//! The control subsystem `c1` of the locomotion agent (the paper's section 3.1).
//!
//! Behaviours (Fig. 5): `B1` waits for a plan from `a2`, `B2` executes it, `B3`
//! acknowledges. The transition subfunctions are the paper's Algorithms 4–8, one Rust
//! function each, named as in `specs/rex.ron`:
//!
//! | function | algorithm | target |
//! |---|---|---|
//! | [`cc_1_tp`] | 4: a new plan is processed, the planner initialised | memory |
//! | [`cT_1_tp`] | 5: a new plan clears `ack` | `c2` |
//! | [`cc_2_tp`] | 6: the planning process and the fragment list | memory |
//! | [`ce_2_tp`] | 7: the next fragment to `e11` with `steps` and `notify` | `e11` |
//! | [`cT_3_tp`] | 8: `ack` | `c2` |
//! | [`ce_1`], [`cT_q`] | relays: map pose and `A4x4` to `e11`, state estimate to `a3` | `e11`, `c3` |
//! | [`cT_2`] | relays `e11`'s plan outcomes to `a2` during `B2` (also done by `cT_1_tp`, `cT_3_tp`) | `c2` |
//! | [`cc_3`] | clears the plan's flags (needed by the refusal arc `B1 → B3`) | memory |
//!
//! **Outcomes.** `Done` is the paper's early acknowledgement: the last fragment was
//! handed over. Whether the platform then reached the plan's end, or was stopped,
//! `e11` measures and reports (`outcome`), and every behaviour of `c1` relays it to
//! `a2` with its target-`c2` function. A stop during `B2` ends the behaviour
//! (`stopped`): the plan is acknowledged `Failed` with the stop's reason. Fragments
//! carry the stop count `c1` knows (`epoch`) so that `e11` refuses those handed
//! over before `c1` heard of a stop, and the plan after a stop is planned from the
//! state estimate, not from where the last plan should have ended.
//!
//! **Restarts.** The process running `c1` may crash and be restarted (a
//! deployment over several processes): its memory starts afresh, and the plan
//! it was executing is lost with it. `c1` tells `a2` who it is every iteration
//! (`alive`: the incarnation number its builder gives it, [`C1Params::boot`], and
//! the newest plan it received) and
//! relays `e11`'s `progress` (fragments executed to their end); `a2` answers a
//! new incarnation by sending again, in order, every plan not yet settled, each
//! from its first point not known reached ([`Plan::first`]). `c1` takes a plan
//! id once: a copy of a plan it has taken (a resend crossing its `ack`) is
//! ignored.
//!
//! Two details the paper leaves open. `ready` comes from `e11`, which runs five times
//! slower than `c1`; it is an event (sent once per fragment, when `notify` steps are
//! done, and once at start) latched in memory (`ready_latch`) until a fragment is
//! handed over, so one `ready` releases exactly one fragment. And a plan that cannot
//! be executed (empty, non-finite, off the map or too close to an obstacle) is
//! refused: `B1` goes straight to `B3`, which reports the reason to `a2`; a planned
//! fragment that leaves the free space fails the plan like a planner failure.

pub mod trajgen;

use std::collections::VecDeque;

use embodied::{Buffers, Fsm, FsmBuildError, Group, In, Memory, Out, Subsystem, fsm};

use crate::a1::map::Map;
use crate::algorithms::planner::ground::GroundTiming;
use crate::algorithms::planner::{Fragment, Waypoint, nearest_angle};
use crate::model::Friction;
use crate::payload::{
    Ack, AckStatus, Alive, Execution, MapPose, Plan, PlanOutcome, Progress, State, Transform,
};
use trajgen::{Status, TrajGen};

/// Settings of `c1`.
#[derive(Clone, Debug, PartialEq)]
pub struct C1Params {
    /// Plan points and planned fragments must lie in its free space (its clearance:
    /// the platform's footprint and a margin).
    pub map: Map,
    /// The most points a plan may have.
    pub max_points: usize,
    /// How long before the end of a fragment `e11` reports ready \[s\].
    pub notify_lead: f64,
    /// How many iterations a plan may wait for the first state estimate of `e11`
    /// before it is refused (or, after a stop, for the platform to come to rest
    /// before it is planned from wherever it is).
    pub estimate_wait_max: u32,
    /// This incarnation of `c1` (sent as `alive`): a process that runs `c1`
    /// gives each of its starts a new number, so that `a2` knows that plans
    /// sent before were lost. 0 in a run in one process.
    pub boot: u64,
    /// How fragments are timed for the ground `e11` estimates, when it does
    /// (`None`: as planned).
    pub ground: Option<GroundTiming>,
}

impl Default for C1Params {
    fn default() -> Self {
        C1Params {
            map: Map::default(),
            max_points: 1000,
            notify_lead: 1.0,
            estimate_wait_max: 500,
            boot: 0,
            ground: None,
        }
    }
}

/// `c1`'s internal memory (`^c c_1`).
#[derive(Clone, Memory)]
pub struct C1Memory {
    /// `plan`: the points still to plan towards, with desired orientations.
    pub plan: VecDeque<Waypoint>,
    /// `traj`: fragments planned and not yet handed over.
    pub traj: VecDeque<Fragment>,
    /// `trajgen`: the trajectory planner.
    pub trajgen: TrajGen,
    /// `new`: a new plan was taken.
    pub new: bool,
    /// A `ready` event from `e11` not yet answered with a fragment.
    pub ready_latch: bool,
    /// The plan being served.
    pub plan_id: u32,
    /// The newest plan id taken: copies of it or of older plans are ignored.
    pub taken: u32,
    /// Why the plan being served was refused.
    pub refusal: Option<String>,
    /// Fragments handed to `e11` for the current plan.
    pub handed: u32,
    /// A plan received before `e11` sent its first state estimate, and the
    /// iterations it has waited (the planner starts from the estimate).
    pub pending: Option<(Plan, u32)>,
    /// Plans replaced by a newer one while waiting in `pending` (never acknowledged;
    /// `a2` sends one plan at a time, so this stays 0 in Rex).
    pub superseded: u32,
    /// Plans refused as numbered out of sequence: more than one past the
    /// newest this incarnation has taken or holds (a plan lost on the way, or a
    /// sender that is not `a2`). Taking one would make `c1` ignore every real
    /// plan numbered below it.
    pub out_of_sequence: u32,
    /// `e11`'s stop count when the plan being served was taken.
    pub plan_epoch: u32,
    /// Why the plan being served failed after planning began (a fragment that
    /// leaves the free space).
    pub failure: Option<String>,
    /// The next plan starts from the state estimate (the last one did not end
    /// where it was planned to).
    pub restart: bool,
    /// Settings.
    pub params: C1Params,
}

/// The state of the memory in one line (plan points left, fragments waiting by
/// `plan.index`, the planner's status and flags), for traces.
impl std::fmt::Debug for C1Memory {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let traj: Vec<String> = self
            .traj
            .iter()
            .map(|t| format!("{}.{}", t.plan, t.index))
            .collect();
        write!(
            f,
            "{{plan {}: {} points left, traj [{}], trajgen {:?}, new {}, ready {}, handed {}",
            self.plan_id,
            self.plan.len(),
            traj.join(" "),
            self.trajgen.status(),
            self.new,
            self.ready_latch,
            self.handed
        )?;
        if let Some(r) = &self.refusal {
            write!(f, ", refused: {r}")?;
        }
        if let Some((p, waited)) = &self.pending {
            write!(f, ", pending plan {} ({waited} it.)", p.id)?;
        }
        f.write_str("}")
    }
}

impl C1Memory {
    /// An idle `c1` with this planner.
    pub fn new(trajgen: TrajGen, params: C1Params) -> C1Memory {
        C1Memory {
            plan: VecDeque::new(),
            traj: VecDeque::new(),
            trajgen,
            new: false,
            ready_latch: false,
            plan_id: 0,
            taken: 0,
            refusal: None,
            handed: 0,
            pending: None,
            superseded: 0,
            out_of_sequence: 0,
            plan_epoch: 0,
            failure: None,
            restart: false,
            params,
        }
    }
}

/// Inputs from `e11`.
#[derive(Clone, Debug, Default, Group)]
#[group(peer = VirtualEffector)]
pub struct C1FromE11 {
    /// `q~, q~ dot`.
    pub q_est: In<State>,
    /// The ready event.
    pub ready: In<bool>,
    /// How a plan's execution ended.
    pub outcome: In<PlanOutcome>,
    /// Fragments executed to their end.
    pub progress: In<Progress>,
}

/// Inputs from `r11`.
#[derive(Clone, Debug, Default, Group)]
#[group(peer = VirtualReceptor)]
#[expect(non_snake_case, reason = "the paper's buffer names")]
pub struct C1FromR11 {
    /// Visual odometry.
    pub A4x4: In<Transform>,
}

/// Inputs from the ontology agent.
#[derive(Clone, Debug, Default, Group)]
#[group(peer = Control)]
pub struct C1FromC2 {
    /// The plan.
    pub desired_plan: In<Plan>,
}

/// Inputs from the map agent.
#[derive(Clone, Debug, Default, Group)]
#[group(peer = Control)]
pub struct C1FromC3 {
    /// The pose on the map.
    pub pose: In<MapPose>,
}

/// `c1`'s input buffers.
#[derive(Clone, Debug, Default, Buffers)]
pub struct C1Input {
    /// From `e11`.
    pub e11: C1FromE11,
    /// From `r11`.
    pub r11: C1FromR11,
    /// From `c2`.
    pub c2: C1FromC2,
    /// From `c3`.
    pub c3: C1FromC3,
}

/// Outputs to `e11`.
#[derive(Debug, Default, Group)]
#[group(peer = VirtualEffector)]
#[expect(non_snake_case, reason = "the paper's buffer names")]
pub struct C1ToE11 {
    /// Map pose relay.
    pub pose: Out<MapPose>,
    /// Visual odometry relay.
    pub A4x4: Out<Transform>,
    /// The fragment to execute.
    pub traj: Out<Fragment>,
    /// Steps to execute it.
    pub steps: Out<u32>,
    /// Step after which to report ready (`notify < steps`).
    pub notify: Out<u32>,
}

/// Outputs to `c2`.
#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub struct C1ToC2 {
    /// The acknowledgement.
    pub ack: Out<Ack>,
    /// How a plan's execution ended (relayed from `e11`).
    pub outcome: Out<PlanOutcome>,
    /// Fragments executed to their end (relayed from `e11`).
    pub progress: Out<Progress>,
    /// This incarnation of `c1` ([`C1Params::boot`]) and the newest plan it
    /// received, every iteration.
    pub alive: Out<Alive>,
}

/// Outputs to `c3`.
#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub struct C1ToC3 {
    /// The state estimate.
    pub q_est: Out<State>,
}

/// `c1`'s output buffers.
#[derive(Debug, Default, Buffers)]
pub struct C1Output {
    /// To `e11`.
    pub e11: C1ToE11,
    /// To `c2`.
    pub c2: C1ToC2,
    /// To `c3`.
    pub c3: C1ToC3,
}

/// The control subsystem `c1`.
#[derive(Subsystem)]
#[subsystem(kind = Control, memory = C1Memory, input = C1Input, output = C1Output)]
pub struct C1;

// ---------------------------------------------------------------------------
// Auxiliary functions of the paper.

/// `proc(desired_plan)`: check the plan and add desired orientations. Interior points
/// face along their neighbours (`p_{k+1} − p_{k−1}`), the last one along the last
/// segment; repeated points take the direction of the nearest distinct ones; a plan
/// whose points are all equal leaves the heading free.
pub fn proc(plan: &Plan, params: &C1Params) -> Result<VecDeque<Waypoint>, String> {
    let pts = &plan.points;
    if pts.is_empty() {
        return Err("the plan has no points".into());
    }
    if pts.len() > params.max_points {
        return Err(format!(
            "the plan has {} points, more than {}",
            pts.len(),
            params.max_points
        ));
    }
    // A plan resumed from its point `first` had more points than that.
    if plan.first as usize >= params.max_points {
        return Err(format!(
            "the plan resumes from point {}, beyond the {} points a plan may have",
            plan.first, params.max_points
        ));
    }
    for (k, p) in pts.iter().enumerate() {
        if !(p.x.is_finite() && p.y.is_finite()) {
            return Err(format!("point {k} ({}, {}) is not finite", p.x, p.y));
        }
        if let Err(why) = params.map.explain(p.x, p.y) {
            return Err(format!("point {k} is off the map: {why}"));
        }
    }
    let direction = |a: usize, b: usize| -> Option<f64> {
        let (dx, dy) = (pts[b].x - pts[a].x, pts[b].y - pts[a].y);
        (dx.hypot(dy) > 1e-6).then(|| dy.atan2(dx))
    };
    // Look for a distinct point before and after k.
    let heading = |k: usize| -> Option<f64> {
        let before = (0..k).rev().find(|&j| direction(j, k).is_some());
        let after = (k + 1..pts.len()).find(|&j| direction(k, j).is_some());
        match (before, after) {
            (Some(b), Some(a)) => direction(b, a).or(direction(b, k)),
            (Some(b), None) => direction(b, k),
            (None, Some(a)) => direction(k, a),
            (None, None) => None,
        }
    };
    let mut out = VecDeque::with_capacity(pts.len());
    let mut previous: Option<f64> = None;
    for (k, p) in pts.iter().enumerate() {
        let phi = heading(k).map(|h| previous.map_or(h, |prev| nearest_angle(h, prev)));
        if phi.is_some() {
            previous = phi;
        }
        out.push_back(Waypoint {
            x: p.x,
            y: p.y,
            phi,
        });
    }
    Ok(out)
}

/// `trajToSteps(traj)`: iterations of `e11` to execute a fragment.
pub fn traj_to_steps(f: &Fragment) -> u32 {
    (f.steps() as u32).max(1)
}

/// `trajToNotify(traj)`: the step after which `e11` reports ready, `notify_lead`
/// seconds before the end, and always `notify < steps`.
pub fn traj_to_notify(f: &Fragment, params: &C1Params) -> u32 {
    let steps = traj_to_steps(f);
    let lead = ((params.notify_lead / f.dt.max(1e-9)).round() as u32).max(1);
    steps.saturating_sub(lead.min(steps))
}

/// `ready^i`: the latched event or a fresh one.
fn ready(m: &C1Memory, x: &C1Input) -> bool {
    m.ready_latch || x.e11.ready.fresh() == Some(&true)
}

/// Whether the platform stands still (after a stop it may still be braking).
fn at_rest(s: &State) -> bool {
    s.q_dot[0].hypot(s.q_dot[1]) < 0.02 && s.q_dot[2].abs() < 0.05
}

/// `e11`'s stop count as `c1` knows it (from its latest outcome).
fn epoch(x: &C1Input) -> u32 {
    x.e11.outcome.get().map_or(0, |o| o.epoch)
}

/// `e11` stopped the platform since the plan being served was taken: why.
fn stopped(m: &C1Memory, x: &C1Input) -> Option<String> {
    let o = x.e11.outcome.get().filter(|o| o.epoch > m.plan_epoch)?;
    Some(match &o.result {
        Execution::Stopped(why) => format!("e11 stopped the platform: {why}"),
        other => format!("e11 stopped the platform ({other})"),
    })
}

/// Why a planned fragment cannot be executed: a sample outside the free space.
fn blocked(f: &Fragment, params: &C1Params) -> Option<String> {
    f.states.iter().find_map(|s| {
        params.map.explain(s[0], s[1]).err().map(|why| {
            format!(
                "fragment {} of plan {} leaves the free space: {why}",
                f.index, f.plan
            )
        })
    })
}

/// The fragment at the front of the list as it is handed over: timed for the
/// ground `e11` estimates now ([`GroundTiming`]; while the estimate has not
/// settled, for the more slippery of it and the cautious ground, each
/// coefficient apart), when it estimates one and `params.ground` is set; `Err`
/// with the reason when that ground cannot deliver it. (Planned one fragment
/// ahead, a fragment is timed at hand-over: by then the estimator has seen the
/// platform drive on the ground of the one before.) `cc_2_tp` and `ce_2_tp`
/// both ask, in the iteration of a hand-over only.
fn front_timed(m: &C1Memory, x: &C1Input) -> Option<Result<Fragment, String>> {
    let f = m.traj.front()?;
    let ground = x.e11.q_est.get().and_then(|s| s.ground);
    Some(match (&m.params.ground, ground) {
        (Some(timing), Some(ground)) if ground.settled => {
            timing.time(f, &ground.friction).map_err(|e| e.to_string())
        }
        (Some(timing), Some(ground)) => {
            let (e, c) = (ground.friction, timing.cautious);
            let assumed = Friction {
                mu_long: e.mu_long.min(c.mu_long),
                mu_lat: e.mu_lat.min(c.mu_lat),
                rolling: e.rolling.max(c.rolling),
            };
            timing
                .time(f, &assumed)
                .map_err(|e| format!("{e} (assumed until the estimate settles)"))
        }
        _ => Ok(f.clone()),
    })
}

/// Relay plan outcomes and progress from `e11` to `a2`; say who is alive.
fn relay(m: &C1Memory, x: &C1Input, y: &mut C1ToC2) {
    if let Some(o) = x.e11.outcome.fresh() {
        y.outcome.set(o.clone());
    }
    if let Some(p) = x.e11.progress.fresh() {
        y.progress.set(*p);
    }
    y.alive.set(Alive {
        boot: m.params.boot,
        newest: newest(m),
    });
}

// ---------------------------------------------------------------------------
// Transition subfunctions.

/// Algorithm 4 (`c,c f_1,1,tp`): a new plan is processed, the fragment list emptied,
/// the planner initialised from the state estimate, `new` set.
///
/// `isnew(desired_plan)` is read as "a plan was received and not yet taken": a plan
/// that arrives before `e11`'s first state estimate (at start-up) waits in
/// `pending` for at most `estimate_wait_max` iterations, then is refused.
pub fn cc_1_tp(m: &mut C1Memory, x: &C1Input) {
    keep_incoming(m, x);
    let state = x.e11.q_est.get();
    let Some((desired, waited)) = m.pending.take() else {
        latch(m, x, false);
        return;
    };
    // A stop since the last plan was taken: the platform is not where that plan
    // was to end; the next one starts from the estimate, once the platform has
    // come to rest.
    if epoch(x) > m.plan_epoch {
        m.restart = true;
    }
    let settling = m.restart && state.is_some_and(|s| !at_rest(s));
    if (state.is_none() || settling) && waited < m.params.estimate_wait_max {
        m.pending = Some((desired, waited + 1));
        latch(m, x, false);
        return;
    }
    m.plan_id = desired.id;
    m.taken = m.taken.max(desired.id);
    m.handed = 0;
    m.traj.clear();
    m.new = true;
    m.plan_epoch = epoch(x);
    m.failure = None;
    let processed = proc(&desired, &m.params).and_then(|plan| match state {
        Some(state) if state.is_finite() => Ok((plan, *state)),
        Some(_) => Err("the state estimate is not finite".into()),
        None => Err(format!(
            "no state estimate from e11 after {waited} iterations"
        )),
    });
    match processed {
        Ok((plan, state)) => {
            m.plan = plan;
            m.refusal = None;
            let p = state.pose();
            let pose = [p.x, p.y, p.phi];
            m.trajgen.init(pose, desired.id, desired.first);
            if std::mem::take(&mut m.restart) {
                m.trajgen.restart_from(pose);
            }
        }
        Err(reason) => {
            m.plan.clear();
            m.refusal = Some(reason);
        }
    }
    latch(m, x, false);
}

/// The newest plan id `c1` has taken or holds.
fn newest(m: &C1Memory) -> u32 {
    m.taken.max(m.pending.as_ref().map_or(0, |(p, _)| p.id))
}

/// Whether `plan` is new to `c1`: not a copy of one taken or waiting.
fn unseen(m: &C1Memory, plan: &Plan) -> bool {
    plan.id > m.taken && m.pending.as_ref().is_none_or(|(p, _)| p.id != plan.id)
}

/// Whether `plan` is numbered out of sequence: past the next after the newest
/// this incarnation has (its first plan may have any number: after a restart
/// `a2` sends again those it lost).
fn out_of_sequence(m: &C1Memory, plan: &Plan) -> bool {
    let newest = newest(m);
    newest > 0 && plan.id > newest.saturating_add(1)
}

/// A plan `c1` takes: new to it, and in sequence.
fn acceptable(m: &C1Memory, plan: &Plan) -> bool {
    unseen(m, plan) && !out_of_sequence(m, plan)
}

/// Algorithm 5 (`c,T f_1,1,tp`): a new plan sets `ack` to false; plan outcomes
/// and progress are relayed.
#[expect(
    non_snake_case,
    reason = "the paper's name: the target is the transmission buffer T"
)]
pub fn cT_1_tp(m: &C1Memory, x: &C1Input, y: &mut C1ToC2) {
    if let Some(plan) = x.c2.desired_plan.fresh().filter(|p| acceptable(m, p)) {
        y.ack.set(Ack {
            plan: plan.id,
            status: AckStatus::Received,
        });
    }
    relay(m, x, y);
}

/// `c,T f_1,2`: relay plan outcomes and progress during `B2`.
#[expect(
    non_snake_case,
    reason = "the paper's name: the target is the transmission buffer T"
)]
pub fn cT_2(m: &C1Memory, x: &C1Input, y: &mut C1ToC2) {
    relay(m, x, y);
}

/// Keep a plan that arrives, whatever the behaviour: `B1` takes it (a plan sent
/// during `B2` or `B3` is taken after the current one is acknowledged, never lost).
/// A copy of a plan taken or waiting is ignored; one numbered out of sequence is
/// refused and counted (reported at the end of the run).
fn keep_incoming(m: &mut C1Memory, x: &C1Input) {
    if let Some(plan) = x.c2.desired_plan.fresh()
        && unseen(m, plan)
        && out_of_sequence(m, plan)
    {
        m.out_of_sequence += 1;
        return;
    }
    if let Some(desired) = x.c2.desired_plan.fresh().filter(|p| acceptable(m, p)) {
        if m.pending.is_some() {
            m.superseded += 1;
        }
        m.pending = Some((desired.clone(), 0));
    }
}

/// Keep a `ready` event until a fragment answers it.
fn latch(m: &mut C1Memory, x: &C1Input, handed: bool) {
    m.ready_latch = if handed { false } else { ready(m, x) };
}

/// Algorithm 6 (`c,c f_1,2,tp`): collect planned fragments, drop the one handed over,
/// start planning towards the next point or stop.
pub fn cc_2_tp(m: &mut C1Memory, x: &C1Input) {
    keep_incoming(m, x);
    let ready_i = ready(m, x);
    let gen_ready = m.trajgen.is_ready();
    let mut hand_over = ready_i && !m.traj.is_empty();
    if hand_over && let Some(Err(why)) = front_timed(m, x) {
        // The ground cannot deliver it: the plan fails (B2 ends on
        // `planner_failed`), nothing is handed over.
        m.failure = Some(why);
        hand_over = false;
    }
    if hand_over {
        if gen_ready {
            collect(m);
        }
        m.traj.pop_front();
        m.handed += 1;
    } else if gen_ready {
        collect(m);
    }
    if m.new {
        m.new = false;
        match m.plan.pop_front() {
            Some(p) => m.trajgen.start(p),
            None => m.trajgen.stop(),
        }
    } else if gen_ready {
        match m.plan.pop_front() {
            None => m.trajgen.stop(),
            Some(p) => m.trajgen.start(p),
        }
    } else {
        m.trajgen.stat();
    }
    latch(m, x, hand_over);
}

/// `listAddLast` (also of `listAddLastDelFirst`): the planned fragment joins the
/// list; one that leaves the free space fails the plan instead.
fn collect(m: &mut C1Memory) {
    if let Some(f) = m.trajgen.get_traj() {
        match blocked(&f, &m.params) {
            None => m.traj.push_back(f),
            Some(why) => m.failure = Some(why),
        }
    }
}

/// Algorithm 7 (`c,e f_1,2,tp`): hand the first fragment of the list to `e11` with
/// `steps` and `notify`; relay the pose and the visual odometry.
pub fn ce_2_tp(m: &C1Memory, x: &C1Input, y: &mut C1ToE11) {
    if ready(m, x)
        && let Some(Ok(f)) = front_timed(m, x)
    {
        // The last one: nothing more planned, or to plan.
        let last = !m.new
            && m.plan.is_empty()
            && m.traj.len() == 1
            && *m.trajgen.status() == Status::Stopped;
        y.steps.set(traj_to_steps(&f));
        y.notify.set(traj_to_notify(&f, &m.params));
        y.traj.set(Fragment {
            last,
            epoch: epoch(x),
            ..f
        });
    }
    ce_1(m, x, y);
}

/// Why the plan being served failed, if it did (planner, a fragment leaving the
/// free space, a stop of `e11`).
fn failed(m: &C1Memory, x: &C1Input) -> Option<String> {
    m.trajgen
        .failed()
        .map(str::to_owned)
        .or_else(|| m.failure.clone())
        .or_else(|| stopped(m, x))
}

/// Algorithm 8 (`c,T f_1,3,tp`): `ack`, with how the plan ended; plan outcomes are
/// relayed.
#[expect(
    non_snake_case,
    reason = "the paper's name: the target is the transmission buffer T"
)]
pub fn cT_3_tp(m: &C1Memory, x: &C1Input, y: &mut C1ToC2) {
    let status = match (&m.refusal, failed(m, x)) {
        (Some(reason), _) => AckStatus::Refused(reason.clone()),
        (None, Some(why)) => AckStatus::Failed(why),
        (None, None) => AckStatus::Done,
    };
    y.ack.set(Ack {
        plan: m.plan_id,
        status,
    });
    relay(m, x, y);
}

/// `c,c f_1,3`: forget the plan's flags (so that `B1` waits for the next plan);
/// after a failure the next plan starts from the state estimate.
pub fn cc_3(m: &mut C1Memory, x: &C1Input) {
    keep_incoming(m, x);
    if m.refusal.is_none() && failed(m, x).is_some() {
        m.restart = true;
    }
    m.new = false;
    m.refusal = None;
    m.failure = None;
    latch(m, x, false);
}

/// `c,e f_1` (behaviours 1 and 3): relay the map pose and the visual odometry.
pub fn ce_1(_: &C1Memory, x: &C1Input, y: &mut C1ToE11) {
    if let Some(p) = x.c3.pose.fresh() {
        y.pose.set(*p);
    }
    if let Some(a) = x.r11.A4x4.fresh() {
        y.A4x4.set(*a);
    }
}

/// Relay the state estimate to the map agent.
#[expect(
    non_snake_case,
    reason = "the paper's name: the target is the transmission buffer T"
)]
pub fn cT_q(_: &C1Memory, x: &C1Input, y: &mut C1ToC3) {
    if let Some(q) = x.e11.q_est.fresh() {
        y.q_est.set(*q);
    }
}

/// `c1`'s FSM (Fig. 5, with the refusal arc `B1 → B3`).
pub fn c1_fsm() -> Result<Fsm<C1>, FsmBuildError> {
    fsm! {
        subsystem C1;
        predicates {
            plan_new: |m: &C1Memory, _| m.new,
            plan_valid: |m: &C1Memory, _| m.refusal.is_none(),
            plan_sent: |m: &C1Memory, _| {
                !m.new
                    && m.plan.is_empty()
                    && m.traj.is_empty()
                    && *m.trajgen.status() == Status::Stopped
            },
            planner_failed: |m: &C1Memory, _| m.trajgen.failed().is_some() || m.failure.is_some(),
            stopped: |m: &C1Memory, x: &C1Input| stopped(m, x).is_some(),
        }
        repeat B1 until plan_new { c2 <- cT_1_tp, e11 <- ce_1, c3 <- cT_q, memory <- cc_1_tp }
        repeat B2 until plan_sent || planner_failed || stopped {
            e11 <- ce_2_tp, c2 <- cT_2, c3 <- cT_q, memory <- cc_2_tp
        }
        repeat B3 until true { c2 <- cT_3_tp, e11 <- ce_1, c3 <- cT_q, memory <- cc_3 }
        initial B1;
        B1 -> B2 when plan_valid;
        B1 -> B3 when !plan_valid;
        B2 -> B3;
        B3 -> B1;
    }
}

#[cfg(test)]
mod tests;
