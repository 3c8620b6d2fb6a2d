//! A recording in the raw encoding of earlier versions (`embodied-wire/1`: one
//! value a message, its log time the value's instant, its sequence the link's
//! count) replays as a recording of today does.
//!
//! The earlier file is made from today's recording of the tank example by
//! writing each value of a raw message (`embodied-wire-frames/1`) as a message
//! of its own, as the writer did before it framed them; every other record is
//! copied as it is. Every subsystem replays equivalent from both files, and a
//! change of one value in the earlier file is the first divergence, at its
//! instant.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

#[path = "common/recording.rs"]
mod recording;
#[path = "common/tank_run.rs"]
mod tank_run;

use std::collections::BTreeMap;
use std::path::Path;

use embodied::record::record::{FRAMES_ENCODING, WIRE_ENCODING};
use embodied::record::{RecordOptions, mcap};
use embodied::replay::{Difference, Recording, ReplayOptions, Replayed, replay_file};
use embodied::*;

use recording::copy_without_messages;
use tank_run::{subsystems, system, tmp};

/// 20 s of the tank example, recorded today.
fn record(path: &Path) {
    recording::record(path, system(), RecordOptions::default());
}

/// `from` written again to `to` with its raw channels in the earlier
/// encoding; `change`, if given, is applied to the body of the raw value of
/// that link's topic and count (from 1). Returns (raw values, raw messages
/// of `from`).
fn to_earlier(from: &Path, to: &Path, change: Option<(&str, u64)>) -> (usize, usize) {
    let (r, mut w, channels) = copy_without_messages(from, to, |c| {
        let encoding = if c.message_encoding == FRAMES_ENCODING {
            WIRE_ENCODING
        } else {
            c.message_encoding.as_str()
        };
        (encoding.to_owned(), c.metadata.clone())
    });
    let (mut values, mut frames) = (0, 0);
    let mut counts: BTreeMap<u16, u32> = BTreeMap::new();
    for m in &r.messages {
        let channel = &channels[&m.channel];
        let topic = &r.channels[&m.channel].topic;
        if r.channels[&m.channel].message_encoding != FRAMES_ENCODING {
            let header = mcap::records::MessageHeader {
                channel_id: *channel,
                sequence: m.sequence,
                log_time: m.log_time,
                publish_time: m.log_time,
            };
            w.write_to_known_channel(&header, &m.data).unwrap();
            continue;
        }
        frames += 1;
        for value in embodied::record::record::raw_values(FRAMES_ENCODING, &m.data) {
            let mut value = value.unwrap().to_vec();
            let (header, body) = WireHeader::read(&value).unwrap();
            let (time, seq, an_f64) = (header.stamp.time.as_nanos(), header.seq, body.len() == 8);
            if change == Some((topic.as_str(), seq)) && an_f64 {
                // The value's last byte (a little-endian f64's sign and
                // exponent: another number).
                *value.last_mut().unwrap() ^= 0x40;
            }
            let count = counts.entry(*channel).or_default();
            let header = mcap::records::MessageHeader {
                channel_id: *channel,
                sequence: *count,
                log_time: time,
                publish_time: time,
            };
            *count += 1;
            w.write_to_known_channel(&header, &value).unwrap();
            values += 1;
        }
    }
    w.finish().unwrap();
    (values, frames)
}

#[test]
fn a_recording_in_the_earlier_raw_encoding_replays_as_todays_does() {
    let (today, earlier) = (tmp("today.mcap"), tmp("earlier.mcap"));
    record(&today);
    let (values, frames) = to_earlier(&today, &earlier, None);
    // Today's file frames several values a message; the earlier one does not.
    assert!(values > 2 * frames, "{values} values in {frames} messages");
    let old = Recording::open(&earlier).unwrap();
    let raw: Vec<_> = old
        .channels
        .values()
        .filter(|c| c.topic.starts_with("/raw/"))
        .collect();
    assert!(!raw.is_empty());
    assert!(raw.iter().all(|c| c.message_encoding == WIRE_ENCODING));
    let raw_messages = old
        .messages
        .iter()
        .filter(|m| old.channels[&m.channel].topic.starts_with("/raw/"))
        .count();
    assert_eq!(raw_messages, values);

    for node in subsystems() {
        let a = replay_file(&today, system(), &node, ReplayOptions::default()).unwrap();
        let b = replay_file(&earlier, system(), &node, ReplayOptions::default()).unwrap();
        assert!(matches!(a, Replayed::Equivalent { .. }), "{node}: {a}");
        assert!(matches!(b, Replayed::Equivalent { .. }), "{node}: {b}");
        // The same iterations and transfers from either file.
        assert_eq!(a.to_string(), b.to_string(), "{node}");
    }
}

#[test]
fn a_changed_value_in_the_earlier_encoding_is_the_first_divergence() {
    let (today, earlier) = (tmp("today_changed.mcap"), tmp("earlier_changed.mcap"));
    record(&today);
    // The 50th value of each link of an `f64` (levels, flows, duties) that a
    // subsystem sends, changed in turn: the sender's replay diverges exactly
    // there (it sends another value than the file says), and no replay
    // diverges before.
    let r = Recording::open(&today).unwrap();
    let links: Vec<String> = r
        .channels
        .values()
        .filter(|c| c.topic.starts_with("/raw/") && c.message_encoding == FRAMES_ENCODING)
        .filter(|c| {
            ["/level/", "/flow/", "/duty/"]
                .iter()
                .any(|p| c.topic.contains(p))
        })
        // Sent by a subsystem (a real effector or receptor is not replayed).
        .filter(|c| {
            let from = c.topic.trim_start_matches("/raw/links/");
            subsystems()
                .iter()
                .any(|n| from.starts_with(&format!("{n}/")))
        })
        .map(|c| c.topic.clone())
        .collect();
    assert!(links.len() >= 3, "{links:?}");
    for topic in &links {
        to_earlier(&today, &earlier, Some((topic, 50)));
        let c = Recording::open(&earlier).unwrap();
        let channel = c.channels.values().find(|x| &x.topic == topic).unwrap();
        let changed = c
            .messages
            .iter()
            .filter(|m| m.channel == channel.id)
            .nth(49)
            .unwrap()
            .log_time;
        let mut at_the_change = 0;
        for node in subsystems() {
            let replayed =
                replay_file(&earlier, system(), &node, ReplayOptions::default()).unwrap();
            if let Replayed::Diverged(d) = &replayed {
                assert!(
                    d.time.as_nanos() >= changed,
                    "{topic} changed at {changed} ns, {node} diverged before: {replayed}"
                );
                if d.time.as_nanos() == changed && matches!(d.what, Difference::Value { .. }) {
                    at_the_change += 1;
                }
            }
        }
        assert_eq!(at_the_change, 1, "{topic}: the sender, at {changed} ns");
    }
}
