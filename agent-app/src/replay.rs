//! `replay FILE.mcap --subsystem NAME`: the subsystem rebuilt from this
//! program's code with the recorded configuration, fed its recorded inputs,
//! compared bit for bit.

use std::collections::BTreeMap;
use std::path::Path;
use std::time::Instant;

use agent_mcap::{Recording, Window, replay_file};

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

/// `replay FILE --subsystem S`: every recorded start of the process that ran
/// `S` (or the one `--incarnation` names), each rebuilt and replayed in its
/// window; a file one process recorded whole, replayed whole.
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
    let config = recorded_config(app, flags, common, file, &head)?;
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
    if starts.is_empty() {
        // One process recorded the whole system.
        let system = app.build(&config, &Target::Whole)?;
        let verdict = once(file, system, subsystem, app.replay_options(&config), "")?;
        return Ok(verdict);
    }
    let chosen = chosen_starts(&starts, incarnation, file, subsystem)?;
    let parts = Parts {
        head: &head,
        subsystem,
        // A process's own recording holds its `end`; a merged one each part's.
        own: head.metadata.contains_key("process"),
        several: starts.len() > 1,
    };
    let mut status = Status::Success;
    let mut replayed = 0;
    for start in chosen {
        let which = parts.which(start);
        let Some(window) = parts.window(start) else {
            output::out(format_args!(
                "replay {subsystem}{which}: not replayed: its recording was not finished (the process was killed)\n"
            ));
            continue;
        };
        let target = Target::Process {
            deployment: &start.deployment,
            process: &start.process,
            incarnation: start.incarnation,
            boot: start.boot,
        };
        let system = app.build(&config, &target)?;
        let options = agent_mcap::ReplayOptions {
            window,
            ..app.replay_options(&config)
        };
        status = status.and(once(file, system, subsystem, options, &which)?);
        replayed += 1;
    }
    if replayed == 0 {
        output::error(&format_args!(
            "{}: no start of the process that ran `{subsystem}` can be replayed",
            file.display()
        ));
        return Ok(Status::Failed);
    }
    Ok(status)
}

/// The configuration recorded in `head` (the file's metadata), as this run's
/// flags change it.
fn recorded_config<A: Application>(
    app: &mut A,
    flags: &A::Flags,
    common: &Common,
    file: &Path,
    head: &Recording,
) -> Result<A::Config, AppError> {
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
    app.reconfigure(recorded, flags, common)
}

/// The starts to replay: those of `--incarnation`, else all; none is
/// invalid input that names the starts there are.
fn chosen_starts<'s>(
    starts: &'s [Recorded],
    incarnation: Option<u32>,
    file: &Path,
    subsystem: &str,
) -> Result<Vec<&'s Recorded>, AppError> {
    let chosen: Vec<&Recorded> = starts
        .iter()
        .filter(|r| incarnation.is_none_or(|k| r.incarnation == k))
        .collect();
    if chosen.is_empty() {
        return Err(AppError::invalid(format!(
            "--incarnation {}: {} holds start(s) {} of process `{}`, which ran `{subsystem}`",
            incarnation.unwrap_or(0),
            file.display(),
            starts
                .iter()
                .map(|r| r.incarnation.to_string())
                .collect::<Vec<_>>()
                .join(", "),
            starts[0].process,
        )));
    }
    Ok(chosen)
}

/// The recorded starts of the process that ran the replayed subsystem.
struct Parts<'a> {
    /// The file's metadata.
    head: &'a Recording,
    subsystem: &'a str,
    /// Whether the file is the process's own recording (else a merged one).
    own: bool,
    /// Whether the file holds several starts of the process.
    several: bool,
}

impl Parts<'_> {
    /// How the replay of `start` is said after the subsystem's name: which
    /// start of which process, where there is more than the first.
    fn which(&self, start: &Recorded) -> String {
        if self.several || start.incarnation > 0 {
            format!(
                " (start {} of process `{}`)",
                start.incarnation, start.process
            )
        } else {
            String::new()
        }
    }

    /// The window `start` is replayed in (`Some(None)`: the whole file), or
    /// `None` if its part was never finished.
    fn window(&self, start: &Recorded) -> Option<Option<Window>> {
        let label = match start.incarnation {
            0 => start.process.clone(),
            k => format!("{}#{k}", start.process),
        };
        let end = if self.own {
            self.head.metadata.get("end")
        } else {
            self.head.metadata.get(&format!("end/{label}"))
        };
        // A start after a restart runs from the instant it joined: replayed
        // in its window, from its part's end record (a merged file's parts
        // each have theirs; one part may never have been finished: killed).
        if !(self.several || start.incarnation > 0 || !self.own) {
            return Some(None);
        }
        match end.and_then(|e| Window::of(e, self.subsystem)) {
            Some(w) => Some(Some(w)),
            // A merged file of an earlier layer: its own `end`.
            None if !self.several && start.incarnation == 0 && !self.own => Some(None),
            None => None,
        }
    }
}

/// One replay, said: `replay S<which>: verdict` and its figures.
fn once(
    file: &Path,
    system: agent_core::System,
    subsystem: &str,
    options: agent_mcap::ReplayOptions,
    which: &str,
) -> Result<Status, AppError> {
    let started = Instant::now();
    let result = replay_file(file, system, subsystem, options);
    let ms = started.elapsed().as_secs_f64() * 1e3;
    match result {
        Ok(r) => {
            output::out(format_args!("replay {subsystem}{which}: {r}\n"));
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
