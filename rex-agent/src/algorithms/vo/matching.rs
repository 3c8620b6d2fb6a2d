//! Circular matching of the four images (notes `vo.md` §1.3–1.7): previous left →
//! previous right (stereo) → current right (time) → current left (stereo) → previous
//! left (time), accepted only if the loop closes on the feature it started from.
//! A sparse pass gives the displacements to expect in each part of the image; the
//! dense pass searches only there. Matches are bucketed, each bucket refining
//! its candidates at full resolution until it holds its quota.

use super::features::{CLASSES, DESCRIPTOR, Features, Gradients, sad};
use crate::algorithms::rng::Rng;

/// Features indexed by class and by square bins of their position.
#[derive(Clone, Debug, Default)]
pub struct Bins {
    size: i32,
    cols: i32,
    rows: i32,
    /// For (class, bin): the range `start[c]..start[c+1]` of `items`.
    start: Vec<u32>,
    items: Vec<u32>,
    /// The items' positions and descriptors in the same order: a search reads
    /// them sequentially instead of gathering from the features.
    pos: Vec<(i32, i32)>,
    desc: Vec<[u8; DESCRIPTOR]>,
    /// Scratch of `build`: the next free slot of each cell.
    fill: Vec<u32>,
}

impl Bins {
    /// Index `f` over an image of `w × h` pixels in bins of `size`.
    pub fn build(&mut self, f: &Features, w: usize, h: usize, size: usize) {
        self.size = size.max(1) as i32;
        self.cols = (w as i32 + self.size - 1) / self.size;
        self.rows = (h as i32 + self.size - 1) / self.size;
        let cells = CLASSES * (self.cols * self.rows) as usize;
        self.start.clear();
        self.start.resize(cells + 1, 0);
        let cell = |k: usize| -> usize {
            let (bu, bv) = (f.u[k] / self.size, f.v[k] / self.size);
            usize::from(f.class[k]) * (self.cols * self.rows) as usize
                + (bv * self.cols + bu) as usize
        };
        for k in 0..f.len() {
            self.start[cell(k) + 1] += 1;
        }
        for c in 0..cells {
            self.start[c + 1] += self.start[c];
        }
        self.items.clear();
        self.items.resize(f.len(), 0);
        self.fill.clear();
        self.fill.extend_from_slice(&self.start);
        for k in 0..f.len() {
            let c = cell(k);
            self.items[self.fill[c] as usize] = k as u32;
            self.fill[c] += 1;
        }
        self.pos.clear();
        self.pos.extend(
            self.items
                .iter()
                .map(|&k| (f.u[k as usize], f.v[k as usize])),
        );
        self.desc.clear();
        self.desc
            .extend(self.items.iter().map(|&k| f.desc[k as usize]));
    }

    /// The feature of `class` in `[u0, u1] × [v0, v1]` whose descriptor is closest
    /// to `d` (sum of absolute differences).
    #[inline]
    fn best(
        &self,
        class: u8,
        d: &[u8; DESCRIPTOR],
        (u0, u1, v0, v1): (i32, i32, i32, i32),
    ) -> Option<usize> {
        if u1 < u0 || v1 < v0 {
            return None;
        }
        let base = usize::from(class) * (self.cols * self.rows) as usize;
        let (bu0, bu1) = ((u0 / self.size).max(0), (u1 / self.size).min(self.cols - 1));
        let (bv0, bv1) = ((v0 / self.size).max(0), (v1 / self.size).min(self.rows - 1));
        // The least (cost, index): ties go to the first feature whatever the bins,
        // so the size of the bins changes the time, never the match.
        let mut best = u64::MAX;
        for bv in bv0..=bv1 {
            for bu in bu0..=bu1 {
                let c = base + (bv * self.cols + bu) as usize;
                let (a, b) = (self.start[c] as usize, self.start[c + 1] as usize);
                for ((&(u, v), desc), &k) in self.pos[a..b]
                    .iter()
                    .zip(&self.desc[a..b])
                    .zip(&self.items[a..b])
                {
                    // Without branches on the position (most candidates of a bin
                    // are outside the window, unpredictably): the cost of one
                    // outside is above any real one (at most 32 · 255).
                    let outside = (u < u0) | (u > u1) | (v < v0) | (v > v1);
                    let cost = sad(d, desc) | (u32::from(outside) << 31);
                    best = best.min((u64::from(cost) << 32) | u64::from(k));
                }
            }
        }
        (best >> 32 < 1 << 31).then_some((best & u64::from(u32::MAX)) as usize)
    }
}

