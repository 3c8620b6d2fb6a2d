//! `rex --ros2` against a ROS 2 listener we did not write: Eclipse Zenoh's
//! Python API (PyPI `eclipse-zenoh` 1.10.2) as the router and rosbags' Kilted
//! type store decoding the CDR (tests/ros2_bridge.py). Rex flies its square
//! mission without the camera (`--no-vo`); the listener must discover the
//! publishers of `/rex/pose`, `/rex/estimate`, `/rex/ack`, `/rex/outcome`,
//! `/rex/imu` and `/rex/reference_path` with their types and hashes (as
//! rosbags computes them: the official ones for the standard messages), decode
//! at least one value of each (Rex's own messages registered from the .msg
//! text of the bridge's plan), and see the tokens vanish at the end; Rex says
//! what it published, that the camera's topic is left out, and that its
//! deterministic run takes nothing from `/rex/plan` (tests/ros2_plans.rs: a
//! real-time run that does).
//!
//! With the camera (Rex listening for 2 s, recorded): the camera's topic is a
//! `sensor_msgs/msg/CompressedImage` publisher, every standard type's hash is
//! the one the official wheels (`ros-sensor-msgs` and the others) ship, and
//! the listener decodes as many images as the recording holds on
//! `/camera/left`, the first one's PNG equal to the recording's.
//!
//! `scripts/test -p rex-agent --test ros2_bridge` installs the clients and
//! sets `EMBODIED_INTEROP_PYTHON`; plain `cargo test` skips, saying so. The
//! refusals before anything runs (no router, no plan) are agent-app's tests.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

mod common;
#[path = "../../agent-ros2/tests/interop/python.rs"]
mod python;
#[path = "../../agent-ros2/tests/interop/script.rs"]
mod script;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{bridge_plan, own_messages};
use embodied::record::mcap;
use python::python;
use rex_agent::mission::Mission;
use script::{Script, free_port};
use serde_json::{Value, json};

/// The topics Rex publishes without the camera, with their types.
const TOPICS: [(&str, &str); 6] = [
    ("/rex/pose", "geometry_msgs/msg/PoseStamped"),
    ("/rex/estimate", "rex_msgs/msg/"),
    ("/rex/reference_path", "nav_msgs/msg/Path"),
    ("/rex/imu", "sensor_msgs/msg/Imu"),
    ("/rex/ack", "rex_msgs/msg/"),
    ("/rex/outcome", "rex_msgs/msg/"),
];

/// The camera's topic and message.
const CAMERA: (&str, &str) = (
    "/rex/camera/image/compressed",
    "sensor_msgs/msg/CompressedImage",
);

/// The recording's channel of the camera's left images (rex_agent::record).
const CAMERA_LEFT: &str = "/camera/left";

/// What the listener saw of a run of `rex` with `args` and `--ros2` at the
/// listener, whose Rex messages are those of `plan`: Rex's standard error
/// (once it exited 0) and the listener's answer.
fn listened(python: &Path, plan: &embodied::ros2::bridge::Plan, args: &[&str]) -> (String, Value) {
    let endpoint = format!("tcp/127.0.0.1:{}", free_port());
    let mut listener = Script::start(
        Command::new(python).arg(concat!(env!("CARGO_MANIFEST_DIR"), "/tests/ros2_bridge.py")),
        "the listener",
    );
    listener.send(json!({"listen": endpoint, "register": own_messages(plan)}));
    listener.ready();
    let out = Command::new(env!("CARGO_BIN_EXE_rex"))
        .args(args)
        .arg(format!("--ros2={endpoint}"))
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{stderr}");
    let answer = listener.end("end");
    assert_eq!(answer["problems"], json!([]), "{answer}");
    assert_eq!(answer["all_vanished"], json!(true), "{answer}");
    (stderr, answer)
}

/// The token of the publisher of `topic` the listener saw.
fn publisher<'a>(answer: &'a Value, topic: &str) -> &'a Value {
    answer["publishers"]
        .as_array()
        .unwrap()
        .iter()
        .find(|p| p["topic"] == topic)
        .unwrap_or_else(|| panic!("no publisher of {topic}: {answer}"))
}

/// Rex's report of what the bridge did, checked: nothing dropped or failed,
/// nothing taken from ROS 2.
fn nothing_lost(stderr: &str) {
    let report = stderr
        .lines()
        .find(|l| l.starts_with("ros2: published="))
        .unwrap_or_else(|| panic!("no report line: {stderr}"));
    // The deterministic run goes ~50 times faster than real time: it waits
    // for the publishing thread rather than drop a value.
    assert!(
        report.contains(
            " dropped=0 encode_failures=0 put_failures=0 received=0 delivered=0 refused=0 lost=0"
        ),
        "{report}"
    );
    // A deterministic run takes nothing from ROS 2, and says so.
    assert!(
        stderr.contains("/rex/plan")
            && stderr.contains("a deterministic run is not on the wall clock"),
        "{stderr}"
    );
}

