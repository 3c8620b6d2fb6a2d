//! Merging the recordings of the processes of one distributed run into one
//! file, in time order. A part cut short (its process killed) is kept up to
//! where it ends, and said ([`MergeSummary::cut_short`]).
//!
//! Each process of a deployment records what its own nodes did (the values they
//! sent, the values they read, their behaviour switches and errors) with the
//! same channels, made from the same system. [`merge`] checks that the files
//! are of one system, puts every message of every file into one file ordered
//! by log time (stable: a channel's messages keep their order), keeps each
//! channel and schema once, and merges the metadata: records equal in every
//! file once; `end` as the run's (finished if every process finished, the last
//! instant of all, each node's iterations added up: a process counts only its
//! own; each node's first and last instants); any other record that differs,
//! once per file, named `<name>/<process>` (the file's `process` record names
//! it, else its file name; a process's restart `<process>#<k>`). Each file's
//! own `end` stays as `end/<process>`, and a run with restarts says which starts
//! it holds (`restarts`). The result replays as a recording of the whole run,
//! and each start of a restarted process replays on its own.
//!
//! [`merge_launch`] merges the parts of one launch only: a part whose
//! `process` record names another launch (one an earlier launch left beside
//! the file under the same name) is left out, and said
//! ([`MergeSummary::left_out`]).

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use crate::read::{ReadError, Recording};

/// What a merge wrote.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct MergeSummary {
    /// Files merged.
    pub files: usize,
    /// Messages written.
    pub messages: u64,
    /// Channels written.
    pub channels: usize,
    /// Whether every process finished its recording.
    pub finished: bool,
    /// The parts cut short (a process killed while it recorded): each kept up
    /// to where it ends, and said here (the file and where it ends).
    pub cut_short: Vec<String>,
    /// The parts not merged because they were recorded by another launch
    /// ([`merge_launch`]; none for [`merge`]).
    pub left_out: Vec<PathBuf>,
}

/// Why files could not be merged.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    /// No file to merge.
    #[error("no recordings to merge")]
    Empty,
    /// A file could not be read.
    #[error(transparent)]
    Read(#[from] ReadError),
    /// The files are of different systems.
    #[error(
        "{file} records another system than {first} (their `system` metadata differ): recordings of one run only"
    )]
    OtherSystem {
        /// The first file.
        first: PathBuf,
        /// The file that differs.
        file: PathBuf,
    },
    /// Two files declare the same topic differently.
    #[error("{file} declares `{topic}` with another encoding or schema than {first}")]
    Channel {
        /// The topic.
        topic: String,
        /// The file where it was first seen.
        first: PathBuf,
        /// The file that differs.
        file: PathBuf,
    },
    /// The merged file could not be written.
    #[error("writing {path}: {message}")]
    Write {
        /// The file.
        path: PathBuf,
        /// What failed.
        message: String,
    },
}

/// Merge the recordings `inputs` (of the processes of one run) into `output`
/// (see the module's documentation).
pub fn merge(inputs: &[PathBuf], output: &Path) -> Result<MergeSummary, MergeError> {
    let parts = read_parts(inputs)?;
    merge_read(parts, output, Vec::new())
}

/// [`merge`] of the parts that launch `launch` recorded (the `launch` entry
/// of each part's `process` record): a part of another launch, or of none, is
/// left out and named in [`MergeSummary::left_out`]. What a launcher merges,
/// so that a part an earlier launch left under the same name (a restart that
/// this launch did not have) never joins this launch's recording.
pub fn merge_launch(
    inputs: &[PathBuf],
    output: &Path,
    launch: &str,
) -> Result<MergeSummary, MergeError> {
    let (parts, others): (Vec<_>, Vec<_>) = read_parts(inputs)?.into_iter().partition(|(f, _)| {
        let of = f.metadata.get("process").and_then(|p| p.get("launch"));
        of.is_some_and(|l| l == launch)
    });
    let left_out = others.into_iter().map(|(f, _)| f.path).collect();
    merge_read(parts, output, left_out)
}

/// Merge the parts read into `output`.
fn merge_read(
    parts: Vec<(Recording, Option<String>)>,
    output: &Path,
    left_out: Vec<PathBuf>,
) -> Result<MergeSummary, MergeError> {
    let (files, cut_short): (Vec<Recording>, Vec<Option<String>>) = parts.into_iter().unzip();
    let cut_short = cut_short.into_iter().flatten().collect();
    one_system(&files)?;
    let mut out = Merged::create(output)?;
    let ids = out.channels(&files)?;
    for (name, entries) in merged_metadata(&files) {
        out.metadata(name, entries)?;
    }
    let messages = out.messages(&files, &ids)?;
    let channels = out.channels_written();
    out.finish()?;
    Ok(MergeSummary {
        files: files.len(),
        messages,
        channels,
        finished: files.iter().all(Recording::finished),
        cut_short,
        left_out,
    })
}

