//! What a real camera adds to the renderer's ideal image: motion blur during the
//! exposure, vignetting, a gain and exposure that differ between the two cameras
//! and from frame to frame, and sensor noise (read noise plus shot noise that grows
//! with the signal).
//!
//! Everything is seeded: the noise and gains of a frame are a function of the
//! sensor's `seed`, the frame's number and the camera (left or right) only, so a
//! frame is the same on every run and on any thread. The ideal sensor
//! ([`SensorConfig::default`]) changes nothing, bit for bit.
//!
//! The model, per pixel of an image rendered at irradiance `I` (grey levels of the
//! ideal renderer, 0..255):
//!
//! ```text
//! I' = I · (1 − vignetting · r²) · g_frame · g_camera + offset_camera
//! out = round(I' + n),  n ~ N(0, read_noise² + shot_noise² · I'/255), clamped to 0..255
//! ```
//!
//! with `r` the distance from the principal point relative to the image's corner,
//! `g_frame ~ 1 + N(0, exposure_jitter²)` common to both cameras (auto-exposure
//! hunting), `g_camera ~ 1 + N(0, gain_jitter²)` per camera and frame, times
//! `right_gain` and plus `right_offset` for the right camera (a mismatched pair).
//! Motion blur: the image is the mean of sub-frames rendered along the platform's
//! motion while the shutter is open ([`Exposure`]), as many as the image moves
//! pixels ([`SensorConfig::blur_samples`] at most).

use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::CameraConfig;
use crate::config::{Invalid, Validate, non_negative, positive};
use crate::math::rng::Rng;

/// The sensor of both cameras of the pair (see the [module docs](self)).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SensorConfig {
    /// Seed of the noise and gains.
    pub seed: u64,
    /// Read noise: standard deviation in grey levels, whatever the signal.
    pub read_noise: f64,
    /// Shot noise: standard deviation in grey levels at full scale (255); it
    /// grows with the square root of the signal.
    pub shot_noise: f64,
    /// Relative standard deviation of the exposure from frame to frame, common
    /// to both cameras (0.03: 3 %).
    pub exposure_jitter: f64,
    /// Relative standard deviation of each camera's gain from frame to frame.
    pub gain_jitter: f64,
    /// Gain of the right camera relative to the left (1: matched).
    pub right_gain: f64,
    /// Offset of the right camera relative to the left \[grey levels\].
    pub right_offset: f64,
    /// Brightness lost at the image's corners, relative (0: none; 0.3: the
    /// corners get 70 % of the light the centre gets), falling off with the
    /// square of the distance from the principal point.
    pub vignetting: f64,
    /// How long the shutter is open \[s\]: the image is blurred by the motion
    /// meanwhile (0: no blur).
    pub exposure_s: f64,
    /// Most sub-frames rendered for one blurred image (a sub-frame per pixel the
    /// image moves, up to this many).
    pub blur_samples: u32,
}

impl Default for SensorConfig {
    /// The ideal sensor: no noise, no blur, matched cameras.
    fn default() -> Self {
        SensorConfig {
            seed: 0,
            read_noise: 0.0,
            shot_noise: 0.0,
            exposure_jitter: 0.0,
            gain_jitter: 0.0,
            right_gain: 1.0,
            right_offset: 0.0,
            vignetting: 0.0,
            exposure_s: 0.0,
            blur_samples: 8,
        }
    }
}

impl SensorConfig {
    /// A machine-vision camera in an indoor room: 2 grey levels of read noise, 4 of
    /// shot noise at full scale, 3 % exposure hunting, 2 % gain jitter per camera,
    /// the right camera 6 % brighter with an offset of −3, 25 % vignetting, a 4 ms
    /// shutter.
    pub fn realistic(seed: u64) -> SensorConfig {
        SensorConfig {
            seed,
            read_noise: 2.0,
            shot_noise: 4.0,
            exposure_jitter: 0.03,
            gain_jitter: 0.02,
            right_gain: 1.06,
            right_offset: -3.0,
            vignetting: 0.25,
            exposure_s: 0.004,
            blur_samples: 8,
        }
    }