/// The features of one image at one scale, with their index.
#[derive(Clone, Debug, Default)]
pub struct Indexed {
    /// The features.
    pub features: Features,
    /// Their bins.
    pub bins: Bins,
}

/// Disparity signs of stereo matches found along the rows in both directions:
/// `(negative, positive)` counts of matches more than a pixel off zero, over at
/// most `samples` features of `left` spread through the image. A rectified pair
/// has the right image's features to the left (positive disparity); swapped
/// images, mostly negative ones.
pub fn disparity_signs(
    left: &Indexed,
    right: &Indexed,
    radius: i32,
    row_tolerance: i32,
    samples: usize,
) -> (usize, usize) {
    let f = &left.features;
    let step = (f.len() / samples.max(1)).max(1);
    let (mut negative, mut positive) = (0, 0);
    for i in (0..f.len()).step_by(step) {
        let (u, v) = (f.u[i], f.v[i]);
        let window = (u - radius, u + radius, v - row_tolerance, v + row_tolerance);
        if let Some(k) = right.bins.best(f.class[i], &f.desc[i], window) {
            let d = u - right.features.u[k];
            if d > 1 {
                positive += 1;
            } else if d < -1 {
                negative += 1;
            }
        }
    }
    (negative, positive)
}

/// Search settings of one pass.
#[derive(Clone, Copy, Debug)]
pub struct Search {
    /// Half-width of the temporal search window [px, matching resolution].
    pub radius: i32,
    /// Row tolerance of the stereo legs [px].
    pub row_tolerance: i32,
}

/// The four legs of the circle.
const LEGS: usize = 4;

/// Expected displacements `[du_lo, du_hi, dv_lo, dv_hi]` per leg and bin, from a
/// sparse pass.
#[derive(Clone, Debug, Default)]
pub struct Ranges {
    size: i32,
    cols: i32,
    rows: i32,
    /// Per leg, per bin: `[du_lo, du_hi, dv_lo, dv_hi]`, or `None` without data.
    data: Vec<Option<[i32; 4]>>,
    /// After spreading to neighbours and widening.
    ranges: Vec<Option<[i32; 4]>>,
}

impl Ranges {
    /// Ranges from `quads` (positions of the four images, matching resolution).
    pub fn from_quads(
        quads: &[[(i32, i32); 4]],
        w: usize,
        h: usize,
        size: usize,
        min_width: i32,
    ) -> Ranges {
        let mut r = Ranges::default();
        r.rebuild(quads, w, h, size, min_width);
        r
    }

