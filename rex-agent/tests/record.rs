//! A Rex run recorded to MCAP (`embodied::record::McapRecorder` on the deterministic
//! executor), read back with the `mcap` crate's reader: every link has a JSON
//! channel with its type's schema and a raw channel with the exact bytes, the
//! FSM channels hold the behaviour switches with the value of every predicate,
//! the system is described in the metadata, and the JSON of a value is the
//! value.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::collections::BTreeMap;
use std::time::Duration;

use embodied::Executor;
use embodied::record::mcap;
use embodied::record::{self, McapRecorder, RecordOptions, RecordSummary};
use rex_agent::mission::Mission;
use rex_agent::payload::State;
use rex_agent::system::{RexConfig, build};
use rex_agent::world::WorldConfig;

/// The shipped figure-eight without the camera: the recording tests' mission.
fn figure_eight() -> RexConfig {
    let mut config = RexConfig::new(
        WorldConfig::shipped().unwrap(),
        Mission::shipped("figure_eight").unwrap(),
    );
    config.visual_odometry = false;
    config
}

#[test]
fn a_rex_run_recorded_to_mcap_reads_back_with_schemas_switches_and_exact_values() {
    let config = figure_eight();
    let (system, _) = build(&config).unwrap();
    let links = system.info().links.len();
    let nodes = system.info().nodes.len();
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("rex_record.mcap");
    let mut options = RecordOptions::default();
    options.metadata.insert(
        "run".into(),
        BTreeMap::from([("mission".to_owned(), "figure_eight".to_owned())]),
    );
    let recorder = McapRecorder::create(&path, &system, options).unwrap();
    let mut exec = Executor::with_observer(system, config.exec, recorder);
    exec.run_for(Duration::from_secs(6)).unwrap();
    let summary = exec.into_observer().finish().unwrap();
    // Per link: its value, raw, reads; per node: its switches; the errors.
    assert_eq!(summary.channels, 3 * links + nodes + 1);
    assert_eq!(summary.undecodable, 0);
    assert!(summary.json_values.is_empty(), "{summary:?}");
    assert!(summary.messages > 10_000, "{summary:?}");
    // The writer ran in the background: SCHED_IDLE (which needs no privilege)
    // as the OS reports the thread's policy once set.
    assert_eq!(summary.background, cfg!(target_os = "linux"), "{summary:?}");

    let bytes = std::fs::read(&path).unwrap();
    let read = ReadBack::of(&bytes);
    read.raw_channels_are_the_value_channels(&summary, links);
    read.cdr_is_ros2s_layout_and_raw_is_exact();
    read.c1_took_the_first_plan();
    the_metadata_is_the_systems_and_the_callers(&bytes);
}

/// What a recording reads back as: each message's channel checked (its
/// encoding and schema, and a raw channel's framing), and what the test then
/// compares counted or kept.
#[derive(Default)]
struct ReadBack {
    per_topic: BTreeMap<String, u64>,
    /// c1's behaviour switches.
    switches: Vec<serde_json::Value>,
    /// e11's estimates on their value channel and on their raw one.
    estimates: (u64, u64),
    raw_q: Vec<State>,
    cdr_q: Vec<Vec<u8>>,
    /// Values per raw channel.
    raw_counts: BTreeMap<String, u64>,
    /// e11's iterations, from the estimates' stamps.
    raw_iterations: Vec<u64>,
    /// Messages per raw channel.
    raw_messages: BTreeMap<u16, u32>,
    /// Values and messages on the raw channels.
    values_per_raw_message: (u64, u64),
}

impl ReadBack {
    /// Read every message of the recording `bytes`.
    fn of(bytes: &[u8]) -> ReadBack {
        let mut read = ReadBack::default();
        for m in mcap::MessageStream::new(bytes).unwrap() {
            let m = m.unwrap();
            *read.per_topic.entry(m.channel.topic.clone()).or_default() += 1;
            let topic = m.channel.topic.as_str();
            check_channel(&m);
            if topic == "/fsm/c1" {
                read.switches
                    .push(serde_json::from_slice::<serde_json::Value>(&m.data).unwrap());
            }
            if topic == "/links/e11/c1/q_est/to/c1" {
                read.estimates.0 += 1;
                read.cdr_q.push(m.data.to_vec());
            }
            if topic.starts_with("/raw/") {
                read.raw(&m);
            }
        }
        read
    }

