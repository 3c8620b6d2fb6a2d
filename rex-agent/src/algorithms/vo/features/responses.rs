//! The blob and corner filter responses of an image and their non-maximum
//! suppression (StereoScan, notes `vo.md` §1.1).
//!
//! The responses are 16-bit: the blob filter's taps add up to at most 16·255 =
//! 4 080 either way and the corner filter's to 8·255, so every response and
//! every partial sum fits an `i16`, and the filters, the dilations and the
//! comparisons below run eight to a vector even at the baseline x86-64 level
//! (SSE2 has 16-bit `min`/`max` and compares; 32-bit `min`/`max` need SSE4.1).
//!
//! The suppression keeps, in each `(n+1) × (n+1)` block, the first (in row-major
//! order) extreme of each of the four classes when nothing in its `(2n+1) ×
//! (2n+1)` neighbourhood is more extreme. Instead of comparing each candidate's
//! neighbourhood, each map is dilated once (a separable running maximum, by
//! doubling windows) and a pixel is a local extreme where it equals its
//! dilation: the same features in the same order (tested against the
//! window-by-window scan), in fewer instructions (callgrind's counts for the
//! suppression and the filters: docs/measurements.md, "The odometry's kernels").

use super::{Features, Gradients, Gray, vertex};

/// The blob and corner responses of an image, and the suppression's scratch.
#[derive(Clone, Debug, Default)]
pub struct Responses {
    w: usize,
    h: usize,
    /// Blob response: centre-surround (`−Σ5×5 + 2·Σ3×3 + 7·centre`); zero on the
    /// 2-pixel border.
    pub blob: Vec<i16>,
    /// Corner (checkerboard) response: the diagonal 2 × 2 quadrants of the 5 × 5
    /// window against the anti-diagonal ones; zero on the 2-pixel border.
    pub corner: Vec<i16>,
    /// Horizontal sums of 2, 3 and 5 pixels, and the 2 × 2 sums.
    sums: [Vec<i16>; 4],
    /// The map being dilated (padded), the two buffers of its passes, and its
    /// dilations at each window size.
    padded: Vec<i16>,
    pass: [Vec<i16>; 2],
    wide: [Vec<i16>; 2],
    /// Per pixel of the valid area (padded stride): bit `c + 4k` where class `c`
    /// has a local extreme at window size `k` that reaches the threshold.
    mask: Vec<u16>,
}

/// Row `r` of a row-major map of width `w`, columns `c0..c0 + n`.
fn row<T>(map: &[T], w: usize, r: usize, c0: usize, n: usize) -> &[T] {
    &map[r * w + c0..r * w + c0 + n]
}

impl Responses {
    /// Compute both responses of `img` (zero on the 2-pixel border).
    #[inline(always)]
    pub fn compute(&mut self, img: &Gray) {
        let (w, h) = (img.w, img.h);
        self.w = w;
        self.h = h;
        self.blob.clear();
        self.blob.resize(w * h, 0);
        self.corner.clear();
        self.corner.resize(w * h, 0);
        if w < 5 || h < 5 {
            return;
        }
        let [s2, s3, s5, q] = &mut self.sums;
        for s in [&mut *s2, &mut *s3, &mut *s5, &mut *q] {
            s.resize(w * h, 0);
        }
        // Horizontal sums: s2 over columns u..=u+1 (u < w−1), s3 over u−1..=u+1
        // and s5 over u−2..=u+2 (2 ≤ u < w−2; s3 is read only there).
        for ((p, (r2, r3)), r5) in img
            .data
            .chunks_exact(w)
            .zip(s2.chunks_exact_mut(w).zip(s3.chunks_exact_mut(w)))
            .zip(s5.chunks_exact_mut(w))
        {
            for (win, o) in p.windows(2).zip(r2.iter_mut()) {
                *o = i16::from(win[0]) + i16::from(win[1]);
            }
            for ((win, o3), o5) in p.windows(5).zip(&mut r3[2..]).zip(&mut r5[2..]) {
                let x = |k: usize| i16::from(win[k]);
                let inner = x(1) + x(2) + x(3);
                *o3 = inner;
                *o5 = inner + x(0) + x(4);
            }
        }
        // 2 × 2 sums: q at (u, v) covers columns u..=u+1, rows v..=v+1.
        for v in 0..h - 1 {
            let (a, b) = (row(s2, w, v, 0, w - 1), row(s2, w, v + 1, 0, w - 1));
            for ((o, &a), &b) in q[v * w..v * w + w - 1].iter_mut().zip(a).zip(b) {
                *o = a + b;
            }
        }
        // Vertical sums, one output row at a time over columns 2..w−2 (equal-length
        // slices: the loops are vectorised).
        let n = w - 4;
        for v in 2..h - 2 {
            let b5: [&[i16]; 5] = std::array::from_fn(|k| row(s5, w, v + k - 2, 2, n));
            let b3: [&[i16]; 3] = std::array::from_fn(|k| row(s3, w, v + k - 1, 2, n));
            let centre = row(&img.data, w, v, 2, n);
            let out = &mut self.blob[v * w + 2..v * w + 2 + n];
            for (u, o) in out.iter_mut().enumerate() {
                let s5 = b5[0][u] + b5[1][u] + b5[2][u] + b5[3][u] + b5[4][u];
                let s3 = b3[0][u] + b3[1][u] + b3[2][u];
                *o = -s5 + 2 * s3 + 7 * i16::from(centre[u]);
            }
            // Quadrants: top-left at (u−2, v−2), top-right (u+1, v−2), bottom-left
            // (u−2, v+1), bottom-right (u+1, v+1).
            let (tl, tr) = (row(q, w, v - 2, 0, n), row(q, w, v - 2, 3, n));
            let (bl, br) = (row(q, w, v + 1, 0, n), row(q, w, v + 1, 3, n));
            let out = &mut self.corner[v * w + 2..v * w + 2 + n];
            for (u, o) in out.iter_mut().enumerate() {
                *o = -tl[u] + tr[u] + bl[u] - br[u];
            }
        }
    }

