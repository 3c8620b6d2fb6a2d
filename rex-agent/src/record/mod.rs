//! What a Rex recording adds for Foxglove: channels in Foxglove's standard
//! schemas, derived from Rex's buffers on the recorder's writer thread
//! ([`embodied::record::Derive`]).
//!
//! | topic | schema | from |
//! |---|---|---|
//! | `/camera/left` | `sensor_msgs/msg/CompressedImage` (ROS 2, CDR; PNG) | the camera's pairs (`R1.r11.img_lr`) |
//! | `/pose/mocap` | `foxglove.PoseInFrame` | the motion capture's poses (`R3.r31.pose`) |
//! | `/pose/estimate` | `foxglove.PoseInFrame` | e11's estimate (`e11.c1.q_est`) |
//! | `/path/reference` | `foxglove.PosesInFrame` | each fragment c1 hands e11 (`c1.e11.traj`) |
//!
//! The image is in ROS 2's schema and encoding (`ros2msg`, CDR), which Foxglove
//! reads like its own: the PNG goes into the file as it is, where JSON would
//! have it in base64 (a third larger, and compressed again with the chunk).
//! Every pose is in the frame `map`; the log time is the sender's instant (the
//! simulation's time).
//!
//! And the codec of the camera's pairs ([`codecs`]): on their raw channel as two
//! PNG images ([`StereoPng`]), whose left one `/camera/left` reuses.

use std::sync::Arc;

use embodied::ExecConfig;
use embodied::Time;
use embodied::record::{Codec, Derive, DerivedChannel, RecordOptions};
use embodied::replay::ReplayOptions;
use embodied::trace::LinkInfo;
use serde_json::{Value, json};

use crate::algorithms::planner::Fragment;
use crate::payload::{MapPose, State, StereoPair};

pub(crate) mod stereo_png;

pub use stereo_png::StereoPng;

/// The derived channels of a Rex recording (see the module's documentation).
pub fn derived() -> Vec<Box<dyn Derive>> {
    vec![Box::new(Foxglove::default())]
}

/// The codecs of a Rex recording's raw channels, for
/// [`RecordOptions::codecs`] and, to replay it, [`ReplayOptions::codecs`].
pub fn codecs() -> Vec<Arc<dyn Codec>> {
    vec![Arc::new(StereoPng)]
}

/// How Rex records: its derived channels and codecs, the rest by default.
pub fn options() -> RecordOptions {
    RecordOptions {
        derived: derived(),
        codecs: codecs(),
        ..RecordOptions::default()
    }
}

