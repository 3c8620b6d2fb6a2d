//! The stereo camera R1: a rectified pinhole pair fixed on the platform, rendering a
//! textured scene, and KITTI-format output.
//!
//! Camera frame as in KITTI: x right, y down, z forward (the optical axis). The left
//! camera is the reference; the right one is `baseline` metres along its x axis, with
//! the same orientation and intrinsics, so a point at depth `Z` has disparity
//! `f · b / Z` exactly.
//!
//! Pixel coordinates follow KITTI and OpenCV: the centre of pixel `(i, j)` (column
//! `i`, row `j`, from the top left) is at `(u, v) = (i, j)`, so the pixel covers
//! `[i − ½, i + ½] × [j − ½, j + ½]` and the image centre, the principal point, is at
//! `((w − 1)/2, (h − 1)/2)`. The renderer casts one ray through each pixel centre,
//! and `calib.txt` holds the same principal point, so a point projected with the
//! written matrices lands on the pixel that shows it.

pub mod kitti;
pub mod render;
pub mod scene;
pub mod sensor;

use nalgebra::{Matrix3, Rotation3, Vector3};
use serde::{Deserialize, Serialize};

use crate::algorithms::vo::Calibration;
use crate::config::{Invalid, Validate, finite, non_negative, positive};

pub use render::Renderer;
pub use scene::{Obstacle, Room, SceneConfig, Texture, Textures};
pub use sensor::{Exposure, SensorConfig, Side};

/// Resolution, optics and mounting of the stereo pair.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CameraConfig {
    /// Image width \[px\].
    pub width: u32,
    /// Image height \[px\].
    pub height: u32,
    /// Focal length \[px\].
    pub focal: f64,
    /// Baseline between the left and right optical centres \[m\].
    pub baseline: f64,
    /// Height of the optical centres above the floor \[m\].
    pub mount_height: f64,
    /// Distance of the optical centres ahead of the platform's centre of mass \[m\].
    pub mount_forward: f64,
    /// Downward pitch of the optical axis \[rad\].
    pub pitch: f64,
    /// What the sensor adds to the ideal image: noise, gains, vignetting, motion
    /// blur (default: the ideal sensor).
    #[serde(default)]
    pub sensor: SensorConfig,
}

impl Default for CameraConfig {
    /// 640×480, f = 400 px (77° horizontal field of view), baseline 0.3 m, 0.5 m
    /// above the floor, 0.2 m ahead of the centre of mass, pitched 0.1 rad down.
    fn default() -> Self {
        CameraConfig {
            width: 640,
            height: 480,
            focal: 400.0,
            baseline: 0.3,
            mount_height: 0.5,
            mount_forward: 0.2,
            pitch: 0.1,
            sensor: SensorConfig::default(),
        }
    }
}

impl Validate for CameraConfig {
    fn validate(&self) -> Result<(), Invalid> {
        if self.width < 16 || self.height < 16 || self.width > 8192 || self.height > 8192 {
            return Err((
                "width x height".into(),
                format!("{}x{}", self.width, self.height),
                "must be between 16 and 8192 pixels each",
            ));
        }
        positive("focal", self.focal)?;
        positive("baseline", self.baseline)?;
        non_negative("mount_height", self.mount_height)?;
        finite("mount_forward", self.mount_forward)?;
        finite("pitch", self.pitch)?;
        if self.pitch.abs() >= 1.5 {
            return Err((
                "pitch".into(),
                self.pitch.to_string(),
                "must be within ±1.5 rad",
            ));
        }
        self.sensor.validate()
    }
}

/// A rigid transform: `world = rotation · camera + center`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CameraPose {
    /// Optical centre in the world \[m\].
    pub center: [f64; 3],
    /// Columns are the camera axes (x right, y down, z forward) in world coordinates.
    pub rotation: [[f64; 3]; 3],
}

impl CameraPose {
    /// World coordinates of camera-frame vector `v` (rotation only).
    pub fn to_world_dir(&self, v: [f64; 3]) -> [f64; 3] {
        let r = &self.rotation;
        [0, 1, 2].map(|i| r[i][0] * v[0] + r[i][1] * v[1] + r[i][2] * v[2])
    }

