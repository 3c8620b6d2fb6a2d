//! Where the layer writes: the summary on standard output, everything else
//! (progress, timing tables, warnings, errors) on standard error, each line
//! prefixed with the program's name where it is a message.

use std::io::Write;
use std::path::Path;

use agent_spec::Spec;

use crate::AppError;
use crate::watch::{Ended, RunSummary, Verdict, Watcher};

/// The program's name as invoked (`rex`), for messages.
pub(crate) fn program() -> String {
    std::env::args()
        .next()
        .and_then(|a| {
            std::path::Path::new(&a)
                .file_name()
                .map(|n| n.to_string_lossy().into_owned())
        })
        .unwrap_or_else(|| "app".to_owned())
}

/// Write to standard output; if it is closed (`program | head`), end the
/// program quietly instead of panicking.
pub fn emit(text: std::fmt::Arguments<'_>) {
    if std::io::stdout().lock().write_fmt(text).is_err() {
        std::process::exit(0);
    }
}

pub(crate) fn out(text: std::fmt::Arguments<'_>) {
    emit(text);
}

/// A line on standard error (ignored if it is closed).
pub(crate) fn err(text: std::fmt::Arguments<'_>) {
    let _ = writeln!(std::io::stderr().lock(), "{text}");
}

/// `<program>: warning: ...` on standard error.
pub(crate) fn warn(text: std::fmt::Arguments<'_>) {
    err(format_args!("{}: warning: {text}", program()));
}

/// `<program>: ...` (an error) on standard error.
pub(crate) fn error(e: &dyn std::fmt::Display) {
    err(format_args!("{}: {e}", program()));
}

/// Check, before a run, that the folder `dir` that a flag (`flag`, for example
/// `--out`) names can take the files the run will write at its end: it is, or
/// can be made as, a folder other than the file system's root, and a file can
/// be written in it. An application calls it from
/// [`Application::configure`](crate::Application::configure), so that a run of
/// minutes does not end in an error it could have named at once (an
/// invalid-input error: exit status 2).
pub fn writable_folder(flag: &str, dir: &Path) -> Result<(), AppError> {
    check_folder(dir).map_err(|e| AppError::invalid(format!("{flag} {}: {e}", dir.display())))
}

fn check_folder(dir: &Path) -> std::io::Result<()> {
    if std::path::absolute(dir).is_ok_and(|d| d.parent().is_none()) {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "is the file system's root; name a folder for the run's files",
        ));
    }
    if dir.exists() && !dir.is_dir() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::NotADirectory,
            "exists and is not a folder",
        ));
    }
    std::fs::create_dir_all(dir)?;
    let probe = dir.join(format!(".write-test-{}", std::process::id()));
    std::fs::write(&probe, b"")?;
    std::fs::remove_file(&probe)
}

/// Judge the run `summary` tells of with `watcher`, and print the verdict's
/// text ([`said`]).
pub(crate) fn judgement<M>(
    watcher: &mut dyn Watcher<M>,
    summary: &RunSummary,
    timing: Option<&Spec>,
) -> Verdict {
    let verdict = watcher.judge(summary);
    out(format_args!("{}", said(&verdict, summary, timing)));
    verdict
}

/// What a run's summary says of its `verdict`: its text, the timing
/// certificate of the spec `timing` names (`--verbose`), and, if the run was
/// stopped or failed before its end, why.
fn said(verdict: &Verdict, summary: &RunSummary, timing: Option<&Spec>) -> String {
    let mut text = verdict.text.clone();
    if let Some(spec) = timing {
        text.push_str(&crate::report::timing(spec));
    }
    if let Ended::Stopped(why) | Ended::Failed(why) = &summary.ended {
        let how = if matches!(summary.ended, Ended::Failed(_)) {
            "failed"
        } else {
            "was stopped"
        };
        text.push_str(&format!("the run {how} before its end: {why}\n"));
    }
    text
}

#[cfg(test)]
mod tests {
    use super::writable_folder;

    #[test]
    fn the_verdict_is_said_with_the_timing_certificate_and_why_it_ended() {
        use crate::watch::{Ended, Mode, RunSummary, Verdict};
        let spec = crate::SpecFile::parse("rex.ron", include_str!("../../specs/rex.ron"));
        let Ok(spec) = spec.map(|s| s.spec) else {
            panic!("Rex's spec is valid");
        };
        let verdict = Verdict {
            passed: false,
            text: "2 of 3 plans achieved\n".into(),
            line: "plans=2/3".into(),
        };
        let mut summary = RunSummary {
            spec: "rex".into(),
            mode: Mode::Simulated,
            ended: Ended::Limit,
            rule_stated: false,
            last: agent_core::Time::ZERO,
            wall: std::time::Duration::ZERO,
            errors: 0,
            first_errors: Vec::new(),
        };
        assert_eq!(super::said(&verdict, &summary, None), verdict.text);
        let timing = crate::report::timing(&spec);
        assert!(
            timing.starts_with("# The timing analysis of `rex`"),
            "{timing}"
        );
        summary.ended = Ended::Stopped("SIGTERM received".into());
        assert_eq!(
            super::said(&verdict, &summary, Some(&spec)),
            format!(
                "{}{timing}the run was stopped before its end: SIGTERM received\n",
                verdict.text
            )
        );
        summary.ended = Ended::Failed("a step failed".into());
        let said = super::said(&verdict, &summary, None);
        assert!(
            said.ends_with("the run failed before its end: a step failed\n"),
            "{said}"
        );
    }

    fn message(flag: &str, dir: &std::path::Path) -> String {
        writable_folder(flag, dir).map_or_else(|e| e.to_string(), |()| "ok".to_owned())
    }

    #[test]
    fn a_folder_is_made_and_left_empty() {
        let root = std::env::temp_dir().join(format!("writable-{}", std::process::id()));
        let dir = root.join("a/b");
        assert_eq!(message("--out", &dir), "ok");
        assert!(dir.is_dir());
        assert_eq!(std::fs::read_dir(&dir).map(Iterator::count).ok(), Some(0));
        let _ = std::fs::remove_dir_all(root);
    }

    #[test]
    fn a_file_and_the_root_are_refused_naming_the_flag() {
        let file = std::env::temp_dir().join(format!("writable-file-{}", std::process::id()));
        assert!(std::fs::write(&file, b"x").is_ok());
        let said = message("--out", &file);
        assert!(
            said.starts_with("--out ") && said.ends_with("exists and is not a folder"),
            "{said}"
        );
        let _ = std::fs::remove_file(file);
        let said = message("--reports", std::path::Path::new("/"));
        assert!(
            said.contains("--reports /: is the file system's root"),
            "{said}"
        );
    }
}
