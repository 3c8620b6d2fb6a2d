//! `embodied merge`: the recordings of the processes of one run made one.
//!
//! Two recorders split one run of the tank example as two processes would
//! record it (each the nodes of one agent: what they did, sent and read); the
//! merged file holds every message of both in time order, as many as one
//! recorder of the whole run wrote, and every subsystem replays equivalent
//! from it. Files of another system, or unreadable, are refused clearly.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

#[path = "common/tank_run.rs"]
mod tank_run;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use embodied::record::{McapRecorder, RecordOptions, Recording};
use embodied::replay::{ReplayOptions, Replayed, replay_file};
use embodied::trace::{ActionEvent, ErasedPayload, ReadEvent, TransferEvent, TransitionEvent};
use embodied::*;

use tank_run::{subsystems, system, tmp};

/// Each event to the recorder of the process that runs the node it is about.
struct Split {
    owner: Vec<usize>,
    from: Vec<usize>,
    to: Vec<usize>,
    parts: Vec<McapRecorder>,
}

impl Observer for Split {
    fn transition(&mut self, e: &TransitionEvent) {
        self.parts[self.owner[e.node]].transition(e);
    }
    fn action(&mut self, e: &ActionEvent) {
        self.parts[self.owner[e.node]].action(e);
    }
    fn transfer(&mut self, e: &TransferEvent, value: &dyn ErasedPayload) {
        self.parts[self.from[e.link]].transfer(e, value);
    }
    fn read(&mut self, e: &ReadEvent) {
        self.parts[self.to[e.link]].read(e);
    }
}

/// The run recorded whole to `whole.mcap`, and split by agent into
/// `station.mcap` and `operator.mcap`.
fn run<O: Observer>(observer: O) -> O {
    let mut exec = Executor::with_observer(system(), ExecConfig::default(), observer);
    exec.run_for(Duration::from_secs(20)).unwrap();
    exec.into_observer()
}

/// As [`record`], the files' names starting with `prefix` and each part's
/// `process` record naming launch `launch`.
fn record_launch(prefix: &str, launch: &str) -> (PathBuf, Vec<PathBuf>) {
    let whole = tmp(&format!("{prefix}whole.mcap"));
    let s = system();
    let recorder = McapRecorder::create(&whole, &s, RecordOptions::default()).unwrap();
    run(recorder).finish().unwrap();

    let info = s.info().clone();
    let agents = ["station", "operator"];
    let owner: Vec<usize> = info
        .nodes
        .iter()
        .map(|n| agents.iter().position(|a| *a == n.agent).unwrap())
        .collect();
    let paths: Vec<PathBuf> = agents
        .iter()
        .map(|a| tmp(&format!("{prefix}{a}.mcap")))
        .collect();
    let parts = agents
        .iter()
        .zip(&paths)
        .map(|(a, p)| {
            let mut options = RecordOptions::default();
            options.metadata.insert(
                "process".into(),
                [
                    ("name".to_owned(), (*a).to_owned()),
                    ("launch".to_owned(), launch.to_owned()),
                ]
                .into(),
            );
            McapRecorder::create(p, &s, options).unwrap()
        })
        .collect();
    let split = Split {
        from: info.links.iter().map(|l| owner[l.from]).collect(),
        to: info.links.iter().map(|l| owner[l.to]).collect(),
        owner,
        parts,
    };
    for part in run(split).parts {
        part.finish().unwrap();
    }
    (whole, paths)
}

fn record() -> (PathBuf, Vec<PathBuf>) {
    record_launch("", "0123456789abcdef")
}

