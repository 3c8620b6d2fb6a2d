//! A small system recorded, then exported for ROS 2 tools (`export_ros2`),
//! the export read back with the `mcap` crate: profile `ros2`; exactly the
//! recording's CDR channels with a `ros2msg` schema (a buffer's values and a
//! derived channel in a standard type), each with every message as recorded
//! (bytes, log and publish times, sequence numbers); one definition per type
//! name across the file; the others (JSON values, behaviour switches,
//! errors, raw copies, reads, a derived JSON channel) left out and named with
//! their reason. A file cut short exports what it holds; a missing file,
//! another kind of file, a recording without ROS 2 channels and an export
//! over its own recording are refused, writing nothing.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::time::Duration;

use agent_core::trace::LinkInfo;
use agent_core::*;
use agent_mcap::record::{Derive, DerivedChannel, McapRecorder, RecordOptions};
use agent_mcap::{ExportError, ExportOptions, LeftOutReason, export_ros2};
use serde::{Deserialize, Serialize};

/// A type that contains itself: recorded as JSON.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
struct Tree {
    label: u32,
    children: Vec<Tree>,
}

/// A 4x4 matrix: its rows are the recorder's `Item` messages of 4 doubles.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
struct Transform {
    matrix: [[f64; 4]; 4],
    from: f64,
}

/// Rows of 5: the recorder's `Item` messages of 5 doubles, another
/// definition of the same name.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
struct Rows {
    rows: [[f64; 5]; 2],
}

struct Sender;

#[derive(Debug, Default)]
struct ToE {
    tree: Out<Tree>,
    size: Out<f64>,
    transform: Out<Transform>,
    rows: Out<Rows>,
}
impl Group for ToE {
    const PEER: NodeKind = NodeKind::VirtualEffector;
}

#[derive(Debug, Default)]
struct SenderOut {
    e: ToE,
}

impl Subsystem for Sender {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = u32;
    type Input = ();
    type Output = SenderOut;
}

struct Keeper;

#[derive(Debug, Default, Clone)]
struct FromC {
    tree: In<Tree>,
    size: In<f64>,
    transform: In<Transform>,
    rows: In<Rows>,
}
impl Group for FromC {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Debug, Default, Clone)]
struct KeeperIn {
    c: FromC,
}

impl Subsystem for Keeper {
    const KIND: SubsystemKind = SubsystemKind::VirtualEffector;
    type Memory = ();
    type Input = KeeperIn;
    type Output = ();
}

/// c sends e a tree, a number, a transform and rows every 10 ms.
fn system() -> System {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let period = Period::from_millis(10).unwrap();
    let send = Fsm::single(Behaviour::while_loop(
        "send",
        Action::<Sender>::new()
            .output(
                |y| &mut y.e,
                |n: &u32, _: &(), y: &mut ToE| {
                    let x = f64::from(*n);
                    y.tree.set(Tree {
                        label: *n,
                        children: vec![Tree::default()],
                    });
                    y.size.set(x * 0.5);
                    y.transform.set(Transform {
                        matrix: [[x, 1.0, 2.0, 3.0]; 4],
                        from: -x,
                    });
                    y.rows.set(Rows {
                        rows: [[x; 5], [2.0 * x; 5]],
                    });
                },
            )
            .memory(|n: &mut u32, _: &()| *n += 1),
        "false",
    ))
    .unwrap();
    let keep = Fsm::single(Behaviour::while_loop(
        "keep",
        Action::<Keeper>::new(),
        "false",
    ))
    .unwrap();
    let c = b.subsystem(a, "c", period, 0u32, send);
    let e = b.subsystem(a, "e", period, (), keep);
    b.connect(
        c.output(port!(SenderOut, e.tree)),
        e.input(port!(KeeperIn, c.tree)),
        Policy::Sample,
    );
    b.connect(
        c.output(port!(SenderOut, e.size)),
        e.input(port!(KeeperIn, c.size)),
        Policy::Sample,
    );
    b.connect(
        c.output(port!(SenderOut, e.transform)),
        e.input(port!(KeeperIn, c.transform)),
        Policy::Sample,
    );
    b.connect(
        c.output(port!(SenderOut, e.rows)),
        e.input(port!(KeeperIn, c.rows)),
        Policy::Sample,
    );
    b.build().unwrap()
}