    /// A raw message: several values, each framed with the wire header a link
    /// between processes would carry: the type's fingerprint (as the channel
    /// says), the link's count from 1, and the sender's stamp (the first
    /// value's instant the message's log time).
    fn raw(&mut self, m: &mcap::Message<'_>) {
        let topic = m.channel.topic.as_str();
        assert_eq!(m.channel.message_encoding, "embodied-wire-frames/1");
        let raw = self.raw_messages.entry(m.channel.id).or_insert(0u32);
        assert_eq!(m.sequence, *raw, "{topic}");
        *raw += 1;
        let mut last_time = 0;
        for (k, value) in record::raw_values(&m.channel.message_encoding, &m.data).enumerate() {
            let (header, body) = embodied::WireHeader::read(value.unwrap()).unwrap();
            let fingerprint = &m.channel.metadata["fingerprint"];
            assert_eq!(&format!("{:016x}", header.fingerprint), fingerprint);
            let count = self.raw_counts.entry(topic.to_owned()).or_insert(0u64);
            *count += 1;
            assert_eq!((header.seq, header.epoch), (*count, 0), "{topic}");
            let time = header.stamp.time.as_nanos();
            if k == 0 {
                assert_eq!(time, m.log_time, "{topic}");
            }
            assert!(time >= last_time, "{topic}");
            last_time = time;
            self.values_per_raw_message.0 += 1;
            if topic == "/raw/links/e11/c1/q_est/to/c1" {
                self.estimates.1 += 1;
                self.raw_q
                    .push(postcard::from_bytes::<State>(body).unwrap());
                self.raw_iterations.push(header.stamp.iteration);
            }
        }
        self.values_per_raw_message.1 += 1;
    }

    /// Every value of a link is on its raw channel as on its value channel,
    /// the 1 kHz sensor links fill a raw message with many values, and the
    /// stamps carry e11's iterations.
    fn raw_channels_are_the_value_channels(&self, summary: &RecordSummary, links: usize) {
        let values_per_raw_message = self.values_per_raw_message;
        assert!(
            values_per_raw_message.0 > 10 * values_per_raw_message.1,
            "{values_per_raw_message:?}"
        );
        // (No value here is too long for its value channel.)
        assert_eq!(summary.raw_only, 0);
        for (topic, values) in &self.raw_counts {
            let value_topic = topic.strip_prefix("/raw").unwrap();
            assert_eq!(Some(values), self.per_topic.get(value_topic), "{topic}");
        }
        assert!(self.raw_counts.len() > links / 2, "{:?}", self.raw_counts);
        // One value per iteration at most.
        assert!(
            self.raw_iterations.windows(2).all(|w| w[1] > w[0]),
            "{:?}",
            self.raw_iterations
        );
        // Every link's two channels carried something in 6 s, but the camera's
        // (no visual odometry here) and those that wait for events.
        assert!(self.per_topic.len() > links, "{:?}", self.per_topic);
        assert_eq!(self.estimates.0, self.estimates.1);
        assert!(self.estimates.0 > 100, "{:?}", self.estimates);
    }

    /// Each estimate's CDR is its fields as ROS 2 lays them out (`float64[7]
    /// q`, `float64[7] q_dot`, `Ground[<=1] ground`: the header, 14
    /// little-endian doubles, the bounded sequence's length, then (aligned to
    /// 8) the friction's three doubles and the `settled` byte); the raw bytes
    /// are exact.
    fn cdr_is_ros2s_layout_and_raw_is_exact(&self) {
        let mut grounds = 0;
        for (c, q) in self.cdr_q.iter().zip(&self.raw_q) {
            let mut expected = vec![0, 1, 0, 0];
            for x in q.q.iter().chain(&q.q_dot) {
                expected.extend(x.to_le_bytes());
            }
            match q.ground {
                None => expected.extend(0u32.to_le_bytes()),
                Some(g) => {
                    grounds += 1;
                    expected.extend(1u32.to_le_bytes());
                    expected.extend([0; 4]);
                    for x in g.friction.to_array() {
                        expected.extend(x.to_le_bytes());
                    }
                    expected.push(u8::from(g.settled));
                }
            }
            assert_eq!(c, &expected);
        }
        // The MHE estimates the ground from its first estimate on.
        assert_eq!(grounds, self.cdr_q.len());
    }

