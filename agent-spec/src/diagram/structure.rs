//! Agents, components with their buffers, and links (Figs. 2 and 4).

use std::fmt::Write as _;

use super::geometry::{Path, Point, Scene};
use super::svg::{Align, Boxed, LINE_H, LabelAt, MARGIN, PAD, Svg, text_w};
use super::{Format, dot_esc, mermaid_esc, mermaid_id};
use crate::model::{Agent, DeviceKind, Group, Policy, Spec, SubsystemKind};

/// One component as drawn.
struct Comp<'a> {
    agent: usize,
    name: &'a str,
    /// 0: control, 1: virtual effectors and receptors, 2: devices.
    row: usize,
    lines: Vec<String>,
}

fn group_lines(arrow: &str, groups: &[Group]) -> Vec<String> {
    groups
        .iter()
        .map(|g| {
            let names: Vec<&str> = g.buffers.iter().map(|b| b.name.as_str()).collect();
            format!("{arrow} {}: {}", g.peer, names.join(", "))
        })
        .collect()
}

fn components<'a>(spec: &'a Spec, agents: &[usize]) -> Vec<Comp<'a>> {
    let mut out = Vec::new();
    for &a in agents {
        let agent: &Agent = &spec.agents[a];
        for s in &agent.subsystems {
            let (kind, row) = match s.kind {
                SubsystemKind::Control => ("control subsystem", 0),
                SubsystemKind::VirtualEffector => ("virtual effector", 1),
                SubsystemKind::VirtualReceptor => ("virtual receptor", 1),
            };
            let mut lines = vec![format!("{} · {kind} · {} ms", s.name, s.period_ms)];
            if !s.memory.is_empty() {
                let names: Vec<&str> = s.memory.iter().map(|b| b.name.as_str()).collect();
                lines.push(format!("memory: {}", names.join(", ")));
            }
            lines.extend(group_lines("in from", &s.inputs));
            lines.extend(group_lines("out to", &s.outputs));
            out.push(Comp {
                agent: a,
                name: &s.name,
                row,
                lines,
            });
        }
        for d in &agent.devices {
            let kind = match d.kind {
                DeviceKind::Effector => "real effector",
                DeviceKind::Receptor => "real receptor",
            };
            let mut lines = vec![format!("{} · {kind} · {} ms", d.name, d.period_ms)];
            lines.extend(group_lines("in from", &d.inputs));
            lines.extend(group_lines("out to", &d.outputs));
            out.push(Comp {
                agent: a,
                name: &d.name,
                row: 2,
                lines,
            });
        }
    }
    out
}

