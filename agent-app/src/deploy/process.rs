//! One process of a deployment: its components in real time, the others
//! reached over Zenoh, until the run's limit, a stop from the launcher (or
//! any participant), a signal, or the launcher's end. However it ends, it
//! sends the launcher its last reports, finishes its recording and prints its
//! timing and summary line.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::mpsc::Receiver;
use std::time::{Duration, SystemTime};

use agent_core::{ExecConfig, NodeId, OnError, Probes, RealTime, RtConfig, Running};
use agent_monitor::live::Live;
use agent_zenoh::{Member, MemberError, Options};

use super::{NOTE, Note, SEEN};
use crate::error::{AppError, Status};
use crate::local::{PROBE_CAPACITY, halting_nodes};
use crate::ros2::{Part, Ros2Out};
use crate::{Application, Common, Signals, SpecFile, Target, output, record};
use crate::{contracts, transitions, watch};

/// How long processes get to come up, agree on instant zero and start.
const LEAD: Duration = Duration::from_millis(1000);

/// The recording of start `incarnation` of `process`, from the pattern given
/// to `--record` (`{process}` stands for the process's name): the first start
/// records to the pattern, the `k`-th restart to `<stem>.<k>.<ext>` beside
/// it, so that no start overwrites another's.
pub(crate) fn part_path(pattern: &Path, process: &str, incarnation: u32) -> PathBuf {
    let path = PathBuf::from(pattern.to_string_lossy().replace("{process}", process));
    if incarnation == 0 {
        return path;
    }
    let stem = path
        .file_stem()
        .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
    let name = match path.extension() {
        Some(ext) => format!("{stem}.{incarnation}.{}", ext.to_string_lossy()),
        None => format!("{stem}.{incarnation}"),
    };
    path.with_file_name(name)
}

/// A launched child ends with its launcher: SIGTERM when the launcher dies
/// (Linux's parent-death signal), and at once if it died already.
fn tie_to_launcher(pid: u32) -> Result<(), AppError> {
    use nix::sys::signal::Signal;
    use nix::unistd::getppid;
    #[cfg(any(target_os = "linux", target_os = "android"))]
    nix::sys::prctl::set_pdeathsig(Signal::SIGTERM)
        .map_err(|e| AppError::Run(format!("cannot tie this process to its launcher: {e}")))?;
    let parent = getppid().as_raw();
    if u32::try_from(parent).ok() != Some(pid) {
        let _ = Signal::SIGTERM;
        return Err(AppError::Run(format!(
            "the launcher (pid {pid}) is gone before this process started (its parent is pid {parent})"
        )));
    }
    Ok(())
}

/// Turn a failure to join into the error that names its cause: an endpoint
/// another program holds is named with that program.
fn joined(
    e: MemberError,
    spec: &agent_spec::Spec,
    deployment: &str,
    process: &str,
    port: Option<u16>,
) -> AppError {
    if let MemberError::Zenoh { error, .. } = &e
        && (error.contains("in use") || error.contains("os error 98"))
        && let Some(endpoint) = super::endpoint_of(spec, deployment, process, port)
    {
        let holder = super::holder::holder(&endpoint);
        return AppError::EndpointTaken {
            process: process.to_owned(),
            endpoint,
            holder,
        };
    }
    AppError::Member(e)
}

