//! What the probes of a run that is not stepped by us (real-time threads, or
//! processes of a deployment) report, and how it becomes an [`Outcome`]: the
//! same pairing as the deterministic run (e11's activation at `t` with the
//! platform's true pose at `t`), the same end of mission (every plan sent and
//! acknowledged, the last fragment executed), the same judgement.

use embodied::app::{Every, Pairs, Ran, Tally, Watcher};
use embodied::{Probes, Time};
use serde::{Deserialize, Serialize};

use super::{Outcome, Progress, Sample};
use crate::payload::{Ack, PlanOutcome, Point2};
use crate::system::{RexConfig, RobotHandles};
use crate::world::devices::{MotionCapture, Truth};

/// One report of a probe on Rex (or of a process at its end): what a run's
/// watcher reads, in one process or from every process of a deployment.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub enum Seen {
    /// After an activation of e11.
    E11 {
        /// Its instant.
        t: Time,
        /// What it tracks (the truth is filled in when paired).
        sample: Sample,
        /// A plan outcome it reported in that activation.
        event: Option<PlanOutcome>,
        /// Nothing to execute and nothing to report.
        idle: bool,
    },
    /// c1's behaviour (0 = B1, 1 = B2, 2 = B3) when it changed or c1 took a
    /// plan.
    C1 {
        /// The behaviour.
        behaviour: u8,
        /// The plan c1 took in that activation, with its last point (`None`
        /// for a plan refused as it was taken: its points are not kept).
        took: Option<(u32, Option<Point2>)>,
    },
    /// a2's new acknowledgements, whether it has ended, and the plans it sent.
    C2 {
        /// Its instant.
        t: Time,
        /// The acknowledgements received in that activation.
        acks: Vec<Ack>,
        /// Whether it halted (every plan acknowledged).
        halted: bool,
        /// Plans sent so far.
        sent: usize,
    },
    /// The platform's true pose `(X, Y, φ)` at `at`.
    Truth {
        /// The instant of the state.
        at: Time,
        /// The pose.
        pose: [f64; 3],
    },
    /// The last pose the motion capture delivered, and when.
    Mocap(Option<f64>),
    /// A process's counters at its end (its components' part of the run's).
    Counters(Box<super::Counters>),
    /// The planner's, tracker's and estimator's names, from the process that
    /// ran c1 (the planner) and e11 (the others).
    Parts([Option<String>; 3]),
}

/// What reads a mission as it runs (through Rex's probes, in any executor and
/// from every process of a deployment): it pairs e11's samples with the truth,
/// tells `progress` of acknowledgements and ticks, decides the mission's end
/// and judges the outcome.
pub(crate) struct MissionWatch<P> {
    pub(crate) out: Outcome,
    pub(crate) config: RexConfig,
    pub(crate) progress: P,
    /// e11's reports (a sample, a plan outcome, whether idle) paired with the
    /// true pose at their instant.
    pairs: Pairs<(Sample, Option<PlanOutcome>, bool), [f64; 3]>,
    behaviour: u8,
    delivered_at: Option<f64>,
    mocap_since: Option<f64>,
    a2_done: bool,
    idle: bool,
    /// The mission's plans (ids `1..=n`): c1's plans numbered after them came
    /// from another sender.
    own: u32,
    sent: usize,
    /// When a progress tick is due.
    tick: Every,
}

