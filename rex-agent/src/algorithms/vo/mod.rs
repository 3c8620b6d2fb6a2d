//! Stereo visual odometry in the manner of StereoScan (Geiger, Ziegler & Stiller,
//! IV 2011), re-implemented from the description in the notes (`vo.md` §1): the
//! virtual receptor r1,1 runs it on the stereo camera R1, and the `vo` example on any
//! KITTI odometry sequence.
//!
//! Per stereo pair: features in both images ([`features`]: blob and corner filters
//! at half resolution, non-maximum suppression into four classes, 32-byte gradient
//! descriptors), circular matching of the previous and current pairs
//! ([`matching`]: a sparse pass that measures the displacements to expect in each
//! part of the image, then a dense pass searching only there; refinement at full
//! resolution, [`refine`]; bucketing), and the motion by Gauss–Newton on the
//! reprojection error inside RANSAC ([`egomotion`]). [`StereoOdometry::process`]
//! returns the motion `Tr` with `p_curr = Tr · p_prev` (a point of the previous
//! left-camera frame in the current one), or an explicit [`NoEstimate`]: never an
//! identity guessed in its place, never a non-finite transform. After a failure the
//! pair just processed becomes the reference of the next one, so the odometry
//! recovers on the next good pair. [`metric`] is the KITTI drift metric.
//!
//! Not implemented from libviso2: the Delaunay-based outlier pre-filter (RANSAC does
//! the rejection); its constant-velocity prior on the temporal search is an option,
//! off by default ([`VoSettings::motion_prior_weight`]). Added:
//! Lucas–Kanade refinement of the matches kept ([`Refinement::Photometric`]).

pub mod egomotion;
pub mod features;
pub mod matching;
pub mod metric;
pub mod outliers;
pub mod refine;

use serde::{Deserialize, Serialize};

pub use egomotion::{Calibration, EgomotionError};
pub use refine::Refinement;

use features::{Gradients, Gray, Responses};
use matching::{Circle, Indexed, Ranges, Search};

use crate::math::rng::Rng;

/// Settings of the odometry: libviso2's defaults, except three chosen on the
/// simulator's 640 × 480 tuning sequences (never on `bench_vo`'s held-out
/// tours): photometric refinement (Lucas–Kanade alignment at full resolution
/// from the matching positions: less drift, less time), 8 matches per bucket
/// instead of 2 (libviso2's 2 suit 1241 × 376 images), and no reweighting
/// towards the centre column (it guards against calibration errors at the image
/// borders, which a simulated camera does not have; turn it on for real
/// cameras). The measurements: docs/measurements.md, "The odometry's settings".
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct VoSettings {
    /// Detect and match at half resolution.
    pub half_resolution: bool,
    /// Non-maximum suppression window of the dense features (the sparse ones use
    /// three times it, at most 10).
    pub nms_n: usize,
    /// Least filter response of a feature.
    pub nms_tau: i32,
    /// Border without features \[px, matching resolution\].
    pub margin: usize,
    /// Match sparse features first to bound the search of the dense ones.
    pub multi_stage: bool,
    /// Bin size of the candidate index and of the search ranges \[px, full res.\].
    pub match_binsize: usize,
    /// Half-width of the temporal search window \[px, full res.\].
    pub match_radius: i32,
    /// Row tolerance of the stereo legs \[px, matching res.\].
    pub match_disp_tolerance: i32,
    /// Least width of a search range of the dense pass \[px, full res.\].
    pub range_min_width: i32,
    /// Refinement of the matches at full resolution.
    pub refinement: Refinement,
    /// Bucket size \[px, full res.\].
    pub bucket_size: f64,
    /// Matches kept per bucket.
    pub bucket_max: usize,
    /// RANSAC iterations.
    pub ransac_iterations: usize,
    /// Inlier threshold on the reprojection error \[px\].
    pub inlier_threshold: f64,
    /// Weight residuals towards the image's centre column.
    pub reweighting: bool,
    /// libviso2's constant-velocity prior on the temporal legs of the matching:
    /// the last motion predicts where a point appears, and a candidate's cost
    /// grows by `motion_prior_weight` per pixel from there (0: off; libviso2: 4).
    /// Off by default: on the tuning sequences it helped some and hurt others
    /// (docs/measurements.md), where no pair fails to match without it.
    pub motion_prior_weight: f32,
    /// libviso2's outlier pre-filter ([`outliers`]): a circular match whose
    /// neighbours (Delaunay) disagree with its disparity or flow by 5 px or more
    /// is dropped, in the sparse pass before it sets the search ranges and in the
    /// dense pass before refinement. Off by default: on four of the five tuning
    /// sequences the odometry drifted more with it, and it costs time
    /// (docs/measurements.md). On, a pair allocates its triangulation.
    pub outlier_filter: bool,
    /// Fewest inliers of an estimate.
    pub min_inliers: usize,
    /// Fewest features per image for a pair to be usable.
    pub min_features: usize,
    /// Seed of RANSAC and bucketing (runs are deterministic).
    pub seed: u64,
    /// Threads of a pair: above 1, the left and right images' features are
    /// computed on two threads, and the circles are matched and their buckets
    /// refined on up to this many (the results, in order, are the same with any
    /// number). 1: the caller's thread only.
    pub threads: usize,
}

