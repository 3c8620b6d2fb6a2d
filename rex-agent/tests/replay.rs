//! Replay (`embodied::replay`) on Rex: every subsystem of a recorded mission,
//! rebuilt from the code and fed its recorded inputs, does what the recording
//! says bit for bit; a changed gain or arc condition diverges exactly where a
//! whole run with the change first differs; a damaged file is an error naming
//! the offset, never a panic.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::path::{Path, PathBuf};
use std::time::Duration;

use embodied::Executor;
use embodied::WireHeader;
use embodied::record::{McapRecorder, ReadError, Recording};
use embodied::replay::{Difference, ReplayOptions, Replayed, replay, replay_file};
use proptest::prelude::*;
use rex_agent::mission::Mission;
use rex_agent::payload::StereoPair;
use rex_agent::system::{RexConfig, build};
use rex_agent::world::WorldConfig;

/// e11's estimates to c1.
const ESTIMATES: &str = "e11.c1.q_est -> c1.e11.q_est";

fn config(vo: bool) -> RexConfig {
    let mut c = RexConfig::new(
        WorldConfig::shipped().unwrap(),
        Mission::shipped("figure_eight").unwrap(),
    );
    c.visual_odometry = vo;
    c
}

fn tmp(name: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join(name)
}

/// Run `config` for `seconds` in the deterministic executor, recorded to `name`.
fn record(config: &RexConfig, seconds: u64, name: &str) -> PathBuf {
    let path = tmp(name);
    let (system, _) = build(config).unwrap();
    let options = rex_agent::record::options();
    let recorder = McapRecorder::create(&path, &system, options).unwrap();
    let mut exec = Executor::with_observer(system, config.exec, recorder);
    exec.run_for(Duration::from_secs(seconds)).unwrap();
    let summary = exec.into_observer().finish().unwrap();
    assert_eq!(summary.undecodable, 0);
    path
}

fn replayed(config: &RexConfig, path: &Path, node: &str) -> Replayed {
    let (system, _) = build(config).unwrap();
    replay_file(
        path,
        system,
        node,
        rex_agent::record::replay_options(config.exec),
    )
    .unwrap()
}

/// Every subsystem of Rex with VO replays `path` equivalent, with the
/// recorded iteration counts (`end`: the recording's `end` metadata).
fn every_subsystem_replays_equivalent(
    vo: &RexConfig,
    path: &Path,
    end: &std::collections::BTreeMap<String, String>,
) {
    for node in ["c1", "e11", "r11", "c2", "c3", "r31"] {
        let r = replayed(vo, path, node);
        let Replayed::Equivalent {
            iterations,
            transfers,
            ..
        } = r
        else {
            panic!("{node}: {r}");
        };
        assert_eq!(
            iterations.to_string(),
            end[&format!("iterations/{node}")],
            "{node}"
        );
        assert!(iterations > 0 && transfers > 0, "{node}: {r}");
    }
}