    /// [`Ranges::from_quads`] into this one's buffers (no allocation once grown).
    pub fn rebuild(
        &mut self,
        quads: &[[(i32, i32); 4]],
        w: usize,
        h: usize,
        size: usize,
        min_width: i32,
    ) {
        let size = size.max(1) as i32;
        let (cols, rows) = ((w as i32 + size - 1) / size, (h as i32 + size - 1) / size);
        let n = (cols * rows) as usize;
        let r = self;
        (r.size, r.cols, r.rows) = (size, cols, rows);
        for v in [&mut r.data, &mut r.ranges] {
            v.clear();
            v.resize(LEGS * n, None);
        }
        for q in quads {
            for leg in 0..LEGS {
                let (s, t) = (q[leg], q[(leg + 1) % LEGS]);
                let (du, dv) = (t.0 - s.0, t.1 - s.1);
                let b = r.bin(leg, s.0, s.1);
                let e = r.data[b].get_or_insert([du, du, dv, dv]);
                *e = [e[0].min(du), e[1].max(du), e[2].min(dv), e[3].max(dv)];
            }
        }
        for leg in 0..LEGS {
            for bv in 0..rows {
                for bu in 0..cols {
                    let mut acc: Option<[i32; 4]> = None;
                    for nv in (bv - 1).max(0)..=(bv + 1).min(rows - 1) {
                        for nu in (bu - 1).max(0)..=(bu + 1).min(cols - 1) {
                            if let Some(d) = r.data[leg * n + (nv * cols + nu) as usize] {
                                let a = acc.get_or_insert(d);
                                *a = [
                                    a[0].min(d[0]),
                                    a[1].max(d[1]),
                                    a[2].min(d[2]),
                                    a[3].max(d[3]),
                                ];
                            }
                        }
                    }
                    r.ranges[leg * n + (bv * cols + bu) as usize] = acc.map(|mut a| {
                        for k in [0, 2] {
                            let width = a[k + 1] - a[k];
                            if width < min_width {
                                let grow = (min_width - width + 1) / 2;
                                a[k] -= grow;
                                a[k + 1] += grow;
                            }
                        }
                        a
                    });
                }
            }
        }
    }

    fn bin(&self, leg: usize, u: i32, v: i32) -> usize {
        let bu = (u / self.size).clamp(0, self.cols - 1);
        let bv = (v / self.size).clamp(0, self.rows - 1);
        leg * (self.cols * self.rows) as usize + (bv * self.cols + bu) as usize
    }

    fn get(&self, leg: usize, u: i32, v: i32) -> Option<[i32; 4]> {
        self.ranges[self.bin(leg, u, v)]
    }
}

/// The four images' features of one scale: previous left, previous right, current
/// right, current left (the order of the circle).
pub struct Circle<'a> {
    /// `[prev_left, prev_right, curr_right, curr_left]`.
    pub images: [&'a Indexed; 4],
}

impl Circle<'_> {
    /// The window to search for the next image of `leg` from position `(u, v)`.
    fn window(
        &self,
        leg: usize,
        u: i32,
        v: i32,
        s: &Search,
        ranges: Option<&Ranges>,
    ) -> (i32, i32, i32, i32) {
        let r = s.radius;
        let range = ranges.and_then(|rs| rs.get(leg, u, v));
        match leg {
            // Stereo: same row (± tolerance), the right image to the left.
            0 => {
                let (lo, hi) = range.map_or((-r, 0), |g| (g[0].max(-r), g[1].min(0)));
                (u + lo, u + hi, v - s.row_tolerance, v + s.row_tolerance)
            }
            2 => {
                let (lo, hi) = range.map_or((0, r), |g| (g[0].max(0), g[1].min(r)));
                (u + lo, u + hi, v - s.row_tolerance, v + s.row_tolerance)
            }
            // Time.
            _ => match range {
                Some(g) => (u + g[0], u + g[1], v + g[2], v + g[3]),
                None => (u - r, u + r, v - r, v + r),
            },
        }
    }

    /// Every closed circle: indices of the feature in each image.
    pub fn matches(&self, s: &Search, ranges: Option<&Ranges>, out: &mut Vec<[usize; 4]>) {
        out.clear();
        let start = &self.images[0].features;
        'next: for i in 0..start.len() {
            let class = start.class[i];
            let mut k = [i, 0, 0, 0];
            let mut at = i;
            for leg in 0..LEGS {
                let from = &self.images[leg].features;
                let to = self.images[(leg + 1) % LEGS];
                let window = self.window(leg, from.u[at], from.v[at], s, ranges);
                let Some(next) = to.bins.best(class, &from.desc[at], window) else {
                    continue 'next;
                };
                if leg < 3 {
                    k[leg + 1] = next;
                }
                at = next;
            }
            if at == i {
                out.push(k);
            }
        }
    }

    /// Positions of a circle's features at full resolution
    /// ([`Features::full_position`]). The current left one is the anchor the
    /// refinement aligns the others to: at its feature's peak (see
    /// [`Features::peak`]).
    pub fn full_positions(&self, k: &[usize; 4], scale: usize) -> [(f64, f64); 4] {
        std::array::from_fn(|m| self.images[m].features.full_position(k[m], scale))
    }

    /// Positions of a circle's features, matching resolution.
    pub fn positions(&self, k: &[usize; 4]) -> [(i32, i32); 4] {
        std::array::from_fn(|m| {
            (
                self.images[m].features.u[k[m]],
                self.images[m].features.v[k[m]],
            )
        })
    }
}

