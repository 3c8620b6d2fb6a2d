//! libviso2's outlier pre-filter: a match whose neighbours in the image move
//! differently is probably wrong. The matches' current-left positions are
//! triangulated (Delaunay, the `delaunator` crate); an edge of a triangle whose
//! two ends have about the same disparity in the previous pair and about the
//! same flow (current left − previous left) gives each end a vote, and a match
//! with fewer than [`MIN_VOTES`] votes is dropped. An interior edge votes once
//! for each triangle it borders.

use delaunator::Point;

/// Votes a match needs to stay (libviso2's).
pub const MIN_VOTES: u32 = 4;

/// The tolerances of an edge, in pixels of the positions given.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tolerances {
    /// Of the difference of the two ends' disparities in the previous pair.
    pub disparity: f64,
    /// Of the L1 norm of the difference of the two ends' flows.
    pub flow: f64,
}

/// Reusable buffers of [`filter`].
#[derive(Clone, Debug, Default)]
pub struct Scratch {
    points: Vec<Point>,
    /// Each match's disparity in the previous pair and flow `(u, v)`.
    motions: Vec<(f64, f64, f64)>,
    votes: Vec<u32>,
}

/// Keep the matches of `quads` that their neighbours support, in order; the
/// others are removed. `position(q, m)` is match `q`'s position in image `m`
/// of `[prev_left, prev_right, curr_right, curr_left]`. Fewer than three
/// matches, or all on one line, leave no triangle: nothing is supported and
/// all are removed, as in libviso2 (the pair then has too few matches for a
/// motion). A match with a position that is not finite is removed, and so is
/// one at the current-left position of another (the triangulation skips it).
pub fn filter<T>(
    quads: &mut Vec<T>,
    position: impl Fn(&T, usize) -> (f64, f64),
    tol: Tolerances,
    scratch: &mut Scratch,
) {
    quads.retain(|q| {
        (0..4).all(|m| {
            let (u, v) = position(q, m);
            u.is_finite() && v.is_finite()
        })
    });
    scratch.points.clear();
    scratch.points.extend(quads.iter().map(|q| {
        let (x, y) = position(q, 3);
        Point { x, y }
    }));
    scratch.motions.clear();
    scratch.motions.extend(quads.iter().map(|q| {
        let (pl, pr, cl) = (position(q, 0), position(q, 1), position(q, 3));
        (pl.0 - pr.0, cl.0 - pl.0, cl.1 - pl.1)
    }));
    let triangulation = delaunator::triangulate(&scratch.points);
    scratch.votes.clear();
    scratch.votes.resize(quads.len(), 0);
    for t in triangulation.triangles.chunks_exact(3) {
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            let (da, ua, va) = scratch.motions[a];
            let (db, ub, vb) = scratch.motions[b];
            if (da - db).abs() < tol.disparity && (ua - ub).abs() + (va - vb).abs() < tol.flow {
                scratch.votes[a] += 1;
                scratch.votes[b] += 1;
            }
        }
    }
    let mut k = 0;
    quads.retain(|_| {
        k += 1;
        scratch.votes[k - 1] >= MIN_VOTES
    });
}

#[cfg(test)]
mod tests {
    use super::*;

    const TOL: Tolerances = Tolerances {
        disparity: 5.0,
        flow: 5.0,
    };

    /// A match at `(u, v)` in the current left image with disparity `d` and
    /// flow `(fu, fv)`.
    fn quad(u: f64, v: f64, d: f64, (fu, fv): (f64, f64)) -> [(f64, f64); 4] {
        let prev = (u - fu, v - fv);
        [prev, (prev.0 - d, prev.1), (u - d, v), (u, v)]
    }

    fn at(q: &[(f64, f64); 4], m: usize) -> (f64, f64) {
        q[m]
    }

    fn grid(flow: (f64, f64)) -> Vec<[(f64, f64); 4]> {
        (0..100)
            .map(|i| {
                let (u, v) = (f64::from(i % 10) * 30.0, f64::from(i / 10) * 30.0);
                // Slightly irregular, so that the triangulation is unique.
                let jitter = f64::from((i * 7) % 5) * 0.37;
                quad(u + jitter, v - jitter, 20.0 + u / 100.0, flow)
            })
            .collect()
    }

    #[test]
    fn consistent_matches_stay_and_a_wrong_one_goes() {
        let mut quads = grid((3.0, -1.0));
        let mut scratch = Scratch::default();
        filter(&mut quads, at, TOL, &mut scratch);
        // Every match of a smooth field stays.
        assert_eq!(quads.len(), 100);
        // One match in the middle with a wrong flow, one with a wrong disparity.
        let mut quads = grid((3.0, -1.0));
        let wrong_flow = quads[44][3];
        quads[44] = quad(wrong_flow.0, wrong_flow.1, 20.0, (15.0, 4.0));
        let wrong_disparity = quads[55][3];
        quads[55] = quad(wrong_disparity.0, wrong_disparity.1, 45.0, (3.0, -1.0));
        filter(&mut quads, at, TOL, &mut scratch);
        assert_eq!(quads.len(), 98);
        assert!(
            quads
                .iter()
                .all(|q| q[3] != wrong_flow && q[3] != wrong_disparity)
        );
    }

    #[test]
    fn too_few_or_collinear_matches_leave_nothing_and_do_not_panic() {
        let mut scratch = Scratch::default();
        for n in 0..3 {
            let mut quads: Vec<_> = grid((1.0, 1.0)).into_iter().take(n).collect();
            filter(&mut quads, at, TOL, &mut scratch);
            assert!(quads.is_empty());
        }
        let mut line: Vec<_> = (0..20)
            .map(|i| quad(f64::from(i) * 10.0, 50.0, 10.0, (1.0, 0.0)))
            .collect();
        filter(&mut line, at, TOL, &mut scratch);
        assert!(line.is_empty());
        // Two matches at one current-left position: one is not triangulated.
        let mut twins = grid((1.0, 1.0));
        twins.push(twins[44]);
        filter(&mut twins, at, TOL, &mut scratch);
        assert_eq!(twins.len(), 100);
        // NaN positions neither panic nor survive.
        let mut bad = grid((1.0, 1.0));
        bad[0] = [(f64::NAN, 0.0); 4];
        filter(&mut bad, at, TOL, &mut scratch);
        assert!(bad.iter().all(|q| q[3].0.is_finite()));
    }
}
