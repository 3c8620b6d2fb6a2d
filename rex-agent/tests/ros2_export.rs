//! A Rex run with its camera, recorded and exported for ROS 2 tools
//! (`embodied::record::export_ros2`, what `embodied export --ros2` runs).
//!
//! The export, read with the `mcap` crate: profile `ros2`, Rex's CDR channels
//! only (every buffer, and the camera's `sensor_msgs/msg/CompressedImage`),
//! each with every message as recorded; the JSON, raw and read channels left
//! out and named. Then read whole by a reader we did not write: rosbags
//! (PyPI, installed by `scripts/test`, which sets `EMBODIED_INTEROP_PYTHON`)
//! opens it with its MCAP storage reader (which refuses a file not of
//! profile `ros2`), registers the types of every channel's schema in one type
//! store as its `AnyReader` does, and decodes every message, which it encodes
//! again to the same bytes; e11's estimates decode to the values e11 sent,
//! the camera's images to PNGs stamped at their log time. Plain `cargo test`
//! skips that part, saying so.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::Duration;

use embodied::Executor;
use embodied::record::{ExportOptions, ExportSummary, McapRecorder, export_ros2, mcap};
use rex_agent::mission::Mission;
use rex_agent::payload::State;
use rex_agent::system::{RexConfig, build};
use rex_agent::world::WorldConfig;

/// The estimates' topic, in the recording and in the export.
const ESTIMATES: &str = "/links/e11/c1/q_est/to/c1";

/// One recording and its export, for every test of this file: (recording,
/// export, the export's summary).
fn exported() -> &'static (PathBuf, PathBuf, ExportSummary) {
    static EXPORTED: OnceLock<(PathBuf, PathBuf, ExportSummary)> = OnceLock::new();
    EXPORTED.get_or_init(|| {
        let tmp = Path::new(env!("CARGO_TARGET_TMPDIR"));
        let mut config = RexConfig::new(
            WorldConfig::shipped().unwrap(),
            Mission::shipped("square").unwrap(),
        );
        config.visual_odometry = true;
        let (system, _) = build(&config).unwrap();
        let path = tmp.join("rex_for_ros2.mcap");
        let recorder = McapRecorder::create(&path, &system, rex_agent::record::options()).unwrap();
        let mut exec = Executor::with_observer(system, config.exec, recorder);
        exec.run_for(Duration::from_secs(3)).unwrap();
        exec.into_observer().finish().unwrap();
        let out = tmp.join("rex_ros2.mcap");
        let summary = export_ros2(&path, &out, &ExportOptions::default()).unwrap();
        (path, out, summary)
    })
}

/// Messages per topic of the channels that `keep` accepts (by message
/// encoding and schema encoding), and the file's profile.
fn per_topic(path: &Path, keep: impl Fn(&str, &str) -> bool) -> (String, BTreeMap<String, u64>) {
    let bytes = std::fs::read(path).unwrap();
    let mut profile = String::new();
    for record in mcap::read::LinearReader::new(&bytes).unwrap() {
        if let mcap::records::Record::Header(h) = record.unwrap() {
            profile = h.profile;
        }
    }
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let mut counts = BTreeMap::new();
    for c in summary.channels.values() {
        let schema = c.schema.as_ref().map_or("", |s| s.encoding.as_str());
        if keep(&c.message_encoding, schema) {
            counts.insert(c.topic.clone(), 0u64);
        }
    }
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if let Some(n) = counts.get_mut(&m.channel.topic) {
            *n += 1;
        }
    }
    (profile, counts)
}

#[test]
fn a_rex_recording_exports_its_cdr_channels_with_every_message_and_names_the_rest() {
    let (recording, export, summary) = exported();
    let ros2 = |encoding: &str, schema: &str| encoding == "cdr" && schema == "ros2msg";
    let (_, recorded) = per_topic(recording, ros2);
    let (profile, written) = per_topic(export, |_, _| true);
    assert_eq!(profile, "ros2");
    // Every buffer of Rex, and the camera's images.
    assert!(recorded.len() >= 20, "{recorded:?}");
    assert!(recorded.contains_key("/camera/left"), "{recorded:?}");
    assert_eq!(written, recorded);
    assert_eq!(&summary.per_topic, &recorded);
    assert!(written[ESTIMATES] >= 50, "{written:?}");
    let (_, all_written) = per_topic(export, ros2);
    assert_eq!(all_written.len(), written.len(), "only ROS 2 channels");
    // Rex's topics are ROS 2 names already.
    assert!(summary.renamed_topics.is_empty(), "{summary:?}");
    // The rest, named: JSON (Foxglove's poses, the switches, the errors), the
    // raw copies and the reads.
    let left: Vec<&str> = summary.left_out.iter().map(|l| l.topic.as_str()).collect();
    for topic in [
        "/pose/estimate",
        "/path/reference",
        "/fsm/c1",
        "/errors",
        "/raw/links/e11/c1/q_est/to/c1",
        "/reads/links/e11/c1/q_est/to/c1",
    ] {
        assert!(left.contains(&topic), "{topic} not in {left:?}");
    }
    let (_, all) = per_topic(recording, |_, _| true);
    assert_eq!(left.len() + written.len(), all.len());
}

