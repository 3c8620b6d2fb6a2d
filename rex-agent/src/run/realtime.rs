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

use std::path::Path;
use std::sync::mpsc::{Receiver, TryRecvError};
use std::time::{Duration, Instant};

use embodied::record::{McapRecorder, RecordOptions, RecordSummary};
use embodied::{RealTime, RtConfig, RtReport, Time};

use super::collect::{Collector, Seen};
use super::{Outcome, Progress, RunError, Sample, finish_counters};
use crate::a1::payload::Ack;
use crate::a1::{RexConfig, RexHandles, build};
use crate::report::judge;
use crate::world::devices::{MotionCapture, Truth};

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
    progress: impl FnMut(Progress<'_>),
) -> Result<(Outcome, RtReport), RtRunError> {
    let (outcome, report, _) = realtime(config, limit, tick, rt, None, progress)?;
    Ok((outcome, report))
}

/// [`run_mission_realtime`], recorded to `path` (every thread's part of the
/// run: what each node sent and read, its behaviour switches, the errors).
pub fn run_mission_realtime_recorded(
    config: &RexConfig,
    limit: Duration,
    tick: Duration,
    rt: RtConfig,
    (path, options): (&Path, RecordOptions),
    progress: impl FnMut(Progress<'_>),
) -> Result<(Outcome, RtReport, RecordSummary), RtRunError> {
    let (outcome, report, summary) =
        realtime(config, limit, tick, rt, Some((path, options)), progress)?;
    // A recording was asked for: `realtime` returns its summary.
    Ok((outcome, report, summary.unwrap_or_default()))
}

fn realtime(
    config: &RexConfig,
    limit: Duration,
    tick: Duration,
    rt: RtConfig,
    record: Option<(&Path, RecordOptions)>,
    mut progress: impl FnMut(Progress<'_>),
) -> Result<(Outcome, RtReport, Option<RecordSummary>), RtRunError> {
    let (system, h) = build(config).map_err(RunError::from)?;
    let recorder = match record {
        Some((path, options)) => {
            Some(McapRecorder::create(path, &system, options).map_err(RunError::from)?)
        }
        None => None,
    };
    let mut rt = RealTime::new(
        system,
        RtConfig {
            exec: config.exec,
            ..rt
        },
    );
    let probes = install_probes(&mut rt, &h, |_| true);
    if let Some(r) = &recorder {
        rt.observe(r.threads());
    }
    let mut collect = Collector::new(config, tick);
    let running = rt.start(limit)?;
    let wall = Instant::now();
    loop {
        let finished = running.is_finished();
        if !receive(
            &probes,
            &mut collect,
            &mut progress,
            Duration::from_millis(5),
        ) {
            // Every probe's thread ended (the others may not have yet): wait,
            // don't spin.
            std::thread::sleep(Duration::from_millis(5));
        }
        if collect.advance(finished, &mut progress) && !finished {
            running.stop();
        }
        if finished {
            break;
        }
    }
    let finished = running.join()?;
    let mut out = std::mem::take(&mut collect.out);
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
    let summary = recorder
        .map(McapRecorder::finish)
        .transpose()
        .map_err(RunError::from)?;
    Ok((out, finished.into_report(), summary))
}

/// Probes on the components `here` says run in this process: e11 (what it
/// tracks), c1 (its behaviour), a2 (acknowledgements), the world (the true
/// pose) and the motion capture (deliveries).
pub(crate) fn install_probes(
    rt: &mut RealTime,
    h: &RexHandles,
    here: impl Fn(&str) -> bool,
) -> Vec<Receiver<Seen>> {
    let mut probes = Vec::new();
    if here("e11") {
        probes.push(rt.probe(&h.e11, |p| {
            let m = p.memory;
            let est = m.estym.estimate.x;
            Some(Seen::E11 {
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
            })
        }));
    }
    if here("c1") {
        let mut last = None;
        probes.push(rt.probe(&h.c1, move |p| {
            let b = match p.behaviour {
                "B2" => 1u8,
                "B3" => 2,
                _ => 0,
            };
            // Only changes: c1's behaviour is a state, not a stream.
            (last.replace(b) != Some(b)).then_some(Seen::C1(b))
        }));
    }
    if here("c2") {
        let mut acks_sent = 0;
        let mut sent = 0;
        probes.push(rt.probe(&h.c2, move |p| {
            let new: Vec<Ack> = p.memory.acks.iter().skip(acks_sent).cloned().collect();
            acks_sent = p.memory.acks.len();
            let more = p.memory.next != sent;
            sent = p.memory.next;
            (!new.is_empty() || p.halted || more).then_some(Seen::C2 {
                t: p.time,
                acks: new,
                halted: p.halted,
                sent,
            })
        }));
    }
    if here("E1") {
        probes.push(rt.probe_environment(|_, w: &Truth| {
            let s = &w.state;
            // The truth after the world's step at `t` is the state at `w.time`.
            let at = Time::from_nanos((w.time * 1e9).round().max(0.0) as u64);
            Some(Seen::Truth {
                at,
                pose: [s.x, s.y, s.phi],
            })
        }));
    }
    if here("R3") {
        let mut last = None;
        probes.push(rt.probe_driver(&h.map.mocap, move |_, m: &MotionCapture| {
            let at = m.last_delivered().map(|(at, _)| at);
            (at.is_some() && at != last).then(|| {
                last = at;
                Seen::Mocap(at)
            })
        }));
    }
    probes
}

/// Take what the probes reported into `collect`, waiting up to `wait` for the
/// first report. Returns false when every probe's thread has ended.
pub(crate) fn receive(
    probes: &[Receiver<Seen>],
    collect: &mut Collector,
    progress: &mut impl FnMut(Progress<'_>),
    wait: Duration,
) -> bool {
    let deadline = Instant::now() + wait;
    let mut alive = false;
    let mut got = false;
    loop {
        for rx in probes {
            loop {
                match rx.try_recv() {
                    Ok(seen) => {
                        collect.see(seen, progress);
                        got = true;
                        alive = true;
                    }
                    Err(TryRecvError::Empty) => {
                        alive = true;
                        break;
                    }
                    Err(TryRecvError::Disconnected) => break,
                }
            }
        }
        if got || !alive || Instant::now() >= deadline {
            return alive;
        }
        std::thread::sleep(Duration::from_micros(500));
    }
}
