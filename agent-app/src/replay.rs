//! `replay FILE.mcap --subsystem NAME`: the subsystem rebuilt from this
//! program's code with the recorded configuration, fed its recorded inputs,
//! compared bit for bit.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use agent_mcap::{Recording, replay_file};

use crate::error::{AppError, Status};
use crate::{Application, Common, Target, output};

/// What the metadata says of one start of one process that recorded.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Recorded {
    pub(crate) process: String,
    pub(crate) deployment: String,
    pub(crate) runs: Vec<String>,
    pub(crate) incarnation: u32,
    pub(crate) boot: u64,
}

/// Every process start a recording's metadata describes (a process's own
/// recording: one; a merged one: one per part).
pub(crate) fn recorded_processes(
    metadata: &BTreeMap<String, BTreeMap<String, String>>,
) -> Vec<Recorded> {
    let mut out: Vec<Recorded> = metadata
        .iter()
        .filter(|(name, _)| *name == "process" || name.starts_with("process/"))
        .filter_map(|(_, m)| {
            Some(Recorded {
                process: m.get("name")?.clone(),
                deployment: m.get("deployment")?.clone(),
                runs: m
                    .get("runs")
                    .map(|r| r.split(", ").map(str::to_owned).collect())
                    .unwrap_or_default(),
                incarnation: m
                    .get("incarnation")
                    .and_then(|k| k.parse().ok())
                    .unwrap_or(0),
                boot: m.get("boot").and_then(|b| b.parse().ok()).unwrap_or(0),
            })
        })
        .collect();
    out.sort_by(|a, b| (&a.process, a.incarnation).cmp(&(&b.process, b.incarnation)));
    out
}

pub(crate) fn replay<A: Application>(
    app: &mut A,
    flags: &A::Flags,
    common: &Common,
    file: &Path,
    subsystem: &str,
    incarnation: Option<u32>,
) -> Result<Status, AppError> {
    // The metadata first (no message kept): the configuration to build from.
    let head = Recording::open_filtered(file, |_| false).map_err(AppError::invalid)?;
    let text = head
        .metadata
        .get("app")
        .and_then(|m| m.get("config"))
        .ok_or_else(|| {
            AppError::invalid(format!(
                "{} does not say the configuration of its run (not recorded by this program with --record?)",
                file.display()
            ))
        })?;
    let recorded: A::Config = serde_json::from_str(text).map_err(|e| {
        AppError::invalid(format!(
            "the configuration recorded in {} does not read: {e} (recorded by another version of this program?)",
            file.display()
        ))
    })?;
    let config = app.reconfigure(recorded, flags, common)?;
    let spec = app.spec(&config)?;
    if let Some(text) = head.metadata.get("spec").and_then(|m| m.get("text"))
        && *text != spec.text
    {
        output::warn(format_args!(
            "the spec {} differs from the one recorded in {}: a divergence may come from there",
            spec.path,
            file.display()
        ));
    }
    let starts: Vec<Recorded> = recorded_processes(&head.metadata)
        .into_iter()
        .filter(|r| r.runs.iter().any(|n| n == subsystem))
        .collect();
    let chosen: Vec<&Recorded> = match incarnation {
        None => starts.iter().collect(),
        Some(k) => {
            let one: Vec<&Recorded> = starts.iter().filter(|r| r.incarnation == k).collect();
            if one.is_empty() {
                return Err(AppError::invalid(format!(
                    "--incarnation {k}: {} holds {} of the process that ran `{subsystem}`",
                    file.display(),
                    match starts.len() {
                        0 => "no start".to_owned(),
                        n => format!(
                            "{n} start(s): {}",
                            starts
                                .iter()
                                .map(|r| r.incarnation.to_string())
                                .collect::<Vec<_>>()
                                .join(", ")
                        ),
                    }
                )));
            }
            one
        }
    };
    if chosen.len() > 1 {
        return Err(AppError::invalid(format!(
            "{} holds {} starts of process `{}` (it was restarted); replay one with --incarnation K ({})",
            file.display(),
            chosen.len(),
            chosen[0].process,
            chosen
                .iter()
                .map(|r| r.incarnation.to_string())
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    let target = match chosen.first() {
        Some(r) => Target::Process {
            deployment: &r.deployment,
            process: &r.process,
            incarnation: r.incarnation,
            boot: r.boot,
        },
        None => Target::Whole,
    };
    let system = app.build(&config, &target)?;
    let started = Instant::now();
    let result = replay_file(file, system, subsystem, app.replay_options(&config));
    let ms = started.elapsed().as_secs_f64() * 1e3;
    match result {
        Ok(r) => {
            output::out(format_args!("replay {subsystem}: {r}\n"));
            output::out(format_args!(
                "replay_ms={ms:.0} equivalent={}\n",
                if r.is_equivalent() { "yes" } else { "no" }
            ));
            Ok(if r.is_equivalent() {
                Status::Success
            } else {
                Status::Failed
            })
        }
        Err(e) => Err(AppError::invalid(e)),
    }
}
