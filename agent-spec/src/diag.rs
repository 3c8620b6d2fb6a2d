//! Findings: stable codes, messages, help lines and labelled spans into the RON file,
//! rendered like rustc diagnostics: drawn by miette with the `render` feature (the
//! CLI's), as plain excerpts without it.

use std::fmt;
use std::fmt::Write as _;
use std::ops::Range;
#[cfg(feature = "render")]
use std::sync::Arc;

#[cfg(feature = "render")]
use miette::{
    GraphicalReportHandler, GraphicalTheme, LabeledSpan, MietteDiagnostic, MietteError,
    MietteSpanContents, SourceCode, SourceSpan, SpanContents,
};

/// How bad a finding is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Severity {
    /// The spec is wrong: `embodied check` exits with status 1.
    Error,
    /// Probably a mistake; the spec is still usable.
    Warning,
}

macro_rules! codes {
    ($( $(#[doc = $doc:literal])* $variant:ident = $text:literal, $sev:ident; )*) => {
        /// The stable code of a finding. `Code::ALL` lists them; the specification
        /// reference (`docs/spec-reference.md`) explains each.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
        pub enum Code {
            $( $(#[doc = $doc])* $variant, )*
        }

        impl Code {
            /// Every code.
            pub const ALL: &'static [Code] = &[ $( Code::$variant, )* ];

            /// The code as printed: `spec::unknown_buffer`.
            pub const fn as_str(self) -> &'static str {
                match self { $( Code::$variant => $text, )* }
            }

            /// The severity of findings with this code.
            pub const fn severity(self) -> Severity {
                match self { $( Code::$variant => Severity::$sev, )* }
            }

            /// What the code means.
            pub const fn description(self) -> &'static str {
                match self { $( Code::$variant => concat!($($doc),*).trim_ascii(), )* }
            }
        }
    };
}

codes! {
    /// The file is not valid RON, or not a spec (wrong type, bad value).
    Syntax = "spec::syntax", Error;
    /// A field the schema does not have (misspelt?).
    UnknownField = "spec::unknown_field", Error;
    /// A required field is missing.
    MissingField = "spec::missing_field", Error;
    /// A name is not an identifier.
    InvalidName = "spec::invalid_name", Error;
    /// Two entries of one scope have the same name.
    DuplicateName = "spec::duplicate_name", Error;
    /// A reference to a component (subsystem or device) that does not exist.
    UnknownComponent = "spec::unknown_component", Error;
    /// A reference to a buffer that does not exist where it is looked for.
    UnknownBuffer = "spec::unknown_buffer", Error;
    /// A bare buffer name that several input groups have.
    AmbiguousBuffer = "spec::ambiguous_buffer", Error;
    /// A behaviour uses a transition function that is not defined.
    UnknownFunction = "spec::unknown_function", Error;
    /// A reference to a behaviour that does not exist.
    UnknownBehaviour = "spec::unknown_behaviour", Error;
    /// A condition or relation names an undeclared predicate.
    UnknownPredicate = "spec::unknown_predicate", Error;
    /// A function's target is not memory or one of the subsystem's output groups.
    UnknownTarget = "spec::unknown_target", Error;
    /// A transition function writes a buffer outside its declared target.
    WriteOutsideTarget = "spec::write_outside_target", Error;
    /// Two functions of one behaviour write the same target.
    DuplicateTarget = "spec::duplicate_target", Error;
    /// An agent without exactly one control subsystem.
    AgentControl = "spec::agent_control", Error;
    /// A group or link that breaks the agent structure (e and r talk only to their own c and devices; agents only through control subsystems).
    Structure = "spec::structure", Error;
    /// A link whose ends do not name each other as peers.
    PeerMismatch = "spec::peer_mismatch", Error;
    /// A link from an input or to an output.
    LinkDirection = "spec::link_direction", Error;
    /// A link between buffers of different types.
    TypeMismatch = "spec::type_mismatch", Error;
    /// An input buffer fed by no output.
    UnfedInput = "spec::unfed_input", Error;
    /// An input buffer fed by more than one output.
    MultipleWriters = "spec::multiple_writers", Error;
    /// An output buffer nobody reads.
    UnreadOutput = "spec::unread_output", Warning;
    /// A queue link with capacity zero.
    QueueBound = "spec::queue_bound", Error;
    /// A period that is not a positive finite number.
    Period = "spec::period", Error;
    /// An FSM without an initial behaviour.
    NoInitial = "spec::no_initial", Error;
    /// A behaviour that cannot be reached from the initial behaviour.
    Unreachable = "spec::unreachable", Error;
    /// A behaviour that can end but has no outgoing arc and is not declared final.
    NoWayOut = "spec::no_way_out", Error;
    /// A final behaviour with outgoing arcs.
    FinalWithArcs = "spec::final_with_arcs", Error;
    /// A condition that does not parse.
    ConditionSyntax = "spec::condition_syntax", Error;
    /// Two arcs leaving one behaviour can hold at once (with a counterexample).
    ArcsOverlap = "spec::arcs_overlap", Error;
    /// When a behaviour ends, possibly no arc holds (with a counterexample).
    ArcsIncomplete = "spec::arcs_incomplete", Error;
    /// The arc proof's budget ran out: the arcs of a behaviour are neither proven nor refuted.
    ProofBudget = "spec::proof_budget", Warning;
    /// The file is not UTF-8 text.
    Encoding = "spec::encoding", Error;
    /// A terminal condition that can never hold.
    TerminalNever = "spec::terminal_never", Warning;
    /// A function no behaviour uses.
    UnusedFunction = "spec::unused_function", Warning;
    /// A predicate no condition uses.
    UnusedPredicate = "spec::unused_predicate", Warning;
    /// A deployment names a component twice, or runs an omitted one.
    DeployTwice = "spec::deploy_twice", Error;
    /// A deployment neither runs nor omits a component.
    DeployMissing = "spec::deploy_missing", Error;
    /// A process's endpoint that is not `tcp/<host>:<port>` (or `tls/...`), or one
    /// that two processes share.
    DeployEndpoint = "spec::deploy_endpoint", Error;
    /// A ROS 2 name (topic, node, namespace, package or message type) that breaks ROS 2's rules.
    Ros2Name = "spec::ros2_name", Error;
    /// A ROS 2 domain id above 232.
    Ros2Domain = "spec::ros2_domain", Error;
    /// A ROS 2 topic's quality of service that keeps no sample (depth 0).
    Ros2Qos = "spec::ros2_qos", Error;
    /// A ROS 2 publish of an input buffer, or a subscribe into an output buffer.
    Ros2Direction = "spec::ros2_direction", Error;
    /// A ROS 2 topic given twice in one section, or an input buffer fed by two topics.
    Ros2Duplicate = "spec::ros2_duplicate", Error;
    /// A deployment's `ros2` section names a buffer of a component the deployment does not run.
    Ros2NotDeployed = "spec::ros2_not_deployed", Error;
    /// A ROS 2 topic feeds an input that a running component also writes over a sample link: each overwrites the other.
    Ros2Overwritten = "spec::ros2_overwritten", Warning;
    /// A ROS 2 publish of an output that no link carries: its values reach no one, the bridge included.
    Ros2Unlinked = "spec::ros2_unlinked", Error;
    /// A ROS 2 topic whose buffer's Rust type cannot be its message: the
    /// type cannot be a ROS 2 message (no shape, or a shape CDR cannot carry),
    /// or no adapter makes (or reads) the standard message the entry names.
    /// Found by the program that builds the bridge (`--ros2`), which knows the
    /// types; said in the checker's format at the entry.
    Ros2Type = "spec::ros2_type", Error;
    /// A contract or timing figure with a bad value (not a positive finite number, limits the wrong way round, a field path its buffer's type cannot have), or one that names no deployment or no queue link.
    Contract = "spec::contract", Error;
    /// A chain whose hops are not carried by links, do not connect, or do not run from a real receptor to a real effector.
    Chain = "spec::chain", Error;
    /// A figure the timing analysis needs is not declared: a component's worst-case execution time, the latency between a deployment's processes.
    TimingMissing = "spec::timing_missing", Error;
    /// A thread whose worst-case response time exceeds its period under rate-monotonic fixed priorities.
    Unschedulable = "spec::unschedulable", Error;
    /// A chain whose worst-case data age or reaction time exceeds its deadline.
    ChainDeadline = "spec::chain_deadline", Error;
    /// A queue link whose bound is below what its rates and response times need, or whose writer outpaces its reader.
    QueueOverflow = "spec::queue_overflow", Error;
}

impl Code {
    /// Whether only a program finds it, not the checker: it needs the Rust
    /// types behind the spec's buffers (a program building its ROS 2 bridge
    /// reports it at the spec's entry, in the checker's format).
    pub const fn is_found_by_programs(self) -> bool {
        matches!(self, Code::Ros2Type)
    }

    /// Whether a finding of this code is a root cause: something wrong where it is
    /// written (the syntax, a name, a reference to something that does not exist, a
    /// bad value). The other findings are about the whole (the wiring, the FSM
    /// graph, the proofs, deployments), and a root cause often causes some of them:
    /// a misspelt peer leaves inputs unfed. Reports list root causes first.
    pub const fn is_root_cause(self) -> bool {
        matches!(
            self,
            Code::Syntax
                | Code::UnknownField
                | Code::MissingField
                | Code::Encoding
                | Code::InvalidName
                | Code::DuplicateName
                | Code::UnknownComponent
                | Code::UnknownBuffer
                | Code::AmbiguousBuffer
                | Code::UnknownFunction
                | Code::UnknownBehaviour
                | Code::UnknownPredicate
                | Code::UnknownTarget
                | Code::ConditionSyntax
                | Code::Period
                | Code::QueueBound
                | Code::LinkDirection
                | Code::Ros2Name
                | Code::Ros2Domain
                | Code::Ros2Qos
                | Code::Ros2Direction
                | Code::Contract
        )
    }
}

impl fmt::Display for Code {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A labelled byte range of the source.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Label {
    /// Byte range.
    pub span: Range<usize>,
    /// What to print under it.
    pub text: String,
}

/// One finding of the checker.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Finding {
    /// Stable code.
    pub code: Code,
    /// One sentence.
    pub message: String,
    /// How to fix it.
    pub help: String,
    /// Spans; the first is the primary one.
    pub labels: Vec<Label>,
}

impl Finding {
    /// A finding with a primary label.
    pub fn new(
        code: Code,
        span: Range<usize>,
        label: impl Into<String>,
        message: impl Into<String>,
    ) -> Self {
        Finding {
            code,
            message: cap(message.into()),
            help: String::new(),
            labels: vec![Label {
                span,
                text: cap(label.into()),
            }],
        }
    }

    /// Set the help line.
    pub fn help(mut self, help: impl Into<String>) -> Self {
        self.help = cap(help.into());
        self
    }

    /// Add a secondary label.
    pub fn label(mut self, span: Range<usize>, text: impl Into<String>) -> Self {
        self.labels.push(Label {
            span,
            text: cap(text.into()),
        });
        self
    }

    /// Its severity.
    pub fn severity(&self) -> Severity {
        self.code.severity()
    }

    /// Byte offset of the primary label.
    pub fn offset(&self) -> usize {
        self.labels.first().map_or(0, |l| l.span.start)
    }
}

/// All findings for one file.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Report {
    /// File name as given.
    pub file: String,
    /// Its text.
    pub source: String,
    /// Findings: root causes first ([`Code::is_root_cause`]), then the findings
    /// they may cause, each part sorted by position then code.
    pub findings: Vec<Finding>,
}

impl Report {
    /// A report, sorting the findings (root causes first, then by position).
    pub fn new(
        file: impl Into<String>,
        source: impl Into<String>,
        mut findings: Vec<Finding>,
    ) -> Self {
        findings.sort_by(|a, b| {
            let key = |f: &Finding| (!f.code.is_root_cause(), f.offset(), f.code);
            key(a).cmp(&key(b)).then_with(|| a.message.cmp(&b.message))
        });
        findings.dedup();
        Report {
            file: file.into(),
            source: source.into(),
            findings,
        }
    }

    /// Number of errors.
    pub fn errors(&self) -> usize {
        self.findings
            .iter()
            .filter(|f| f.severity() == Severity::Error)
            .count()
    }

    /// Number of warnings.
    pub fn warnings(&self) -> usize {
        self.findings.len() - self.errors()
    }

    /// Whether the spec is usable (no errors).
    pub fn is_ok(&self) -> bool {
        self.errors() == 0
    }

    /// `line:col` (1-based) of a byte offset.
    pub fn line_col(&self, offset: usize) -> (usize, usize) {
        line_col(&self.source, offset)
    }

    /// Render the findings like rustc/miette, without colours, at `width` columns:
    /// each with its code, message, the lines around its labels, and help. The
    /// first [`Report::RENDER_MAX`] findings are drawn; a line counts the others
    /// (`short` lists them all). A label on a line longer than [`LONG_LINE`] bytes
    /// is shown in an excerpt of that line instead. The cost is linear in the
    /// number of findings and in the size of the text.
    ///
    /// Without the `render` feature (miette), every finding is shown as such an
    /// excerpt: the header, the primary label's line with a caret line, the help.
    pub fn render(&self, width: usize) -> String {
        #[cfg(feature = "render")]
        let out = self.render_miette(width);
        #[cfg(not(feature = "render"))]
        let out = {
            let _ = width;
            let index = LineIndex::new(&self.source);
            let mut cursor = Cursor::new(&self.source, &index);
            let mut out = String::new();
            for f in self.findings.iter().take(Self::RENDER_MAX) {
                let at = cursor.at(f.offset());
                self.render_plain(&mut out, f, &index, at);
            }
            out
        };
        let mut out = out;
        let more = self.findings.len().saturating_sub(Self::RENDER_MAX);
        if more > 0 {
            let _ = writeln!(
                out,
                "... and {more} more findings (`--style short` lists every finding, one line each)"
            );
        }
        out
    }

    /// The first [`Report::RENDER_MAX`] findings drawn by miette.
    #[cfg(feature = "render")]
    fn render_miette(&self, width: usize) -> String {
        let handler = GraphicalReportHandler::new_themed(GraphicalTheme::unicode_nocolor())
            .with_width(width)
            .with_links(false);
        let index = Arc::new(LineIndex::new(&self.source));
        let source = Indexed {
            name: Arc::from(self.file.as_str()),
            text: Arc::from(self.source.as_str()),
            index: Arc::clone(&index),
        };
        let mut cursor = Cursor::new(&self.source, &index);
        let mut out = String::new();
        for f in self.findings.iter().take(Self::RENDER_MAX) {
            let (line, col) = cursor.at(f.offset());
            let long = f.labels.iter().any(|l| {
                let (start, len) = clamp(&l.span, self.source.len());
                (index.line_of(start)..=index.line_of(start + len))
                    .any(|k| index.line_len(k) > LONG_LINE)
            });
            if long {
                self.render_plain(&mut out, f, &index, (line, col));
                continue;
            }
            let labels = f.labels.iter().enumerate().map(|(i, l)| {
                let span = clamp(&l.span, self.source.len());
                let text = (!l.text.is_empty()).then(|| l.text.clone());
                if i == 0 {
                    LabeledSpan::new_primary_with_span(text, span)
                } else {
                    LabeledSpan::new_with_span(text, span)
                }
            });
            let mut d = MietteDiagnostic::new(f.message.clone())
                .with_code(f.code.as_str())
                .with_severity(match f.severity() {
                    Severity::Error => miette::Severity::Error,
                    Severity::Warning => miette::Severity::Warning,
                })
                .with_labels(labels);
            if !f.help.is_empty() {
                d = d.with_help(f.help.clone());
            }
            let report = miette::Report::new(d).with_source_code(source.clone());
            if handler.render_report(&mut out, report.as_ref()).is_err() {
                self.render_plain(&mut out, f, &index, (line, col));
            }
        }
        out
    }

    /// At most this many findings are drawn by [`Report::render`].
    pub const RENDER_MAX: usize = 1000;

    /// A finding without miette: the header, an excerpt of the primary label's line
    /// around it with a caret line, and the help.
    fn render_plain(&self, out: &mut String, f: &Finding, index: &LineIndex, at: (usize, usize)) {
        let sev = match f.severity() {
            Severity::Error => "error",
            Severity::Warning => "warning",
        };
        let _ = writeln!(out, "{}\n\n  × {}", f.code, f.message);
        let _ = writeln!(out, "  at {}:{}:{} ({sev})", self.file, at.0, at.1);
        if let Some(l) = f.labels.first() {
            let (start, len) = clamp(&l.span, self.source.len());
            let line = index.line_of(start);
            let (ls, le) = (index.line_start(line), index.line_end(line));
            let text = &self.source[ls..le];
            let rel = start - ls;
            let from = floor_char(text, rel.saturating_sub(EXCERPT));
            let to = floor_char(text, (rel + len.max(1) + EXCERPT).min(text.len()));
            let excerpt = text[from..to].trim_end_matches(['\n', '\r']);
            let lead = if from > 0 { "…" } else { "" };
            let tail = if to < text.len() { "…" } else { "" };
            let pad = lead.chars().count() + text[from..rel].chars().count();
            let width = text[rel..floor_char(text, (rel + len).min(text.len()))]
                .chars()
                .count()
                .clamp(1, EXCERPT);
            let _ = writeln!(out, "   │ {lead}{excerpt}{tail}");
            let _ = writeln!(
                out,
                "   │ {}{} {}",
                " ".repeat(pad),
                "^".repeat(width),
                l.text
            );
        }
        if !f.help.is_empty() {
            let _ = writeln!(out, "  help: {}", f.help);
        }
        out.push('\n');
    }

    /// One line per finding: `file:line:col: severity[code]: message`.
    pub fn short(&self) -> String {
        let index = LineIndex::new(&self.source);
        let mut cursor = Cursor::new(&self.source, &index);
        let mut out = String::new();
        for f in &self.findings {
            let (l, c) = cursor.at(f.offset());
            let sev = match f.severity() {
                Severity::Error => "error",
                Severity::Warning => "warning",
            };
            let _ = writeln!(
                out,
                "{}:{l}:{c}: {sev}[{}]: {}",
                self.file, f.code, f.message
            );
        }
        out
    }
}

/// Lines longer than this many bytes are not handed to miette (it formats columns
/// with widths, which panic past 65,535): their findings show an excerpt.
pub const LONG_LINE: usize = 4096;

/// Bytes of context on either side of a label in an excerpt.
const EXCERPT: usize = 60;

/// `at` moved back to a character boundary of `text`.
fn floor_char(text: &str, mut at: usize) -> usize {
    at = at.min(text.len());
    while !text.is_char_boundary(at) {
        at -= 1;
    }
    at
}

/// The byte offsets at which the lines of a text start.
#[derive(Debug)]
struct LineIndex {
    starts: Vec<usize>,
    len: usize,
}

impl LineIndex {
    fn new(text: &str) -> LineIndex {
        let mut starts = vec![0];
        starts.extend(
            text.bytes()
                .enumerate()
                .filter(|(_, b)| *b == b'\n')
                .map(|(i, _)| i + 1),
        );
        LineIndex {
            starts,
            len: text.len(),
        }
    }

    /// 0-based line of byte `offset`.
    fn line_of(&self, offset: usize) -> usize {
        self.starts
            .partition_point(|&s| s <= offset.min(self.len))
            .saturating_sub(1)
    }

    fn line_start(&self, line: usize) -> usize {
        self.starts.get(line).copied().unwrap_or(self.len)
    }

    /// End of `line`, its newline included.
    fn line_end(&self, line: usize) -> usize {
        self.starts.get(line + 1).copied().unwrap_or(self.len)
    }

    #[cfg(feature = "render")]
    fn line_len(&self, line: usize) -> usize {
        self.line_end(line) - self.line_start(line)
    }
}

/// `line:col` of increasing offsets in time linear in the text: the column is
/// counted on from the previous offset when it is on the same line.
struct Cursor<'a> {
    text: &'a str,
    index: &'a LineIndex,
    /// Last offset asked, its line and column (1-based).
    at: Option<(usize, usize, usize)>,
}

