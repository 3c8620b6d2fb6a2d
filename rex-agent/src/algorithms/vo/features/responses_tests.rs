#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use super::super::{Features, Gradients, Gray, vertex};
use super::Responses;

/// The responses through an integral image, in `i32`, as they were computed
/// before the 16-bit filters.
fn reference_responses(img: &Gray) -> (Vec<i32>, Vec<i32>) {
    let (w, h) = (img.w, img.h);
    let iw = w + 1;
    let mut ii = vec![0i32; iw * (h + 1)];
    for v in 0..h {
        let mut row = 0i32;
        for u in 0..w {
            row += i32::from(img.data[v * w + u]);
            ii[(v + 1) * iw + u + 1] = ii[v * iw + u + 1] + row;
        }
    }
    let (mut blob, mut corner) = (vec![0; w * h], vec![0; w * h]);
    if w < 5 || h < 5 {
        return (blob, corner);
    }
    let sum = |u0: usize, v0: usize, u1: usize, v1: usize| {
        ii[(v1 + 1) * iw + u1 + 1] - ii[v0 * iw + u1 + 1] - ii[(v1 + 1) * iw + u0]
            + ii[v0 * iw + u0]
    };
    for v in 2..h - 2 {
        for u in 2..w - 2 {
            let c = i32::from(img.data[v * w + u]);
            blob[v * w + u] =
                -sum(u - 2, v - 2, u + 2, v + 2) + 2 * sum(u - 1, v - 1, u + 1, v + 1) + 7 * c;
            corner[v * w + u] = -sum(u - 2, v - 2, u - 1, v - 1)
                + sum(u + 1, v - 2, u + 2, v - 1)
                + sum(u - 2, v + 1, u - 1, v + 2)
                - sum(u + 1, v + 1, u + 2, v + 2);
        }
    }
    (blob, corner)
}

/// The suppression as libviso2 writes it: each block's first extreme of each
/// class, every pixel of its window compared. The reference the dilations must
/// match exactly.
fn reference_suppress(
    (blob, corner): (&[i32], &[i32]),
    (w, h): (usize, usize),
    (n, tau, margin): (usize, i32, usize),
    grad: &Gradients,
) -> Features {
    let mut out = Features::default();
    let margin = margin.max(5);
    if w <= 2 * (n + margin) || h <= 2 * (n + margin) {
        return out;
    }
    let (lo_u, hi_u, lo_v, hi_v) = (margin, w - margin, margin, h - margin);
    let mut i = n + margin;
    while i + n < hi_u {
        let mut j = n + margin;
        while j + n < hi_v {
            let mut cand = [(i, j, blob[j * w + i]); 4];
            cand[2].2 = corner[j * w + i];
            cand[3].2 = cand[2].2;
            for v in j..=j + n {
                for u in i..=i + n {
                    let (b, c) = (blob[v * w + u], corner[v * w + u]);
                    if b < cand[0].2 {
                        cand[0] = (u, v, b);
                    }
                    if b > cand[1].2 {
                        cand[1] = (u, v, b);
                    }
                    if c < cand[2].2 {
                        cand[2] = (u, v, c);
                    }
                    if c > cand[3].2 {
                        cand[3] = (u, v, c);
                    }
                }
            }
            for (class, &(u, v, val)) in cand.iter().enumerate() {
                let is_max = class % 2 == 1;
                if (is_max && val < tau) || (!is_max && val > -tau) {
                    continue;
                }
                let map = if class < 2 { blob } else { corner };
                let sign = if is_max { 1 } else { -1 };
                let beaten = (v.saturating_sub(n).max(lo_v)..=(v + n).min(hi_v - 1)).any(|vv| {
                    (u.saturating_sub(n).max(lo_u)..=(u + n).min(hi_u - 1))
                        .any(|uu| sign * map[vv * w + uu] > sign * val)
                });
                if !beaten {
                    out.u.push(u as i32);
                    out.v.push(v as i32);
                    out.class.push(class as u8);
                    out.desc.push(grad.descriptor(u, v));
                    out.peak.push((
                        vertex(map[v * w + u - 1], val, map[v * w + u + 1]),
                        vertex(map[(v - 1) * w + u], val, map[(v + 1) * w + u]),
                    ));
                }
            }
            j += n + 1;
        }
        i += n + 1;
    }
    out
}

