//! KITTI odometry sequences: writing what the simulated camera renders, and reading
//! any sequence back.
//!
//! Layout of a sequence folder:
//!
//! ```text
//! SEQ/image_0/000000.png   left images (8-bit grayscale)
//! SEQ/image_1/000000.png   right images
//! SEQ/calib.txt            P0:..P3: 3×4 projection matrices, Tr: a 3×4 transform
//! SEQ/times.txt            one timestamp [s] per frame
//! SEQ/poses.txt            ground truth: the left camera's pose in the first
//!                          camera's frame, 3×4 row-major, one line per frame
//! ```
//!
//! `calib.txt` has the five lines of a KITTI odometry sequence, so KITTI tools
//! (`pykitti.odometry`, evaluation scripts) read it:
//!
//! * `P0:` the left camera, `[f 0 c_u 0; 0 f c_v 0; 0 0 1 0]`, and `P1:` the right
//!   one, the same with `−f·b` in the last column; the principal point `(c_u, c_v)`
//!   is `((w − 1)/2, (h − 1)/2)`, with pixel centres at integer coordinates as in
//!   KITTI and OpenCV (see [`CameraConfig::principal_point`]), which is where the
//!   renderer puts them.
//! * `P2:` and `P3:` are copies of `P0:` and `P1:`. KITTI's colour cameras 2 and 3
//!   have their own lines; the simulated rig has no colour camera, so tools that
//!   expect them get the grayscale pair again (there are no `image_2/`, `image_3/`).
//! * `Tr:` maps the platform's body frame (x forward, y left, z up, origin at the
//!   centre of mass on the floor) to the left camera's frame. In KITTI it maps the
//!   Velodyne frame, which has the same axes, to camera 0; there is no laser scanner
//!   here, the body frame takes its place.
//!
//! The reader needs `P0:` and `P1:` only (files with just those two lines, as this
//! writer produced before, still open), and reads `Tr:` when it is there.
//!
//! KITTI keeps ground truth in `poses/NN.txt` beside `sequences/NN/`; the reader
//! looks for `SEQ/poses.txt` and then `SEQ/../../poses/NN.txt`.
//!
//! [`run_sequence`] runs the stereo visual odometry of `algorithms::vo` over a
//! sequence on disk (the `vo` and `bench_vo` examples).

use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::{CameraConfig, CameraPose};
use crate::algorithms::vo::{Calibration, NoEstimate, StereoOdometry, VoSettings, VoStats};
use crate::config::{self, ConfigError};
use crate::math::geometry::{IDENTITY, Pose34, compose, invert};

/// A problem with a sequence folder, naming the file.
#[derive(Debug, thiserror::Error)]
pub enum KittiError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A file has the wrong content.
    #[error("{path}: {message}")]
    Format {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// The camera to write a sequence for is invalid.
    #[error(transparent)]
    Camera(#[from] ConfigError),
}

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

/// Write a grayscale PNG.
pub fn write_png(path: &Path, width: u32, height: u32, data: &[u8]) -> Result<(), KittiError> {
    let file = File::create(path).map_err(io(path))?;
    let mut encoder = png::Encoder::new(BufWriter::new(file), width, height);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Fast);
    let mut writer = encoder
        .write_header()
        .map_err(|e| format_err(path, e.to_string()))?;
    writer
        .write_image_data(data)
        .map_err(|e| format_err(path, e.to_string()))
}

/// The largest image [`read_png`] accepts: 16384 pixels in each direction.
pub const MAX_PNG_SIDE: u32 = 16_384;

