//! Starting the recording's file on the writer thread: its header, a
//! schema and channels per link (the value in the form tools read, raw,
//! reads, derived), the `/fsm` and `/errors` channels, and the metadata.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use agent_core::Time;
use agent_core::TypeShape;
use agent_core::trace::{LinkInfo, SystemInfo};

use super::writer::{LinkChannels, Output};
use super::{
    Derive, FRAMES_ENCODING, READ_ENCODING, RecordError, RecordOptions, RecordSummary, SHAPE_KEY,
    Values,
};
use crate::cdr::{root_name, ros2msg_schema};
use crate::codec::CODEC_KEY;
use crate::json::json_schema;

/// What the writer thread makes the file from: what needed the system, taken
/// on the caller's thread.
pub(super) struct Plan {
    pub(super) file: File,
    pub(super) path: PathBuf,
    pub(super) info: SystemInfo,
    /// Per link: the payload's shape as JSON text (`serde-reflection`'s
    /// formats cannot cross threads), and its fingerprint.
    pub(super) shapes: Vec<Option<String>>,
    pub(super) fingerprints: Vec<u64>,
    pub(super) options: RecordOptions,
}

impl Output {
    /// Start the file: its header, schemas, channels and metadata. Returns
    /// the writer and the links' shapes.
    pub(super) fn open(plan: Plan) -> Result<(Output, Vec<Option<TypeShape>>), RecordError> {
        let Plan {
            file,
            path,
            info,
            shapes,
            fingerprints,
            mut options,
        } = plan;
        let texts = shapes;
        let shapes = read_shapes(&texts);
        let mut d = Declare {
            w: start_file(file, &path)?,
            path: &path,
            json_values: Vec::new(),
        };
        let mut links = Vec::with_capacity(info.links.len());
        for ((k, link), topic) in info.links.iter().enumerate().zip(link_topics(&info)) {
            let shape = shapes
                .get(k)
                .and_then(Option::as_ref)
                .zip(texts.get(k).and_then(Option::as_deref));
            let fingerprint = fingerprints.get(k).copied().unwrap_or(0);
            links.push(d.link(k, link, topic, shape, fingerprint, &mut options)?);
        }
        let fsm = d.fsm_channels(&info)?;
        let errors = d.error_channel()?;
        let mut metadata = std::mem::take(&mut options.metadata);
        metadata.insert("system".into(), describe(&info));
        d.metadata(metadata)?;
        let channels =
            links.len() * 3 + links.iter().map(|l| l.derived.len()).sum::<usize>() + fsm.len() + 1;
        let Declare { w, json_values, .. } = d;
        let out = Output {
            w,
            path,
            info,
            links,
            predicates: vec![(None, 0); fsm.len()],
            fsm,
            errors,
            derived: options.derived,
            value_max_bytes: options.value_max_bytes,
            scratch: Vec::new(),
            encoded: Vec::new(),
            summary: RecordSummary {
                channels,
                json_values,
                ..RecordSummary::default()
            },
        };
        Ok((out, shapes))
    }
}

/// The links' shapes, from their JSON text (`None`: no shape, or a text that
/// does not read).
fn read_shapes(texts: &[Option<String>]) -> Vec<Option<TypeShape>> {
    texts
        .iter()
        .map(|text| {
            let (root, registry) = serde_json::from_str(text.as_deref()?).ok()?;
            Some(TypeShape { root, registry })
        })
        .collect()
}

/// The MCAP writer on `file`, its header written.
fn start_file(file: File, path: &Path) -> Result<mcap::Writer<BufWriter<File>>, RecordError> {
    mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .compression_level(1)
        // On the writer thread: Zstd's default worker per CPU takes the
        // executor's core (measured: 1.47 -> 1.38 the wall time of a
        // recorded run without images, `bench_record`).
        .compression_threads(0)
        .profile("")
        .library(concat!(
            "embodied-agents agent-mcap ",
            env!("CARGO_PKG_VERSION")
        ))
        .create(BufWriter::new(file))
        .map_err(|e| write_failed(path, &e))
}

