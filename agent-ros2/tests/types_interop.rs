//! Our type hashes and CDR against implementations we did not write: the
//! official ROS 2 Kilted message wheels of PyPI (`ros-std-msgs` and the
//! others: the type descriptions and `RIHS01_` hashes rosidl generated, in
//! their `share/<package>/msg/<Name>.json`) and `rosbags` (its own
//! `hash_rihs01`, and its CDR deserializer and serializer).
//!
//! The test command `scripts/test` installs them (tests/interop/requirements.txt)
//! into a virtual environment and sets `EMBODIED_INTEROP_PYTHON`; plain
//! `cargo test` stays offline and skips these tests, saying so.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

#[path = "interop/python.rs"]
mod python;

use std::collections::BTreeMap;
use std::io::Write as _;
use std::path::Path;
use std::process::{Command, Stdio};

use agent_ros2::types::standard::builtin_interfaces::Time;
use agent_ros2::types::standard::geometry_msgs::{Point, Pose, PoseStamped, Quaternion, Vector3};
use agent_ros2::types::standard::nav_msgs;
use agent_ros2::types::standard::sensor_msgs::{CompressedImage, Imu};
use agent_ros2::types::standard::std_msgs::Header;
use agent_ros2::types::standard::{StandardMessage, standard_messages};
use agent_ros2::types::{Messages, TypeDescription, encode_cdr, messages, with_references};
use python::python;
use serde::{Deserialize, Serialize};
use serde_json::{Value, json};

/// The folder of tests/interop/ros2_side.py, our stand-in for a ROS 2 node.
const INTEROP: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/../tests/interop");

/// Reads a request (JSON on stdin): messages to register in a Kilted type
/// store (`register`: name and `.msg` text), types to hash (`hash`), CDR
/// messages to decode (`decode`: type and hex); answers with the
/// environment's prefix, rosbags' hashes, and each decoded value (as plain
/// JSON) with its bytes serialized again by rosbags; the folder of
/// ros2_side.py as its argument.
const PY_ROSBAGS: &str = r#"
import json, sys
sys.path.insert(0, sys.argv[1])
from ros2_side import plain, type_store
request = json.load(sys.stdin)
store = type_store(request["register"])
decoded = []
for name, data in request["decode"]:
    message = store.deserialize_cdr(bytes.fromhex(data), name)
    again = bytes(store.serialize_cdr(message, name)).hex()
    decoded.append({"value": plain(message), "again": again})
hashes = {name: store.hash_rihs01(name) for name in request["hash"]}
print(json.dumps({"prefix": sys.prefix, "hashes": hashes, "decoded": decoded}))
"#;

/// rosbags' answer to `request` (see [`PY_ROSBAGS`]).
fn rosbags(python: &Path, request: &Value) -> Value {
    let mut child = Command::new(python)
        .args(["-c", PY_ROSBAGS, INTEROP])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut stdin = child.stdin.take().unwrap();
    stdin.write_all(request.to_string().as_bytes()).unwrap();
    drop(stdin);
    let out = child.wait_with_output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).unwrap()
}