/// The size as ROS 2's `std_msgs/msg/Float64` (CDR), or as JSON.
struct SizeAs {
    ros2: bool,
}

impl Derive for SizeAs {
    fn channel(&mut self, _link: usize, info: &LinkInfo) -> Option<DerivedChannel> {
        let (topic, schema_name, schema_encoding, schema, message_encoding) = if self.ros2 {
            (
                "/size",
                "std_msgs/msg/Float64",
                "ros2msg",
                "float64 data\n",
                "cdr",
            )
        } else {
            ("/size_json", "size", "jsonschema", "{}", "json")
        };
        info.name.contains("size").then(|| DerivedChannel {
            topic: topic.into(),
            schema_name: schema_name.into(),
            schema_encoding: schema_encoding.into(),
            schema: schema.as_bytes().to_vec(),
            message_encoding: message_encoding.into(),
        })
    }

    fn message(&mut self, _link: usize, _time: Time, body: &[u8], out: &mut Vec<u8>) -> bool {
        let x = f64::from_le_bytes(body.try_into().unwrap());
        if self.ros2 {
            out.extend([0, 1, 0, 0]);
            out.extend(x.to_le_bytes());
        } else {
            out.extend(format!("{{\"size\":{x}}}").as_bytes());
        }
        true
    }
}

fn tmp(name: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join(name)
}

/// Record 200 ms of the system to `name`, with the values as `values`.
fn record(name: &str, values: agent_mcap::Values) -> PathBuf {
    let path = tmp(name);
    let s = system();
    let mut options = RecordOptions {
        values,
        derived: vec![
            Box::new(SizeAs { ros2: true }),
            Box::new(SizeAs { ros2: false }),
        ],
        ..RecordOptions::default()
    };
    options.metadata.insert(
        "run".into(),
        BTreeMap::from([("purpose".to_owned(), "export".to_owned())]),
    );
    let recorder = McapRecorder::create(&path, &s, options).unwrap();
    let mut exec = Executor::with_observer(s, ExecConfig::default(), recorder);
    exec.run_for(Duration::from_millis(200)).unwrap();
    exec.into_observer().finish().unwrap();
    path
}

/// A schema: name, encoding, text.
type Schema = (String, String, String);

/// A message: log time, publish time, sequence, bytes.
type Message = (u64, u64, u32, Vec<u8>);

/// A file read with the `mcap` crate: its profile, each channel's encoding
/// and schema (name, encoding, text) by topic (from its summary), its messages per topic (log
/// time, publish time, sequence, bytes) and its metadata records' names.
struct File {
    profile: String,
    channels: BTreeMap<String, (String, Option<Schema>)>,
    messages: BTreeMap<String, Vec<Message>>,
    metadata: Vec<String>,
}

impl File {
    fn read(path: &Path) -> File {
        let bytes = std::fs::read(path).unwrap();
        let mut f = File {
            profile: String::new(),
            channels: BTreeMap::new(),
            messages: BTreeMap::new(),
            metadata: Vec::new(),
        };
        for record in mcap::read::LinearReader::new(&bytes).unwrap() {
            match record.unwrap() {
                mcap::records::Record::Header(h) => f.profile = h.profile,
                mcap::records::Record::Metadata(m) => f.metadata.push(m.name),
                _ => {}
            }
        }
        let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
        for c in summary.channels.values() {
            let schema = c.schema.as_ref().map(|s| {
                let text = String::from_utf8(s.data.to_vec()).unwrap_or_default();
                (s.name.clone(), s.encoding.clone(), text)
            });
            f.channels
                .insert(c.topic.clone(), (c.message_encoding.clone(), schema));
        }
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            let message = (m.log_time, m.publish_time, m.sequence, m.data.to_vec());
            f.messages
                .entry(m.channel.topic.clone())
                .or_default()
                .push(message);
        }
        f
    }

    /// Whether the channel of `topic` is ROS 2: CDR with a `ros2msg` schema.
    fn ros2(&self, topic: &str) -> bool {
        let (encoding, schema) = &self.channels[topic];
        encoding == "cdr" && schema.as_ref().is_some_and(|s| s.1 == "ros2msg")
    }
}