    /// c1 took the first plan: B1 -> B2 by `plan_valid`, with `plan_new` true.
    fn c1_took_the_first_plan(&self) {
        let first = &self.switches[0];
        assert_eq!(
            (first["from"].as_str(), first["to"].as_str()),
            (Some("B1"), Some("B2")),
            "{:?}",
            self.switches
        );
        assert_eq!(first["condition"], "plan_valid");
        assert_eq!(first["predicates"]["plan_new"], true);
        assert_eq!(first["predicates"]["plan_valid"], true);
    }
}

/// A message's channel: reads are 16 bytes; every Rex payload has a ROS 2
/// message, CDR as Foxglove reads; the other channels but the raw ones are
/// JSON with a JSON schema.
fn check_channel(m: &mcap::Message<'_>) {
    let topic = m.channel.topic.as_str();
    if topic.starts_with("/reads/") {
        assert_eq!(m.channel.message_encoding, "embodied-read/1", "{topic}");
        assert_eq!(m.data.len(), 16, "{topic}");
    } else if topic.starts_with("/links/") {
        assert_eq!(m.channel.message_encoding, "cdr", "{topic}");
        let schema = m.channel.schema.as_ref().expect(topic);
        assert_eq!(schema.encoding, "ros2msg", "{topic}");
        assert!(schema.name.starts_with("embodied/msg/"), "{topic}");
    } else if !topic.starts_with("/raw/") {
        assert_eq!(m.channel.message_encoding, "json", "{topic}");
        let schema = m.channel.schema.as_ref().expect(topic);
        assert_eq!(schema.encoding, "jsonschema", "{topic}");
        serde_json::from_slice::<serde_json::Value>(&schema.data).unwrap();
    }
}

/// The metadata: the system's and the caller's.
fn the_metadata_is_the_systems_and_the_callers(bytes: &[u8]) {
    let mut names = Vec::new();
    for record in mcap::read::LinearReader::new(bytes).unwrap() {
        if let mcap::records::Record::Metadata(m) = record.unwrap() {
            names.push(m.name.clone());
            if m.name == "system" {
                assert!(m.metadata.contains_key("node/c1"), "{:?}", m.metadata);
            }
        }
    }
    assert_eq!(names, ["run", "system", "end"]);
}

#[test]
fn a_recording_to_a_place_that_cannot_be_written_is_a_clear_error() {
    let config = figure_eight();
    let (system, _) = build(&config).unwrap();
    let err = McapRecorder::create(
        std::path::Path::new("/nonexistent-folder/run.mcap"),
        &system,
        RecordOptions::default(),
    )
    .unwrap_err();
    assert!(
        err.to_string().contains("/nonexistent-folder/run.mcap"),
        "{err}"
    );
}

/// Asked for JSON, the values are JSON with their JSON schema, each the value
/// itself (CDR is the default, tested above).
#[test]
fn values_recorded_as_json_are_the_values_themselves() {
    let config = figure_eight();
    let (system, _) = build(&config).unwrap();
    let options = RecordOptions {
        values: embodied::record::Values::Json,
        ..RecordOptions::default()
    };
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("rex_json.mcap");
    let recorder = McapRecorder::create(&path, &system, options).unwrap();
    let mut exec = Executor::with_observer(system, config.exec, recorder);
    exec.run_for(Duration::from_secs(2)).unwrap();
    let summary = exec.into_observer().finish().unwrap();
    assert_eq!(summary.undecodable, 0);
    let bytes = std::fs::read(&path).unwrap();
    let (mut json_q, mut raw_q) = (Vec::new(), Vec::new());
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        let topic = m.channel.topic.as_str();
        if topic.starts_with("/links/") {
            assert_eq!(m.channel.message_encoding, "json", "{topic}");
            let schema = m.channel.schema.as_ref().expect(topic);
            assert_eq!(schema.encoding, "jsonschema", "{topic}");
        }
        if topic == "/links/e11/c1/q_est/to/c1" {
            json_q.push(serde_json::from_slice::<serde_json::Value>(&m.data).unwrap());
        }
        if topic == "/raw/links/e11/c1/q_est/to/c1" {
            for value in record::raw_values(&m.channel.message_encoding, &m.data) {
                let (_, body) = embodied::WireHeader::read(value.unwrap()).unwrap();
                raw_q.push(postcard::from_bytes::<State>(body).unwrap());
            }
        }
    }
    assert!(
        json_q.len() > 10 && json_q.len() == raw_q.len(),
        "{}",
        json_q.len()
    );
    for (j, q) in json_q.iter().zip(&raw_q) {
        assert_eq!(j, &serde_json::to_value(q).unwrap());
    }
}

