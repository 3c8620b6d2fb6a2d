//! Refinement of the matches at full resolution (notes `vo.md` §1.5): libviso2's
//! pixel and subpixel passes on the gradients' refinement descriptor, and ours,
//! Lucas–Kanade alignment of the intensities with the current left image's patch
//! at the match's anchor.

use super::features::{Gradients, sad};

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
    /// matching positions. (A subpixel pass before it drifted more and took
    /// longer: docs/measurements.md.)
    Photometric,
}

/// The `S × S` patch of `img` centred on `(u, v)` (`S` odd), bilinearly
/// interpolated (one fractional offset for the whole patch, so the weights are
/// computed once), into `out` row by row; `false` if the patch (with a 1-pixel
/// rim) leaves the image. In `f32` (ample for 8-bit pixels) and of a size known at
/// compile time, so that each row is a few vector operations.
#[inline(always)]
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
    let w = img.w;
    // Separable: each of the S + 1 rows interpolated along u, then each pair of
    // rows along v (a third of the conversions and half the arithmetic of
    // weighting four pixels per sample).
    let mut above = [0.0f32; S];
    for y in 0..=S {
        let start = (j as usize + y) * w + i as usize;
        // In the image: checked above.
        let px: &[u8] = img.data.get(start..start + S + 1).unwrap_or(&[]);
        let (left, right) = (px.get(..S).unwrap_or(&[]), px.get(1..).unwrap_or(&[]));
        let mut row = [0.0f32; S];
        for ((r, &p0), &p1) in row.iter_mut().zip(left).zip(right) {
            let p0 = f32::from(p0);
            *r = p0 + a * (f32::from(p1) - p0);
        }
        if y > 0 {
            for ((o, &t), &b_) in out[y - 1].iter_mut().zip(&above).zip(&row) {
                *o = t + b * (b_ - t);
            }
        }
        above = row;
    }
    true
}

/// Side of the Lucas–Kanade patches.
const LK: usize = 9;

/// The template of a Lucas–Kanade alignment: the gradients of the 9 × 9 patch, the
/// Gauss–Newton matrix they make (inverse compositional: fixed for every target
/// aligned with it), and their products with the mean-subtracted patch.
pub struct Template {
    gx: [f32; LK * LK],
    gy: [f32; LK * LK],
    h: (f64, f64, f64),
    det: f64,
    /// `Σ gx`, `Σ gy`, `Σ gx·t`, `Σ gy·t` (`t` the mean-subtracted patch): the
    /// parts of the steepest-descent products that do not depend on the target.
    sums: [f32; 4],
}

impl Template {
    /// The template of `image` at `t`; `None` if the patch leaves the image, or is
    /// flat or one-dimensional (an edge: it cannot be aligned), or not finite.
    #[inline(always)]
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
        let sums = [
            dot(&gx, None),
            dot(&gy, None),
            dot(&gx, Some(&tv)),
            dot(&gy, Some(&tv)),
        ];
        Some(Template {
            gx,
            gy,
            h: (h00, h01, h11),
            det,
            sums,
        })
    }

    /// Align the 9 × 9 patch of `target` at `p` with the template (translation
    /// only, on mean-subtracted intensities); `None` if it does not converge,
    /// leaves the image or moves more than a pixel and a half. Intensities and sums
    /// in `f32`, the position in `f64`.
    #[inline(always)]
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
            // Σ g·(i − mean − t) = Σ g·i − mean·Σ g − Σ g·t.
            let mean_i = dot(iv, None) / n;
            let [sgx, sgy, sgxt, sgyt] = self.sums;
            let (b0, b1) = (
                f64::from(dot(&self.gx, Some(iv)) - mean_i * sgx - sgxt),
                f64::from(dot(&self.gy, Some(iv)) - mean_i * sgy - sgyt),
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
            // and drifted more on every tuning sequence (docs/measurements.md).
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
#[inline(always)]
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
///
/// Compiled for AVX2 as well, chosen at run time, with the template and the
/// alignment inlined: fewer instructions (the counts: docs/measurements.md,
/// "The odometry's kernels"). The same positions on any machine: Rust never
/// fuses a multiply and an add, so each operation rounds as IEEE 754 says
/// whatever the vector width.
#[multiversion::multiversion(targets("x86_64+avx2"))]
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
        // more on the held-out tours of bench_vo; see docs/measurements.md.)
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
    fn the_dispatched_refinement_is_the_baseline_code_bit_for_bit() {
        // `photometric` runs its AVX2 clone where the machine has AVX2; the
        // template and alignment called here are compiled at the baseline level.
        let images = [
            scene(0.4, -0.3, 1.0, 0.0),
            scene(-0.7, 0.2, 1.0, 12.0),
            scene(0.9, 0.6, 1.0, -9.0),
            scene(0.0, 0.0, 1.0, 0.0),
        ];
        let refs = [&images[0], &images[1], &images[2], &images[3]];
        let mut aligned = 0;
        for t in [
            (24.0, 24.0),
            (23.6, 24.3),
            (24.2, 23.1),
            (23.0, 25.0),
            (3.0, 3.0),
        ] {
            // Near where each image's content lies, as the matching leaves it.
            let p = [
                (t.0 + 0.3, t.1 - 0.2),
                (t.0 - 0.5, t.1 + 0.1),
                (t.0 + 0.7, t.1 + 0.5),
                t,
            ];
            let baseline = Template::new(refs[3], p[3]).and_then(|t| {
                let mut out = p;
                for m in 0..3 {
                    out[m] = t.align(refs[m], p[m])?;
                }
                Some(out)
            });
            let dispatched = photometric(p, refs);
            assert_eq!(
                dispatched.map(|o| o.map(|(u, v)| (u.to_bits(), v.to_bits()))),
                baseline.map(|o| o.map(|(u, v)| (u.to_bits(), v.to_bits()))),
                "at {t:?}"
            );
            aligned += usize::from(baseline.is_some());
        }
        assert!(aligned >= 3, "most starts align: {aligned}");
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