    /// Whether the sensor changes the image at all (besides motion blur).
    pub fn develops(&self) -> bool {
        self.read_noise > 0.0
            || self.shot_noise > 0.0
            || self.exposure_jitter > 0.0
            || self.gain_jitter > 0.0
            || self.right_gain != 1.0
            || self.right_offset != 0.0
            || self.vignetting > 0.0
    }

    /// Turn the ideal image `img` (`width × height` of `camera`, row-major) of
    /// the camera on `side` in frame `frame` into what this sensor delivers.
    pub fn develop(&self, camera: &CameraConfig, frame: u64, side: Side, img: &mut [u8]) {
        if !self.develops() {
            return;
        }
        // The frame's exposure is common to both cameras; each camera's gain and
        // noise are its own.
        let mut common = Rng::new(mix(self.seed, frame, 0));
        let mut own = Rng::new(mix(self.seed, frame, 1 + side as u64));
        let jitter = |rng: &mut Rng, sd: f64| (1.0 + rng.gauss(sd)).clamp(0.5, 1.5);
        let exposure = jitter(&mut common, self.exposure_jitter);
        let mut gain = exposure * jitter(&mut own, self.gain_jitter);
        let mut offset = 0.0;
        if side == Side::Right {
            gain *= self.right_gain;
            offset = self.right_offset;
        }
        let (w, h) = (camera.width as usize, camera.height as usize);
        let (cu, cv) = camera.principal_point();
        let corner2 = (cu * cu + cv * cv).max(1.0);
        let (gain, offset) = (gain as f32, offset as f32);
        let read2 = (self.read_noise * self.read_noise) as f32;
        let shot2 = (self.shot_noise * self.shot_noise / 255.0) as f32;
        let noisy = read2 > 0.0 || shot2 > 0.0;
        for (j, row) in img.chunks_exact_mut(w).take(h).enumerate() {
            let dv2 = (j as f64 - cv).powi(2);
            for (i, px) in row.iter_mut().enumerate() {
                let r2 = ((i as f64 - cu).powi(2) + dv2) / corner2;
                let shade = (1.0 - self.vignetting * r2) as f32;
                let mut v = f32::from(*px) * shade * gain + offset;
                if noisy {
                    let sd = (read2 + shot2 * v.max(0.0)).sqrt();
                    let n: f32 = StandardNormal.sample(&mut own);
                    v += sd * n;
                }
                *px = v.round().clamp(0.0, 255.0) as u8;
            }
        }
    }

    /// Sub-frames to render for `exposure` seen by `camera`: one per pixel the
    /// image moves during it (the rotation's shift, plus the translation's at 1 m),
    /// at least 1, at most [`SensorConfig::blur_samples`].
    pub fn sub_frames(&self, camera: &CameraConfig, exposure: &Exposure) -> u32 {
        let [x0, y0, a0] = exposure.open;
        let [x1, y1, a1] = exposure.close;
        const NEAR_M: f64 = 1.0;
        let shift = camera.focal * (wrap(a1 - a0).abs() + (x1 - x0).hypot(y1 - y0) / NEAR_M);
        if !shift.is_finite() {
            return 1;
        }
        (shift.ceil() as u32).clamp(1, self.blur_samples.max(1))
    }
}

impl Validate for SensorConfig {
    fn validate(&self) -> Result<(), Invalid> {
        non_negative("sensor.read_noise", self.read_noise)?;
        non_negative("sensor.shot_noise", self.shot_noise)?;
        non_negative("sensor.exposure_jitter", self.exposure_jitter)?;
        non_negative("sensor.gain_jitter", self.gain_jitter)?;
        positive("sensor.right_gain", self.right_gain)?;
        crate::config::finite("sensor.right_offset", self.right_offset)?;
        non_negative("sensor.vignetting", self.vignetting)?;
        non_negative("sensor.exposure_s", self.exposure_s)?;
        let limits = [
            ("sensor.read_noise", self.read_noise, 64.0),
            ("sensor.shot_noise", self.shot_noise, 64.0),
            ("sensor.exposure_jitter", self.exposure_jitter, 0.5),
            ("sensor.gain_jitter", self.gain_jitter, 0.5),
            ("sensor.right_gain", self.right_gain, 4.0),
            ("sensor.right_offset", self.right_offset.abs(), 128.0),
            ("sensor.vignetting", self.vignetting, 0.9),
            ("sensor.exposure_s", self.exposure_s, 0.1),
        ];
        for (field, value, most) in limits {
            if value > most {
                return Err((
                    field.to_owned(),
                    value.to_string(),
                    "is beyond what a camera does (noise <= 64 grey levels, jitter <= 0.5, right_gain <= 4, |right_offset| <= 128, vignetting <= 0.9, exposure_s <= 0.1)",
                ));
            }
        }
        if !(1..=64).contains(&self.blur_samples) {
            return Err((
                "sensor.blur_samples".into(),
                self.blur_samples.to_string(),
                "must be between 1 and 64",
            ));
        }
        Ok(())
    }
}

