//! The overview of a large system: one box per agent and one edge per pair of
//! agents that links join, in a grid.
//!
//! The detailed structure diagram ([`super::structure`]) draws every component
//! and every link; above [`THRESHOLD`] subsystems it grows too wide to read and
//! too slow to place. The overview draws, in time and size linear in the agents
//! and links:
//!
//! * each agent as a box with its subsystems' and devices' names when it has at
//!   most [`NAMES_UP_TO`] of them, else their counts;
//! * the links between two agents (either way) as one edge with their buffer
//!   names when there are at most two, else their count; `⇄` when they go both
//!   ways (the arrow shows the direction of the first);
//! * the agents in rows of at most [`MAX_COLUMNS`], in link order (each agent
//!   next to the one it was reached from, depth first from the first agent), the
//!   rows read alternately left to right and right to left, so that a chain or a
//!   ring of agents stays a chain of neighbouring boxes.

use std::collections::HashMap;
use std::fmt::Write as _;

use super::geometry::{Path, Point, Scene, Segment};
use super::svg::{Boxed, LABEL_H, LINE_H, LabelAt, MARGIN, PAD, Svg, label_w};
use super::{Format, dot_esc, mermaid_esc, mermaid_id};
use crate::model::Spec;

/// Above this many subsystems in the agents drawn, [`super::Detail::Auto`]
/// draws the overview instead of the detailed structure.
pub const THRESHOLD: usize = 60;

/// The most columns of agents.
pub(crate) const MAX_COLUMNS: usize = 24;

/// An agent's components are named in its box when it has at most this many.
pub(crate) const NAMES_UP_TO: usize = 4;

/// The longest line in a box, in characters.
const MAX_CHARS: usize = 32;

/// The longest edge label, in characters (it fits between neighbouring boxes).
const MAX_LABEL_CHARS: usize = 14;

/// Horizontal space between boxes.
const COL_GAP: f64 = 120.0;

/// Vertical space between rows of boxes.
const ROW_GAP: f64 = 56.0;

/// The links between two agents (positions in the drawing order).
struct Pair {
    from: usize,
    to: usize,
    count: usize,
    both_ways: bool,
    /// The first buffers' names (at most 3 kept).
    names: Vec<String>,
}

impl Pair {
    fn label(&self) -> String {
        let text = if self.count <= 2 {
            self.names.join(", ")
        } else {
            format!("{} links", self.count)
        };
        let text = if text.chars().count() > MAX_LABEL_CHARS - 2 {
            format!("{} links", self.count)
        } else {
            text
        };
        if self.both_ways {
            format!("{text} ⇄")
        } else {
            text
        }
    }
}

/// The overview's content: agents (indices into `spec.agents`) in drawing
/// order, each box's lines, and the pairs of agents with links.
struct Model {
    order: Vec<usize>,
    lines: Vec<Vec<String>>,
    pairs: Vec<Pair>,
}

fn cut(s: &str, max: usize) -> String {
    if s.chars().count() <= max {
        s.to_owned()
    } else {
        let mut out: String = s.chars().take(max - 1).collect();
        out.push('…');
        out
    }
}

fn plural(n: usize, one: &str) -> String {
    if n == 1 {
        format!("1 {one}")
    } else {
        format!("{n} {one}s")
    }
}

fn box_lines(spec: &Spec, a: usize) -> Vec<String> {
    let agent = &spec.agents[a];
    let mut lines = vec![cut(&format!("agent {}", agent.name), MAX_CHARS)];
    let (ns, nd) = (agent.subsystems.len(), agent.devices.len());
    if ns + nd <= NAMES_UP_TO {
        if ns > 0 {
            let names: Vec<&str> = agent.subsystems.iter().map(|s| s.name.as_str()).collect();
            lines.push(cut(&names.join(", "), MAX_CHARS));
        }
        if nd > 0 {
            let names: Vec<&str> = agent.devices.iter().map(|d| d.name.as_str()).collect();
            lines.push(cut(&format!("devices: {}", names.join(", ")), MAX_CHARS));
        }
    } else {
        let mut line = plural(ns, "subsystem");
        if nd > 0 {
            let _ = write!(line, ", {}", plural(nd, "device"));
        }
        lines.push(line);
    }
    lines
}