/// Each link's topic: `/links/<from>/<port>/to/<to>`, with the receiving
/// port after it where two links would share one.
fn link_topics(info: &SystemInfo) -> Vec<String> {
    let mut topics = std::collections::BTreeSet::new();
    let mut out = Vec::with_capacity(info.links.len());
    for link in &info.links {
        let from = &info.nodes[link.from].name;
        let to = &info.nodes[link.to].name;
        let mut topic = format!("/links/{from}/{}/to/{to}", link.from_port.replace('.', "/"));
        if !topics.insert(topic.clone()) {
            topic = format!("{topic}/{}", link.to_port.replace('.', "/"));
            topics.insert(topic.clone());
        }
        out.push(topic);
    }
    out
}

/// The MCAP writer's failure, writing the file at `path`.
fn write_failed(path: &Path, e: &mcap::McapError) -> RecordError {
    RecordError::Write {
        path: path.to_owned(),
        message: e.to_string(),
    }
}

/// The file's schemas, channels and metadata being declared.
struct Declare<'p> {
    w: mcap::Writer<BufWriter<File>>,
    path: &'p Path,
    /// The links whose values are JSON though CDR was asked for: each
    /// `<link>: <why>`.
    json_values: Vec<String>,
}

impl Declare<'_> {
    fn schema(&mut self, name: &str, encoding: &str, data: &[u8]) -> Result<u16, RecordError> {
        self.w
            .add_schema(name, encoding, data)
            .map_err(|e| write_failed(self.path, &e))
    }

    fn channel(
        &mut self,
        schema: u16,
        topic: &str,
        encoding: &str,
        metadata: &BTreeMap<String, String>,
    ) -> Result<u16, RecordError> {
        self.w
            .add_channel(schema, topic, encoding, metadata)
            .map_err(|e| write_failed(self.path, &e))
    }

    /// The channels of link `k` (its value channel, raw, reads and derived
    /// channels), and how to write its values; `shape`: the payload's shape
    /// and its JSON text.
    fn link(
        &mut self,
        k: usize,
        link: &LinkInfo,
        topic: String,
        shape: Option<(&TypeShape, &str)>,
        fingerprint: u64,
        options: &mut RecordOptions,
    ) -> Result<LinkChannels, RecordError> {
        let (value, cdr) = self.value_channel(link, &topic, shape, options.values)?;
        let read_meta = BTreeMap::from([
            ("link".to_owned(), link.name.clone()),
            ("fingerprint".to_owned(), format!("{fingerprint:016x}")),
        ]);
        let codec = options
            .codecs
            .iter()
            .find(|c| c.payload() == link.payload)
            .cloned();
        let mut raw_meta = read_meta.clone();
        if let Some(c) = &codec {
            raw_meta.insert(CODEC_KEY.to_owned(), c.name().to_owned());
        }
        let raw = self.channel(0, &format!("/raw{topic}"), FRAMES_ENCODING, &raw_meta)?;
        let reads = self.channel(0, &format!("/reads{topic}"), READ_ENCODING, &read_meta)?;
        let derived = self.derived_channels(k, link, &mut options.derived)?;
        Ok(LinkChannels {
            topic,
            raw_meta,
            received: None,
            received_count: 0,
            value,
            cdr,
            raw,
            reads,
            read_sequence: 0,
            fingerprint,
            count: 0,
            derived,
            codec,
            pending: Vec::new(),
            pending_since: Time::ZERO,
            raw_messages: 0,
        })
    }

    /// The channel of a link's values in the form tools read (CDR with its
    /// `ros2msg` schema if asked for and the type has a ROS 2 message, else
    /// JSON), and whether it is CDR. A CDR channel's metadata [`SHAPE_KEY`]
    /// holds the payload's shape (its JSON text), by which a reader without
    /// the Rust type reads a value back ([`read_cdr`](crate::cdr::read_cdr)).
    fn value_channel(
        &mut self,
        link: &LinkInfo,
        topic: &str,
        shape: Option<(&TypeShape, &str)>,
        values: Values,
    ) -> Result<(u16, bool), RecordError> {
        let (shape, text) = (shape.map(|(s, _)| s), shape.map(|(_, t)| t));
        let ros2 = match (shape, values) {
            (Some(s), Values::Cdr) => match ros2msg_schema(s, root_name(link.payload)) {
                Ok(r) => Some(r),
                Err(why) => {
                    self.json_values.push(format!("{}: {why}", link.name));
                    None
                }
            },
            _ => None,
        };
        let (schema, encoding) = match (shape, &ros2) {
            (_, Some(r)) => (self.schema(&r.name, "ros2msg", r.text.as_bytes())?, "cdr"),
            (Some(s), None) => {
                let text = json_schema(s, link.payload).to_string();
                let id = self.schema(link.payload, "jsonschema", text.as_bytes())?;
                (id, "json")
            }
            (None, None) => (0, "json"),
        };
        let mut metadata = BTreeMap::new();
        if let (Some(_), Some(text)) = (&ros2, text) {
            metadata.insert(SHAPE_KEY.to_owned(), text.to_owned());
        }
        let value = self.channel(schema, topic, encoding, &metadata)?;
        Ok((value, ros2.is_some()))
    }

    /// The channels the derives add for link `k`: (the derive, its channel).
    fn derived_channels(
        &mut self,
        k: usize,
        link: &LinkInfo,
        derives: &mut [Box<dyn Derive>],
    ) -> Result<Vec<(usize, u16)>, RecordError> {
        let mut derived = Vec::new();
        for (d, derive) in derives.iter_mut().enumerate() {
            if let Some(c) = derive.channel(k, link) {
                let schema = self.schema(&c.schema_name, &c.schema_encoding, &c.schema)?;
                let id = self.channel(schema, &c.topic, &c.message_encoding, &BTreeMap::new())?;
                derived.push((d, id));
            }
        }
        Ok(derived)
    }

    /// Each node's `/fsm/<node>` channel (and their schema).
    fn fsm_channels(&mut self, info: &SystemInfo) -> Result<Vec<u16>, RecordError> {
        let fsm_schema = self.schema(
            "embodied.Transition",
            "jsonschema",
            TRANSITION_SCHEMA.as_bytes(),
        )?;
        let none = BTreeMap::new();
        let mut fsm = Vec::with_capacity(info.nodes.len());
        for node in &info.nodes {
            fsm.push(self.channel(fsm_schema, &format!("/fsm/{}", node.name), "json", &none)?);
        }
        Ok(fsm)
    }

    /// The `/errors` channel (and its schema).
    fn error_channel(&mut self) -> Result<u16, RecordError> {
        let error_schema = self.schema("embodied.Error", "jsonschema", ERROR_SCHEMA.as_bytes())?;
        self.channel(error_schema, "/errors", "json", &BTreeMap::new())
    }

    /// The metadata records.
    fn metadata(
        &mut self,
        metadata: BTreeMap<String, BTreeMap<String, String>>,
    ) -> Result<(), RecordError> {
        for (name, entries) in metadata {
            self.w
                .write_metadata(&mcap::records::Metadata {
                    name,
                    metadata: entries,
                })
                .map_err(|e| write_failed(self.path, &e))?;
        }
        Ok(())
    }
}

