//! A recording exported for ROS 2 tools: [`export_ros2`] writes an MCAP file
//! of profile `ros2` that holds the recording's ROS 2 channels only: the form
//! of a ROS 2 bag's MCAP file, which rosbags' MCAP storage reader reads whole
//! (its `AnyReader` opens bag folders, with a `metadata.yaml` beside the
//! file, which the export does not write).
//!
//! A channel is ROS 2 when its messages are CDR (`cdr`) with a `ros2msg`
//! schema: by default every buffer's values, and derived channels in a ROS 2
//! type (Rex's `/camera/left`, `sensor_msgs/msg/CompressedImage`). Each is
//! copied with its messages (log and publish times, sequence numbers and
//! bytes as recorded), in log time order. The others are left out, and said
//! ([`ExportSummary::left_out`]): JSON channels (a type without a ROS 2
//! message, the behaviour switches `/fsm/...`, `/errors`, Foxglove's JSON
//! channels), the raw copies `/raw/...` and the reads `/reads/...` (the
//! recorder's own encodings), a CDR channel without a `ros2msg` schema.
//!
//! What ROS 2 tools need that the recording does not give is made here, not in
//! the recorder (whose schemas Foxglove reads as they are):
//! - one definition per type name across the file (the recorder names each
//!   payload type's helper messages on its own, so `embodied/Item` can have
//!   two definitions, and rosbags' single type store then decodes a channel
//!   with the other's): a second definition of a name gets it with the first
//!   free number (`Item2`), and the fields that use it follow; names are made
//!   ones ROS 2 allows (package `^[a-z][a-z0-9_]*$`, message
//!   `^[A-Z][A-Za-z0-9]*$`), schema names `pkg/msg/Name`;
//! - topic names valid in ROS 2: a leading `/`, characters other than ASCII
//!   letters, digits, `_` and `/` made `_`, runs of `_` one, empty tokens
//!   gone, a token that starts with a digit given a leading `_`, a name
//!   already taken numbered (`_2`); a valid topic is kept;
//!
//! and every change is said ([`ExportSummary::renamed_types`],
//! [`ExportSummary::renamed_topics`]). The recording's metadata records are
//! kept (ROS 2 readers skip them), unless [`ExportOptions::metadata`] is off.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::read::{ChannelInfo, ReadError, Recording};

mod topics;
mod types;

/// How to export.
#[derive(Clone, Debug)]
pub struct ExportOptions {
    /// Keep the recording's metadata records (the system, the settings, the
    /// run's end). Default: yes.
    pub metadata: bool,
}

impl Default for ExportOptions {
    fn default() -> Self {
        ExportOptions { metadata: true }
    }
}

/// Why a channel was left out of an export.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LeftOutReason {
    /// Its messages are not CDR.
    #[error("its messages are `{encoding}`, not CDR")]
    NotCdr {
        /// Their encoding.
        encoding: String,
    },
    /// It is CDR without a `ros2msg` schema.
    #[error("it is CDR without a `ros2msg` schema (its schema's encoding: `{schema}`)")]
    NoRos2msg {
        /// Its schema's encoding (empty: no schema).
        schema: String,
    },
    /// Its `ros2msg` schema cannot be a ROS 2 type.
    #[error("its `ros2msg` schema cannot be read: {0}")]
    Schema(String),
}

/// A channel left out of an export, and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LeftOut {
    /// Its topic.
    pub topic: String,
    /// Why.
    pub reason: LeftOutReason,
}

/// What an export wrote, and what it changed or left out.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ExportSummary {
    /// Channels written: the recording's ROS 2 channels.
    pub channels: usize,
    /// Messages written: all of theirs.
    pub messages: u64,
    /// Messages written per topic (as written).
    pub per_topic: BTreeMap<String, u64>,
    /// Metadata records written.
    pub metadata: usize,
    /// The channels left out, with why, in the recording's order.
    pub left_out: Vec<LeftOut>,
    /// Topics renamed to valid ROS 2 names: (recorded, written).
    pub renamed_topics: Vec<(String, String)>,
    /// Message types renamed (`pkg/msg/Name`): (recorded, written).
    pub renamed_types: Vec<(String, String)>,
    /// Where the recording was cut short, if it was (its writer killed): the
    /// export holds what it holds up to there.
    pub cut_short: Option<String>,
}

