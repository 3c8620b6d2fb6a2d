//! Circular matching of the four images (notes `vo.md` §1.3–1.7): previous left →
//! previous right (stereo) → current right (time) → current left (stereo) → previous
//! left (time), accepted only if the loop closes on the feature it started from.
//! A sparse pass gives the displacements to expect in each part of the image; the
//! dense pass searches only there. Matches are bucketed, each bucket refining
//! its candidates at full resolution until it holds its quota.

use super::features::{CLASSES, DESCRIPTOR, Features, sad};
use crate::math::rng::Rng;

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
    fn best(&self, class: u8, d: &[u8; DESCRIPTOR], window: (i32, i32, i32, i32)) -> Option<usize> {
        self.scan(class, d, window, |_, _| 0)
    }

    /// [`Bins::best`] with `weight` added to the cost per pixel of distance from
    /// `near` (the constant-velocity prior; libviso2's weight is 4).
    #[inline]
    fn best_near(
        &self,
        class: u8,
        d: &[u8; DESCRIPTOR],
        window: (i32, i32, i32, i32),
        (near, weight): ((f32, f32), f32),
    ) -> Option<usize> {
        self.scan(class, d, window, |u, v| {
            let (du, dv) = (u as f32 - near.0, v as f32 - near.1);
            // At most 2^20: the cost stays below 2^31.
            (weight * (du * du + dv * dv).sqrt()).min(1_048_576.0) as u32
        })
    }

    /// The least `SAD + penalty(u, v)` in the window (`penalty` at most 2^20).
    #[inline(always)]
    fn scan(
        &self,
        class: u8,
        d: &[u8; DESCRIPTOR],
        (u0, u1, v0, v1): (i32, i32, i32, i32),
        penalty: impl Fn(i32, i32) -> u32,
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
                    // outside is above any real one (at most 32 · 255 + 2^20).
                    let outside = (u < u0) | (u > u1) | (v < v0) | (v > v1);
                    let cost = (sad(d, desc) + penalty(u, v)) | (u32::from(outside) << 31);
                    best = best.min((u64::from(cost) << 32) | u64::from(k));
                }
            }
        }
        (best >> 32 < 1 << 31).then_some((best & u64::from(u32::MAX)) as usize)
    }
}

/// The constant-velocity prior of the temporal legs (libviso2's, `vo.md` §1.3):
/// the last motion predicts where a previous point appears in the current right
/// image, and the closing leg prefers the feature it started from; a candidate
/// pays `weight` per pixel of distance from the prediction.
#[derive(Clone, Copy, Debug)]
pub struct MotionPrior {
    /// The last motion, `p_curr = r · p_prev + t` (left-camera frames).
    pub r: nalgebra::Matrix3<f64>,
    /// Its translation \[m\].
    pub t: nalgebra::Vector3<f64>,
    /// The calibration at matching resolution.
    pub calib: super::Calibration,
    /// Cost per pixel of distance.
    pub weight: f32,
}