/// Links aggregated per ordered pair of components: (from, to, buffer names, each
/// with its policy if it is a queue).
fn bundles(spec: &Spec, comps: &[Comp<'_>]) -> Vec<(usize, usize, String)> {
    let mut out: Vec<(usize, usize, Vec<String>)> = Vec::new();
    for l in &spec.links {
        let (Some(f), Some(t)) = (l.from.split('.').next(), l.to.split('.').next()) else {
            continue;
        };
        let (Some(fi), Some(ti)) = (
            comps.iter().position(|c| c.name == f),
            comps.iter().position(|c| c.name == t),
        ) else {
            continue;
        };
        // A sample link (the default) shows the buffer; a queue also its bound.
        let name = l.from.rsplit('.').next().unwrap_or_default();
        let buffer = match l.policy {
            Policy::Sample => name.to_owned(),
            Policy::Queue { bound } => format!("{name} (queue {bound})"),
        };
        match out.iter_mut().find(|(a, b, _)| *a == fi && *b == ti) {
            Some((_, _, names)) => names.push(buffer),
            None => out.push((fi, ti, vec![buffer])),
        }
    }
    out.into_iter()
        .map(|(a, b, names)| (a, b, names.join(", ")))
        .collect()
}

/// Agents ordered for drawing: the most connected in the middle, the others
/// alternately to its left and right, so links between agents stay short.
fn arrange(spec: &Spec, agents: &[usize]) -> Vec<usize> {
    let agent_of = |comp: &str| {
        spec.agents.iter().position(|a| {
            a.subsystems.iter().any(|s| s.name == comp) || a.devices.iter().any(|d| d.name == comp)
        })
    };
    let mut degree = vec![0usize; spec.agents.len()];
    for l in &spec.links {
        let f = l.from.split('.').next().and_then(agent_of);
        let t = l.to.split('.').next().and_then(agent_of);
        if let (Some(f), Some(t)) = (f, t)
            && f != t
        {
            degree[f] += 1;
            degree[t] += 1;
        }
    }
    let mut by_degree = agents.to_vec();
    by_degree.sort_by(|a, b| degree[*b].cmp(&degree[*a]).then(a.cmp(b)));
    let mut out = std::collections::VecDeque::new();
    for (k, a) in by_degree.into_iter().enumerate() {
        if k % 2 == 1 {
            out.push_front(a);
        } else {
            out.push_back(a);
        }
    }
    out.into_iter().collect()
}

pub(crate) fn render(spec: &Spec, agents: &[usize], format: Format) -> String {
    let agents = &arrange(spec, agents)[..];
    let comps = components(spec, agents);
    let links = bundles(spec, &comps);
    match format {
        Format::Dot => dot(spec, agents, &comps, &links),
        Format::Mermaid => mermaid(spec, agents, &comps, &links),
        Format::Svg => draw(spec, agents, &comps, &links).0,
    }
}

fn dot(
    spec: &Spec,
    agents: &[usize],
    comps: &[Comp<'_>],
    links: &[(usize, usize, String)],
) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "digraph \"{} structure\" {{", dot_esc(&spec.name));
    out.push_str("  rankdir=TB;\n  compound=true;\n  fontname=\"monospace\";\n");
    out.push_str("  node [shape=box, fontname=\"monospace\"];\n  edge [fontname=\"monospace\"];\n");
    for &a in agents {
        let agent = &spec.agents[a];
        let _ = writeln!(out, "  subgraph \"cluster_{}\" {{", dot_esc(&agent.name));
        let _ = writeln!(out, "    label=\"agent {}\";", dot_esc(&agent.name));
        for c in comps.iter().filter(|c| c.agent == a) {
            let label: String = c
                .lines
                .iter()
                .map(|l| format!("{}\\l", dot_esc(l)))
                .collect();
            let _ = writeln!(out, "    \"{}\" [label=\"{label}\"];", dot_esc(c.name));
        }
        out.push_str("  }\n");
    }
    for (a, b, label) in links {
        let _ = writeln!(
            out,
            "  \"{}\" -> \"{}\" [label=\"{}\"];",
            dot_esc(comps[*a].name),
            dot_esc(comps[*b].name),
            dot_esc(label)
        );
    }
    out.push_str("}\n");
    out
}