#[test]
fn a_ros_2_listener_discovers_rexs_topics_and_decodes_them() {
    let Some(python) = python() else { return };
    let (plan, _) = bridge_plan("square", false);
    let args = ["--no-vo", "--mission", "square", "--no-report", "--quiet"];
    let (stderr, answer) = listened(&python, &plan, &args);
    nothing_lost(&stderr);
    // The camera's buffer, of a component `--no-vo` does not build: left out, and said.
    assert!(
        stderr.contains(
            "--ros2: not shown to ROS 2, their components are not in this run: R1.r11.img_lr"
        ),
        "{stderr}"
    );
    assert!(
        !answer["publishers"]
            .as_array()
            .unwrap()
            .iter()
            .any(|p| p["topic"] == CAMERA.0),
        "{answer}"
    );
    for (topic, ty) in TOPICS {
        let publisher = publisher(&answer, topic);
        let name = publisher["type"].as_str().unwrap();
        assert!(name.starts_with(ty), "{topic}: {publisher}");
        assert_eq!(publisher["hash"], publisher["rosbags_hash"], "{topic}");
        let seen = &answer["topics"][topic];
        assert_eq!(seen["problems"], json!([]), "{topic}: {seen}");
        assert!(seen["samples"].as_u64() >= Some(1), "{topic}: {seen}");
        assert!(seen["first"].is_object(), "{topic}: {seen}");
    }
    let pose = &answer["topics"]["/rex/pose"]["first"];
    assert_eq!(pose["header"]["frame_id"], "map", "{pose}");
    let path = &answer["topics"]["/rex/reference_path"]["first"];
    assert!(!path["poses"].as_array().unwrap().is_empty(), "{path}");
}

#[test]
fn the_camera_is_shown_as_compressed_images_equal_to_the_recordings() {
    let Some(python) = python() else { return };
    let (plan, _) = bridge_plan(Mission::LISTEN, true);
    let recording = Path::new(env!("CARGO_TARGET_TMPDIR")).join("ros2_bridge_camera.mcap");
    let _ = std::fs::remove_file(&recording);
    let record = recording.to_str().unwrap();
    let args = [
        "--mission",
        Mission::LISTEN,
        "--for",
        "2",
        "--record",
        record,
        "--no-report",
        "--quiet",
    ];
    let (stderr, answer) = listened(&python, &plan, &args);
    nothing_lost(&stderr);

    // Every standard message's hash is the official wheels' own.
    let prefix = prefix(&python);
    for (topic, ty) in TOPICS.into_iter().chain([CAMERA]) {
        let publisher = publisher(&answer, topic);
        assert!(
            publisher["type"].as_str().unwrap().starts_with(ty),
            "{topic}: {publisher}"
        );
        if !ty.starts_with("rex_msgs/") {
            assert_eq!(publisher["hash"], official_hash(&prefix, ty), "{topic}");
        }
    }

    // Every image the run recorded, decoded; the first one's PNG the recording's.
    let seen = &answer["topics"][CAMERA.0];
    assert_eq!(seen["problems"], json!([]), "{seen}");
    let first = &seen["first"];
    assert_eq!(
        (&first["format"], &first["header"]["frame_id"]),
        (&json!("png"), &json!("camera_left")),
    );
    let data: Vec<u8> = serde_json::from_value(first["data"].clone()).unwrap();
    assert!(
        data.starts_with(b"\x89PNG\r\n\x1a\n"),
        "{:?}",
        &data[..8.min(data.len())]
    );
    let recorded = recorded_images(&recording);
    assert!(recorded.len() >= 10, "{} images recorded", recorded.len());
    assert_eq!(seen["samples"].as_u64(), Some(recorded.len() as u64));
    // The recording's CDR of the first image ends with its PNG, after its length.
    let cdr = &recorded[0];
    let len = u32::try_from(data.len()).unwrap().to_le_bytes();
    let tail = [&len[..], &data].concat();
    assert!(
        cdr.ends_with(&tail),
        "the first image differs from the recording's"
    );
}

/// The prefix of the environment of the interpreter `python` (`sys.prefix`).
fn prefix(python: &Path) -> PathBuf {
    let out = Command::new(python)
        .args(["-c", "import sys; print(sys.prefix)"])
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    PathBuf::from(String::from_utf8(out.stdout).unwrap().trim_end())
}

/// The type hash of `name` (`sensor_msgs/msg/Imu`) in the type description
/// the official wheel installed in the environment at `prefix` ships
/// (`share/<name>.json`).
fn official_hash(prefix: &Path, name: &str) -> Value {
    let path = prefix.join("share").join(format!("{name}.json"));
    let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path:?}: {e}"));
    let file: Value = serde_json::from_str(&text).unwrap();
    let hash = file["type_hashes"]
        .as_array()
        .unwrap()
        .iter()
        .find(|h| h["type_name"] == name)
        .map(|h| h["hash_string"].clone())
        .unwrap_or_else(|| panic!("no hash of {name} in {path:?}"));
    assert!(hash.as_str().unwrap().starts_with("RIHS01_"), "{hash}");
    hash
}

/// The CDR of every image on the recording's `/camera/left`, in order.
fn recorded_images(path: &Path) -> Vec<Vec<u8>> {
    let bytes = std::fs::read(path).unwrap();
    mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(Result::unwrap)
        .filter(|m| m.channel.topic == CAMERA_LEFT)
        .map(|m| m.data.into_owned())
        .collect()
}
