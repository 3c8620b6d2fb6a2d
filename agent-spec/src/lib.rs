//! # agent-spec: specifications of embodied-agent systems
//!
//! A researcher writes the structure of a control system once, in RON: agents, their
//! subsystems and devices, every buffer with its type, transition functions with what
//! they read and the target they write, behaviours, FSMs with Boolean initial
//! conditions, links with policies, periods and deployments. This crate loads such a
//! file ([`model`]), checks it ([`check_source`]) and draws it ([`diagram`]).
//!
//! The checker reports every finding at once, each with a stable [`Code`], a message,
//! a help line and labelled spans into the file, rendered like rustc diagnostics
//! ([`Report::render`]). Beyond names, types and wiring, it proves for every FSM node
//! that the initial conditions of the outgoing arcs are mutually exclusive and cover
//! every case in which the node's terminal condition holds, under the declared
//! relations between predicates, and prints the counterexample when they do not.
//!
//! The same loader and checker serve the `embodied` CLI, the diagrams and the macros:
//! there is one parser. A spec's `ros2` sections say what a system shows to ROS 2;
//! [`ros2`] holds ROS 2's name rules (which the ROS 2 bridge's plan applies too,
//! to the node, namespace, package and full topic names it announces) and the
//! interface a system or deployment shows, every default applied.

pub mod check;
pub mod contracts;
pub mod deploy;
pub mod diag;
pub mod diagram;
pub mod export;
pub mod fans;
pub mod model;
pub mod names;
mod proof;
pub mod ros2;
pub mod span;
pub mod timing;

use std::path::Path;

pub use deploy::{Assembly, AssemblyError, wire};
pub use diag::{Code, Finding, Label, Report, Severity};
pub use model::Spec;

/// A spec parsed from RON, with the span index of its text.
#[derive(Clone, Debug)]
pub struct Loaded {
    /// The spec.
    pub spec: Spec,
    /// Spans of the text's values (absent only if the span parser gave up).
    pub index: Option<span::SNode>,
    /// File name, for diagnostics.
    pub file: String,
    /// The text.
    pub source: String,
}

/// Parse `source` (named `file` in diagnostics). Syntax and schema errors come back
/// as a report with one finding. A UTF-8 byte-order mark at the start is skipped
/// (editors on Windows write one).
pub fn load(file: impl Into<String>, source: impl Into<String>) -> Result<Loaded, Report> {
    let (file, mut source) = (file.into(), source.into());
    if source.starts_with('\u{feff}') {
        source.drain(..'\u{feff}'.len_utf8());
    }
    match options().from_str::<Spec>(&source) {
        Ok(spec) => {
            let index = span::parse(&source);
            Ok(Loaded {
                spec,
                index,
                file,
                source,
            })
        }
        Err(e) => {
            let finding = syntax_finding(&source, &e);
            Err(Report::new(file, source, vec![finding]))
        }
    }
}

/// The RON options of spec files: `implicit_some` is on, so optional fields are
/// written without `Some(...)`.
pub fn options() -> ron::Options {
    ron::Options::default().with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
}

/// Load and check `source`; the spec is returned when it could be parsed.
pub fn check_source(file: impl Into<String>, source: impl Into<String>) -> (Option<Spec>, Report) {
    match load(file, source) {
        Ok(loaded) => {
            let report = check(&loaded);
            (Some(loaded.spec), report)
        }
        Err(report) => (None, report),
    }
}

/// Check a loaded spec.
pub fn check(loaded: &Loaded) -> Report {
    let findings = check::Checker::new(&loaded.spec, loaded.index.as_ref()).run();
    Report::new(loaded.file.clone(), loaded.source.clone(), findings)
}

/// Check a loaded spec without the arc proof: names, types, wiring, FSM graphs
/// (what drawing a diagram needs, at a cost linear in the spec).
pub fn check_structure(loaded: &Loaded) -> Report {
    let findings = check::Checker::new(&loaded.spec, loaded.index.as_ref())
        .without_proof()
        .run();
    Report::new(loaded.file.clone(), loaded.source.clone(), findings)
}

/// Read, load and check a file.
pub fn check_file(path: &Path) -> std::io::Result<(Option<Spec>, Report)> {
    read_and_check(path, check)
}

/// Read, load and check a file without the arc proof ([`check_structure`]).
pub fn check_file_structure(path: &Path) -> std::io::Result<(Option<Spec>, Report)> {
    read_and_check(path, check_structure)
}

fn read_and_check(
    path: &Path,
    check: fn(&Loaded) -> Report,
) -> std::io::Result<(Option<Spec>, Report)> {
    let file = path.display().to_string();
    let bytes = std::fs::read(path)?;
    let source = match decode(&file, bytes) {
        Ok(source) => source,
        Err(report) => return Ok((None, report)),
    };
    Ok(match load(file, source) {
        Ok(loaded) => {
            let report = check(&loaded);
            (Some(loaded.spec), report)
        }
        Err(report) => (None, report),
    })
}

