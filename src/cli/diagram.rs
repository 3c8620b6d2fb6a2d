//! `embodied diagram`: the FSMs, the structure or the data flow of a spec, as DOT,
//! Mermaid or SVG.

use std::path::Path;
use std::process::ExitCode;

use embodied::spec::diagram::{self, Detail, Format, Kind};

/// Draws `kind` of `file` (only `subsystem`, if given) in `format`, the structure
/// as `detail` says, to `output` or standard output.
pub(crate) fn run(
    file: &Path,
    kind: Kind,
    subsystem: Option<&str>,
    format: Format,
    detail: Detail,
    output: Option<&Path>,
) -> ExitCode {
    // Drawing needs the structure, not the arc proof (`check` does that).
    let (spec, report) = match embodied::spec::check_file_structure(file) {
        Ok(x) => x,
        Err(e) => {
            errln!("error: cannot read {}: {e}", file.display());
            return ExitCode::FAILURE;
        }
    };
    let Some(spec) = spec else {
        err!("{}", report.render(super::width()));
        return ExitCode::FAILURE;
    };
    if !report.is_ok() {
        err!("{}", report.render(super::width()));
        errln!(
            "warning: {} has errors; the diagram leaves out what does not resolve",
            file.display()
        );
    }
    let text = match diagram::render_with(&spec, kind, subsystem, format, detail) {
        Ok(t) => t,
        Err(e) => {
            errln!("error: {e}");
            return ExitCode::FAILURE;
        }
    };
    match output {
        None => {
            out!("{text}");
            ExitCode::SUCCESS
        }
        Some(path) => match std::fs::write(path, text) {
            Ok(()) => ExitCode::SUCCESS,
            Err(e) => {
                errln!("error: cannot write {}: {e}", path.display());
                ExitCode::FAILURE
            }
        },
    }
}