/// Which camera of the pair.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Side {
    /// The left (reference) camera.
    Left,
    /// The right camera.
    Right,
}

/// One exposure of the pair: the platform's pose `(x, y, φ)` when the shutter
/// opens and when it closes, and the frame's number (which seeds its noise).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Exposure {
    /// The pose when the shutter opens.
    pub open: [f64; 3],
    /// The pose when it closes.
    pub close: [f64; 3],
    /// The frame's number.
    pub frame: u64,
}

impl Exposure {
    /// A still platform at `body`.
    pub fn still(body: [f64; 3], frame: u64) -> Exposure {
        Exposure {
            open: body,
            close: body,
            frame,
        }
    }

    /// A platform at `body` at mid-exposure, moving with world-frame velocity
    /// `(ẋ, ẏ, φ̇)` during `duration` seconds.
    pub fn moving(body: [f64; 3], velocity: [f64; 3], duration: f64, frame: u64) -> Exposure {
        let half = 0.5 * duration;
        Exposure {
            open: [0, 1, 2].map(|k| body[k] - half * velocity[k]),
            close: [0, 1, 2].map(|k| body[k] + half * velocity[k]),
            frame,
        }
    }

    /// The pose a fraction `s` (0 open .. 1 closed) through the exposure.
    pub fn at(&self, s: f64) -> [f64; 3] {
        let [x0, y0, a0] = self.open;
        let [x1, y1, a1] = self.close;
        [
            x0 + s * (x1 - x0),
            y0 + s * (y1 - y0),
            a0 + s * wrap(a1 - a0),
        ]
    }
}

/// An angle in (−π, π].
fn wrap(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    a - t * ((a + std::f64::consts::PI) / t).floor()
}

