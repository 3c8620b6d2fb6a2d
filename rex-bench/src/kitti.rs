//! KITTI odometry sequences as data sets: scripted paths of the simulated camera
//! written as sequences ([`ScriptedPath`], [`write_scripted`], [`is_current`]),
//! any sequence read back ([`Sequence`], [`read_poses`]), and the stereo visual
//! odometry of `rex_agent::algorithms::vo` run over one ([`run_sequence`]: the
//! `vo` and `bench_vo` examples). A sequence's folder and its `calib.txt` are
//! those [`SequenceWriter`] writes (see [`rex_agent::world::camera::kitti`]).
//!
//! The reader needs `P0:` and `P1:` only (files with just those two lines, as the
//! writer produced before, still open), and reads `Tr:` when it is there.
//!
//! KITTI keeps ground truth in `poses/NN.txt` beside `sequences/NN/`; the reader
//! looks for `SEQ/poses.txt` and then `SEQ/../../poses/NN.txt`.

use std::fs::{self, File};
use std::path::{Path, PathBuf};

use rex_agent::algorithms::vo::{Calibration, NoEstimate, StereoOdometry, VoSettings, VoStats};
use rex_agent::math::geometry::{IDENTITY, Pose34, compose, invert};
use rex_agent::math::rng::Rng;
use rex_agent::world::camera::kitti::{KittiError, SequenceWriter, read_png};
use rex_agent::world::camera::{Exposure, Renderer};

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> KittiError + '_ {
    move |source| KittiError::Io {
        path: path.to_owned(),
        source,
    }
}

fn format_err(path: &Path, message: impl Into<String>) -> KittiError {
    KittiError::Format {
        path: path.to_owned(),
        message: message.into(),
    }
}

/// Scripted paths of the platform through the room, for sequences of the camera
/// alone (10 frames per second in [`write_scripted`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ScriptedPath {
    /// The figure eight of the missions (2 m × 1 m lobes), 40 s per lap.
    FigureEight,
    /// Straight ahead at 0.3 m/s.
    Straight,
    /// Turning in place at 0.3 rad/s.
    Turn,
    /// A long tour of the room, different for each seed: three epicycles (the
    /// largest of 1.8-2.3 m radius) driven at 0.9-2.2 m/s, always forward, turning
    /// at most about 2 rad/s, within 4 m of the centre (clear of the shipped
    /// room's obstacles); 200 m take about 140 s.
    Tour(u64),
}

impl std::str::FromStr for ScriptedPath {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "figure_eight" => Ok(ScriptedPath::FigureEight),
            "straight" => Ok(ScriptedPath::Straight),
            "turn" => Ok(ScriptedPath::Turn),
            "tour" => Ok(ScriptedPath::Tour(1)),
            other => match other.strip_prefix("tour:").map(str::parse) {
                Some(Ok(seed)) => Ok(ScriptedPath::Tour(seed)),
                _ => Err(format!(
                    "unknown path `{other}` (figure_eight, straight, turn, tour, tour:SEED)"
                )),
            },
        }
    }
}

impl ScriptedPath {
    /// The platform's pose `(x, y, φ)` at `t` seconds.
    pub fn pose(self, t: f64) -> [f64; 3] {
        match self {
            ScriptedPath::FigureEight => {
                let w = std::f64::consts::TAU / 40.0;
                let (x, y) = (2.0 * (w * t).sin(), (2.0 * w * t).sin());
                let (dx, dy) = (2.0 * w * (w * t).cos(), 2.0 * w * (2.0 * w * t).cos());
                [x, y, dy.atan2(dx)]
            }
            ScriptedPath::Straight => [-3.0 + 0.3 * t, 0.5, 0.0],
            ScriptedPath::Turn => [0.0, 0.0, 0.3 * t],
            ScriptedPath::Tour(seed) => {
                let (c, terms) = tour(seed);
                let (mut p, mut v) = (c, [0.0, 0.0]);
                for [r, w, phase] in terms {
                    let (s, co) = (w * t + phase).sin_cos();
                    p = [p[0] + r * co, p[1] + r * s];
                    v = [v[0] - r * w * s, v[1] + r * w * co];
                }
                [p[0], p[1], v[1].atan2(v[0])]
            }
        }
    }

    /// The frames (10 per second) whose path is at least `length` metres long.
    pub fn frames_for(self, length: f64) -> usize {
        let mut travelled = 0.0;
        let mut last = self.pose(0.0);
        let mut k = 0usize;
        // Turning in place never gets anywhere: a bound keeps this finite.
        while travelled < length && k < 10_000_000 {
            k += 1;
            let p = self.pose(k as f64 * 0.1);
            travelled += (p[0] - last[0]).hypot(p[1] - last[1]);
            last = p;
        }
        k + 1
    }
}