/// How Rex's recordings replay: with its codecs, and `exec`.
pub fn replay_options(exec: ExecConfig) -> ReplayOptions {
    ReplayOptions {
        exec,
        codecs: codecs(),
        ..ReplayOptions::default()
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Image,
    Mocap,
    Estimate,
    Path,
}

/// Rex's buffers in Foxglove's schemas.
#[derive(Debug, Default)]
pub struct Foxglove {
    /// By link index.
    kinds: Vec<Option<Kind>>,
    png: Vec<u8>,
}

impl Derive for Foxglove {
    fn channel(&mut self, link: usize, info: &LinkInfo) -> Option<DerivedChannel> {
        let kind = match (info.from_port, info.to_port) {
            ("r11.img_lr", _) => Kind::Image,
            ("r31.pose", _) => Kind::Mocap,
            ("c1.q_est", "e11.q_est") => Kind::Estimate,
            ("e11.traj", _) => Kind::Path,
            _ => return None,
        };
        // Several links from one output (none in Rex today): one channel.
        if self.kinds.contains(&Some(kind)) {
            return None;
        }
        if self.kinds.len() <= link {
            self.kinds.resize(link + 1, None);
        }
        self.kinds[link] = Some(kind);
        let (topic, name, schema) = match kind {
            Kind::Image => ("/camera/left", IMAGE_SCHEMA_NAME, IMAGE_SCHEMA),
            Kind::Mocap => ("/pose/mocap", "foxglove.PoseInFrame", POSE_SCHEMA),
            Kind::Estimate => ("/pose/estimate", "foxglove.PoseInFrame", POSE_SCHEMA),
            Kind::Path => ("/path/reference", "foxglove.PosesInFrame", POSES_SCHEMA),
        };
        let (schema_encoding, message_encoding) = match kind {
            Kind::Image => ("ros2msg", "cdr"),
            _ => ("jsonschema", "json"),
        };
        Some(DerivedChannel {
            topic: topic.into(),
            schema_name: name.into(),
            schema_encoding: schema_encoding.into(),
            schema: schema.as_bytes().to_vec(),
            message_encoding: message_encoding.into(),
        })
    }

    fn message_encoded(
        &mut self,
        link: usize,
        time: Time,
        body: &[u8],
        encoded: &[u8],
        out: &mut Vec<u8>,
    ) -> bool {
        // The left PNG the codec made, when it made one.
        match (self.kinds.get(link), stereo_png::parts(encoded)) {
            (Some(Some(Kind::Image)), Some(pair)) => image(time, pair.left, out),
            _ => self.message(link, time, body, out),
        }
    }

    fn message(&mut self, link: usize, time: Time, body: &[u8], out: &mut Vec<u8>) -> bool {
        let Some(Some(kind)) = self.kinds.get(link).copied() else {
            return false;
        };
        let stamp = timestamp(time);
        let value = match kind {
            Kind::Image => {
                let Ok(pair) = postcard::from_bytes::<StereoPair>(body) else {
                    return false;
                };
                return self.encode_png(&pair) && image(time, &self.png, out);
            }
            Kind::Mocap => {
                let Ok(p) = postcard::from_bytes::<MapPose>(body) else {
                    return false;
                };
                pose_in_frame(&stamp, p.pose.x, p.pose.y, p.pose.phi)
            }
            Kind::Estimate => {
                let Ok(s) = postcard::from_bytes::<State>(body) else {
                    return false;
                };
                pose_in_frame(&stamp, s.q[0], s.q[1], s.q[2])
            }
            Kind::Path => {
                let Ok(f) = postcard::from_bytes::<Fragment>(body) else {
                    return false;
                };
                json!({
                    "timestamp": stamp,
                    "frame_id": "map",
                    "poses": f.states.iter().map(|s| pose(s[0], s[1], s[2])).collect::<Vec<_>>(),
                })
            }
        };
        serde_json::to_writer(out, &value).is_ok()
    }
}

impl Foxglove {
    /// The left image as an 8-bit grayscale PNG, into `self.png`.
    fn encode_png(&mut self, pair: &StereoPair) -> bool {
        let (w, h) = (pair.width, pair.height);
        if w == 0 || h == 0 || pair.left.len() != (w as usize) * (h as usize) {
            return false;
        }
        self.png.clear();
        stereo_png::encode_png(&pair.left, w, h, &mut self.png)
    }
}

/// The camera's left image, `png`, as a `sensor_msgs/msg/CompressedImage` in
/// CDR (little-endian, plain: each primitive aligned to its size from the end
/// of the 4-byte encapsulation header). `false` past 2^31 s.
fn image(time: Time, png: &[u8], out: &mut Vec<u8>) -> bool {
    let ns = time.as_nanos();
    let (Ok(sec), Ok(len)) = (i32::try_from(ns / 1_000_000_000), u32::try_from(png.len())) else {
        return false;
    };
    let nanosec = (ns % 1_000_000_000) as u32;
    let start = out.len();
    out.extend_from_slice(&[0, 1, 0, 0]);
    let align4 = |out: &mut Vec<u8>| {
        while !(out.len() - start - 4).is_multiple_of(4) {
            out.push(0);
        }
    };
    let string = |out: &mut Vec<u8>, s: &str| {
        align4(out);
        out.extend_from_slice(&(s.len() as u32 + 1).to_le_bytes());
        out.extend_from_slice(s.as_bytes());
        out.push(0);
    };
    // header: stamp (sec, nanosec), frame_id; format; data.
    out.extend_from_slice(&sec.to_le_bytes());
    out.extend_from_slice(&nanosec.to_le_bytes());
    string(out, "camera_left");
    string(out, "png");
    align4(out);
    out.extend_from_slice(&len.to_le_bytes());
    out.extend_from_slice(png);
    true
}

fn timestamp(t: Time) -> Value {
    let ns = t.as_nanos();
    json!({"sec": ns / 1_000_000_000, "nsec": ns % 1_000_000_000})
}

/// A pose on the floor: a rotation about z by `phi`.
fn pose(x: f64, y: f64, phi: f64) -> Value {
    let q = nalgebra::UnitQuaternion::from_euler_angles(0.0, 0.0, phi);
    json!({
        "position": {"x": x, "y": y, "z": 0.0},
        "orientation": {"x": q.i, "y": q.j, "z": q.k, "w": q.w},
    })
}

fn pose_in_frame(stamp: &Value, x: f64, y: f64, phi: f64) -> Value {
    json!({"timestamp": stamp, "frame_id": "map", "pose": pose(x, y, phi)})
}

const IMAGE_SCHEMA_NAME: &str = "sensor_msgs/msg/CompressedImage";

/// ROS 2's definition, with the types it uses after it (as `ros2msg` wants).
const IMAGE_SCHEMA: &str = "std_msgs/Header header
string format
uint8[] data
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
";

const POSE_SCHEMA: &str = concat!(
    r#"{"title":"foxglove.PoseInFrame","type":"object","properties":{"timestamp":"#,
    r#"{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}}"#,
    r#","frame_id":{"type":"string"},"pose":"#,
    r#"{"type":"object","properties":{"position":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},"orientation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}}"#,
    r#"}}"#
);

const POSES_SCHEMA: &str = concat!(
    r#"{"title":"foxglove.PosesInFrame","type":"object","properties":{"timestamp":"#,
    r#"{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}}"#,
    r#","frame_id":{"type":"string"},"poses":{"type":"array","items":"#,
    r#"{"type":"object","properties":{"position":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},"orientation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}}"#,
    r#"}}}"#
);

#[cfg(test)]
mod tests {
    use super::*;

    const TIME: &str = r#"{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}}"#;

    const POSE: &str = r#"{"type":"object","properties":{"position":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"}}},"orientation":{"type":"object","properties":{"x":{"type":"number"},"y":{"type":"number"},"z":{"type":"number"},"w":{"type":"number"}}}}}"#;

    #[test]
    fn the_schemas_are_json_and_agree_with_their_parts() {
        for s in [POSE_SCHEMA, POSES_SCHEMA] {
            let v: Value = serde_json::from_str(s).expect(s);
            assert_eq!(
                v["properties"]["timestamp"],
                serde_json::from_str::<Value>(TIME).unwrap()
            );
        }
        let pose: Value = serde_json::from_str(POSE_SCHEMA).unwrap();
        assert_eq!(
            pose["properties"]["pose"],
            serde_json::from_str::<Value>(POSE).unwrap()
        );
    }

    #[test]
    fn an_image_is_cdr_aligned_as_ros_2_lays_it_out() {
        let mut out = Vec::new();
        assert!(image(Time::from_nanos(3_000_000_007), &[9, 8, 7], &mut out));
        let u32_at = |k: usize| u32::from_le_bytes(out[k..k + 4].try_into().unwrap());
        assert_eq!(&out[..4], &[0, 1, 0, 0], "CDR, little-endian");
        // From the end of the encapsulation header: sec, nanosec at 0 and 4.
        assert_eq!((u32_at(4), u32_at(8)), (3, 7));
        // frame_id at 8: length with its NUL, the bytes, NUL (ends at 24).
        assert_eq!(u32_at(12), 12);
        assert_eq!(&out[16..28], b"camera_left\0");
        // format at 24 (aligned), then data's count at 32, the bytes at 36.
        assert_eq!(u32_at(28), 4);
        assert_eq!(&out[32..36], b"png\0");
        assert_eq!(u32_at(36), 3);
        assert_eq!(&out[40..], &[9, 8, 7]);
        // Beyond what a ROS 2 time says: no message.
        assert!(!image(Time::from_nanos(u64::MAX), &[], &mut Vec::new()));
    }

    #[test]
    fn a_heading_becomes_a_rotation_about_z() {
        let p = pose(1.0, 2.0, std::f64::consts::FRAC_PI_2);
        let half = std::f64::consts::FRAC_PI_4;
        assert!((p["orientation"]["z"].as_f64().unwrap() - half.sin()).abs() < 1e-12);
        assert!((p["orientation"]["w"].as_f64().unwrap() - half.cos()).abs() < 1e-12);
        assert_eq!(p["orientation"]["x"], 0.0);
        assert_eq!(p["position"]["y"], 2.0);
    }

    #[test]
    fn a_pair_that_is_not_its_size_gives_no_image() {
        let mut f = Foxglove::default();
        let pair = StereoPair {
            width: 4,
            height: 4,
            left: vec![0; 15],
            ..StereoPair::default()
        };
        assert!(!f.encode_png(&pair));
        let pair = StereoPair {
            width: 4,
            height: 4,
            left: (0..16).collect(),
            ..StereoPair::default()
        };
        assert!(f.encode_png(&pair));
        let decoder = png::Decoder::new(std::io::Cursor::new(&f.png));
        let mut reader = decoder.read_info().unwrap();
        let mut buf = vec![0; reader.output_buffer_size()];
        reader.next_frame(&mut buf).unwrap();
        assert_eq!(&buf[..16], &(0..16).collect::<Vec<u8>>()[..]);
    }
}
