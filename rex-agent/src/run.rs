//! Running a Rex mission in the deterministic executor and collecting what happened.

use std::time::{Duration, Instant};

use embodied::{ExecConfig, ExecError, Executor, NoObserver, Time};

use crate::rex::{RexConfig, RexError, RexHandles, build};
use crate::types::{Ack, AckStatus};

/// One sample of a run, every period of e11.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    /// Simulation time [s].
    pub t: f64,
    /// True pose `(X, Y, φ)`.
    pub truth: [f64; 3],
    /// Estimated pose.
    pub estimate: [f64; 3],
    /// Reference `(X, Y, φ, v, ω)`, when e11 follows one.
    pub reference: Option<[f64; 5]>,
    /// Whether a fragment is being executed (not holding a point).
    pub executing: bool,
    /// Torques commanded.
    pub tau: [f64; 4],
    /// c1's behaviour (index: 0 = B1, 1 = B2, 2 = B3).
    pub behaviour: u8,
}

impl Sample {
    /// Distance between the true position and the reference position.
    pub fn error(&self) -> Option<f64> {
        self.reference
            .map(|r| (r[0] - self.truth[0]).hypot(r[1] - self.truth[1]))
    }
}

/// What a run produced.
#[derive(Clone, Debug, Default)]
pub struct Outcome {
    /// The mission's name.
    pub mission: String,
    /// Plans in the mission.
    pub plans: usize,
    /// Acknowledgements received by a2 (with their arrival time).
    pub acks: Vec<(f64, Ack)>,
    /// Samples every e11 period.
    pub samples: Vec<Sample>,
    /// Simulated time [s].
    pub sim_s: f64,
    /// Wall-clock time [s].
    pub wall_s: f64,
    /// Fragments executed by e11.
    pub fragments: u32,
    /// Measurements rejected by the estimator.
    pub rejected_measurements: u64,
    /// Torque commands clamped or rejected by the platform.
    pub clamped_torques: u64,
    /// Whether the mission ended (every plan acknowledged and the last fragment done).
    pub completed: bool,
    /// Planner figures: fragments, iterations, failures.
    pub planner: (u64, u64, u64),
}

impl Outcome {
    /// Plans acknowledged as done.
    pub fn plans_done(&self) -> usize {
        self.acks
            .iter()
            .filter(|(_, a)| a.status == AckStatus::Done)
            .count()
    }

    /// RMS of the tracking error over the samples that follow a fragment.
    pub fn rms(&self) -> f64 {
        let e: Vec<f64> = self
            .samples
            .iter()
            .filter(|s| s.executing)
            .filter_map(Sample::error)
            .collect();
        if e.is_empty() {
            return 0.0;
        }
        (e.iter().map(|x| x * x).sum::<f64>() / e.len() as f64).sqrt()
    }

    /// Largest tracking error while following fragments.
    pub fn max_error(&self) -> f64 {
        self.samples
            .iter()
            .filter(|s| s.executing)
            .filter_map(Sample::error)
            .fold(0.0, f64::max)
    }

    /// The summary line of the main job.
    pub fn summary_line(&self) -> String {
        format!(
            "mission={} plans_acked={}/{} rms_m={:.4} max_m={:.4} realtime_factor={:.1}",
            self.mission,
            self.acks.len(),
            self.plans,
            self.rms(),
            self.max_error(),
            self.sim_s / self.wall_s.max(1e-9)
        )
    }
}

/// Why a run failed.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// Rex could not be built.
    #[error(transparent)]
    Build(#[from] RexError),
    /// The executor stopped on an error.
    #[error(transparent)]
    Exec(#[from] ExecError),
}

/// Run `config`'s mission until every plan is acknowledged and the platform has
/// executed the last fragment (or `limit` of simulated time); `progress` sees each
/// acknowledgement as it arrives.
pub fn run_mission(
    config: &RexConfig,
    limit: Duration,
    mut progress: impl FnMut(f64, &Ack),
) -> Result<Outcome, RunError> {
    let (system, h, _truth) = build(config)?;
    let mut exec: Executor<NoObserver> = Executor::new(system, ExecConfig::default());
    let wall = Instant::now();
    let dt = Duration::from_secs_f64(0.05);
    let end = Time::from_nanos(0).saturating_add(limit);
    let mut out = Outcome {
        mission: config.mission.name.clone(),
        plans: config.mission.plans.len(),
        ..Outcome::default()
    };
    let mut seen = 0;
    while exec.now() < end {
        exec.run_for(dt)?;
        let t = exec.now().as_secs_f64();
        sample(&exec, &h, t, &mut out);
        if let Some(m) = exec.memory(&h.c2) {
            for ack in &m.acks[seen..] {
                progress(t, ack);
                out.acks.push((t, ack.clone()));
            }
            seen = m.acks.len();
        }
        let idle = exec
            .memory(&h.e11)
            .is_some_and(|m| m.track.running.is_none() && m.track.queue.is_empty());
        if exec.is_halted(h.c2.id()) && idle {
            out.completed = true;
            break;
        }
    }
    out.wall_s = wall.elapsed().as_secs_f64();
    out.sim_s = exec.now().as_secs_f64();
    if let Some(m) = exec.memory(&h.e11) {
        out.fragments = m.track.completed;
        out.rejected_measurements = m.estym.estimator.rejected();
    }
    if let Some(p) = exec.driver(&h.platform) {
        let s = p.command_stats();
        out.clamped_torques = s.not_finite + s.out_of_bounds;
    }
    if let Some(m) = exec.memory(&h.c1) {
        let t = m.trajgen.totals();
        out.planner = (t.fragments, t.iterations, t.failures);
    }
    Ok(out)
}

fn sample(exec: &Executor<NoObserver>, h: &RexHandles, t: f64, out: &mut Outcome) {
    let (Some(p), Some(e11)) = (exec.driver(&h.platform), exec.memory(&h.e11)) else {
        return;
    };
    let s = p.plant().state;
    let est = e11.estym.estimate.x;
    let behaviour = match exec.behaviour(&h.c1) {
        Some("B2") => 1,
        Some("B3") => 2,
        _ => 0,
    };
    out.samples.push(Sample {
        t,
        truth: [s.x, s.y, s.phi],
        estimate: [est[0], est[1], est[2]],
        reference: e11.track.reference,
        executing: e11.track.running.is_some(),
        tau: e11.tau,
        behaviour,
    });
}
