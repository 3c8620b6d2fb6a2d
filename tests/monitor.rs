//! `embodied monitor` over recordings of the tank example: contracts that
//! hold, a range seeded to break (found at the first value out of it, over
//! JSON and CDR values alike), a level sensor that stops sending (the rate and
//! freshness found at the instants the recording implies), invariants judged
//! live and over the predicates the recorder kept (the same verdicts), the
//! contracts a recording cannot show, damaged values, and the exit codes.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

#[path = "common/binary.rs"]
mod binary;
#[path = "common/recording.rs"]
mod recording;
#[path = "common/tank_run.rs"]
#[allow(dead_code, reason = "shared with the tests that replay each subsystem")]
mod tank_run;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::Duration;

use embodied::record::read::Message;
use embodied::record::{McapRecorder, RecordOptions, Recording, Values, mcap};
use embodied::spec::contracts::{
    Bound, Contracts, Freshness, Invariant, Rate, Response, ValueRange,
};
use embodied::*;

use binary::embodied;
use recording::{copy_without_messages, record};
use tank_run::{system, tmp};

/// The level filter's output, read by the station (c1) every 50 ms.
const LEVEL: &str = "/links/r1/control/level/to/c1";

/// The tank's spec with `contracts`, as RON.
fn spec_text(contracts: Contracts) -> String {
    let text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/specs/tank.ron")).unwrap();
    let mut spec = embodied::spec::load("tank.ron", text).unwrap().spec;
    spec.contracts = Some(contracts);
    embodied::spec::export::to_ron(&spec).unwrap()
}

/// Contracts the tank meets, one of each kind a recording shows.
fn kept() -> Contracts {
    Contracts {
        // r1 sends every 10 ms; c1 reads every 50 ms.
        freshness: vec![Freshness {
            input: "c1.r1.level".into(),
            max_age_ms: 20.0,
        }],
        rates: vec![Rate {
            input: "c1.r1.level".into(),
            min_hz: 50.0,
        }],
        bounds: vec![Bound {
            behaviour: "c1.fill".into(),
            max_s: Some(60.0),
            max_iterations: Some(1200),
        }],
        ranges: vec![ValueRange {
            name: "level_in_tank".into(),
            buffer: "r1.c1.level".into(),
            field: None,
            min: Some(-0.1),
            max: Some(3.0),
        }],
        responses: vec![Response {
            name: "order_acknowledged".into(),
            trigger: "c2.c1.order".into(),
            response: "c1.c2.ack".into(),
            within_s: 30.0,
        }],
        ..Contracts::default()
    }
}

/// 20 s of the tank recorded to `name` (once for all the tests), values as
/// `values`, the spec with [`kept`] in its metadata.
fn recorded_once(file: &'static OnceLock<PathBuf>, name: &str, values: Values) -> &'static Path {
    file.get_or_init(|| {
        let path = tmp(name);
        let options = RecordOptions {
            values,
            metadata: BTreeMap::from([(
                "spec".to_owned(),
                BTreeMap::from([("text".to_owned(), spec_text(kept()))]),
            )]),
            ..RecordOptions::default()
        };
        record(&path, system(), options);
        path
    })
}

/// 20 s of the tank, values as JSON, the spec with [`kept`] in its metadata.
fn recording() -> &'static Path {
    static FILE: OnceLock<PathBuf> = OnceLock::new();
    recorded_once(&FILE, "monitor_tank.mcap", Values::Json)
}

fn write(name: &str, text: &str) -> PathBuf {
    let p = tmp(name);
    std::fs::write(&p, text).unwrap();
    p
}

/// `embodied monitor` over [`recording`] with the tank's spec with
/// `contracts` (written to `name`): its exit status, output and error.
fn monitor_with(contracts: Contracts, name: &str) -> (i32, String, String) {
    let spec = write(name, &spec_text(contracts));
    embodied(&[
        "monitor",
        recording().to_str().unwrap(),
        "--spec",
        spec.to_str().unwrap(),
    ])
}