/// Every part, each read up to where it ends, with what says where a part
/// cut short ends (the error that stopped its reading).
fn read_parts(inputs: &[PathBuf]) -> Result<Vec<(Recording, Option<String>)>, MergeError> {
    let mut files = Vec::with_capacity(inputs.len());
    for p in inputs {
        let (f, cut) = Recording::open_salvaging(p)?;
        files.push((f, cut.map(|e| e.to_string())));
    }
    Ok(files)
}

/// Refuses no file, and files of different systems.
fn one_system(files: &[Recording]) -> Result<(), MergeError> {
    let first = files.first().ok_or(MergeError::Empty)?;
    for f in &files[1..] {
        if f.metadata.get("system") != first.metadata.get("system") {
            return Err(MergeError::OtherSystem {
                first: first.path.clone(),
                file: f.path.clone(),
            });
        }
    }
    Ok(())
}

/// A channel as merged: its encoding, its schema (name, encoding, data) and
/// its metadata; a topic declared with another is refused.
type ChannelKey = (
    String,
    Option<(String, String, Vec<u8>)>,
    BTreeMap<String, String>,
);

/// The merged file being written.
struct Merged<'p> {
    w: mcap::Writer<BufWriter<File>>,
    path: &'p Path,
    /// Channels by topic: their key, the merged id, the file that first
    /// declared it.
    by_topic: BTreeMap<String, (ChannelKey, u16, PathBuf)>,
    /// Schemas written, by (name, encoding, data).
    schema_ids: BTreeMap<(String, String, Vec<u8>), u16>,
}

