//! Rex split into processes, as a deployment of the spec places its components
//! (`split`: the world with the partner agents; c1 with e11; r11 on its own, as
//! in the paper's Fig. 10), over Zenoh.
//!
//! Every process builds the whole system from the spec (so the wiring is
//! checked the same way everywhere) and runs only its own components, in real
//! time ([`embodied::RealTime::place`]); links to the other processes go over
//! Zenoh. The processes agree on instant zero, so their instants line up as in
//! the single-process real-time run. Each process publishes what its probes see
//! (e11's tracking, c1's behaviour, a2's acknowledgements, the true pose);
//! [`launch`] starts every process, collects that, judges the mission as the
//! other runs do, and stops the processes when the mission has ended.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use embodied::distributed::{Child, Control, LaunchReport, Launcher, Line, Member, Options, Watch};
use embodied::record::{McapRecorder, RecordOptions, RecordSummary};
use embodied::{ExecConfig, OnError, RealTime, RtConfig, RtReport};

use super::collect::{Collector, Seen};
use super::realtime::install_probes;
use super::{Outcome, Progress, finish_counters};
use crate::a1::{RexConfig, RexError, build_deployment, load_spec};
use crate::report::judge;

/// The drivers that act on or sense the simulated world: they share it, so a
/// deployment must run them in one process.
const WORLD_DRIVERS: [&str; 3] = ["E1", "R1", "R3"];

/// How long processes get to come up, agree and start.
const LEAD: Duration = Duration::from_millis(1000);