/// Run process `--process` of `--deployment`.
pub(crate) fn run<A: Application>(
    app: &mut A,
    config: A::Config,
    common: &Common,
) -> Result<Status, AppError> {
    let signals = Signals::get();
    let (start, spec) = this_start(app, &config, common)?;
    let process = start.process;
    let limit = common.limit()?.unwrap_or_else(|| app.limit(&config));
    let (mut member, refusals) = join(&spec.spec, &start, common, signals)?;
    let system = app.build(&config, &start.target())?;
    let runs = member.runs().to_vec();
    let here = |n: &str| runs.iter().any(|r| r == n);
    let mut ros2 = Ros2Out::start(app, common, &spec, &system, Some(start.part(&runs)))?;
    // The end rule's subsystems that run here: each one's halt is told.
    let halting: Vec<_> = halting_nodes(&system, &app.end(&config))?
        .unwrap_or_default()
        .into_iter()
        .filter(|(_, name)| here(name))
        .collect();
    let (mut probes, seen) = Probes::new(PROBE_CAPACITY);
    app.probes(&mut probes, &here);
    let mut recorder = match &common.record {
        Some(pattern) => {
            let file = part_path(pattern, process, start.incarnation);
            let metadata = start.metadata(&runs, member.launch());
            Some(start_recording(
                app, &config, &spec, &file, metadata, &system,
            )?)
        }
        None => None,
    };
    let contracts = contracts::live(&spec, &system)?;
    let mut rt = real_time(
        app,
        &config,
        (system, probes),
        common,
        transitions::Observers {
            recorder: recorder.as_ref(),
            print: common.transitions,
            ros2: ros2.threads(),
            contracts: contracts.as_ref(),
        },
    );
    ros2.feed(&mut rt)?;
    let (running, end) = start_run(rt, &mut member, limit, &mut recorder)?;
    ros2.started(&running);
    let mut vigil = Vigil {
        member: &member,
        signals,
        process,
        undeliverable: 0,
        stopped: None,
    };
    vigil.until_over(&running, &seen, &halting, end, recorder.as_ref());
    let finished = running.join().map_err(AppError::from);
    let bridged = ros2.finish();
    let finished = finished?;
    for m in app.finished(&finished).into_iter().chain(seen.try_iter()) {
        vigil.send(SEEN, &m);
    }
    let report = finished.report();
    let overruns: u64 = report.nodes.iter().map(|n| n.overruns).sum();
    let refused = say_refused_links(&finished);
    let errors = contracts::run_errors(report, contracts.as_ref(), on_error(common));
    vigil.send_end(report, errors, (overruns, refused), refusals.as_ref());
    let stopped = vigil.close();
    if let Some(r) = &refusals {
        say_refusals(r);
    }
    let sample_dropped = member.sample_dropped();
    let left = member.close();
    let recorded = recorder.is_none_or(|r| record::finish_timed(r, report, process));
    let kept = say_end(
        common,
        process,
        report,
        Figures {
            overruns,
            sample_dropped,
            refused,
            crossing: sample_crossing(&finished, &runs),
        },
        contracts.as_ref(),
    );
    if let Some((why, _)) = &stopped {
        output::err(format_args!(
            "{}: process `{process}` stopped: {why}",
            output::program()
        ));
    }
    if let Err(e) = &left {
        output::error(e);
    }
    // Stopped before its end (a signal, its launcher gone): the run failed,
    // as a run in one process does (status 1). A launcher that stops its
    // processes restarts none, whatever their status.
    let interrupted = stopped.as_ref().is_some_and(|(_, early)| *early);
    Ok(if recorded && bridged && kept && !interrupted {
        Status::Success
    } else {
        Status::Failed
    })
}

/// A process's error policy: `--on-error`'s, else `continue`.
fn on_error(common: &Common) -> OnError {
    common.on_error.map_or(OnError::Continue, Into::into)
}

/// The figures of a process's line.
struct Figures {
    /// Overruns of its nodes.
    overruns: u64,
    /// Sample values its publishing thread was too far behind to take.
    sample_dropped: u64,
    /// Messages its links from other processes refused.
    refused: u64,
    /// Its sample links with other processes ([`sample_crossing`]).
    crossing: Crossing,
}

/// The values of the sample links between a process and the others.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct Crossing {
    /// Written here and published.
    published: u64,
    /// Written here and not published: each was written over before any
    /// reader elsewhere read (a sample link crosses at its readers'
    /// instants).
    withheld: u64,
    /// From elsewhere, arrived after a read they were due for (which took
    /// the fallback, or nothing new).
    late: u64,
}

/// The sample links between the nodes that run here (`runs`) and the others:
/// what crossed, what was not published, what came late.
fn sample_crossing(finished: &agent_core::Finished, runs: &[String]) -> Crossing {
    let info = finished.info();
    let here = |node: usize| runs.iter().any(|r| *r == info.nodes[node].name);
    let mut crossing = Crossing::default();
    for (link, stats) in info.links.iter().zip(finished.links()) {
        if link.policy != agent_core::Policy::Sample {
            continue;
        }
        match (here(link.from), here(link.to)) {
            (true, false) => {
                crossing.withheld += stats.overwritten;
                crossing.published += stats.sent.saturating_sub(stats.overwritten);
            }
            (false, true) => crossing.late += stats.late,
            _ => {}
        }
    }
    crossing
}