/// Reads an export (argument 1) with rosbags: its MCAP storage reader, the
/// types of every schema in one store (as `AnyReader` registers them), every
/// message decoded and encoded again; prints, as JSON, the messages per
/// topic (every channel's), how many encoded again to their bytes, e11's first estimates and
/// the camera's images checked.
const ROSBAGS: &str = r#"
import json, sys
from pathlib import Path
from rosbags.interfaces import MessageDefinitionFormat
from rosbags.rosbag2.storage_mcap import McapReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
reader = McapReader(Path(sys.argv[1]))
reader.open()
types = {}
for c in reader.connections:
    assert c.msgdef.format == MessageDefinitionFormat.MSG, c.topic
    assert c.ext.serialization_format == "cdr", c.topic
    types.update(get_types_from_msg(c.msgdef.data, c.msgtype))
store = get_typestore(Stores.EMPTY)
store.register(types)
counts, exact, estimates, images = {c.topic: 0 for c in reader.connections}, 0, [], 0
for c, time, data in reader.messages(reader.connections):
    m = store.deserialize_cdr(data, c.msgtype)
    counts[c.topic] += 1
    if bytes(store.serialize_cdr(m, c.msgtype)) == bytes(data):
        exact += 1
    if c.topic == sys.argv[2] and len(estimates) < 50:
        estimates.append([float(x) for x in m.q] + [float(x) for x in m.q_dot])
    if c.topic == "/camera/left":
        assert c.msgtype == "sensor_msgs/msg/CompressedImage", c.msgtype
        assert m.format == "png" and m.header.frame_id == "camera_left", m.header
        assert bytes(m.data[:8]) == b"\x89PNG\r\n\x1a\n"
        assert m.header.stamp.sec * 10**9 + m.header.stamp.nanosec == time
        images += 1
reader.close()
print(json.dumps({"counts": counts, "exact": exact, "estimates": estimates,
                  "images": images}))
"#;

#[test]
fn rosbags_reads_and_decodes_every_message_of_a_rex_export() {
    let Some(python) = std::env::var_os("EMBODIED_INTEROP_PYTHON") else {
        eprintln!(
            "skipped: EMBODIED_INTEROP_PYTHON is not set (`scripts/test` installs rosbags and sets it)"
        );
        return;
    };
    let (recording, export, summary) = exported();
    let out = std::process::Command::new(python)
        .args(["-c", ROSBAGS])
        .arg(export)
        .arg(ESTIMATES)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let read: serde_json::Value = serde_json::from_str(&text).unwrap();
    let counts: BTreeMap<String, u64> = serde_json::from_value(read["counts"].clone()).unwrap();
    // Every channel, every message, decoded; and encoded again to its bytes.
    assert_eq!(counts, summary.per_topic);
    assert!(counts.len() >= 20, "{counts:?}");
    assert_eq!(read["exact"].as_u64(), Some(summary.messages), "{text}");
    assert_eq!(read["images"].as_u64(), Some(counts["/camera/left"]));
    assert!(counts["/camera/left"] >= 30, "{counts:?}");

    // e11's estimates as rosbags decodes them: the values e11 sent, as
    // their raw copies in the recording hold them.
    let bytes = std::fs::read(recording).unwrap();
    let mut sent = Vec::new();
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic == format!("/raw{ESTIMATES}") {
            let values = embodied::record::raw_values(&m.channel.message_encoding, &m.data);
            for value in values {
                let (_, body) = embodied::WireHeader::read(value.unwrap()).unwrap();
                let q = postcard::from_bytes::<State>(body).unwrap();
                sent.push(q.q.iter().chain(&q.q_dot).copied().collect::<Vec<f64>>());
            }
        }
    }
    let decoded: Vec<Vec<f64>> = serde_json::from_value(read["estimates"].clone()).unwrap();
    assert_eq!(decoded.len(), 50, "{text}");
    assert_eq!(decoded[..], sent[..50]);
    assert!(decoded.iter().any(|q| q.iter().any(|x| *x != 0.0)));
}
