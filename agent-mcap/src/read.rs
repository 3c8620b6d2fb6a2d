//! Reading a recording back: [`Recording::open`] walks the file record by
//! record (the `mcap` crate parses each record and decompresses and checks each
//! chunk), so that a file cut short or damaged is an error that names the
//! offset where it goes wrong, never a panic or a silent end.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use mcap::records::Record;

/// The magic bytes that open and close an MCAP file.
const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// The largest chunk read: a chunk is a few MiB (one value more, if a
/// value is larger); a chunk that says more has a damaged size.
pub const MAX_CHUNK: u64 = 512 << 20;

/// Why a recording could not be read.
#[derive(Debug, thiserror::Error)]
pub enum ReadError {
    /// The file could not be read.
    #[error("reading {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The OS's reason.
        source: std::io::Error,
    },
    /// The file does not start as an MCAP file does.
    #[error("{path} is not an MCAP file (it does not start with MCAP's magic bytes)")]
    NotMcap {
        /// The file.
        path: PathBuf,
    },
    /// The file ends before its end: the run was cut short (the recorder did
    /// not finish), or the file was truncated.
    #[error("{path} is truncated at offset {offset}: {what}")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Where the missing part starts.
        offset: u64,
        /// What was expected there.
        what: String,
    },
    /// A record cannot be read: the file is damaged.
    #[error("{path} is corrupt at offset {offset}: {message}")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// The offset of the record that cannot be read (of its chunk, for a
        /// record inside a chunk).
        offset: u64,
        /// What is wrong.
        message: String,
    },
}

/// A channel of a recording.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChannelInfo {
    /// The channel's id in the file.
    pub id: u16,
    /// Its topic.
    pub topic: String,
    /// Its messages' encoding.
    pub message_encoding: String,
    /// Its metadata.
    pub metadata: BTreeMap<String, String>,
    /// Its schema's name, if it has one.
    pub schema: Option<String>,
    /// Its schema's id in the file ([`Recording::schemas`]; 0: none).
    pub schema_id: u16,
}

impl ChannelInfo {
    /// The payload's shape its metadata holds ([`SHAPE_KEY`](crate::record::SHAPE_KEY):
    /// a CDR value channel's, written by this crate's recorder since it
    /// records shapes); `None` without one, an error when the text does not
    /// read as a shape.
    pub fn payload_shape(&self) -> Option<Result<agent_core::TypeShape, String>> {
        let text = self.metadata.get(crate::record::SHAPE_KEY)?;
        Some(
            serde_json::from_str(text)
                .map(|(root, registry)| agent_core::TypeShape { root, registry })
                .map_err(|e| format!("its payload's shape does not read: {e}")),
        )
    }
}

/// A schema of a recording.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SchemaInfo {
    /// Its name (`foxglove.PoseInFrame`, a Rust type's path).
    pub name: String,
    /// Its encoding (`jsonschema`).
    pub encoding: String,
    /// The schema itself.
    pub data: Vec<u8>,
}

/// One message.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Message {
    /// Its channel.
    pub channel: u16,
    /// Its sequence number in the channel.
    pub sequence: u32,
    /// Its log time, in ns (the sender's instant).
    pub log_time: u64,
    /// Its publish time, in ns (the recorder writes the log time).
    pub publish_time: u64,
    /// The offset of the record in the file (of its chunk, for a message
    /// inside a chunk).
    pub offset: u64,
    /// Its bytes.
    pub data: Vec<u8>,
}

/// A recording, read: its channels, metadata and (the kept) messages, in the
/// file's order.
#[derive(Clone, Debug, Default)]
pub struct Recording {
    /// The file.
    pub path: PathBuf,
    /// The channels, by id.
    pub channels: BTreeMap<u16, ChannelInfo>,
    /// The schemas, by id.
    pub schemas: BTreeMap<u16, SchemaInfo>,
    /// The metadata records, by name.
    pub metadata: BTreeMap<String, BTreeMap<String, String>>,
    /// The messages kept, in the file's order.
    pub messages: Vec<Message>,
}