/// Why a recording could not be exported.
#[derive(Debug, thiserror::Error)]
pub enum ExportError {
    /// The recording could not be read.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// The export would overwrite the recording.
    #[error("{path} is the recording itself: export to another file")]
    SameFile {
        /// The file.
        path: PathBuf,
    },
    /// The recording has no ROS 2 channel.
    #[error(
        "{path} has no ROS 2 channel (CDR with a `ros2msg` schema) among its {channels} channels: record with CDR values (the default) to export"
    )]
    NoRos2Channel {
        /// The recording.
        path: PathBuf,
        /// Its channels.
        channels: usize,
    },
    /// The export could not be written.
    #[error("writing {path}: {message}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

/// Export the recording `input` to `output` as an MCAP file of profile `ros2`
/// with its ROS 2 channels only (see the module's documentation).
pub fn export_ros2(
    input: &Path,
    output: &Path,
    options: &ExportOptions,
) -> Result<ExportSummary, ExportError> {
    if let (Ok(a), Ok(b)) = (input.canonicalize(), output.canonicalize())
        && a == b
    {
        return Err(ExportError::SameFile {
            path: output.to_owned(),
        });
    }
    let (recording, cut) =
        Recording::open_salvaging_filtered(input, |c| c.message_encoding == "cdr")?;
    let plan = Plan::of(&recording);
    if plan.kept.is_empty() {
        return Err(ExportError::NoRos2Channel {
            path: input.to_owned(),
            channels: recording.channels.len(),
        });
    }
    let file = File::create(output).map_err(|e| ExportError::Write {
        path: output.to_owned(),
        message: e.to_string(),
    })?;
    let written = write(file, &recording, &plan, output, options).inspect_err(|_| {
        // The file this made, cut short by the failure, would read as an export.
        let _ = std::fs::remove_file(output);
    })?;
    Ok(ExportSummary {
        channels: plan.kept.len(),
        messages: written.per_topic.values().sum(),
        per_topic: written.per_topic,
        metadata: written.metadata,
        left_out: plan.left_out,
        renamed_topics: plan.renamed_topics,
        renamed_types: plan.renamed_types,
        cut_short: cut.map(|e| e.to_string()),
    })
}

/// A channel kept: its topic and schema as written.
struct Kept {
    topic: String,
    schema_name: String,
    schema_text: String,
    metadata: BTreeMap<String, String>,
}

/// What an export writes: the channels kept (by their id in the recording),
/// those left out, and the names it changes.
struct Plan {
    kept: BTreeMap<u16, Kept>,
    left_out: Vec<LeftOut>,
    renamed_topics: Vec<(String, String)>,
    renamed_types: Vec<(String, String)>,
}

impl Plan {
    /// Which channels of `recording` are ROS 2, and how they are written.
    fn of(recording: &Recording) -> Plan {
        let mut left_out = Vec::new();
        let mut types = types::Types::default();
        let mut candidates: Vec<&ChannelInfo> = Vec::new();
        for c in recording.channels.values() {
            match ros2_schema(recording, c) {
                Err(reason) => left_out.push(LeftOut {
                    topic: c.topic.clone(),
                    reason,
                }),
                Ok((name, text)) => match types.take(c.schema_id, name, text) {
                    Ok(()) => candidates.push(c),
                    Err(e) => left_out.push(LeftOut {
                        topic: c.topic.clone(),
                        reason: LeftOutReason::Schema(e),
                    }),
                },
            }
        }
        let named = types.named();
        let recorded: Vec<&str> = candidates.iter().map(|c| c.topic.as_str()).collect();
        let topics = topics::ros2_topics(&recorded);
        let mut kept = BTreeMap::new();
        let mut renamed_topics = Vec::new();
        for (c, topic) in candidates.into_iter().zip(topics) {
            let Some((schema_name, schema_text)) = named.schema(c.schema_id) else {
                continue;
            };
            if topic != c.topic && !renamed_topics.iter().any(|(r, _)| *r == c.topic) {
                renamed_topics.push((c.topic.clone(), topic.clone()));
            }
            kept.insert(
                c.id,
                Kept {
                    topic,
                    schema_name,
                    schema_text,
                    metadata: c.metadata.clone(),
                },
            );
        }
        Plan {
            kept,
            left_out,
            renamed_topics,
            renamed_types: named.renamed,
        }
    }
}

