//! KITTI odometry sequences written from what the simulated camera renders
//! ([`SequenceWriter`], which the stereo camera R1 records to), and the PNG
//! images they hold ([`write_png`], [`read_png`]). Reading a sequence back,
//! scripted sequences and running the visual odometry over one are data set
//! tooling, in the benchmark crate (`rex_bench::kitti`).
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

use std::fs::{self, File};
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use super::{CameraConfig, CameraPose};
use crate::config::{self, ConfigError};
use crate::math::geometry::{Pose34, compose, invert};

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

#[cfg(test)]
mod tests {
    //! The PNG reader against damaged and crafted files, and the transforms the
    //! poses are written with.

    use super::*;

    fn temp_dir(name: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("rex-kitti-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        dir
    }

    /// A PNG file with a header (IHDR) of `width × height` 8-bit gray, an image data
    /// chunk (IDAT) holding an empty zlib stream, and IEND.
    fn png_header_only(width: u32, height: u32) -> Vec<u8> {
        fn crc32(bytes: &[u8]) -> u32 {
            let mut crc = !0u32;
            for &b in bytes {
                crc ^= u32::from(b);
                for _ in 0..8 {
                    crc = if crc & 1 == 1 {
                        (crc >> 1) ^ 0xEDB8_8320
                    } else {
                        crc >> 1
                    };
                }
            }
            !crc
        }
        fn chunk(out: &mut Vec<u8>, kind: &[u8; 4], data: &[u8]) {
            out.extend_from_slice(&(data.len() as u32).to_be_bytes());
            let start = out.len();
            out.extend_from_slice(kind);
            out.extend_from_slice(data);
            let crc = crc32(&out[start..]);
            out.extend_from_slice(&crc.to_be_bytes());
        }
        let mut out = b"\x89PNG\r\n\x1a\n".to_vec();
        let mut ihdr = Vec::new();
        ihdr.extend_from_slice(&width.to_be_bytes());
        ihdr.extend_from_slice(&height.to_be_bytes());
        ihdr.extend_from_slice(&[8, 0, 0, 0, 0]); // 8 bits, gray, deflate, no filter, no interlace
        chunk(&mut out, b"IHDR", &ihdr);
        chunk(
            &mut out,
            b"IDAT",
            &[0x78, 0x9c, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01],
        );
        chunk(&mut out, b"IEND", &[]);
        out
    }

    #[test]
    fn crafted_png_headers_are_errors_not_panics_or_huge_allocations() {
        let dir = temp_dir("png");
        fs::create_dir_all(&dir).unwrap();
        let path = dir.join("crafted.png");
        // w·h overflows u32 (65536² = 2³², 100000² > 2³²), or is merely too large.
        for (w, h) in [
            (65_536, 65_536),
            (100_000, 100_000),
            (70_000, 70_000),
            (16_385, 1),
            (1, 16_385),
        ] {
            fs::write(&path, png_header_only(w, h)).unwrap();
            let err = read_png(&path).unwrap_err().to_string();
            assert!(
                err.contains("crafted.png")
                    && err.contains(&format!("{w}x{h}"))
                    && err.contains("16384"),
                "{w}x{h}: {err}"
            );
        }
        // Wider than the decoder's own limits: its error, naming the file.
        fs::write(&path, png_header_only(2_000_000_000, 3)).unwrap();
        let err = read_png(&path).unwrap_err().to_string();
        assert!(err.contains("crafted.png"), "{err}");
        // A plausible size but no image data: a decoding error.
        fs::write(&path, png_header_only(640, 480)).unwrap();
        let err = read_png(&path).unwrap_err().to_string();
        assert!(
            err.contains("crafted.png") && err.contains("cannot decode"),
            "{err}"
        );
        // Not a PNG at all.
        fs::write(&path, b"P5 640 480 255\n").unwrap();
        let err = read_png(&path).unwrap_err().to_string();
        assert!(err.contains("not a PNG"), "{err}");
        // A real one round-trips.
        let data: Vec<u8> = (0..=255u8).cycle().take(37 * 11).collect();
        write_png(&path, 37, 11, &data).unwrap();
        assert_eq!(read_png(&path).unwrap(), (37, 11, data));
        fs::remove_dir_all(&dir).unwrap();
    }

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
