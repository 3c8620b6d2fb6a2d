//! What the transition functions of each behaviour read and write (Figs. 6-8).

use std::fmt::Write as _;

use super::geometry::Scene;
use super::layout::{Graph, SlotKind, Spacing};
use super::svg::{Boxed, LINE_H, MARGIN, PAD, Svg};
use super::{Format, dot_esc, mermaid_esc, mermaid_id};
use crate::model::{Behaviour, Spec, Subsystem, Target};

/// A buffer node of a behaviour's data flow.
#[derive(Clone, Debug, PartialEq, Eq)]
enum Buf {
    /// `^c c^ι` read, or `^c c^ι+1` written.
    Memory(String, bool),
    /// An input `group.name`.
    Input(String),
    /// An output `group.name`.
    Output(String),
}

impl Buf {
    fn label(&self, sub: &str) -> String {
        match self {
            Buf::Memory(n, false) => format!("{sub}.{n} (ι)"),
            Buf::Memory(n, true) => format!("{sub}.{n} (ι+1)"),
            Buf::Input(n) => format!("in {n}"),
            Buf::Output(n) => format!("out {n}"),
        }
    }

    fn id(&self) -> String {
        match self {
            Buf::Memory(n, false) => format!("m_{n}"),
            Buf::Memory(n, true) => format!("m_{n}_next"),
            Buf::Input(n) => format!("i_{n}"),
            Buf::Output(n) => format!("o_{n}"),
        }
    }
}

/// The data flow of one behaviour: buffers read, functions, buffers written.
struct Flow<'a> {
    behaviour: &'a Behaviour,
    reads: Vec<Buf>,
    functions: Vec<&'a str>,
    writes: Vec<Buf>,
    /// (buffer index in `reads`, function index)
    read_edges: Vec<(usize, usize)>,
    /// (function index, buffer index in `writes`)
    write_edges: Vec<(usize, usize)>,
}

/// Resolve a read the way the checker does: memory first, then a unique input.
fn read_buf(sub: &Subsystem, r: &str) -> Buf {
    if r.contains('.') {
        return Buf::Input(r.to_owned());
    }
    if sub.memory.iter().any(|b| b.name == r) {
        return Buf::Memory(r.to_owned(), false);
    }
    match sub
        .inputs
        .iter()
        .find(|g| g.buffers.iter().any(|b| b.name == r))
    {
        Some(g) => Buf::Input(format!("{}.{r}", g.peer)),
        None => Buf::Input(r.to_owned()),
    }
}

fn write_buf(target: &Target, w: &str) -> Buf {
    match target {
        Target::Memory | Target::Common => Buf::Memory(w.to_owned(), true),
        Target::Output(peer) => match w.split_once('.') {
            Some(_) => Buf::Output(w.to_owned()),
            None => Buf::Output(format!("{peer}.{w}")),
        },
    }
}

fn flows(sub: &Subsystem) -> Vec<Flow<'_>> {
    sub.behaviours
        .iter()
        .map(|b| {
            let mut flow = Flow {
                behaviour: b,
                reads: Vec::new(),
                functions: Vec::new(),
                writes: Vec::new(),
                read_edges: Vec::new(),
                write_edges: Vec::new(),
            };
            for fname in &b.functions {
                let Some(f) = sub.function(fname) else {
                    continue;
                };
                let fi = flow.functions.len();
                flow.functions.push(&f.name);
                for r in &f.reads {
                    let buf = read_buf(sub, r);
                    let bi = match flow.reads.iter().position(|x| *x == buf) {
                        Some(i) => i,
                        None => {
                            flow.reads.push(buf);
                            flow.reads.len() - 1
                        }
                    };
                    flow.read_edges.push((bi, fi));
                }
                for w in &f.writes {
                    let buf = write_buf(&f.target, w);
                    let bi = match flow.writes.iter().position(|x| *x == buf) {
                        Some(i) => i,
                        None => {
                            flow.writes.push(buf);
                            flow.writes.len() - 1
                        }
                    };
                    flow.write_edges.push((fi, bi));
                }
            }
            flow
        })
        .collect()
}