/// The tour of `seed`: its centre and its three terms `(radius, rate, phase)`.
/// The first term's speed exceeds the others' together by at least 0.85 m/s, so
/// the platform always moves forward.
fn tour(seed: u64) -> ([f64; 2], [[f64; 3]; 3]) {
    let mut rng = Rng::stream(seed, "tour");
    let mut u = |lo: f64, hi: f64| lo + (hi - lo) * rng.uniform();
    let centre = [u(-0.3, 0.3), u(-0.3, 0.3)];
    let mut terms = [[0.0; 3]; 3];
    // (radius range, speed range) of each term.
    let ranges = [
        ((1.8, 2.3), (1.35, 1.65)),
        ((0.6, 0.9), (0.25, 0.35)),
        ((0.2, 0.4), (0.1, 0.15)),
    ];
    for (k, ((r0, r1), (s0, s1))) in ranges.into_iter().enumerate() {
        let r = u(r0, r1);
        let speed = u(s0, s1);
        let sign = if k > 0 && u(0.0, 1.0) < 0.5 {
            -1.0
        } else {
            1.0
        };
        terms[k] = [r, sign * speed / r, u(0.0, std::f64::consts::TAU)];
    }
    (centre, terms)
}

/// Render `frames` stereo pairs along `path` (10 per second) and write them as a
/// KITTI sequence in `dir`, with the true poses; returns the frames written. The
/// camera's sensor blurs each pair by the motion during its exposure (centred on
/// the pair's instant, the pose written) and adds its noise.
pub fn write_scripted(
    dir: &Path,
    renderer: &mut Renderer,
    path: ScriptedPath,
    frames: usize,
) -> Result<usize, KittiError> {
    let camera = renderer.camera().clone();
    let mut writer = SequenceWriter::create(dir, &camera)?;
    let (mut left, mut right) = (Vec::new(), Vec::new());
    for k in 0..frames {
        let (t, body) = capture_scripted(renderer, path, k, &mut left, &mut right);
        writer.push(t, &camera.left_pose(body), &left, &right)?;
    }
    writer.finish()
}

/// Frame `k` of [`write_scripted`]'s sequence along `path` into `left` and
/// `right`; its instant and the platform's pose then.
fn capture_scripted(
    renderer: &mut Renderer,
    path: ScriptedPath,
    k: usize,
    left: &mut Vec<u8>,
    right: &mut Vec<u8>,
) -> (f64, [f64; 3]) {
    let half = 0.5 * renderer.camera().sensor.exposure_s;
    let t = k as f64 * 0.1;
    let exposure = Exposure {
        open: path.pose(t - half),
        close: path.pose(t + half),
        frame: k as u64,
    };
    renderer.capture_pair(&exposure, left, right);
    (t, path.pose(t))
}

/// Whether `seq` is what [`write_scripted`] would write now with `renderer` along
/// `path`: as many frames as `frames`, and its first and last pairs the same
/// pixels as they render now (a sequence rendered by another version of the
/// renderer, or with another camera or scene, is not).
pub fn is_current(
    seq: &Sequence,
    renderer: &mut Renderer,
    path: ScriptedPath,
    frames: usize,
) -> Result<bool, KittiError> {
    if seq.len() != frames {
        return Ok(false);
    }
    let size = (renderer.camera().width, renderer.camera().height);
    let (mut left, mut right) = (Vec::new(), Vec::new());
    for k in [0, frames.saturating_sub(1)] {
        if k >= frames {
            break;
        }
        let (w, h, stored_left, stored_right) = seq.frame(k)?;
        capture_scripted(renderer, path, k, &mut left, &mut right);
        if (w, h) != size || stored_left != left || stored_right != right {
            return Ok(false);
        }
    }
    Ok(true)
}

/// The poses of a KITTI poses file (12 numbers a line: a 3 × 4 matrix, row-major),
/// as the ground truth or an odometry's estimate.
pub fn read_poses(path: &Path) -> Result<Vec<Pose34>, KittiError> {
    let text = fs::read_to_string(path).map_err(io(path))?;
    text.lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            let v = parse_numbers(path, i + 1, l)?;
            if v.len() != 12 {
                return Err(format_err(
                    path,
                    format!("line {}: {} numbers, expected 12", i + 1, v.len()),
                ));
            }
            Ok([
                [v[0], v[1], v[2], v[3]],
                [v[4], v[5], v[6], v[7]],
                [v[8], v[9], v[10], v[11]],
            ])
        })
        .collect()
}