impl Recording {
    /// Read every message of the file at `path`.
    pub fn open(path: &Path) -> Result<Recording, ReadError> {
        Recording::open_filtered(path, |_| true)
    }

    /// Read the file at `path`, keeping the messages of the channels `keep`
    /// accepts (every record is still read and checked).
    pub fn open_filtered(
        path: &Path,
        keep: impl FnMut(&ChannelInfo) -> bool,
    ) -> Result<Recording, ReadError> {
        let bytes = std::fs::read(path).map_err(|source| ReadError::Io {
            path: path.to_owned(),
            source,
        })?;
        Recording::parse(path, &bytes, keep)
    }

    /// Read every message of the file at `path` up to where it was cut short,
    /// if it was (its writer killed: a file without its end, or ending inside
    /// a record): the recording up to there, and the error that says where it
    /// ends. A damaged file is still an error.
    pub fn open_salvaging(path: &Path) -> Result<(Recording, Option<ReadError>), ReadError> {
        Recording::open_salvaging_filtered(path, |_| true)
    }

    /// [`Recording::open_salvaging`], keeping the messages of the channels
    /// `keep` accepts (every record is still read and checked).
    pub fn open_salvaging_filtered(
        path: &Path,
        keep: impl FnMut(&ChannelInfo) -> bool,
    ) -> Result<(Recording, Option<ReadError>), ReadError> {
        let bytes = std::fs::read(path).map_err(|source| ReadError::Io {
            path: path.to_owned(),
            source,
        })?;
        let mut salvaged = None;
        let r = Recording::parse_with(path, &bytes, keep, Some(&mut salvaged))?;
        Ok((r, salvaged))
    }

    /// Read a file's bytes (`path` names it in errors).
    pub fn parse(
        path: &Path,
        bytes: &[u8],
        keep: impl FnMut(&ChannelInfo) -> bool,
    ) -> Result<Recording, ReadError> {
        Recording::parse_with(path, bytes, keep, None)
    }

    /// [`Recording::parse`]; with `salvage`, a file cut short is what it holds
    /// up to there, and the error goes into `salvage`.
    fn parse_with(
        path: &Path,
        bytes: &[u8],
        mut keep: impl FnMut(&ChannelInfo) -> bool,
        salvage: Option<&mut Option<ReadError>>,
    ) -> Result<Recording, ReadError> {
        let mut salvage = salvage;
        let mut cut = |r: Reader<'_>, e: ReadError| -> Result<Recording, ReadError> {
            match salvage.take() {
                Some(slot) if matches!(e, ReadError::Truncated { .. }) => {
                    *slot = Some(e);
                    Ok(r.out)
                }
                _ => Err(e),
            }
        };
        let mut r = Reader {
            path,
            out: Recording {
                path: path.to_owned(),
                ..Recording::default()
            },
            kept: BTreeMap::new(),
            summary: false,
        };
        if bytes.len() < MAGIC.len() || &bytes[..MAGIC.len()] != MAGIC {
            return Err(ReadError::NotMcap {
                path: path.to_owned(),
            });
        }
        let mut offset = MAGIC.len();
        loop {
            let at = offset as u64;
            let (opcode, body) = match r.record_at(bytes, offset) {
                Ok(record) => record,
                Err(e) => return cut(r, e),
            };
            let record =
                mcap::parse_record(opcode, body).map_err(|e| r.corrupt(at, e.to_string()))?;
            offset += 9 + body.len();
            match record {
                Record::Footer(_) => {
                    r.closing_magic(bytes, offset)?;
                    return Ok(r.out);
                }
                Record::Chunk { header, data } => r.chunk(at, &header, &data, &mut keep)?,
                // The summary repeats the data section's schemas and
                // channels, and indexes it: what is read is the data.
                Record::DataEnd(_) => r.summary = true,
                _ if r.summary => {}
                other => r.take(at, other, &mut keep)?,
            }
        }
    }

    /// The channel with this topic.
    pub fn channel(&self, topic: &str) -> Option<&ChannelInfo> {
        self.channels.values().find(|c| c.topic == topic)
    }

    /// The raw channel (encoding `embodied-wire-frames/1`, or
    /// `embodied-wire/1` in earlier files) of the link named `link`
    /// (`from.port -> to.port`); [`crate::raw_values`] reads its messages.
    pub fn raw_channel(&self, link: &str) -> Option<&ChannelInfo> {
        self.channels.values().find(|c| {
            [crate::record::FRAMES_ENCODING, crate::record::WIRE_ENCODING]
                .contains(&c.message_encoding.as_str())
                && c.metadata.get("link").is_some_and(|l| l == link)
        })
    }

    /// Whether the recorder finished the file (its `end` metadata is there).
    pub fn finished(&self) -> bool {
        self.metadata
            .get("end")
            .is_some_and(|m| m.get("finished").is_some_and(|f| f == "true"))
    }
}

