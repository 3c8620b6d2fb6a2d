//! `embodied merge`: the recordings of the processes of one run made one.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

/// Merge `files` into `output`; print what was written, or why not.
pub(crate) fn run(files: &[PathBuf], output: &Path) -> ExitCode {
    match embodied::record::merge(files, output) {
        Ok(m) => {
            outln!(
                "{}: {} files merged, {} messages on {} channels{}",
                output.display(),
                m.files,
                m.messages,
                m.channels,
                if m.finished {
                    ""
                } else {
                    " (a recording was not finished: the merged run has no `end`)"
                }
            );
            ExitCode::SUCCESS
        }
        Err(e) => {
            errln!("embodied merge: {e}");
            ExitCode::FAILURE
        }
    }
}