/// What a process says at its end: the timing table, the contracts' verdicts,
/// its figure line and its first errors. Whether its contracts were kept (a
/// broken one fails the process unless `--on-error continue`, the default
/// of a deployment's processes, only reports it).
fn say_end(
    common: &Common,
    process: &str,
    report: &agent_core::RtReport,
    figures: Figures,
    contracts: Option<&Live>,
) -> bool {
    let Figures {
        overruns,
        sample_dropped,
        refused,
        crossing,
    } = figures;
    if !common.quiet {
        output::err(format_args!("{report}"));
    }
    let kept = contracts.is_none_or(|live| contracts::say(live, common.quiet))
        || common
            .on_error
            .is_none_or(|p| p == crate::OnErrorArg::Continue);
    output::out(format_args!(
        "process={process} rt_priority={} overruns={overruns} executor_errors={} sample_dropped={sample_dropped} refused={refused} sample_published={} sample_withheld={} sample_late={}\n",
        if report.rt_priority() { "yes" } else { "no" },
        report.error_count,
        crossing.published,
        crossing.withheld,
        crossing.late,
    ));
    for e in report.errors.iter().take(watch::FIRST_ERRORS) {
        output::error(e);
    }
    kept
}

/// Join the deployment as this start of its process: the member, and the
/// count of what the access control refuses in a secure deployment.
fn join(
    spec: &agent_spec::Spec,
    start: &ThisStart<'_>,
    common: &Common,
    signals: &Signals,
) -> Result<(Member, Option<agent_zenoh::security::Refusals>), AppError> {
    let (deployment, process) = (start.deployment, start.process);
    let options = Options {
        port: common.port,
        timeout: common.wait()?,
        credentials: common.credentials.clone(),
        launch: common.launch_id.clone(),
        launched: common.launcher_pid.is_some(),
        cancel: Some(signals.flag()),
    };
    // A secure deployment: count what the access control refuses (before the
    // session opens, so that nothing is missed).
    let refusals = spec
        .deployment(deployment)
        .is_some_and(|d| d.is_secure())
        .then(agent_zenoh::security::Refusals::watch);
    let member = Member::join(spec, deployment, process, &options)
        .map_err(|e| joined(e, spec, deployment, process, common.port))?;
    Ok((member, refusals))
}

/// This start of a process of a deployment.
struct ThisStart<'a> {
    deployment: &'a String,
    process: &'a String,
    /// Its restarts before it (0: the first start).
    incarnation: u32,
    /// This start's epoch (unique among starts).
    boot: u64,
}

impl ThisStart<'_> {
    /// What the application builds for it.
    fn target(&self) -> Target<'_> {
        Target::Process {
            deployment: self.deployment,
            process: self.process,
            incarnation: self.incarnation,
            boot: self.boot,
        }
    }

    /// Its part of the deployment, running the components `runs`.
    fn part<'r>(&'r self, runs: &'r [String]) -> Part<'r> {
        Part {
            deployment: self.deployment,
            process: self.process,
            runs,
        }
    }

    /// The `process` metadata record of its recording (`runs`: the
    /// subsystems it runs; `launch`: the launch's identity).
    fn metadata(&self, runs: &[String], launch: &str) -> BTreeMap<String, String> {
        [
            ("name", self.process.clone()),
            ("deployment", self.deployment.clone()),
            ("runs", runs.join(", ")),
            ("incarnation", self.incarnation.to_string()),
            ("boot", self.boot.to_string()),
            ("launch", launch.to_owned()),
        ]
        .into_iter()
        .map(|(k, v)| (k.to_owned(), v))
        .collect()
    }
}

/// The process `--process` and `--deployment` name, checked (tied to its
/// launcher first, if launched; an unprotected deployment is said when not),
/// and the spec.
fn this_start<'c, A: Application>(
    app: &A,
    config: &A::Config,
    common: &'c Common,
) -> Result<(ThisStart<'c>, SpecFile), AppError> {
    let (Some(deployment), Some(process)) = (&common.deployment, &common.process) else {
        return Err(AppError::invalid("--process needs --deployment"));
    };
    if let Some(pid) = common.launcher_pid {
        tie_to_launcher(pid)?;
    }
    let spec = app.spec(config)?;
    if spec.spec.deployment(deployment).is_none() {
        return Err(AppError::invalid(format!(
            "spec `{}` has no deployment `{deployment}` (it has: {})",
            spec.spec.name,
            spec.spec.deployment_names()
        )));
    }
    super::check_port(&spec.spec, deployment, common.port)?;
    app.check_deployment(config, deployment)?;
    if common.launch_id.is_none() {
        super::say_unprotected(&spec.spec, deployment);
    }
    let start = ThisStart {
        deployment,
        process,
        incarnation: common.incarnation.unwrap_or(0),
        boot: agent_core::link::remote::new_epoch(),
    };
    Ok((start, spec))
}

