//! Diagrams from a spec, as DOT, Mermaid or SVG (drawn here: no Graphviz needed).
//!
//! * [`Kind::Fsm`]: the FSM of a subsystem, like Fig. 5 of the paper: behaviours with
//!   their kind and terminal condition, arcs labelled with initial conditions.
//! * [`Kind::Structure`]: agents, their components with buffers, and the links
//!   between them, like Figs. 2 and 4; above [`OVERVIEW_THRESHOLD`] subsystems
//!   (see [`Detail`]), an overview instead: one box per agent, one edge per pair
//!   of linked agents with the links' count, in rows.
//! * [`Kind::Dataflow`]: for each behaviour of a subsystem, which buffers its
//!   transition functions read and write, like Figs. 6-8.
//!
//! Rendering is a pure function of the spec; output is byte-stable (declaration order,
//! fixed number formatting), so it can be snapshot-tested and diffed in review.

mod dataflow;
mod fsm;
#[doc(hidden)]
pub mod geometry;
mod layout;
mod overview;
mod structure;
mod svg;

use std::fmt;
use std::str::FromStr;

use crate::model::{Spec, Subsystem};

pub use overview::THRESHOLD as OVERVIEW_THRESHOLD;

/// Which diagram.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kind {
    /// The FSM of a subsystem.
    Fsm,
    /// Agents, components, buffers and links.
    Structure,
    /// What the transition functions read and write.
    Dataflow,
}

/// How much of the structure to draw ([`Kind::Structure`]; the other kinds
/// ignore it).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Detail {
    /// The detailed structure up to [`OVERVIEW_THRESHOLD`] (60) subsystems in
    /// the agents drawn, the overview above.
    #[default]
    Auto,
    /// One box per agent (its components' names, or their counts), one edge per
    /// pair of linked agents (the buffers' names, or the links' count), in rows
    /// of at most 24 agents in link order: time and size linear in the agents
    /// and links, readable at 500 agents.
    Overview,
    /// Every component with its buffers and every link, whatever the size (the
    /// layout of the links between agents that are not neighbours grows
    /// quadratically: slow and very wide above [`OVERVIEW_THRESHOLD`]
    /// subsystems).
    Detailed,
}

/// Output format.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Format {
    /// Graphviz DOT.
    Dot,
    /// Mermaid (renders on GitHub and in many Markdown tools).
    Mermaid,
    /// SVG, laid out by this crate.
    Svg,
}

/// A diagram that cannot be drawn.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum DiagramError {
    /// `--subsystem` names no subsystem.
    #[error("no subsystem `{name}` in the spec (subsystems: {known})")]
    UnknownSubsystem {
        /// The name asked for.
        name: String,
        /// The subsystems there are.
        known: String,
    },
    /// A kind or format name that does not exist.
    #[error("unknown {what} `{name}` (expected one of: {expected})")]
    UnknownName {
        /// "kind" or "format".
        what: &'static str,
        /// The name given.
        name: String,
        /// The accepted names.
        expected: &'static str,
    },
}

impl FromStr for Kind {
    type Err = DiagramError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "fsm" => Ok(Kind::Fsm),
            "structure" => Ok(Kind::Structure),
            "dataflow" => Ok(Kind::Dataflow),
            _ => Err(DiagramError::UnknownName {
                what: "kind",
                name: s.to_owned(),
                expected: "fsm, structure, dataflow",
            }),
        }
    }
}

impl FromStr for Format {
    type Err = DiagramError;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "dot" => Ok(Format::Dot),
            "mermaid" => Ok(Format::Mermaid),
            "svg" => Ok(Format::Svg),
            _ => Err(DiagramError::UnknownName {
                what: "format",
                name: s.to_owned(),
                expected: "dot, mermaid, svg",
            }),
        }
    }
}

impl fmt::Display for Kind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Kind::Fsm => "fsm",
            Kind::Structure => "structure",
            Kind::Dataflow => "dataflow",
        })
    }
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Format::Dot => "dot",
            Format::Mermaid => "mermaid",
            Format::Svg => "svg",
        })
    }
}

/// Render a diagram. For [`Kind::Fsm`] and [`Kind::Dataflow`], `subsystem` selects
/// one subsystem; without it every subsystem is drawn. [`Kind::Structure`] draws the
/// whole system (or, with `subsystem`, the agent that holds it).
///
/// The structure is detailed up to [`OVERVIEW_THRESHOLD`] subsystems, an
/// overview above ([`Detail::Auto`]; [`render_with`] chooses).
///
/// The spec should have passed the checker; references that do not resolve are left
/// out of the drawing rather than reported.
pub fn render(
    spec: &Spec,
    kind: Kind,
    subsystem: Option<&str>,
    format: Format,
) -> Result<String, DiagramError> {
    render_with(spec, kind, subsystem, format, Detail::Auto)
}

/// [`render`], the structure drawn as `detail` says.
pub fn render_with(
    spec: &Spec,
    kind: Kind,
    subsystem: Option<&str>,
    format: Format,
    detail: Detail,
) -> Result<String, DiagramError> {
    let subs = select(spec, subsystem)?;
    Ok(match kind {
        Kind::Fsm => fsm::render(spec, &subs, format),
        Kind::Dataflow => dataflow::render(spec, &subs, format),
        Kind::Structure => structure_of(spec, &agents_of(spec, subsystem), format, detail),
    })
}

