//! A layered layout in the manner of Graphviz's `dot` (Sugiyama et al.), small enough
//! to read: every element is a *slot* in a horizontal *rank* (band); an edge is a
//! *chain* of slots in consecutive ranks, with dummy slots where it crosses a rank and
//! a label slot where its label goes. Because
//!
//! * the slots of a rank never overlap (each has its own column of the band),
//! * between two bands there are only edges, and
//! * an edge crosses a band only inside one of its own slots,
//!
//! no edge passes through a box or a label, no label overlaps a box or another label,
//! and a label sits next to the run of its edge through its slot. The steps:
//!
//! 1. order each rank (barycentres, sweeping down and up; the fewest crossings win),
//!    keeping the slots of a *group* (an agent of a structure diagram) together;
//! 2. place the slots of each rank left to right, each as near as the order allows to
//!    the slots it is joined to (weighted isotonic regression, a few sweeps), then
//!    separate the groups;
//! 3. stack the bands; 4. route each chain through its slots.

use super::geometry::{Path, Point, Segment};
use super::svg::{Boxed, LabelAt};

/// What a slot holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum SlotKind {
    /// A box; its edges attach to its top and bottom.
    Node,
    /// An edge passing through the rank: a vertical run at the slot's left.
    Dummy,
    /// An edge passing through the rank with its label right of the run.
    Label,
    /// An edge that comes from the rank above and goes back up (a link between two
    /// boxes of one rank): a U, with the label under it.
    Turn,
    /// Reserved room (a frame's title).
    Title,
}

/// One element of a rank.
#[derive(Clone, Debug)]
pub(crate) struct Slot {
    pub(crate) kind: SlotKind,
    pub(crate) rank: usize,
    /// Slots are ordered by group first; groups are kept apart horizontally.
    pub(crate) group: usize,
    /// Width and height of the whole slot.
    pub(crate) w: f64,
    pub(crate) h: f64,
    /// For a node: the width of its box (the rest of the slot, to its right, is for
    /// self-loops); for a label or turn: the width of the label.
    pub(crate) inner_w: f64,
    /// Left and top, once placed (the slot is centred vertically in its band).
    pub(crate) x: f64,
    pub(crate) y: f64,
    /// Position in its rank, once ordered.
    pos: usize,
}

impl Slot {
    /// Where edges meet the slot, relative to its left.
    fn anchor(&self) -> f64 {
        match self.kind {
            SlotKind::Node => self.inner_w / 2.0,
            SlotKind::Dummy | SlotKind::Label => 0.0,
            SlotKind::Turn | SlotKind::Title => self.w / 2.0,
        }
    }
}

/// An edge: its slots in the order of the path, from source to target; consecutive
/// slots are in adjacent ranks, except across the `arch` (the slots `arch` and
/// `arch + 1` are joined over the top of the drawing, see [`Graph::route`]).
#[derive(Clone, Debug)]
pub(crate) struct Chain {
    pub(crate) slots: Vec<usize>,
    pub(crate) arch: Option<usize>,
}

/// Spacing of a layout.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Spacing {
    /// Between two boxes of a rank.
    pub(crate) node_gap: f64,
    /// Between a box or a run and anything else of its rank.
    pub(crate) gap: f64,
    /// Between two groups.
    pub(crate) group_gap: f64,
    /// Between two bands.
    pub(crate) rank_gap: f64,
}

/// Depth of the U of a [`SlotKind::Turn`].
pub(crate) const TURN_DEPTH: f64 = 10.0;
/// Radius of the corners of an arch.
const CORNER: f64 = 6.0;

/// The slots and chains of a drawing.
#[derive(Clone, Debug, Default)]
pub(crate) struct Graph {
    pub(crate) slots: Vec<Slot>,
    pub(crate) chains: Vec<Chain>,
    /// Top and bottom of each rank's band, once placed.
    pub(crate) bands: Vec<(f64, f64)>,
}

impl Graph {
    /// Add a slot; returns its index.
    pub(crate) fn slot(
        &mut self,
        kind: SlotKind,
        rank: usize,
        group: usize,
        (w, h): (f64, f64),
        inner_w: f64,
    ) -> usize {
        self.slots.push(Slot {
            kind,
            rank,
            group,
            w,
            h,
            inner_w,
            x: 0.0,
            y: 0.0,
            pos: 0,
        });
        self.slots.len() - 1
    }

    /// Add a chain; returns its index.
    pub(crate) fn chain(&mut self, slots: Vec<usize>, arch: Option<usize>) -> usize {
        self.chains.push(Chain { slots, arch });
        self.chains.len() - 1
    }

