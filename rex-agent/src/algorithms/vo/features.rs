//! Features of a grey image (StereoScan, notes `vo.md` §1.1–1.2): a blob and a
//! corner filter response, non-maximum suppression in blocks ([`Responses`]),
//! four classes (blob min/max, corner min/max), and a 32-byte descriptor of
//! gradient samples around each feature, compared by the sum of absolute
//! differences.

mod responses;

pub use responses::Responses;

/// Bytes of a matching descriptor.
pub const DESCRIPTOR: usize = 32;

/// A grey image, row-major, one byte per pixel.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Gray {
    /// Width \[px\].
    pub w: usize,
    /// Height \[px\].
    pub h: usize,
    /// Pixels.
    pub data: Vec<u8>,
}

impl Gray {
    /// The pixel at `(u, v)`.
    #[inline]
    pub fn at(&self, u: usize, v: usize) -> u8 {
        self.data[v * self.w + u]
    }

    /// Resize to `w × h` (keeping the allocation when it is large enough).
    pub fn reshape(&mut self, w: usize, h: usize) {
        self.w = w;
        self.h = h;
        self.data.resize(w * h, 0);
    }

    /// Half resolution by 2 × 2 averaging into `out`.
    #[inline(always)]
    pub fn half_into(&self, out: &mut Gray) {
        let (w, h) = (self.w / 2, self.h / 2);
        out.reshape(w, h);
        for v in 0..h {
            let (r0, r1) = (2 * v * self.w, (2 * v + 1) * self.w);
            let row = &mut out.data[v * w..(v + 1) * w];
            for (u, o) in row.iter_mut().enumerate() {
                let s = u16::from(self.data[r0 + 2 * u])
                    + u16::from(self.data[r0 + 2 * u + 1])
                    + u16::from(self.data[r1 + 2 * u])
                    + u16::from(self.data[r1 + 2 * u + 1]);
                *o = ((s + 2) / 4) as u8;
            }
        }
    }
}

/// Horizontal and vertical gradients of an image, one byte each (5 × 5 Sobel,
/// divided by 128, offset by 128, saturated); 128 (no gradient) on the 2-pixel
/// border.
#[derive(Clone, Debug, Default)]
pub struct Gradients {
    /// Width \[px\].
    pub w: usize,
    /// Height \[px\].
    pub h: usize,
    /// `∂/∂u`.
    pub du: Vec<u8>,
    /// `∂/∂v`.
    pub dv: Vec<u8>,
    /// Scratch rows of the separable filter.
    tmp_d: Vec<i16>,
    tmp_s: Vec<i16>,
}

impl Gradients {
    /// Compute the gradients of `img`.
    #[inline(always)]
    pub fn compute(&mut self, img: &Gray) {
        let (w, h) = (img.w, img.h);
        self.w = w;
        self.h = h;
        // Every byte is written below, the border with 128: no clearing pass.
        self.du.resize(w * h, 128);
        self.dv.resize(w * h, 128);
        if w < 5 || h < 5 {
            self.du.fill(128);
            self.dv.fill(128);
            return;
        }
        // Horizontal pass: derivative (1, 2, 0, −2, −1) and smoothing (1, 4, 6, 4, 1),
        // in i16 (|d| ≤ 3·255, s ≤ 16·255, and the vertical pass's sums stay
        // within 16·765 = 12 240: exact). Only columns 2..w−2 are read later.
        self.tmp_d.resize(w * h, 0);
        self.tmp_s.resize(w * h, 0);
        for ((row, td), ts) in img
            .data
            .chunks_exact(w)
            .zip(self.tmp_d.chunks_exact_mut(w))
            .zip(self.tmp_s.chunks_exact_mut(w))
        {
            for ((win, d), s) in row.windows(5).zip(&mut td[2..]).zip(&mut ts[2..]) {
                let p = |k: usize| i16::from(win[k]);
                *d = p(0) + 2 * p(1) - 2 * p(3) - p(4);
                *s = p(0) + 4 * p(1) + 6 * p(2) + 4 * p(3) + p(4);
            }
        }
        // Vertical pass: smoothing of the horizontal derivative, derivative of the
        // horizontal smoothing.
        let sat = |x: i16| ((x >> 7) + 128).clamp(0, 255) as u8;
        for v in 0..h {
            let (du, dv) = (
                &mut self.du[v * w..(v + 1) * w],
                &mut self.dv[v * w..(v + 1) * w],
            );
            if v < 2 || v >= h - 2 {
                du.fill(128);
                dv.fill(128);
                continue;
            }
            // Rows v−2..=v+2, columns 2..w−2.
            fn rows(t: &[i16], v: usize, w: usize) -> [&[i16]; 5] {
                std::array::from_fn(|k| &t[(v + k - 2) * w + 2..(v + k - 1) * w - 2])
            }
            let (d, s) = (rows(&self.tmp_d, v, w), rows(&self.tmp_s, v, w));
            // Every slice of the same length `n` and one output per loop: then the
            // loops are vectorised (indexing the rows as before kept them scalar;
            // Gradients::compute 7.0 -> 5.4 % of the odometry's samples).
            let n = w - 4;
            let [d0, d1, d2, d3, d4] = d.map(|r| &r[..n]);
            let [s0, s1, _, s3, s4] = s.map(|r| &r[..n]);
            let (du_in, dv_in) = (&mut du[2..n + 2], &mut dv[2..n + 2]);
            for (u, o) in du_in.iter_mut().enumerate().take(n) {
                *o = sat(d0[u] + 4 * d1[u] + 6 * d2[u] + 4 * d3[u] + d4[u]);
            }
            for (u, o) in dv_in.iter_mut().enumerate().take(n) {
                *o = sat(s0[u] + 2 * s1[u] - 2 * s3[u] - s4[u]);
            }
            du[..2].fill(128);
            dv[..2].fill(128);
            du[w - 2..].fill(128);
            dv[w - 2..].fill(128);
        }
    }