#[test]
fn every_subsystem_of_a_recorded_mission_replays_equivalent() {
    // With visual odometry (the camera's pairs, r11), a few seconds.
    let vo = config(true);
    let path = record(&vo, 4, "replay_vo.mcap");
    let recording = Recording::open(&path).unwrap();
    let end = &recording.metadata["end"];
    // The camera's left images, for Foxglove: ROS 2's CompressedImage in CDR,
    // a PNG of the camera's size (the Python test decodes them independently).
    let camera = recording.channel("/camera/left").unwrap();
    assert_eq!(
        camera.schema.as_deref(),
        Some("sensor_msgs/msg/CompressedImage")
    );
    assert_eq!(camera.message_encoding, "cdr");
    let images: Vec<_> = recording
        .messages
        .iter()
        .filter(|m| m.channel == camera.id)
        .collect();
    assert!(images.len() >= 10, "{}", images.len());
    // After the header, the stamp and the frame (`camera_left`): the format
    // (`png`) at 28, the data's length at 36, the data.
    let cdr = &images[0].data;
    assert_eq!(&cdr[32..36], b"png\0");
    let len = u32::from_le_bytes(cdr[36..40].try_into().unwrap()) as usize;
    let png_bytes = &cdr[40..];
    assert_eq!(png_bytes.len(), len);
    let mut decoder = png::Decoder::new(std::io::Cursor::new(png_bytes))
        .read_info()
        .unwrap();
    let mut left = vec![0; decoder.output_buffer_size()];
    decoder.next_frame(&mut left).unwrap();
    assert_eq!(
        decoder.info().size(),
        (vo.world.camera.width, vo.world.camera.height)
    );
    // The pairs' raw channel: through the PNG codec (every pair as two PNGs),
    // decoded to the pair the camera sent, whose left image Foxglove's is.
    let raw = recording
        .raw_channel("R1.r11.img_lr -> r11.R1.img_lr")
        .unwrap();
    assert_eq!(raw.metadata["codec"], "rex.stereo-png/1");
    let pairs: Vec<_> = recording
        .messages
        .iter()
        .filter(|m| m.channel == raw.id)
        .flat_map(|m| embodied::record::raw_values(&raw.message_encoding, &m.data))
        .map(Result::unwrap)
        .collect();
    assert_eq!(pairs.len(), images.len());
    let codec = rex_agent::record::StereoPng;
    for m in &pairs {
        let (_, encoded) = WireHeader::read(m).unwrap();
        assert_eq!(encoded[0], 1, "the PNG form");
    }
    let (_, encoded) = WireHeader::read(pairs[0]).unwrap();
    let mut body = Vec::new();
    embodied::record::Codec::decode(&codec, encoded, &mut body).unwrap();
    let pair: StereoPair = postcard::from_bytes(&body).unwrap();
    assert_eq!(pair.left, left);
    assert_eq!(pair.right.len(), left.len());
    // A replay not given the codec refuses, naming it.
    let (system, _) = build(&vo).unwrap();
    let err = replay_file(&path, system, "r11", ReplayOptions::default()).unwrap_err();
    assert!(
        err.to_string().contains("codec `rex.stereo-png/1`"),
        "{err}"
    );
    every_subsystem_replays_equivalent(&vo, &path, end);
    // The whole mission without visual odometry: every plan, every switch.
    let no_vo = config(false);
    let path = record(&no_vo, 60, "replay_mission.mcap");
    for node in ["c1", "e11", "c2", "c3", "r31"] {
        let r = replayed(&no_vo, &path, node);
        assert!(r.is_equivalent(), "{node}: {r}");
    }
    let Replayed::Equivalent { switches, .. } = replayed(&no_vo, &path, "c1") else {
        unreachable!()
    };
    // Two plans: B1 -> B2 -> B3 -> B1 twice, and B2 once more at least.
    assert!(switches >= 6, "{switches}");
}

/// Where two recordings of runs of the same system first differ in what
/// `node` sends or how it switches: the instant in ns, and the links (or
/// `/fsm/node`) that differ then.
fn first_difference(a: &Path, b: &Path, node: &str) -> Option<(u64, Vec<String>)> {
    let keep = |c: &embodied::record::read::ChannelInfo| {
        c.topic == format!("/fsm/{node}")
            || c.metadata
                .get("link")
                .is_some_and(|l| l.starts_with(&format!("{node}.")))
    };
    let (a, b) = (
        Recording::open_filtered(a, keep).unwrap(),
        Recording::open_filtered(b, keep).unwrap(),
    );
    let name = |r: &Recording, c: u16| {
        let c = &r.channels[&c];
        c.metadata.get("link").cloned().unwrap_or(c.topic.clone())
    };
    let mut first: Option<(u64, Vec<String>)> = None;
    let topics: Vec<String> = a.channels.values().map(|c| c.topic.clone()).collect();
    for topic in topics {
        let (Some(ca), Some(cb)) = (a.channel(&topic), b.channel(&topic)) else {
            continue;
        };
        // Each record: its instant and bytes (a raw message's values one by one).
        let records = |r: &Recording, c: &embodied::record::read::ChannelInfo| {
            let mut out: Vec<(u64, Vec<u8>)> = Vec::new();
            for m in r.messages.iter().filter(|m| m.channel == c.id) {
                if c.topic.starts_with("/raw/") {
                    for v in embodied::record::raw_values(&c.message_encoding, &m.data) {
                        let v = v.unwrap();
                        let (header, _) = WireHeader::read(v).unwrap();
                        out.push((header.stamp.time.as_nanos(), v.to_vec()));
                    }
                } else {
                    out.push((m.log_time, m.data.clone()));
                }
            }
            out
        };
        let (ma, mb) = (records(&a, ca), records(&b, cb));
        let at = ma
            .iter()
            .zip(&mb)
            .find(|(x, y)| x != y)
            .map(|(x, y)| x.0.min(y.0))
            .or_else(|| {
                (ma.len() != mb.len()).then(|| {
                    let n = ma.len().min(mb.len());
                    ma.get(n).or(mb.get(n)).map_or(u64::MAX, |m| m.0)
                })
            });
        match (at, &mut first) {
            (Some(at), Some((t, names))) if at == *t => names.push(name(&a, ca.id)),
            (Some(at), Some((t, _))) if at > *t => {}
            (Some(at), _) => first = Some((at, vec![name(&a, ca.id)])),
            (None, _) => {}
        }
    }
    first
}

