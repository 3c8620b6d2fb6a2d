//! Running a Rex mission in real time: the same system as [`run_mission`](super::run_mission),
//! on threads against the wall clock ([`embodied::RealTime`]): the world (the 1 kHz
//! plant, the camera, the motion capture) on one thread, every subsystem on its
//! own, as on the robot.
//!
//! The run is watched through probes: `e11` reports what it tracks after each
//! activation, the world reports the platform's true pose after each of its
//! instants, `a2` reports its acknowledgements. A sample pairs `e11`'s activation
//! at `t` with the true pose at `t` (the world's report whose truth time is `t`), as
//! the deterministic run does. The mission ends as there: every plan sent,
//! acknowledged, and the last fragment executed.

use std::collections::BTreeMap;
use std::sync::mpsc::RecvTimeoutError;
use std::time::{Duration, Instant};

use embodied::{RealTime, RtConfig, RtReport, Time};

use super::{Outcome, Progress, RunError, Sample, finish_counters};
use crate::a1::payload::{Ack, PlanOutcome};
use crate::a1::{RexConfig, build};
use crate::report::judge;
use crate::world::devices::Truth;

/// What `e11` reports after an activation.
struct E11View {
    t: Time,
    sample: Sample,
    event: Option<PlanOutcome>,
    idle: bool,
}

/// Why the real-time run failed to start or ended badly.
#[derive(Debug, thiserror::Error)]
pub enum RtRunError {
    /// Rex could not be built or the executor failed.
    #[error(transparent)]
    Run(#[from] RunError),
    /// The threads could not run.
    #[error(transparent)]
    Rt(#[from] embodied::RtError),
}

/// Run `config`'s mission in real time, for at most `limit` of wall-clock time.
/// Returns the outcome (judged as the deterministic run's is) and what the
/// executor measured.
pub fn run_mission_realtime(
    config: &RexConfig,
    limit: Duration,
    tick: Duration,
    rt: RtConfig,
    mut progress: impl FnMut(Progress<'_>),
) -> Result<(Outcome, RtReport), RtRunError> {
    let (system, h) = build(config).map_err(RunError::from)?;
    let mut rt = RealTime::new(
        system,
        RtConfig {
            exec: config.exec,
            ..rt
        },
    );
    let e11 = rt.probe(&h.e11, |p| {
        let m = p.memory;
        let est = m.estym.estimate.x;
        Some(E11View {
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
            },
            event: m.event.clone(),
            idle: m.track.running.is_none()
                && m.track.queue.is_empty()
                && m.arrival.is_none()
                && m.outbox.is_empty(),
        })
    });
    let c1 = rt.probe(&h.c1, |p| {
        Some(match p.behaviour {
            "B2" => 1u8,
            "B3" => 2,
            _ => 0,
        })
    });
    // Acknowledgements as they arrive, and whether a2 has ended.
    let mut acks_sent = 0;
    let c2 = rt.probe(&h.c2, move |p| {
        let new: Vec<Ack> = p.memory.acks.iter().skip(acks_sent).cloned().collect();
        acks_sent = p.memory.acks.len();
        (!new.is_empty() || p.halted).then_some((p.time, new, p.halted))
    });
    let truth = rt.probe_environment(|_, w: &Truth| {
        let s = &w.state;
        // The truth after the world's step at `t` is the state at `w.time`.
        let at = Time::from_nanos((w.time * 1e9).round().max(0.0) as u64);
        Some((at, [s.x, s.y, s.phi]))
    });
    let mocap = rt.probe_driver(
        &h.map.mocap,
        |t, m: &crate::world::devices::MotionCapture| {
            Some((t, m.last_delivered().map(|(at, _)| at)))
        },
    );
    let mut out = Outcome {
        mission: config.mission.name.clone(),
        plans: config.mission.plans.len(),
        ..Outcome::default()
    };
    let running = rt.start(limit)?;
    let wall = Instant::now();
    let mut truths: BTreeMap<Time, [f64; 3]> = BTreeMap::new();
    let mut pending: Vec<E11View> = Vec::new();
    let mut behaviour = 0u8;
    let mut delivered_at: Option<f64> = None;
    let mut mocap_since: Option<f64> = None;
    let mut a2_done = false;
    let tick_ns = tick.as_nanos().max(1);
    let mut next_tick = tick_ns;
    loop {
        let finished = running.is_finished();
        match e11.recv_timeout(Duration::from_millis(5)) {
            Ok(v) => pending.push(v),
            Err(RecvTimeoutError::Timeout) => {}
            // e11's thread ended (the others may not have yet): wait, don't spin.
            Err(RecvTimeoutError::Disconnected) => std::thread::sleep(Duration::from_millis(5)),
        }
        pending.extend(e11.try_iter());
        truths.extend(truth.try_iter());
        if let Some(b) = c1.try_iter().last() {
            behaviour = b;
        }
        for (_, at) in mocap.try_iter() {
            delivered_at = at.or(delivered_at);
        }
        for (t, acks, halted) in c2.try_iter() {
            for ack in acks {
                let ts = t.as_secs_f64();
                progress(Progress::Ack { t: ts, ack: &ack });
                out.acks.push((ts, ack));
            }
            a2_done |= halted;
        }
        // Samples whose instant the world has passed: pair them with the truth.
        let world_at = truths.keys().next_back().copied().unwrap_or(Time::ZERO);
        let (ready, later): (Vec<E11View>, Vec<E11View>) =
            pending.drain(..).partition(|v| v.t <= world_at || finished);
        pending = later;
        let mut idle = false;
        for mut v in ready {
            let ts = v.t.as_secs_f64();
            if let Some(o) = v.event.take() {
                out.outcomes.push((ts, o));
            }
            idle = v.idle;
            let Some(pose) = truths.get(&v.t) else {
                continue;
            };
            let delivering = delivered_at.is_some_and(|at| at >= ts - 0.05);
            mocap_since = if delivering {
                mocap_since.or(Some(ts))
            } else {
                None
            };
            v.sample.truth = *pose;
            v.sample.behaviour = behaviour;
            v.sample.mocap_for = mocap_since.map_or(0.0, |since| ts - since);
            out.samples.push(v.sample);
            if u128::from(v.t.as_nanos()) >= next_tick {
                next_tick += tick_ns;
                progress(Progress::Tick {
                    t: ts,
                    sample: &v.sample,
                });
            }
        }
        // Truth older than the oldest sample waiting is no longer needed.
        let keep_from = pending.first().map_or(world_at, |v| v.t);
        truths = truths.split_off(&keep_from);
        if a2_done && idle && !out.completed {
            out.completed = true;
            running.stop();
        }
        if finished {
            break;
        }
    }
    let finished = running.join()?;
    out.wall_s = wall.elapsed().as_secs_f64();
    out.sim_s = finished.report().last_instant.as_secs_f64();
    if let (Some(c1), Some(e11)) = (finished.memory(&h.c1), finished.memory(&h.e11)) {
        out.parts = [
            c1.trajgen.kind().name().to_owned(),
            e11.track.tracker.name().to_owned(),
            e11.estym.estimator.name().to_owned(),
        ];
    }
    let sent = finish_counters(&finished, &h, &mut out.counters);
    out.counters.executor_errors = finished.report().error_count;
    out.reports = judge::judge(&out, config, sent);
    Ok((out, finished.into_report()))
}