    fn ranks(&self) -> usize {
        self.slots.iter().map(|s| s.rank + 1).max().unwrap_or(0)
    }

    /// The joined pairs of slots (in adjacent ranks), each once per chain step.
    fn pairs(&self) -> Vec<(usize, usize)> {
        let mut out = Vec::new();
        for c in &self.chains {
            for k in 0..c.slots.len().saturating_sub(1) {
                if c.arch != Some(k) {
                    out.push((c.slots[k], c.slots[k + 1]));
                }
            }
        }
        out
    }

    /// Order, place and stack: after this every slot has its `x`, `y`, and every rank
    /// its band. Coordinates start at `(x0, y0)`.
    pub(crate) fn place(&mut self, x0: f64, y0: f64, sp: Spacing) {
        // Drop empty ranks (no chain steps over one: its steps join adjacent ranks).
        let mut used = vec![false; self.ranks()];
        for s in &self.slots {
            used[s.rank] = true;
        }
        let new_rank: Vec<usize> = used
            .iter()
            .scan(0, |n, &u| {
                let r = *n;
                *n += usize::from(u);
                Some(r)
            })
            .collect();
        for s in &mut self.slots {
            s.rank = new_rank[s.rank];
        }
        let n_ranks = self.ranks();
        let pairs = self.pairs();
        let mut nbrs: Vec<Vec<usize>> = vec![Vec::new(); self.slots.len()];
        for &(a, b) in &pairs {
            nbrs[a].push(b);
            nbrs[b].push(a);
        }
        let ranks = self.order(n_ranks, &pairs, &nbrs);
        self.assign_x(&ranks, &nbrs, x0, sp);
        // Stack the bands.
        self.bands.clear();
        let mut y = y0;
        for r in 0..n_ranks {
            let h = ranks[r]
                .iter()
                .map(|&i| self.slots[i].h)
                .fold(0.0, f64::max);
            self.bands.push((y, y + h));
            for &i in &ranks[r] {
                self.slots[i].y = match self.slots[i].kind {
                    SlotKind::Turn | SlotKind::Title => y,
                    _ => y + (h - self.slots[i].h) / 2.0,
                };
            }
            y += h + sp.rank_gap;
        }
    }

    /// Move everything down by `dy`.
    pub(crate) fn shift_y(&mut self, dy: f64) {
        for s in &mut self.slots {
            s.y += dy;
        }
        for b in &mut self.bands {
            b.0 += dy;
            b.1 += dy;
        }
    }

    /// The x of the run of chain `c` through its `k`-th slot.
    pub(crate) fn run_at(&self, c: usize, k: usize) -> f64 {
        self.run_x(c, k)
    }

    /// Move each box to its slot (`slot_of[i]` holds `boxes[i]`), once placed.
    pub(crate) fn put(&self, boxes: &mut [Boxed], slot_of: &[usize]) {
        for (b, &i) in boxes.iter_mut().zip(slot_of) {
            b.x = self.slots[i].x;
            b.y = self.slots[i].y;
        }
    }

    /// Right end of the placed slots.
    pub(crate) fn right(&self) -> f64 {
        self.slots.iter().map(|s| s.x + s.w).fold(0.0, f64::max)
    }

    /// Bottom of the last band.
    pub(crate) fn bottom(&self) -> f64 {
        self.bands.last().map_or(0.0, |b| b.1)
    }