impl<'a> Cursor<'a> {
    fn new(text: &'a str, index: &'a LineIndex) -> Cursor<'a> {
        Cursor {
            text,
            index,
            at: None,
        }
    }

    fn at(&mut self, offset: usize) -> (usize, usize) {
        let offset = floor_char(self.text, offset);
        let line = self.index.line_of(offset);
        let (from, col) = match self.at {
            Some((off, l, c)) if l == line + 1 && off <= offset => (off, c),
            _ => (self.index.line_start(line), 1),
        };
        let col = col + self.text[from..offset].chars().count();
        self.at = Some((offset, line + 1, col));
        (line + 1, col)
    }
}

/// A file as miette's source: the lines around a span are found with the line
/// index, not by scanning the file from its start (miette's own way, which made
/// rendering quadratic in the number of findings).
#[cfg(feature = "render")]
#[derive(Clone, Debug)]
struct Indexed {
    name: Arc<str>,
    text: Arc<str>,
    index: Arc<LineIndex>,
}

#[cfg(feature = "render")]
impl SourceCode for Indexed {
    fn read_span<'a>(
        &'a self,
        span: &SourceSpan,
        context_lines_before: usize,
        context_lines_after: usize,
    ) -> Result<Box<dyn SpanContents<'a> + 'a>, MietteError> {
        // The lines miette would return, cut out, read by miette, and put back.
        let (start, end) = (span.offset(), span.offset() + span.len());
        let first = self
            .index
            .line_of(start)
            .saturating_sub(context_lines_before);
        let last = self.index.line_of(end.saturating_sub(1).max(start)) + context_lines_after + 1;
        let (from, to) = (self.index.line_start(first), self.index.line_end(last));
        let window = self.text.get(from..to).ok_or(MietteError::OutOfBounds)?;
        let local = SourceSpan::new(start.saturating_sub(from).into(), span.len());
        let inner = window.read_span(&local, context_lines_before, context_lines_after)?;
        Ok(Box::new(MietteSpanContents::new_named(
            self.name.to_string(),
            inner.data(),
            SourceSpan::new((inner.span().offset() + from).into(), inner.span().len()),
            inner.line() + first,
            inner.column(),
            inner.line_count() + first,
        )))
    }
}

