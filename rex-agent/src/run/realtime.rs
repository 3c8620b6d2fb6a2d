//! Running a Rex mission in real time: the same system as [`run_mission`](super::run_mission),
//! on threads against the wall clock ([`embodied::RealTime`]): the world (the 1 kHz
//! plant, the camera, the motion capture) on one thread, every subsystem on its
//! own, as on the robot. The run is watched through the same probes, paired and
//! judged the same way, and ends the same way: every plan sent, acknowledged,
//! and the last fragment executed.

use std::path::Path;
use std::time::Duration;

use embodied::app::{End, Watched};
use embodied::record::{McapRecorder, RecordOptions, RecordSummary};
use embodied::{Probes, RtConfig, RtReport};

use super::{MissionWatch, Outcome, PROBES, Progress, RunError, install_probes};
use crate::system::{RexConfig, build};

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
    progress: impl FnMut(Progress<'_>),
) -> Result<(Outcome, RtReport, Option<RecordSummary>), RtRunError> {
    let (system, h) = build(config).map_err(RunError::from)?;
    let recorder = match record {
        Some((path, options)) => {
            Some(McapRecorder::create(path, &system, options).map_err(RunError::from)?)
        }
        None => None,
    };
    let (mut probes, seen) = Probes::new(PROBES);
    install_probes(&mut probes, &h, &|_| true);
    let mut watch = MissionWatch::new(config, tick, progress);
    let ran = Watched {
        probes,
        seen,
        watcher: &mut watch,
        end: End::Limit,
        limit,
        quiet: true,
        transitions: false,
        // The library's mission runs judge the mission; the spec's contracts
        // are watched in the program's runs (`rex`, through the layer).
        contracts: None,
    }
    .realtime(
        system,
        RtConfig {
            exec: config.exec,
            ..rt
        },
        recorder.as_ref(),
    )
    .map_err(RunError::from)?;
    let outcome = watch.conclude(&ran, &h);
    let summary = recorder
        .map(McapRecorder::finish)
        .transpose()
        .map_err(RunError::from)?;
    Ok((outcome, ran.finished.into_report(), summary))
}