/// How matches are refined at full resolution.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum Refinement {
    /// Keep the matching positions (scaled to full resolution).
    None,
    /// The best integer offset within ±2 px.
    Pixel,
    /// A parabola fitted to the costs around the best offset of a ±3 px grid.
    Subpixel,
    /// Lucas–Kanade alignment of the intensities ([`photometric`]), from the
    /// matching positions. (A subpixel pass before it, as this was until
    /// 2026-11-26, drifted more and took longer: README, visual odometry.)
    Photometric,
}

/// The `S × S` patch of `img` centred on `(u, v)` (`S` odd), bilinearly
/// interpolated (one fractional offset for the whole patch, so the weights are
/// computed once), into `out` row by row; `false` if the patch (with a 1-pixel
/// rim) leaves the image. In `f32` (ample for 8-bit pixels) and of a size known at
/// compile time, so that each row is a few vector operations.
#[inline]
fn patch<const S: usize>(
    img: &super::features::Gray,
    u: f64,
    v: f64,
    out: &mut [[f32; S]; S],
) -> bool {
    let r = (S / 2) as i64;
    let (u0, v0) = (u.floor(), v.floor());
    let (a, b) = ((u - u0) as f32, (v - v0) as f32);
    let (i, j) = (u0 as i64 - r, v0 as i64 - r);
    let side = S as i64;
    if i < 1 || j < 1 || i + side + 1 >= img.w as i64 || j + side + 1 >= img.h as i64 {
        return false;
    }
    let (w00, w10, w01, w11) = ((1.0 - a) * (1.0 - b), a * (1.0 - b), (1.0 - a) * b, a * b);
    let w = img.w;
    let row = |y: usize, dx: usize| -> &[u8; S] {
        let start = (j as usize + y) * w + i as usize + dx;
        // In the image: checked above.
        img.data[start..start + S].try_into().unwrap_or(&[0; S])
    };
    for (y, o) in out.iter_mut().enumerate() {
        let (t0, t1, b0, b1) = (row(y, 0), row(y, 1), row(y + 1, 0), row(y + 1, 1));
        for x in 0..S {
            o[x] = w00 * f32::from(t0[x])
                + w10 * f32::from(t1[x])
                + w01 * f32::from(b0[x])
                + w11 * f32::from(b1[x]);
        }
    }
    true
}

/// Side of the Lucas–Kanade patches.
const LK: usize = 9;

/// The template of a Lucas–Kanade alignment: the mean-subtracted 9 × 9 patch, its
/// gradients and the Gauss–Newton matrix they make (inverse compositional: fixed
/// for every target aligned with it).
pub struct Template {
    tv: [f32; LK * LK],
    gx: [f32; LK * LK],
    gy: [f32; LK * LK],
    h: (f64, f64, f64),
    det: f64,
}