fn model(spec: &Spec, agents: &[usize]) -> Model {
    // Which agent holds each component, and where each shown agent is listed.
    let mut holder: HashMap<&str, usize> = HashMap::new();
    for (i, a) in spec.agents.iter().enumerate() {
        for s in &a.subsystems {
            holder.entry(s.name.as_str()).or_insert(i);
        }
        for d in &a.devices {
            holder.entry(d.name.as_str()).or_insert(i);
        }
    }
    let mut listed = vec![None; spec.agents.len()];
    for (k, &a) in agents.iter().enumerate() {
        listed[a] = Some(k);
    }
    let agent_of = |end: &str| {
        end.split('.')
            .next()
            .and_then(|c| holder.get(c))
            .and_then(|&a| listed[a])
    };
    // The links between shown agents, per pair (listing positions).
    let mut pairs: Vec<Pair> = Vec::new();
    let mut pair_of: HashMap<(usize, usize), usize> = HashMap::new();
    let mut adjacent: Vec<Vec<usize>> = vec![Vec::new(); agents.len()];
    for l in &spec.links {
        let (Some(f), Some(t)) = (agent_of(&l.from), agent_of(&l.to)) else {
            continue;
        };
        if f == t {
            continue;
        }
        let name = l.from.rsplit('.').next().unwrap_or_default().to_owned();
        match pair_of.get(&(f.min(t), f.max(t))) {
            Some(&p) => {
                let p = &mut pairs[p];
                p.count += 1;
                p.both_ways |= p.from != f;
                if p.names.len() < 3 {
                    p.names.push(name);
                }
            }
            None => {
                pair_of.insert((f.min(t), f.max(t)), pairs.len());
                pairs.push(Pair {
                    from: f,
                    to: t,
                    count: 1,
                    both_ways: false,
                    names: vec![name],
                });
                adjacent[f].push(t);
                adjacent[t].push(f);
            }
        }
    }
    // Link order: depth first from each agent not yet reached, in listing order.
    let mut place = vec![usize::MAX; agents.len()];
    let mut order = Vec::with_capacity(agents.len());
    let mut stack = Vec::new();
    for start in 0..agents.len() {
        stack.push(start);
        while let Some(k) = stack.pop() {
            if place[k] != usize::MAX {
                continue;
            }
            place[k] = order.len();
            order.push(k);
            stack.extend(
                adjacent[k]
                    .iter()
                    .rev()
                    .filter(|&&n| place[n] == usize::MAX),
            );
        }
    }
    for p in &mut pairs {
        (p.from, p.to) = (place[p.from], place[p.to]);
    }
    let order: Vec<usize> = order.into_iter().map(|k| agents[k]).collect();
    let lines = order.iter().map(|&a| box_lines(spec, a)).collect();
    Model {
        order,
        lines,
        pairs,
    }
}

pub(crate) fn render(spec: &Spec, agents: &[usize], format: Format) -> String {
    let m = model(spec, agents);
    match format {
        Format::Dot => dot(spec, &m),
        Format::Mermaid => mermaid(spec, &m),
        Format::Svg => draw_model(spec, &m).0,
    }
}

/// The SVG of the overview of the agents (indices into `spec.agents`), and
/// what it placed.
pub(crate) fn draw(spec: &Spec, agents: &[usize]) -> (String, Scene) {
    draw_model(spec, &model(spec, agents))
}

fn dot(spec: &Spec, m: &Model) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "digraph \"{} overview\" {{", dot_esc(&spec.name));
    out.push_str("  fontname=\"monospace\";\n");
    out.push_str("  node [shape=box, fontname=\"monospace\"];\n  edge [fontname=\"monospace\"];\n");
    for (&a, lines) in m.order.iter().zip(&m.lines) {
        let label: String = lines.iter().map(|l| format!("{}\\l", dot_esc(l))).collect();
        let _ = writeln!(
            out,
            "  \"{}\" [label=\"{label}\"];",
            dot_esc(&spec.agents[a].name)
        );
    }
    for p in &m.pairs {
        let dir = if p.both_ways { ", dir=both" } else { "" };
        let _ = writeln!(
            out,
            "  \"{}\" -> \"{}\" [label=\"{}\"{dir}];",
            dot_esc(&spec.agents[m.order[p.from]].name),
            dot_esc(&spec.agents[m.order[p.to]].name),
            dot_esc(&p.label())
        );
    }
    out.push_str("}\n");
    out
}