impl Default for VoSettings {
    fn default() -> Self {
        VoSettings {
            half_resolution: true,
            nms_n: 3,
            nms_tau: 50,
            margin: 8,
            multi_stage: true,
            match_binsize: 50,
            match_radius: 200,
            match_disp_tolerance: 2,
            range_min_width: 20,
            refinement: Refinement::Photometric,
            bucket_size: 50.0,
            bucket_max: 8,
            ransac_iterations: 200,
            inlier_threshold: 2.0,
            reweighting: false,
            motion_prior_weight: 0.0,
            outlier_filter: false,
            min_inliers: 6,
            min_features: 30,
            seed: 0,
            threads: 1,
        }
    }
}

/// Why a pair gave no motion.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum NoEstimate {
    /// The images are not of the announced size, or too small.
    #[error("bad images: {0}")]
    BadImages(String),
    /// Too few features (a blank, saturated or textureless pair).
    #[error("too few features: {left} left, {right} right, at least {needed} each")]
    Textureless {
        /// Features of the left image.
        left: usize,
        /// Features of the right image.
        right: usize,
        /// Needed.
        needed: usize,
    },
    /// The previous pair was unusable: nothing to match against.
    #[error("no usable previous pair to match against")]
    NoReference,
    /// Most stereo matches have a negative disparity: the left and right images
    /// look swapped (or the camera is not rectified as calibrated).
    #[error(
        "{negative} of {} stereo matches have negative disparity (the right image's feature to the right of the left's): are the left and right images swapped?",
        negative + positive
    )]
    SwappedStereo {
        /// Matches with negative disparity.
        negative: usize,
        /// Matches with positive disparity.
        positive: usize,
    },
    /// The motion could not be estimated from the matches.
    #[error(transparent)]
    Egomotion(#[from] EgomotionError),
}

/// Invalid calibration or settings.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("invalid visual odometry set-up: {0}")]
pub struct VoError(pub String);

/// The motion between two pairs.
#[derive(Clone, Debug, PartialEq)]
pub struct VoMotion {
    /// `Tr`: `p_curr = Tr · p_prev`, left-camera frames.
    pub tr: [[f64; 4]; 4],
    /// Circular matches after refinement and bucketing.
    pub matches: usize,
    /// RANSAC inliers.
    pub inliers: usize,
}

/// Counters of the odometry.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct VoStats {
    /// Pairs processed.
    pub pairs: u64,
    /// Motions estimated.
    pub motions: u64,
    /// Pairs without an estimate.
    pub failures: u64,
}