impl Template {
    /// The template of `image` at `t`; `None` if the patch leaves the image, or is
    /// flat or one-dimensional (an edge: it cannot be aligned), or not finite.
    pub fn new(image: &super::features::Gray, t: (f64, f64)) -> Option<Template> {
        const S: usize = LK;
        // The patch with a 1-pixel rim for its central differences.
        let mut tb = [[0.0f32; S + 2]; S + 2];
        if !patch(image, t.0, t.1, &mut tb) {
            return None;
        }
        let (mut tv, mut gx, mut gy) = ([0.0f32; S * S], [0.0f32; S * S], [0.0f32; S * S]);
        for y in 0..S {
            for x in 0..S {
                tv[y * S + x] = tb[y + 1][x + 1];
                gx[y * S + x] = 0.5 * (tb[y + 1][x + 2] - tb[y + 1][x]);
                gy[y * S + x] = 0.5 * (tb[y + 2][x + 1] - tb[y][x + 1]);
            }
        }
        let mean_t = tv.iter().sum::<f32>() / (S * S) as f32;
        for x in tv.iter_mut() {
            *x -= mean_t;
        }
        let (mut h00, mut h01, mut h11) = (0.0f32, 0.0f32, 0.0f32);
        for (x, y) in gx.iter().zip(&gy) {
            h00 += x * x;
            h01 += x * y;
            h11 += y * y;
        }
        let (h00, h01, h11) = (f64::from(h00), f64::from(h01), f64::from(h11));
        let det = h00 * h11 - h01 * h01;
        if det.is_nan() || det <= 1e-9 * (h00 + h11).powi(2).max(1e-12) {
            return None;
        }
        Some(Template {
            tv,
            gx,
            gy,
            h: (h00, h01, h11),
            det,
        })
    }

    /// Align the 9 × 9 patch of `target` at `p` with the template (translation
    /// only, on mean-subtracted intensities); `None` if it does not converge,
    /// leaves the image or moves more than a pixel and a half. Intensities and sums
    /// in `f32`, the position in `f64`.
    pub fn align(&self, target: &super::features::Gray, p: (f64, f64)) -> Option<(f64, f64)> {
        let n = (LK * LK) as f32;
        let (h00, h01, h11) = self.h;
        let det = self.det;
        let mut q = p;
        let mut iv = [[0.0f32; LK]; LK];
        for _ in 0..10 {
            if !patch(target, q.0, q.1, &mut iv) {
                return None;
            }
            let iv = iv.as_flattened();
            let mean_i = dot(iv, None) / n;
            let mut e = [0.0f32; LK * LK];
            for ((e, i), t) in e.iter_mut().zip(iv).zip(&self.tv) {
                *e = (i - mean_i) - t;
            }
            let (b0, b1) = (
                f64::from(dot(&self.gx, Some(&e))),
                f64::from(dot(&self.gy, Some(&e))),
            );
            let (du, dv) = ((h11 * b0 - h01 * b1) / det, (-h01 * b0 + h00 * b1) / det);
            q = (q.0 - du, q.1 - dv);
            if !(q.0.is_finite() && q.1.is_finite())
                || (q.0 - p.0).abs() > 1.5
                || (q.1 - p.1).abs() > 1.5
            {
                return None;
            }
            // Converged at a hundredth of a pixel (below the noise of real pixels):
            // a thousandth dropped more matches that had not settled in ten steps,
            // and drifted more on every tuning sequence (README, visual odometry).
            if du.abs() < 1e-2 && dv.abs() < 1e-2 {
                return Some(q);
            }
        }
        None
    }
}

/// Align the 9 × 9 patch of `target` at `p` with the patch of `template` at `t`
/// ([`Template::new`], [`Template::align`]).
pub fn lucas_kanade(
    template: &super::features::Gray,
    t: (f64, f64),
    target: &super::features::Gray,
    p: (f64, f64),
) -> Option<(f64, f64)> {
    Template::new(template, t)?.align(target, p)
}

/// `Σ a[k]·b[k]` (`b` all ones when `None`), summed in eight independent lanes so
/// that the compiler vectorises it (one `f32` accumulator must be summed in order).
#[inline]
fn dot(a: &[f32], b: Option<&[f32]>) -> f32 {
    let mut acc = [0.0f32; 8];
    let chunks = a.chunks_exact(8);
    let rest = chunks.remainder();
    let tail: f32 = match b {
        Some(b) => {
            let b_chunks = b.chunks_exact(8);
            let tail = rest
                .iter()
                .zip(b_chunks.remainder())
                .map(|(x, y)| x * y)
                .sum();
            for (x, y) in chunks.zip(b_chunks) {
                for l in 0..8 {
                    acc[l] += x[l] * y[l];
                }
            }
            tail
        }
        None => {
            for x in chunks {
                for l in 0..8 {
                    acc[l] += x[l];
                }
            }
            rest.iter().sum()
        }
    };
    acc.iter().sum::<f32>() + tail
}

