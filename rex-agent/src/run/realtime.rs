//! Running a Rex mission in real time: the same system as [`run_mission`](super::run_mission),
//! on threads against the wall clock ([`embodied::RealTime`]): the world (the 1 kHz
//! plant, the camera, the motion capture) on one thread, the subsystems on the
//! executor's workers (`RtConfig::threading`). The run is watched through the same probes, paired and
//! judged the same way, and ends the same way: every plan sent, acknowledged,
//! and the last fragment executed.

use std::path::Path;
use std::time::Duration;

use embodied::app::Watched;
use embodied::record::{RecordOptions, RecordSummary};
use embodied::{RtConfig, RtReport};

use super::{MissionWatch, Outcome, Progress, RunError, install_probes};
use crate::system::{RexConfig, build};

/// Run `config`'s mission in real time, for at most `limit` of wall-clock time.
/// Returns the outcome (judged as the deterministic run's is) and what the
/// executor measured.
pub fn run_mission_realtime(
    config: &RexConfig,
    limit: Duration,
    tick: Duration,
    rt: RtConfig,
    progress: impl FnMut(Progress<'_>),
) -> Result<(Outcome, RtReport), RunError> {
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
) -> Result<(Outcome, RtReport, RecordSummary), RunError> {
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
) -> Result<(Outcome, RtReport, Option<RecordSummary>), RunError> {
    let (system, h) = build(config).map_err(|e| RunError::Build(Box::new(e)))?;
    let mut watch = MissionWatch::new(config, tick, progress);
    // Watched as the deterministic run is (see `run_mission_observed`).
    let mut run = Watched::new(&mut watch, limit);
    install_probes(&mut run.probes, &h, &|_| true);
    let rt = RtConfig {
        exec: config.exec,
        ..rt
    };
    let (ran, summary) = run.realtime_recorded(system, rt, record)?;
    Ok((
        watch.conclude(&ran, &h),
        ran.finished.into_report(),
        summary,
    ))
}