impl<P: FnMut(Progress<'_>)> MissionWatch<P> {
    pub(crate) fn new(config: &RexConfig, tick: std::time::Duration, progress: P) -> Self {
        MissionWatch {
            out: Outcome {
                mission: config.mission.name.clone(),
                plans: config.mission.plans.len(),
                ..Outcome::default()
            },
            config: config.clone(),
            progress,
            pairs: Pairs::default(),
            behaviour: 0,
            delivered_at: None,
            mocap_since: None,
            a2_done: false,
            idle: false,
            own: config.mission.plans.len() as u32,
            sent: 0,
            tick: Every::new(tick),
        }
    }

    /// The run's outcome, judged, once every report is in (`wall` and `sim`:
    /// the run's wall-clock and simulated seconds).
    pub(crate) fn outcome(&mut self, wall: f64, sim: f64) -> Outcome {
        let mut out = std::mem::take(&mut self.out);
        out.wall_s = wall;
        out.sim_s = sim;
        out.reports = super::judge::judge(&out, &self.config, self.sent);
        out
    }

    /// The end of a run in this process: the last reports read off its
    /// nodes, then the outcome.
    pub(crate) fn conclude(&mut self, ran: &Ran, h: impl Into<RobotHandles>) -> Outcome {
        ran.conclude(self, super::last_reports(&ran.finished, h));
        let sim = ran.finished.report().last_instant.as_secs_f64();
        self.outcome(ran.wall.as_secs_f64(), sim)
    }

    /// Whether every plan c1 took from another sender has its final
    /// acknowledgement.
    fn foreign_answered(&self) -> bool {
        self.out.foreign.iter().all(|(id, _)| {
            self.out
                .acks
                .iter()
                .any(|(_, a)| a.plan == *id && a.ready())
        })
    }
}

impl<P: FnMut(Progress<'_>)> Watcher<Seen> for MissionWatch<P> {
    /// Take one report in.
    fn see(&mut self, seen: Seen) {
        match seen {
            Seen::E11 {
                t,
                sample,
                event,
                idle,
            } => self.pairs.sample(t, (sample, event, idle)),
            Seen::C1 { behaviour, took } => {
                self.behaviour = behaviour;
                // A plan numbered after the mission's is another sender's: it
                // is counted and judged with them (once: after a restart of
                // c1 it is taken again).
                if let Some((plan, end)) = took
                    && plan > self.own
                    && !self.out.foreign.iter().any(|(p, _)| *p == plan)
                {
                    self.out.foreign.push((plan, end));
                    self.out.plans += 1;
                }
            }
            Seen::C2 {
                t,
                acks,
                halted,
                sent,
            } => {
                for ack in acks {
                    let ts = t.as_secs_f64();
                    (self.progress)(Progress::Ack { t: ts, ack: &ack });
                    self.out.acks.push((ts, ack));
                }
                self.a2_done |= halted;
                self.sent = self.sent.max(sent);
            }
            Seen::Truth { at, pose } => self.pairs.reference(at, pose),
            Seen::Mocap(at) => self.delivered_at = at.or(self.delivered_at),
            Seen::Counters(c) => self.out.counters.tally(*c),
            Seen::Parts(parts) => {
                for (mine, given) in self.out.parts.iter_mut().zip(parts) {
                    if let Some(name) = given {
                        *mine = name;
                    }
                }
            }
        }
    }

    /// Pair the samples whose instant the world has passed (all of them once
    /// the run is `finished`) with the truth. Returns whether the mission has
    /// ended: a2 has every acknowledgement and e11 is idle. A listening
    /// mission never ends before the run does: once `finished`, it is
    /// complete if every plan c1 took has its final acknowledgement and e11
    /// is idle (nothing left executing).
    fn ended(&mut self, finished: bool) -> bool {
        for (t, (mut sample, event, idle), truth) in self.pairs.take(finished) {
            let ts = t.as_secs_f64();
            if let Some(o) = event {
                self.out.outcomes.push((ts, o));
            }
            self.idle = idle;
            let Some(pose) = truth else {
                continue;
            };
            let delivering = self.delivered_at.is_some_and(|at| at >= ts - 0.05);
            self.mocap_since = if delivering {
                self.mocap_since.or(Some(ts))
            } else {
                None
            };
            sample.truth = pose;
            sample.behaviour = self.behaviour;
            sample.mocap_for = self.mocap_since.map_or(0.0, |since| ts - since);
            self.out.samples.push(sample);
            if self.tick.due(t) {
                (self.progress)(Progress::Tick {
                    t: ts,
                    sample: &sample,
                });
            }
        }
        if self.config.mission.listens() {
            if finished {
                self.out.completed = self.idle && self.foreign_answered();
            }
            return false;
        }
        if self.a2_done && self.idle && !self.out.completed {
            self.out.completed = true;
        }
        self.out.completed
    }
}