fn function_label(sub: &Subsystem, name: &str) -> String {
    match sub.function(name).map(|f| &f.target) {
        Some(Target::Memory) => format!("{name} [{0},{0}]", kind_letter(sub)),
        Some(Target::Common) => format!("{name} [common]"),
        Some(Target::Output(p)) => format!("{name} [{},{p}]", kind_letter(sub)),
        None => name.to_owned(),
    }
}

fn kind_letter(sub: &Subsystem) -> &'static str {
    agent_core::NodeKind::from(sub.kind).symbol()
}

pub(crate) fn render(spec: &Spec, subs: &[&Subsystem], format: Format) -> String {
    match format {
        Format::Dot => dot(spec, subs),
        Format::Mermaid => mermaid(subs),
        Format::Svg => draw(spec, subs).0,
    }
}

fn dot(spec: &Spec, subs: &[&Subsystem]) -> String {
    let mut out = String::new();
    let _ = writeln!(out, "digraph \"{} data flow\" {{", dot_esc(&spec.name));
    out.push_str("  rankdir=TB;\n  fontname=\"monospace\";\n  node [fontname=\"monospace\"];\n");
    for sub in subs {
        for flow in flows(sub) {
            let cluster = format!("{}/{}", sub.name, flow.behaviour.name);
            let _ = writeln!(out, "  subgraph \"cluster_{}\" {{", dot_esc(&cluster));
            let _ = writeln!(
                out,
                "    label=\"{} — behaviour {}\";",
                dot_esc(&sub.name),
                dot_esc(&flow.behaviour.name)
            );
            for b in flow.reads.iter().chain(&flow.writes) {
                let _ = writeln!(
                    out,
                    "    \"{}/{}\" [shape=box, label=\"{}\"];",
                    dot_esc(&cluster),
                    b.id(),
                    dot_esc(&b.label(&sub.name))
                );
            }
            for f in &flow.functions {
                let _ = writeln!(
                    out,
                    "    \"{}/f/{}\" [shape=ellipse, label=\"{}\"];",
                    dot_esc(&cluster),
                    dot_esc(f),
                    dot_esc(&function_label(sub, f))
                );
            }
            for &(b, f) in &flow.read_edges {
                let _ = writeln!(
                    out,
                    "    \"{0}/{1}\" -> \"{0}/f/{2}\";",
                    dot_esc(&cluster),
                    flow.reads[b].id(),
                    dot_esc(flow.functions[f])
                );
            }
            for &(f, b) in &flow.write_edges {
                let _ = writeln!(
                    out,
                    "    \"{0}/f/{1}\" -> \"{0}/{2}\";",
                    dot_esc(&cluster),
                    dot_esc(flow.functions[f]),
                    flow.writes[b].id()
                );
            }
            out.push_str("  }\n");
        }
    }
    out.push_str("}\n");
    out
}

fn mermaid(subs: &[&Subsystem]) -> String {
    let mut out = String::from("flowchart TB\n");
    for sub in subs {
        for flow in flows(sub) {
            let p = format!("{}_{}_", sub.name, flow.behaviour.name);
            let _ = writeln!(
                out,
                "    subgraph {}[\"{} — behaviour {}\"]",
                mermaid_id("", &format!("{}_{}", sub.name, flow.behaviour.name)),
                mermaid_esc(&sub.name),
                mermaid_esc(&flow.behaviour.name)
            );
            for b in flow.reads.iter().chain(&flow.writes) {
                let _ = writeln!(
                    out,
                    "        {}[\"{}\"]",
                    mermaid_id(&p, &b.id()),
                    mermaid_esc(&b.label(&sub.name))
                );
            }
            for f in &flow.functions {
                let _ = writeln!(
                    out,
                    "        {}([\"{}\"])",
                    mermaid_id(&p, &format!("f_{f}")),
                    mermaid_esc(&function_label(sub, f))
                );
            }
            for &(b, f) in &flow.read_edges {
                let _ = writeln!(
                    out,
                    "        {} --> {}",
                    mermaid_id(&p, &flow.reads[b].id()),
                    mermaid_id(&p, &format!("f_{}", flow.functions[f]))
                );
            }
            for &(f, b) in &flow.write_edges {
                let _ = writeln!(
                    out,
                    "        {} --> {}",
                    mermaid_id(&p, &format!("f_{}", flow.functions[f])),
                    mermaid_id(&p, &flow.writes[b].id())
                );
            }
            out.push_str("    end\n");
        }
    }
    out
}

