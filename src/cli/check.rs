//! `embodied check`: every finding of every spec file, and an exit status; with
//! `--timing`, the timing analysis of each file's system (or one deployment of
//! it) and its certificate.

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

/// Checks `files`: status 1 if any has an error or cannot be read, else 0.
/// `timing`: also analyse their timing, of the deployment given or of the
/// whole system as one process, and print the certificate.
pub(crate) fn run(files: &[PathBuf], style: Style, timing: Option<Option<&str>>) -> ExitCode {
    let width = super::width();
    let (mut errors, mut warnings, mut unreadable) = (0, 0, 0);
    for path in files {
        let report = match timing {
            None => embodied::spec::check_file(path).map(|(_, r)| (r, None)),
            Some(deployment) => with_timing(path, deployment),
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
fn with_timing(path: &Path, deployment: Option<&str>) -> std::io::Result<(Report, Option<String>)> {
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
    let certificate =
        match embodied::spec::timing::analyse(&loaded.spec, loaded.index.as_ref(), deployment) {
            Ok(analysis) => {
                findings.extend(analysis.findings.iter().cloned());
                Some(analysis.to_string())
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
