//! `embodied check`: every finding of every spec file, and an exit status; with
//! `--timing`, the timing analysis of each file's system (or one deployment of
//! it) and its certificate.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use embodied::spec::{Code, Finding, Report};

/// How `check` prints the findings.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Style {
    /// Diagnostics with source excerpts, like rustc.
    Human,
    /// One `file:line:col: severity[code]: message` line per finding.
    Short,
}

/// The codes of the timing analysis's findings.
const TIMING: [Code; 4] = [
    Code::TimingMissing,
    Code::Unschedulable,
    Code::ChainDeadline,
    Code::QueueOverflow,
];

/// What `--timing` analyses: the deployment (`None`: the whole system as one
/// process), and the WCETs and release jitters measured in a recording
/// (`--wcet-from`), if given.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Timing<'a> {
    /// `--deployment`.
    pub(crate) deployment: Option<&'a str>,
    /// `--wcet-from`'s measurements.
    pub(crate) measured: Option<&'a Measured>,
}

/// What a recording measured of each component \[ns\]: its largest
/// execution time and its largest wake-up lateness.
#[derive(Clone, Debug)]
pub(crate) struct Measured {
    /// Per component, the largest execution time.
    pub(crate) wcet: BTreeMap<String, u64>,
    /// Per component, the largest wake-up lateness (its release jitter).
    pub(crate) lateness: BTreeMap<String, u64>,
}

/// The WCETs and release jitters measured in the recording at `path` (its
/// `/timing` channel); or why there are none (the file cannot be read, has no
/// `/timing` channel, or no message on it).
pub(crate) fn measured(path: &Path) -> Result<Measured, String> {
    use embodied::record::timing::{
        TIMING_TOPIC, TimingReadError, measured_lateness, measured_wcets, read_timing,
    };
    let recording = embodied::record::Recording::open_filtered(path, |c| c.topic == TIMING_TOPIC)
        .map_err(|e| format!("--wcet-from {}: {e}", path.display()))?;
    let stats = read_timing(&recording).map_err(|e| match e {
        TimingReadError::NoChannel(_) => format!(
            "--wcet-from {}: the recording has no `/timing` channel: it was made without `--realtime` (only real-time runs record timing statistics; a deterministic run has no wall clock)",
            path.display()
        ),
        e => format!("--wcet-from: {e}"),
    })?;
    if stats.is_empty() {
        return Err(format!(
            "--wcet-from {}: the `/timing` channel has no message (a run that did not finish?)",
            path.display()
        ));
    }
    for s in &stats {
        if !s.rt_priority {
            errln!(
                "warning: --wcet-from {}: process `{}` on `{}` ran without the real-time priorities it asked for: its times include preemption by other programs",
                path.display(),
                s.process,
                s.host
            );
        }
    }
    Ok(Measured {
        wcet: measured_wcets(&stats),
        lateness: measured_lateness(&stats),
    })
}

/// Checks `files`: status 1 if any has an error or cannot be read, else 0.
/// `timing`: also analyse their timing, of the deployment given or of the
/// whole system as one process, and print the certificate.
pub(crate) fn run(files: &[PathBuf], style: Style, timing: Option<Timing<'_>>) -> ExitCode {
    let width = super::width();
    let (mut errors, mut warnings, mut unreadable) = (0, 0, 0);
    for path in files {
        let report = match timing {
            None => embodied::spec::check_file(path).map(|(_, r)| (r, None)),
            Some(t) => with_timing(path, t),
        };
        match report {
            Err(e) => {
                errln!("error: cannot read {}: {e}", path.display());
                unreadable += 1;
            }
            Ok((report, certificate)) => {
                match style {
                    Style::Human => err!("{}", report.render(width)),
                    Style::Short => err!("{}", report.short()),
                }
                if let Some(c) = certificate {
                    out!("{c}");
                }
                errors += report.errors();
                warnings += report.warnings();
                let verdict = if report.is_ok() { "ok" } else { "FAILED" };
                outln!(
                    "{}: {verdict} ({} errors, {} warnings)",
                    path.display(),
                    report.errors(),
                    report.warnings()
                );
            }
        }
    }
    if files.len() > 1 {
        outln!(
            "{} files: {errors} errors, {warnings} warnings{}",
            files.len(),
            if unreadable > 0 {
                format!(", {unreadable} unreadable")
            } else {
                String::new()
            }
        );
    }
    if errors > 0 || unreadable > 0 {
        ExitCode::FAILURE
    } else {
        ExitCode::SUCCESS
    }
}

/// The check's findings with the timing analysis of `deployment` in place of
/// the whole system's, and the certificate (absent when the spec does not
/// pass the other checks, or cannot be analysed: a finding says why).
fn with_timing(path: &Path, timing: Timing<'_>) -> std::io::Result<(Report, Option<String>)> {
    let deployment = timing.deployment;
    let bytes = std::fs::read(path)?;
    let file = path.display().to_string();
    let source = match embodied::spec::decode(&file, bytes) {
        Ok(s) => s,
        Err(report) => return Ok((report, None)),
    };
    let loaded = match embodied::spec::load(file.clone(), source) {
        Ok(l) => l,
        Err(report) => return Ok((report, None)),
    };
    let checked = embodied::spec::check(&loaded);
    let mut findings: Vec<Finding> = checked
        .findings
        .iter()
        .filter(|f| !TIMING.contains(&f.code))
        .cloned()
        .collect();
    if findings
        .iter()
        .any(|f| f.code.severity() == embodied::spec::Severity::Error)
    {
        return Ok((Report::new(file, loaded.source.clone(), findings), None));
    }
    let mut spec = loaded.spec.clone();
    let mut sources = String::new();
    if let Some(measured) = timing.measured {
        use embodied::spec::timing::{
            WCET_MARGIN, use_measured_release_jitters, use_measured_wcets,
        };
        if let Some(list) = use_measured_wcets(&mut spec, &measured.wcet, WCET_MARGIN) {
            sources.push_str(&format!(
                "WCETs from the recording: measured max x {WCET_MARGIN} (margin); declared where not measured\n"
            ));
            for s in list {
                sources.push_str(&format!("{s}\n"));
            }
        }
        let jitters = use_measured_release_jitters(&mut spec, &measured.lateness, WCET_MARGIN);
        if let Some(list) = jitters {
            sources.push_str(&format!(
                "release jitters from the recording: largest wake-up lateness x {WCET_MARGIN} (margin); declared where not measured\n"
            ));
            for s in list {
                sources.push_str(&format!("{s}\n"));
            }
        }
    }
    let certificate =
        match embodied::spec::timing::analyse(&spec, loaded.index.as_ref(), deployment) {
            Ok(analysis) => {
                findings.extend(analysis.findings.iter().cloned());
                Some(format!("{sources}{analysis}"))
            }
            Err(why) => {
                errln!("error: {}: {why}", path.display());
                findings.push(Finding::new(
                    Code::TimingMissing,
                    0..0,
                    "cannot analyse",
                    why,
                ));
                None
            }
        };
    Ok((
        Report::new(file, loaded.source.clone(), findings),
        certificate,
    ))
}