/// What one image contributes.
#[derive(Debug, Default)]
struct ImageData {
    dense: Indexed,
    sparse: Indexed,
    /// Gradients at full resolution (refinement).
    full: Gradients,
    /// The image at full resolution (photometric refinement).
    image: Gray,
}

/// Both images of a pair.
#[derive(Debug, Default)]
struct PairData {
    left: ImageData,
    right: ImageData,
    usable: bool,
}

/// Scratch buffers of one image's features, reused from pair to pair.
#[derive(Debug, Default)]
struct ImageScratch {
    full: Gray,
    half: Gray,
    responses: Responses,
    grad: Gradients,
}

/// Scratch buffers reused from pair to pair.
#[derive(Debug, Default)]
struct Scratch {
    /// The left and the right image's.
    images: [ImageScratch; 2],
    quads: Vec<[usize; 4]>,
    /// The sparse circles' positions.
    positions: Vec<[(i32, i32); 4]>,
    ranges: Ranges,
    outliers: outliers::Scratch,
    candidates: Vec<[(f64, f64); 4]>,
    buckets: matching::BucketScratch,
    /// The matches kept, refined.
    matches: Vec<[(f64, f64); 4]>,
    observations: Vec<egomotion::Observation>,
    ransac: egomotion::RansacScratch,
}

/// Stereo visual odometry, one pair at a time.
#[derive(Debug)]
pub struct StereoOdometry {
    calib: Calibration,
    s: VoSettings,
    prev: PairData,
    curr: PairData,
    scratch: Scratch,
    rng: Rng,
    stats: VoStats,
    size: Option<(usize, usize)>,
    /// Whether some pair was usable before: then a missing reference is a failure.
    had_usable: bool,
    /// The last motion (`θ`), while pairs keep giving one: the prior of the next.
    last: Option<[f64; 6]>,
}

impl StereoOdometry {
    /// Odometry for a rectified stereo camera.
    pub fn new(calib: Calibration, settings: VoSettings) -> Result<StereoOdometry, VoError> {
        let c = &calib;
        if ![c.f, c.cu, c.cv, c.baseline].iter().all(|v| v.is_finite())
            || c.f <= 0.0
            || c.baseline <= 0.0
        {
            return Err(VoError(format!(
                "focal length and baseline must be positive: {c:?}"
            )));
        }
        let s = &settings;
        if s.nms_n == 0 || s.match_binsize == 0 || s.bucket_max == 0 || s.ransac_iterations == 0 {
            return Err(VoError(
                "nms_n, match_binsize, bucket_max and ransac_iterations must be positive".into(),
            ));
        }
        if !(s.inlier_threshold > 0.0 && s.bucket_size > 0.0) || s.match_radius <= 0 {
            return Err(VoError(
                "inlier_threshold, bucket_size and match_radius must be positive".into(),
            ));
        }
        if !s.motion_prior_weight.is_finite() || s.motion_prior_weight < 0.0 {
            return Err(VoError(format!(
                "motion_prior_weight must be finite and at least 0, not {}",
                s.motion_prior_weight
            )));
        }
        let rng = Rng::new(settings.seed);
        Ok(StereoOdometry {
            calib,
            s: settings,
            prev: PairData::default(),
            curr: PairData::default(),
            scratch: Scratch::default(),
            rng,
            stats: VoStats::default(),
            size: None,
            had_usable: false,
            last: None,
        })
    }

    /// The calibration.
    pub fn calibration(&self) -> &Calibration {
        &self.calib
    }

    /// The counters.
    pub fn stats(&self) -> VoStats {
        self.stats
    }