/// The system's nodes, behaviours and links, for the metadata record.
pub(super) fn describe(info: &SystemInfo) -> BTreeMap<String, String> {
    let mut m = BTreeMap::new();
    for n in &info.nodes {
        m.insert(
            format!("node/{}", n.name),
            format!(
                "agent {}, {:?}, period {}, behaviours [{}]",
                n.agent,
                n.kind,
                n.period,
                n.behaviours.join(", ")
            ),
        );
    }
    for (k, l) in info.links.iter().enumerate() {
        m.insert(
            format!("link/{k}"),
            format!("{} ({:?}, {})", l.name, l.policy, l.payload),
        );
    }
    m
}

pub(super) const TRANSITION_SCHEMA: &str = r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"embodied.Transition","type":"object","properties":{"time_s":{"type":"number"},"iteration":{"type":"integer"},"from":{"type":"string"},"to":{"type":"string"},"arc":{"type":"integer"},"condition":{"type":"string"},"predicates":{"type":"object","additionalProperties":{"type":"boolean"}},"finished":{"type":"boolean"}}}"#;

pub(super) const ERROR_SCHEMA: &str = r#"{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"embodied.Error","type":"object","properties":{"time_s":{"type":"number"},"message":{"type":"string"}},"required":["time_s","message"]}"#;