fn mermaid(
    spec: &Spec,
    agents: &[usize],
    comps: &[Comp<'_>],
    links: &[(usize, usize, String)],
) -> String {
    let mut out = String::from("flowchart TB\n");
    for &a in agents {
        let agent = &spec.agents[a];
        let _ = writeln!(
            out,
            "    subgraph {}[\"agent {}\"]",
            mermaid_id("agent_", &agent.name),
            mermaid_esc(&agent.name)
        );
        for c in comps.iter().filter(|c| c.agent == a) {
            let label: Vec<String> = c.lines.iter().map(|l| mermaid_esc(l)).collect();
            let _ = writeln!(
                out,
                "        {}[\"{}\"]",
                mermaid_id("n_", c.name),
                label.join("<br/>")
            );
        }
        out.push_str("    end\n");
    }
    for (a, b, label) in links {
        let _ = writeln!(
            out,
            "    {} -->|\"{}\"| {}",
            mermaid_id("n_", comps[*a].name),
            mermaid_esc(label),
            mermaid_id("n_", comps[*b].name)
        );
    }
    out
}

/// Anchor points and label position of a link between two boxes; `side` separates
/// the two directions of a pair.
fn connect(a: &Boxed, b: &Boxed, side: f64) -> (Path, LabelAt) {
    let p = Point::new;
    let (dx, dy) = (b.cx() - a.cx(), b.cy() - a.cy());
    let vertical =
        dy.abs() > 1.0 && (dy.abs() - (a.h + b.h) / 2.0) > (dx.abs() - (a.w + b.w) / 2.0);
    let (x1, y1, x2, y2) = if vertical {
        let (y1, y2) = if dy > 0.0 {
            (a.y + a.h, b.y)
        } else {
            (a.y, b.y + b.h)
        };
        (a.cx() + side, y1, b.cx() + side, y2)
    } else {
        let (x1, x2) = if dx > 0.0 {
            (a.x + a.w, b.x)
        } else {
            (a.x, b.x + b.w)
        };
        (x1, a.cy() + side, x2, b.cy() + side)
    };
    let d = if vertical {
        let my = (y1 + y2) / 2.0;
        Path::cubic(p(x1, y1), p(x1, my), p(x2, my), p(x2, y2))
    } else {
        let mx = (x1 + x2) / 2.0;
        Path::cubic(p(x1, y1), p(mx, y1), p(mx, y2), p(x2, y2))
    };
    let align = match (vertical, side) {
        (true, s) if s > 0.0 => Align::Start,
        (true, s) if s < 0.0 => Align::End,
        _ => Align::Middle,
    };
    let at = LabelAt {
        x: (x1 + x2) / 2.0 + if vertical { side * 0.5 } else { 0.0 },
        y: (y1 + y2) / 2.0 + if vertical { 0.0 } else { side * 1.4 },
        align,
    };
    (d, at)
}

/// The SVG of the agents (indices into `spec.agents`), and what it placed.
pub(crate) fn draw_agents(spec: &Spec, agents: &[usize]) -> (String, Scene) {
    let agents = &arrange(spec, agents)[..];
    let comps = components(spec, agents);
    let links = bundles(spec, &comps);
    draw(spec, agents, &comps, &links)
}

fn draw(
    spec: &Spec,
    agents: &[usize],
    comps: &[Comp<'_>],
    links: &[(usize, usize, String)],
) -> (String, Scene) {
    const ROW_GAP: f64 = 90.0;
    const COL_GAP: f64 = 60.0;
    const AGENT_GAP: f64 = 120.0;
    let mut boxes: Vec<Boxed> = comps
        .iter()
        .map(|c| {
            let mut b = Boxed::new(c.lines.clone());
            b.rounded = c.row < 2;
            b
        })
        .collect();
    let mut doc = Svg::new();
    let mut x = MARGIN;
    let mut frames = Vec::new();
    let mut height: f64 = 0.0;
    for &a in agents {
        let members: Vec<usize> = (0..comps.len()).filter(|&i| comps[i].agent == a).collect();
        let rows: Vec<Vec<usize>> = (0..3)
            .map(|r| {
                members
                    .iter()
                    .copied()
                    .filter(|&i| comps[i].row == r)
                    .collect()
            })
            .collect();
        let row_w: Vec<f64> = rows
            .iter()
            .map(|r| {
                r.iter().map(|&i| boxes[i].w).sum::<f64>()
                    + COL_GAP * r.len().saturating_sub(1) as f64
            })
            .collect();
        let title_w = text_w(&format!("agent {}", spec.agents[a].name)) + 2.0 * PAD;
        let inner_w = row_w.iter().copied().fold(title_w, f64::max);
        let mut y = MARGIN + LINE_H + 2.0 * PAD;
        for (r, row) in rows.iter().enumerate() {
            if row.is_empty() {
                continue;
            }
            let h = row.iter().map(|&i| boxes[i].h).fold(0.0, f64::max);
            let mut bx = x + PAD + (inner_w - row_w[r]) / 2.0;
            for &i in row {
                boxes[i].x = bx;
                boxes[i].y = y;
                bx += boxes[i].w + COL_GAP;
            }
            y += h + ROW_GAP;
        }
        let frame_h = y - ROW_GAP + PAD - MARGIN;
        frames.push((
            x,
            inner_w + 2.0 * PAD,
            frame_h,
            format!("agent {}", spec.agents[a].name),
        ));
        height = height.max(frame_h);
        x += inner_w + 2.0 * PAD + AGENT_GAP;
    }
    let frame_ids: Vec<usize> = frames
        .iter()
        .map(|(fx, fw, fh, title)| doc.frame(*fx, MARGIN, *fw, height.max(*fh), title))
        .collect();
    let ids: Vec<usize> = boxes
        .iter()
        .zip(comps)
        .map(|(b, c)| {
            let f = agents
                .iter()
                .position(|&a| a == c.agent)
                .map(|k| frame_ids[k]);
            doc.boxed(b, f)
        })
        .collect();
    let mut extent = x - AGENT_GAP;
    for (a, b, label) in links {
        let reverse = links.iter().any(|(p, q, _)| p == b && q == a);
        let side = if !reverse {
            0.0
        } else if a < b {
            -9.0
        } else {
            9.0
        };
        let (d, at) = connect(&boxes[*a], &boxes[*b], side);
        extent = extent.max(at.right(label));
        doc.edge(&d, Some((label, &at)), (Some(ids[*a]), Some(ids[*b])), None);
    }
    doc.finish(
        extent + MARGIN,
        height + 2.0 * MARGIN,
        &format!("{} — structure", spec.name),
    )
}
