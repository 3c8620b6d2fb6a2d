//! The verdict on each plan of a run, measured with the simulation's truth.
//!
//! a1 judges itself with what it can know: `e11` reports a plan reached when its
//! *estimate* comes within the tolerance of the plan's last point, and stops the
//! platform when the estimate leaves the free space. A run checks those words
//! against the truth: the true position when `e11` reported the plan reached, the
//! true tracking error and the estimate's error while the plan ran, and the true
//! distance to walls and obstacles. A plan is achieved only when a1 said so and
//! the truth agrees. The estimate is held to its limit only while the motion
//! capture delivers (during a dropout nothing tells a1 where it is).

use std::fmt;

use super::Outcome;
use crate::a1::map::Map;
use crate::payload::{AckStatus, Execution, Point2};
use crate::system::{Limits, RexConfig};

/// How a plan went.
#[derive(Clone, Debug, PartialEq)]
pub enum Verdict {
    /// a1 reported it reached, and the truth agrees within every limit.
    Achieved,
    /// a1 reported that it failed (refused, planning failed, stopped, missed).
    Failed(String),
    /// a1 reported it reached, but the platform was not at its last point.
    FalseSuccess(String),
    /// a1 reported it reached, and it was, but a limit was broken on the way
    /// (tracking error, estimate error, clearance).
    Violated(String),
    /// No outcome before the run ended.
    Unfinished(String),
    /// The run ended before `a2` sent it.
    NotSent,
}

impl fmt::Display for Verdict {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Verdict::Achieved => f.write_str("achieved"),
            Verdict::Failed(why) => write!(f, "FAILED: {why}"),
            Verdict::FalseSuccess(why) => write!(f, "FALSE SUCCESS: {why}"),
            Verdict::Violated(why) => write!(f, "FAILED (limit broken): {why}"),
            Verdict::Unfinished(why) => write!(f, "UNFINISHED: {why}"),
            Verdict::NotSent => f.write_str("not sent"),
        }
    }
}

/// One plan of a run, judged.
#[derive(Clone, Debug, PartialEq)]
pub struct PlanReport {
    /// The plan's id (1-based, the mission's order; a plan from another
    /// sender has its own, after the mission's).
    pub plan: u32,
    /// Whether another sender than `a2` gave it to `c1` (ROS 2).
    pub foreign: bool,
    /// a1's final acknowledgement (`Done`, `Refused`, `Failed`).
    pub ack: Option<AckStatus>,
    /// How `e11` reported the execution ended, and when \[s\].
    pub outcome: Option<(f64, Execution)>,
    /// True distance to the plan's last point when `e11` reported the outcome \[m\].
    pub end_error_m: Option<f64>,
    /// Largest true tracking error while the plan's fragments ran \[m\].
    pub max_tracking_m: f64,
    /// Largest error of the estimated position meanwhile, while the motion
    /// capture delivered (see [`crate::run::Sample::with_mocap`]) \[m\].
    pub max_estimate_m: f64,
    /// The verdict.
    pub verdict: Verdict,
}

impl fmt::Display for PlanReport {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let from = if self.foreign { " (not a2's)" } else { "" };
        write!(f, "plan {}{from}: {}", self.plan, self.verdict)?;
        if self.verdict != Verdict::NotSent {
            write!(
                f,
                " (tracking error up to {:.3} m, estimate error up to {:.3} m",
                self.max_tracking_m, self.max_estimate_m
            )?;
            if let Some(e) = self.end_error_m {
                write!(f, ", {e:.3} m from the last point")?;
            }
            f.write_str(")")?;
        }
        Ok(())
    }
}

