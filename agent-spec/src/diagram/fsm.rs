//! The FSM of a subsystem (Fig. 5).

use std::collections::VecDeque;
use std::fmt::Write as _;

use super::geometry::{Path, Point, Scene};
use super::svg::{Boxed, LINE_H, MARGIN, PAD, Svg, layered, route};
use super::{Format, dot_esc, mermaid_esc, mermaid_id};
use crate::model::{BehaviourKind, Spec, Subsystem, SubsystemKind};

/// The FSM as a graph: nodes are behaviour indices.
struct View<'a> {
    sub: &'a Subsystem,
    arcs: Vec<(usize, usize, &'a str)>,
    initial: Option<usize>,
    finals: Vec<bool>,
}

impl<'a> View<'a> {
    fn new(sub: &'a Subsystem) -> Self {
        let find = |n: &str| sub.behaviours.iter().position(|b| b.name == n);
        let arcs = sub
            .fsm
            .arcs
            .iter()
            .filter_map(|a| Some((find(&a.from)?, find(&a.to)?, a.when.as_str())))
            .collect();
        let mut finals = vec![false; sub.behaviours.len()];
        for f in &sub.fsm.finals {
            if let Some(i) = find(f) {
                finals[i] = true;
            }
        }
        View {
            sub,
            arcs,
            initial: sub.fsm.initial.as_deref().and_then(find),
            finals,
        }
    }

    fn node_text(&self, i: usize) -> (String, String) {
        let b = &self.sub.behaviours[i];
        let detail = match (b.kind, b.terminal.trim()) {
            (BehaviourKind::Repeat, "false") => "repeat forever".to_owned(),
            (BehaviourKind::While, "false") => "while: forever".to_owned(),
            // Ends before its first action: the FSM passes through it.
            (BehaviourKind::While, "true") => "while: never".to_owned(),
            (BehaviourKind::Repeat, t) => format!("repeat until {t}"),
            // Algorithm 2 runs while the terminal condition does not hold.
            (BehaviourKind::While, t) => match agent_core::Expr::parse(t) {
                Ok(e) => format!("while {}", e.negated()),
                Err(_) => format!("while !({t})"),
            },
        };
        (b.name.clone(), detail)
    }

    /// Layers by breadth-first distance from the initial behaviour; behaviours not
    /// reached go in a last layer.
    fn layers(&self) -> Vec<Vec<usize>> {
        let n = self.sub.behaviours.len();
        let mut depth = vec![usize::MAX; n];
        let mut queue = VecDeque::new();
        if let Some(s) = self.initial {
            depth[s] = 0;
            queue.push_back(s);
        }
        while let Some(i) = queue.pop_front() {
            for &(a, b, _) in &self.arcs {
                if a == i && depth[b] == usize::MAX {
                    depth[b] = depth[i] + 1;
                    queue.push_back(b);
                }
            }
        }
        let max = depth
            .iter()
            .filter(|d| **d != usize::MAX)
            .max()
            .map_or(0, |m| m + 1);
        let mut layers = vec![Vec::new(); max + 1];
        for (i, d) in depth.iter().enumerate() {
            layers[if *d == usize::MAX { max } else { *d }].push(i);
        }
        layers.retain(|l| !l.is_empty());
        layers
    }
}

fn kind_name(k: SubsystemKind) -> &'static str {
    match k {
        SubsystemKind::Control => "control subsystem",
        SubsystemKind::VirtualEffector => "virtual effector",
        SubsystemKind::VirtualReceptor => "virtual receptor",
    }
}

pub(crate) fn render(spec: &Spec, subs: &[&Subsystem], format: Format) -> String {
    let views: Vec<View<'_>> = subs.iter().map(|s| View::new(s)).collect();
    match format {
        Format::Dot => dot(spec, &views),
        Format::Mermaid => mermaid(&views),
        Format::Svg => draw(spec, subs).0,
    }
}

