//! What the tests that make recordings of the tank, or rewrite them, share:
//! a run recorded, and a recording copied but for its messages, for a test to
//! write them again as it needs.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::BufWriter;
use std::path::Path;
use std::time::Duration;

use embodied::record::read::ChannelInfo;
use embodied::record::{McapRecorder, RecordOptions, Recording, mcap};
use embodied::{ExecConfig, Executor, System};

/// A writer of an MCAP file.
pub(crate) type Writer = mcap::Writer<BufWriter<File>>;

/// 20 s of `system` in the deterministic executor, recorded to `path` with
/// `options`.
pub(crate) fn record(path: &Path, system: System, options: RecordOptions) {
    let recorder = McapRecorder::create(path, &system, options).unwrap();
    let mut exec = Executor::with_observer(system, ExecConfig::default(), recorder);
    exec.run_for(Duration::from_secs(20)).unwrap();
    exec.into_observer().finish().unwrap();
}

/// The recording at `from`, and a writer of `to` that holds its schemas,
/// its channels (each with the message encoding and metadata `channel` gives
/// it) and its metadata records, in that order; with the ids of the channels
/// in `to` by their ids in `from`. Its messages are left to the caller.
pub(crate) fn copy_without_messages(
    from: &Path,
    to: &Path,
    mut channel: impl FnMut(&ChannelInfo) -> (String, BTreeMap<String, String>),
) -> (Recording, Writer, BTreeMap<u16, u16>) {
    let r = Recording::open(from).unwrap();
    let mut w = mcap::Writer::new(BufWriter::new(File::create(to).unwrap())).unwrap();
    let schemas: BTreeMap<u16, u16> = r
        .schemas
        .iter()
        .map(|(&id, s)| (id, w.add_schema(&s.name, &s.encoding, &s.data).unwrap()))
        .collect();
    let mut channels = BTreeMap::new();
    for (&id, c) in &r.channels {
        let schema = schemas.get(&c.schema_id).copied().unwrap_or(0);
        let (encoding, metadata) = channel(c);
        let new = w
            .add_channel(schema, &c.topic, &encoding, &metadata)
            .unwrap();
        channels.insert(id, new);
    }
    for (name, metadata) in &r.metadata {
        w.write_metadata(&mcap::records::Metadata {
            name: name.clone(),
            metadata: metadata.clone(),
        })
        .unwrap();
    }
    (r, w, channels)
}