fn embodied(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_embodied"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn the_processes_recordings_merge_into_one_that_replays_as_the_whole_run() {
    let (whole, parts) = record();
    let merged = tmp("merged.mcap");
    let path = |p: &Path| p.to_str().unwrap().to_owned();
    let (code, stdout, stderr) = embodied(&[
        "merge",
        &path(&parts[0]),
        &path(&parts[1]),
        "-o",
        &path(&merged),
    ]);
    assert_eq!(code, 0, "{stdout}{stderr}");
    assert!(stdout.contains("2 files merged"), "{stdout}");

    let one = Recording::open(&whole).unwrap();
    let m = Recording::open(&merged).unwrap();
    let split: Vec<Recording> = parts.iter().map(|p| Recording::open(p).unwrap()).collect();
    // Each part holds only its own: both had something to say.
    assert!(split.iter().all(|r| !r.messages.is_empty()));
    assert_eq!(
        m.messages.len(),
        split[0].messages.len() + split[1].messages.len()
    );
    assert!(
        m.messages
            .windows(2)
            .all(|w| w[0].log_time <= w[1].log_time)
    );
    // Per channel, the same records as the whole run's recording: its
    // messages, and each raw value (which values share a raw message depends
    // on how each process batched them) with its instant.
    let per_topic = |r: &Recording| {
        let mut v: Vec<(String, u64, Vec<u8>)> = Vec::new();
        for x in &r.messages {
            let c = &r.channels[&x.channel];
            if c.topic.starts_with("/raw/") {
                for value in embodied::record::raw_values(&c.message_encoding, &x.data) {
                    let value = value.unwrap();
                    let (header, _) = WireHeader::read(value).unwrap();
                    let time = header.stamp.time.as_nanos();
                    v.push((c.topic.clone(), time, value.to_vec()));
                }
            } else {
                v.push((c.topic.clone(), x.log_time, x.data.clone()));
            }
        }
        v.sort();
        v
    };
    assert_eq!(per_topic(&m), per_topic(&one));
    // The end: as the whole run's, with the processes named; the processes'
    // own records kept apart.
    let mut end = m.metadata["end"].clone();
    assert_eq!(end.remove("processes").unwrap(), "station, operator");
    assert_eq!(end, one.metadata["end"]);
    assert_eq!(m.metadata["process/station"]["name"], "station");
    assert_eq!(m.metadata["process/operator"]["name"], "operator");
    // Every subsystem replays equivalent from the merged file.
    for node in subsystems() {
        let r = replay_file(&merged, system(), &node, ReplayOptions::default()).unwrap();
        assert!(matches!(r, Replayed::Equivalent { .. }), "{node}: {r}");
    }

    // Another system's file is refused, naming it; so is a missing file.
    let other = tmp("other.mcap");
    {
        use embodied::record::mcap;
        let mut w = mcap::Writer::new(std::io::BufWriter::new(
            std::fs::File::create(&other).unwrap(),
        ))
        .unwrap();
        w.write_metadata(&mcap::records::Metadata {
            name: "system".into(),
            metadata: [("node/x".to_owned(), "another system".to_owned())].into(),
        })
        .unwrap();
        w.finish().unwrap();
    }
    let (code, _, stderr) = embodied(&[
        "merge",
        &path(&parts[0]),
        &path(&other),
        "-o",
        &path(&merged),
    ]);
    assert_eq!(code, 1);
    assert!(stderr.contains("records another system"), "{stderr}");
    assert!(stderr.contains("other.mcap"), "{stderr}");
    let (code, _, stderr) = embodied(&["merge", "/nonexistent/run.mcap", "-o", &path(&merged)]);
    assert_eq!(code, 1);
    assert!(stderr.contains("/nonexistent/run.mcap"), "{stderr}");
}

/// A launch merges the parts it recorded and leaves out one that an earlier
/// launch left under a name of the same pattern (a restart this launch did not
/// have), saying so; a launch that recorded none of them merges nothing.
#[test]
fn a_launch_merges_its_own_parts_and_leaves_out_an_earlier_launchs() {
    let (_, earlier) = record_launch("earlier-", "launch-1");
    let (_, parts) = record_launch("later-", "launch-2");
    let merged = tmp("later-merged.mcap");
    let inputs = [parts[0].clone(), parts[1].clone(), earlier[1].clone()];
    let m = embodied::record::merge_launch(&inputs, &merged, "launch-2").unwrap();
    assert_eq!(m.files, 2);
    assert_eq!(m.left_out, vec![earlier[1].clone()]);
    let own: usize = parts
        .iter()
        .map(|p| Recording::open(p).unwrap().messages.len())
        .sum();
    let r = Recording::open(&merged).unwrap();
    assert_eq!(
        r.messages.len(),
        own,
        "the earlier launch's messages are not in"
    );
    for process in ["station", "operator"] {
        assert_eq!(
            r.metadata[&format!("process/{process}")]["launch"],
            "launch-2"
        );
    }
    // Every part's launch differs from the one asked: nothing to merge.
    let none = embodied::record::merge_launch(&inputs, &tmp("none.mcap"), "launch-3");
    assert!(
        matches!(none, Err(embodied::record::MergeError::Empty)),
        "{none:?}"
    );
    // `merge` takes every file given, as before.
    let all = embodied::record::merge(&inputs, &tmp("all.mcap")).unwrap();
    assert_eq!((all.files, all.left_out.len()), (3, 0));
}
