//! `check` and `diagram` of the application's spec.

use std::path::Path;

use agent_spec::diagram::{self, Format, Kind};

use crate::cli::{DiagramFormat, DiagramKind};
use crate::error::{AppError, Status};
use crate::{SpecFile, output};

/// Every finding of the spec (the arc proofs included); exit 1 on an error.
pub(crate) fn check(spec: &SpecFile) -> Result<Status, AppError> {
    let (_, report) = agent_spec::check_source(spec.path.clone(), spec.text.clone());
    output::err(format_args!("{}", report.render(100).trim_end()));
    output::out(format_args!(
        "{}: {} ({} errors, {} warnings)\n",
        spec.path,
        if report.is_ok() { "ok" } else { "FAILED" },
        report.errors(),
        report.warnings()
    ));
    Ok(if report.is_ok() {
        Status::Success
    } else {
        Status::Failed
    })
}

/// A diagram of the spec, to `output` or standard output.
pub(crate) fn diagram(
    spec: &SpecFile,
    kind: DiagramKind,
    subsystem: Option<&str>,
    format: DiagramFormat,
    output: Option<&Path>,
) -> Result<Status, AppError> {
    let kind = match kind {
        DiagramKind::Fsm => Kind::Fsm,
        DiagramKind::Structure => Kind::Structure,
        DiagramKind::Dataflow => Kind::Dataflow,
    };
    let format = match format {
        DiagramFormat::Dot => Format::Dot,
        DiagramFormat::Mermaid => Format::Mermaid,
        DiagramFormat::Svg => Format::Svg,
    };
    let text = diagram::render(&spec.spec, kind, subsystem, format).map_err(AppError::invalid)?;
    match output {
        None => output::out(format_args!("{text}")),
        Some(path) => std::fs::write(path, text).map_err(|source| AppError::Io {
            path: path.to_owned(),
            source,
        })?,
    }
    Ok(Status::Success)
}