/// Read an 8-bit grayscale PNG (RGB images are converted to luma). An image larger
/// than [`MAX_PNG_SIDE`] in either direction (a damaged or crafted header) is an
/// error before anything is allocated for it.
pub fn read_png(path: &Path) -> Result<(u32, u32, Vec<u8>), KittiError> {
    let file = File::open(path).map_err(io(path))?;
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder
        .read_info()
        .map_err(|e| format_err(path, format!("not a PNG image: {e}")))?;
    let (w, h) = reader.info().size();
    if w == 0 || h == 0 || w > MAX_PNG_SIDE || h > MAX_PNG_SIDE {
        return Err(format_err(
            path,
            format!(
                "the header says {w}x{h} pixels; images must be 1 to {MAX_PNG_SIDE} pixels in each direction"
            ),
        ));
    }
    // At most 4 bytes per pixel after the transformations (RGBA, 8 bits), so the
    // buffer is at most 1 GiB; still, compute in usize with checked arithmetic.
    let n = (w as usize)
        .checked_mul(h as usize)
        .ok_or_else(|| format_err(path, format!("{w}x{h} pixels overflow")))?;
    let (color, _) = reader.output_color_type();
    let channels = color.samples();
    let size = n
        .checked_mul(channels)
        .filter(|&size| size == reader.output_buffer_size())
        .ok_or_else(|| {
            format_err(
                path,
                format!("{w}x{h} pixels of {color:?}: unexpected buffer size"),
            )
        })?;
    let mut buf = vec![0; size];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| format_err(path, format!("cannot decode: {e}")))?;
    if (info.width, info.height) != (w, h) || info.color_type != color {
        return Err(format_err(
            path,
            format!(
                "the frame is {}x{} {:?}, the header {w}x{h} {color:?}",
                info.width, info.height, info.color_type
            ),
        ));
    }
    let luma = |p: &[u8]| {
        ((77 * u32::from(p[0]) + 150 * u32::from(p[1]) + 29 * u32::from(p[2])) >> 8) as u8
    };
    let gray = match color {
        png::ColorType::Grayscale => buf,
        png::ColorType::GrayscaleAlpha => buf.chunks_exact(2).map(|p| p[0]).collect(),
        png::ColorType::Rgb => buf.chunks_exact(3).map(luma).collect(),
        png::ColorType::Rgba => buf.chunks_exact(4).map(luma).collect(),
        png::ColorType::Indexed => return Err(format_err(path, "indexed PNGs are not supported")),
    };
    Ok((w, h, gray))
}

fn matrix_text(p: &Pose34) -> String {
    let v: Vec<String> = p.iter().flatten().map(|x| format!("{x:e}")).collect();
    v.join(" ")
}

fn write_pose(out: &mut impl Write, p: &Pose34) -> std::io::Result<()> {
    writeln!(out, "{}", matrix_text(p))
}

/// The contents of `calib.txt` for `camera` (see the module docs).
pub fn calib_text(camera: &CameraConfig) -> String {
    let (cu, cv) = camera.principal_point();
    let f = camera.focal;
    let p = |tx: f64| matrix_text(&[[f, 0.0, cu, tx], [0.0, f, cv, 0.0], [0.0, 0.0, 1.0, 0.0]]);
    let (p0, p1) = (p(0.0), p(-f * camera.baseline));
    // Camera to body is the left camera's pose with the platform at the origin.
    let tr = invert(&camera.left_pose([0.0; 3]).matrix());
    format!(
        "P0: {p0}\nP1: {p1}\nP2: {p0}\nP3: {p1}\nTr: {}\n",
        matrix_text(&tr)
    )
}

/// Writes frames of the simulated stereo camera as a KITTI sequence.
pub struct SequenceWriter {
    dir: PathBuf,
    camera: CameraConfig,
    count: usize,
    first_inverse: Option<Pose34>,
    times: BufWriter<File>,
    poses: BufWriter<File>,
}

impl SequenceWriter {
    /// Create the folder (and `image_0`, `image_1`), write `calib.txt` (see the
    /// module docs). The camera is validated first.
    pub fn create(dir: &Path, camera: &CameraConfig) -> Result<SequenceWriter, KittiError> {
        config::check("camera", camera)?;
        for sub in ["image_0", "image_1"] {
            let d = dir.join(sub);
            fs::create_dir_all(&d).map_err(io(&d))?;
        }
        let calib = dir.join("calib.txt");
        fs::write(&calib, calib_text(camera)).map_err(io(&calib))?;
        let open = |name: &str| -> Result<BufWriter<File>, KittiError> {
            let path = dir.join(name);
            File::create(&path).map(BufWriter::new).map_err(io(&path))
        };
        Ok(SequenceWriter {
            dir: dir.to_owned(),
            camera: camera.clone(),
            count: 0,
            first_inverse: None,
            times: open("times.txt")?,
            poses: open("poses.txt")?,
        })
    }

    /// Append a frame: its time, the left camera's true pose, and both images.
    pub fn push(
        &mut self,
        time: f64,
        left_pose: &CameraPose,
        left: &[u8],
        right: &[u8],
    ) -> Result<(), KittiError> {
        let name = format!("{:06}.png", self.count);
        let (w, h) = (self.camera.width, self.camera.height);
        write_png(&self.dir.join("image_0").join(&name), w, h, left)?;
        write_png(&self.dir.join("image_1").join(&name), w, h, right)?;
        let pose = left_pose.matrix();
        let first = *self.first_inverse.get_or_insert_with(|| invert(&pose));
        let times_path = self.dir.join("times.txt");
        writeln!(self.times, "{time:e}").map_err(io(&times_path))?;
        let poses_path = self.dir.join("poses.txt");
        write_pose(&mut self.poses, &compose(&first, &pose)).map_err(io(&poses_path))?;
        self.count += 1;
        Ok(())
    }

