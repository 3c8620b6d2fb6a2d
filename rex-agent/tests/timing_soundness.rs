//! Soundness of the timing analysis against measurement (issue 56, "Tests and
//! figures"): Rex is run and recorded (`--no-vo`, a few seconds), in the
//! deterministic executor and in real time; every chain's data age is measured
//! from the recording and compared with the bound `embodied check --timing`
//! computes for the deployment `simulation_without_vo` (the `--no-vo` system
//! as one process), with the WCETs and release jitters (wake-up lateness)
//! measured in the same recording (real time: its `/timing` channel, times
//! [`WCET_MARGIN`]) or the declared ones (deterministic: no wall clock, no
//! `/timing` channel).
//!
//! Data age, measured: for each activation of the chain's effector (each
//! actuation), its instant minus the stamp of the receptor's value behind the
//! value it acts on, followed back hop by hop: at each hop the value the
//! reader held at its activation is the last one its `/reads` channel shows
//! taken at or before that instant, and that value's stamp is the instant of
//! the writer's activation that sent it, whose own input is followed next.
//! The bound is the analysis's worst-case data age (which adds the
//! effector's response time `R_n`: the measured age stops at the effector's
//! release). Response times: each node's largest response time as the
//! executor measured it, from the release (its wake-up lateness included) to
//! the activation's end, against the analysis's `R = J + w`.
//!
//! Each comparison prints one line, `timing_sound=1 run=.. chain=..
//! bound_ms=.. measured_max_ms=.. tightness=..` (tightness: the bound over
//! the largest measured value); run with `--nocapture` to see them.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    clippy::panic,
    clippy::indexing_slicing,
    reason = "a failing unwrap is a failing test"
)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use embodied::record::Recording;
use embodied::record::timing::{TIMING_TOPIC, measured_lateness, measured_wcets, read_timing};
use embodied::spec::timing::{
    Analysis, WCET_MARGIN, analyse, use_measured_release_jitters, use_measured_wcets,
};

/// The deployment whose placement is the `--no-vo` system in one process.
const DEPLOYMENT: &str = "simulation_without_vo";

/// The deployment of two processes (`world`, `locomotion`) without the
/// visual odometry, launched with `rex launch`.
const SPLIT: &str = "split_without_vo";

/// The program that runs Rex: `REX_BIN` if set (a release build gives
/// figures closer to the robot's), else this package's.
fn rex_bin() -> PathBuf {
    std::env::var_os("REX_BIN")
        .map_or_else(|| PathBuf::from(env!("CARGO_BIN_EXE_rex")), PathBuf::from)
}

fn spec_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../specs/rex.ron")
}