/// The SVG, and what it placed.
pub(crate) fn draw(spec: &Spec, subs: &[&Subsystem]) -> (String, Scene) {
    let spacing = Spacing {
        node_gap: 30.0,
        gap: 10.0,
        group_gap: 40.0,
        rank_gap: 60.0,
    };
    let mut doc = Svg::new();
    let mut y = MARGIN;
    let mut width: f64 = 0.0;
    for sub in subs {
        for flow in flows(sub) {
            let title = format!(
                "{} — behaviour {} ({})",
                sub.name, flow.behaviour.name, flow.behaviour.kind
            );
            let top = y + LINE_H + 2.0 * PAD;
            let nr = flow.reads.len();
            let nf = flow.functions.len();
            let mut boxes: Vec<Boxed> = flow
                .reads
                .iter()
                .map(|b| Boxed::new(vec![b.label(&sub.name)]))
                .collect();
            if flow.functions.is_empty() {
                boxes.push(Boxed::new(vec![
                    "(no transition function: the action only waits)".to_owned(),
                ]));
            }
            boxes.extend(flow.functions.iter().map(|f| {
                let mut b = Boxed::new(vec![function_label(sub, f)]);
                b.rounded = true;
                b
            }));
            boxes.extend(flow.writes.iter().map(|b| {
                let mut x = Boxed::new(vec![b.label(&sub.name)]);
                x.rounded = false;
                x
            }));
            for b in boxes.iter_mut().take(nr) {
                b.rounded = false;
            }
            // Reads, functions, writes: one rank each (without functions, the note).
            let rank_of = |i: usize| {
                if nf == 0 || i < nr {
                    0
                } else if i < nr + nf {
                    usize::from(nr > 0)
                } else {
                    1 + usize::from(nr > 0)
                }
            };
            let mut g = Graph::default();
            let slots: Vec<usize> = boxes
                .iter()
                .enumerate()
                .map(|(i, b)| g.slot(SlotKind::Node, rank_of(i), 0, (b.w, b.h), b.w))
                .collect();
            let mut edges: Vec<(usize, usize)> =
                flow.read_edges.iter().map(|&(b, f)| (b, nr + f)).collect();
            edges.extend(flow.write_edges.iter().map(|&(f, b)| (nr + f, nr + nf + b)));
            let chains: Vec<usize> = edges
                .iter()
                .map(|&(a, b)| g.chain(vec![slots[a], slots[b]], None))
                .collect();
            g.place(MARGIN + PAD, top, spacing);
            g.put(&mut boxes, &slots);
            let (f, frame_w, frame_h) = doc.frame_around((y, top), (g.right(), g.bottom()), &title);
            let first = doc.next_box();
            for b in &boxes {
                doc.boxed(b, Some(f));
            }
            for (&(a, b), &c) in edges.iter().zip(&chains) {
                let path = g.route(c, None);
                doc.edge(&path, None, (Some(first + a), Some(first + b)), Some(f));
            }
            width = width.max(frame_w + 2.0 * MARGIN);
            y += frame_h + MARGIN;
        }
    }
    doc.finish(width.max(200.0), y, &format!("{} — data flow", spec.name))
}