fn image(w: usize, h: usize, mut f: impl FnMut(usize, usize) -> u8) -> Gray {
    let mut data = Vec::with_capacity(w * h);
    for v in 0..h {
        for u in 0..w {
            data.push(f(u, v));
        }
    }
    Gray { w, h, data }
}

fn assert_same(ours: &Features, reference: &Features, what: &str) {
    assert_eq!(ours.u, reference.u, "{what}");
    assert_eq!(ours.v, reference.v, "{what}");
    assert_eq!(ours.class, reference.class, "{what}");
    assert_eq!(ours.desc, reference.desc, "{what}");
    assert_eq!(ours.peak, reference.peak, "{what}");
}

#[test]
fn the_filters_and_the_dilations_keep_what_the_window_scan_keeps() {
    let mut rng = crate::math::rng::Rng::new(17);
    let mut found = 0;
    let mut r = Responses::default();
    let mut g = Gradients::default();
    for (w, h) in [(4, 9), (23, 17), (40, 40), (64, 48), (101, 77), (160, 120)] {
        // Noise; areas of a few levels (plateaus: ties everywhere); a noisy
        // checkerboard; full-contrast noise (the filters' extremes); flat.
        let noise = image(w, h, |_, _| (rng.next_u64() % 256) as u8);
        let levels = image(w, h, |u, v| (((u / 3) * 7 + (v / 4) * 13) % 4 * 60) as u8);
        let checker = image(w, h, |u, v| {
            let base = if (u / 5 + v / 5) % 2 == 0 { 40 } else { 200 };
            base + (rng.next_u64() % 8) as u8
        });
        let binary = image(w, h, |_, _| {
            if rng.next_u64().is_multiple_of(2) {
                0
            } else {
                255
            }
        });
        let flat = image(w, h, |_, _| 90);
        for img in [&noise, &levels, &checker, &binary, &flat] {
            r.compute(img);
            g.compute(img);
            let (blob, corner) = reference_responses(img);
            let widened = |m: &[i16]| m.iter().map(|&x| i32::from(x)).collect::<Vec<_>>();
            assert_eq!(widened(&r.blob), blob, "blob {w}x{h}");
            assert_eq!(widened(&r.corner), corner, "corner {w}x{h}");
            for (n, sparse) in [
                (1, 3),
                (2, 6),
                (3, 9),
                (3, 10),
                (4, 10),
                (5, 10),
                (9, 3),
                (0, 2),
            ] {
                for (tau, margin) in [(0, 0), (50, 6), (20, 9), (-5000, 5), (5000, 5)] {
                    let what = format!("{w}x{h} n={n} sparse={sparse} tau={tau} margin={margin}");
                    let (mut d, mut s) = (Features::default(), Features::default());
                    r.suppress_scales((n, &mut d), Some((sparse, &mut s)), tau, margin, &g);
                    let reference =
                        |n| reference_suppress((&blob, &corner), (w, h), (n, tau, margin), &g);
                    assert_same(&d, &reference(n), &what);
                    assert_same(&s, &reference(sparse), &what);
                    let mut alone = Features::default();
                    r.suppress(n, tau, margin, &g, &mut alone);
                    assert_same(&alone, &d, &what);
                    found += d.len() + s.len();
                }
            }
        }
    }
    assert!(found > 10_000, "the comparison saw features: {found}");
}

#[test]
fn responses_reach_their_bounds_within_16_bits() {
    // A bright centre in a dark 5 × 5 and the reverse: the blob filter's
    // extremes ±(8 + 8)·255; a checker of 2 × 2 quadrants: the corner's ±8·255.
    let dot = image(9, 9, |u, v| {
        let (du, dv) = (u.abs_diff(4), v.abs_diff(4));
        if du <= 1 && dv <= 1 { 255 } else { 0 }
    });
    let mut r = Responses::default();
    r.compute(&dot);
    assert_eq!(r.blob[4 * 9 + 4], 16 * 255);
    let hole = image(9, 9, |u, v| 255 - dot.data[v * 9 + u]);
    r.compute(&hole);
    assert_eq!(r.blob[4 * 9 + 4], -16 * 255);
    let checker = image(9, 9, |u, v| if (u < 4) == (v < 4) { 0 } else { 255 });
    r.compute(&checker);
    // Centre (4, 4): the top-left quadrant (2..=3, 2..=3) is dark, top-right light.
    assert_eq!(r.corner[4 * 9 + 4], 8 * 255);
    assert!(r.blob.iter().chain(&r.corner).all(|x| x.abs() <= 16 * 255));
}
