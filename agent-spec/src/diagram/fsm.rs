//! The FSM of a subsystem (Fig. 5).

use std::fmt::Write as _;

use super::geometry::{Path, Point, Scene};
use super::layout::{Graph, SlotKind, Spacing, ranks_between};
use super::svg::{Boxed, LABEL_H, LINE_H, LabelAt, MARGIN, PAD, Svg, label_w};
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

/// Self-loops are drawn as small loops on the right side of their box, one under
/// the other, each with its label to its right.
const EAR_TOP: f64 = 5.0;
/// Vertical distance between two self-loops of a box.
const EAR_PITCH: f64 = 18.0;
/// Height of a self-loop.
const EAR_H: f64 = 12.0;
/// How far right of its box a self-loop's label starts.
const EAR_LABEL: f64 = 19.0;

/// The layers of the FSM as a layered drawing: arcs that close a cycle (found by a
/// depth-first search from the initial behaviour, arcs in declaration order) point
/// up, every other arc points down, and each behaviour is one layer below the
/// lowest behaviour with an arc down to it.
fn layers(v: &View<'_>) -> Vec<usize> {
    let n = v.sub.behaviours.len();
    // 0: not seen, 1: on the stack, 2: done
    let mut state = vec![0u8; n];
    let mut back = vec![false; v.arcs.len()];
    let roots: Vec<usize> = v.initial.into_iter().chain(0..n).collect();
    for root in roots {
        if state[root] != 0 {
            continue;
        }
        // Iterative DFS: (node, next arc index to look at).
        let mut stack = vec![(root, 0usize)];
        state[root] = 1;
        while let Some(&mut (i, ref mut k)) = stack.last_mut() {
            if *k >= v.arcs.len() {
                state[i] = 2;
                stack.pop();
                continue;
            }
            let arc = *k;
            *k += 1;
            let (a, b, _) = v.arcs[arc];
            if a != i || a == b {
                continue;
            }
            match state[b] {
                0 => {
                    state[b] = 1;
                    stack.push((b, 0));
                }
                1 => back[arc] = true,
                _ => {}
            }
        }
    }
    // Arcs into the initial behaviour point up too: it heads the drawing, under its
    // start dot. (No cycle remains: nothing points down into it.)
    for (k, &(a, b, _)) in v.arcs.iter().enumerate() {
        if Some(b) == v.initial && a != b {
            back[k] = true;
        }
    }
    // Longest path over the arcs that point down (a DAG).
    let mut layer = vec![0usize; n];
    for _ in 0..n {
        let mut changed = false;
        for (k, &(a, b, _)) in v.arcs.iter().enumerate() {
            if a == b {
                continue;
            }
            let (u, w) = if back[k] { (b, a) } else { (a, b) };
            if layer[w] < layer[u] + 1 {
                layer[w] = layer[u] + 1;
                changed = true;
            }
        }
        if !changed {
            break;
        }
    }
    layer
}

/// The SVG, and what it placed.
pub(crate) fn draw(spec: &Spec, subs: &[&Subsystem]) -> (String, Scene) {
    let views: Vec<View<'_>> = subs.iter().map(|s| View::new(s)).collect();
    let mut doc = Svg::new();
    let mut y = MARGIN;
    let mut width: f64 = 0.0;
    for v in &views {
        let (frame_w, frame_h) = draw_view(&mut doc, v, y);
        width = width.max(frame_w + 2.0 * MARGIN);
        y += frame_h + MARGIN;
    }
    doc.finish(width.max(200.0), y, &format!("{} — FSM", spec.name))
}

/// One subsystem's FSM in a frame whose top is at `y`: laid out, then drawn;
/// the frame's width and height.
fn draw_view(doc: &mut Svg, v: &View<'_>, y: f64) -> (f64, f64) {
    let spacing = Spacing {
        node_gap: 40.0,
        gap: 10.0,
        group_gap: 40.0,
        rank_gap: 24.0,
    };
    let title = format!("{} — FSM of the {}", v.sub.name, kind_name(v.sub.kind));
    // Room for the title, then for the start dot.
    let top = y + LINE_H + 3.0 + 30.0;
    let layer = layers(v);
    let mut g = Graph::default();
    let (mut boxes, slot_of) = behaviour_slots(&mut g, v, &layer);
    let chain_of = arc_chains(&mut g, v, &layer, &slot_of);
    g.place(MARGIN + PAD, top, spacing);
    g.put(&mut boxes, &slot_of);
    let (f, frame_w, frame_h) = doc.frame_around((y, top), (g.right(), g.bottom()), &title);
    let first = doc.next_box();
    if let Some(i) = v.initial {
        let b = &boxes[i];
        doc.dot(b.cx(), b.y - 20.0, 5.0);
        doc.edge(
            &Path::line(Point::new(b.cx(), b.y - 15.0), Point::new(b.cx(), b.y)),
            None,
            (None, Some(first + i)),
            Some(f),
        );
    }
    for b in &boxes {
        doc.boxed(b, Some(f));
    }
    draw_arcs(doc, v, &g, &boxes, &chain_of, (first, f));
    (frame_w, frame_h)
}