    /// The 32-byte matching descriptor at `(u, v)`: `du` and `dv` at 16 positions of
    /// the 11 × 11 window (needs a margin of 5 pixels).
    #[inline]
    pub fn descriptor(&self, u: usize, v: usize) -> [u8; DESCRIPTOR] {
        const OFFSETS: [(i32, i32); 16] = [
            (-3, -1),
            (-1, -1),
            (1, -1),
            (3, -1),
            (-3, 1),
            (-1, 1),
            (1, 1),
            (3, 1),
            (-1, -5),
            (1, -5),
            (-1, 5),
            (1, 5),
            (-5, -3),
            (5, -3),
            (-5, 3),
            (5, 3),
        ];
        let mut d = [0u8; DESCRIPTOR];
        for (k, (dx, dy)) in OFFSETS.iter().enumerate() {
            let i = (v as i32 + dy) as usize * self.w + (u as i32 + dx) as usize;
            d[2 * k] = self.du[i];
            d[2 * k + 1] = self.dv[i];
        }
        d
    }

    /// The 16-byte refinement descriptor at `(u, v)` (5 × 5 neighbourhood; needs a
    /// margin of 2 pixels): 12 `du` and 4 `dv` samples.
    #[inline]
    pub fn refine_descriptor(&self, u: i32, v: i32) -> [u8; 16] {
        let mut d = [0u8; 16];
        let idx = |dx: i32, dy: i32| ((v + dy) * self.w as i32 + u + dx) as usize;
        for (k, (dx, dy)) in REFINE_DU.iter().enumerate() {
            d[k] = self.du[idx(*dx, *dy)];
        }
        for (k, (dx, dy)) in REFINE_DV.iter().enumerate() {
            d[12 + k] = self.dv[idx(*dx, *dy)];
        }
        d
    }

    /// The SAD between `target` and the refinement descriptor at every offset of
    /// the 7 × 7 grid around `(u, v)`: `costs[(dy + 3) · 7 + dx + 3]` (needs a
    /// margin of 5 pixels). Equal to [`sad`] of [`Gradients::refine_descriptor`]
    /// at each offset, computed a sample at a time over a row of the grid (seven
    /// neighbouring bytes, vectorised) instead of gathering 49 descriptors.
    #[inline]
    pub fn refine_costs(&self, target: &[u8; 16], u: i32, v: i32) -> [u32; 49] {
        const REACH: i32 = 3;
        let mut costs = [0u32; 49];
        let w = self.w as i32;
        let planes = REFINE_DU
            .iter()
            .map(|o| (&self.du, o))
            .chain(REFINE_DV.iter().map(|o| (&self.dv, o)));
        for (row, dy) in costs.chunks_exact_mut(7).zip(-REACH..=REACH) {
            let mut acc = [0u16; 7];
            for ((plane, (ox, oy)), &t) in planes.clone().zip(target) {
                let start = ((v + dy + oy) * w + u - REACH + ox) as usize;
                let samples: &[u8; 7] = plane[start..start + 7].try_into().unwrap_or(&[0; 7]);
                for (a, &x) in acc.iter_mut().zip(samples) {
                    *a += u16::from(x.abs_diff(t));
                }
            }
            for (c, a) in row.iter_mut().zip(acc) {
                *c = u32::from(a);
            }
        }
        costs
    }
}

