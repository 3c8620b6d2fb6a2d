//! What a Rex recording adds for Foxglove: channels in Foxglove's standard
//! schemas, derived from Rex's buffers on the recorder's writer thread
//! ([`embodied::record::Derive`]).
//!
//! | topic | schema | from |
//! |---|---|---|
//! | `/camera/left` | `foxglove.CompressedImage` (PNG) | the camera's pairs (`R1.r11.img_lr`) |
//! | `/pose/mocap` | `foxglove.PoseInFrame` | the motion capture's poses (`R3.r31.pose`) |
//! | `/pose/estimate` | `foxglove.PoseInFrame` | e11's estimate (`e11.c1.q_est`) |
//! | `/path/reference` | `foxglove.PosesInFrame` | each fragment c1 hands e11 (`c1.e11.traj`) |
//!
//! Every pose is in the frame `map`; the log time is the sender's instant (the
//! simulation's time).

use base64::Engine as _;
use embodied::Time;
use embodied::record::{Derive, DerivedChannel};
use embodied::trace::LinkInfo;
use serde_json::{Value, json};

use crate::a1::payload::{MapPose, State, StereoPair};
use crate::algorithms::planner::Fragment;

/// The derived channels of a Rex recording (see the module's documentation).
pub fn derived() -> Vec<Box<dyn Derive>> {
    vec![Box::new(Foxglove::default())]
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
            Kind::Image => ("/camera/left", "foxglove.CompressedImage", IMAGE_SCHEMA),
            Kind::Mocap => ("/pose/mocap", "foxglove.PoseInFrame", POSE_SCHEMA),
            Kind::Estimate => ("/pose/estimate", "foxglove.PoseInFrame", POSE_SCHEMA),
            Kind::Path => ("/path/reference", "foxglove.PosesInFrame", POSES_SCHEMA),
        };
        Some(DerivedChannel {
            topic: topic.into(),
            schema_name: name.into(),
            schema_encoding: "jsonschema".into(),
            schema: schema.as_bytes().to_vec(),
            message_encoding: "json".into(),
        })
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
                if !self.encode_png(&pair) {
                    return false;
                }
                json!({
                    "timestamp": stamp,
                    "frame_id": "camera_left",
                    "format": "png",
                    "data": base64::engine::general_purpose::STANDARD.encode(&self.png),
                })
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
        let mut encoder = png::Encoder::new(&mut self.png, w, h);
        encoder.set_color(png::ColorType::Grayscale);
        encoder.set_depth(png::BitDepth::Eight);
        encoder.set_compression(png::Compression::Fast);
        let Ok(mut writer) = encoder.write_header() else {
            return false;
        };
        writer.write_image_data(&pair.left).is_ok() && writer.finish().is_ok()
    }
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

const IMAGE_SCHEMA: &str = concat!(
    r#"{"title":"foxglove.CompressedImage","type":"object","properties":{"timestamp":"#,
    r#"{"type":"object","properties":{"sec":{"type":"integer","minimum":0},"nsec":{"type":"integer","minimum":0,"maximum":999999999}}}"#,
    r#","frame_id":{"type":"string"},"data":{"type":"string","contentEncoding":"base64"},"format":{"type":"string"}}}"#
);

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
        for s in [IMAGE_SCHEMA, POSE_SCHEMA, POSES_SCHEMA] {
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