    /// Flush the text files; returns the number of frames.
    pub fn finish(mut self) -> Result<usize, KittiError> {
        let t = self.dir.join("times.txt");
        self.times.flush().map_err(io(&t))?;
        let p = self.dir.join("poses.txt");
        self.poses.flush().map_err(io(&p))?;
        Ok(self.count)
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
    let mut rng = crate::math::rng::Rng::stream(seed, "tour");
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
    renderer: &mut super::Renderer,
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
    renderer: &mut super::Renderer,
    path: ScriptedPath,
    k: usize,
    left: &mut Vec<u8>,
    right: &mut Vec<u8>,
) -> (f64, [f64; 3]) {
    let half = 0.5 * renderer.camera().sensor.exposure_s;
    let t = k as f64 * 0.1;
    let exposure = super::Exposure {
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
    renderer: &mut super::Renderer,
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
    /// Focal length [px].
    pub focal: f64,
    /// Principal point [px].
    pub principal: (f64, f64),
    /// Baseline [m].
    pub baseline: f64,
    /// `Tr:` of `calib.txt`, if there is one: body (Velodyne in KITTI) to left camera.
    pub body_to_camera: Option<Pose34>,
    /// Timestamps [s].
    pub times: Vec<f64>,
    /// Ground-truth poses, if present.
    pub poses: Option<Vec<Pose34>>,
    /// Size of the images (of the first left image) [px].
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

impl Sequence {
    /// Open a sequence folder: reads `calib.txt`, `times.txt` and the ground truth if
    /// there is one; checks that every image exists.
    pub fn open(dir: &Path) -> Result<Sequence, KittiError> {
        let calib_path = dir.join("calib.txt");
        let calib = fs::read_to_string(&calib_path).map_err(io(&calib_path))?;
        let mut matrices = std::collections::HashMap::new();
        for (i, line) in calib.lines().enumerate() {
            if let Some((key, rest)) = line.split_once(':') {
                matrices.insert(
                    key.trim().to_owned(),
                    parse_numbers(&calib_path, i + 1, rest)?,
                );
            }
        }
        let get = |k: &str| -> Result<&Vec<f64>, KittiError> {
            matrices
                .get(k)
                .filter(|m| m.len() == 12)
                .ok_or_else(|| format_err(&calib_path, format!("no 3×4 matrix `{k}:`")))
        };
        let (p0, p1) = (get("P0")?, get("P1")?);
        let focal = p0[0];
        if focal.is_nan() || focal <= 0.0 || p1[3].is_nan() || p1[3] >= 0.0 {
            return Err(format_err(
                &calib_path,
                "P0 needs f > 0 and P1 a negative −f·b",
            ));
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
                    &calib_path,
                    format!("`Tr:` has {} numbers, expected 12", v.len()),
                ));
            }
        };
        let times_path = dir.join("times.txt");
        let times_text = fs::read_to_string(&times_path).map_err(io(&times_path))?;
        let times = times_text
            .lines()
            .enumerate()
            .filter(|(_, l)| !l.trim().is_empty())
            .map(|(i, l)| {
                l.trim().parse::<f64>().map_err(|_| {
                    format_err(
                        &times_path,
                        format!("line {}: `{}` is not a time", i + 1, l.trim()),
                    )
                })
            })
            .collect::<Result<Vec<f64>, _>>()?;
        // Times are finite and increase (a pair's motion is over its interval).
        for (k, t) in times.iter().enumerate() {
            if !t.is_finite() {
                return Err(format_err(
                    &times_path,
                    format!("frame {k}: the time {t} is not a finite number"),
                ));
            }
            if k > 0 && *t <= times[k - 1] {
                return Err(format_err(
                    &times_path,
                    format!(
                        "frame {k}: the time {t} does not come after frame {}'s, {}",
                        k - 1,
                        times[k - 1]
                    ),
                ));
            }
        }
        for k in 0..times.len() {
            for cam in ["image_0", "image_1"] {
                let p = dir.join(cam).join(format!("{k:06}.png"));
                if !p.is_file() {
                    return Err(format_err(
                        &p,
                        format!("missing (times.txt lists {} frames)", times.len()),
                    ));
                }
            }
        }
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
        let mut poses = None;
        if let Some(path) = candidates.into_iter().flatten().find(|p| p.is_file()) {
            let list = read_poses(&path)?;
            if list.len() != times.len() {
                return Err(format_err(
                    &path,
                    format!("{} poses for {} frames", list.len(), times.len()),
                ));
            }
            poses = Some(list);
        }
        let size = if times.is_empty() {
            (0, 0)
        } else {
            png_size(&dir.join("image_0").join("000000.png"))?
        };
        Ok(Sequence {
            dir: dir.to_owned(),
            focal,
            principal: (p0[2], p0[6]),
            baseline,
            body_to_camera,
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
    /// Processing time of each pair [ms] (reading the images excluded).
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