/// Asked not to, the writer thread stays at normal priority (the first test
/// checks the default, `SCHED_IDLE` as the OS reports it).
#[test]
fn the_writer_thread_runs_at_normal_priority_when_asked() {
    let config = figure_eight();
    let (system, _) = build(&config).unwrap();
    let options = RecordOptions {
        background: false,
        ..RecordOptions::default()
    };
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("rex_foreground.mcap");
    let recorder = McapRecorder::create(&path, &system, options).unwrap();
    let mut exec = Executor::with_observer(system, config.exec, recorder);
    exec.run_for(Duration::from_millis(500)).unwrap();
    let summary = exec.into_observer().finish().unwrap();
    assert!(!summary.background);
    assert!(summary.messages > 100, "{summary:?}");
}

/// Reads an MCAP file (argument 1) with the official Python reader: every
/// message, JSON ones parsed with their schemas, and those of a Foxglove
/// schema validated against Foxglove's own (argument 2: its JSON schemas by
/// title); prints the counts.
const PY_READER: &str = r#"
import json, sys
import jsonschema
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic
foxglove_schemas = json.load(open(sys.argv[2]))
def only_foxglove_fields(value, schema, where):
    # Foxglove's schemas allow other fields; Foxglove would ignore them: none.
    if schema.get("type") == "object":
        fields = schema.get("properties", {})
        for k, v in value.items():
            assert k in fields, f"{where}: {k} is not a field of Foxglove's schema"
            only_foxglove_fields(v, fields[k], where + "." + k)
    elif schema.get("type") == "array":
        for v in value:
            only_foxglove_fields(v, schema["items"], where + "[]")
foxglove_valid = 0
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f, decoder_factories=[DecoderFactory()])
    summary = reader.get_summary()
    n = 0
    topics = set()
    schemas = set()
    images = 0
    cdr = 0
    codecs = {}
    for schema, channel, message in reader.iter_messages():
        n += 1
        topics.add(channel.topic)
        if schema is not None and schema.name.startswith("foxglove."):
            schemas.add(schema.name + ":" + channel.topic)
            # What Foxglove's panels read: the message against Foxglove's
            # schema of that name (not the one in the file, which is ours).
            official = foxglove_schemas[schema.name]
            value = json.loads(message.data)
            jsonschema.validate(value, official)
            only_foxglove_fields(value, official, channel.topic)
            foxglove_valid += 1
        if channel.message_encoding == "json":
            json.loads(message.data)
            assert schema is not None and schema.encoding == "jsonschema", channel.topic
            json.loads(schema.data)
        if schema is not None and schema.name.startswith("embodied/msg/"):
            # A buffer's value in CDR: decoded by mcap_ros2 against the ros2msg
            # schema the recorder made, and encoded again to the same bytes.
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            if schema.id not in codecs:
                text = schema.data.decode()
                codecs[schema.id] = (
                    generate_dynamic(schema.name, text)[schema.name],
                    serialize_dynamic(schema.name, text)[schema.name],
                )
            decode, encode = codecs[schema.id]
            again = bytes(encode(decode(message.data)))
            assert again == bytes(message.data), (channel.topic, message.data, again)
            cdr += 1
    # The camera's images, in ROS 2's schema: decoded by mcap_ros2.
    for schema, channel, message, image in reader.iter_decoded_messages(topics=["/camera/left"]):
        assert schema.name == "sensor_msgs/msg/CompressedImage" and channel.message_encoding == "cdr"
        assert image.format == "png" and image.header.frame_id == "camera_left", image
        assert bytes(image.data[:8]) == b"\x89PNG\r\n\x1a\n"
        assert image.header.stamp.sec * 10**9 + image.header.stamp.nanosec == message.log_time
        images += 1
    meta = sorted(m.name for m in reader.iter_metadata())
    print(f"images={images} cdr={cdr} messages={n} channels={len(summary.channels)} topics={len(topics)} metadata={','.join(meta)} foxglove={','.join(sorted(schemas))} foxglove_valid={foxglove_valid}")