/// Every definition of every `ros2msg` schema of `f`, by name (`pkg/Name`):
/// the definitions that name has.
fn definitions(f: &File) -> BTreeMap<String, BTreeSet<String>> {
    let separator = format!("{}\n", "=".repeat(80));
    let mut out: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for (_, schema) in f.channels.values() {
        let Some((name, _, text)) = schema.as_ref().filter(|s| s.1 == "ros2msg") else {
            continue;
        };
        let mut parts = text.split(&separator);
        let root = parts.next().unwrap_or_default();
        out.entry(name.replace("/msg/", "/"))
            .or_default()
            .insert(root.to_owned());
        for part in parts {
            let (head, body) = part.split_once('\n').unwrap();
            let name = head.strip_prefix("MSG: ").unwrap();
            out.entry(name.to_owned())
                .or_default()
                .insert(body.to_owned());
        }
    }
    out
}

#[test]
fn an_export_holds_the_ros_2_channels_with_every_message_and_names_what_it_left_out() {
    let source = record("export_source.mcap", agent_mcap::Values::Cdr);
    let out = tmp("export_ros2.mcap");
    let summary = export_ros2(&source, &out, &ExportOptions::default()).unwrap();
    let (src, exp) = (File::read(&source), File::read(&out));

    assert_eq!(exp.profile, "ros2");
    let ros2: BTreeSet<&String> = src.channels.keys().filter(|t| src.ros2(t)).collect();
    let expected: BTreeSet<&str> = [
        "/links/c/e/size/to/e",
        "/links/c/e/transform/to/e",
        "/links/c/e/rows/to/e",
        "/size",
    ]
    .into();
    assert_eq!(
        ros2.iter().map(|t| t.as_str()).collect::<BTreeSet<_>>(),
        expected
    );
    // Exactly those, each with every message as recorded, in a schema named
    // as ROS 2 names types.
    assert_eq!(exp.channels.keys().collect::<BTreeSet<_>>(), ros2);
    for (topic, (encoding, schema)) in &exp.channels {
        let (name, schema_encoding, _) = schema.as_ref().unwrap();
        assert_eq!(
            (encoding.as_str(), schema_encoding.as_str()),
            ("cdr", "ros2msg")
        );
        let (package, rest) = name.split_once("/msg/").unwrap();
        assert!(
            package.chars().all(|c| c.is_ascii_lowercase() || c == '_'),
            "{name}"
        );
        assert!(rest.starts_with(|c: char| c.is_ascii_uppercase()), "{name}");
        let messages = src.messages.get(topic).expect(topic);
        assert_eq!(exp.messages.get(topic), Some(messages), "{topic}");
        assert_eq!(summary.per_topic[topic], messages.len() as u64);
    }
    assert!(src.messages["/links/c/e/transform/to/e"].len() >= 19);
    assert_eq!(
        exp.channels["/size"].1.as_ref().unwrap().0,
        "std_msgs/msg/Float64"
    );
    assert_eq!(summary.channels, 4);
    assert_eq!(
        summary.messages,
        exp.messages.values().map(|m| m.len() as u64).sum::<u64>()
    );
    assert!(summary.renamed_topics.is_empty(), "{summary:?}");

    // One definition per type name in the export; the recording's second
    // definitions of a name are renamed, as many as there are.
    assert!(
        definitions(&exp).values().all(|d| d.len() == 1),
        "{:?}",
        definitions(&exp)
    );
    let clashes: usize = definitions(&src).values().map(|d| d.len() - 1).sum();
    assert_eq!(summary.renamed_types.len(), clashes, "{summary:?}");

    // Every other channel left out, named, with its reason; the metadata kept.
    let left: BTreeSet<&String> = summary.left_out.iter().map(|l| &l.topic).collect();
    let others: BTreeSet<&String> = src.channels.keys().filter(|t| !src.ros2(t)).collect();
    assert_eq!(left, others);
    for topic in ["/links/c/e/tree/to/e", "/fsm/c", "/errors", "/size_json"] {
        let l = summary.left_out.iter().find(|l| l.topic == topic);
        let reason = l.map(|l| &l.reason);
        assert_eq!(
            reason,
            Some(&LeftOutReason::NotCdr {
                encoding: "json".into()
            }),
            "{topic}: {summary:?}"
        );
    }
    assert!(
        left.iter().any(|t| t.starts_with("/raw/links/")),
        "{left:?}"
    );
    // (By name: the reader keeps them so.)
    let sorted = |names: &[String]| names.iter().cloned().collect::<BTreeSet<String>>();
    assert_eq!(sorted(&exp.metadata), sorted(&src.metadata));
    assert!(
        exp.metadata.contains(&"run".to_owned()),
        "{:?}",
        exp.metadata
    );
    assert_eq!(summary.metadata, src.metadata.len());
    assert_eq!(summary.cut_short, None);

    // Without metadata, asked.
    let bare = tmp("export_bare.mcap");
    let summary = export_ros2(&source, &bare, &ExportOptions { metadata: false }).unwrap();
    assert_eq!((summary.metadata, File::read(&bare).metadata.len()), (0, 0));
}