/// A chunk's records: its data decompressed (at most the size it declares)
/// and checked against its CRC.
fn decompress(header: &mcap::records::ChunkHeader, data: &[u8]) -> Result<Vec<u8>, String> {
    let size = usize::try_from(header.uncompressed_size).map_err(|e| e.to_string())?;
    let inner = match header.compression.as_str() {
        "" => data.to_vec(),
        "zstd" => zstd::bulk::decompress(data, size).map_err(|e| format!("zstd: {e}"))?,
        other => {
            return Err(format!(
                "compression `{other}`, which this reader does not read"
            ));
        }
    };
    if inner.len() != size {
        return Err(format!("{} bytes where the chunk says {size}", inner.len()));
    }
    if header.uncompressed_crc != 0 {
        let crc = crc32fast::hash(&inner);
        if crc != header.uncompressed_crc {
            return Err(format!(
                "CRC {crc:08x} where the chunk says {:08x}",
                header.uncompressed_crc
            ));
        }
    }
    Ok(inner)
}

/// The record at `pos` of `bytes`: its opcode and body.
fn frame(bytes: &[u8], pos: usize) -> Result<(u8, &[u8]), String> {
    let head = bytes
        .get(pos..pos + 9)
        .ok_or_else(|| "a record header cut short".to_owned())?;
    let mut len = [0u8; 8];
    len.copy_from_slice(&head[1..9]);
    let len = u64::from_le_bytes(len);
    let body = usize::try_from(len)
        .ok()
        .and_then(|l| (pos + 9).checked_add(l))
        .and_then(|end| bytes.get(pos + 9..end))
        .ok_or_else(|| format!("a record of {len} bytes, longer than what is left"))?;
    Ok((head[0], body))
}

struct Reader<'a> {
    path: &'a Path,
    out: Recording,
    kept: BTreeMap<u16, bool>,
    summary: bool,
}