    /// Step 1: the slots of each rank, in order.
    fn order(
        &mut self,
        n_ranks: usize,
        pairs: &[(usize, usize)],
        nbrs: &[Vec<usize>],
    ) -> Vec<Vec<usize>> {
        let mut ranks: Vec<Vec<usize>> = vec![Vec::new(); n_ranks];
        for (i, s) in self.slots.iter().enumerate() {
            ranks[s.rank].push(i);
        }
        for r in &mut ranks {
            r.sort_by_key(|&i| (self.slots[i].group, self.slots[i].kind != SlotKind::Title));
        }
        let set_pos = |slots: &mut Vec<Slot>, ranks: &Vec<Vec<usize>>| {
            for r in ranks {
                for (k, &i) in r.iter().enumerate() {
                    slots[i].pos = k;
                }
            }
        };
        set_pos(&mut self.slots, &ranks);
        let mut best = ranks.clone();
        let mut best_crossings = self.crossings(pairs);
        for sweep in 0..12 {
            let down = sweep % 2 == 0;
            let order: Vec<usize> = if down {
                (1..n_ranks).collect()
            } else {
                (0..n_ranks.saturating_sub(1)).rev().collect()
            };
            for r in order {
                let from = if down { r.wrapping_sub(1) } else { r + 1 };
                let mut keyed: Vec<(usize, f64, usize)> = ranks[r]
                    .iter()
                    .map(|&i| {
                        let ns: Vec<f64> = nbrs[i]
                            .iter()
                            .filter(|&&j| self.slots[j].rank == from)
                            .map(|&j| self.slots[j].pos as f64)
                            .collect();
                        let bary = if ns.is_empty() {
                            self.slots[i].pos as f64
                        } else {
                            ns.iter().sum::<f64>() / ns.len() as f64
                        };
                        (self.slots[i].group, bary, i)
                    })
                    .collect();
                let not_title = |i: usize| self.slots[i].kind != SlotKind::Title;
                keyed.sort_by(|a, b| {
                    a.0.cmp(&b.0)
                        .then(not_title(a.2).cmp(&not_title(b.2)))
                        .then(a.1.total_cmp(&b.1))
                        .then(self.slots[a.2].pos.cmp(&self.slots[b.2].pos))
                });
                ranks[r] = keyed.into_iter().map(|k| k.2).collect();
                for (k, &i) in ranks[r].iter().enumerate() {
                    self.slots[i].pos = k;
                }
            }
            let c = self.crossings(pairs);
            if c < best_crossings {
                best_crossings = c;
                best = ranks.clone();
            }
        }
        set_pos(&mut self.slots, &best);
        best
    }

    fn crossings(&self, pairs: &[(usize, usize)]) -> usize {
        // Each pair as (upper rank, upper pos, lower pos).
        let mut es: Vec<(usize, usize, usize)> = pairs
            .iter()
            .map(|&(a, b)| {
                let (a, b) = if self.slots[a].rank <= self.slots[b].rank {
                    (a, b)
                } else {
                    (b, a)
                };
                (self.slots[a].rank, self.slots[a].pos, self.slots[b].pos)
            })
            .collect();
        es.sort();
        let mut n = 0;
        for i in 0..es.len() {
            for j in i + 1..es.len() {
                if es[j].0 != es[i].0 {
                    break;
                }
                if (es[i].1 < es[j].1 && es[i].2 > es[j].2)
                    || (es[i].1 > es[j].1 && es[i].2 < es[j].2)
                {
                    n += 1;
                }
            }
        }
        n
    }

    /// Step 2: x of every slot.
    fn assign_x(&mut self, ranks: &[Vec<usize>], nbrs: &[Vec<usize>], x0: f64, sp: Spacing) {
        self.pack_left(ranks, x0, sp);
        // Straight runs through dummies matter most. Each group is laid out on its
        // own (joins across groups are left out), then the groups side by side.
        let n_ranks = ranks.len();
        for sweep in 0..16 {
            let order: Vec<usize> = if sweep % 2 == 0 {
                (0..n_ranks).collect()
            } else {
                (0..n_ranks).rev().collect()
            };
            for r in order {
                let row = &ranks[r];
                if row.is_empty() {
                    continue;
                }
                let (target, wts) = self.row_targets(row, nbrs, sp);
                self.fit_row(row, &target, &wts, sp);
            }
        }
        self.groups_side_by_side(sp);
        // Start at x0.
        let min = self.slots.iter().map(|s| s.x).fold(f64::INFINITY, f64::min);
        if min.is_finite() {
            for s in &mut self.slots {
                s.x += x0 - min;
            }
        }
    }

    /// Each group of each rank packed to the left, to start with (the groups are
    /// put side by side at the end).
    fn pack_left(&mut self, ranks: &[Vec<usize>], x0: f64, sp: Spacing) {
        for r in ranks {
            let mut x = x0;
            for (k, &i) in r.iter().enumerate() {
                if k > 0 {
                    let p = &self.slots[r[k - 1]];
                    if p.group == self.slots[i].group {
                        x += sep(p, &self.slots[i], sp);
                    } else {
                        x = x0;
                    }
                }
                self.slots[i].x = x;
                x += self.slots[i].w;
            }
        }
    }