/// The `ros2msg` schema of channel `c` (its name and text), or why it has
/// none.
fn ros2_schema<'r>(
    recording: &'r Recording,
    c: &ChannelInfo,
) -> Result<(&'r str, &'r str), LeftOutReason> {
    if c.message_encoding != "cdr" {
        return Err(LeftOutReason::NotCdr {
            encoding: c.message_encoding.clone(),
        });
    }
    let schema = recording.schemas.get(&c.schema_id);
    match schema {
        Some(s) if s.encoding == "ros2msg" => std::str::from_utf8(&s.data)
            .map(|text| (s.name.as_str(), text))
            .map_err(|e| LeftOutReason::Schema(format!("its text is not UTF-8: {e}"))),
        _ => Err(LeftOutReason::NoRos2msg {
            schema: schema.map(|s| s.encoding.clone()).unwrap_or_default(),
        }),
    }
}

/// What [`write`] wrote.
struct Written {
    per_topic: BTreeMap<String, u64>,
    metadata: usize,
}

/// Write the export of `recording` that `plan` says to `file`, just
/// created at `path`.
fn write(
    file: File,
    recording: &Recording,
    plan: &Plan,
    path: &Path,
    options: &ExportOptions,
) -> Result<Written, ExportError> {
    let fail = |e: &dyn std::fmt::Display| ExportError::Write {
        path: path.to_owned(),
        message: e.to_string(),
    };
    let mut w = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .profile("ros2")
        .library(concat!(
            "embodied-agents agent-mcap ",
            env!("CARGO_PKG_VERSION"),
            " (export ros2)"
        ))
        .create(BufWriter::new(file))
        .map_err(|e| fail(&e))?;
    let mut ids = BTreeMap::new();
    for (&id, k) in &plan.kept {
        let schema = w
            .add_schema(&k.schema_name, "ros2msg", k.schema_text.as_bytes())
            .map_err(|e| fail(&e))?;
        let channel = w
            .add_channel(schema, &k.topic, "cdr", &k.metadata)
            .map_err(|e| fail(&e))?;
        ids.insert(id, (channel, k.topic.as_str()));
    }
    let mut metadata = 0;
    if options.metadata {
        for (name, entries) in &recording.metadata {
            w.write_metadata(&mcap::records::Metadata {
                name: name.clone(),
                metadata: entries.clone(),
            })
            .map_err(|e| fail(&e))?;
            metadata += 1;
        }
    }
    let mut order: Vec<&crate::read::Message> = recording
        .messages
        .iter()
        .filter(|m| ids.contains_key(&m.channel))
        .collect();
    order.sort_by_key(|m| m.log_time);
    let mut per_topic: BTreeMap<String, u64> =
        ids.values().map(|(_, t)| ((*t).to_owned(), 0)).collect();
    for m in order {
        let Some(&(channel_id, topic)) = ids.get(&m.channel) else {
            continue;
        };
        let header = mcap::records::MessageHeader {
            channel_id,
            sequence: m.sequence,
            log_time: m.log_time,
            publish_time: m.publish_time,
        };
        w.write_to_known_channel(&header, &m.data)
            .map_err(|e| fail(&e))?;
        *per_topic.entry(topic.to_owned()).or_default() += 1;
    }
    crate::close::close(w).map_err(|e| fail(&e))?;
    Ok(Written {
        per_topic,
        metadata,
    })
}