    /// Camera coordinates of world point `p`.
    pub fn to_camera(&self, p: [f64; 3]) -> [f64; 3] {
        let d = [
            p[0] - self.center[0],
            p[1] - self.center[1],
            p[2] - self.center[2],
        ];
        let r = &self.rotation;
        [0, 1, 2].map(|j| r[0][j] * d[0] + r[1][j] * d[1] + r[2][j] * d[2])
    }

    /// As a 3×4 matrix `[R | c]` (camera to world), row-major.
    pub fn matrix(&self) -> [[f64; 4]; 3] {
        let r = &self.rotation;
        [0, 1, 2].map(|i| [r[i][0], r[i][1], r[i][2], self.center[i]])
    }
}

impl CameraConfig {
    /// Principal point `(c_u, c_v)` \[px\]: the image centre, `((w − 1)/2, (h − 1)/2)`
    /// with pixel centres at integer coordinates (KITTI and OpenCV convention).
    pub fn principal_point(&self) -> (f64, f64) {
        (
            (f64::from(self.width) - 1.0) / 2.0,
            (f64::from(self.height) - 1.0) / 2.0,
        )
    }

    /// The calibration the visual odometry needs: focal length, principal point,
    /// baseline.
    pub fn calibration(&self) -> Calibration {
        let (cu, cv) = self.principal_point();
        Calibration {
            f: self.focal,
            cu,
            cv,
            baseline: self.baseline,
        }
    }

    /// The pose of the left camera in the platform's frame (x forward, y left, z up;
    /// the camera's axes x right, y down, z forward) as a 4 × 4 transform: camera
    /// coordinates to platform coordinates.
    pub fn mount(&self) -> [[f64; 4]; 4] {
        let p = self.left_pose([0.0, 0.0, 0.0]);
        let r = &p.rotation;
        [
            [r[0][0], r[0][1], r[0][2], p.center[0]],
            [r[1][0], r[1][1], r[1][2], p.center[1]],
            [r[2][0], r[2][1], r[2][2], p.center[2]],
            [0.0, 0.0, 0.0, 1.0],
        ]
    }

    /// Pose of the left camera when the platform is at `(x, y, φ)`.
    pub fn left_pose(&self, body: [f64; 3]) -> CameraPose {
        let [x, y, phi] = body;
        // The camera's axes (x right, y down, z forward) in the body frame (x forward,
        // y left, z up) of a level camera, as columns; the camera pitched down by
        // `pitch` (about the body's y axis), the body turned by φ.
        #[rustfmt::skip]
        let level = Matrix3::new(
            0.0, 0.0, 1.0,
            -1.0, 0.0, 0.0,
            0.0, -1.0, 0.0,
        );
        let yaw = Rotation3::from_axis_angle(&Vector3::z_axis(), phi);
        let pitch = Rotation3::from_axis_angle(&Vector3::y_axis(), self.pitch);
        let rotation = (yaw * pitch).matrix() * level;
        let center = Vector3::new(x, y, 0.0)
            + yaw * Vector3::new(self.mount_forward, 0.0, self.mount_height);
        CameraPose {
            center: center.into(),
            // Row-major.
            rotation: rotation.transpose().into(),
        }
    }

    /// Pose of the right camera: the left one moved by the baseline along its x axis.
    pub fn right_pose(&self, body: [f64; 3]) -> CameraPose {
        let left = self.left_pose(body);
        let x = left.to_world_dir([1.0, 0.0, 0.0]);
        CameraPose {
            center: [0, 1, 2].map(|i| left.center[i] + self.baseline * x[i]),
            ..left
        }
    }