impl<'p> Merged<'p> {
    /// Create the file at `path` and start it.
    fn create(path: &'p Path) -> Result<Merged<'p>, MergeError> {
        let file = File::create(path).map_err(|e| MergeError::Write {
            path: path.to_owned(),
            message: e.to_string(),
        })?;
        let w = mcap::WriteOptions::new()
            .compression(Some(mcap::Compression::Zstd))
            .profile("")
            .library(concat!(
                "embodied-agents agent-mcap ",
                env!("CARGO_PKG_VERSION"),
                " (merge)"
            ))
            .create(BufWriter::new(file))
            .map_err(|e| write_failed(path, &e))?;
        Ok(Merged {
            w,
            path,
            by_topic: BTreeMap::new(),
            schema_ids: BTreeMap::new(),
        })
    }

    fn fail(&self, e: &mcap::McapError) -> MergeError {
        write_failed(self.path, e)
    }

    /// Every file's channels, each topic once: per file, its channel ids
    /// mapped to the merged ones.
    fn channels(&mut self, files: &[Recording]) -> Result<Vec<BTreeMap<u16, u16>>, MergeError> {
        let mut ids = Vec::with_capacity(files.len());
        for f in files {
            let mut map = BTreeMap::new();
            for c in f.channels.values() {
                let schema = f
                    .schemas
                    .get(&c.schema_id)
                    .map(|s| (s.name.clone(), s.encoding.clone(), s.data.clone()));
                let key: ChannelKey = (c.message_encoding.clone(), schema, c.metadata.clone());
                let id = match self.by_topic.get(&c.topic) {
                    Some((k, id, _)) if *k == key => *id,
                    Some((_, _, seen)) => {
                        return Err(MergeError::Channel {
                            topic: c.topic.clone(),
                            first: seen.clone(),
                            file: f.path.clone(),
                        });
                    }
                    None => self.channel(f, c, key)?,
                };
                map.insert(c.id, id);
            }
            ids.push(map);
        }
        Ok(ids)
    }

    /// A channel first seen in file `f` (and its schema, if not yet written):
    /// its merged id.
    fn channel(
        &mut self,
        f: &Recording,
        c: &crate::read::ChannelInfo,
        key: ChannelKey,
    ) -> Result<u16, MergeError> {
        let schema_id = match &key.1 {
            None => 0,
            Some(s) => match self.schema_ids.get(s) {
                Some(id) => *id,
                None => {
                    let id = self
                        .w
                        .add_schema(&s.0, &s.1, &s.2)
                        .map_err(|e| self.fail(&e))?;
                    self.schema_ids.insert(s.clone(), id);
                    id
                }
            },
        };
        let id = self
            .w
            .add_channel(schema_id, &c.topic, &c.message_encoding, &c.metadata)
            .map_err(|e| self.fail(&e))?;
        self.by_topic
            .insert(c.topic.clone(), (key, id, f.path.clone()));
        Ok(id)
    }

    /// One metadata record.
    fn metadata(
        &mut self,
        name: String,
        entries: BTreeMap<String, String>,
    ) -> Result<(), MergeError> {
        self.w
            .write_metadata(&mcap::records::Metadata {
                name,
                metadata: entries,
            })
            .map_err(|e| self.fail(&e))
    }

    /// Every file's messages, in time order (stable, so each channel keeps
    /// its order): how many.
    fn messages(
        &mut self,
        files: &[Recording],
        ids: &[BTreeMap<u16, u16>],
    ) -> Result<u64, MergeError> {
        let mut order: Vec<(u64, usize, usize)> = files
            .iter()
            .enumerate()
            .flat_map(|(i, f)| {
                f.messages
                    .iter()
                    .enumerate()
                    .map(move |(k, m)| (m.log_time, i, k))
            })
            .collect();
        order.sort_by_key(|&(t, _, _)| t);
        let mut messages = 0u64;
        for (_, i, k) in order {
            let m = &files[i].messages[k];
            let Some(&channel_id) = ids[i].get(&m.channel) else {
                continue;
            };
            self.w
                .write_to_known_channel(
                    &mcap::records::MessageHeader {
                        channel_id,
                        sequence: m.sequence,
                        log_time: m.log_time,
                        publish_time: m.log_time,
                    },
                    &m.data,
                )
                .map_err(|e| self.fail(&e))?;
            messages += 1;
        }
        Ok(messages)
    }

    /// The channels written (one per topic).
    fn channels_written(&self) -> usize {
        self.by_topic.len()
    }

    /// Close the file (its summary and index).
    fn finish(self) -> Result<(), MergeError> {
        let path = self.path;
        crate::close::close(self.w).map_err(|e| write_failed(path, &e))
    }
}

/// The MCAP writer's failure, writing the merged file at `path`.
fn write_failed(path: &Path, e: &mcap::McapError) -> MergeError {
    MergeError::Write {
        path: path.to_owned(),
        message: e.to_string(),
    }
}

/// The name of the process a file recorded, and which start of it
/// (`world`, `locomotion#1` for its first restart).
fn process_of(f: &Recording) -> String {
    let process = f.metadata.get("process");
    let name = process
        .and_then(|m| m.get("name"))
        .cloned()
        .unwrap_or_else(|| {
            f.path
                .file_stem()
                .map(|s| s.to_string_lossy().into_owned())
                .unwrap_or_default()
        });
    match process
        .and_then(|m| m.get("incarnation"))
        .filter(|k| *k != "0")
    {
        Some(k) => format!("{name}#{k}"),
        None => name,
    }
}

fn merged_metadata(files: &[Recording]) -> BTreeMap<String, BTreeMap<String, String>> {
    let mut out = BTreeMap::new();
    let names: std::collections::BTreeSet<&String> =
        files.iter().flat_map(|f| f.metadata.keys()).collect();
    for name in names {
        if name == "end" {
            continue;
        }
        let records: Vec<(&Recording, &BTreeMap<String, String>)> = files
            .iter()
            .filter_map(|f| Some((f, f.metadata.get(name)?)))
            .collect();
        if records.len() == files.len() && records.iter().all(|(_, r)| *r == records[0].1) {
            out.insert(name.clone(), records[0].1.clone());
        } else {
            for (f, r) in records {
                out.insert(format!("{name}/{}", process_of(f)), r.clone());
            }
        }
    }
    // Each part's own end, for a replay of one start of one process.
    for f in files {
        if let Some(end) = f.metadata.get("end") {
            out.insert(format!("end/{}", process_of(f)), end.clone());
        }
    }
    // The restarts, if any: which starts of which process the file holds.
    let starts: Vec<String> = files.iter().map(process_of).collect();
    if starts.iter().any(|s| s.contains('#')) {
        out.insert(
            "restarts".into(),
            BTreeMap::from([("starts".to_owned(), starts.join(", "))]),
        );
    }
    // The run's end: only if every process finished.
    if files.iter().all(Recording::finished) {
        let mut end = BTreeMap::from([("finished".to_owned(), "true".to_owned())]);
        let mut time = 0u64;
        let mut iterations: BTreeMap<String, u64> = BTreeMap::new();
        let mut lasts: BTreeMap<String, u64> = BTreeMap::new();
        let mut firsts: BTreeMap<String, u64> = BTreeMap::new();
        for f in files {
            let Some(e) = f.metadata.get("end") else {
                continue;
            };
            for (k, v) in e {
                let n = v.parse::<u64>().unwrap_or(0);
                if k == "time_ns" {
                    time = time.max(n);
                } else if k.starts_with("last/") {
                    let t = lasts.entry(k.clone()).or_default();
                    *t = (*t).max(n);
                } else if k.starts_with("first/") {
                    let t = firsts.entry(k.clone()).or_insert(n);
                    *t = (*t).min(n);
                } else if k.starts_with("iterations/") {
                    *iterations.entry(k.clone()).or_default() += n;
                }
            }
        }
        end.insert("time_ns".into(), time.to_string());
        end.extend(iterations.into_iter().map(|(k, v)| (k, v.to_string())));
        end.extend(lasts.into_iter().map(|(k, v)| (k, v.to_string())));
        end.extend(firsts.into_iter().map(|(k, v)| (k, v.to_string())));
        end.insert(
            "processes".into(),
            files.iter().map(process_of).collect::<Vec<_>>().join(", "),
        );
        out.insert("end".into(), end);
    }
    out
}