    /// Process the next pair (`w × h` grey images, row-major): `Ok(None)` for the
    /// first usable pair, then the motion since the previous pair.
    pub fn process(
        &mut self,
        left: &[u8],
        right: &[u8],
        w: usize,
        h: usize,
    ) -> Result<Option<VoMotion>, NoEstimate> {
        self.stats.pairs += 1;
        let result = self.step(left, right, w, h);
        if !matches!(result, Ok(Some(_))) {
            self.last = None;
        }
        match &result {
            Ok(Some(_)) => self.stats.motions += 1,
            Ok(None) => {}
            Err(_) => self.stats.failures += 1,
        }
        // The pair just processed is the reference of the next one.
        std::mem::swap(&mut self.prev, &mut self.curr);
        result
    }

    /// One pair: its images checked, its features, whether they can give a
    /// motion, then the matches with the previous pair and the motion.
    fn step(
        &mut self,
        left: &[u8],
        right: &[u8],
        w: usize,
        h: usize,
    ) -> Result<Option<VoMotion>, NoEstimate> {
        self.curr.usable = false;
        self.check_images(left, right, w, h)?;
        self.pair_features(left, right, w, h);
        self.check_textured()?;
        self.check_not_swapped()?;
        self.curr.usable = true;
        if !self.prev.usable {
            let first = !self.had_usable;
            self.had_usable = true;
            return if first {
                Ok(None)
            } else {
                Err(NoEstimate::NoReference)
            };
        }
        self.matches(w, h);
        self.motion().map(Some)
    }

    /// The images' sizes checked; a new size leaves nothing to match against.
    fn check_images(
        &mut self,
        left: &[u8],
        right: &[u8],
        w: usize,
        h: usize,
    ) -> Result<(), NoEstimate> {
        let min = 4 * (self.s.margin + 2 * self.s.nms_n + 8);
        if left.len() != w * h || right.len() != w * h {
            return Err(NoEstimate::BadImages(format!(
                "{} and {} bytes for {w}x{h} images",
                left.len(),
                right.len()
            )));
        }
        if w < min || h < min {
            return Err(NoEstimate::BadImages(format!(
                "{w}x{h} is smaller than {min}x{min}"
            )));
        }
        if self.size.is_some_and(|s| s != (w, h)) {
            // A new size: nothing to match against.
            self.prev.usable = false;
        }
        self.size = Some((w, h));
        Ok(())
    }

    /// The features of both images into `self.curr`, on two threads if the
    /// settings allow.
    fn pair_features(&mut self, left: &[u8], right: &[u8], w: usize, h: usize) {
        let mut curr = std::mem::take(&mut self.curr);
        let [sl, sr] = &mut self.scratch.images;
        let (s, (cl, cr)) = (&self.s, (&mut curr.left, &mut curr.right));
        if s.threads > 1 {
            // The two images on two threads: the right one is left for a scoped
            // thread, which this one takes over if it has not started by the time
            // the left one is done (or could not be spawned). The same features.
            let right_job = std::sync::Mutex::new(Some((sr, cr)));
            let right_job = &right_job;
            let take = || {
                right_job
                    .lock()
                    .unwrap_or_else(std::sync::PoisonError::into_inner)
                    .take()
            };
            std::thread::scope(|scope| {
                let other = std::thread::Builder::new()
                    .spawn_scoped(scope, move || {
                        if let Some((sr, cr)) = take() {
                            features(s, right, w, h, sr, cr);
                        }
                    })
                    .ok();
                features(s, left, w, h, sl, cl);
                if let Some((sr, cr)) = take() {
                    features(s, right, w, h, sr, cr);
                }
                if let Some(Err(panic)) = other.map(|t| t.join()) {
                    std::panic::resume_unwind(panic);
                }
            });
        } else {
            features(s, left, w, h, sl, cl);
            features(s, right, w, h, sr, cr);
        }
        self.curr = curr;
    }

    /// Enough features in both images of the current pair.
    fn check_textured(&self) -> Result<(), NoEstimate> {
        let (nl, nr) = (
            self.curr.left.dense.features.len(),
            self.curr.right.dense.features.len(),
        );
        let needed = self.s.min_features;
        if nl < needed || nr < needed {
            return Err(NoEstimate::Textureless {
                left: nl,
                right: nr,
                needed,
            });
        }
        Ok(())
    }