/// The structure of `agents`, detailed or as an overview.
fn structure_of(spec: &Spec, agents: &[usize], format: Format, detail: Detail) -> String {
    if overview_for(spec, agents, detail) {
        overview::render(spec, agents, format)
    } else {
        structure::render(spec, agents, format)
    }
}

/// Whether `detail` draws the overview of `agents`.
fn overview_for(spec: &Spec, agents: &[usize], detail: Detail) -> bool {
    match detail {
        Detail::Overview => true,
        Detail::Detailed => false,
        Detail::Auto => {
            let subsystems: usize = agents
                .iter()
                .map(|&a| spec.agents[a].subsystems.len())
                .sum();
            subsystems > OVERVIEW_THRESHOLD
        }
    }
}

/// The SVG of the structure's overview ([`Detail::Overview`]) and what it
/// placed, for tests of the layout.
#[doc(hidden)]
pub fn render_overview_scene(spec: &Spec) -> (String, geometry::Scene) {
    overview::draw(spec, &agents_of(spec, None))
}

/// The SVG that [`render`] draws with [`Format::Svg`], and the geometry of what it
/// placed, for tests of the layout.
#[doc(hidden)]
pub fn render_svg_scene(
    spec: &Spec,
    kind: Kind,
    subsystem: Option<&str>,
) -> Result<(String, geometry::Scene), DiagramError> {
    let subs = select(spec, subsystem)?;
    Ok(match kind {
        Kind::Fsm => fsm::draw(spec, &subs),
        Kind::Dataflow => dataflow::draw(spec, &subs),
        Kind::Structure => structure::draw_agents(spec, &agents_of(spec, subsystem)),
    })
}

/// The agents a structure diagram shows: all, or the one that holds `subsystem`.
fn agents_of(spec: &Spec, subsystem: Option<&str>) -> Vec<usize> {
    spec.agents
        .iter()
        .enumerate()
        .filter(|(_, a)| subsystem.is_none_or(|name| a.subsystems.iter().any(|s| s.name == name)))
        .map(|(i, _)| i)
        .collect()
}

/// Every diagram of `spec`, as `(file name, text)` for a folder of them: each
/// subsystem's FSM (`fsm_NAME.svg`, and `fsm_NAME.mmd` for Markdown), the structure
/// (`structure.svg`, an overview above [`OVERVIEW_THRESHOLD`] subsystems), and each subsystem's data flow (`dataflow_NAME.svg`),
/// subsystems in the spec's order.
pub fn render_all(spec: &Spec) -> Vec<(String, String)> {
    let mut files = Vec::new();
    for (_, sub) in spec.subsystems() {
        let one = std::slice::from_ref(&sub);
        files.push((
            format!("fsm_{}.svg", sub.name),
            fsm::render(spec, one, Format::Svg),
        ));
        files.push((
            format!("fsm_{}.mmd", sub.name),
            fsm::render(spec, one, Format::Mermaid),
        ));
    }
    files.push((
        "structure.svg".to_owned(),
        structure_of(spec, &agents_of(spec, None), Format::Svg, Detail::Auto),
    ));
    for (_, sub) in spec.subsystems() {
        files.push((
            format!("dataflow_{}.svg", sub.name),
            dataflow::render(spec, std::slice::from_ref(&sub), Format::Svg),
        ));
    }
    files
}

fn select<'a>(spec: &'a Spec, name: Option<&str>) -> Result<Vec<&'a Subsystem>, DiagramError> {
    let all: Vec<&Subsystem> = spec.subsystems().map(|(_, s)| s).collect();
    match name {
        None => Ok(all),
        Some(n) => match all.iter().find(|s| s.name == n) {
            Some(s) => Ok(vec![*s]),
            None => Err(DiagramError::UnknownSubsystem {
                name: n.to_owned(),
                known: all
                    .iter()
                    .map(|s| s.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
            }),
        },
    }
}

/// Escape a DOT string (without the quotes).
pub(crate) fn dot_esc(s: &str) -> String {
    s.replace('\\', "\\\\").replace('"', "\\\"")
}

/// Escape Mermaid label text: quotes and the characters Mermaid's parsers treat as
/// syntax become entity codes.
pub(crate) fn mermaid_esc(s: &str) -> String {
    let mut out = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '"' => out.push_str("#quot;"),
            '&' => out.push_str("#amp;"),
            '|' => out.push_str("#124;"),
            '<' => out.push_str("#lt;"),
            '>' => out.push_str("#gt;"),
            ';' => out.push_str("#59;"),
            '#' => out.push_str("#35;"),
            ':' => out.push_str("#58;"),
            '{' => out.push_str("#123;"),
            '}' => out.push_str("#125;"),
            c => out.push(c),
        }
    }
    out
}

/// A Mermaid-safe identifier for a name (names are identifiers already in a valid
/// spec; anything else is replaced).
pub(crate) fn mermaid_id(prefix: &str, s: &str) -> String {
    let body: String = s
        .chars()
        .map(|c| {
            if c.is_ascii_alphanumeric() || c == '_' {
                c
            } else {
                '_'
            }
        })
        .collect();
    format!("{prefix}{body}")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse() {
        assert_eq!("fsm".parse::<Kind>(), Ok(Kind::Fsm));
        assert_eq!("svg".parse::<Format>(), Ok(Format::Svg));
        assert!("png".parse::<Format>().is_err());
        assert_eq!(mermaid_esc("a && !b || c"), "a #amp;#amp; !b #124;#124; c");
        assert_eq!(dot_esc(r#"say "hi""#), r#"say \"hi\""#);
    }
}