/// The recorder of this start's part of the recording, into `file`, with
/// the application's metadata and this process's (`process`).
fn start_recording<A: Application>(
    app: &A,
    config: &A::Config,
    spec: &SpecFile,
    file: &Path,
    process: BTreeMap<String, String>,
    system: &agent_core::System,
) -> Result<agent_mcap::McapRecorder, AppError> {
    record::check_target(file)
        .map_err(|e| AppError::invalid(format!("--record {}: {e}", file.display())))?;
    let mut options = app.record_options(config);
    options
        .metadata
        .extend(crate::recorded_metadata::<A>(spec, config)?);
    options.metadata.insert("process".into(), process);
    record::create(file, system, options)
}

/// The real-time run of `system`, watched by `probes`, observed by
/// `observers` (the recorder's parts, the ROS 2 bridge's, a printer of
/// transitions, the watch of the contracts).
fn real_time<A: Application>(
    app: &A,
    config: &A::Config,
    (system, probes): (agent_core::System, Probes<A::Seen>),
    common: &Common,
    observers: transitions::Observers<'_>,
) -> RealTime {
    // A lost peer or a gap is reported and the run goes on: a deployment
    // lives with processes that come and go (unless `--on-error` says
    // otherwise).
    let exec = ExecConfig {
        on_error: on_error(common),
        ..app.exec(config)
    };
    let mut rt = RealTime::new(
        system,
        RtConfig {
            exec,
            threading: common.threads.into(),
            ..RtConfig::realtime()
        },
    );
    rt.watch(probes);
    transitions::observe(&mut rt, observers);
    rt
}

/// Start the run, placed as the deployment says, at the instant zero its
/// processes agree on: the run, and its end on the wall clock. A run that
/// cannot start finishes the recording.
fn start_run(
    mut rt: RealTime,
    member: &mut Member,
    limit: Duration,
    recorder: &mut Option<agent_mcap::McapRecorder>,
) -> Result<(Running, Option<SystemTime>), AppError> {
    rt.place(member.placement()?)
        .map_err(|e| AppError::invalid(e.to_string()))?;
    let mut origin = None;
    let started = rt.start_when(limit, || {
        let zero = member.ready(LEAD)?;
        origin = Some(zero);
        Ok::<_, agent_zenoh::MemberError>(zero)
    });
    // The run's end on the wall clock: a process whose nodes all halted stays
    // in the deployment until then (its going would read as a crash).
    let end = origin.map(|zero| zero + limit);
    match started {
        Ok(running) => Ok((running, end)),
        Err(e) => {
            if let Some(r) = recorder.take() {
                record::finish(r);
            }
            Err(AppError::from(e))
        }
    }
}

/// The process watching its run for the launcher: what it reports, and why
/// it was stopped.
struct Vigil<'m> {
    member: &'m Member,
    signals: &'m Signals,
    process: &'m str,
    /// Reports that could not be sent.
    undeliverable: u64,
    /// Why the run was stopped, if it was: by a participant's stop (the
    /// deployment's end, `false`), or before its end (a signal, the launcher
    /// gone: `true`).
    stopped: Option<(String, bool)>,
}