/// A KITTI sequence on disk.
#[derive(Clone, Debug)]
pub struct Sequence {
    /// The folder.
    pub dir: PathBuf,
    /// Focal length \[px\].
    pub focal: f64,
    /// Principal point \[px\].
    pub principal: (f64, f64),
    /// Baseline \[m\].
    pub baseline: f64,
    /// `Tr:` of `calib.txt`, if there is one: body (Velodyne in KITTI) to left camera.
    pub body_to_camera: Option<Pose34>,
    /// Timestamps \[s\].
    pub times: Vec<f64>,
    /// Ground-truth poses, if present.
    pub poses: Option<Vec<Pose34>>,
    /// Size of the images (of the first left image) \[px\].
    pub size: (u32, u32),
}

/// The size of a PNG image, from its header.
fn png_size(path: &Path) -> Result<(u32, u32), KittiError> {
    let file = File::open(path).map_err(io(path))?;
    let decoder = png::Decoder::new(std::io::BufReader::new(file));
    let reader = decoder
        .read_info()
        .map_err(|e| format_err(path, format!("not a PNG image: {e}")))?;
    Ok(reader.info().size())
}

fn parse_numbers(path: &Path, line_no: usize, text: &str) -> Result<Vec<f64>, KittiError> {
    text.split_whitespace()
        .map(|t| {
            t.parse::<f64>()
                .map_err(|_| format_err(path, format!("line {line_no}: `{t}` is not a number")))
        })
        .collect()
}

/// What a sequence's `calib.txt` says of the left camera and the stereo pair.
struct CalibFile {
    focal: f64,
    principal: (f64, f64),
    baseline: f64,
    body_to_camera: Option<Pose34>,
}

impl CalibFile {
    /// Read `P0`, `P1` and the optional `Tr` (each a 3×4 matrix) from `path`.
    fn read(path: &Path) -> Result<CalibFile, KittiError> {
        let calib = fs::read_to_string(path).map_err(io(path))?;
        let mut matrices = std::collections::HashMap::new();
        for (i, line) in calib.lines().enumerate() {
            if let Some((key, rest)) = line.split_once(':') {
                matrices.insert(key.trim().to_owned(), parse_numbers(path, i + 1, rest)?);
            }
        }
        let get = |k: &str| -> Result<&Vec<f64>, KittiError> {
            matrices
                .get(k)
                .filter(|m| m.len() == 12)
                .ok_or_else(|| format_err(path, format!("no 3×4 matrix `{k}:`")))
        };
        let (p0, p1) = (get("P0")?, get("P1")?);
        let focal = p0[0];
        if focal.is_nan() || focal <= 0.0 || p1[3].is_nan() || p1[3] >= 0.0 {
            return Err(format_err(path, "P0 needs f > 0 and P1 a negative −f·b"));
        }
        let baseline = -p1[3] / p1[0];
        let body_to_camera = match matrices.get("Tr") {
            None => None,
            Some(v) if v.len() == 12 => Some([
                [v[0], v[1], v[2], v[3]],
                [v[4], v[5], v[6], v[7]],
                [v[8], v[9], v[10], v[11]],
            ]),
            Some(v) => {
                return Err(format_err(
                    path,
                    format!("`Tr:` has {} numbers, expected 12", v.len()),
                ));
            }
        };
        Ok(CalibFile {
            focal,
            principal: (p0[2], p0[6]),
            baseline,
            body_to_camera,
        })
    }
}

/// The frames' times from `times.txt` at `path`: finite and increasing (a pair's
/// motion is over its interval).
fn read_times(path: &Path) -> Result<Vec<f64>, KittiError> {
    let text = fs::read_to_string(path).map_err(io(path))?;
    let times = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty())
        .map(|(i, l)| {
            l.trim().parse::<f64>().map_err(|_| {
                format_err(
                    path,
                    format!("line {}: `{}` is not a time", i + 1, l.trim()),
                )
            })
        })
        .collect::<Result<Vec<f64>, _>>()?;
    for (k, t) in times.iter().enumerate() {
        if !t.is_finite() {
            return Err(format_err(
                path,
                format!("frame {k}: the time {t} is not a finite number"),
            ));
        }
        if k > 0 && *t <= times[k - 1] {
            return Err(format_err(
                path,
                format!(
                    "frame {k}: the time {t} does not come after frame {}'s, {}",
                    k - 1,
                    times[k - 1]
                ),
            ));
        }
    }
    Ok(times)
}

/// Check that both images of each of the `frames` frames exist in `dir`.
fn check_images(dir: &Path, frames: usize) -> Result<(), KittiError> {
    for k in 0..frames {
        for cam in ["image_0", "image_1"] {
            let p = dir.join(cam).join(format!("{k:06}.png"));
            if !p.is_file() {
                return Err(format_err(
                    &p,
                    format!("missing (times.txt lists {frames} frames)"),
                ));
            }
        }
    }
    Ok(())
}