fn mermaid(spec: &Spec, m: &Model) -> String {
    let mut out = String::from("flowchart LR\n");
    for (&a, lines) in m.order.iter().zip(&m.lines) {
        let label: Vec<String> = lines.iter().map(|l| mermaid_esc(l)).collect();
        let _ = writeln!(
            out,
            "    {}[\"{}\"]",
            mermaid_id("agent_", &spec.agents[a].name),
            label.join("<br/>")
        );
    }
    for p in &m.pairs {
        let arrow = if p.both_ways { "<-->" } else { "-->" };
        let _ = writeln!(
            out,
            "    {} {arrow}|\"{}\"| {}",
            mermaid_id("agent_", &spec.agents[m.order[p.from]].name),
            mermaid_esc(&p.label()),
            mermaid_id("agent_", &spec.agents[m.order[p.to]].name)
        );
    }
    out
}

/// Where the segment from the centre of a `w` × `h` box at `c` towards `d`
/// leaves the box.
fn border(c: Point, (w, h): (f64, f64), d: (f64, f64)) -> Point {
    let tx = if d.0 == 0.0 {
        f64::INFINITY
    } else {
        w / 2.0 / d.0.abs()
    };
    let ty = if d.1 == 0.0 {
        f64::INFINITY
    } else {
        h / 2.0 / d.1.abs()
    };
    let t = tx.min(ty).min(1.0);
    Point::new(c.x + t * d.0, c.y + t * d.1)
}

fn draw_model(spec: &Spec, m: &Model) -> (String, Scene) {
    let n = m.order.len();
    let cols = ((n as f64).sqrt().ceil() as usize).clamp(1, MAX_COLUMNS);
    let rows = n.div_ceil(cols).max(1);
    let mut boxes: Vec<Boxed> = m.lines.iter().map(|l| Boxed::new(l.clone())).collect();
    let box_w = boxes.iter().map(|b| b.w).fold(2.0 * PAD, f64::max);
    let box_h = boxes.iter().map(|b| b.h).fold(LINE_H + 2.0, f64::max);
    for (k, b) in boxes.iter_mut().enumerate() {
        let (row, i) = (k / cols, k % cols);
        let col = if row % 2 == 0 { i } else { cols - 1 - i };
        b.rounded = true;
        b.w = box_w;
        b.h = box_h;
        b.x = MARGIN + col as f64 * (box_w + COL_GAP);
        b.y = MARGIN + row as f64 * (box_h + ROW_GAP);
    }
    let mut width = 2.0 * MARGIN + cols as f64 * box_w + (cols - 1) as f64 * COL_GAP;
    let height = 2.0 * MARGIN + rows as f64 * box_h + (rows - 1) as f64 * ROW_GAP;
    let centre = |b: &Boxed| Point::new(b.x + b.w / 2.0, b.y + b.h / 2.0);
    let mut doc = Svg::new();
    // The edges first, under the boxes; the boxes' scene ids follow the order.
    let first_box = doc.next_box();
    for p in &m.pairs {
        let (ca, cb) = (centre(&boxes[p.from]), centre(&boxes[p.to]));
        let d = (cb.x - ca.x, cb.y - ca.y);
        let a = border(ca, (box_w, box_h), d);
        let b = border(cb, (box_w, box_h), (-d.0, -d.1));
        let path = Path {
            segments: vec![Segment::Line(a, b)],
        };
        let label = p.label();
        let mid = Point::new((a.x + b.x) / 2.0, (a.y + b.y) / 2.0);
        let at = if d.0.abs() >= d.1.abs() {
            LabelAt {
                x: mid.x - label_w(&label) / 2.0,
                y: mid.y - LABEL_H / 2.0 - 1.0,
            }
        } else {
            LabelAt {
                x: mid.x + 4.0,
                y: mid.y,
            }
        };
        width = width.max(at.right(&label) + MARGIN);
        doc.edge(
            &path,
            Some((label.as_str(), &at)),
            (Some(first_box + p.from), Some(first_box + p.to)),
            None,
        );
    }
    for b in &boxes {
        doc.boxed(b, None);
    }
    doc.finish(width, height, &format!("{} — overview", spec.name))
}