/// Run Rex for `seconds` with `extra` flags, recorded to `file`.
fn record(file: &Path, seconds: &str, extra: &[&str]) {
    let out = Command::new(rex_bin())
        .args(extra)
        .args(["--no-vo", "--quiet", "--for", seconds, "--record"])
        .arg(file)
        // Its report folder (`target/rex-report`) goes beside the recording.
        .current_dir(file.parent().expect("a folder"))
        .output()
        .expect("rex runs");
    assert!(
        file.exists(),
        "rex made no recording: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// What a real-time recording measured, per node \[ns\]: the largest
/// execution time and the largest wake-up lateness.
type Measured = (BTreeMap<String, u64>, BTreeMap<String, u64>);

/// The analysis of Rex's spec placed by `deployment`, with the WCETs and
/// release jitters `measured` (times the margin) where given, as
/// `embodied check --timing --wcet-from` takes them.
fn analysis(measured: Option<&Measured>, deployment: &str) -> Analysis {
    let text = std::fs::read_to_string(spec_path()).expect("the spec reads");
    let loaded = embodied::spec::load("rex.ron", text).expect("the spec loads");
    let mut spec = loaded.spec.clone();
    if let Some((wcets, lateness)) = measured {
        let sources = use_measured_wcets(&mut spec, wcets, WCET_MARGIN).expect("a timing section");
        let jitters = use_measured_release_jitters(&mut spec, lateness, WCET_MARGIN)
            .expect("a timing section");
        for s in sources.iter().chain(&jitters) {
            println!("{s}");
        }
    }
    analyse(&spec, None, Some(deployment)).expect("the analysis runs")
}

/// One hop's reads: (reader's instant, writer's instant of the value), in
/// time order.
type Reads = Vec<(u64, u64)>;

/// The reads of the link whose output end is `path` (`writer.group.buffer`).
fn reads(rec: &Recording, path: &str) -> Reads {
    let mut parts = path.split('.');
    let (Some(writer), Some(reader), Some(buffer)) = (parts.next(), parts.next(), parts.next())
    else {
        panic!("a chain's path entry `{path}` is writer.group.buffer");
    };
    let topic = format!("/reads/links/{writer}/{reader}/{buffer}/to/{reader}");
    let ids: Vec<u16> = rec
        .channels
        .values()
        .filter(|c| {
            c.topic == topic
                || c.topic
                    .strip_prefix(&topic)
                    .is_some_and(|rest| rest.starts_with('/'))
        })
        .map(|c| c.id)
        .collect();
    assert_eq!(ids.len(), 1, "one reads channel for `{path}` ({topic})");
    let mut out: Reads = rec
        .messages
        .iter()
        .filter(|m| m.channel == ids[0])
        .filter_map(|m| {
            let stamp = u64::from_le_bytes(m.data.get(8..16)?.try_into().ok()?);
            Some((m.log_time, stamp))
        })
        .collect();
    out.sort_unstable();
    out
}

/// The writer's instant of the value the reader held at its activation of
/// `instant`: the last one read at or before it.
fn held(reads: &Reads, instant: u64) -> Option<u64> {
    let k = reads.partition_point(|&(t, _)| t <= instant);
    k.checked_sub(1).map(|k| reads[k].1)
}

/// The instants of the writer's activations that sent on the link whose
/// output end is `path` (its value channel's log times), in order.
fn sends(rec: &Recording, path: &str) -> Vec<u64> {
    let mut parts = path.split('.');
    let (Some(writer), Some(reader), Some(buffer)) = (parts.next(), parts.next(), parts.next())
    else {
        panic!("a chain's path entry `{path}` is writer.group.buffer");
    };
    let topic = format!("/links/{writer}/{reader}/{buffer}/to/{reader}");
    let id = rec.channel(&topic).map(|c| c.id);
    let mut out: Vec<u64> = rec
        .messages
        .iter()
        .filter(|m| Some(m.channel) == id)
        .map(|m| m.log_time)
        .collect();
    out.sort_unstable();
    out.dedup();
    out
}

/// What was measured of one chain \[ns\].
#[derive(Debug, Default)]
struct Ages {
    /// The largest data age over the actuations where every writer of the
    /// chain wrote within its interval `M` (the analysis's assumption).
    largest: u64,
    /// Those actuations.
    count: u64,
    /// The largest over every actuation, writers' silences included.
    largest_any: u64,
    /// Actuations left out: a writer behind them was silent longer than `M`.
    silent: u64,
    /// Per hop, the actuations it was silent behind.
    silent_at: Vec<u64>,
}

/// The data ages of chain `path` over the effector's activations (period
/// `period_ns`, from its first read of the chain's last link to its last);
/// `intervals`: per hop, the greatest time `M` between the writer's writes
/// the analysis assumes \[ns\].
fn ages(rec: &Recording, path: &[String], intervals: &[u64], period_ns: u64) -> Ages {
    let hops: Vec<Reads> = path.iter().map(|p| reads(rec, p)).collect();
    let written: Vec<Vec<u64>> = path.iter().map(|p| sends(rec, p)).collect();
    let last_hop = hops.last().expect("a chain has hops");
    let (Some(&(first, _)), Some(&(last, _))) = (last_hop.first(), last_hop.last()) else {
        panic!("the effector never read the chain's last link");
    };
    let mut out = Ages {
        silent_at: vec![0; path.len()],
        ..Ages::default()
    };
    let mut t = first;
    while t <= last {
        // Back from the effector's activation at `t` to the receptor.
        let mut instant = Some(t);
        let mut silent = false;
        for (h, ((hop, sent), &m)) in hops.iter().zip(&written).zip(intervals).enumerate().rev() {
            let reader = instant;
            instant = instant.and_then(|i| held(hop, i));
            // The writer's next write after the value held: later than `M`
            // after it, before the reader's instant, is a silence the analysis
            // does not assume.
            if let (Some(s), Some(r)) = (instant, reader) {
                let k = sent.partition_point(|&w| w <= s);
                let next = sent.get(k).copied().unwrap_or(u64::MAX);
                if next > s + m && r > s + m {
                    silent = true;
                    out.silent_at[h] += 1;
                }
            }
        }
        if let Some(stamp) = instant {
            let age = t - stamp;
            out.largest_any = out.largest_any.max(age);
            if silent {
                out.silent += 1;
            } else {
                out.largest = out.largest.max(age);
                out.count += 1;
            }
        }
        t += period_ns;
    }
    out
}

/// Compare every chain's measured age with its bound; print the figures.
fn compare(run: &str, rec: &Recording, a: &Analysis) {
    let text = std::fs::read_to_string(spec_path()).expect("the spec reads");
    let spec = embodied::spec::load("rex.ron", text)
        .expect("the spec loads")
        .spec;
    let chains = &spec.contracts.as_ref().expect("contracts").chains;
    let mut compared = 0;
    for chain in &a.chains {
        let declared = chains
            .iter()
            .find(|c| c.name == chain.name)
            .expect("the chain is declared");
        let effector = declared
            .path
            .last()
            .and_then(|p| p.split('.').nth(1))
            .expect("an effector");
        let period = a
            .threads
            .iter()
            .find(|t| t.component == effector)
            .expect("the effector is placed")
            .period;
        let response = |c: &str| {
            a.threads
                .iter()
                .find(|t| t.component == c)
                .and_then(|t| t.response)
                .unwrap_or(0)
        };
        // Per hop, `M` = its age term minus `R_w + L`.
        let intervals: Vec<u64> = chain
            .hops
            .iter()
            .map(|h| h.age - response(&h.writer) - h.latency)
            .collect();
        assert_eq!(
            intervals.len(),
            declared.path.len(),
            "{:?}",
            chain.hops.iter().map(|h| &h.buffer).collect::<Vec<_>>()
        );
        let measured = ages(rec, &declared.path, &intervals, period);
        let count = measured.count;
        println!(
            "timing_assumption run={run} chain={} actuations_with_a_silent_writer={} per_hop={:?} largest_age_with_them_ms={:.3}",
            chain.name,
            measured.silent,
            measured.silent_at,
            measured.largest_any as f64 / 1e6
        );
        let measured = measured.largest;
        assert!(count > 100, "{run} {}: only {count} actuations", chain.name);
        let ms = |ns: u64| ns as f64 / 1e6;
        let tightness = chain.age as f64 / measured.max(1) as f64;
        println!(
            "timing_sound={} run={run} chain={} figure=data_age bound_ms={:.3} measured_max_ms={:.3} tightness={:.2} actuations={count}",
            u8::from(measured <= chain.age),
            chain.name,
            ms(chain.age),
            ms(measured),
            tightness
        );
        assert!(
            measured <= chain.age,
            "{run} {}: measured age {measured} ns above the bound {} ns",
            chain.name,
            chain.age
        );
        compared += 1;
    }
    assert!(compared > 0, "no chain analysed: {:?}", a.skipped);
    for (name, why) in &a.skipped {
        println!("timing_sound=- run={run} chain={name} not_analysed=\"{why}\"");
    }
}

#[test]
fn measured_data_ages_and_response_times_are_within_the_bounds() {
    let dir = std::env::temp_dir().join(format!("rex-timing-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("a temporary folder");

    // The deterministic executor: no wall clock, no `/timing`; declared WCETs.
    let sim = dir.join("sim.mcap");
    record(&sim, "3", &[]);
    let rec = Recording::open(&sim).expect("the simulation's recording reads");
    assert!(
        rec.channel(TIMING_TOPIC).is_none(),
        "a deterministic run records no timing statistics"
    );
    assert!(read_timing(&rec).is_err());
    let a = analysis(None, DEPLOYMENT);
    assert!(a.is_certified(), "not certified: {a}");
    compare("simulation", &rec, &a);

    // Real time, in one process and as two: the WCETs measured in the same
    // recording.
    realtime(
        "realtime",
        &dir.join("rt.mcap"),
        &["--realtime"],
        DEPLOYMENT,
        1,
    );
    realtime(
        "split",
        &dir.join("split.mcap"),
        &["launch", "--deployment", SPLIT],
        SPLIT,
        2,
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// Record a real-time run (`args`: how to start it) of `processes`
/// processes to `file`, and compare what it measured with the bounds of
/// `deployment` computed with the WCETs it measured.
fn realtime(run: &str, file: &Path, args: &[&str], deployment: &str, processes: usize) {
    record(file, "3", args);
    let rec = Recording::open(file).expect("the real-time recording reads");
    let stats = read_timing(&rec).expect("a real-time run records its timing statistics");
    assert_eq!(stats.len(), processes, "one message per process");
    let measured = (measured_wcets(&stats), measured_lateness(&stats));
    for node in ["c1", "e11", "c3", "r31", "E1"] {
        assert!(
            measured.0.contains_key(node),
            "{node} measured: {measured:?}"
        );
        assert!(measured.1.contains_key(node), "{node} woke: {measured:?}");
    }
    let a = analysis(Some(&measured), deployment);
    if !a.is_certified() {
        // A run may measure times that do not fit the periods (an unoptimised
        // build, an activation slowed by the machine): nothing is certified,
        // so there is no bound to compare with; said, not failed.
        let why: Vec<_> = a.findings.iter().map(|f| f.message.clone()).collect();
        println!(
            "timing_sound=- run={run} not_certified=\"the measured WCETs do not fit: {}\"",
            why.join("; ")
        );
        return;
    }
    compare(run, &rec, &a);
    for s in &stats {
        for n in &s.nodes {
            let Some(t) = a.threads.iter().find(|t| t.component == n.node) else {
                continue;
            };
            let bound = t.response.expect("certified: every response time bounded");
            // From the release to the activation's end, as the executor
            // measured it (lateness, reads, the nodes before it on its
            // worker, its execution); lateness plus execution in a recording
            // that lacks it.
            let measured = match n.response_max_ns {
                0 => n.lateness_max_ns + n.exec_max_ns,
                r => r,
            };
            // Drivers sharing the simulated world's thread are not modelled
            // (one delays the other on it): printed, not asserted.
            let world = n.thread == "world";
            println!(
                "timing_sound={} run={run} process={} component={} figure=response bound_ms={:.3} measured_max_ms={:.3} tightness={:.2} thread={} rt_priority={}",
                u8::from(measured <= bound),
                s.process,
                n.node,
                bound as f64 / 1e6,
                measured as f64 / 1e6,
                bound as f64 / measured.max(1) as f64,
                n.thread,
                s.rt_priority
            );
            if s.rt_priority && !world {
                assert!(
                    measured <= bound,
                    "{run}: {} (thread {}): response {measured} ns above R = {bound} ns",
                    n.node,
                    n.thread
                );
            }
        }
    }
}