fn hex(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

/// The official type description file of `name` (`std_msgs/msg/Header`) in
/// the environment at `prefix`.
fn official(prefix: &str, name: &str) -> Value {
    let path = Path::new(prefix).join("share").join(format!("{name}.json"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    serde_json::from_str(&text).unwrap()
}

#[test]
fn our_hashes_of_the_standard_messages_are_the_official_ones() {
    let Some(python) = python() else { return };
    let catalog = standard_messages();
    let names: Vec<String> = catalog.iter().map(|m| m.name.to_string()).collect();
    // The standard messages Rex's poses, path, IMU and camera go as (issue 55).
    for required in [
        "geometry_msgs/msg/PoseStamped",
        "nav_msgs/msg/Path",
        "sensor_msgs/msg/Imu",
        "sensor_msgs/msg/CompressedImage",
    ] {
        assert!(names.iter().any(|n| n == required), "{required}: {names:?}");
    }
    let answer = rosbags(
        &python,
        &json!({"register": [], "hash": names, "decode": []}),
    );
    let prefix = answer["prefix"].as_str().unwrap();
    for m in &catalog {
        let name = m.name.to_string();
        let ours = TypeDescription::of(&with_references(m.clone(), &catalog)).unwrap();
        let file = official(prefix, &name);
        // The description rosidl generated, default values aside.
        let theirs: TypeDescription =
            serde_json::from_value(file["type_description_msg"].clone()).unwrap();
        assert_eq!(ours, theirs, "{name}");
        let hashes = file["type_hashes"].as_array().unwrap();
        let official_hash = hashes
            .iter()
            .find(|h| h["type_name"] == name.as_str())
            .and_then(|h| h["hash_string"].as_str())
            .unwrap();
        assert!(official_hash.starts_with("RIHS01_"), "{official_hash}");
        assert_eq!(ours.hash().to_string(), official_hash, "{name}");
        // rosbags' own hash of its Kilted definition agrees.
        assert_eq!(answer["hashes"][&name], official_hash, "{name}");
    }
    eprintln!(
        "{} standard messages hash as the official wheels say",
        catalog.len()
    );
}

/// The value of a standard type `T`, encoded by us, for rosbags to decode.
fn standard<T: StandardMessage>(value: &T) -> (String, String, Value) {
    let mut cdr = Vec::new();
    encode_cdr(value, &agent_core::reflect::<T>().unwrap(), &mut cdr).unwrap();
    let name = T::message().name.to_string();
    (name, hex(&cdr), serde_json::to_value(value).unwrap())
}

fn header(sec: i32, frame: &str) -> Header {
    Header {
        stamp: Time {
            sec,
            nanosec: 999_999_999,
        },
        frame_id: frame.into(),
    }
}

fn pose(x: f64, w: f64) -> Pose {
    Pose {
        position: Point { x, y: -x, z: 0.5 },
        orientation: Quaternion {
            x: 0.0,
            y: 0.0,
            z: (1.0 - w * w).sqrt(),
            w,
        },
    }
}

#[test]
fn rosbags_decodes_our_cdr_of_each_standard_type_to_the_same_values() {
    let Some(python) = python() else { return };
    let stamped = |k: i32| PoseStamped {
        header: header(k, "map"),
        pose: pose(f64::from(k) / 3.0, 0.6),
    };
    let vector = Vector3 {
        x: 1e-300,
        y: -0.0,
        z: 9.81,
    };
    let covariance = std::array::from_fn(|k| k as f64 - 1.0);
    let cases = [
        standard(&Time {
            sec: -7,
            nanosec: 12,
        }),
        // Strings of odd lengths and not ASCII: the alignment after them.
        standard(&header(1_700_000_000, "caméra")),
        standard(&pose(2.5, 0.8).position),
        standard(&pose(2.5, 0.8).orientation),
        standard(&pose(-1.25, 1.0)),
        standard(&stamped(3)),
        standard(&vector),
        standard(&nav_msgs::Path {
            header: header(5, "odom"),
            poses: (0..3).map(stamped).collect(),
        }),
        standard(&nav_msgs::Path::default()),
        standard(&Imu {
            header: header(6, "imu_link"),
            orientation: pose(0.0, 0.6).orientation,
            orientation_covariance: covariance,
            angular_velocity: vector,
            angular_velocity_covariance: [0.0; 9],
            linear_acceleration: Vector3::default(),
            linear_acceleration_covariance: covariance,
        }),
        standard(&CompressedImage {
            header: header(7, "camera_left"),
            format: "png".into(),
            data: vec![0x89, b'P', b'N', b'G', 0, 255, 7],
        }),
    ];
    let decode: Vec<_> = cases.iter().map(|(n, h, _)| json!([n, h])).collect();
    let answer = rosbags(
        &python,
        &json!({"register": [], "hash": [], "decode": decode}),
    );
    let decoded = answer["decoded"].as_array().unwrap();
    assert_eq!(decoded.len(), cases.len());
    for ((name, ours, value), theirs) in cases.iter().zip(decoded) {
        assert_eq!(&theirs["value"], value, "{name}");
        // And rosbags' encoding of what it read is our bytes.
        assert_eq!(theirs["again"].as_str(), Some(ours.as_str()), "{name}");
    }
}

/// A pose on the floor, as Rex's own.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Pose2d {
    x: f64,
    y: f64,
    phi: f64,
}

/// An empty message (CDR: one byte; REP 2011: ROS 2's one `uint8` field).
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Marker;

#[derive(Clone, Debug, Serialize, Deserialize)]
enum Estimate {
    NotYet,
    Pose(Pose2d),
    Lost { since: u64, reason: String },
    Pair(i8, u16),
}

/// A plan with every kind of field the mapping makes.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct Plan {
    id: u32,
    label: String,
    waypoints: Vec<Pose2d>,
    gains: [f32; 3],
    deadline: Option<f64>,
    estimate: Estimate,
    grid: Vec<Vec<u8>>,
    marker: Marker,
    counts: BTreeMap<String, u16>,
    pair: (bool, i64),
    wide: u128,
    letter: char,
}

#[derive(Clone, Debug, Serialize, Deserialize)]
struct Ack {
    plan: u32,
    accepted: bool,
    note: Option<String>,
}

/// The messages of `T` in `rex_msgs`, and a value of it encoded by us.
fn embodied<T: agent_core::Payload>(root: &str, value: &T) -> (Messages, String) {
    let shape = agent_core::reflect::<T>().unwrap();
    let made = messages(&shape, "rex_msgs", root).unwrap();
    let mut cdr = Vec::new();
    encode_cdr(value, &shape, &mut cdr).unwrap();
    (made, hex(&cdr))
}

#[test]
fn rosbags_hashes_and_reads_our_messages_of_embodied_types_as_we_do() {
    let Some(python) = python() else { return };
    let plan = Plan {
        id: 4,
        label: "figure-eight".into(),
        waypoints: vec![
            Pose2d {
                x: 1.0,
                y: 0.0,
                phi: 0.5,
            };
            2
        ],
        gains: [0.5, 1.5, -2.0],
        deadline: Some(12.5),
        estimate: Estimate::Lost {
            since: 3,
            reason: "no features".into(),
        },
        grid: vec![vec![1, 2, 3], vec![]],
        marker: Marker,
        counts: BTreeMap::from([("a".into(), 1), ("bc".into(), 2)]),
        pair: (true, -9),
        wide: u128::MAX - 5,
        letter: 'é',
    };
    let poses = vec![Pose2d {
        x: -1.0,
        y: 2.0,
        phi: 3.0,
    }];
    let ack = Ack {
        plan: 4,
        accepted: false,
        note: Some("late".into()),
    };
    let cases = [
        embodied("Plan", &plan),
        embodied("Estimate", &Estimate::Pair(-3, 9)),
        embodied("Estimate", &Estimate::NotYet),
        embodied("Ack", &ack),
        embodied("Poses", &poses),
        embodied("Marker", &Marker),
    ];
    let mut register = BTreeMap::new();
    for (m, _) in &cases {
        register.insert(m.name().to_string(), m.msg_text());
    }
    let register: Vec<_> = register.into_iter().collect();
    let hash: Vec<_> = register.iter().map(|(n, _)| n.clone()).collect();
    let decode: Vec<_> = cases
        .iter()
        .map(|(m, h)| json!([m.name().to_string(), h]))
        .collect();
    let answer = rosbags(
        &python,
        &json!({"register": register, "hash": hash, "decode": decode}),
    );
    for (m, _) in &cases {
        let name = m.name().to_string();
        let hash = TypeDescription::of(m).unwrap().hash().to_string();
        assert_eq!(answer["hashes"][&name], hash.as_str(), "{name}");
    }
    assert_eq!(hash.len(), 5, "{hash:?}");
    let decoded = answer["decoded"].as_array().unwrap();
    for ((m, ours), theirs) in cases.iter().zip(decoded) {
        assert_eq!(
            theirs["again"].as_str(),
            Some(ours.as_str()),
            "{}",
            m.name()
        );
    }
    // The plan's fields, as rosbags read them.
    let read = &decoded[0]["value"];
    assert_eq!(read["label"], "figure-eight");
    assert_eq!(read["estimate"]["variant"], 2);
    assert_eq!(read["estimate"]["lost"][0]["reason"], "no features");
    assert_eq!(read["grid"][0]["value"], json!([1, 2, 3]));
    assert_eq!(read["letter"], u32::from('é'));
}