/// Each message of `topic`: (log time, data).
fn messages(file: &Path, topic: &str) -> Vec<(u64, Vec<u8>)> {
    let r = Recording::open(file).unwrap();
    let id = r.channels.values().find(|c| c.topic == topic).unwrap().id;
    r.messages
        .iter()
        .filter(|m| m.channel == id)
        .map(|m| (m.log_time, m.data.clone()))
        .collect()
}

#[test]
fn the_contracts_the_tank_keeps_pass_with_the_recorded_spec() {
    let file = recording().to_str().unwrap();
    let (code, out, err) = embodied(&["monitor", file]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(
        out.ends_with("contracts_checked=5 contracts_violated=0 contracts_not_evaluable=0\n"),
        "{out}"
    );
}

#[test]
fn a_range_seeded_to_break_is_found_at_the_first_value_out_of_it() {
    let mut c = kept();
    c.ranges[0].max = Some(0.9);
    let (code, out, err) = monitor_with(c, "monitor_range.ron");
    // The first level above 0.9, read from the recording independently.
    let levels: Vec<_> = messages(recording(), LEVEL)
        .into_iter()
        .map(|(t, d)| (t, serde_json_number(&d)))
        .collect();
    let (t, v) = *levels
        .iter()
        .find(|(_, v)| *v > 0.9)
        .expect("the mission fills above 0.9 m within 20 s");
    assert_eq!(code, 1, "{out}{err}");
    let line = out.lines().next().unwrap();
    assert_eq!(
        line,
        format!(
            "t={:.6}s subsystem=r1 contract=range:level_in_tank: value {v} outside [-0.1, 0.9]",
            t as f64 / 1e9
        )
    );
    assert!(
        out.ends_with("contracts_checked=5 contracts_violated=1 contracts_not_evaluable=0\n"),
        "{out}"
    );
}

/// A JSON number as the recorder wrote it.
fn serde_json_number(d: &[u8]) -> f64 {
    std::str::from_utf8(d).unwrap().trim().parse().unwrap()
}

/// `from` rewritten as if r1 stopped sending the level after `stop` \[ns\]:
/// its values after then dropped, and c1's reads after then of the last value
/// sent (the stamp it keeps reading).
fn stop_level_sensor(from: &Path, to: &Path, stop: u64) {
    let reads = format!("/reads{LEVEL}");
    let mut last_stamp = None;
    rewrite(
        from,
        to,
        |_, m| m.clone(),
        |topic, _, m| {
            if topic == LEVEL && m.log_time > stop {
                return None;
            }
            if topic == LEVEL {
                last_stamp = Some(m.log_time);
            }
            let mut data = m.data.clone();
            if topic == reads && m.log_time > stop {
                // The value read is the last one sent: its stamp (the sender's
                // iteration is left as it was; only the instant is read).
                data[8..16].copy_from_slice(&last_stamp.unwrap().to_le_bytes());
            }
            Some(data)
        },
    );
}

#[test]
fn a_sensor_that_stops_is_found_by_rate_and_freshness() {
    let stopped = tmp("monitor_stopped.mcap");
    stop_level_sensor(recording(), &stopped, 10_000_000_000);
    let (code, out, err) = embodied(&["monitor", stopped.to_str().unwrap()]);
    assert_eq!(code, 1, "{out}{err}");
    let last = messages(recording(), LEVEL)
        .into_iter()
        .map(|(t, _)| t)
        .filter(|&t| t <= 10_000_000_000)
        .max()
        .unwrap();
    // The rate's window (20 ms) closes empty 20 ms after the last value.
    let rate = format!(
        "t={:.6}s subsystem=c1 contract=rate:c1.r1.level: no value for 20.000 ms since t={:.6}s",
        (last + 20_000_000) as f64 / 1e9,
        last as f64 / 1e9
    );
    assert!(out.lines().any(|l| l == rate), "{rate}\n{out}");
    // The first read by c1 (every 50 ms) of a value older than 20 ms.
    let read = messages(&stopped, &format!("/reads{LEVEL}"))
        .into_iter()
        .find(|(t, _)| *t > last + 20_000_000)
        .unwrap()
        .0;
    let fresh = format!(
        "t={:.6}s subsystem=c1 contract=freshness:c1.r1.level: age {:.3} ms > 20.000 ms",
        read as f64 / 1e9,
        (read - last) as f64 / 1e6
    );
    assert!(out.lines().any(|l| l == fresh), "{fresh}\n{out}");
    // Nothing before the stop; after it, the one silence (the level never
    // comes back) and every read of the stale value.
    let lines: Vec<_> = out.lines().filter(|l| l.starts_with("t=")).collect();
    assert_eq!(lines[..2], [rate.as_str(), fresh.as_str()], "{out}");
    assert!(
        lines[2..]
            .iter()
            .all(|l| l.contains("contract=freshness:c1.r1.level: age")),
        "{out}"
    );
    let reads_after = messages(&stopped, &format!("/reads{LEVEL}"))
        .iter()
        .filter(|(t, _)| *t >= read)
        .count();
    assert_eq!(lines.len(), 1 + reads_after, "{out}");
    assert!(
        out.ends_with("contracts_checked=5 contracts_violated=2 contracts_not_evaluable=0\n"),
        "{out}"
    );
}

#[test]
fn what_a_recording_cannot_show_is_named_not_passed() {
    let mut c = kept();
    c.invariants = vec![Invariant {
        name: "order_means_valid".into(),
        subsystem: "c1".into(),
        holds: "!has_order || order_valid || !order_valid".into(),
    }];
    let (code, out, err) = monitor_with(c, "monitor_invariant.ron");
    assert_eq!(code, 0, "{out}{err}");
    // Recorded without the contracts' watch: no predicates after each
    // activation.
    assert!(
        out.contains(
            "not evaluable offline: contract=invariant:order_means_valid subsystem=c1: no \
             `/predicates/c1` channel"
        ),
        "{out}"
    );
    assert!(
        out.ends_with("contracts_checked=5 contracts_violated=0 contracts_not_evaluable=1\n"),
        "{out}"
    );
}

#[test]
fn unreadable_files_and_specs_exit_2() {
    let file = recording().to_str().unwrap();
    let (code, _, err) = embodied(&["monitor", "/nonexistent/run.mcap"]);
    assert_eq!(code, 2, "{err}");
    let not_mcap = write("monitor_not.mcap", "not a recording");
    let (code, _, err) = embodied(&["monitor", not_mcap.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("not an MCAP file"), "{err}");
    let bad = write("monitor_bad.ron", "(name: ");
    let (code, _, err) = embodied(&["monitor", file, "--spec", bad.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("does not load"), "{err}");
    let mut c = kept();
    c.bounds[0].behaviour = "c1.flying".into();
    let unknown = write("monitor_unknown.ron", &spec_text(c));
    let (code, _, err) = embodied(&["monitor", file, "--spec", unknown.to_str().unwrap()]);
    assert_eq!(code, 2, "{err}");
    assert!(err.contains("no behaviour `flying`"), "{err}");
}

/// A number field of a JSON object as the recorder writes it (`"key":1.5`).
fn json_number(text: &str, key: &str) -> f64 {
    let at = text.find(&format!("\"{key}\":")).unwrap() + key.len() + 3;
    let rest = &text[at..];
    let end = rest.find([',', '}']).unwrap();
    rest[..end].parse().unwrap()
}

#[test]
fn bounds_and_responses_seeded_to_break_are_found_at_their_deadlines() {
    let mut c = kept();
    c.bounds[0].max_s = Some(1.0);
    c.bounds[0].max_iterations = None;
    c.responses[0].within_s = 0.01;
    let (code, out, err) = monitor_with(c, "monitor_deadlines.ron");
    assert_eq!(code, 1, "{out}{err}");
    // c1's first run of `fill`, from its switches.
    let switches: Vec<String> = messages(recording(), "/fsm/c1")
        .into_iter()
        .map(|(_, d)| String::from_utf8(d).unwrap())
        .collect();
    let entered = switches
        .iter()
        .position(|s| s.contains("\"to\":\"fill\""))
        .unwrap();
    let t_in = json_number(&switches[entered], "time_s");
    // It ends at the next switch, or with the run (20 s).
    let t_out = switches
        .get(entered + 1)
        .map_or(20.0, |s| json_number(s, "time_s"));
    assert!(t_out - t_in > 1.0, "the first fill lasts over 1 s");
    let bound = format!(
        "t={:.6}s subsystem=c1 contract=bound:c1.fill: entered at t={t_in:.6}s, still running after 1.000 s",
        t_in + 1.0
    );
    assert!(out.lines().any(|l| l == bound), "{bound}\n{out}");
    // The operator's first order, unanswered 10 ms later.
    let order = messages(recording(), "/links/c2/station/order/to/c1")[0].0;
    let response = format!(
        "t={:.6}s subsystem=c1 contract=response:order_acknowledged: trigger at t={:.6}s unanswered within 0.010 s",
        (order + 10_000_000) as f64 / 1e9,
        order as f64 / 1e9
    );
    assert!(out.lines().any(|l| l == response), "{response}\n{out}");
    assert!(
        out.ends_with("contracts_checked=5 contracts_violated=2 contracts_not_evaluable=0\n"),
        "{out}"
    );
}

/// 20 s of the tank, values as CDR (the recorder's default), the spec with
/// [`kept`] in its metadata.
fn cdr_recording() -> &'static Path {
    static FILE: OnceLock<PathBuf> = OnceLock::new();
    recorded_once(&FILE, "monitor_cdr.mcap", RecordOptions::default().values)
}

#[test]
fn ranges_over_cdr_values_give_the_verdicts_of_json_values() {
    let file = cdr_recording().to_str().unwrap();
    let r = Recording::open(cdr_recording()).unwrap();
    assert_eq!(r.channel(LEVEL).unwrap().message_encoding, "cdr");
    let (code, out, err) = embodied(&["monitor", file]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(
        out.ends_with("contracts_checked=5 contracts_violated=0 contracts_not_evaluable=0\n"),
        "{out}"
    );
    // The range seeded to break: the same lines as over the JSON values.
    let mut c = kept();
    c.ranges[0].max = Some(0.9);
    let spec = write("monitor_cdr_range.ron", &spec_text(c));
    let spec = spec.to_str().unwrap();
    let (code, cdr, err) = embodied(&["monitor", file, "--spec", spec]);
    assert_eq!(code, 1, "{cdr}{err}");
    let json = recording().to_str().unwrap();
    let (_, from_json, _) = embodied(&["monitor", json, "--spec", spec]);
    assert_eq!(cdr, from_json);
    assert!(
        cdr.starts_with("t=") && cdr.contains("contract=range:level_in_tank: value "),
        "{cdr}"
    );
}

/// `from` copied to `to` with each channel's metadata and each message's
/// bytes as `edit` makes them from its channel's topic, its count in the
/// channel (from 0) and the message (`None`: the message left out).
fn rewrite(
    from: &Path,
    to: &Path,
    meta: impl Fn(&str, &BTreeMap<String, String>) -> BTreeMap<String, String>,
    mut edit: impl FnMut(&str, usize, &Message) -> Option<Vec<u8>>,
) {
    let (r, mut w, channels) = copy_without_messages(from, to, |c| {
        (c.message_encoding.clone(), meta(&c.topic, &c.metadata))
    });
    let mut counts: BTreeMap<u16, usize> = BTreeMap::new();
    for m in &r.messages {
        let count = counts.entry(m.channel).or_default();
        *count += 1;
        let Some(data) = edit(&r.channels[&m.channel].topic, *count - 1, m) else {
            continue;
        };
        let header = mcap::records::MessageHeader {
            channel_id: channels[&m.channel],
            sequence: m.sequence,
            log_time: m.log_time,
            publish_time: m.publish_time,
        };
        w.write_to_known_channel(&header, &data).unwrap();
    }
    w.finish().unwrap();
}

#[test]
fn cdr_values_without_their_shape_or_damaged_are_said_not_passed() {
    use embodied::record::record::SHAPE_KEY;
    // An older recorder's file: CDR values without the payload's shape.
    let old = tmp("monitor_cdr_shapeless.mcap");
    rewrite(
        cdr_recording(),
        &old,
        |_, m| {
            let mut m = m.clone();
            m.remove(SHAPE_KEY);
            m
        },
        |_, _, m| Some(m.data.clone()),
    );
    let (code, out, err) = embodied(&["monitor", old.to_str().unwrap()]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(
        out.contains(
            "not evaluable offline: contract=range:level_in_tank subsystem=r1: `r1.c1.level` is \
             recorded as CDR without its payload's shape"
        ),
        "{out}"
    );
    assert!(
        out.ends_with("contracts_checked=4 contracts_violated=0 contracts_not_evaluable=1\n"),
        "{out}"
    );
    // A shape that is not one.
    let garbled = tmp("monitor_cdr_garbled_shape.mcap");
    rewrite(
        cdr_recording(),
        &garbled,
        |_, m| {
            let mut m = m.clone();
            if let Some(s) = m.get_mut(SHAPE_KEY) {
                *s = "[\"F64\", {".to_owned();
            }
            m
        },
        |_, _, m| Some(m.data.clone()),
    );
    let (code, out, err) = embodied(&["monitor", garbled.to_str().unwrap()]);
    assert_eq!(code, 0, "{out}{err}");
    assert!(
        out.contains("`r1.c1.level` is recorded as CDR, and its payload's shape does not read"),
        "{out}"
    );
    // Damaged values: cut short, a foreign encapsulation, bytes after the
    // value; each an error that names the channel and the offset.
    for (name, damage) in [
        (
            "short",
            (|d: &[u8]| d[..d.len() - 3].to_vec()) as fn(&[u8]) -> Vec<u8>,
        ),
        ("big_endian", |d: &[u8]| {
            [&[0u8, 0, 0, 0][..], &d[4..]].concat()
        }),
        ("trailing", |d: &[u8]| [d, &[1, 2, 3, 4, 5][..]].concat()),
        ("empty", |_: &[u8]| Vec::new()),
    ] {
        let bad = tmp(&format!("monitor_cdr_{name}.mcap"));
        rewrite(
            cdr_recording(),
            &bad,
            |_, m| m.clone(),
            |topic, k, m| {
                Some(if topic == LEVEL && k == 7 {
                    damage(&m.data)
                } else {
                    m.data.clone()
                })
            },
        );
        let (code, out, err) = embodied(&["monitor", bad.to_str().unwrap()]);
        assert_eq!(code, 2, "{name}: {out}{err}");
        assert!(
            err.contains(&format!("{LEVEL}: message at offset"))
                && err.contains("not CDR of its payload's shape"),
            "{name}: {err}"
        );
    }
}

#[test]
fn invariants_are_judged_live_and_over_the_predicates_recorded() {
    use embodied::monitor::Monitors;
    use embodied::monitor::live::Live;
    use embodied::monitor::recording::{evaluate, needed};
    let mut c = kept();
    c.invariants = vec![
        // Kept: the orders of the tank's mission are all valid.
        Invariant {
            name: "orders_are_valid".into(),
            subsystem: "c1".into(),
            holds: "!has_order || order_valid".into(),
        },
        // Seeded to break: c1 gets an order.
        Invariant {
            name: "never_ordered".into(),
            subsystem: "c1".into(),
            holds: "!has_order".into(),
        },
    ];
    let spec = embodied::spec::load("tank.ron", spec_text(c)).unwrap().spec;
    let path = tmp("monitor_invariants.mcap");
    let s = system();
    let recorder = McapRecorder::create(&path, &s, RecordOptions::default()).unwrap();
    let live = Live::new(Monitors::new(&spec).unwrap(), &s);
    let exec = ExecConfig {
        on_error: OnError::Continue,
        ..ExecConfig::default()
    };
    let mut exec = Executor::with_observer(s, exec, (recorder, live.watch()));
    exec.run_for(Duration::from_secs(20)).unwrap();
    let (recorder, watch) = exec.into_observer();
    drop(watch);
    recorder.finish().unwrap();
    let verdicts = live.verdicts();
    assert!(verdicts.not_judged.is_empty(), "{:?}", verdicts.not_judged);
    let shown = |m: &Monitors, v: &[embodied::monitor::Violation]| -> Vec<String> {
        v.iter().map(|v| m.display(v).to_string()).collect()
    };
    let live_lines = shown(live.monitors(), &verdicts.violations);
    assert!(!live_lines.is_empty());
    assert!(
        live_lines
            .iter()
            .all(|l| l.contains("contract=invariant:never_ordered: false with has_order=true")),
        "{live_lines:#?}"
    );

    let recorded = Recording::open_filtered(&path, needed).unwrap();
    let mut monitors = Monitors::new(&spec).unwrap();
    let report = evaluate(&mut monitors, &recorded).unwrap();
    assert!(
        report.not_evaluable.is_empty(),
        "{:?}",
        report.not_evaluable
    );
    assert_eq!(shown(&monitors, &report.violations), live_lines);
    // The predicates of c1 only, those its invariants read.
    let all = Recording::open(&path).unwrap();
    let topics: Vec<&str> = all
        .channels
        .values()
        .map(|c| c.topic.as_str())
        .filter(|t| t.starts_with("/predicates/"))
        .collect();
    assert_eq!(topics, ["/predicates/c1"]);
    let first = messages(&path, "/predicates/c1")[0].1.clone();
    let first = String::from_utf8(first).unwrap();
    assert!(
        first.contains("\"predicates\":{\"has_order\":") && !first.contains("reached"),
        "{first}"
    );
}

#[test]
fn invariants_are_judged_in_each_thread_of_a_real_time_run_and_over_its_recording() {
    use embodied::monitor::Monitors;
    use embodied::monitor::live::Live;
    use embodied::monitor::recording::{evaluate, needed};
    // The invariant alone (the rates of `kept` are judged at c1's takes of
    // values sent from another thread, which a real-time run does not keep).
    let c = Contracts {
        invariants: vec![Invariant {
            name: "never_ordered".into(),
            subsystem: "c1".into(),
            holds: "!has_order".into(),
        }],
        ..Contracts::default()
    };
    let spec = embodied::spec::load("tank.ron", spec_text(c)).unwrap().spec;
    let path = tmp("monitor_invariants_rt.mcap");
    let s = system();
    let recorder = McapRecorder::create(&path, &s, RecordOptions::default()).unwrap();
    let live = Live::new(Monitors::new(&spec).unwrap(), &s);
    let config = RtConfig {
        exec: ExecConfig {
            on_error: OnError::Continue,
            ..ExecConfig::default()
        },
        ..RtConfig::default()
    };
    let mut rt = RealTime::new(s, config);
    let mut parts = recorder.threads();
    let contracts = live.clone();
    rt.observe(move |thread, nodes| Box::new((parts(thread, nodes), contracts.watch_nodes(nodes))));
    rt.start(Duration::from_millis(1500))
        .unwrap()
        .join()
        .unwrap();
    recorder.finish().unwrap();
    let verdicts = live.verdicts();
    assert!(verdicts.not_judged.is_empty(), "{:?}", verdicts.not_judged);
    let lines: Vec<String> = verdicts
        .violations
        .iter()
        .map(|v| live.monitors().display(v).to_string())
        .collect();
    assert!(!lines.is_empty(), "c1 gets its first order within 1.5 s");
    assert!(
        lines.iter().all(|l| l
            .contains("subsystem=c1 contract=invariant:never_ordered: false with has_order=true")),
        "{lines:#?}"
    );
    // The recording of the threads' predicates: the same verdicts.
    let recorded = Recording::open_filtered(&path, needed).unwrap();
    let mut monitors = Monitors::new(&spec).unwrap();
    let report = evaluate(&mut monitors, &recorded).unwrap();
    let offline: Vec<String> = report
        .violations
        .iter()
        .filter(|v| {
            monitors
                .contract(v.contract)
                .is_some_and(|c| c.name == "never_ordered")
        })
        .map(|v| monitors.display(v).to_string())
        .collect();
    assert_eq!(offline, lines);
}

/// An observer that wants every event of every link (and does nothing with
/// them): beside a watch, it makes the executor deliver everything.
struct Everything;

impl Observer for Everything {}

/// A watch that is told every event but not the executor's instants (as the
/// real-time executor tells it): it moves its clock by the events, where one
/// given the instants and only the activations it asks for moves it there.
struct Unclocked<O>(O);

impl<O: Observer> Observer for Unclocked<O> {
    fn start(&mut self, system: &trace::SystemInfo) {
        self.0.start(system);
    }
    fn transition(&mut self, event: &TransitionEvent) {
        self.0.transition(event);
    }
    fn action(&mut self, event: &ActionEvent) {
        self.0.action(event);
    }
    fn transfer(&mut self, event: &trace::TransferEvent, value: &dyn trace::ErasedPayload) {
        self.0.transfer(event, value);
    }
    fn read(&mut self, event: &trace::ReadEvent) {
        self.0.read(event);
    }
    fn held(&mut self, event: &trace::ReadEvent) {
        self.0.held(event);
    }
    fn received(&mut self, event: &trace::ReadEvent, value: &dyn trace::ErasedPayload) {
        self.0.received(event, value);
    }
    fn error(&mut self, time: Time, error: &ExecError) {
        self.0.error(time, error);
    }
    fn predicates_wanted(&self, node: usize) -> u64 {
        self.0.predicates_wanted(node)
    }
    fn predicates(&mut self, event: &ActionEvent, values: Valuation) {
        self.0.predicates(event, values);
    }
    fn raised(&mut self) -> Option<ExecError> {
        self.0.raised()
    }
}

/// What a watch is given: what it asks for, every event beside it, or
/// every event and no instant.
#[derive(Clone, Copy, PartialEq)]
enum Given {
    Asked,
    Every,
    Unclocked,
}

/// 20 s of the tank watched by `spec`'s contracts, the watch given `given`:
/// its verdicts, the executor's errors, and what it asked of each link and
/// node.
fn watched(
    spec: &embodied::spec::Spec,
    given: Given,
) -> (
    embodied::monitor::live::Verdicts,
    Vec<String>,
    Vec<trace::LinkEvents>,
    Vec<trace::NodeEvents>,
) {
    use embodied::monitor::Monitors;
    use embodied::monitor::live::Live;
    let s = system();
    let live = Live::new(Monitors::new(spec).unwrap(), &s);
    let watch = live.watch();
    let asked = (0..s.info().links.len())
        .map(|l| watch.link_events(l))
        .collect();
    let nodes = (0..s.info().nodes.len())
        .map(|n| watch.node_events(n))
        .collect();
    let config = ExecConfig {
        on_error: OnError::Continue,
        ..ExecConfig::default()
    };
    let errors = match given {
        Given::Every => run_20s(s, config, (Everything, watch)),
        Given::Unclocked => run_20s(s, config, Unclocked(watch)),
        Given::Asked => run_20s(s, config, watch),
    };
    (live.verdicts(), errors, asked, nodes)
}

/// 20 s of `system` observed by `observer`: the executor's errors.
fn run_20s<O: Observer>(system: System, config: ExecConfig, observer: O) -> Vec<String> {
    let mut exec = Executor::with_observer(system, config, observer);
    exec.run_for(Duration::from_secs(20)).unwrap();
    exec.report().errors.iter().map(|e| e.to_string()).collect()
}

#[test]
fn a_watch_given_only_the_events_it_asks_for_judges_as_one_given_every_event() {
    use embodied::monitor::live::Verdicts;
    use embodied::trace::{LinkEvents, NodeEvents};
    // Seeded to break: the level's range (checked where r1 sends it, no
    // other contract counting those sends), its freshness, the response,
    // c1's bound on `fill` (its activations there, of no other behaviour).
    let mut c = kept();
    c.rates.clear();
    c.ranges[0].max = Some(0.9);
    c.freshness[0].max_age_ms = 5.0;
    c.responses[0].within_s = 0.001;
    c.bounds[0].max_iterations = Some(10);
    let spec = embodied::spec::load("tank.ron", spec_text(c)).unwrap().spec;
    let run = |given| watched(&spec, given);
    let (asked_only, errors, asked, nodes) = run(Given::Asked);
    let (every, every_errors, _, _) = run(Given::Every);
    assert_eq!(asked_only, every);
    assert_eq!(errors, every_errors);
    // Told every event and no instant (its clock moved by the events, every
    // activation told): the same verdicts and errors.
    let (unclocked, unclocked_errors, _, _) = run(Given::Unclocked);
    assert_eq!(unclocked, every);
    assert_eq!(unclocked_errors, every_errors);
    let kinds = |v: &Verdicts| {
        let mut k: Vec<u32> = v.violations.iter().map(|v| v.contract.0).collect();
        k.sort_unstable();
        k.dedup();
        k.len()
    };
    assert_eq!(
        kinds(&every),
        4,
        "range, freshness, response and bound broken"
    );
    assert!(asked_only.raised > 0 && asked_only.undecodable == 0);
    // The watch asked for less than everything: no events of the links no
    // contract reads, r1's levels only when out of range, and their reads
    // (a freshness alone) only of a value older than its 5 ms.
    assert!(asked.contains(&LinkEvents::none()), "{asked:?}");
    assert!(
        asked.iter().any(|w| !w.transfers
            && w.out_of.len() == 1
            && !w.reads
            && w.older_than == Some(5_000_000)),
        "{asked:?}"
    );
    // Of the nodes' activations, c1's in `fill` only (its bound), with its
    // transitions; of the others, none (the clock moves at every instant).
    let s = system();
    let info = s.info();
    let c1 = info.nodes.iter().position(|n| n.name == "c1").unwrap();
    let fill = info.nodes[c1]
        .behaviours
        .iter()
        .position(|b| b == "fill")
        .unwrap();
    assert_eq!(
        nodes[c1],
        NodeEvents {
            transitions: true,
            actions: 1 << fill
        }
    );
    for (n, asked) in nodes.iter().enumerate().filter(|(n, _)| *n != c1) {
        assert_eq!(*asked, NodeEvents::none(), "{}", info.nodes[n].name);
    }
}

#[test]
fn a_rate_judged_from_the_executor_s_stamps_judges_as_one_told_every_send() {
    use embodied::monitor::Broke;
    // The level's rate alone, seeded to break: a window of 6.7 ms, r1
    // sending every 10 ms, so that each gap between its sends breaks it
    // once (a silence reported, then its end found at the next send).
    let c = Contracts {
        rates: vec![Rate {
            input: "c1.r1.level".into(),
            min_hz: 150.0,
        }],
        ..Contracts::default()
    };
    let spec = embodied::spec::load("tank.ron", spec_text(c)).unwrap().spec;
    let (asked, errors, links, _) = watched(&spec, Given::Asked);
    // The level's sends are not told: their instants are kept.
    let kept: Vec<_> = links.iter().filter(|w| w.stamps).collect();
    assert_eq!(kept.len(), 1, "{links:?}");
    assert!(!kept[0].transfers && !kept[0].reads, "{links:?}");
    let (every, every_errors, _, _) = watched(&spec, Given::Every);
    let (unclocked, unclocked_errors, _, _) = watched(&spec, Given::Unclocked);
    assert_eq!(asked, every);
    assert_eq!(errors, every_errors);
    assert_eq!(unclocked, every);
    assert_eq!(unclocked_errors, every_errors);
    // One silence a gap: 2,000 sends in 20 s.
    assert!((1_990..=2_001).contains(&asked.count), "{}", asked.count);
    for v in &asked.violations {
        match v.broke {
            Broke::Silent { since, window } => {
                assert_eq!(v.time, since.saturating_add(window), "{v:?}");
                assert!(window < Duration::from_millis(7), "{v:?}");
            }
            _ => panic!("{v:?}"),
        }
    }
}
