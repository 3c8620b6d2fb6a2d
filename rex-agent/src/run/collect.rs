//! What the probes of a run that is not stepped by us (real-time threads, or
//! processes of a deployment) report, and how it becomes an [`Outcome`]: the
//! same pairing as the deterministic run (e11's activation at `t` with the
//! platform's true pose at `t`), the same end of mission (every plan sent and
//! acknowledged, the last fragment executed), the same judgement.

use std::collections::BTreeMap;

use embodied::Time;
use serde::{Deserialize, Serialize};

use super::{Outcome, Progress, Sample};
use crate::a1::RexConfig;
use crate::a1::payload::{Ack, PlanOutcome};

/// One report of a probe.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) enum Seen {
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
    /// c1's behaviour (0 = B1, 1 = B2, 2 = B3).
    C1(u8),
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
}

/// Turns what the probes report into an outcome.
pub(crate) struct Collector {
    pub(crate) out: Outcome,
    truths: BTreeMap<Time, [f64; 3]>,
    pending: Vec<(Time, Sample, Option<PlanOutcome>, bool)>,
    behaviour: u8,
    delivered_at: Option<f64>,
    mocap_since: Option<f64>,
    a2_done: bool,
    idle: bool,
    /// The latest instant of e11 seen: truths from it on may still be needed.
    last_e11: Time,
    pub(crate) sent: usize,
    tick_ns: u128,
    next_tick: u128,
}

impl Collector {
    pub(crate) fn new(config: &RexConfig, tick: std::time::Duration) -> Self {
        let tick_ns = tick.as_nanos().max(1);
        Collector {
            out: Outcome {
                mission: config.mission.name.clone(),
                plans: config.mission.plans.len(),
                ..Outcome::default()
            },
            truths: BTreeMap::new(),
            pending: Vec::new(),
            behaviour: 0,
            delivered_at: None,
            mocap_since: None,
            a2_done: false,
            idle: false,
            last_e11: Time::ZERO,
            sent: 0,
            tick_ns,
            next_tick: tick_ns,
        }
    }

    /// The latest instant of the world seen [s] (a distributed run's clock).
    #[cfg(feature = "distributed")]
    pub(crate) fn time(&self) -> f64 {
        self.truths
            .keys()
            .next_back()
            .copied()
            .unwrap_or(self.last_e11)
            .as_secs_f64()
    }

    /// Take one report in.
    pub(crate) fn see(&mut self, seen: Seen, progress: &mut impl FnMut(Progress<'_>)) {
        match seen {
            Seen::E11 {
                t,
                sample,
                event,
                idle,
            } => {
                self.last_e11 = self.last_e11.max(t);
                self.pending.push((t, sample, event, idle));
            }
            Seen::C1(b) => self.behaviour = b,
            Seen::C2 {
                t,
                acks,
                halted,
                sent,
            } => {
                for ack in acks {
                    let ts = t.as_secs_f64();
                    progress(Progress::Ack { t: ts, ack: &ack });
                    self.out.acks.push((ts, ack));
                }
                self.a2_done |= halted;
                self.sent = self.sent.max(sent);
            }
            Seen::Truth { at, pose } => {
                self.truths.insert(at, pose);
            }
            Seen::Mocap(at) => self.delivered_at = at.or(self.delivered_at),
            Seen::Counters(c) => self.out.counters.absorb(*c),
        }
    }

    /// Pair the samples whose instant the world has passed (all of them once
    /// the run is `finished`) with the truth. Returns whether the mission has
    /// ended: a2 has every acknowledgement and e11 is idle.
    pub(crate) fn advance(
        &mut self,
        finished: bool,
        progress: &mut impl FnMut(Progress<'_>),
    ) -> bool {
        let world_at = self
            .truths
            .keys()
            .next_back()
            .copied()
            .unwrap_or(Time::ZERO);
        self.pending.sort_by_key(|p| p.0);
        let split = self
            .pending
            .iter()
            .position(|p| !(p.0 <= world_at || finished))
            .unwrap_or(self.pending.len());
        let ready: Vec<_> = self.pending.drain(..split).collect();
        for (t, mut sample, event, idle) in ready {
            let ts = t.as_secs_f64();
            if let Some(o) = event {
                self.out.outcomes.push((ts, o));
            }
            self.idle = idle;
            let Some(pose) = self.truths.get(&t) else {
                continue;
            };
            let delivering = self.delivered_at.is_some_and(|at| at >= ts - 0.05);
            self.mocap_since = if delivering {
                self.mocap_since.or(Some(ts))
            } else {
                None
            };
            sample.truth = *pose;
            sample.behaviour = self.behaviour;
            sample.mocap_for = self.mocap_since.map_or(0.0, |since| ts - since);
            self.out.samples.push(sample);
            if u128::from(t.as_nanos()) >= self.next_tick {
                self.next_tick += self.tick_ns;
                progress(Progress::Tick {
                    t: ts,
                    sample: &sample,
                });
            }
        }
        // Truth older than the oldest sample waiting, and than the latest sample
        // seen, is no longer needed (a sample's truth often arrives first).
        let keep_from = self.pending.first().map_or(self.last_e11, |p| p.0);
        self.truths = self.truths.split_off(&keep_from);
        if self.a2_done && self.idle && !self.out.completed {
            self.out.completed = true;
        }
        self.out.completed
    }
}