/// The ground truth of the sequence in `dir`, if it has one: its `poses.txt`, or
/// KITTI's layout `../../poses/NAME.txt`; one pose per frame.
fn read_ground_truth(dir: &Path, frames: usize) -> Result<Option<Vec<Pose34>>, KittiError> {
    let candidates = [
        Some(dir.join("poses.txt")),
        dir.file_name().and_then(|n| {
            Some(
                dir.parent()?
                    .parent()?
                    .join("poses")
                    .join(format!("{}.txt", n.to_str()?)),
            )
        }),
    ];
    let Some(path) = candidates.into_iter().flatten().find(|p| p.is_file()) else {
        return Ok(None);
    };
    let list = read_poses(&path)?;
    if list.len() != frames {
        return Err(format_err(
            &path,
            format!("{} poses for {} frames", list.len(), frames),
        ));
    }
    Ok(Some(list))
}

impl Sequence {
    /// Open a sequence folder: reads `calib.txt`, `times.txt` and the ground truth if
    /// there is one; checks that every image exists.
    pub fn open(dir: &Path) -> Result<Sequence, KittiError> {
        let calib = CalibFile::read(&dir.join("calib.txt"))?;
        let times = read_times(&dir.join("times.txt"))?;
        check_images(dir, times.len())?;
        let poses = read_ground_truth(dir, times.len())?;
        let size = if times.is_empty() {
            (0, 0)
        } else {
            png_size(&dir.join("image_0").join("000000.png"))?
        };
        Ok(Sequence {
            dir: dir.to_owned(),
            focal: calib.focal,
            principal: calib.principal,
            baseline: calib.baseline,
            body_to_camera: calib.body_to_camera,
            times,
            poses,
            size,
        })
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.times.len()
    }

    /// Whether the sequence has no frame.
    pub fn is_empty(&self) -> bool {
        self.times.is_empty()
    }

    /// The left and right images of frame `k`, with their size.
    pub fn frame(&self, k: usize) -> Result<(u32, u32, Vec<u8>, Vec<u8>), KittiError> {
        let name = format!("{k:06}.png");
        let lp = self.dir.join("image_0").join(&name);
        let rp = self.dir.join("image_1").join(&name);
        let (w, h, left) = read_png(&lp)?;
        let (w2, h2, right) = read_png(&rp)?;
        // Each image against the sequence's size: the one that differs is named.
        let (sw, sh) = self.size;
        for (path, size) in [(&lp, (w, h)), (&rp, (w2, h2))] {
            if size != self.size {
                return Err(format_err(
                    path,
                    format!(
                        "{}x{}, but the sequence's images are {sw}x{sh} (image_0/000000.png)",
                        size.0, size.1
                    ),
                ));
            }
        }
        Ok((w, h, left, right))
    }
}

/// What [`run_sequence`] produced.
#[derive(Clone, Debug)]
pub struct SequenceRun {
    /// Estimated pose of each left camera in the frame of the first (KITTI's).
    pub poses: Vec<Pose34>,
    /// Processing time of each pair \[ms\] (reading the images excluded).
    pub ms: Vec<f64>,
    /// The odometry's counters.
    pub stats: VoStats,
    /// Image size.
    pub size: (u32, u32),
    /// The pairs without an estimate: frame and why.
    pub failures: Vec<(usize, NoEstimate)>,
}

/// Run the odometry over the first `frames` pairs of a KITTI sequence. A pair
/// without an estimate repeats the previous motion (constant velocity, as the peer
/// does) and is counted in `stats.failures`.
pub fn run_sequence(
    seq: &Sequence,
    settings: VoSettings,
    frames: usize,
) -> Result<SequenceRun, Box<dyn std::error::Error>> {
    let calib = Calibration {
        f: seq.focal,
        cu: seq.principal.0,
        cv: seq.principal.1,
        baseline: seq.baseline,
    };
    let mut vo = StereoOdometry::new(calib, settings)?;
    let n = frames.min(seq.len());
    let mut pose = IDENTITY;
    let mut last: Option<Pose34> = None;
    let mut out = SequenceRun {
        poses: Vec::with_capacity(n),
        ms: Vec::with_capacity(n),
        stats: VoStats::default(),
        size: (0, 0),
        failures: Vec::new(),
    };
    for k in 0..n {
        let (w, h, left, right) = seq.frame(k)?;
        out.size = (w, h);
        let t = std::time::Instant::now();
        let r = vo.process(&left, &right, w as usize, h as usize);
        out.ms.push(t.elapsed().as_secs_f64() * 1e3);
        let motion = match r {
            Ok(Some(m)) => {
                last = Some([m.tr[0], m.tr[1], m.tr[2]]);
                last
            }
            Ok(None) => None,
            Err(e) => {
                out.failures.push((k, e));
                last
            }
        };
        if let Some(tr) = motion {
            pose = compose(&pose, &invert(&tr));
        }
        out.poses.push(pose);
    }
    out.stats = vo.stats();
    Ok(out)
}

#[cfg(test)]
mod tests;
