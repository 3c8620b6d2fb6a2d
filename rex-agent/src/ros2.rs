//! Rex shown to ROS 2: how its buffers become the standard messages a ROS user
//! expects, for the bridge that publishes what `specs/rex.ron`'s `ros2` section
//! names ([`embodied::ros2::bridge`]).
//!
//! | buffer | type | message |
//! |---|---|---|
//! | `c3.c1.pose` | [`MapPose`] | `geometry_msgs/msg/PoseStamped` in the frame `map` |
//! | `c1.e11.traj` | [`Fragment`] | `nav_msgs/msg/Path`: the fragment's reference poses, each stamped `k · dt` after the fragment's |
//! | `E1.e11.imu` | [`Imu`] | `sensor_msgs/msg/Imu` in the frame `base_link` |
//! | `R1.r11.img_lr` | [`StereoPair`] | `sensor_msgs/msg/CompressedImage`: the left image as PNG |
//!
//! The other buffers of the section (e11's estimate, the acknowledgements and
//! outcomes) go as messages of Rex's own package, made from their types.

use embodied::ros2::bridge::Adapters;
use embodied::ros2::types::standard::builtin_interfaces::Time;
use embodied::ros2::types::standard::geometry_msgs::{
    Point, Pose, PoseStamped, Quaternion, Vector3,
};
use embodied::ros2::types::standard::nav_msgs::Path;
use embodied::ros2::types::standard::sensor_msgs::{self, CompressedImage};
use embodied::ros2::types::standard::std_msgs::Header;
use nalgebra::UnitQuaternion;

use crate::algorithms::planner::Fragment;
use crate::payload::{Imu, MapPose, StereoPair};

/// The frame of every pose on the map (the motion capture's, the plans').
pub const MAP_FRAME: &str = "map";
/// The platform's body frame (the IMU's).
pub const BODY_FRAME: &str = "base_link";
/// The camera's frame.
pub const CAMERA_FRAME: &str = "camera_left";

/// Rex's adapters to the standard messages (see the module's table).
pub fn adapters() -> Adapters {
    Adapters::new()
        .publish::<MapPose, PoseStamped>(|p, stamp| {
            pose_stamped(p.pose.x, p.pose.y, p.pose.phi, stamp)
        })
        .publish::<Fragment, Path>(path)
        .publish::<Imu, sensor_msgs::Imu>(imu)
        .publish::<StereoPair, CompressedImage>(image)
}

/// The orientation of heading `phi` \[rad\] about the vertical axis.
fn yaw(phi: f64) -> Quaternion {
    let q = UnitQuaternion::from_euler_angles(0.0, 0.0, phi);
    Quaternion {
        x: q.i,
        y: q.j,
        z: q.k,
        w: q.w,
    }
}

fn header(stamp: Time, frame: &str) -> Header {
    Header {
        stamp,
        frame_id: frame.to_owned(),
    }
}

fn pose_stamped(x: f64, y: f64, phi: f64, stamp: Time) -> PoseStamped {
    PoseStamped {
        header: header(stamp, MAP_FRAME),
        pose: Pose {
            position: Point { x, y, z: 0.0 },
            orientation: yaw(phi),
        },
    }
}

/// `stamp` moved on by `seconds` (saturating at the ends of ROS 2's time).
fn later(stamp: Time, seconds: f64) -> Time {
    let ns = i128::from(stamp.sec) * 1_000_000_000
        + i128::from(stamp.nanosec)
        + (seconds * 1e9).round() as i128;
    let sec = ns.div_euclid(1_000_000_000);
    Time {
        sec: i32::try_from(sec).unwrap_or(if sec < 0 { i32::MIN } else { i32::MAX }),
        nanosec: u32::try_from(ns.rem_euclid(1_000_000_000)).unwrap_or(0),
    }
}

/// A fragment's reference poses `(X, Y, φ)`, the `k`-th stamped `k · dt` after
/// the fragment's own stamp.
fn path(f: &Fragment, stamp: Time) -> Path {
    Path {
        header: header(stamp, MAP_FRAME),
        poses: f
            .states
            .iter()
            .enumerate()
            .map(|(k, s)| pose_stamped(s[0], s[1], s[2], later(stamp, k as f64 * f.dt)))
            .collect(),
    }
}

/// The IMU's reading: the integrated heading as the orientation (the platform
/// is planar: no roll, no pitch), the yaw rate about `z`, the body-frame
/// acceleration in `x`, `y` (`z` is 0: the simulated unit measures no vertical
/// axis, gravity included). Covariances all zero: unknown, as `sensor_msgs`
/// says.
fn imu(m: &Imu, stamp: Time) -> sensor_msgs::Imu {
    sensor_msgs::Imu {
        header: header(stamp, BODY_FRAME),
        orientation: yaw(m.yaw),
        orientation_covariance: [0.0; 9],
        angular_velocity: Vector3 {
            x: 0.0,
            y: 0.0,
            z: m.yaw_rate,
        },
        angular_velocity_covariance: [0.0; 9],
        linear_acceleration: Vector3 {
            x: m.accel[0],
            y: m.accel[1],
            z: 0.0,
        },
        linear_acceleration_covariance: [0.0; 9],
    }
}