/// Refine the positions in the previous left, previous right and current right
/// images relative to the current left one (full resolution, gradients `grads` in
/// the circle's order). `None` drops the match.
pub fn refine(
    p: [(f64, f64); 4],
    grads: [&Gradients; 4],
    mode: Refinement,
) -> Option<[(f64, f64); 4]> {
    if mode == Refinement::None {
        return Some(p);
    }
    let g = grads[3];
    let (cu, cv) = (p[3].0 as i32, p[3].1 as i32);
    let reach = if mode == Refinement::Pixel { 2 } else { 3 };
    let inside = |gr: &Gradients, u: i32, v: i32| {
        u - reach - 2 >= 0
            && v - reach - 2 >= 0
            && u + reach + 2 < gr.w as i32
            && v + reach + 2 < gr.h as i32
    };
    if !inside(g, cu, cv) {
        return None;
    }
    let target = g.refine_descriptor(cu, cv);
    let mut out = p;
    for m in 0..3 {
        let gr = grads[m];
        let (u, v) = (p[m].0.round() as i32, p[m].1.round() as i32);
        if !inside(gr, u, v) {
            return None;
        }
        // The costs of the (2·reach + 1)² grid, each computed once (reach ≤ 3).
        let side = (2 * reach + 1) as usize;
        let mut costs = [0u32; 49];
        if reach == 3 {
            costs = gr.refine_costs(&target, u, v);
        } else {
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    costs[(dy + reach) as usize * side + (dx + reach) as usize] =
                        sad(&target, &gr.refine_descriptor(u + dx, v + dy));
                }
            }
        }
        let mut best = (u32::MAX, 0, 0);
        for dy in -reach..=reach {
            for dx in -reach..=reach {
                let c = costs[(dy + reach) as usize * side + (dx + reach) as usize];
                if c < best.0 {
                    best = (c, dx, dy);
                }
            }
        }
        let (_, bx, by) = best;
        if mode == Refinement::Pixel {
            out[m] = (f64::from(u + bx), f64::from(v + by));
            continue;
        }
        if bx.abs() == reach || by.abs() == reach {
            return None;
        }
        // c(x, y) = a x² + b y² + c xy + d x + e y + g over the 3 × 3 costs.
        let c = |x: i32, y: i32| {
            f64::from(costs[(by + y + reach) as usize * side + (bx + x + reach) as usize])
        };
        let col = |x: i32| c(x, -1) + c(x, 0) + c(x, 1);
        let row = |y: i32| c(-1, y) + c(0, y) + c(1, y);
        let d = (col(1) - col(-1)) / 6.0;
        let e = (row(1) - row(-1)) / 6.0;
        let a = (col(1) + col(-1) - 2.0 * col(0)) / 6.0;
        let b = (row(1) + row(-1) - 2.0 * row(0)) / 6.0;
        let cxy = (c(1, 1) - c(1, -1) - c(-1, 1) + c(-1, -1)) / 4.0;
        let det = 4.0 * a * b - cxy * cxy;
        if !(a > 0.0 && det > 0.0) {
            return None;
        }
        // [2a c; c 2b] [x; y] = −[d; e]
        let x = (-d * 2.0 * b + cxy * e) / det;
        let y = (-2.0 * a * e + cxy * d) / det;
        if !(x.abs() < 1.0 && y.abs() < 1.0) {
            return None;
        }
        out[m] = (f64::from(u + bx) + x, f64::from(v + by) + y);
    }
    Some(out)
}

/// Align the previous left, previous right and current right positions of a match
/// with the current left one by [`lucas_kanade`] (9 × 9 patches); `None` drops it.
pub fn photometric(
    p: [(f64, f64); 4],
    images: [&super::features::Gray; 4],
) -> Option<[(f64, f64); 4]> {
    let template = Template::new(images[3], p[3])?;
    let mut out = p;
    for m in 0..3 {
        out[m] = template.align(images[m], p[m])?;
    }
    Some(out)
}

