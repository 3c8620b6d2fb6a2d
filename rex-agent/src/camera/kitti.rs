//! KITTI odometry sequences: writing what the simulated camera renders, and reading
//! any sequence back.
//!
//! Layout of a sequence folder:
//!
//! ```text
//! SEQ/image_0/000000.png   left images (8-bit grayscale)
//! SEQ/image_1/000000.png   right images
//! SEQ/calib.txt            P0: and P1: 3×4 projection matrices (P1 has −f·b)
//! SEQ/times.txt            one timestamp [s] per frame
//! SEQ/poses.txt            ground truth: the left camera's pose in the first
//!                          camera's frame, 3×4 row-major, one line per frame
//! ```
//!
//! KITTI keeps ground truth in `poses/NN.txt` beside `sequences/NN/`; the reader
//! looks for `SEQ/poses.txt` and then `SEQ/../../poses/NN.txt`.

use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::{CameraConfig, CameraPose};

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

/// A 4×4 rigid transform as its top 3×4 rows.
pub type Pose34 = [[f64; 4]; 3];

/// `a · b` for rigid transforms.
pub fn compose(a: &Pose34, b: &Pose34) -> Pose34 {
    let mut r = [[0.0; 4]; 3];
    for i in 0..3 {
        for j in 0..4 {
            r[i][j] =
                (0..3).map(|k| a[i][k] * b[k][j]).sum::<f64>() + if j == 3 { a[i][3] } else { 0.0 };
        }
    }
    r
}

/// The inverse of a rigid transform.
pub fn invert(a: &Pose34) -> Pose34 {
    let mut r = [[0.0; 4]; 3];
    for i in 0..3 {
        for j in 0..3 {
            r[i][j] = a[j][i];
        }
        r[i][3] = -(0..3).map(|k| a[k][i] * a[k][3]).sum::<f64>();
    }
    r
}

/// The identity transform.
pub const IDENTITY: Pose34 = [
    [1.0, 0.0, 0.0, 0.0],
    [0.0, 1.0, 0.0, 0.0],
    [0.0, 0.0, 1.0, 0.0],
];

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

/// Read an 8-bit grayscale PNG (RGB images are converted to luma).
pub fn read_png(path: &Path) -> Result<(u32, u32, Vec<u8>), KittiError> {
    let file = File::open(path).map_err(io(path))?;
    let mut decoder = png::Decoder::new(std::io::BufReader::new(file));
    decoder.set_transformations(png::Transformations::EXPAND | png::Transformations::STRIP_16);
    let mut reader = decoder
        .read_info()
        .map_err(|e| format_err(path, format!("not a PNG image: {e}")))?;
    let mut buf = vec![0; reader.output_buffer_size()];
    let info = reader
        .next_frame(&mut buf)
        .map_err(|e| format_err(path, format!("cannot decode: {e}")))?;
    let (w, h) = (info.width, info.height);
    let n = (w * h) as usize;
    let gray = match info.color_type {
        png::ColorType::Grayscale => buf[..n].to_vec(),
        png::ColorType::GrayscaleAlpha => buf[..2 * n].chunks_exact(2).map(|p| p[0]).collect(),
        png::ColorType::Rgb => buf[..3 * n]
            .chunks_exact(3)
            .map(|p| {
                ((77 * u32::from(p[0]) + 150 * u32::from(p[1]) + 29 * u32::from(p[2])) >> 8) as u8
            })
            .collect(),
        png::ColorType::Rgba => buf[..4 * n]
            .chunks_exact(4)
            .map(|p| {
                ((77 * u32::from(p[0]) + 150 * u32::from(p[1]) + 29 * u32::from(p[2])) >> 8) as u8
            })
            .collect(),
        png::ColorType::Indexed => return Err(format_err(path, "indexed PNGs are not supported")),
    };
    Ok((w, h, gray))
}

fn write_pose(out: &mut impl Write, p: &Pose34) -> std::io::Result<()> {
    let v: Vec<String> = p.iter().flatten().map(|x| format!("{x:e}")).collect();
    writeln!(out, "{}", v.join(" "))
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
    /// Create the folder (and `image_0`, `image_1`), write `calib.txt`.
    pub fn create(dir: &Path, camera: &CameraConfig) -> Result<SequenceWriter, KittiError> {
        for sub in ["image_0", "image_1"] {
            let d = dir.join(sub);
            fs::create_dir_all(&d).map_err(io(&d))?;
        }
        let (cu, cv) = camera.principal_point();
        let f = camera.focal;
        let calib = dir.join("calib.txt");
        let p = |tx: f64| format!("{f:e} 0 {cu:e} {tx:e} 0 {f:e} {cv:e} 0 0 0 1 0");
        fs::write(
            &calib,
            format!("P0: {}\nP1: {}\n", p(0.0), p(-f * camera.baseline)),
        )
        .map_err(io(&calib))?;
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
    /// Timestamps [s].
    pub times: Vec<f64>,
    /// Ground-truth poses, if present.
    pub poses: Option<Vec<Pose34>>,
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
            let text = fs::read_to_string(&path).map_err(io(&path))?;
            let list = text
                .lines()
                .enumerate()
                .filter(|(_, l)| !l.trim().is_empty())
                .map(|(i, l)| {
                    let v = parse_numbers(&path, i + 1, l)?;
                    if v.len() != 12 {
                        return Err(format_err(
                            &path,
                            format!("line {}: {} numbers, expected 12", i + 1, v.len()),
                        ));
                    }
                    Ok([
                        [v[0], v[1], v[2], v[3]],
                        [v[4], v[5], v[6], v[7]],
                        [v[8], v[9], v[10], v[11]],
                    ])
                })
                .collect::<Result<Vec<Pose34>, _>>()?;
            if list.len() != times.len() {
                return Err(format_err(
                    &path,
                    format!("{} poses for {} frames", list.len(), times.len()),
                ));
            }
            poses = Some(list);
        }
        Ok(Sequence {
            dir: dir.to_owned(),
            focal,
            principal: (p0[2], p0[6]),
            baseline,
            times,
            poses,
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
        if (w, h) != (w2, h2) {
            return Err(format_err(
                &rp,
                format!("{w2}x{h2}, but the left image is {w}x{h}"),
            ));
        }
        Ok((w, h, left, right))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn transforms_invert() {
        let cam = CameraConfig::default();
        let p = cam.left_pose([1.0, -2.0, 0.7]).matrix();
        let id = compose(&invert(&p), &p);
        for i in 0..3 {
            for j in 0..4 {
                let e = if i == j { 1.0 } else { 0.0 };
                assert!((id[i][j] - e).abs() < 1e-12);
            }
        }
    }
}