"#;

#[test]
fn the_official_python_reader_reads_every_message_of_a_rex_recording() {
    // The reader (PyPI `mcap`, `mcap-ros2-support`, `jsonschema`) and
    // Foxglove's JSON schemas (npm `@foxglove/schemas`) are test dependencies
    // that the test command, `scripts/test`, installs under the target folder;
    // plain `cargo test` stays offline and skips this.
    let (Some(python), Some(foxglove)) = (
        std::env::var_os("EMBODIED_INTEROP_PYTHON"),
        std::env::var_os("EMBODIED_INTEROP_FOXGLOVE"),
    ) else {
        eprintln!(
            "skipped: EMBODIED_INTEROP_PYTHON and EMBODIED_INTEROP_FOXGLOVE are not set (`scripts/test` installs the official readers and sets them)"
        );
        return;
    };
    let tmp = std::path::Path::new(env!("CARGO_TARGET_TMPDIR"));

    let mut config = RexConfig::new(
        WorldConfig::shipped().unwrap(),
        Mission::shipped("square").unwrap(),
    );
    // With the camera: its images are in ROS 2's encoding.
    config.visual_odometry = true;
    let (system, _) = build(&config).unwrap();
    let path = tmp.join("rex_python.mcap");
    let options = rex_agent::record::options();
    let recorder = McapRecorder::create(&path, &system, options).unwrap();
    let mut exec = Executor::with_observer(system, config.exec, recorder);
    exec.run_for(Duration::from_secs(3)).unwrap();
    let summary = exec.into_observer().finish().unwrap();

    let out = std::process::Command::new(&python)
        .args(["-c", PY_READER])
        .arg(&path)
        .arg(&foxglove)
        .output()
        .unwrap();
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let figure = |key: &str| -> u64 {
        text.split_whitespace()
            .find_map(|w| w.strip_prefix(&format!("{key}=")))
            .and_then(|v| v.parse().ok())
            .unwrap_or_else(|| panic!("no {key}= in {text}"))
    };
    assert_eq!(figure("messages"), summary.messages, "{text}");
    assert_eq!(figure("channels") as usize, summary.channels, "{text}");
    // Every buffer value in CDR went through mcap_ros2 and back.
    let bytes = std::fs::read(&path).unwrap();
    let values = mcap::MessageStream::new(&bytes)
        .unwrap()
        .filter(|m| m.as_ref().unwrap().channel.topic.starts_with("/links/"))
        .count() as u64;
    assert!(values > 9_000, "{values}");
    assert_eq!(figure("cdr"), values, "{text}");
    assert!(text.contains("metadata=end,system"), "{text}");
    // Every image the camera took (from 0 s, every 0.1 s).
    assert!(figure("images") >= 30, "{text}");
    // Foxglove's schemas, on the channels Rex adds.
    assert!(
        text.contains(
            "foxglove=foxglove.PoseInFrame:/pose/estimate,foxglove.PoseInFrame:/pose/mocap,foxglove.PosesInFrame:/path/reference"
        ),
        "{text}"
    );
    // Every one of their messages is valid in Foxglove's own schemas.
    let poses = mcap::MessageStream::new(&bytes)
        .unwrap()
        .filter(|m| {
            let topic = &m.as_ref().unwrap().channel.topic;
            topic.starts_with("/pose/") || topic == "/path/reference"
        })
        .count() as u64;
    assert!(poses > 200, "{poses}");
    assert_eq!(figure("foxglove_valid"), poses, "{text}");
}