    /// The current pair's stereo matches mostly of positive disparity.
    ///
    /// A swapped pair would be matched in the wrong direction only, giving wrong
    /// motions without a word: this looks along the rows both ways first.
    fn check_not_swapped(&self) -> Result<(), NoEstimate> {
        let scale = if self.s.half_resolution { 2 } else { 1 };
        let (negative, positive) = matching::disparity_signs(
            &self.curr.left.dense,
            &self.curr.right.dense,
            (self.s.match_radius / scale).max(1),
            self.s.match_disp_tolerance,
            200,
        );
        if negative >= 20 && negative > 2 * positive {
            return Err(NoEstimate::SwappedStereo { negative, positive });
        }
        Ok(())
    }

    /// The motion from `scratch.matches`: RANSAC and Gauss–Newton on their
    /// reprojection errors; it becomes the prior of the next pair.
    fn motion(&mut self) -> Result<VoMotion, NoEstimate> {
        let sc = &mut self.scratch;
        egomotion::observations_into(
            &self.calib,
            &sc.matches,
            self.s.reweighting,
            &mut sc.observations,
        );
        let e = egomotion::estimate(
            &self.calib,
            &sc.observations,
            self.s.ransac_iterations,
            self.s.inlier_threshold,
            self.s.min_inliers,
            &mut self.rng,
            &mut sc.ransac,
        )?;
        self.last = Some(e.theta);
        Ok(VoMotion {
            tr: egomotion::transform(&e.theta),
            matches: sc.matches.len(),
            inliers: e.inliers,
        })
    }

    /// Circular matches of the previous and current pairs, refined, bucketed, at
    /// full resolution, into `scratch.matches`: `[prev_left, prev_right,
    /// curr_right, curr_left]`.
    fn matches(&mut self, w: usize, h: usize) {
        let s = &self.s;
        let sc = &mut self.scratch;
        let scale: usize = if s.half_resolution { 2 } else { 1 };
        let search = Search {
            radius: (s.match_radius / scale as i32).max(1),
            row_tolerance: s.match_disp_tolerance,
        };
        let (p, c) = (&self.prev, &self.curr);
        let prior = self
            .last
            .filter(|_| s.motion_prior_weight > 0.0)
            .map(|theta| {
                let tr = egomotion::transform(&theta);
                let k = scale as f64;
                let at = |x: f64| (x - (k - 1.0) / 2.0) / k;
                matching::MotionPrior {
                    r: nalgebra::Matrix3::from_fn(|i, j| tr[i][j]),
                    t: nalgebra::Vector3::new(tr[0][3], tr[1][3], tr[2][3]),
                    calib: Calibration {
                        f: self.calib.f / k,
                        cu: at(self.calib.cu),
                        cv: at(self.calib.cv),
                        baseline: self.calib.baseline,
                    },
                    weight: s.motion_prior_weight,
                }
            });
        let ranges = if s.multi_stage {
            let sparse = Circle {
                images: [
                    &p.left.sparse,
                    &p.right.sparse,
                    &c.right.sparse,
                    &c.left.sparse,
                ],
            };
            sparse.matches(&search, None, prior.as_ref(), s.threads, &mut sc.quads);
            sc.positions.clear();
            sc.positions
                .extend(sc.quads.iter().map(|k| sparse.positions(k)));
            if s.outlier_filter {
                let k = scale as f64;
                let full =
                    |q: &[(i32, i32); 4], m: usize| (f64::from(q[m].0) * k, f64::from(q[m].1) * k);
                outliers::filter(
                    &mut sc.positions,
                    full,
                    OUTLIER_TOLERANCES,
                    &mut sc.outliers,
                );
            }
            sc.ranges.rebuild(
                &sc.positions,
                w / scale,
                h / scale,
                (s.match_binsize / scale).max(1),
                (s.range_min_width / scale as i32).max(1),
            );
            Some(&sc.ranges)
        } else {
            None
        };
        let dense = Circle {
            images: [&p.left.dense, &p.right.dense, &c.right.dense, &c.left.dense],
        };
        dense.matches(&search, ranges, prior.as_ref(), s.threads, &mut sc.quads);
        let grads = [&p.left.full, &p.right.full, &c.right.full, &c.left.full];
        let images = [&p.left.image, &p.right.image, &c.right.image, &c.left.image];
        let mode = s.refinement;
        sc.candidates.clear();
        sc.candidates
            .extend(sc.quads.iter().map(|k| dense.full_positions(k, scale)));
        if s.outlier_filter {
            let at = |q: &[(f64, f64); 4], m: usize| q[m];
            outliers::filter(&mut sc.candidates, at, OUTLIER_TOLERANCES, &mut sc.outliers);
        }
        matching::bucket_refined(
            &mut sc.candidates,
            s.bucket_size,
            s.bucket_max,
            &mut self.rng,
            s.threads,
            &mut sc.buckets,
            &mut sc.matches,
            |q| match mode {
                Refinement::Photometric => refine::photometric(*q, images),
                _ => refine::refine(*q, grads, mode),
            },
        )
    }
}