/// Judge every plan of `out`'s mission, `sent` of which `a2` sent, then every
/// plan `c1` took from another sender ([`Outcome::foreign`]), each against
/// its own last point.
pub fn judge(out: &Outcome, config: &RexConfig, sent: usize) -> Vec<PlanReport> {
    let limits = &config.limits;
    let map = limits.safety_map(&config.world);
    let mission = config.mission.plans.iter().enumerate().map(|(k, points)| {
        let id = k as u32 + 1;
        (id, points.last().copied(), k < sent, false)
    });
    let foreign = out.foreign.iter().map(|&(id, last)| (id, last, true, true));
    mission
        .chain(foreign)
        .map(|plan| judge_plan(out, limits, &map, plan))
        .collect()
}

/// Judge one plan of `out`: its id, last point, whether it was sent (a
/// plan from another sender was), and whether it came from another sender.
fn judge_plan(
    out: &Outcome,
    limits: &Limits,
    map: &Map,
    (id, last, was_sent, foreign): (u32, Option<Point2>, bool, bool),
) -> PlanReport {
    let ack = out
        .acks
        .iter()
        .rev()
        .find(|(_, a)| a.plan == id && a.ready())
        .map(|(_, a)| a.status.clone());
    let outcome = out
        .outcomes
        .iter()
        .find(|(_, o)| o.plan == id)
        .map(|(t, o)| (*t, o.result.clone()));
    let samples: Vec<_> = out
        .samples
        .iter()
        .filter(|s| s.fragment.is_some_and(|(p, _)| p == id))
        .collect();
    let max_tracking = samples.iter().filter_map(|s| s.error()).fold(0.0, f64::max);
    let max_estimate = samples
        .iter()
        .filter(|s| s.with_mocap())
        .map(|s| s.estimate_error())
        .fold(0.0, f64::max);
    let too_close = samples.iter().find_map(|s| {
        map.explain(s.truth[0], s.truth[1])
            .err()
            .map(|why| format!("at {:.2} s the platform at {why}", s.t))
    });
    let end_error = outcome.as_ref().and_then(|(t, o)| {
        if matches!(o, Execution::Stopped(_)) {
            return None;
        }
        let s = out.samples.iter().find(|s| s.t >= *t)?;
        let p = last?;
        Some((s.truth[0] - p.x).hypot(s.truth[1] - p.y))
    });
    let verdict = if !was_sent {
        Verdict::NotSent
    } else {
        match (&ack, &outcome) {
            (Some(AckStatus::Refused(why)), _) => Verdict::Failed(format!("refused: {why}")),
            (Some(AckStatus::Failed(why)), _) => Verdict::Failed(why.clone()),
            (_, Some((_, Execution::Stopped(why)))) => Verdict::Failed(format!("stopped: {why}")),
            (_, Some((_, Execution::Missed { error_m }))) => Verdict::Failed(format!(
                "missed its last point by {error_m:.3} m (estimated; tolerance {:.2} m)",
                limits.final_m
            )),
            (_, Some((_, Execution::Reached { .. }))) => match end_error {
                Some(e) if e > limits.final_m => Verdict::FalseSuccess(format!(
                    "reported reached, but the platform was {e:.3} m from the last point (tolerance {:.2} m)",
                    limits.final_m
                )),
                None => {
                    Verdict::FalseSuccess("reported reached, with no sample to confirm it".into())
                }
                Some(_) if max_tracking > limits.tracking_m => Verdict::Violated(format!(
                    "tracking error {max_tracking:.3} m (limit {:.2} m)",
                    limits.tracking_m
                )),
                Some(_) if max_estimate > limits.estimate_m => Verdict::Violated(format!(
                    "estimate error {max_estimate:.3} m (limit {:.2} m)",
                    limits.estimate_m
                )),
                Some(_) => match too_close {
                    Some(why) => Verdict::Violated(why),
                    None => Verdict::Achieved,
                },
            },
            (Some(_), None) => {
                Verdict::Unfinished("no outcome from e11 before the run ended".into())
            }
            (None, None) => Verdict::Unfinished("not acknowledged".into()),
        }
    };
    PlanReport {
        plan: id,
        foreign,
        ack,
        outcome,
        end_error_m: end_error,
        max_tracking_m: max_tracking,
        max_estimate_m: max_estimate,
        verdict,
    }
}