/// Each behaviour's box (double for a final one, taller and wider for its
/// self-loops' ears) and its slot in the layout, on the even rank of its layer.
fn behaviour_slots(g: &mut Graph, v: &View<'_>, layer: &[usize]) -> (Vec<Boxed>, Vec<usize>) {
    let n = v.sub.behaviours.len();
    let mut boxes = Vec::with_capacity(n);
    let mut slot_of = Vec::with_capacity(n);
    for i in 0..n {
        let (name, detail) = v.node_text(i);
        let mut b = Boxed::new(vec![name, detail]);
        b.double = v.finals[i];
        let loops: Vec<&str> = v
            .arcs
            .iter()
            .filter(|&&(a, c, _)| a == i && c == i)
            .map(|a| a.2)
            .collect();
        let mut extra = 0.0;
        if !loops.is_empty() {
            b.h = b.h.max(EAR_TOP + EAR_PITCH * loops.len() as f64 + 2.0);
            extra = EAR_LABEL + loops.iter().map(|w| label_w(w)).fold(0.0, f64::max) + 2.0;
        }
        slot_of.push(g.slot(SlotKind::Node, 2 * layer[i], 0, (b.w + extra, b.h), b.w));
        boxes.push(b);
    }
    (boxes, slot_of)
}

/// Each arc between two behaviours as a chain of slots through the ranks
/// between them, its label in the odd rank nearest the middle; `None` for a
/// self-loop.
fn arc_chains(
    g: &mut Graph,
    v: &View<'_>,
    layer: &[usize],
    slot_of: &[usize],
) -> Vec<Option<usize>> {
    let mut chain_of = vec![None; v.arcs.len()];
    for (k, &(a, b, when)) in v.arcs.iter().enumerate() {
        if a == b {
            continue;
        }
        // The label goes in the odd rank nearest the middle.
        let (between, label_rank) = ranks_between(2 * layer[a], 2 * layer[b], 1);
        let mut slots = vec![slot_of[a]];
        for r in between {
            slots.push(if Some(r) == label_rank && !when.is_empty() {
                let w = label_w(when);
                g.slot(SlotKind::Label, r, 0, (w + 2.0, LABEL_H), w)
            } else {
                g.slot(SlotKind::Dummy, r, 0, (0.0, 0.0), 0.0)
            });
        }
        slots.push(slot_of[b]);
        chain_of[k] = Some(g.chain(slots, None));
    }
    chain_of
}

/// The arcs, each with its condition: routed along its chain, or a self-loop
/// as an ear on its box's right side. `first` is the document's index of the
/// first box, `frame` the frame's.
fn draw_arcs(
    doc: &mut Svg,
    v: &View<'_>,
    g: &Graph,
    boxes: &[Boxed],
    chain_of: &[Option<usize>],
    (first, frame): (usize, usize),
) {
    let mut ears = vec![0usize; v.sub.behaviours.len()];
    for (k, &(a, b, when)) in v.arcs.iter().enumerate() {
        let ends = (Some(first + a), Some(first + b));
        match chain_of[k] {
            Some(c) => {
                let at = g.label_at(c);
                let path = g.route(c, None);
                doc.edge(&path, at.as_ref().map(|at| (when, at)), ends, Some(frame));
            }
            None => {
                // A self-loop.
                let bx = &boxes[a];
                let (x, y0) = (bx.x + bx.w, bx.y + EAR_TOP + EAR_PITCH * ears[a] as f64);
                ears[a] += 1;
                let p = Point::new;
                let path = Path::cubic(
                    p(x, y0),
                    p(x + 22.0, y0 - 2.0),
                    p(x + 22.0, y0 + EAR_H + 2.0),
                    p(x, y0 + EAR_H),
                );
                let at = LabelAt {
                    x: x + EAR_LABEL,
                    y: y0 + EAR_H / 2.0,
                };
                doc.edge(&path, Some((when, &at)), ends, Some(frame));
            }
        }
    }
}