/// Messages, help lines and labels quote the spec (conditions, names, lists of
/// names): at most this many characters of each are kept, so that a hostile
/// spec cannot make its report larger than a bounded multiple of its findings.
pub const TEXT_MAX: usize = 1000;

fn cap(mut text: String) -> String {
    if let Some((cut, _)) = text.char_indices().nth(TEXT_MAX) {
        let dropped = text[cut..].chars().count();
        text.truncate(cut);
        text.push_str(&format!("… ({dropped} more characters)"));
    }
    text
}

/// `text` cut to `max` characters, with `…` where cut: for quoting conditions
/// and the like in messages.
pub fn abbreviate(text: &str, max: usize) -> std::borrow::Cow<'_, str> {
    match text.char_indices().nth(max) {
        Some((cut, _)) => format!("{}…", &text[..cut]).into(),
        None => text.into(),
    }
}

fn clamp(span: &Range<usize>, len: usize) -> (usize, usize) {
    let start = span.start.min(len);
    let end = span.end.clamp(start, len);
    (start, end - start)
}

/// `line:col` (1-based, columns in characters) of byte `offset` of `text`.
pub fn line_col(text: &str, offset: usize) -> (usize, usize) {
    let offset = floor_char(text, offset);
    let before = &text[..offset];
    let line = before.matches('\n').count() + 1;
    let col = before.rsplit('\n').next().map_or(0, |l| l.chars().count()) + 1;
    (line, col)
}