impl Vigil<'_> {
    /// The end of the watch: warns of the reports the launcher could not be
    /// sent; returns why the process was stopped, if it was, and whether
    /// before the run's end.
    fn close(self) -> Option<(String, bool)> {
        if self.undeliverable > 0 {
            output::warn(format_args!(
                "{} reports could not be sent to the launcher",
                self.undeliverable
            ));
        }
        self.stopped
    }

    /// Send one report to the launcher; count what cannot go.
    fn send<T: serde::Serialize>(&mut self, name: &str, value: &T) {
        observe(self.member, name, value, &mut self.undeliverable);
    }

    /// Tell the launcher the run here ended: its errors, last instant,
    /// overruns and refusals.
    fn send_end(
        &mut self,
        report: &agent_core::RtReport,
        (errors, first_errors): (u64, Vec<String>),
        (overruns, refused): (u64, u64),
        refusals: Option<&agent_zenoh::security::Refusals>,
    ) {
        self.send(
            NOTE,
            &Note::Ended {
                errors,
                first_errors,
                last_ns: report.last_instant.as_nanos(),
                overruns,
                refused,
                acl_refused: refusals.map_or(0, |r| r.total()),
            },
        );
    }

    /// Until the run is over (stopped, or every node here finished and the
    /// run's `end` passed): the probes' reports and the halts of the
    /// `halting` nodes sent, a stop (a signal, the launcher gone, a stop
    /// asked) acted on, the recorder watched.
    fn until_over<M: serde::Serialize>(
        &mut self,
        running: &Running,
        seen: &Receiver<M>,
        halting: &[(NodeId, String)],
        end: Option<SystemTime>,
        recorder: Option<&agent_mcap::McapRecorder>,
    ) {
        let mut told = vec![false; halting.len()];
        let mut failing = record::FailWatch::new();
        let mut idle_said = false;
        loop {
            let finished = running.is_finished();
            for m in seen.try_iter() {
                self.send(SEEN, &m);
            }
            for (k, (id, name)) in halting.iter().enumerate() {
                if !told[k] && running.is_halted(*id) {
                    told[k] = true;
                    self.send(NOTE, &Note::Halted(name.clone()));
                }
            }
            if self.stopped.is_none() {
                self.look_for_stop(running);
            }
            if finished {
                let over = self.stopped.is_some() || end.is_none_or(|end| SystemTime::now() >= end);
                if over {
                    break;
                }
                if !idle_said {
                    idle_said = true;
                    output::err(format_args!(
                        "{}: process `{}`: every node here halted; it stays in the deployment until the run ends",
                        output::program(),
                        self.process
                    ));
                }
                std::thread::sleep(Duration::from_millis(20));
                continue;
            }
            failing.look(recorder);
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// Whether the run is to stop (a signal, the launcher gone, a stop from
    /// a participant): then it is stopped, and why is kept.
    fn look_for_stop(&mut self, running: &Running) {
        let member = self.member;
        if let Some(sig) = self.signals.received() {
            self.stopped = Some((format!("{sig} received"), true));
        } else if member.launcher_gone() {
            self.stopped = Some(("its launcher is gone".into(), true));
        } else if member.stop_requested() {
            let by = member.stopped_by().unwrap_or_else(|| "this process".into());
            self.stopped = Some((format!("a stop from {by}"), false));
        }
        if self.stopped.is_some() {
            running.stop();
        }
    }
}

/// Every message refused on a link from another process, said link by link:
/// how many in all.
fn say_refused_links(finished: &agent_core::Finished) -> u64 {
    let mut refused = 0u64;
    for (link, stats) in finished.info().links.iter().zip(finished.links()) {
        if stats.refused > 0 {
            refused += stats.refused;
            output::err(format_args!(
                "{}: link `{}`: {} messages refused (see the errors for why)",
                output::program(),
                link.name,
                stats.refused
            ));
        }
    }
    refused
}

/// What the access control refused, by what and key (or that it could not
/// be counted).
fn say_refusals(r: &agent_zenoh::security::Refusals) {
    if !r.counting() {
        output::warn(format_args!(
            "refusals of the access control cannot be counted (a tracing subscriber was installed before)"
        ));
    }
    for (what, key, n) in r.counts() {
        output::err(format_args!(
            "{}: the access control refused {n} x {what} on `{key}`",
            output::program()
        ));
    }
}

/// Send one report to the launcher; count what cannot go.
fn observe<T: serde::Serialize>(member: &Member, name: &str, value: &T, failed: &mut u64) {
    let sent = postcard::to_allocvec(value)
        .ok()
        .is_some_and(|bytes| member.observe(name, bytes).is_ok());
    if !sent {
        *failed += 1;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_start_of_a_process_records_to_a_file_of_its_own() {
        let p = Path::new("/tmp/run.{process}.mcap");
        assert_eq!(part_path(p, "world", 0), Path::new("/tmp/run.world.mcap"));
        assert_eq!(part_path(p, "world", 2), Path::new("/tmp/run.world.2.mcap"));
        assert_eq!(
            part_path(Path::new("out/{process}"), "c", 1),
            Path::new("out/c.1")
        );
    }
}