#[test]
fn a_recording_cut_short_exports_what_it_holds() {
    let source = record("export_whole.mcap", agent_mcap::Values::Cdr);
    let bytes = std::fs::read(&source).unwrap();
    let cut = tmp("export_cut.mcap");
    std::fs::write(&cut, &bytes[..bytes.len() * 3 / 4]).unwrap();
    let out = tmp("export_cut_ros2.mcap");
    let summary = export_ros2(&cut, &out, &ExportOptions::default()).unwrap();
    assert!(summary.cut_short.is_some(), "{summary:?}");
    let whole = export_ros2(
        &source,
        &tmp("export_whole_ros2.mcap"),
        &ExportOptions::default(),
    )
    .unwrap();
    assert!(summary.messages <= whole.messages, "{summary:?} {whole:?}");
    let exp = File::read(&out);
    assert_eq!(exp.profile, "ros2");
    let read: u64 = exp.messages.values().map(|m| m.len() as u64).sum();
    assert_eq!(read, summary.messages);
}

#[test]
fn what_cannot_be_exported_is_refused_clearly_and_writes_nothing() {
    let out = tmp("export_refused.mcap");
    let _ = std::fs::remove_file(&out);
    let options = ExportOptions::default();

    let e = export_ros2(&tmp("no_such_recording.mcap"), &out, &options).unwrap_err();
    assert!(
        matches!(e, ExportError::Read(agent_mcap::ReadError::Io { .. })),
        "{e}"
    );
    let text = tmp("export_not_mcap.txt");
    std::fs::write(&text, "not a recording").unwrap();
    let e = export_ros2(&text, &out, &options).unwrap_err();
    assert!(
        matches!(e, ExportError::Read(agent_mcap::ReadError::NotMcap { .. })),
        "{e}"
    );

    // Values as JSON: the derived `/size` is still ROS 2, so without it.
    let json = tmp("export_json.mcap");
    let s = system();
    let recorder = McapRecorder::create(
        &json,
        &s,
        RecordOptions {
            values: agent_mcap::Values::Json,
            ..RecordOptions::default()
        },
    )
    .unwrap();
    let mut exec = Executor::with_observer(s, ExecConfig::default(), recorder);
    exec.run_for(Duration::from_millis(50)).unwrap();
    exec.into_observer().finish().unwrap();
    let e = export_ros2(&json, &out, &options).unwrap_err();
    assert!(matches!(e, ExportError::NoRos2Channel { .. }), "{e}");
    assert!(e.to_string().contains("record with CDR values"), "{e}");
    assert!(!out.exists());

    let e = export_ros2(&json, &json, &options).unwrap_err();
    assert!(matches!(e, ExportError::SameFile { .. }), "{e}");
    assert!(
        File::read(&json).messages.len() > 3,
        "the recording is intact"
    );
}