/// The refinement descriptor's `du` samples (`(0, 0)` twice), `(dx, dy)`.
const REFINE_DU: [(i32, i32); 12] = [
    (0, 0),
    (0, 0),
    (0, -1),
    (0, 1),
    (0, -2),
    (0, 2),
    (-1, 0),
    (1, 0),
    (-2, -1),
    (-2, 1),
    (2, -1),
    (2, 1),
];
/// Its `dv` samples.
const REFINE_DV: [(i32, i32); 4] = [(0, -1), (0, 1), (-1, 0), (1, 0)];

/// Sum of absolute differences of two byte arrays.
#[inline(never)]
pub fn sad<const N: usize>(a: &[u8; N], b: &[u8; N]) -> u32 {
    // Written as |zext(x) − zext(y)| summed in i32: the form LLVM turns into
    // `psadbw` on x86-64 (measured: `abs_diff` on bytes was not vectorised).
    // Not inlined: inlined into the candidate loop of the matching, LLVM
    // vectorised that loop instead, widening the bytes to 32 bits (the matching
    // took 2-4 % longer overall).
    a.iter()
        .zip(b)
        .map(|(x, y)| (i32::from(*x) - i32::from(*y)).abs())
        .sum::<i32>() as u32
}

/// The classes of features: matching only compares features of the same class.
pub const CLASSES: usize = 4;

/// Features of one image at one NMS scale, struct of arrays.
#[derive(Clone, Debug, Default)]
pub struct Features {
    /// Column \[px, matching resolution\].
    pub u: Vec<i32>,
    /// Row.
    pub v: Vec<i32>,
    /// Class: 0 blob minimum, 1 blob maximum, 2 corner minimum, 3 corner maximum.
    pub class: Vec<u8>,
    /// Descriptors.
    pub desc: Vec<[u8; DESCRIPTOR]>,
    /// Where the filter response peaks relative to `(u, v)` [px, matching
    /// resolution, each within ±0.5]: the vertex of the parabola through the
    /// extreme and its two neighbours, along each axis. At half resolution the
    /// full-resolution anchor of a match is placed there; at the half-resolution
    /// pixel's corner instead, every anchor sat half a pixel up and left of its
    /// feature, and aligning a patch whose anchor is off its texture's centre by
    /// a translation, across the scale change of a forward motion, shifted the
    /// matches by an amount proportional to the inverse depth: a spurious
    /// translation. Of the anchors tried, the peak drifted least (the
    /// measurements: docs/measurements.md, "The odometry's kernels").
    pub peak: Vec<(f32, f32)>,
}

impl Features {
    /// Number of features.
    pub fn len(&self) -> usize {
        self.u.len()
    }

    /// Whether there is none.
    pub fn is_empty(&self) -> bool {
        self.u.is_empty()
    }

    /// Feature `k`'s position at full resolution (`scale` full-resolution pixels to
    /// one of matching): its response's [`peak`](Features::peak), rounded to the
    /// nearest pixel. (Pixel `u` at half resolution covers the full-resolution
    /// pixels `2u` and `2u + 1`: its centre is `2u + 0.5`.)
    pub fn full_position(&self, k: usize, scale: usize) -> (f64, f64) {
        let s = scale as f64;
        let (du, dv) = self.peak[k];
        let at = |x: i32, d: f32| (s * (f64::from(x) + f64::from(d)) + (s - 1.0) / 2.0).round();
        (at(self.u[k], du), at(self.v[k], dv))
    }

    fn clear(&mut self) {
        self.u.clear();
        self.v.clear();
        self.class.clear();
        self.desc.clear();
        self.peak.clear();
    }
}