/// Byte offset of 1-based `line:col` (columns in characters), clamped to the text.
pub fn offset_of(text: &str, line: usize, col: usize) -> usize {
    let mut off = 0;
    for (i, l) in text.split_inclusive('\n').enumerate() {
        if i + 1 == line {
            let c = l
                .char_indices()
                .nth(col.saturating_sub(1))
                .map_or(l.len(), |(b, _)| b);
            return off + c;
        }
        off += l.len();
    }
    text.len()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn positions_round_trip() {
        let text = "ab\ncdé\nf";
        for off in [0, 1, 3, 5, 8, 9] {
            let (l, c) = line_col(text, off);
            assert_eq!(offset_of(text, l, c), off, "offset {off} -> {l}:{c}");
        }
        assert_eq!(line_col(text, 100), (3, 2));
    }

    /// Without miette (the default of a user's crate), a report is drawn as plain
    /// excerpts: the code and message, the line with a caret under the label, the
    /// help. (`.ci/run` runs agent-spec's unit tests without the feature.)
    #[cfg(not(feature = "render"))]
    #[test]
    fn without_miette_findings_are_plain_excerpts() {
        let source = "(\n  name: \"x\",\n  bad: 1,\n)\n";
        let at = source.find("bad").unwrap_or(0);
        let finding = Finding::new(
            Code::UnknownField,
            at..at + 3,
            "not a field",
            "no field `bad`",
        )
        .help("remove it");
        let text = Report::new("x.ron", source, vec![finding]).render(80);
        assert!(text.contains("spec::unknown_field"), "{text}");
        assert!(text.contains("no field `bad`"), "{text}");
        assert!(text.contains("bad: 1,"), "{text}");
        assert!(text.contains('^'), "{text}");
        assert!(text.contains("remove it"), "{text}");
    }

    #[test]
    fn codes_are_stable_and_documented() {
        for c in Code::ALL {
            assert!(c.as_str().starts_with("spec::"));
            assert!(!c.description().is_empty());
        }
        let mut names: Vec<_> = Code::ALL.iter().map(|c| c.as_str()).collect();
        names.sort_unstable();
        names.dedup();
        assert_eq!(names.len(), Code::ALL.len());
    }
}