#[cfg(test)]
pub(super) mod tests {
    use super::*;
    use crate::model::Link;

    /// `n` copies of the spec's first agent, their components renamed with the
    /// copy's number, and a link from each copy's first subsystem to the next
    /// copy's: a ring.
    pub(crate) fn ring(n: usize) -> Spec {
        let Ok(loaded) = crate::load("tank.ron", include_str!("../../../specs/tank.ron")) else {
            panic!("tank.ron loads");
        };
        let base = loaded.spec;
        let mut spec = base.clone();
        spec.name = format!("ring{n}");
        spec.links.clear();
        spec.deployments.clear();
        spec.agents.clear();
        let template = &base.agents[0];
        for i in 0..n {
            let mut a = template.clone();
            a.name = format!("a{i}");
            for s in &mut a.subsystems {
                s.name = format!("{}{i}", s.name);
            }
            for d in &mut a.devices {
                d.name = format!("{}{i}", d.name);
            }
            spec.agents.push(a);
        }
        let first = &template.subsystems[0].name;
        for i in 0..n {
            spec.links.push(Link {
                from: format!("{first}{i}.out.t"),
                to: format!("{first}{}.in.t", (i + 1) % n),
                policy: Default::default(),
            });
        }
        spec
    }

    #[test]
    fn a_ring_of_500_agents_is_bounded() {
        let spec = ring(500);
        let all: Vec<usize> = (0..500).collect();
        let started = std::time::Instant::now();
        let (svg, scene) = draw(&spec, &all);
        let took = started.elapsed();
        assert!(took.as_secs_f64() < 5.0, "took {took:?}");
        assert_eq!(scene.boxes.len(), 500);
        assert_eq!(scene.edges.len(), 500, "one edge per neighbouring pair");
        // 23 columns and 22 rows of boxes.
        assert!(scene.width < 8_000.0, "width {}", scene.width);
        assert!(scene.height < 3_000.0, "height {}", scene.height);
        assert!(svg.contains(&format!(r#"width="{:.1}""#, scene.width)));
        for i in 0..500 {
            let title = format!(">agent a{i}<");
            assert_eq!(svg.matches(&title).count(), 1, "{title}");
        }
        // Ring neighbours are grid neighbours: every edge but the closing one
        // is short.
        let long = scene
            .edges
            .iter()
            .filter(|e| match e.path.segments[0] {
                Segment::Line(a, b) => (a.x - b.x).abs() + (a.y - b.y).abs() > COL_GAP + ROW_GAP,
                _ => true,
            })
            .count();
        assert_eq!(long, 1);
    }

    #[test]
    fn links_between_two_agents_are_one_edge_with_their_count() {
        let mut spec = ring(3);
        let first = spec.agents[0].subsystems[0].name.clone();
        let second = spec.agents[1].subsystems[0].name.clone();
        for k in 0..3 {
            spec.links.push(Link {
                from: format!("{first}.out.b{k}"),
                to: format!("{second}.in.b{k}"),
                policy: Default::default(),
            });
        }
        spec.links.push(Link {
            from: format!("{second}.out.back"),
            to: format!("{first}.in.back"),
            policy: Default::default(),
        });
        let (svg, scene) = draw(&spec, &[0, 1, 2]);
        assert_eq!(scene.boxes.len(), 3);
        assert_eq!(scene.edges.len(), 3);
        assert!(svg.contains(">5 links ⇄<"), "{svg}");
        assert!(svg.contains(">t<"), "a single link shows its buffer: {svg}");
        let dot = render(&spec, &[0, 1, 2], Format::Dot);
        assert!(dot.contains("[label=\"5 links ⇄\", dir=both]"), "{dot}");
        let mermaid = render(&spec, &[0, 1, 2], Format::Mermaid);
        assert_eq!(mermaid.matches("-->").count(), 3, "{mermaid}");
    }
}