/// The pair's left image as PNG (format `png`, as image_transport's
/// compressed images name it); a pair whose size disagrees with its pixels
/// goes as an empty image of format `png` (the subscriber sees it and the
/// bridge's count goes on; no value is made up).
fn image(pair: &StereoPair, stamp: Time) -> CompressedImage {
    let mut data = Vec::new();
    let fits = usize::try_from(u64::from(pair.width) * u64::from(pair.height))
        .is_ok_and(|n| n > 0 && n == pair.left.len());
    if !(fits
        && crate::record::stereo_png::encode_png(&pair.left, pair.width, pair.height, &mut data))
    {
        data.clear();
    }
    CompressedImage {
        header: header(stamp, CAMERA_FRAME),
        format: "png".to_owned(),
        data,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::payload::Pose2;

    fn at(sec: i32, nanosec: u32) -> Time {
        Time { sec, nanosec }
    }

    #[test]
    fn a_pose_on_the_map_is_a_pose_stamped_with_its_heading_about_z() {
        let p = MapPose {
            pose: Pose2 {
                x: 1.5,
                y: -2.0,
                phi: std::f64::consts::FRAC_PI_2,
            },
            time: 3.0,
        };
        let m = pose_stamped(p.pose.x, p.pose.y, p.pose.phi, at(7, 5));
        assert_eq!(m.header.frame_id, "map");
        assert_eq!((m.header.stamp.sec, m.header.stamp.nanosec), (7, 5));
        assert_eq!(
            (m.pose.position.x, m.pose.position.y, m.pose.position.z),
            (1.5, -2.0, 0.0)
        );
        let q = m.pose.orientation;
        let half = std::f64::consts::FRAC_PI_4;
        assert!((q.z - half.sin()).abs() < 1e-12 && (q.w - half.cos()).abs() < 1e-12);
        assert!(q.x.abs() < 1e-12 && q.y.abs() < 1e-12);
    }

    #[test]
    fn a_fragment_is_a_path_of_its_reference_poses_stamped_along_it() {
        let f = Fragment {
            dt: 0.25,
            states: vec![
                [0.0, 0.0, 0.0, 1.0, 0.0],
                [0.25, 0.0, 0.0, 1.0, 0.0],
                [0.5, 0.1, 0.2, 1.0, 0.0],
                [0.75, 0.2, 0.3, 1.0, 0.0],
                [1.0, 0.3, 0.4, 1.0, 0.0],
            ],
            ..Fragment::default()
        };
        let p = path(&f, at(10, 900_000_000));
        assert_eq!(p.poses.len(), 5);
        let stamps: Vec<(i32, u32)> = p
            .poses
            .iter()
            .map(|s| (s.header.stamp.sec, s.header.stamp.nanosec))
            .collect();
        assert_eq!(
            stamps,
            [
                (10, 900_000_000),
                (11, 150_000_000),
                (11, 400_000_000),
                (11, 650_000_000),
                (11, 900_000_000)
            ]
        );
        assert_eq!(p.poses[2].pose.position.y, 0.1);
    }

    #[test]
    fn time_saturates_instead_of_wrapping() {
        let t = later(at(i32::MAX, 999_999_999), 10.0);
        assert_eq!(t.sec, i32::MAX);
        let t = later(at(0, 0), -0.5);
        assert_eq!((t.sec, t.nanosec), (-1, 500_000_000));
    }

    #[test]
    fn the_imu_reads_as_a_planar_unit() {
        let m = imu(
            &Imu {
                yaw: 0.3,
                yaw_rate: -0.2,
                accel: [0.5, 0.1],
            },
            at(1, 0),
        );
        assert_eq!(m.header.frame_id, "base_link");
        assert_eq!(
            (
                m.angular_velocity.z,
                m.linear_acceleration.x,
                m.linear_acceleration.y
            ),
            (-0.2, 0.5, 0.1)
        );
        assert!((2.0 * m.orientation.z.atan2(m.orientation.w) - 0.3).abs() < 1e-12);
    }

    #[test]
    fn the_left_image_goes_as_a_png_that_decodes_to_its_pixels() {
        let (w, h) = (16u32, 8u32);
        let left: Vec<u8> = (0..w * h).map(|i| (i * 7 % 251) as u8).collect();
        let pair = StereoPair {
            seq: 1,
            time: 0.0,
            width: w,
            height: h,
            left: left.clone(),
            right: left.clone(),
        };
        let m = image(&pair, at(0, 0));
        assert_eq!(m.format, "png");
        let decoder = png::Decoder::new(std::io::Cursor::new(&m.data));
        let mut reader = decoder.read_info().expect("a PNG");
        let mut buf = vec![0; reader.output_buffer_size()];
        let info = reader.next_frame(&mut buf).expect("a frame");
        assert_eq!((info.width, info.height), (w, h));
        assert_eq!(&buf[..info.buffer_size()], &left[..]);
        let bad = StereoPair { width: 99, ..pair };
        assert!(image(&bad, at(0, 0)).data.is_empty());
    }
}