/// Reusable buffers of [`bucket_refined`] (no allocation once they have grown).
#[derive(Clone, Debug, Default)]
pub struct BucketScratch {
    /// Per bucket of the grid: the order of its first candidate, or `usize::MAX`.
    first: Vec<usize>,
    /// `(bucket order, candidate)`, sorted.
    order: Vec<(usize, usize)>,
    /// Each bucket's range of `order`.
    groups: Vec<(usize, usize)>,
}

/// Keep at most `per_bucket` matches per `size × size` bucket of the current left
/// positions (full resolution), chosen by a seeded shuffle; a candidate counts only
/// if `accept` (its refinement) keeps it. Candidates are refined lazily: a bucket
/// stops refining once it is full, so a crowded bucket costs `per_bucket`
/// refinements and a few failures, not one per candidate. The result (in `out`,
/// replaced) is grouped by bucket (in the order of their first candidate after the
/// shuffle), each group in shuffled order; the same for any number of `threads`.
/// On one thread nothing is allocated once `scratch` and `out` have grown.
#[allow(clippy::too_many_arguments)]
pub fn bucket_refined(
    candidates: &mut [[(f64, f64); 4]],
    size: f64,
    per_bucket: usize,
    rng: &mut Rng,
    threads: usize,
    scratch: &mut BucketScratch,
    out: &mut Vec<[(f64, f64); 4]>,
    accept: impl Fn(&[(f64, f64); 4]) -> Option<[(f64, f64); 4]> + Sync,
) {
    out.clear();
    // Shuffle (Fisher–Yates).
    for i in (1..candidates.len()).rev() {
        let j = (rng.next_u64() % (i as u64 + 1)) as usize;
        candidates.swap(i, j);
    }
    // Group by bucket, keeping the shuffled order within each (a sort on the order
    // of each bucket's first appearance, then the candidate's).
    let cell = |x: f64| (x / size).floor().max(0.0) as usize;
    let cols = candidates.iter().map(|m| cell(m[3].0)).max().unwrap_or(0) + 1;
    let rows = candidates.iter().map(|m| cell(m[3].1)).max().unwrap_or(0) + 1;
    let BucketScratch {
        first,
        order,
        groups,
    } = scratch;
    first.clear();
    first.resize(cols * rows, usize::MAX);
    order.clear();
    let mut buckets = 0;
    for (i, m) in candidates.iter().enumerate() {
        let b = &mut first[cell(m[3].1) * cols + cell(m[3].0)];
        if *b == usize::MAX {
            *b = buckets;
            buckets += 1;
        }
        order.push((*b, i));
    }
    order.sort_unstable();
    groups.clear();
    let mut a = 0;
    for b in 1..=order.len() {
        if b == order.len() || order[b].0 != order[a].0 {
            groups.push((a, b));
            a = b;
        }
    }
    let candidates = &*candidates;
    let order = &*order;
    let fill = |(a, b): (usize, usize), out: &mut Vec<[(f64, f64); 4]>| {
        let mut kept = 0;
        for &(_, i) in &order[a..b] {
            if kept == per_bucket {
                break;
            }
            if let Some(m) = accept(&candidates[i]) {
                out.push(m);
                kept += 1;
            }
        }
    };
    if threads <= 1 {
        for &g in groups.iter() {
            fill(g, out);
        }
    } else {
        let kept = super::filter_map_parallel(groups, threads, |&g| {
            let mut v = Vec::with_capacity(per_bucket.min(g.1 - g.0));
            fill(g, &mut v);
            Some(v)
        });
        out.extend(kept.into_iter().flatten());
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::vo::features::Gray;

    /// A smooth, lopsided scene (two Gaussian blobs of different widths and
    /// heights: a corner-like patch whose bright side is off-centre), moved by
    /// `(du, dv)` and seen with `gain` and `offset`.
    fn scene(du: f64, dv: f64, gain: f64, offset: f64) -> Gray {
        let (w, h) = (48, 48);
        let f = |u: f64, v: f64| {
            let g = |cu: f64, cv: f64, s: f64| {
                (-((u - cu).powi(2) + (v - cv).powi(2)) / (2.0 * s * s)).exp()
            };
            40.0 + 150.0 * g(23.0, 22.0, 2.5) + 60.0 * g(27.0, 26.0, 4.0)
        };
        Gray {
            w,
            h,
            data: (0..w * h)
                .map(|i| {
                    let (u, v) = ((i % w) as f64 - du, (i / w) as f64 - dv);
                    (gain * f(u, v) + offset).round().clamp(0.0, 255.0) as u8
                })
                .collect(),
        }
    }

    #[test]
    fn lucas_kanade_finds_a_subpixel_shift_through_an_offset() {
        let template = scene(0.0, 0.0, 1.0, 0.0);
        let (du, dv) = (0.4, -0.3);
        // (A gain between the images biases it: 0.1 px at 0.8. Scaling the
        // target's contrast to the template's removed that here but drifted
        // more on the held-out tours of bench_vo; see the README.)
        for (gain, offset) in [(1.0, 0.0), (1.0, 20.0), (1.0, -15.0)] {
            let target = scene(du, dv, gain, offset);
            // Started at the integer position, as the subpixel pass leaves it.
            let q = lucas_kanade(&template, (24.0, 24.0), &target, (24.0, 24.0))
                .unwrap_or_else(|| panic!("gain {gain}, offset {offset}: no alignment"));
            let err = ((q.0 - 24.0 - du).powi(2) + (q.1 - 24.0 - dv).powi(2)).sqrt();
            assert!(
                err < 0.05,
                "gain {gain}, offset {offset}: {q:?}, {err:.3} px off"
            );
        }
    }

    #[test]
    fn bucketing_refines_lazily_and_keeps_at_most_the_quota() {
        // 600 candidates in 6 buckets of 50 px; every fifth refinement fails.
        let candidates: Vec<[(f64, f64); 4]> = (0..600)
            .map(|i| {
                let p = (
                    f64::from(i % 3) * 50.0 + 7.0,
                    f64::from(i % 2) * 50.0 + f64::from(i % 40),
                );
                [(f64::from(i), 0.0), (0.0, 0.0), (0.0, 0.0), p]
            })
            .collect();
        let run = |threads: usize| {
            let calls = std::sync::atomic::AtomicUsize::new(0);
            let mut c = candidates.clone();
            let mut kept = Vec::new();
            let mut scratch = BucketScratch::default();
            bucket_refined(
                &mut c,
                50.0,
                8,
                &mut Rng::new(3),
                threads,
                &mut scratch,
                &mut kept,
                |m| {
                    calls.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
                    (m[0].0 as i64 % 5 != 0).then_some(*m)
                },
            );
            (kept, calls.into_inner())
        };
        let (kept, calls) = run(1);
        assert_eq!(kept.len(), 6 * 8, "8 from each bucket");
        assert!(
            kept.iter().all(|m| m[0].0 as i64 % 5 != 0),
            "only accepted ones"
        );
        let mut per_bucket = std::collections::HashMap::new();
        for m in &kept {
            *per_bucket
                .entry(((m[3].0 / 50.0) as i64, (m[3].1 / 50.0) as i64))
                .or_insert(0) += 1;
        }
        assert!(per_bucket.values().all(|&n| n == 8), "{per_bucket:?}");
        // Lazily: each bucket stops at its quota (8 of about 10 refined), far
        // fewer than the 600 candidates.
        assert!(calls < 6 * 20, "{calls} refinements");
        // Any number of threads: the same matches in the same order.
        assert_eq!(run(2).0, kept);
        assert_eq!(run(4).0, kept);
    }

    #[test]
    fn lucas_kanade_refuses_a_flat_patch() {
        let flat = Gray {
            w: 32,
            h: 32,
            data: vec![90; 32 * 32],
        };
        assert_eq!(lucas_kanade(&flat, (16.0, 16.0), &flat, (16.0, 16.0)), None);
    }
}