fn assert_diverges_where_a_run_with_the_change_does(
    original: &Path,
    changed: &RexConfig,
    name: &str,
) -> String {
    let changed_run = record(changed, 15, name);
    let (at, what) = first_difference(original, &changed_run, "c1").expect("the change changes c1");
    let r = replayed(changed, original, "c1");
    let Replayed::Diverged(d) = &r else {
        panic!("equivalent after a change: {r}");
    };
    assert_eq!(
        d.time.as_nanos(),
        at,
        "{r} (a run with the change differs first in {what:?})"
    );
    match &d.what {
        Difference::Value { link, .. }
        | Difference::Missing { link, .. }
        | Difference::Extra { link, .. } => assert!(what.contains(link), "{r}: {what:?}"),
        Difference::Switch { .. } => assert!(what.iter().any(|w| w == "/fsm/c1"), "{r}"),
        Difference::Iterations { .. } => panic!("{r}"),
    }
    r.to_string()
}

#[test]
fn a_changed_gain_or_arc_condition_diverges_first_where_a_run_with_it_differs() {
    let original = config(false);
    let path = record(&original, 15, "replay_original.mcap");
    assert!(replayed(&original, &path, "c1").is_equivalent());

    // A gain of c1's planner: the speed that sets a fragment's duration.
    let mut slower = original.clone();
    slower.planner_settings.cruise_speed *= 0.9;
    let said = assert_diverges_where_a_run_with_the_change_does(&path, &slower, "replay_gain.mcap");
    assert!(said.contains("c1.e11.traj -> e11.c1.traj"), "{said}");
    assert!(said.contains("field states["), "{said}");

    // An arc condition of c1's FSM: B1's two arcs swapped, so a valid plan is
    // refused. The first switch differs: B1 -> B3 instead of B1 -> B2.
    let text = std::fs::read_to_string(&original.spec).unwrap();
    let swapped = text
        .replace(
            r#"(from: "B1", to: "B2", when: "plan_valid")"#,
            r#"(from: "B1", to: "B2", when: "!plan_valid")"#,
        )
        .replace(
            r#"(from: "B1", to: "B3", when: "!plan_valid")"#,
            r#"(from: "B1", to: "B3", when: "plan_valid")"#,
        );
    assert_ne!(text, swapped);
    let spec = tmp("rex_swapped_arcs.ron");
    std::fs::write(&spec, swapped).unwrap();
    let mut refusing = original.clone();
    refusing.spec = spec;
    let said =
        assert_diverges_where_a_run_with_the_change_does(&path, &refusing, "replay_arc.mcap");
    assert!(said.contains("behaviour switch"), "{said}");
    assert!(said.contains(r#""to":"B3""#), "{said}");
}

#[test]
fn a_replay_of_a_build_whose_types_or_names_differ_is_refused_clearly() {
    let c = config(false);
    let path = record(&c, 1, "replay_names.mcap");
    let (system, _) = build(&c).unwrap();
    let err = replay_file(&path, system, "c9", ReplayOptions::default()).unwrap_err();
    assert!(err.to_string().contains("no subsystem `c9`"), "{err}");
    assert!(err.to_string().contains("c1, e11"), "{err}");
    // A recording whose raw values say another type: the fingerprint differs.
    let mut recording = Recording::open(&path).unwrap();
    for c in recording.channels.values_mut() {
        if c.metadata
            .get("link")
            .is_some_and(|l| l.starts_with("c1.e11.traj"))
        {
            c.metadata
                .insert("fingerprint".into(), "0000000000000001".into());
        }
    }
    let (system, _) = build(&c).unwrap();
    let err = replay(&recording, system, "c1", ReplayOptions::default()).unwrap_err();
    assert!(err.to_string().contains("c1.e11.traj"), "{err}");
    assert!(
        err.to_string().contains("differs from the recorded one"),
        "{err}"
    );
    // A recorded value whose header is damaged: the value and its offset named.
    let mut recording = Recording::open(&path).unwrap();
    let id = recording.raw_channel(ESTIMATES).unwrap().id;
    let m = recording
        .messages
        .iter_mut()
        .find(|m| m.channel == id)
        .unwrap();
    // The first value's header, after its 4-byte length.
    m.data[4] = 9;
    let offset = m.offset;
    let (system, _) = build(&c).unwrap();
    let err = replay(&recording, system, "c1", ReplayOptions::default()).unwrap_err();
    assert!(err.to_string().contains("wire version 9"), "{err}");
    assert!(
        err.to_string().contains(&format!("offset {offset}")),
        "{err}"
    );
    // A raw message cut inside a value: the cut and the offset named.
    let mut recording = Recording::open(&path).unwrap();
    let m = recording
        .messages
        .iter_mut()
        .find(|m| m.channel == id)
        .unwrap();
    let len = m.data.len();
    m.data.truncate(len - 3);
    let offset = m.offset;
    let (system, _) = build(&c).unwrap();
    let err = replay(&recording, system, "c1", ReplayOptions::default()).unwrap_err();
    let text = err.to_string();
    assert!(text.contains("raw message: a value of"), "{err}");
    assert!(
        text.contains(&format!("of a message of {} bytes", len - 3)),
        "{err}"
    );
    assert!(text.contains(&format!("offset {offset}")), "{err}");
}

/// The reads of a recording: (reader's instant, the value's stamp) per link
/// name, decoded from its `/reads/...` channels.
fn reads(recording: &Recording) -> Vec<(String, u64, u64)> {
    let links: std::collections::BTreeMap<u16, &str> = recording
        .channels
        .values()
        .filter(|c| c.message_encoding == "embodied-read/1")
        .map(|c| (c.id, c.metadata["link"].as_str()))
        .collect();
    assert!(!links.is_empty(), "no reads channels");
    recording
        .messages
        .iter()
        .filter_map(|m| {
            let link = links.get(&m.channel)?;
            assert_eq!(m.data.len(), 16);
            let at = u64::from_le_bytes(m.data[8..].try_into().unwrap());
            Some(((*link).to_owned(), m.log_time, at))
        })
        .collect()
}

#[test]
fn the_recorded_stamps_are_the_senders() {
    let c = config(false);
    let path = record(&c, 1, "replay_stamps.mcap");
    let recording = Recording::open(&path).unwrap();
    let id = recording.raw_channel(ESTIMATES).unwrap().id;
    // e11 runs every 50 ms and sends its estimate at each iteration: the
    // stamps count its iterations and say its instants; the log time is the
    // instant.
    let encoding = &recording.channels[&id].message_encoding;
    let mut k = 0;
    for m in recording.messages.iter().filter(|m| m.channel == id) {
        for (i, value) in embodied::record::raw_values(encoding, &m.data).enumerate() {
            let (header, _) = WireHeader::read(value.unwrap()).unwrap();
            k += 1;
            assert_eq!(header.seq, k);
            // A raw message's log time is its first value's instant.
            let time = header.stamp.time.as_nanos();
            assert!(if i == 0 {
                time == m.log_time
            } else {
                time > m.log_time
            });
            assert_eq!(time, header.stamp.iteration * 50_000_000);
        }
    }
    assert!(k > 10, "{k}");
    // In the deterministic executor a node reads a value at its first
    // activation after the value's instant, never at it.
    let reads = reads(&recording);
    assert!(reads.len() > 100, "{}", reads.len());
    for (link, read_at, sent_at) in &reads {
        assert!(
            read_at > sent_at,
            "{link}: read at {read_at}, sent at {sent_at}"
        );
    }
}

#[test]
fn every_subsystem_of_a_real_time_run_replays_equivalent() {
    // On threads against the wall clock, with visual odometry, 4 s: which
    // value each activation read depends on which thread reached an instant
    // first, late wake-ups, overruns; the recording says it, the replay feeds it.
    let vo = config(true);
    let path = tmp("replay_rt.mcap");
    let options = rex_agent::record::options();
    let (_, report, summary) = rex_agent::run::run_mission_realtime_recorded(
        &vo,
        Duration::from_secs(4),
        Duration::from_secs(5),
        embodied::RtConfig::default(),
        (&path, options),
        |_| {},
    )
    .unwrap();
    assert_eq!(summary.undecodable, 0);
    assert!(summary.messages > 1000, "{summary:?}");
    let recording = Recording::open(&path).unwrap();
    assert!(recording.finished());
    let end = &recording.metadata["end"];
    let reads = reads(&recording);
    // How often a value was read at its own instant (the sender's thread ran
    // first), or even at an earlier one (the reader woke late and the sender
    // had gone on), which the deterministic executor never does: said, not
    // asserted (it is the machine's timing). The replay feeds each as read.
    let same_instant = reads.iter().filter(|(_, r, s)| r == s).count();
    let ahead = reads.iter().filter(|(_, r, s)| r < s).count();
    eprintln!(
        "{} reads, {same_instant} at the value's own instant, {ahead} of a value newer than the reader's instant; overruns {}",
        reads.len(),
        report.nodes.iter().map(|n| n.overruns).sum::<u64>()
    );
    every_subsystem_replays_equivalent(&vo, &path, end);
}

fn small_recording() -> &'static (PathBuf, Vec<u8>) {
    static FILE: std::sync::OnceLock<(PathBuf, Vec<u8>)> = std::sync::OnceLock::new();
    FILE.get_or_init(|| {
        let path = record(&config(false), 2, "replay_small.mcap");
        let bytes = std::fs::read(&path).unwrap();
        (path, bytes)
    })
}

#[test]
fn the_small_recording_reads_whole() {
    let (path, bytes) = small_recording();
    let r = Recording::parse(path, bytes, |_| true).unwrap();
    assert!(r.finished());
    assert!(r.messages.len() > 1000, "{}", r.messages.len());
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// A file cut anywhere is an error that names an offset at or before the
    /// cut; never a panic, never a silently shorter recording.
    #[test]
    fn a_truncated_recording_is_an_error_naming_the_offset(cut in 0.0f64..1.0) {
        let (path, bytes) = small_recording();
        let at = ((bytes.len() - 1) as f64 * cut) as usize;
        match Recording::parse(path, &bytes[..at], |_| true) {
            Err(ReadError::Truncated { offset, .. }) => prop_assert!(offset as usize <= at),
            Err(ReadError::NotMcap { .. }) => prop_assert!(at < 8),
            other => prop_assert!(false, "cut at {}: {:?}", at, other.map(|r| r.messages.len())),
        }
    }

    /// A byte changed anywhere: an error naming an offset inside the file, or
    /// (a byte no reader checks: an index, padding) a reading; never a panic.
    /// A change inside a chunk is always found (its CRC). The offset named is
    /// not always at or before the damage: a record length made shorter is
    /// only found where the records after it no longer frame.
    #[test]
    fn a_corrupted_recording_is_an_error_naming_the_offset_or_reads(
        at in 0.0f64..1.0,
        flip in 1u8..=255,
    ) {
        let (path, bytes) = small_recording();
        let at = ((bytes.len() - 1) as f64 * at) as usize;
        let mut damaged = bytes.clone();
        damaged[at] ^= flip;
        match Recording::parse(path, &damaged, |_| true) {
            Err(ReadError::Corrupt { offset, message, .. }) => {
                prop_assert!((offset as usize) < damaged.len(), "{} (damage at {}): {}", offset, at, message);
                let said = ReadError::Corrupt { path: path.clone(), offset, message }.to_string();
                let named = said.contains(&format!("offset {offset}"));
                prop_assert!(named, "{}", said);
            }
            Err(ReadError::Truncated { offset, .. }) => {
                prop_assert!((offset as usize) <= damaged.len());
            }
            Err(ReadError::NotMcap { .. }) => prop_assert!(at < 8),
            Err(e) => prop_assert!(false, "{}", e),
            Ok(r) => {
                // The messages read are the file's: a damaged byte in a chunk
                // would have been found.
                let whole = Recording::parse(path, bytes, |_| true).unwrap();
                prop_assert_eq!(r.messages, whole.messages);
            }
        }
    }
}