    /// The desired left end of each slot of `row`, and its weight: the weighted
    /// mean of where its joins in its group meet it, or for an unjoined slot the
    /// place next to its left neighbour in the group (else the group's left),
    /// lightly held.
    fn row_targets(&self, row: &[usize], nbrs: &[Vec<usize>], sp: Spacing) -> (Vec<f64>, Vec<f64>) {
        let mut target = Vec::with_capacity(row.len());
        let mut wts = Vec::with_capacity(row.len());
        for &i in row {
            let s = &self.slots[i];
            let (mut sum, mut wsum) = (0.0, 0.0);
            for &j in nbrs[i].iter().filter(|&&j| self.slots[j].group == s.group) {
                let t = &self.slots[j];
                let w = weight(s, t);
                sum += w * (t.x + t.anchor());
                wsum += w;
            }
            if wsum > 0.0 {
                target.push(sum / wsum - s.anchor());
                wts.push(wsum);
            } else {
                // Unjoined: next to its left neighbour in the group, else at the
                // group's left (a title heads its group).
                let k = target.len();
                let left = group_left(&self.slots, s.group);
                let x = match k.checked_sub(1).map(|p| &self.slots[row[p]]) {
                    Some(p) if p.group == s.group && s.kind != SlotKind::Title => {
                        p.x + p.w + sep(p, s, sp)
                    }
                    _ if left.is_finite() => left,
                    _ => s.x,
                };
                target.push(x);
                wts.push(if s.kind == SlotKind::Title { 1.0 } else { 0.01 });
            }
        }
        (target, wts)
    }

    /// Place each group's part of `row` as near its targets as the separations
    /// allow (a weighted isotonic fit: offsets turn the separations into
    /// x_k <= x_k+1).
    fn fit_row(&mut self, row: &[usize], target: &[f64], wts: &[f64], sp: Spacing) {
        let mut start = 0;
        while start < row.len() {
            let g = self.slots[row[start]].group;
            let end = (start..row.len())
                .find(|&k| self.slots[row[k]].group != g)
                .unwrap_or(row.len());
            let part = &row[start..end];
            let mut off = vec![0.0; part.len()];
            for k in 1..part.len() {
                let (a, b) = (&self.slots[part[k - 1]], &self.slots[part[k]]);
                off[k] = off[k - 1] + a.w + sep(a, b, sp);
            }
            let t: Vec<f64> = target[start..end]
                .iter()
                .zip(&off)
                .map(|(t, o)| t - o)
                .collect();
            let y = isotonic(&t, &wts[start..end]);
            for (k, &i) in part.iter().enumerate() {
                self.slots[i].x = y[k] + off[k];
            }
            start = end;
        }
    }

    /// The groups side by side, each `group_gap` right of the one before.
    fn groups_side_by_side(&mut self, sp: Spacing) {
        let max_group = self.slots.iter().map(|s| s.group).max().unwrap_or(0);
        let mut right_of_prev: Option<f64> = None;
        for g in 0..=max_group {
            let members: Vec<usize> = (0..self.slots.len())
                .filter(|&i| self.slots[i].group == g)
                .collect();
            if members.is_empty() {
                continue;
            }
            let left = members
                .iter()
                .map(|&i| self.slots[i].x)
                .fold(f64::INFINITY, f64::min);
            if let Some(prev) = right_of_prev {
                let shift = prev + sp.group_gap - left;
                for s in self.slots.iter_mut().filter(|s| s.group == g) {
                    s.x += shift;
                }
            }
            right_of_prev = Some(
                members
                    .iter()
                    .map(|&i| self.slots[i].x + self.slots[i].w)
                    .fold(f64::NEG_INFINITY, f64::max),
            );
        }
    }

    /// The x of the run of chain `c` through its `k`-th slot, for a node the port on
    /// its top or bottom. Ports of a side are spread over the box in the order of the
    /// slots they lead to.
    fn run_x(&self, c: usize, k: usize) -> f64 {
        let chain = &self.chains[c];
        let i = chain.slots[k];
        let s = &self.slots[i];
        if s.kind != SlotKind::Node {
            return s.x + s.anchor();
        }
        let other = |c: usize, k: usize| -> Option<usize> {
            let ch = &self.chains[c];
            let i = ch.slots[k];
            let prev = (k > 0 && ch.arch != Some(k - 1)).then(|| ch.slots[k - 1]);
            let next = (k + 1 < ch.slots.len() && ch.arch != Some(k)).then(|| ch.slots[k + 1]);
            let _ = i;
            prev.or(next)
        };
        let Some(o) = other(c, k) else {
            return s.x + s.inner_w / 2.0;
        };
        let below = self.slots[o].rank > s.rank;
        // Every attachment on the same side of this node.
        let mut side: Vec<(f64, usize, usize)> = Vec::new();
        for (c2, ch) in self.chains.iter().enumerate() {
            for (k2, &j) in ch.slots.iter().enumerate() {
                if j != i {
                    continue;
                }
                if let Some(o2) = other(c2, k2)
                    && (self.slots[o2].rank > s.rank) == below
                {
                    let t = &self.slots[o2];
                    side.push((t.x + t.anchor(), c2, k2));
                }
            }
        }
        side.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
        let m = side.len();
        let at = side
            .iter()
            .position(|&(_, c2, k2)| c2 == c && k2 == k)
            .unwrap_or(0);
        s.x + s.inner_w * (at as f64 + 1.0) / (m as f64 + 1.0)
    }