/// libviso2's tolerances of the outlier filter, at full resolution.
const OUTLIER_TOLERANCES: outliers::Tolerances = outliers::Tolerances {
    disparity: 5.0,
    flow: 5.0,
};

/// Features of one image (both scales), its full-resolution gradients.
///
/// Compiled for AVX2 as well, chosen at run time, with the filters, the
/// suppression and the gradients inlined into it: fewer instructions (the
/// counts: docs/measurements.md, "The odometry's kernels"). The same features
/// on any machine: all integer arithmetic.
#[multiversion::multiversion(targets("x86_64+avx2"))]
fn features(
    s: &VoSettings,
    data: &[u8],
    w: usize,
    h: usize,
    sc: &mut ImageScratch,
    out: &mut ImageData,
) {
    sc.full.w = w;
    sc.full.h = h;
    sc.full.data.clear();
    sc.full.data.extend_from_slice(data);
    let img = if s.half_resolution {
        sc.full.half_into(&mut sc.half);
        &sc.half
    } else {
        &sc.full
    };
    sc.responses.compute(img);
    sc.grad.compute(img);
    let sparse_n = if 3 * s.nms_n > 10 {
        s.nms_n.max(10)
    } else {
        3 * s.nms_n
    };
    sc.responses.suppress_scales(
        (s.nms_n, &mut out.dense.features),
        s.multi_stage
            .then_some((sparse_n, &mut out.sparse.features)),
        s.nms_tau,
        s.margin,
        &sc.grad,
    );
    let scale = if s.half_resolution { 2 } else { 1 };
    let bin = (s.match_binsize / scale).max(1);
    // The dense features' windows are narrow (a search range, or a few rows):
    // finer bins scan fewer candidates outside them (a third of the ranges'
    // bins: 8 px at half resolution, measured best of 25, 16, 12, 8, 6; the
    // matches do not depend on it).
    let dense_bin = (bin / 3).max(1);
    out.dense
        .bins
        .build(&out.dense.features, img.w, img.h, dense_bin);
    if s.multi_stage {
        out.sparse
            .bins
            .build(&out.sparse.features, img.w, img.h, bin);
    }
    if s.refinement == Refinement::Photometric {
        out.image.w = w;
        out.image.h = h;
        out.image.data.clear();
        out.image.data.extend_from_slice(data);
    }
    if matches!(s.refinement, Refinement::Pixel | Refinement::Subpixel) {
        if s.half_resolution {
            out.full.compute(&sc.full);
        } else {
            std::mem::swap(&mut out.full, &mut sc.grad);
        }
    }
}