/// The text of a spec file's bytes, or a report whose finding points at the first
/// byte that is not UTF-8 (`spec::encoding`).
pub fn decode(file: &str, bytes: Vec<u8>) -> Result<String, Report> {
    match String::from_utf8(bytes) {
        Ok(text) => Ok(text),
        Err(e) => {
            let at = e.utf8_error().valid_up_to();
            let bad = e.as_bytes().get(at).copied().unwrap_or(0);
            // The lossy text has the same prefix: the replacement character is at `at`.
            let text = String::from_utf8_lossy(e.as_bytes()).into_owned();
            let (line, col) = diag::line_col(&text, at);
            let finding = Finding::new(
                Code::Encoding,
                one_char_at(&text, at),
                format!("byte 0x{bad:02x}"),
                format!("the file is not UTF-8 text: byte 0x{bad:02x} at {line}:{col} does not belong to a UTF-8 character"),
            )
            .help("specs are UTF-8 text; save the file as UTF-8");
            Err(Report::new(file, text, vec![finding]))
        }
    }
}

/// The span of the `name` field (or the opening) of the innermost struct whose
/// closing parenthesis is at byte `close`.
fn struct_name_ending_at(node: &span::SNode, close: usize) -> Option<std::ops::Range<usize>> {
    use span::SKind;
    let children: Vec<&span::SNode> = match &node.kind {
        SKind::Struct { fields, .. } => fields.iter().map(|f| &f.value).collect(),
        SKind::Tuple { items, .. } | SKind::List(items) => items.iter().collect(),
        SKind::Map(entries) => entries.iter().map(|(_, v)| v).collect(),
        SKind::Str { .. } | SKind::Atom => Vec::new(),
    };
    if let Some(inner) = children
        .into_iter()
        .filter(|c| c.span.start <= close && close < c.span.end)
        .find_map(|c| struct_name_ending_at(c, close))
    {
        return Some(inner);
    }
    match &node.kind {
        SKind::Struct { fields, .. } if node.span.end == close + 1 => Some(
            fields
                .iter()
                .find(|f| f.key == "name")
                .map_or(node.span.start..node.span.start + 1, |f| {
                    f.value.content_span()
                }),
        ),
        _ => None,
    }
}

/// The character at byte `at` (a character boundary), or the last one if `at` is the
/// end of the text: a non-empty span for a position, unless the text is empty.
fn one_char_at(source: &str, at: usize) -> std::ops::Range<usize> {
    match (
        source[at..].chars().next(),
        source[..at].chars().next_back(),
    ) {
        (Some(c), _) => at..at + c.len_utf8(),
        (None, Some(c)) => at - c.len_utf8()..at,
        (None, None) => at..at,
    }
}

fn syntax_finding(source: &str, e: &ron::error::SpannedError) -> Finding {
    use ron::error::Error as E;
    let start = diag::offset_of(source, e.span.start.line, e.span.start.col);
    let end = diag::offset_of(source, e.span.end.line, e.span.end.col).max(start);
    let mut span = if end > start {
        start..end
    } else {
        one_char_at(source, start)
    };
    if let E::MissingStructField { .. } = &e.code {
        // `ron` points at the struct's closing parenthesis; point at its name instead.
        if let Some(name) =
            span::parse(source).and_then(|root| struct_name_ending_at(&root, span.start))
        {
            span = name;
        }
    }
    let (code, message, help) = match &e.code {
        E::NoSuchStructField {
            expected,
            found,
            outer,
        } => (
            Code::UnknownField,
            format!(
                "unknown field `{found}`{}",
                outer
                    .as_ref()
                    .map_or(String::new(), |o| format!(" in `{o}`"))
            ),
            format!("expected one of: {}", expected.join(", ")),
        ),
        E::MissingStructField { field, outer } => (
            Code::MissingField,
            format!(
                "missing field `{field}`{}",
                outer
                    .as_ref()
                    .map_or(String::new(), |o| format!(" in `{o}`"))
            ),
            format!("add `{field}: ...`"),
        ),
        other => (
            Code::Syntax,
            other.to_string(),
            "see the specification reference, docs/spec-reference.md, for the schema".to_owned(),
        ),
    };
    Finding::new(code, span, "here", message).help(help)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn syntax_errors_label_a_whole_character() {
        // At a multi-byte character, at the end of the text, in an empty text.
        for (text, label) in [("é", "é"), ("(", "("), ("(name: \"x\",\n", "\n")] {
            let (_, report) = check_source("x.ron", text);
            let f = &report.findings[0];
            assert_eq!(f.code, Code::Syntax, "{text:?}: {f:?}");
            assert_eq!(&text[f.labels[0].span.clone()], label, "{text:?}: {f:?}");
        }
        let (_, report) = check_source("x.ron", "");
        assert_eq!(report.findings[0].labels[0].span, 0..0);
    }
}