    /// Non-maximum and non-minimum suppression in blocks of `(n+1) × (n+1)`: in each
    /// block the extreme responses of each filter are candidates, kept if nothing in
    /// their `(2n+1) × (2n+1)` neighbourhood is more extreme and their magnitude
    /// reaches `tau`. Features closer than `margin` to the border are skipped, and
    /// closer than 5 whatever `margin` (the descriptor's reach: a smaller margin
    /// read outside the gradients).
    /// Replaces `out` with the features, descriptors from `grad`.
    pub fn suppress(
        &mut self,
        n: usize,
        tau: i32,
        margin: usize,
        grad: &Gradients,
        out: &mut Features,
    ) {
        self.suppress_scales((n, out), None, tau, margin, grad);
    }

    /// [`suppress`](Responses::suppress) at two window sizes at once (libviso2's
    /// dense and sparse features): the larger windows' extremes are the smaller
    /// ones' joined (two passes an axis from 7 to 19 or 21 instead of five from 1).
    #[inline(always)]
    pub fn suppress_scales(
        &mut self,
        dense: (usize, &mut Features),
        sparse: Option<(usize, &mut Features)>,
        tau: i32,
        margin: usize,
        grad: &Gradients,
    ) {
        let margin = margin.max(5);
        let (w, h) = (self.w, self.h);
        // The window sizes that fit the image, in front (no allocation).
        let mut scales: [Option<(usize, &mut Features)>; 2] = [None, None];
        let (mut ns, mut count) = ([0usize; 2], 0);
        for (n, out) in std::iter::once(dense).chain(sparse) {
            out.clear();
            if w > 2 * (n + margin) && h > 2 * (n + margin) {
                (scales[count], ns[count]) = (Some((n, out)), n);
                count += 1;
            }
        }
        let ns = &ns[..count];
        let Some(&pad) = ns.iter().max() else {
            return;
        };
        // The valid area [lo, hi) in each axis, padded by `pad` on every side.
        let (lo_u, hi_u) = (margin, w - margin);
        let (lo_v, hi_v) = (margin, h - margin);
        let pw = hi_u - lo_u + 2 * pad;
        let ph = hi_v - lo_v + 2 * pad;
        // |response| ≤ 4 080: a threshold beyond the i16 range keeps all or none,
        // as its clamp does.
        let tau = tau.clamp(-i32::from(i16::MAX), i32::from(i16::MAX)) as i16;
        let Responses {
            blob,
            corner,
            padded,
            pass,
            wide,
            mask,
            ..
        } = self;
        mask.clear();
        mask.resize(pw * ph, 0);
        // Mask index i is the valid pixel (lo_u + i % pw, lo_v + i / pw), padded
        // index i + off(pad); the window of radius r around it starts at
        // i + off(pad − r).
        let off = |r: usize| r * (pw + 1);
        // i16::MIN around the valid area (outside every neighbourhood, which is
        // clipped to the valid area), filled once: each class rewrites only the
        // valid area.
        padded.clear();
        padded.resize(pw * ph, i16::MIN);
        for class in 0..4 {
            let map = if class < 2 { &*blob } else { &*corner };
            // A minimum is a maximum of the negated map (exact: |x| ≤ 4 080).
            let sign: i16 = if class % 2 == 1 { 1 } else { -1 };
            // The signed map in the valid area.
            for v in lo_v..hi_v {
                let src = row(map, w, v, lo_u, hi_u - lo_u);
                let dst = &mut padded[(v - lo_v + pad) * pw + pad..][..hi_u - lo_u];
                for (d, &x) in dst.iter_mut().zip(src) {
                    *d = sign * x;
                }
            }
            // Each window size from the largest smaller one computed (or from 1).
            for (k, &n) in ns.iter().enumerate() {
                let base = (0..k).filter(|&b| ns[b] <= n).max_by_key(|&b| ns[b]);
                let (done, rest) = wide.split_at_mut(k);
                match base {
                    Some(b) => widen(&done[b], pw, 2 * ns[b] + 1, 2 * n + 1, pass),
                    None => widen(padded, pw, 1, 2 * n + 1, pass),
                }
                std::mem::swap(&mut rest[0], &mut pass[0]);
                let bit = 1u16 << (class + 4 * k);
                let (x, d) = (&padded[off(pad)..], &wide[k][off(pad - n)..]);
                let len = x.len().min(d.len());
                let (m, x, d) = (&mut mask[..len], &x[..len], &d[..len]);
                for i in 0..len {
                    let keep = i16::from(x[i] == d[i]) & i16::from(x[i] >= tau);
                    m[i] |= bit & keep.wrapping_neg() as u16;
                }
            }
        }
        let at = |u: usize, v: usize| (v - lo_v) * pw + (u - lo_u);
        let maps = [&*blob, &*blob, &*corner, &*corner];
        for (k, (n, out)) in scales.into_iter().flatten().enumerate() {
            // Blocks [i, i+n] × [j, j+n], columns outer, as libviso2 walks them.
            let step = n + 1;
            let mut i = n + margin;
            while i + n < hi_u {
                let mut j = n + margin;
                while j + n < hi_v {
                    let any = (j..=j + n).fold(0u16, |acc, v| {
                        acc | mask[at(i, v)..=at(i + n, v)].iter().fold(0, |a, &m| a | m)
                    }) >> (4 * k);
                    for class in 0..4u8 {
                        if any & (1 << class) != 0 {
                            let bit = 1u16 << (class + 4 * k as u8);
                            let first = (j..=j + n).find_map(|v| {
                                mask[at(i, v)..=at(i + n, v)]
                                    .iter()
                                    .position(|&m| m & bit != 0)
                                    .map(|c| (i + c, v))
                            });
                            if let Some(p) = first {
                                keep(maps[usize::from(class)], w, class, (i, j, n), p, grad, out);
                            }
                        }
                    }
                    j += step;
                }
                i += step;
            }
        }
    }
}