    /// Pixel coordinates `(u, v)` (pixel centres at integers) and depth of world
    /// point `p` seen from `pose`, if in front.
    pub fn project(&self, pose: &CameraPose, p: [f64; 3]) -> Option<(f64, f64, f64)> {
        let c = pose.to_camera(p);
        if c[2] <= 1e-9 {
            return None;
        }
        let (cu, cv) = self.principal_point();
        Some((
            self.focal * c[0] / c[2] + cu,
            self.focal * c[1] / c[2] + cv,
            c[2],
        ))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_known_point_lands_on_the_predicted_pixel_with_disparity_fb_over_z() {
        let cam = CameraConfig {
            pitch: 0.0,
            ..CameraConfig::default()
        };
        let body = [1.0, 2.0, 0.5];
        let left = cam.left_pose(body);
        let right = cam.right_pose(body);
        // 4 m straight ahead of the left camera, 0.5 m to its right, 0.25 m below.
        let p_cam = [0.5, 0.25, 4.0];
        let p = [0, 1, 2]
            .map(|i| left.center[i] + (0..3).map(|j| left.rotation[i][j] * p_cam[j]).sum::<f64>());
        let (u, v, z) = cam.project(&left, p).unwrap();
        let (cu, cv) = cam.principal_point();
        assert!((u - (cu + 400.0 * 0.5 / 4.0)).abs() < 1e-9, "u = {u}");
        assert!((v - (cv + 400.0 * 0.25 / 4.0)).abs() < 1e-9, "v = {v}");
        assert!((z - 4.0).abs() < 1e-12);
        let (ur, vr, _) = cam.project(&right, p).unwrap();
        assert!((vr - v).abs() < 1e-9, "rectified: same row");
        assert!(
            ((u - ur) - cam.focal * cam.baseline / z).abs() < 1e-9,
            "disparity f b / Z"
        );
        // The optical axis points along the heading, level with the floor.
        let axis = left.to_world_dir([0.0, 0.0, 1.0]);
        assert!((axis[0] - 0.5f64.cos()).abs() < 1e-12 && (axis[1] - 0.5f64.sin()).abs() < 1e-12);
        assert!(axis[2].abs() < 1e-12);
        assert!(
            cam.project(
                &left,
                [left.center[0] - axis[0], left.center[1] - axis[1], 0.5]
            )
            .is_none(),
            "behind"
        );
    }

    #[test]
    fn the_principal_point_is_the_centre_of_the_pixel_grid() {
        let cam = CameraConfig::default();
        assert_eq!(cam.principal_point(), (319.5, 239.5));
        // The optical axis passes through the image centre: between pixels 319 and
        // 320 of 640 (centres at 0..=639).
        let pose = cam.left_pose([0.0; 3]);
        let ahead = pose.to_world_dir([0.0, 0.0, 1.0]);
        let p = [0, 1, 2].map(|i| pose.center[i] + 3.0 * ahead[i]);
        let (u, v, _) = cam.project(&pose, p).unwrap();
        assert!((u - 319.5).abs() < 1e-9 && (v - 239.5).abs() < 1e-9);
        let odd = CameraConfig {
            width: 33,
            height: 17,
            ..CameraConfig::default()
        };
        assert_eq!(odd.principal_point(), (16.0, 8.0), "the middle pixel");
    }

    #[test]
    fn a_world_file_sets_the_sensor_and_absurd_values_are_named() {
        let text = "(width: 64, height: 48, focal: 50.0, baseline: 0.3, mount_height: 0.5,
            mount_forward: 0.2, pitch: 0.1,
            sensor: (seed: 11, read_noise: 2.0, shot_noise: 4.0, exposure_jitter: 0.03,
                     gain_jitter: 0.02, right_gain: 1.06, right_offset: -3.0,
                     vignetting: 0.25, exposure_s: 0.004, blur_samples: 8))";
        let path = std::path::Path::new("camera.ron");
        let cam: CameraConfig = crate::config::parse(path, text).unwrap();
        assert_eq!(cam.sensor, SensorConfig::realistic(11));
        // Without the block: the ideal sensor.
        let plain = text
            .split(",\n            sensor")
            .next()
            .unwrap()
            .to_owned()
            + ")";
        let cam: CameraConfig = crate::config::parse(path, &plain).unwrap();
        assert_eq!(cam.sensor, SensorConfig::default());
        let bad = text.replace("vignetting: 0.25", "vignetting: -1.0");
        let e = crate::config::parse::<CameraConfig>(path, &bad)
            .unwrap_err()
            .to_string();
        assert!(e.contains("sensor.vignetting"), "{e}");
        let unknown = text.replace("seed: 11", "sed: 11");
        assert!(crate::config::parse::<CameraConfig>(path, &unknown).is_err());
    }

    #[test]
    fn pitch_looks_down() {
        let cam = CameraConfig::default();
        let axis = cam.left_pose([0.0; 3]).to_world_dir([0.0, 0.0, 1.0]);
        assert!(axis[2] < 0.0 && (axis[2] + cam.pitch.sin()).abs() < 1e-12);
        let down = cam.left_pose([0.0; 3]).to_world_dir([0.0, 1.0, 0.0]);
        assert!(down[2] < -0.9, "image y points down: {down:?}");
    }
}
