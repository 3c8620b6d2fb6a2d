//! `embodied check`: every finding of every spec file, and an exit status.

use std::path::PathBuf;
use std::process::ExitCode;

/// How `check` prints the findings.
#[derive(Clone, Copy, Debug)]
pub(crate) enum Style {
    /// Diagnostics with source excerpts, like rustc.
    Human,
    /// One `file:line:col: severity[code]: message` line per finding.
    Short,
}

/// Checks `files`: status 1 if any has an error or cannot be read, else 0.
pub(crate) fn run(files: &[PathBuf], style: Style) -> ExitCode {
    let width = super::width();
    let (mut errors, mut warnings, mut unreadable) = (0, 0, 0);
    for path in files {
        match embodied::spec::check_file(path) {
            Err(e) => {
                eprintln!("error: cannot read {}: {e}", path.display());
                unreadable += 1;
            }
            Ok((_, report)) => {
                match style {
                    Style::Human => eprint!("{}", report.render(width)),
                    Style::Short => eprint!("{}", report.short()),
                }
                errors += report.errors();
                warnings += report.warnings();
                let verdict = if report.is_ok() { "ok" } else { "FAILED" };
                println!(
                    "{}: {verdict} ({} errors, {} warnings)",
                    path.display(),
                    report.errors(),
                    report.warnings()
                );
            }
        }
    }
    if files.len() > 1 {
        println!(
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