/// `items.iter().filter_map(f)` collected in order, the items split between
/// `threads` threads ([`filter_map_range_parallel`]).
pub(crate) fn filter_map_parallel<T: Sync, U: Send>(
    items: &[T],
    threads: usize,
    f: impl Fn(&T) -> Option<U> + Sync,
) -> Vec<U> {
    filter_map_range_parallel(items.len(), threads, |i| f(&items[i]))
}

/// `(0..n).filter_map(f)` collected in order, the indices split between
/// `threads` threads (scoped; this one takes the first share). A thread that cannot
/// be spawned leaves its share to this one; a panic in `f` is passed on.
pub(crate) fn filter_map_range_parallel<U: Send>(
    n: usize,
    threads: usize,
    f: impl Fn(usize) -> Option<U> + Sync,
) -> Vec<U> {
    // Below this, a thread costs more than it saves.
    const LEAST_PER_THREAD: usize = 32;
    let threads = threads.min(n / LEAST_PER_THREAD).max(1);
    if threads == 1 {
        return (0..n).filter_map(&f).collect();
    }
    let chunk = n.div_ceil(threads);
    let f = &f;
    std::thread::scope(|scope| {
        let others: Vec<_> = (chunk..n)
            .step_by(chunk)
            .map(|from| {
                let part = from..(from + chunk).min(n);
                let job = {
                    let part = part.clone();
                    move || part.filter_map(f).collect::<Vec<U>>()
                };
                (
                    part,
                    std::thread::Builder::new().spawn_scoped(scope, job).ok(),
                )
            })
            .collect();
        let mut out: Vec<U> = (0..chunk).filter_map(f).collect();
        for (part, handle) in others {
            match handle.map(|h| h.join()) {
                Some(Ok(v)) => out.extend(v),
                Some(Err(panic)) => std::panic::resume_unwind(panic),
                None => out.extend(part.filter_map(f)),
            }
        }
        out
    })
}

/// The median of `v` (sorted in place); NaN when empty.
pub fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

#[cfg(test)]
mod tests {
    use super::features::Features;
    use super::*;

    #[test]
    fn the_dispatched_features_are_the_baseline_code() {
        // `features` runs its AVX2 clone where the machine has AVX2; the filters
        // and the suppression called here are compiled at the baseline level.
        let mut rng = crate::math::rng::Rng::new(5);
        let (w, h) = (160, 120);
        let noise: Vec<u8> = (0..w * h).map(|_| (rng.next_u64() % 256) as u8).collect();
        // Smoothed noise: blobs and corners of every size.
        let data: Vec<u8> = (0..w * h)
            .map(|i| {
                let (u, v) = (i % w, i / w);
                let at = |du: usize, dv: usize| u32::from(noise[((v + dv) % h) * w + (u + du) % w]);
                ((at(0, 0) + at(1, 0) + at(0, 1) + at(1, 1)) / 4) as u8
            })
            .collect();
        let s = VoSettings::default();
        let (mut sc, mut out) = (ImageScratch::default(), ImageData::default());
        features(&s, &data, w, h, &mut sc, &mut out);
        let full = Gray { w, h, data };
        let (mut half, mut r, mut g) =
            (Gray::default(), Responses::default(), Gradients::default());
        full.half_into(&mut half);
        r.compute(&half);
        g.compute(&half);
        let (mut dense, mut sparse) = (Features::default(), Features::default());
        r.suppress_scales(
            (s.nms_n, &mut dense),
            Some((3 * s.nms_n, &mut sparse)),
            s.nms_tau,
            s.margin,
            &g,
        );
        assert!(dense.len() > 100, "features found: {}", dense.len());
        for (ours, base) in [
            (&out.dense.features, &dense),
            (&out.sparse.features, &sparse),
        ] {
            assert_eq!(
                (&ours.u, &ours.v, &ours.class),
                (&base.u, &base.v, &base.class)
            );
            assert_eq!((&ours.desc, &ours.peak), (&base.desc, &base.peak));
        }
    }
}