impl MotionPrior {
    /// Where the point seen at `left` in the previous left image and at column
    /// `right_u` in the previous right one appears in the current right image
    /// (disparity at least 1 px), or `None` behind the camera.
    fn predict_right(&self, left: (i32, i32), right_u: i32) -> Option<(f32, f32)> {
        let c = &self.calib;
        let d = f64::from((left.0 - right_u).max(1));
        let z = c.f * c.baseline / d;
        let p = nalgebra::Vector3::new(
            (f64::from(left.0) - c.cu) * z / c.f,
            (f64::from(left.1) - c.cv) * z / c.f,
            z,
        );
        let q = self.r * p + self.t;
        (q.z > 1e-6).then(|| {
            (
                (c.f * (q.x - c.baseline) / q.z + c.cu) as f32,
                (c.f * q.y / q.z + c.cv) as f32,
            )
        })
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
    /// Half-width of the temporal search window \[px, matching resolution\].
    pub radius: i32,
    /// Row tolerance of the stereo legs \[px\].
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

    /// Every closed circle: indices of the feature in each image; with a
    /// constant-velocity `prior` on the temporal legs. The start features are
    /// split between up to `threads` threads (scoped); the circles are the same,
    /// in the same order, for any number of threads, and on one thread nothing
    /// is allocated once `out` has grown.
    pub fn matches(
        &self,
        s: &Search,
        ranges: Option<&Ranges>,
        prior: Option<&MotionPrior>,
        threads: usize,
        out: &mut Vec<[usize; 4]>,
    ) {
        out.clear();
        let n = self.images[0].features.len();
        let circle = |i: usize| self.circle(i, s, ranges, prior);
        if threads > 1 {
            out.extend(super::filter_map_range_parallel(n, threads, circle));
        } else {
            out.extend((0..n).filter_map(circle));
        }
    }

    /// The circle from start feature `i`, if it closes (see [`Self::matches`]).
    fn circle(
        &self,
        i: usize,
        s: &Search,
        ranges: Option<&Ranges>,
        prior: Option<&MotionPrior>,
    ) -> Option<[usize; 4]> {
        let start = &self.images[0].features;
        let class = start.class[i];
        let mut k = [i, 0, 0, 0];
        let mut at = i;
        for leg in 0..LEGS {
            let from = &self.images[leg].features;
            let to = self.images[(leg + 1) % LEGS];
            let window = self.window(leg, from.u[at], from.v[at], s, ranges);
            let near = prior.and_then(|p| match leg {
                1 => p
                    .predict_right((start.u[i], start.v[i]), from.u[at])
                    .map(|x| (x, p.weight)),
                3 => Some(((start.u[i] as f32, start.v[i] as f32), p.weight)),
                _ => None,
            });
            let next = match near {
                Some(near) => to.bins.best_near(class, &from.desc[at], window, near),
                None => to.bins.best(class, &from.desc[at], window),
            }?;
            if leg < 3 {
                k[leg + 1] = next;
            }
            at = next;
        }
        (at == i).then_some(k)
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
#[expect(
    clippy::too_many_arguments,
    reason = "the candidates, the bucketing, its seeded shuffle, the threads, reused storage and the refinement: one pass"
)]
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
    fn the_motion_prior_predicts_where_a_point_moves_in_the_right_image() {
        let calib = crate::algorithms::vo::Calibration {
            f: 200.0,
            cu: 159.75,
            cv: 119.75,
            baseline: 0.3,
        };
        let project = |p: nalgebra::Vector3<f64>, right: bool| {
            let x = if right { p.x - calib.baseline } else { p.x };
            (calib.f * x / p.z + calib.cu, calib.f * p.y / p.z + calib.cv)
        };
        // A point 4 m ahead; the camera moves 0.2 m forward and turns 3°.
        let p = nalgebra::Vector3::new(0.5, -0.2, 4.0);
        let r = *nalgebra::Rotation3::from_axis_angle(&nalgebra::Vector3::y_axis(), 0.05).matrix();
        let t = nalgebra::Vector3::new(0.01, 0.0, -0.2);
        let prior = MotionPrior {
            r,
            t,
            calib,
            weight: 4.0,
        };
        // Seen at integer pixels, as features are: the prediction is within the
        // rounding's effect (a pixel).
        let (l, rr) = (project(p, false), project(p, true));
        let left = (l.0.round() as i32, l.1.round() as i32);
        let got = prior.predict_right(left, rr.0.round() as i32).unwrap();
        let want = project(r * p + t, true);
        assert!(
            (f64::from(got.0) - want.0).abs() < 1.0 && (f64::from(got.1) - want.1).abs() < 1.0,
            "{got:?} vs {want:?}"
        );
        // Behind the camera after the motion: no prediction.
        let back = MotionPrior {
            t: nalgebra::Vector3::new(0.0, 0.0, -10.0),
            ..prior
        };
        assert_eq!(back.predict_right(left, rr.0.round() as i32), None);
    }
}