    /// The top and bottom of the box of a node slot.
    pub(crate) fn box_y(&self, i: usize) -> (f64, f64) {
        let s = &self.slots[i];
        (s.y, s.y + s.h)
    }

    /// The path of chain `c`; `arch_y` is the height of its arch, if it has one.
    pub(crate) fn route(&self, c: usize, arch_y: Option<f64>) -> Path {
        let chain = &self.chains[c];
        let p = Point::new;
        let mut segs: Vec<Segment> = Vec::new();
        let line = |segs: &mut Vec<Segment>, a: Point, b: Point| {
            if (a.x - b.x).abs() > 0.01 || (a.y - b.y).abs() > 0.01 {
                segs.push(Segment::Line(a, b));
            }
        };
        let n = chain.slots.len();
        let mut cur: Option<Point> = None;
        for k in 0..n {
            let i = chain.slots[k];
            let s = &self.slots[i];
            let (top, bottom) = self.bands[s.rank];
            let x = self.run_x(c, k);
            let prev = (k > 0).then(|| chain.slots[k - 1]);
            let next = (k + 1 < n).then(|| chain.slots[k + 1]);
            let across_arch_before = k > 0 && chain.arch == Some(k - 1);
            let across_arch_after = chain.arch == Some(k);
            // The side of the band the path enters and leaves by.
            let side = |o: Option<usize>, arch: bool| -> Option<bool> {
                if arch {
                    return Some(true); // arches leave by the top
                }
                o.map(|o| self.slots[o].rank < s.rank) // true: top
            };
            let enter_top = side(prev, across_arch_before);
            let leave_top = side(next, across_arch_after);
            let band_y = |top_side: bool| if top_side { top } else { bottom };
            let (entry, exit) = match s.kind {
                SlotKind::Node => {
                    let (bt, bb) = self.box_y(i);
                    match (enter_top, leave_top) {
                        (None, Some(t)) => {
                            let port = p(x, if t { bt } else { bb });
                            (port, p(x, band_y(t)))
                        }
                        (Some(t), _) => {
                            let port = p(x, if t { bt } else { bb });
                            (p(x, band_y(t)), port)
                        }
                        (None, None) => (p(x, bt), p(x, bt)),
                    }
                }
                SlotKind::Turn => {
                    // Enter on the side of the slot nearer the previous slot.
                    let px = prev.map_or(x, |o| self.slots[o].x + self.slots[o].anchor());
                    let nx = next.map_or(x, |o| self.slots[o].x + self.slots[o].anchor());
                    let (l, r) = (s.x + 2.0, s.x + s.w - 2.0);
                    let (a, b) = if px <= nx { (l, r) } else { (r, l) };
                    (p(a, top), p(b, top))
                }
                _ => (
                    p(x, band_y(enter_top.unwrap_or(true))),
                    p(x, band_y(leave_top.unwrap_or(false))),
                ),
            };
            // Join from the previous slot's exit.
            if let Some(from) = cur {
                if across_arch_before {
                    let y = arch_y.unwrap_or(from.y - 20.0);
                    let dir = if entry.x >= from.x { 1.0 } else { -1.0 };
                    line(&mut segs, from, p(from.x, y + CORNER));
                    segs.push(Segment::Cubic(
                        p(from.x, y + CORNER),
                        p(from.x, y),
                        p(from.x, y),
                        p(from.x + dir * CORNER, y),
                    ));
                    line(
                        &mut segs,
                        p(from.x + dir * CORNER, y),
                        p(entry.x - dir * CORNER, y),
                    );
                    segs.push(Segment::Cubic(
                        p(entry.x - dir * CORNER, y),
                        p(entry.x, y),
                        p(entry.x, y),
                        p(entry.x, y + CORNER),
                    ));
                    line(&mut segs, p(entry.x, y + CORNER), entry);
                } else if (from.x - entry.x).abs() < 0.05 {
                    line(&mut segs, from, entry);
                } else {
                    let my = (from.y + entry.y) / 2.0;
                    segs.push(Segment::Cubic(from, p(from.x, my), p(entry.x, my), entry));
                }
            }
            // The run through the slot.
            if s.kind == SlotKind::Turn {
                let d = top + TURN_DEPTH * 4.0 / 3.0;
                segs.push(Segment::Cubic(entry, p(entry.x, d), p(exit.x, d), exit));
            } else {
                line(&mut segs, entry, exit);
            }
            cur = Some(exit);
        }
        Path { segments: segs }
    }