/// Why a distributed run failed.
#[derive(Debug, thiserror::Error)]
pub enum DistError {
    /// Rex could not be built.
    #[error(transparent)]
    Rex(#[from] RexError),
    /// Joining the deployment failed.
    #[error(transparent)]
    Member(#[from] embodied::distributed::MemberError),
    /// The real-time executor failed.
    #[error(transparent)]
    Rt(#[from] embodied::RtError),
    /// The launcher failed.
    #[error(transparent)]
    Launch(#[from] embodied::distributed::LaunchError),
    /// The recording of the process, or the merge of the processes'
    /// recordings, failed.
    #[error(transparent)]
    Record(#[from] embodied::record::RecordError),
    /// The processes' recordings could not be merged.
    #[error(transparent)]
    Merge(#[from] embodied::record::MergeError),
    /// The deployment cannot run the simulation.
    #[error("deployment `{deployment}`: {reason}")]
    Deployment {
        /// The deployment.
        deployment: String,
        /// What is wrong.
        reason: String,
    },
}

impl DistError {
    /// Whether running again cannot help: a spec or deployment that does not
    /// fit, a process or component the deployment does not have, an endpoint
    /// Zenoh refuses (a port taken, an address not here).
    pub fn is_configuration(&self) -> bool {
        use embodied::distributed::MemberError as M;
        matches!(
            self,
            DistError::Rex(_)
                | DistError::Deployment { .. }
                | DistError::Member(
                    M::UnknownDeployment { .. }
                        | M::UnknownProcess { .. }
                        | M::Zenoh { .. }
                        | M::Credentials { .. }
                        | M::Policy(_)
                )
                | DistError::Rt(embodied::RtError::UnknownNode { .. })
        )
    }
}

/// Check that `deployment` keeps the simulated world's drivers in one process.
fn check_world(spec: &embodied::spec::Spec, deployment: &str) -> Result<(), DistError> {
    let fail = |reason: String| DistError::Deployment {
        deployment: deployment.to_owned(),
        reason,
    };
    let Some(dep) = spec.deployments.iter().find(|d| d.name == deployment) else {
        return Err(fail(format!(
            "no such deployment in spec `{}` (it has: {})",
            spec.name,
            spec.deployments
                .iter()
                .map(|d| d.name.as_str())
                .collect::<Vec<_>>()
                .join(", ")
        )));
    };
    let mut places: Vec<(String, &str)> = WORLD_DRIVERS
        .iter()
        .filter_map(|d| Some((dep.process_of(d)?.name.clone(), *d)))
        .collect();
    places.sort();
    if places.windows(2).any(|w| w[0].0 != w[1].0) {
        return Err(fail(format!(
            "the simulated world's drivers share one environment and must run in one process, but {}",
            places
                .iter()
                .map(|(p, d)| format!("{d} runs in `{p}`"))
                .collect::<Vec<_>>()
                .join(", ")
        )));
    }
    Ok(())
}

/// What one process of a deployment did ([`run_process`]).
#[derive(Debug)]
pub struct ProcessRun {
    /// The real-time run's timing, errors and priorities.
    pub report: RtReport,
    /// What was recorded, with `record`.
    pub recording: Option<RecordSummary>,
    /// Values of sample links this process dropped before Zenoh had them
    /// (its publishing thread that far behind; queue links refuse instead).
    pub sample_dropped: u64,
    /// Why leaving the deployment did not go cleanly (messages put in the run
    /// that were not yet in Zenoh's hands when the session closed), if it did
    /// not: reported, and the run's report and recording are kept.
    pub left: Result<(), embodied::distributed::MemberError>,
}

/// Run process `process` of `deployment`: its components in real time, the
/// others reached over Zenoh, until the limit, a stop from any participant, or
/// `interrupted`. What its probes see is published for the launcher. With
/// `record`, what its components do is recorded to that file, with the
/// metadata `process` (its name, the deployment, the nodes it runs and, if it
/// runs c1, c1's incarnation number: what a replay of c1 needs); the files of
/// a run's processes merge into one ([`embodied::record::merge`]).
#[expect(
    clippy::too_many_arguments,
    reason = "a process's inputs, each used once"
)]
pub fn run_process(
    config: &RexConfig,
    limit: Duration,
    deployment: &str,
    process: &str,
    options: &Options,
    rt: RtConfig,
    record: Option<(&Path, RecordOptions)>,
    interrupted: &AtomicBool,
) -> Result<ProcessRun, DistError> {
    let spec = load_spec(&config.spec)?;
    check_world(&spec, deployment)?;
    // A secure deployment: count what the access control refuses (before the
    // session opens, so that nothing is missed).
    let refusals = spec
        .deployment(deployment)
        .is_some_and(|d| d.secure)
        .then(embodied::distributed::security::Refusals::watch);
    let mut member = Member::join(&spec, deployment, process, options)?;
    // Each start of this process is a new incarnation of c1 (if it runs c1):
    // a2 tells a restart by it and sends again the plans that were lost.
    let mut config = config.clone();
    config.c1.boot = embodied::link::remote::new_epoch();
    let (system, h) = build_deployment(&config, deployment)?;
    let runs = member.runs().to_vec();
    let recorder = match record {
        Some((path, mut options)) => {
            let mut about = BTreeMap::from([
                ("name".to_owned(), process.to_owned()),
                ("deployment".to_owned(), deployment.to_owned()),
                ("runs".to_owned(), runs.join(", ")),
            ]);
            if runs.iter().any(|r| r == "c1") {
                about.insert("c1_boot".into(), config.c1.boot.to_string());
            }
            options.metadata.insert("process".into(), about);
            Some(McapRecorder::create(path, &system, options)?)
        }
        None => None,
    };
    // A lost peer or a gap is reported and the run goes on: the platform's
    // watchdog and e11's safety monitor handle the consequences.
    let mut rt = RealTime::new(
        system,
        RtConfig {
            exec: ExecConfig {
                on_error: OnError::Continue,
                ..config.exec
            },
            ..rt
        },
    );
    let probes = install_probes(&mut rt, &h, |n| runs.iter().any(|r| r == n));
    if let Some(r) = &recorder {
        rt.observe(r.threads());
    }
    rt.place(member.placement()?)?;
    let running = rt.start_when(limit, || member.ready(LEAD))?;
    loop {
        let finished = running.is_finished();
        for rx in &probes {
            for seen in rx.try_iter() {
                if let Ok(bytes) = postcard::to_allocvec(&seen) {
                    // A monitor that is gone is not this process's failure.
                    let _ = member.observe("seen", bytes);
                }
            }
        }
        if member.stop_requested() || interrupted.load(Ordering::Relaxed) {
            running.stop();
        }
        if finished {
            break;
        }
        std::thread::sleep(Duration::from_millis(2));
    }
    let finished = running.join()?;
    // This process's part of the run's counters, for the launcher's summary.
    let mut counters = super::Counters::default();
    finish_counters(&finished, &h, &mut counters);
    counters.executor_errors = finished.report().error_count;
    if let Some(r) = &refusals {
        if !r.counting() {
            eprintln!(
                "rex: refusals of the access control cannot be counted (a tracing subscriber was installed before)"
            );
        }
        for (what, key, n) in r.counts() {
            eprintln!("rex: the access control refused {n} x {what} on `{key}`");
        }
        counters.acl_refused = r.total();
    }
    if let Ok(bytes) = postcard::to_allocvec(&Seen::Counters(Box::new(counters))) {
        let _ = member.observe("seen", bytes);
    }
    let sample_dropped = member.sample_dropped();
    let left = member.close();
    let recording = recorder.map(McapRecorder::finish).transpose()?;
    Ok(ProcessRun {
        report: finished.into_report(),
        recording,
        sample_dropped,
        left,
    })
}

/// Start every process of `deployment` (this program again, with `args` and
/// `--process <name>`), print their lines prefixed with their names, collect
/// what they observe, judge the mission, and stop them when it has ended (or
/// on `interrupted`). Each `(process, seconds)` of `faults` is killed with
/// SIGKILL once the mission's time reaches `seconds` (and restarted).
#[expect(
    clippy::too_many_arguments,
    reason = "the launch's inputs, each used once"
)]
pub fn launch(
    config: &RexConfig,
    deployment: &str,
    options: &Options,
    program: std::path::PathBuf,
    args: &[String],
    faults: &[(String, f64)],
    interrupted: &AtomicBool,
    mut progress: impl FnMut(Progress<'_>),
) -> Result<(Outcome, LaunchReport), DistError> {
    let spec = load_spec(&config.spec)?;
    check_world(&spec, deployment)?;
    let watch = Watch::open(&spec, deployment, options)?;
    let dep = spec
        .deployments
        .iter()
        .find(|d| d.name == deployment)
        .ok_or_else(|| DistError::Deployment {
            deployment: deployment.to_owned(),
            reason: "no such deployment".into(),
        })?;
    let children: Vec<Child> = dep
        .processes()
        .into_iter()
        .map(|(_, p, _)| Child {
            name: p.name.clone(),
            program: program.clone(),
            args: args
                .iter()
                .cloned()
                .chain(["--process".to_owned(), p.name.clone()])
                .collect(),
        })
        .collect();
    let mut collect = Collector::new(config, Duration::from_secs(5));
    let wall = Instant::now();
    let mut stop_sent = false;
    let mut undecodable = 0u64;
    let mut faults: Vec<(String, f64)> = faults.to_vec();
    // Exit status 2 is a bad command line or configuration: restarting won't help.
    let report = Launcher::new(children)
        .fatal_codes([2])
        .run(interrupted, |line| {
            match line {
                Line::Output { process, text } => eprintln!("[{process}] {text}"),
                Line::Exited {
                    process,
                    code,
                    restarting,
                } => eprintln!(
                    "[{process}] exited ({}){}",
                    code.map_or("killed by a signal".to_owned(), |c| format!("status {c}")),
                    if *restarting { "; restarting it" } else { "" }
                ),
                Line::Idle => {}
            }
            while let Some((process, _, bytes)) = watch.next(Duration::ZERO) {
                take(
                    &mut collect,
                    &mut undecodable,
                    &process,
                    &bytes,
                    &mut progress,
                );
            }
            if collect.advance(false, &mut progress) && !stop_sent {
                stop_sent = true;
                watch.stop();
            }
            let now = collect.time();
            if let Some(k) = faults.iter().position(|(_, at)| now >= *at) {
                let (process, at) = faults.remove(k);
                eprintln!("rex: killing `{process}` at {now:.2} s (--kill {process}@{at})");
                return Control::Kill(process);
            }
            Control::Continue
        })?;
    // What arrived after the processes ended.
    while let Some((process, _, bytes)) = watch.next(Duration::from_millis(200)) {
        take(
            &mut collect,
            &mut undecodable,
            &process,
            &bytes,
            &mut progress,
        );
    }
    if undecodable > 0 {
        eprintln!(
            "rex: {undecodable} observations did not decode (a process of another build?); the summary lacks them"
        );
    }
    collect.advance(true, &mut progress);
    let sent = collect.sent;
    let mut out = std::mem::take(&mut collect.out);
    out.wall_s = wall.elapsed().as_secs_f64();
    out.sim_s = out.samples.last().map_or(0.0, |s| s.t);
    out.parts = [
        config.planner.name().to_owned(),
        format!("{:?}", config.tracker).to_lowercase(),
        format!("{:?}", config.estimator).to_lowercase(),
    ];
    out.reports = judge::judge(&out, config, sent);
    Ok((out, report))
}

/// One observation into `collect`; one that does not decode is counted (and
/// the first named), never silently dropped.
fn take(
    collect: &mut Collector,
    undecodable: &mut u64,
    process: &str,
    bytes: &[u8],
    progress: &mut impl FnMut(Progress<'_>),
) {
    match postcard::from_bytes::<Seen>(bytes) {
        Ok(seen) => collect.see(seen, progress),
        Err(e) => {
            if *undecodable == 0 {
                eprintln!("rex: an observation of `{process}` does not decode: {e}");
            }
            *undecodable += 1;
        }
    }
}
