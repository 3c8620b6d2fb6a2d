//! Rex's contracts (specs/rex.ron) watched while it runs, through the program
//! as a user runs it: the main mission keeps every one (its invariant judged
//! after every activation of c2); seeded defects are found with their place
//! and time, handled by the error policy (Rex brakes and holds under
//! `--on-error safe-stop`), and found again, at the same instant, over the
//! run's recording (ranges read from its CDR values, invariants from the
//! predicates it recorded after each activation).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::path::{Path, PathBuf};
use std::process::Command;

use embodied::monitor::Monitors;
use embodied::monitor::recording::{evaluate, needed};
use embodied::record::Recording;

const WORLD: &str = include_str!("../config/world.ron");
const CONFIG: &str = include_str!("../config/rex.ron");
const SPEC: &str = include_str!("../../specs/rex.ron");

/// A folder of this test's own.
fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("contracts-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `rex ARGS` (no report folder): its status, standard output and error.
fn rex(args: &[&str]) -> (Option<i32>, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_rex"))
        .args(args)
        .arg("--no-report")
        .output()
        .unwrap();
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// `text` with `from` replaced by `to` (which must be there once).
fn edited(text: &str, from: &str, to: &str) -> String {
    assert_eq!(text.matches(from).count(), 1, "`{from}` once");
    text.replace(from, to)
}

fn write(dir: &Path, name: &str, text: &str) -> String {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path.display().to_string()
}

/// A run of `rex` that its policy stopped at a contract's violation.
struct Stopped {
    /// Its standard error.
    err: String,
    /// The first violation's line, without `contract violated: `.
    found: String,
    /// Its recording.
    recording: PathBuf,
}

/// `rex ARGS --config CONFIG --for 20 --record RECORDING`, with `config` (a
/// run file: the shipped one edited) written to `dir` and the recording in
/// it: a run that fails (status 1) and stops at its first contract violation
/// (Rex's policy), whose line it returns.
fn stopped_by_a_violation(dir: &Path, config: &str, args: &[&str]) -> Stopped {
    let config = write(dir, "config.ron", config);
    let recording = dir.join("run.mcap");
    let mut all = args.to_vec();
    all.extend([
        "--config",
        &config,
        "--for",
        "20",
        "--record",
        recording.to_str().unwrap(),
    ]);
    let (code, out, err) = rex(&all);
    assert_eq!(code, Some(1), "{out}\n{err}");
    let found = err
        .lines()
        .find_map(|l| l.strip_prefix("contract violated: "))
        .expect("a violation")
        .to_owned();
    assert!(out.contains("the run failed before its end"), "{out}");
    Stopped {
        err,
        found,
        recording,
    }
}

#[test]
fn the_main_mission_keeps_every_contract() {
    let (code, out, err) = rex(&["--verbose"]);
    assert_eq!(code, Some(0), "{out}\n{err}");
    assert!(
        out.contains("contracts_checked=13 contracts_violated=0 contracts_not_evaluable=0\n"),
        "{out}"
    );
    assert!(!err.contains("contract violated"), "{err}");
    // `--verbose` prints the timing certificate, as the report folder's
    // `timing.txt` has it.
    let spec = embodied::spec::load("rex.ron", SPEC).unwrap().spec;
    let analysis = embodied::spec::timing::analyse(&spec, None, None).unwrap();
    let certificate = format!(
        "# The timing analysis of `rex` as one process on one host (embodied check --timing)\n{analysis}"
    );
    assert!(out.contains(&certificate), "{out}");
    assert!(
        out.contains("mocap_to_wheels"),
        "the chains' certificates: {out}"
    );
}

#[test]
fn a_motion_capture_that_stops_is_found_and_rex_safe_stops() {
    let dir = scratch("mocap");
    // The capture's first dropout (at 0.5 s of the main mission) never ends.
    let world = write(
        &dir,
        "world.ron",
        &edited(WORLD, "dropout_length: 0.5,", "dropout_length: 1000.0,"),
    );
    let recording = dir.join("run.mcap");
    let (code, out, err) = rex(&[
        "--world",
        &world,
        "--for",
        "4",
        "--on-error",
        "safe-stop",
        "--record",
        recording.to_str().unwrap(),
    ]);
    assert_eq!(code, Some(1), "a safe-stopped run fails: {out}\n{err}");
    // The last pose came at 0.5 s: no pose for 1.25 s breaks the rate at 1.75 s
    // (the rate's window), which safe-stops the run at the next instant (every
    // subsystem halted: none judges a stale value after it).
    let found = "t=1.750000s subsystem=c1 contract=rate:c1.c3.pose: no value for 1250.000 ms since t=0.500000s";
    assert!(
        err.contains(&format!("contract violated: {found}")),
        "{err}"
    );
    assert!(
        err.contains("safe-stopped at t=1.751000s"),
        "the first violation safe-stops the run: {err}"
    );
    assert_eq!(
        err.matches("contract violated").count(),
        1,
        "the halted subsystems are judged no more: {err}"
    );
    assert!(out.contains("contracts_violated=1"), "{out}");
    assert!(
        !err.contains("contract=range:torque_wheel"),
        "no torque beyond the platform's limit, braking included: {err}"
    );

    // The same violation, at the same instant, over the recording.
    let recorded = Recording::open_filtered(&recording, needed).unwrap();
    let mut monitors = Monitors::new(&embodied::spec::load("rex.ron", SPEC).unwrap().spec).unwrap();
    let report = evaluate(&mut monitors, &recorded).unwrap();
    let lines: Vec<String> = report
        .violations
        .iter()
        .map(|v| monitors.display(v).to_string())
        .collect();
    assert_eq!(lines.first().map(String::as_str), Some(found), "{lines:#?}");

    // Reported and gone on with, the stale pose is found at c1's first
    // activation past 0.5 + 1.25 s, and e11's at its own.
    let (code, out, err) = rex(&["--world", &world, "--for", "2.5", "--on-error", "continue"]);
    assert_eq!(code, Some(1), "the mission did not complete: {out}\n{err}");
    for found in [
        "t=1.760000s subsystem=c1 contract=freshness:c1.c3.pose: age 1260.000 ms > 1250.000 ms",
        "t=1.850000s subsystem=e11 contract=freshness:e11.c1.pose: age 1340.000 ms > 1300.000 ms",
    ] {
        assert!(
            err.contains(&format!("contract violated: {found}")),
            "{err}"
        );
    }
    assert!(out.contains("contracts_violated=3"), "{out}");
}

#[test]
fn a_behaviour_that_never_ends_is_found_by_its_bound() {
    let dir = scratch("bound");
    // The operator's promise: a plan comes within 2 s, so c1 leaves B1 (waiting
    // for one) within 2 s. With no plans from a2 (`listen`) and no ROS 2,
    // none ever comes.
    let spec = write(
        &dir,
        "rex.ron",
        &edited(
            SPEC,
            r#"bounds: [(behaviour: "c1.B3", max_iterations: 1)],"#,
            r#"bounds: [(behaviour: "c1.B3", max_iterations: 1), (behaviour: "c1.B1", max_s: 2.0)],"#,
        ),
    );
    let (code, out, err) = rex(&["--spec", &spec, "--mission", "listen", "--for", "5"]);
    assert_eq!(code, Some(1), "{out}\n{err}");
    assert!(
        err.contains(
            "t=2.000000s subsystem=c1 contract=bound:c1.B1: entered at t=0.000000s, still running after 2.000 s"
        ),
        "{err}"
    );
    // Rex's policy is to stop at the first error: the run ended there.
    assert!(out.contains("the run failed before its end"), "{out}");
    assert!(out.contains("contracts_violated=1"), "{out}");
}

#[test]
fn a_torque_bound_raised_past_the_platform_limit_is_found_by_the_ranges() {
    let dir = scratch("torque");
    write(&dir, "world.ron", WORLD);
    // The changed gain: e11's NMPC may ask twice the traction of the ground,
    // up to 20 N m a wheel (the platform's limit, and the contracts', is 10).
    // Tracking is smooth well within 10 N m; a stop at speed (the tracking
    // limit tightened to 3 cm) brakes with all the bound allows.
    let mut config = edited(CONFIG, "traction_margin: 0.85,", "traction_margin: 2.0,");
    config = edited(&config, "torque_nm: None,", "torque_nm: Some(20.0),");
    config = edited(&config, "tracking_m: 0.30,", "tracking_m: 0.03,");
    // Rex's policy stops the run at the first error: the first torque beyond
    // 10 N m, with its time and value.
    let Stopped {
        err,
        found,
        recording,
    } = stopped_by_a_violation(&dir, &config, &[]);
    assert!(
        found.starts_with("t=12.950000s subsystem=e11 contract=range:torque_wheel_"),
        "{err}"
    );
    let value: f64 = found
        .split("value ")
        .nth(1)
        .and_then(|v| v.split(' ').next())
        .and_then(|v| v.parse().ok())
        .expect("the value");
    assert!(value.abs() > 10.0 && value.abs() <= 20.0, "{found}");
    assert!(found.ends_with("outside [-10, 10]"), "{found}");

    // The same violation, at the same instant, over the recording: Rex
    // records its values as CDR, read back by the payload's shape.
    let recorded = Recording::open_filtered(&recording, needed).unwrap();
    let mut monitors = Monitors::new(&embodied::spec::load("rex.ron", SPEC).unwrap().spec).unwrap();
    let report = evaluate(&mut monitors, &recorded).unwrap();
    assert!(
        report.not_evaluable.is_empty(),
        "{:#?}",
        report.not_evaluable
    );
    let first = report.violations.first().expect("a violation offline");
    assert_eq!(monitors.display(first).to_string(), found);
    // Every range the live watch raised before the stop, offline too.
    let live: Vec<&str> = err
        .lines()
        .filter_map(|l| l.strip_prefix("contract violated: "))
        .collect();
    let offline: Vec<String> = report
        .violations
        .iter()
        .map(|v| monitors.display(v).to_string())
        .collect();
    for l in &live {
        assert!(
            offline.iter().any(|o| o == l),
            "{l} not offline: {offline:#?}"
        );
    }

    // The bounds are checked before anything runs.
    for (from, to, field) in [
        (
            "traction_margin: 0.85,",
            "traction_margin: -1.0,",
            "limits.traction_margin",
        ),
        (
            "torque_nm: None,",
            "torque_nm: Some(NaN),",
            "limits.torque_nm",
        ),
    ] {
        let bad = write(&dir, "bad.ron", &edited(CONFIG, from, to));
        let (code, out, err) = rex(&["--config", &bad]);
        assert_eq!(code, Some(2), "{out}\n{err}");
        assert!(err.contains(field), "{err}");
    }
}

#[test]
fn an_invariant_broken_by_a_seeded_defect_is_found_live_and_over_the_recording() {
    let dir = scratch("invariant");
    // The operator's promise: on the main mission e11 never has to stop the
    // platform (c1's `stopped`: e11 stopped it since the plan was taken).
    let spec = write(
        &dir,
        "rex.ron",
        &edited(
            SPEC,
            r#"invariants: [(name: "lost_plans_are_resent", subsystem: "c2", holds: "!lost || more")],"#,
            r#"invariants: [(name: "lost_plans_are_resent", subsystem: "c2", holds: "!lost || more"), (name: "never_stopped", subsystem: "c1", holds: "!stopped")],"#,
        ),
    );
    // The defect: a tracking limit of 3 cm, which e11's safety monitor
    // enforces by stopping the platform.
    // Rex's policy stops the run at the first error: the invariant, at the
    // activation of c1 after e11's stop, with the predicate's value.
    let Stopped {
        err,
        found,
        recording,
    } = stopped_by_a_violation(
        &dir,
        &edited(CONFIG, "tracking_m: 0.30,", "tracking_m: 0.03,"),
        &["--spec", &spec],
    );
    assert!(
        found.contains(" subsystem=c1 contract=invariant:never_stopped: false with stopped=true"),
        "{err}"
    );

    // Over the recording: the predicates c1's invariant reads, recorded after
    // each of its activations, give the same violation at the same instant;
    // c2's invariant is judged too, and kept.
    let recorded = Recording::open_filtered(&recording, needed).unwrap();
    let spec = embodied::spec::load("rex.ron", std::fs::read_to_string(&spec).unwrap()).unwrap();
    let mut monitors = Monitors::new(&spec.spec).unwrap();
    let report = evaluate(&mut monitors, &recorded).unwrap();
    assert!(
        report.not_evaluable.is_empty(),
        "{:#?}",
        report.not_evaluable
    );
    let first = report.violations.first().expect("a violation offline");
    assert_eq!(monitors.display(first).to_string(), found);
    let names: Vec<&str> = report
        .checked
        .iter()
        .filter_map(|c| monitors.contract(*c))
        .filter(|c| c.kind == embodied::monitor::ContractKind::Invariant)
        .map(|c| c.name.as_str())
        .collect();
    assert_eq!(names, ["lost_plans_are_resent", "never_stopped"]);
    assert!(
        report.violations.iter().all(|v| monitors
            .contract(v.contract)
            .is_some_and(|c| c.name != "lost_plans_are_resent")),
        "{:#?}",
        report.violations
    );
    // Only the subsystems with invariants have their predicates recorded.
    let all = Recording::open(&recording).unwrap();
    let mut topics: Vec<&str> = all
        .channels
        .values()
        .map(|c| c.topic.as_str())
        .filter(|t| t.starts_with("/predicates/"))
        .collect();
    topics.sort_unstable();
    assert_eq!(topics, ["/predicates/c1", "/predicates/c2"]);
    // The violation is the run's error, on `/errors` with its line.
    let errors = all.channel("/errors").expect("an errors channel").id;
    assert!(
        all.messages
            .iter()
            .filter(|m| m.channel == errors)
            .any(|m| String::from_utf8_lossy(&m.data).contains(&found)),
        "{found} on /errors"
    );
}