    /// Where the label of chain `c` goes: in its label or turn slot.
    pub(crate) fn label_at(&self, c: usize) -> Option<LabelAt> {
        let chain = &self.chains[c];
        let i = *chain
            .slots
            .iter()
            .find(|&&i| matches!(self.slots[i].kind, SlotKind::Label | SlotKind::Turn))?;
        let s = &self.slots[i];
        let (top, bottom) = self.bands[s.rank];
        Some(match s.kind {
            SlotKind::Turn => LabelAt {
                x: s.x + (s.w - s.inner_w) / 2.0,
                y: top + TURN_DEPTH + 1.0 + super::svg::LABEL_H / 2.0,
            },
            _ => LabelAt {
                x: s.x + 1.5,
                y: (top + bottom) / 2.0,
            },
        })
    }
}

/// The ranks an edge from rank `from` to rank `to` crosses, in its order, and
/// the one of them of parity `label_parity` (the ranks that take labels)
/// nearest the middle, nearer `from` on a tie: where the edge's label goes.
pub(crate) fn ranks_between(
    from: usize,
    to: usize,
    label_parity: usize,
) -> (Vec<usize>, Option<usize>) {
    let between: Vec<usize> = if to > from {
        (from + 1..to).collect()
    } else {
        (to + 1..from).rev().collect()
    };
    let mid = (from + to) as f64 / 2.0;
    let label_rank = between
        .iter()
        .copied()
        .filter(|r| r % 2 == label_parity)
        .min_by(|x, y| (*x as f64 - mid).abs().total_cmp(&(*y as f64 - mid).abs()));
    (between, label_rank)
}

/// The room between two neighbours of a rank.
fn sep(a: &Slot, b: &Slot, sp: Spacing) -> f64 {
    if a.kind == SlotKind::Node && b.kind == SlotKind::Node {
        sp.node_gap
    } else {
        sp.gap
    }
}

/// How strongly a join pulls its two slots into line: straight runs through
/// dummies matter most.
fn weight(a: &Slot, b: &Slot) -> f64 {
    match (a.kind, b.kind) {
        (SlotKind::Node, SlotKind::Node) => 1.0,
        (SlotKind::Node, _) | (_, SlotKind::Node) => 2.0,
        _ => 8.0,
    }
}

/// The left end of group `g` (its title aside), infinite if it has no slot.
fn group_left(slots: &[Slot], g: usize) -> f64 {
    slots
        .iter()
        .filter(|t| t.group == g && t.kind != SlotKind::Title)
        .map(|t| t.x)
        .fold(f64::INFINITY, f64::min)
}

/// Weighted isotonic regression (pool adjacent violators): the non-decreasing `y`
/// nearest to `t` in the weighted least-squares sense.
fn isotonic(t: &[f64], w: &[f64]) -> Vec<f64> {
    // Blocks of (weight, weighted sum, count).
    let mut blocks: Vec<(f64, f64, usize)> = Vec::new();
    for (ti, wi) in t.iter().zip(w) {
        blocks.push((*wi, wi * ti, 1));
        while blocks.len() >= 2 {
            let (b, a) = (blocks[blocks.len() - 1], blocks[blocks.len() - 2]);
            if a.1 / a.0 > b.1 / b.0 {
                blocks.pop();
                let last = blocks.len() - 1;
                blocks[last] = (a.0 + b.0, a.1 + b.1, a.2 + b.2);
            } else {
                break;
            }
        }
    }
    let mut out = Vec::with_capacity(t.len());
    for (w, s, n) in blocks {
        out.extend(std::iter::repeat_n(s / w, n));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn isotonic_pools_violators() {
        let y = isotonic(&[1.0, 3.0, 2.0, 4.0], &[1.0, 1.0, 1.0, 1.0]);
        assert_eq!(y, vec![1.0, 2.5, 2.5, 4.0]);
    }
}