/// A seed for one stream of one frame.
fn mix(seed: u64, frame: u64, stream: u64) -> u64 {
    seed ^ frame.wrapping_mul(0x9E37_79B9_7F4A_7C15) ^ stream.wrapping_mul(0xD1B5_4A32_D192_ED03)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn camera() -> CameraConfig {
        CameraConfig {
            width: 64,
            height: 48,
            ..CameraConfig::default()
        }
    }

    fn mean_sd(v: &[u8]) -> (f64, f64) {
        let n = v.len() as f64;
        let m = v.iter().map(|&x| f64::from(x)).sum::<f64>() / n;
        let var = v.iter().map(|&x| (f64::from(x) - m).powi(2)).sum::<f64>() / n;
        (m, var.sqrt())
    }

    #[test]
    fn the_ideal_sensor_changes_nothing() {
        let s = SensorConfig::default();
        assert!(!s.develops());
        let mut img: Vec<u8> = (0..64 * 48).map(|k| (k * 7 % 256) as u8).collect();
        let before = img.clone();
        s.develop(&camera(), 3, Side::Right, &mut img);
        assert_eq!(img, before);
    }

    #[test]
    fn noise_has_the_configured_deviation_and_is_the_same_for_the_same_frame() {
        let cam = CameraConfig {
            width: 400,
            height: 300,
            ..CameraConfig::default()
        };
        let s = SensorConfig {
            read_noise: 3.0,
            shot_noise: 6.0,
            ..SensorConfig::default()
        };
        let shot = |frame, side| {
            let mut img = vec![100u8; 400 * 300];
            s.develop(&cam, frame, side, &mut img);
            img
        };
        let a = shot(5, Side::Left);
        let (m, sd) = mean_sd(&a);
        let want = (9.0 + 36.0 * 100.0 / 255.0f64).sqrt();
        assert!((m - 100.0).abs() < 0.1, "mean {m}");
        // The rounding to grey levels adds 1/12 to the variance.
        let want = (want * want + 1.0 / 12.0).sqrt();
        assert!((sd / want - 1.0).abs() < 0.02, "sd {sd} want {want}");
        assert_eq!(a, shot(5, Side::Left), "seeded by the frame");
        assert_ne!(a, shot(6, Side::Left), "a new frame, new noise");
        assert_ne!(a, shot(5, Side::Right), "each camera its own noise");
    }

    #[test]
    fn gains_differ_between_cameras_and_frames_and_vignetting_darkens_the_corners() {
        let cam = camera();
        let s = SensorConfig {
            right_gain: 1.1,
            right_offset: -4.0,
            exposure_jitter: 0.05,
            ..SensorConfig::default()
        };
        let shot = |frame, side| {
            let mut img = vec![100u8; 64 * 48];
            s.develop(&cam, frame, side, &mut img);
            mean_sd(&img).0
        };
        for frame in 0..5 {
            let (l, r) = (shot(frame, Side::Left), shot(frame, Side::Right));
            assert!((r - (l * 1.1 - 4.0)).abs() < 1.1, "frame {frame}: {l} {r}");
        }
        let means: Vec<f64> = (0..20).map(|f| shot(f, Side::Left)).collect();
        let (lo, hi) = means
            .iter()
            .fold((f64::MAX, f64::MIN), |(a, b), &m| (a.min(m), b.max(m)));
        assert!(
            hi - lo > 3.0,
            "the exposure varies between frames: {means:?}"
        );

        let v = SensorConfig {
            vignetting: 0.3,
            ..SensorConfig::default()
        };
        let mut img = vec![200u8; 64 * 48];
        v.develop(&cam, 0, Side::Left, &mut img);
        let centre = img[24 * 64 + 32];
        assert!((i32::from(centre) - 200).abs() <= 1, "{centre}");
        assert_eq!(img[0], 140, "the corner gets 70 %");
    }

    #[test]
    fn sub_frames_follow_the_image_motion() {
        let cam = CameraConfig::default();
        let s = SensorConfig::realistic(1);
        assert_eq!(s.sub_frames(&cam, &Exposure::still([1.0, 2.0, 3.0], 0)), 1);
        // Turning at 1 rad/s for 4 ms: 1.6 px at f = 400.
        let e = Exposure::moving([0.0, 0.0, 3.0], [0.0, 0.0, 1.0], 0.004, 0);
        assert_eq!(s.sub_frames(&cam, &e), 2);
        let fast = Exposure::moving([0.0; 3], [0.0, 0.0, 20.0], 0.004, 0);
        assert_eq!(s.sub_frames(&cam, &fast), 8, "at most blur_samples");
        // The midpoint is the pose given, across the ±π seam too.
        let seam = Exposure {
            open: [0.0, 0.0, 3.1],
            close: [0.0, 0.0, -3.1],
            frame: 0,
        };
        assert!((seam.at(0.5)[2] - std::f64::consts::PI).abs() < 1e-12);
    }

    #[test]
    fn absurd_sensors_are_refused_with_the_field_named() {
        for (s, field) in [
            (
                SensorConfig {
                    read_noise: f64::NAN,
                    ..SensorConfig::default()
                },
                "sensor.read_noise",
            ),
            (
                SensorConfig {
                    right_gain: 0.0,
                    ..SensorConfig::default()
                },
                "sensor.right_gain",
            ),
            (
                SensorConfig {
                    vignetting: 1.5,
                    ..SensorConfig::default()
                },
                "sensor.vignetting",
            ),
            (
                SensorConfig {
                    blur_samples: 0,
                    ..SensorConfig::default()
                },
                "sensor.blur_samples",
            ),
        ] {
            assert_eq!(s.validate().unwrap_err().0, field);
        }
        assert!(SensorConfig::realistic(7).validate().is_ok());
    }
}