/// Keep block `(i, j)`'s feature of `class` at its first masked pixel `(u, v)`,
/// if that is the block's first extreme: an earlier pixel of the same value
/// would be the scan's candidate, and it is not a local extreme (or it would be
/// the first masked one), so the scan keeps nothing there.
fn keep(
    map: &[i16],
    w: usize,
    class: u8,
    (i, j, n): (usize, usize, usize),
    (u, v): (usize, usize),
    grad: &Gradients,
    out: &mut Features,
) {
    let val = map[v * w + u];
    let earlier = |vv: usize, end: usize| map[vv * w + i..vv * w + end].contains(&val);
    if (j..v).any(|vv| earlier(vv, i + n + 1)) || earlier(v, u) {
        return;
    }
    let x = |uu: usize, vv: usize| i32::from(map[vv * w + uu]);
    out.u.push(u as i32);
    out.v.push(v as i32);
    out.class.push(class);
    out.desc.push(grad.descriptor(u, v));
    // Neighbours inside: the margin is at least 5.
    out.peak.push((
        vertex(x(u - 1, v), x(u, v), x(u + 1, v)),
        vertex(x(u, v - 1), x(u, v), x(u, v + 1)),
    ));
}

/// Running maxima over windows: `src` (row-major, width `w`) holds at index `i`
/// the maximum of the `from × from` window whose top-left corner is at `i`;
/// `bufs[0]` receives the same for `to × to` windows (`to ≥ from`; meaningful
/// where the window lies inside the map). Windows double (`from`, `2·from`, …)
/// and a last pass joins two overlapping ones, in each axis: `⌈log₂(to/from)⌉`
/// passes an axis, each a vectorised maximum of two slices.
#[inline(always)]
fn widen(src: &[i16], w: usize, from: usize, to: usize, bufs: &mut [Vec<i16>; 2]) {
    let len = src.len();
    let mut first = true;
    for stride in [1, w] {
        let mut span = from;
        while span < to {
            // Join windows `shift` apart: 2·span wide, or the last to − span.
            let shift = span.min(to - span);
            span += shift;
            let reach = (shift * stride).min(len);
            let [a, b] = &mut *bufs;
            let input: &[i16] = if first { src } else { a };
            b.resize(len, i16::MIN);
            for ((o, &x), &y) in b[..len - reach].iter_mut().zip(input).zip(&input[reach..]) {
                *o = x.max(y);
            }
            std::mem::swap(a, b);
            first = false;
        }
    }
    if first {
        bufs[0].clear();
        bufs[0].extend_from_slice(src);
    }
}

#[cfg(test)]
#[path = "responses_tests.rs"]
mod tests;
