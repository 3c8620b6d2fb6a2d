//! Agents, components with their buffers, and links (Figs. 2 and 4).
//!
//! Drawn by default up to [`super::OVERVIEW_THRESHOLD`] (60) subsystems in the
//! agents shown; above, [`super::Detail::Auto`] draws the overview
//! ([`super::overview`]) instead: placing the links between agents that are
//! not neighbours (the arches over the frames) grows with their square, and
//! the drawing's width with the components.

use std::fmt::Write as _;

use super::geometry::Scene;
use super::layout::{Graph, SlotKind, Spacing, TURN_DEPTH, ranks_between};
use super::svg::{Boxed, LABEL_H, LINE_H, LabelAt, MARGIN, PAD, Svg, label_w, text_w};
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

/// Above this many agents, [`arrange`] places them in link order.
const LINK_ORDER_ABOVE: usize = 8;

/// Agents ordered for drawing: up to [`LINK_ORDER_ABOVE`], the most connected
/// in the middle, the others alternately to its left and right, so links
/// between agents stay short. Above, in link order (depth first along the
/// links from the first agent): in a chain or a ring of agents, neighbours are
/// drawn side by side instead of far apart, so that their links need no arch
/// over the frames (placing the arches grows with their square).
fn arrange(spec: &Spec, agents: &[usize]) -> Vec<usize> {
    let agent_of = |comp: &str| {
        spec.agents.iter().position(|a| {
            a.subsystems.iter().any(|s| s.name == comp) || a.devices.iter().any(|d| d.name == comp)
        })
    };
    let mut degree = vec![0usize; spec.agents.len()];
    let mut adjacent: Vec<Vec<usize>> = vec![Vec::new(); spec.agents.len()];
    for l in &spec.links {
        let f = l.from.split('.').next().and_then(agent_of);
        let t = l.to.split('.').next().and_then(agent_of);
        if let (Some(f), Some(t)) = (f, t)
            && f != t
        {
            degree[f] += 1;
            degree[t] += 1;
            if agents.len() > LINK_ORDER_ABOVE {
                adjacent[f].push(t);
                adjacent[t].push(f);
            }
        }
    }
    if agents.len() > LINK_ORDER_ABOVE {
        return link_order(agents, &adjacent);
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

/// `agents` depth first along `adjacent` (per agent of the spec, the agents
/// its links join), from each agent not yet reached, in `agents`' order.
fn link_order(agents: &[usize], adjacent: &[Vec<usize>]) -> Vec<usize> {
    let mut shown = vec![false; adjacent.len()];
    for &a in agents {
        shown[a] = true;
    }
    let mut reached = vec![false; adjacent.len()];
    let mut out = Vec::with_capacity(agents.len());
    let mut stack = Vec::new();
    for &start in agents {
        stack.push(start);
        while let Some(a) = stack.pop() {
            if reached[a] {
                continue;
            }
            reached[a] = true;
            out.push(a);
            stack.extend(
                adjacent[a]
                    .iter()
                    .rev()
                    .filter(|&&n| shown[n] && !reached[n]),
            );
        }
    }
    out
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

/// The SVG of the agents (indices into `spec.agents`), and what it placed.
pub(crate) fn draw_agents(spec: &Spec, agents: &[usize]) -> (String, Scene) {
    let agents = &arrange(spec, agents)[..];
    let comps = components(spec, agents);
    let links = bundles(spec, &comps);
    draw(spec, agents, &comps, &links)
}

/// Distance between two arches over the agents.
const TRACK_PITCH: f64 = LABEL_H + 6.0;

/// A link between agents that are not neighbours, drawn over the top of the frames.
struct Arch {
    chain: usize,
    /// x of its two vertical runs (source side, target side).
    xa: f64,
    xb: f64,
    /// Width of its label.
    w: f64,
    /// Its track (0: nearest the frames) and the left end of its label, once chosen.
    track: usize,
    label_x: f64,
}

/// Choose a track and a label position for each arch: the label lies on its arch,
/// clear of the other arches' labels and of the vertical runs of the arches above
/// it; the vertical runs of an arch stay clear of the labels below it.
fn assign_tracks(arches: &mut [Arch]) {
    let mut order: Vec<usize> = (0..arches.len()).collect();
    order.sort_by(|&i, &j| {
        let span = |a: &Arch| (a.xa - a.xb).abs();
        span(&arches[i]).total_cmp(&span(&arches[j]))
    });
    let mut placed: Vec<usize> = Vec::new();
    for i in order {
        let (lo, hi) = (
            arches[i].xa.min(arches[i].xb),
            arches[i].xa.max(arches[i].xb),
        );
        let w = arches[i].w;
        // Candidate label positions along the run, left first.
        let mut xs = vec![lo + 10.0];
        let mut x = lo + 18.0;
        while x + w <= hi - 10.0 {
            xs.push(x);
            x += 8.0;
        }
        let hits = |x: f64, l: f64, w: f64| x > l - 3.0 && x < l + w + 3.0;
        // Prefer places that no other arch's vertical run could cross, whatever its
        // track.
        let free: Vec<f64> = xs
            .iter()
            .copied()
            .filter(|&lx| {
                arches
                    .iter()
                    .enumerate()
                    .all(|(j, o)| j == i || (!hits(o.xa, lx, w) && !hits(o.xb, lx, w)))
            })
            .collect();
        if !free.is_empty() {
            xs = free;
        }
        let mut chosen = None;
        'tracks: for t in 0..=placed.len() {
            // My runs must not cross the labels of arches below.
            for &j in &placed {
                let o = &arches[j];
                if o.track < t && (hits(lo, o.label_x, o.w) || hits(hi, o.label_x, o.w)) {
                    continue 'tracks;
                }
            }
            for &lx in &xs {
                let (l, r) = (lo.min(lx), hi.max(lx + w));
                let clear = placed.iter().all(|&j| {
                    let o = &arches[j];
                    let (ol, or) = (
                        o.xa.min(o.xb).min(o.label_x),
                        o.xa.max(o.xb).max(o.label_x + o.w),
                    );
                    if o.track == t {
                        r + 6.0 < ol || or + 6.0 < l
                    } else if o.track > t {
                        !hits(o.xa, lx, w) && !hits(o.xb, lx, w)
                    } else {
                        true
                    }
                });
                if clear {
                    chosen = Some((t, lx));
                    break 'tracks;
                }
            }
        }
        let (t, lx) = chosen.unwrap_or((placed.len(), xs[0]));
        arches[i].track = t;
        arches[i].label_x = lx;
        placed.push(i);
    }
}

/// The column of a component: its agent's place in the drawing.
fn column(agents: &[usize], c: &Comp<'_>) -> usize {
    agents.iter().position(|&a| a == c.agent).unwrap_or(0)
}

/// The rank of a component's box.
fn rank_of(c: &Comp<'_>) -> usize {
    1 + 2 * c.row
}

/// The y of arch track `t` over frames whose top is at `frame_top`.
fn track_y(frame_top: f64, t: usize) -> f64 {
    frame_top - 14.0 - TRACK_PITCH * t as f64
}

/// The structure laid out and placed.
struct Placed {
    g: Graph,
    /// Per component, its box's slot.
    slot_of: Vec<usize>,
    /// Per link, its chain.
    chains: Vec<usize>,
    /// The links between agents that are not neighbours.
    arches: Vec<Arch>,
    /// The frames' top before the drawing moved down by `dy` to make room
    /// for the arches.
    frame_top: f64,
    dy: f64,
}

/// The SVG of the agents' frames, the components' boxes and the links, and
/// what it placed.
fn draw(
    spec: &Spec,
    agents: &[usize],
    comps: &[Comp<'_>],
    links: &[(usize, usize, String)],
) -> (String, Scene) {
    let titles: Vec<String> = agents
        .iter()
        .map(|&a| format!("agent {}", spec.agents[a].name))
        .collect();
    let mut boxes: Vec<Boxed> = comps
        .iter()
        .map(|c| {
            let mut b = Boxed::new(c.lines.clone());
            b.rounded = c.row < 2;
            b
        })
        .collect();
    let p = lay_out(agents, comps, links, &titles, &boxes);
    let frame_top = p.frame_top + p.dy;
    let bottom = p.g.bottom() + PAD;
    p.g.put(&mut boxes, &p.slot_of);
    let mut doc = Svg::new();
    let mut extent: f64 = 0.0;
    let frame_ids = draw_frames(&mut doc, &p.g, &titles, (frame_top, bottom), &mut extent);
    let ids: Vec<usize> = boxes
        .iter()
        .zip(comps)
        .map(|(b, c)| doc.boxed(b, Some(frame_ids[column(agents, c)])))
        .collect();
    draw_links(&mut doc, &p, links, &ids, &mut extent);
    doc.finish(
        extent + MARGIN,
        bottom + MARGIN,
        &format!("{} — structure", spec.name),
    )
}

/// The layout of titles, boxes and links, placed, with room above the frames
/// for the arches.
///
/// Ranks: 0 the agents' titles, then each row of components (control; virtual
/// effectors and receptors; devices) followed by a rank for labels. Groups: 2k
/// the agent in column k, 2k + 1 the space between it and the next.
fn lay_out(
    agents: &[usize],
    comps: &[Comp<'_>],
    links: &[(usize, usize, String)],
    titles: &[String],
    boxes: &[Boxed],
) -> Placed {
    let spacing = Spacing {
        node_gap: 40.0,
        gap: 12.0,
        group_gap: 2.0 * PAD + 24.0,
        rank_gap: 26.0,
    };
    let mut g = Graph::default();
    for (k, t) in titles.iter().enumerate() {
        g.slot(SlotKind::Title, 0, 2 * k, (text_w(t), LINE_H + 1.0), 0.0);
    }
    let slot_of: Vec<usize> = comps
        .iter()
        .zip(boxes)
        .map(|(c, b)| {
            g.slot(
                SlotKind::Node,
                rank_of(c),
                2 * column(agents, c),
                (b.w, b.h),
                b.w,
            )
        })
        .collect();
    let (chains, mut arches) = link_chains(&mut g, agents, comps, links, &slot_of);
    g.place(MARGIN + PAD, 0.0, spacing);
    let (frame_top, dy) = lift_for_arches(&mut g, &mut arches);
    Placed {
        g,
        slot_of,
        chains,
        arches,
        frame_top,
        dy,
    }
}

/// Each link as a chain of slots: between the same or neighbouring agents
/// through the ranks between its ends (a turn between boxes of one rank);
/// between agents further apart, up to the titles' rank in the source's agent,
/// over the top (an arch), and down in the target's.
fn link_chains(
    g: &mut Graph,
    agents: &[usize],
    comps: &[Comp<'_>],
    links: &[(usize, usize, String)],
    slot_of: &[usize],
) -> (Vec<usize>, Vec<Arch>) {
    let mut chains = Vec::with_capacity(links.len());
    let mut arches: Vec<Arch> = Vec::new();
    for (a, b, label) in links {
        let (ca, cb) = (column(agents, &comps[*a]), column(agents, &comps[*b]));
        let (ra, rb) = (rank_of(&comps[*a]), rank_of(&comps[*b]));
        let mut slots = vec![slot_of[*a]];
        let mut arch = None;
        if ca.abs_diff(cb) <= 1 {
            let group = if ca == cb { 2 * ca } else { 2 * ca.min(cb) + 1 };
            near_link_slots(g, &mut slots, (ra, rb), group, label);
        } else {
            for r in (0..ra).rev() {
                slots.push(g.slot(SlotKind::Dummy, r, 2 * ca, (0.0, 0.0), 0.0));
            }
            arch = Some(slots.len() - 1);
            for r in 0..rb {
                slots.push(g.slot(SlotKind::Dummy, r, 2 * cb, (0.0, 0.0), 0.0));
            }
        }
        slots.push(slot_of[*b]);
        let c = g.chain(slots, arch);
        if arch.is_some() {
            arches.push(Arch {
                chain: c,
                xa: 0.0,
                xb: 0.0,
                w: label_w(label),
                track: 0,
                label_x: 0.0,
            });
        }
        chains.push(c);
    }
    (chains, arches)
}

/// The slots of a link in `group` between boxes of ranks `ra` and `rb`: a turn
/// under their rank if it is one, else a run through the ranks between, its
/// label in the label rank nearest the middle.
fn near_link_slots(
    g: &mut Graph,
    slots: &mut Vec<usize>,
    (ra, rb): (usize, usize),
    group: usize,
    label: &str,
) {
    if ra == rb {
        let w = label_w(label);
        slots.push(g.slot(
            SlotKind::Turn,
            ra + 1,
            group,
            (w + 4.0, TURN_DEPTH + 1.0 + LABEL_H),
            w,
        ));
        return;
    }
    let (between, label_rank) = ranks_between(ra, rb, 0);
    for r in between {
        slots.push(if Some(r) == label_rank {
            let w = label_w(label);
            g.slot(SlotKind::Label, r, group, (w + 2.0, LABEL_H), w)
        } else {
            g.slot(SlotKind::Dummy, r, group, (0.0, 0.0), 0.0)
        });
    }
}

/// The arches over the frames: their runs and tracks; then everything moved
/// down so that the highest fits. The frames' top before the move, and the
/// move.
fn lift_for_arches(g: &mut Graph, arches: &mut [Arch]) -> (f64, f64) {
    for arch in arches.iter_mut() {
        let k = g.chains[arch.chain].arch.unwrap_or(0);
        arch.xa = g.run_at(arch.chain, k);
        arch.xb = g.run_at(arch.chain, k + 1);
    }
    assign_tracks(arches);
    let frame_top = g.bands.first().map_or(0.0, |b| b.0) - 4.0;
    let highest = arches
        .iter()
        .map(|a| track_y(frame_top, a.track) - LABEL_H - 2.0)
        .fold(frame_top, f64::min);
    let dy = MARGIN - highest;
    g.shift_y(dy);
    (frame_top, dy)
}

/// Each agent's frame around its slots, from `top` to `bottom`, widening
/// `extent`; the frames' ids.
fn draw_frames(
    doc: &mut Svg,
    g: &Graph,
    titles: &[String],
    (top, bottom): (f64, f64),
    extent: &mut f64,
) -> Vec<usize> {
    titles
        .iter()
        .enumerate()
        .map(|(k, title)| {
            let members = g.slots.iter().filter(|s| s.group == 2 * k);
            let (l, r) = members.fold((f64::INFINITY, f64::NEG_INFINITY), |(l, r), s| {
                (l.min(s.x), r.max(s.x + s.w))
            });
            *extent = extent.max(r + PAD);
            doc.frame(l - PAD, top, r - l + 2.0 * PAD, bottom - top, title)
        })
        .collect()
}

/// Each link between the boxes `ids`, routed along its chain (an arch over
/// its track, its label on it), widening `extent`.
fn draw_links(
    doc: &mut Svg,
    p: &Placed,
    links: &[(usize, usize, String)],
    ids: &[usize],
    extent: &mut f64,
) {
    let g = &p.g;
    for ((a, b, label), &c) in links.iter().zip(&p.chains) {
        let arch = p.arches.iter().find(|x| x.chain == c);
        let (path, at) = match arch {
            Some(x) => {
                let y = track_y(p.frame_top, x.track) + p.dy;
                let at = LabelAt {
                    x: x.label_x,
                    y: y - LABEL_H / 2.0 - 1.0,
                };
                (g.route(c, Some(y)), Some(at))
            }
            None => (g.route(c, None), g.label_at(c)),
        };
        if let Some(at) = &at {
            *extent = extent.max(at.right(label));
        }
        *extent = extent.max(g.right());
        doc.edge(
            &path,
            at.as_ref().map(|at| (label.as_str(), at)),
            (Some(ids[*a]), Some(ids[*b])),
            None,
        );
    }
}

#[cfg(test)]
mod tests {
    use super::super::overview::tests::ring;
    use super::*;

    #[test]
    fn many_agents_are_drawn_in_link_order() {
        let spec = ring(12);
        let shuffled = [0, 6, 1, 7, 2, 8, 3, 9, 4, 10, 5, 11];
        let order = arrange(&spec, &shuffled);
        assert_eq!(order, (0..12).collect::<Vec<_>>());
        // Few agents: the most connected in the middle, as before.
        let spec = ring(3);
        assert_eq!(arrange(&spec, &[0, 1, 2]), vec![1, 0, 2]);
    }

    #[test]
    fn a_ring_of_agents_needs_one_arch() {
        let spec = ring(20);
        let agents = arrange(&spec, &(0..20).collect::<Vec<_>>());
        let comps = components(&spec, &agents);
        let links = bundles(&spec, &comps);
        let titles: Vec<String> = agents.iter().map(|a| format!("agent a{a}")).collect();
        let boxes: Vec<Boxed> = comps.iter().map(|c| Boxed::new(c.lines.clone())).collect();
        let p = lay_out(&agents, &comps, &links, &titles, &boxes);
        assert_eq!(p.arches.len(), 1, "only the link closing the ring");
    }
}