/// The vertex of the parabola through `(-1, a)`, `(0, b)`, `(1, c)` where `b` is
/// the extreme of the three, clamped to ±0.5 (0 when they are collinear).
fn vertex(a: i32, b: i32, c: i32) -> f32 {
    let (a, b, c) = (a as f32, b as f32, c as f32);
    let curvature = a - 2.0 * b + c;
    if curvature == 0.0 {
        return 0.0;
    }
    (0.5 * (a - c) / curvature).clamp(-0.5, 0.5)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn image(w: usize, h: usize, f: impl Fn(usize, usize) -> u8) -> Gray {
        Gray {
            w,
            h,
            data: (0..w * h).map(|i| f(i % w, i / w)).collect(),
        }
    }

    /// The features of `img` (`suppress(n, tau, margin)`).
    fn features_of(img: &Gray, n: usize, tau: i32, margin: usize) -> Features {
        let mut r = Responses::default();
        r.compute(img);
        let mut g = Gradients::default();
        g.compute(img);
        let mut f = Features::default();
        r.suppress(n, tau, margin, &g, &mut f);
        f
    }

    #[test]
    fn a_bright_dot_is_a_blob_maximum_and_a_checker_a_corner() {
        // A bright 3 × 3 dot at (20, 20) on black; a checkerboard corner at (40, 20).
        let img = image(64, 48, |u, v| {
            if (19..=21).contains(&u) && (19..=21).contains(&v) {
                200
            } else if (35..45).contains(&u) && (15..25).contains(&v) {
                if (u < 40) == (v < 20) { 0 } else { 180 }
            } else {
                0
            }
        });
        let f = features_of(&img, 3, 50, 6);
        let find = |class: u8, u: i32, v: i32| {
            (0..f.len())
                .any(|k| f.class[k] == class && (f.u[k] - u).abs() <= 1 && (f.v[k] - v).abs() <= 1)
        };
        assert!(find(1, 20, 20), "blob maximum at the dot: {f:?}");
        assert!(
            find(2, 40, 20) || find(3, 40, 20) || find(2, 39, 19) || find(3, 39, 19),
            "a corner at the checker: {:?}",
            (0..f.len())
                .map(|k| (f.u[k], f.v[k], f.class[k]))
                .collect::<Vec<_>>()
        );
    }

    #[test]
    fn the_vertex_of_a_sampled_parabola_is_found_and_clamped() {
        // y = 10 − (x − 0.3)² · 4 sampled at −1, 0, 1 (scaled to integers).
        let y = |x: f64| (1000.0 - 400.0 * (x - 0.3f64).powi(2)).round() as i32;
        assert!((vertex(y(-1.0), y(0.0), y(1.0)) - 0.3).abs() < 1e-3);
        // A minimum too, and the other side.
        assert!((vertex(-y(-1.0), -y(0.0), -y(1.0)) - 0.3).abs() < 1e-3);
        assert!((vertex(y(1.0), y(0.0), y(-1.0)) + 0.3).abs() < 1e-3);
        assert_eq!(vertex(5, 5, 5), 0.0);
        // A plateau to one side: half-way to that neighbour.
        assert_eq!(vertex(10, 10, 0), -0.5);
        assert_eq!(vertex(0, 10, 10), 0.5);
    }

    #[test]
    fn a_margin_below_the_descriptors_reach_is_raised_to_it() {
        // No margin and no threshold (a descriptor there read outside the
        // gradients and panicked): features keep 5 px from the border, each with
        // a peak within ±0.5.
        let img = image(24, 20, |u, v| ((u * 37 + v * 91) % 251) as u8);
        let f = features_of(&img, 1, 0, 0);
        assert!(!f.is_empty());
        assert!(f.u.iter().all(|&u| (5..19).contains(&u)), "{:?}", f.u);
        assert!(f.v.iter().all(|&v| (5..15).contains(&v)), "{:?}", f.v);
        assert_eq!(f.peak.len(), f.len());
        assert!(f.peak.iter().all(|p| p.0.abs() <= 0.5 && p.1.abs() <= 0.5));
    }

    #[test]
    fn half_resolution_features_are_placed_at_their_peak_at_full_resolution() {
        // A smooth blob at 64 sub-pixel positions of a full-resolution image, its
        // features found at half resolution: the full-resolution position is the
        // blob's centre to the nearest pixel, with no offset on average (the
        // half-resolution pixel's corner, 2u, was half a pixel up and left).
        let (mut sum, mut worst) = ([0.0f64; 2], 0.0f64);
        let mut n = 0;
        for i in 0..64 {
            let (cu, cv) = (40.0 + f64::from(i % 8) / 8.0, 38.0 + f64::from(i / 8) / 8.0);
            let full = image(96, 80, |u, v| {
                let r2 = (u as f64 - cu).powi(2) + (v as f64 - cv).powi(2);
                (30.0 + 200.0 * (-r2 / (2.0 * 3.0 * 3.0)).exp()).round() as u8
            });
            let mut half = Gray::default();
            full.half_into(&mut half);
            let f = features_of(&half, 3, 20, 4);
            let Some(k) = (0..f.len()).find(|&k| f.class[k] == 1) else {
                panic!("no blob maximum for the blob at ({cu}, {cv})");
            };
            let (u, v) = f.full_position(k, 2);
            let err = [u - cu, v - cv];
            for a in 0..2 {
                sum[a] += err[a];
                worst = worst.max(err[a].abs());
            }
            n += 1;
        }
        let mean = sum.map(|s| s / f64::from(n));
        assert!(
            mean.iter().all(|m| m.abs() < 0.1),
            "mean offset {mean:?} px"
        );
        assert!(worst <= 0.75, "largest offset {worst} px");
    }

    #[test]
    fn a_flat_image_has_no_features_and_no_gradient() {
        let img = image(64, 48, |_, _| 117);
        let (mut r, mut g, mut f) = (
            Responses::default(),
            Gradients::default(),
            Features::default(),
        );
        r.compute(&img);
        g.compute(&img);
        r.suppress(3, 50, 6, &g, &mut f);
        assert!(f.is_empty());
        assert!(g.du.iter().chain(&g.dv).all(|&x| x == 128));
    }

    #[test]
    fn gradients_point_along_the_intensity_change() {
        // Intensity grows to the right: du moves away from 128, dv stays.
        let img = image(32, 32, |u, _| (u * 8) as u8);
        let mut g = Gradients::default();
        g.compute(&img);
        let (du, dv) = (g.du[16 * 32 + 16], g.dv[16 * 32 + 16]);
        assert_ne!(du, 128);
        assert_eq!(dv, 128);
        // Halving keeps the mean.
        let mut half = Gray::default();
        img.half_into(&mut half);
        assert_eq!((half.w, half.h), (16, 16));
        assert_eq!(half.at(3, 7), 52, "(48 + 56 + 48 + 56 + 2) / 4");
    }

    #[test]
    fn the_refinement_grid_is_the_sad_of_each_descriptor() {
        let img = image(40, 30, |u, v| ((u * 37 + v * 91 + u * v * 7) % 251) as u8);
        let mut g = Gradients::default();
        g.compute(&img);
        let target = g.refine_descriptor(20, 14);
        let costs = g.refine_costs(&target, 18, 15);
        for dy in -3..=3 {
            for dx in -3..=3 {
                let at = ((dy + 3) * 7 + dx + 3) as usize;
                let expected = sad(&target, &g.refine_descriptor(18 + dx, 15 + dy));
                assert_eq!(costs[at], expected, "offset ({dx}, {dy})");
            }
        }
        // The grid's own centre is the descriptor compared with itself.
        assert_eq!(g.refine_costs(&target, 20, 14)[24], 0);
    }

    #[test]
    fn gradients_are_the_5x5_sobel_even_at_full_contrast() {
        // 0/255 stripes and speckle: the sums reach their extremes, where a
        // narrower integer type than the filter needs would overflow.
        let img = image(24, 20, |u, v| {
            if (u / 2 + v / 3 + u * v % 3) % 2 == 0 {
                0
            } else {
                255
            }
        });
        let mut g = Gradients::default();
        g.compute(&img);
        let (smooth, deriv) = ([1, 4, 6, 4, 1], [1, 2, 0, -2, -1]);
        let sat = |x: i32| ((x >> 7) + 128).clamp(0, 255) as u8;
        for v in 2..18 {
            for u in 2..22 {
                let (mut du, mut dv) = (0i32, 0i32);
                for j in 0..5 {
                    for k in 0..5 {
                        let p = i32::from(img.at(u + k - 2, v + j - 2));
                        du += smooth[j] * deriv[k] * p;
                        dv += deriv[j] * smooth[k] * p;
                    }
                }
                assert_eq!(
                    (g.du[v * 24 + u], g.dv[v * 24 + u]),
                    (sat(du), sat(dv)),
                    "({u}, {v})"
                );
            }
        }
    }

    #[test]
    fn gradients_leave_the_border_neutral_after_a_larger_image() {
        // The buffers are reused without clearing: a smaller image after a larger
        // one must still get 128 on its 2-pixel border and the same inside.
        let (big, small) = (
            image(50, 40, |u, v| ((u * 13 + v * 29) % 256) as u8),
            image(20, 16, |u, v| ((u * 7 + v * v) % 256) as u8),
        );
        let mut reused = Gradients::default();
        reused.compute(&big);
        reused.compute(&small);
        let mut fresh = Gradients::default();
        fresh.compute(&small);
        assert_eq!(
            (reused.du.clone(), reused.dv.clone()),
            (fresh.du.clone(), fresh.dv.clone())
        );
        for v in 0..16 {
            for u in 0..20 {
                if u < 2 || v < 2 || u >= 18 || v >= 14 {
                    assert_eq!((fresh.du[v * 20 + u], fresh.dv[v * 20 + u]), (128, 128));
                }
            }
        }
    }

    #[test]
    fn sad_counts_byte_differences() {
        assert_eq!(sad(&[1u8, 200, 3], &[4u8, 100, 3]), 103);
    }
}