impl Reader<'_> {
    fn truncated(&self, offset: u64, what: String) -> ReadError {
        ReadError::Truncated {
            path: self.path.to_owned(),
            offset,
            what,
        }
    }

    fn corrupt(&self, offset: u64, message: String) -> ReadError {
        ReadError::Corrupt {
            path: self.path.to_owned(),
            offset,
            message,
        }
    }

    /// The record at `offset` of the file: its opcode and body, or where the
    /// file ends before it does.
    fn record_at<'b>(&self, bytes: &'b [u8], offset: usize) -> Result<(u8, &'b [u8]), ReadError> {
        let at = offset as u64;
        let Some(head) = bytes.get(offset..offset + 9) else {
            return Err(self.truncated(
                at,
                if offset == bytes.len() {
                    "the file ends before its footer (the recording was not finished)".into()
                } else {
                    format!(
                        "a record header of 9 bytes, but the file ends at offset {}",
                        bytes.len()
                    )
                },
            ));
        };
        let opcode = head[0];
        let mut len = [0u8; 8];
        len.copy_from_slice(&head[1..9]);
        let len = u64::from_le_bytes(len);
        let body_start = offset + 9;
        let body_end = usize::try_from(len)
            .ok()
            .and_then(|l| body_start.checked_add(l))
            .filter(|&end| end <= bytes.len());
        let Some(body_end) = body_end else {
            return Err(self.truncated(
                at,
                format!(
                    "a record of {len} bytes, but the file ends at offset {}",
                    bytes.len()
                ),
            ));
        };
        Ok((opcode, &bytes[body_start..body_end]))
    }

    /// What follows the footer at `offset`: MCAP's closing magic bytes, and
    /// nothing more.
    fn closing_magic(&self, bytes: &[u8], offset: usize) -> Result<(), ReadError> {
        match bytes.get(offset..) {
            Some(tail) if tail == MAGIC => Ok(()),
            Some(tail) if tail.len() < MAGIC.len() => Err(self.truncated(
                offset as u64,
                "the closing magic bytes after the footer".into(),
            )),
            _ => Err(self.corrupt(
                offset as u64,
                "the footer is not followed by MCAP's closing magic bytes".into(),
            )),
        }
    }

    /// The records of the chunk at `at`, decompressed and checked, each taken
    /// as a record of the data section.
    fn chunk(
        &mut self,
        at: u64,
        header: &mcap::records::ChunkHeader,
        data: &[u8],
        keep: &mut impl FnMut(&ChannelInfo) -> bool,
    ) -> Result<(), ReadError> {
        // A damaged size must not make the reader allocate it.
        if header.uncompressed_size > MAX_CHUNK {
            return Err(self.corrupt(
                at,
                format!(
                    "a chunk that says it holds {} bytes (more than {MAX_CHUNK}: a damaged size)",
                    header.uncompressed_size
                ),
            ));
        }
        let inner = decompress(header, data)
            .map_err(|message| self.corrupt(at, format!("in the chunk: {message}")))?;
        let mut pos = 0usize;
        while pos < inner.len() {
            let (opcode, body) = frame(&inner, pos).map_err(|message| {
                self.corrupt(
                    at,
                    format!("in the chunk, at byte {pos} of its data: {message}"),
                )
            })?;
            let record = mcap::parse_record(opcode, body).map_err(|e| {
                self.corrupt(at, format!("in the chunk, at byte {pos} of its data: {e}"))
            })?;
            self.take(at, record, keep)?;
            pos += 9 + body.len();
        }
        Ok(())
    }

    fn take(
        &mut self,
        offset: u64,
        record: Record<'_>,
        keep: &mut impl FnMut(&ChannelInfo) -> bool,
    ) -> Result<(), ReadError> {
        match record {
            Record::Schema { header, data } => {
                self.out.schemas.insert(
                    header.id,
                    SchemaInfo {
                        name: header.name,
                        encoding: header.encoding,
                        data: data.into_owned(),
                    },
                );
            }
            Record::Channel(c) => {
                let info = ChannelInfo {
                    id: c.id,
                    topic: c.topic,
                    message_encoding: c.message_encoding,
                    metadata: c.metadata,
                    schema: self.out.schemas.get(&c.schema_id).map(|s| s.name.clone()),
                    schema_id: c.schema_id,
                };
                self.kept.insert(c.id, keep(&info));
                self.out.channels.insert(c.id, info);
            }
            Record::Message { header, data } => match self.kept.get(&header.channel_id) {
                Some(true) => self.out.messages.push(Message {
                    channel: header.channel_id,
                    sequence: header.sequence,
                    log_time: header.log_time,
                    publish_time: header.publish_time,
                    offset,
                    data: data.into_owned(),
                }),
                Some(false) => {}
                None => {
                    return Err(self.corrupt(
                        offset,
                        format!(
                            "a message on channel {}, which the file never declares",
                            header.channel_id
                        ),
                    ));
                }
            },
            Record::Metadata(m) => {
                self.out.metadata.insert(m.name, m.metadata);
            }
            _ => {}
        }
        Ok(())
    }
}