fn dot(spec: &Spec, views: &[View<'_>]) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "digraph \"{} FSM\" {{", dot_esc(&spec.name));
    out.push_str("  rankdir=TB;\n  fontname=\"monospace\";\n");
    out.push_str("  node [shape=box, style=rounded, fontname=\"monospace\"];\n");
    out.push_str("  edge [fontname=\"monospace\"];\n");
    for v in views {
        let s = &v.sub.name;
        let _ = writeln!(out, "  subgraph \"cluster_{}\" {{", dot_esc(s));
        let _ = writeln!(
            out,
            "    label=\"{} ({})\";",
            dot_esc(s),
            kind_name(v.sub.kind)
        );
        if let Some(i) = v.initial {
            let _ = writeln!(
                out,
                "    \"{0}/__start\" [shape=point, label=\"\"];",
                dot_esc(s)
            );
            let _ = writeln!(
                out,
                "    \"{0}/__start\" -> \"{0}/{1}\";",
                dot_esc(s),
                dot_esc(&v.sub.behaviours[i].name)
            );
        }
        for i in 0..v.sub.behaviours.len() {
            let (name, detail) = v.node_text(i);
            let periph = if v.finals[i] { ", peripheries=2" } else { "" };
            let _ = writeln!(
                out,
                "    \"{}/{}\" [label=\"{}\\n{}\"{periph}];",
                dot_esc(s),
                dot_esc(&name),
                dot_esc(&name),
                dot_esc(&detail)
            );
        }
        for &(a, b, when) in &v.arcs {
            let _ = writeln!(
                out,
                "    \"{0}/{1}\" -> \"{0}/{2}\" [label=\"{3}\"];",
                dot_esc(s),
                dot_esc(&v.sub.behaviours[a].name),
                dot_esc(&v.sub.behaviours[b].name),
                dot_esc(when)
            );
        }
        out.push_str("  }\n");
    }
    out.push_str("}\n");
    out
}

fn mermaid(views: &[View<'_>]) -> String {
    let mut out = String::from("stateDiagram-v2\n");
    let nested = views.len() > 1;
    for v in views {
        let indent = if nested { "        " } else { "    " };
        let prefix = if nested {
            format!("{}_", v.sub.name)
        } else {
            String::new()
        };
        if nested {
            let _ = writeln!(out, "    state {} {{", mermaid_id("", &v.sub.name));
        }
        if let Some(i) = v.initial {
            let _ = writeln!(
                out,
                "{indent}[*] --> {}",
                mermaid_id(&prefix, &v.sub.behaviours[i].name)
            );
        }
        for i in 0..v.sub.behaviours.len() {
            let (name, detail) = v.node_text(i);
            let _ = writeln!(
                out,
                "{indent}{} : {} — {}",
                mermaid_id(&prefix, &name),
                mermaid_esc(&name),
                mermaid_esc(&detail)
            );
        }
        for &(a, b, when) in &v.arcs {
            let _ = writeln!(
                out,
                "{indent}{} --> {} : {}",
                mermaid_id(&prefix, &v.sub.behaviours[a].name),
                mermaid_id(&prefix, &v.sub.behaviours[b].name),
                mermaid_esc(when)
            );
        }
        for (i, f) in v.finals.iter().enumerate() {
            if *f {
                let _ = writeln!(
                    out,
                    "{indent}{} --> [*]",
                    mermaid_id(&prefix, &v.sub.behaviours[i].name)
                );
            }
        }
        if nested {
            out.push_str("    }\n");
        }
    }
    out
}

/// The SVG, and what it placed.
pub(crate) fn draw(spec: &Spec, subs: &[&Subsystem]) -> (String, Scene) {
    let views: Vec<View<'_>> = subs.iter().map(|s| View::new(s)).collect();
    let mut doc = Svg::new();
    let mut y = MARGIN;
    let mut width: f64 = 0.0;
    for v in views {
        let top = y + LINE_H + PAD + 24.0; // room for the frame title and the start dot
        let boxes: Vec<Boxed> = (0..v.sub.behaviours.len())
            .map(|i| {
                let (name, detail) = v.node_text(i);
                let mut b = Boxed::new(vec![name, detail]);
                b.double = v.finals[i];
                b
            })
            .collect();
        let edges: Vec<(usize, usize)> = v.arcs.iter().map(|&(a, b, _)| (a, b)).collect();
        let lay = layered(boxes, v.layers(), &edges, MARGIN + PAD, top);
        let right = lay.boxes.iter().map(|b| b.x + b.w).fold(MARGIN, f64::max);
        let mut extent: f64 = right;
        let mut routes = Vec::new();
        for (k, &(a, b, when)) in v.arcs.iter().enumerate() {
            let parallel = v.arcs[..k]
                .iter()
                .filter(|x| x.0 == a && x.1 == b || x.0 == b && x.1 == a)
                .count();
            let up = lay.boxes[b].y <= lay.boxes[a].y + lay.boxes[a].h;
            let lane_k = if up || a == b {
                v.arcs[..k]
                    .iter()
                    .filter(|&&(x, y, _)| lay.boxes[y].y <= lay.boxes[x].y + lay.boxes[x].h)
                    .count()
            } else {
                parallel
            };
            let (d, at) = route(&lay.boxes[a], &lay.boxes[b], lane_k.max(parallel), right);
            extent = extent
                .max(at.right(when))
                .max(right + 30.0 + 12.0 * lane_k as f64);
            routes.push((d, at, when));
        }
        let frame_h = lay.height + (top - y) + PAD + MARGIN / 2.0;
        let frame_w = extent - MARGIN + PAD;
        let f = doc.frame(
            MARGIN,
            y,
            frame_w,
            frame_h,
            &format!("{} — FSM of the {}", v.sub.name, kind_name(v.sub.kind)),
        );
        let first = doc.next_box();
        if let Some(i) = v.initial {
            let b = &lay.boxes[i];
            doc.dot(b.cx(), b.y - 20.0, 5.0);
            doc.edge(
                &Path::line(Point::new(b.cx(), b.y - 15.0), Point::new(b.cx(), b.y)),
                None,
                (None, Some(first + i)),
                Some(f),
            );
        }
        for b in &lay.boxes {
            doc.boxed(b, Some(f));
        }
        for ((d, at, when), &(a, b, _)) in routes.iter().zip(&v.arcs) {
            doc.edge(
                d,
                Some((when, at)),
                (Some(first + a), Some(first + b)),
                Some(f),
            );
        }
        width = width.max(frame_w + 2.0 * MARGIN);
        y += frame_h + MARGIN;
    }
    doc.finish(width.max(200.0), y, &format!("{} — FSM", spec.name))
}