/// Probes on the components `here` says run in this process: e11 (what it
/// tracks), c1 (its behaviour), a2 (acknowledgements), the world (the true
/// pose) and the motion capture (deliveries).
pub(crate) fn install_probes(
    probes: &mut Probes<Seen>,
    h: impl Into<RobotHandles>,
    here: &dyn Fn(&str) -> bool,
) {
    let h = &h.into();
    // In the order they always were: e11, c1, c2, the truth, the motion capture.
    install_probes_as(probes, h, &|name| name != "R3" && here(name), |seen| seen);
    if here("E1") {
        probes.environment(|_, w: &Truth| {
            let s = &w.state;
            // The truth after the world's step at `t` is the state at `w.time`.
            let at = Time::from_nanos((w.time * 1e9).round().max(0.0) as u64);
            Some(Seen::Truth {
                at,
                pose: [s.x, s.y, s.phi],
            })
        });
    }
    install_probes_as(probes, h, &|name| name == "R3" && here(name), |seen| seen);
}

/// [`install_probes`] but for the truth, each report passed through `tag`
/// (a fleet's probes say which robot reports; the fleet reads its truth
/// itself).
pub(crate) fn install_probes_as<M: Send + 'static>(
    probes: &mut Probes<M>,
    h: &RobotHandles,
    here: &dyn Fn(&str) -> bool,
    tag: impl Fn(Seen) -> M + Clone + Send + 'static,
) {
    if here("e11") {
        let tag = tag.clone();
        probes.subsystem(&h.e11, move |p| {
            let m = p.memory;
            let est = m.estym.estimate.x;
            Some(tag(Seen::E11 {
                t: p.time,
                sample: Sample {
                    t: p.time.as_secs_f64(),
                    truth: [f64::NAN; 3],
                    estimate: [est[0], est[1], est[2]],
                    reference: m.track.reference,
                    executing: m.track.following.is_some(),
                    tau: m.tau,
                    behaviour: 0,
                    fragment: m.track.following,
                    mocap_for: 0.0,
                    vo_lost: m.vo.lost,
                    friction: m
                        .estym
                        .estimate
                        .friction
                        .map_or([f64::NAN; 3], |f| f.to_array()),
                },
                event: m.event.clone(),
                idle: m.track.running.is_none()
                    && m.track.queue.is_empty()
                    && m.arrival.is_none()
                    && m.outbox.is_empty(),
            }))
        });
    }
    if here("c1") {
        let tag = tag.clone();
        let mut last = None;
        let mut last_took = None;
        probes.subsystem(&h.c1, move |p| {
            let b = match p.behaviour {
                "B2" => 1u8,
                "B3" => 2,
                _ => 0,
            };
            // The activation that took a plan leaves `new` set (B2 or B3
            // clears it), the plan's points processed in `plan`.
            let m = p.memory;
            let took = (m.new && last_took.replace(m.plan_id) != Some(m.plan_id)).then(|| {
                let end = m.plan.back().map(|w| Point2 { x: w.x, y: w.y });
                (m.plan_id, end)
            });
            // Only changes: c1's behaviour is a state, not a stream.
            (last.replace(b) != Some(b) || took.is_some())
                .then(|| tag(Seen::C1 { behaviour: b, took }))
        });
    }
    if let Some(c2) = h.c2.filter(|_| here("c2")) {
        let tag = tag.clone();
        let mut acks_sent = 0;
        let mut sent = 0;
        probes.subsystem(&c2, move |p| {
            let new: Vec<Ack> = p.memory.acks.iter().skip(acks_sent).cloned().collect();
            acks_sent = p.memory.acks.len();
            let more = p.memory.next != sent;
            sent = p.memory.next;
            (!new.is_empty() || p.halted || more).then(|| {
                tag(Seen::C2 {
                    t: p.time,
                    acks: new,
                    halted: p.halted,
                    sent,
                })
            })
        });
    }
    if here("R3") {
        let mut last = None;
        probes.driver(&h.map.mocap, move |_, m: &MotionCapture| {
            let at = m.last_delivered().map(|(at, _)| at);
            (at.is_some() && at != last).then(|| {
                last = at;
                tag(Seen::Mocap(at))
            })
        });
    }
}
