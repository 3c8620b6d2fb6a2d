//! `embodied export --ros2`: a recording as an MCAP file of profile `ros2`
//! with its ROS 2 channels only, for ROS 2 tools (rosbags reads it whole).
//! Prints what it wrote, and every channel it left out and why, every topic
//! and type it renamed: nothing is dropped or changed silently.

use std::collections::BTreeMap;
use std::path::Path;
use std::process::ExitCode;

use embodied::record::{ExportError, ExportOptions, ExportSummary, export_ros2};

/// Export `file` to `output`: exit 0 written, 1 failed (nothing to export, or
/// the export could not be written), 2 invalid input (a file missing,
/// unreadable or not an MCAP recording, or the export would overwrite it).
pub(crate) fn run(file: &Path, output: &Path, metadata: bool) -> ExitCode {
    match export_ros2(file, output, &ExportOptions { metadata }) {
        Ok(summary) => {
            out!("{}", report(output, &summary));
            ExitCode::SUCCESS
        }
        Err(e) => {
            errln!("embodied export: {e}");
            match e {
                ExportError::Read(_) | ExportError::SameFile { .. } => ExitCode::from(2),
                _ => ExitCode::FAILURE,
            }
        }
    }
}

/// What an export wrote, then what it left out (grouped by reason) and
/// renamed.
fn report(output: &Path, s: &ExportSummary) -> String {
    let mut out = format!(
        "{}: profile ros2, {} ROS 2 channels, {} messages, {} metadata records\n",
        output.display(),
        s.channels,
        s.messages,
        s.metadata
    );
    if let Some(cut) = &s.cut_short {
        out.push_str(&format!(
            "the recording was cut short; exported up to where it ends ({cut})\n"
        ));
    }
    if !s.left_out.is_empty() {
        out.push_str(&format!(
            "left out {} channels that are not ROS 2 (ROS 2 tools read CDR with a `ros2msg` schema only):\n",
            s.left_out.len()
        ));
        let mut by_reason: BTreeMap<String, Vec<&str>> = BTreeMap::new();
        for l in &s.left_out {
            by_reason
                .entry(l.reason.to_string())
                .or_default()
                .push(&l.topic);
        }
        for (reason, topics) in by_reason {
            out.push_str(&format!("  {} ({reason}):\n", topics.len()));
            for t in topics {
                out.push_str(&format!("    {t}\n"));
            }
        }
    }
    for (from, to) in &s.renamed_types {
        out.push_str(&format!(
            "type {from} written as {to} (ROS 2: one definition per type name, names by its rules)\n"
        ));
    }
    for (from, to) in &s.renamed_topics {
        out.push_str(&format!(
            "topic {from} written as {to} (not a valid ROS 2 topic name)\n"
        ));
    }
    out
}
