//! Recording a run: where the file may go, and how its end is said.
//!
//! A recording that cannot be finished (the disk filled, the folder went away)
//! is named with the bytes it reached and removed, so that no half-written
//! file is left to be mistaken for a run; the run's summary is printed all the
//! same, and the program exits 1.

use std::path::Path;

use agent_core::System;
use agent_mcap::{McapRecorder, RecordError, RecordOptions, RecordSummary};

use crate::error::AppError;
use crate::output;

/// Whether `file` can be a recording: not a folder, in a folder that exists.
/// `{process}` in its name stands for a process's name.
pub(crate) fn check_target(file: &Path) -> Result<(), String> {
    if file.as_os_str().is_empty() {
        return Err("no file named".into());
    }
    if file.is_dir() {
        return Err("is a folder; name a file (run.mcap)".into());
    }
    let parent = match file.parent() {
        Some(p) if !p.as_os_str().is_empty() => p,
        _ => Path::new("."),
    };
    if !parent.is_dir() {
        return Err(format!("the folder {} does not exist", parent.display()));
    }
    if file.file_name().is_none() {
        return Err("names no file".into());
    }
    Ok(())
}

/// Start recording a run of `system` to `file`.
pub(crate) fn create(
    file: &Path,
    system: &System,
    options: RecordOptions,
) -> Result<McapRecorder, AppError> {
    McapRecorder::create(file, system, options).map_err(|e| match e {
        RecordError::Create { path, source } => {
            AppError::invalid(format!("--record {}: {source}", path.display()))
        }
        e => AppError::Record(e),
    })
}

/// Warn once, during the run, that the recording stopped.
pub(crate) struct FailWatch {
    warned: bool,
}

impl FailWatch {
    pub(crate) fn new() -> FailWatch {
        FailWatch { warned: false }
    }

    pub(crate) fn look(&mut self, recorder: Option<&McapRecorder>) {
        if let Some(r) = recorder
            && !self.warned
            && r.has_failed()
        {
            self.warned = true;
            let size = std::fs::metadata(r.path()).map_or(0, |m| m.len());
            output::warn(format_args!(
                "the recording {} stopped at {size} bytes (a full disk?); the run goes on unrecorded",
                r.path().display()
            ));
        }
    }
}

/// The name of the host this process runs on (`unknown` where the OS does
/// not say).
fn host_name() -> String {
    std::fs::read_to_string("/proc/sys/kernel/hostname")
        .ok()
        .map(|h| h.trim().to_owned())
        .filter(|h| !h.is_empty())
        .or_else(|| std::env::var("HOSTNAME").ok())
        .unwrap_or_else(|| "unknown".to_owned())
}

/// [`finish`] the recording of a real-time run, its timing statistics
/// (`report`, of process `process` on this host) written first on its
/// `/timing` channel.
pub(crate) fn finish_timed(
    mut recorder: McapRecorder,
    report: &agent_core::RtReport,
    process: &str,
) -> bool {
    let stats = agent_mcap::TimingStats::from_report(report, &host_name(), process);
    recorder.timing(report.last_instant, &stats);
    finish(recorder)
}

/// Finish a recording and say so: `record: FILE (...)` on standard output, or
/// the failure on standard error (the partial file removed). Whether it was
/// finished.
pub(crate) fn finish(recorder: McapRecorder) -> bool {
    let path = recorder.path().to_owned();
    let result = recorder.finish();
    said(&path, result)
}

/// Say how a finished recording went; whether it succeeded.
pub(crate) fn said(path: &Path, result: Result<RecordSummary, RecordError>) -> bool {
    match result {
        Ok(s) => {
            let size = std::fs::metadata(path).map_or(0, |m| m.len());
            output::out(format_args!(
                "record: {} ({} messages on {} channels, {:.1} MB)\n",
                path.display(),
                s.messages,
                s.channels,
                size as f64 / 1e6
            ));
            for link in &s.json_values {
                output::out(format_args!("record: values in JSON, not CDR: {link}\n"));
            }
            true
        }
        Err(e) => {
            let meta = std::fs::metadata(path).ok();
            let size = meta.as_ref().map_or(0, std::fs::Metadata::len);
            // Only a file of ours: never a device (`/dev/full`) or a link.
            let regular = std::fs::symlink_metadata(path).is_ok_and(|m| m.is_file());
            let what = if !regular {
                "is not a regular file: left as it is"
            } else if std::fs::remove_file(path).is_ok() {
                "was removed (it could not be finished)"
            } else {
                "could not be removed"
            };
            output::error(&format_args!(
                "{e}; the recording reached {size} bytes and {what}"
            ));
            false
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_recording_goes_into_an_existing_folder_and_is_not_one() {
        let dir = std::env::temp_dir();
        assert!(check_target(&dir).is_err_and(|e| e.contains("folder")));
        assert!(
            check_target(&dir.join("no-such-folder-here/run.mcap"))
                .is_err_and(|e| e.contains("does not exist"))
        );
        assert!(check_target(&dir.join("run.mcap")).is_ok());
        assert!(check_target(Path::new("run.mcap")).is_ok());
        assert!(check_target(Path::new("")).is_err());
    }
}
