//! A run in this process: the deterministic executor (virtual time) or the
//! real-time one (`--realtime`), recorded or not, watched through the
//! application's probes, ended by its rule, its limit or a signal, and
//! summarised the same way whichever ended it.

use std::path::Path;
use std::sync::mpsc::Receiver;
use std::time::{Duration, Instant};

use agent_core::{
    ExecConfig, Executor, Finished, NoObserver, NodeId, Observer, OnError, Probes, RealTime,
    RtConfig, System, Time,
};
use agent_mcap::{McapRecorder, RecordOptions, RecordSummary};

use agent_monitor::live::Live;

use crate::contracts;
use crate::error::{AppError, Status};
use crate::ros2::Ros2Out;
use crate::transitions::{self, Transitions};
use crate::watch::{End, Ended, Mode, RunSummary, Watcher};
use crate::{Application, Common, Signals, SpecFile, Target, output, record};

/// Results a probe set's channel holds before results are dropped (counted):
/// the deterministic run drains it after every instant, the real-time one
/// every few milliseconds.
pub(crate) const PROBE_CAPACITY: usize = 1 << 16;

/// How often the status line is printed (wall-clock time).
const STATUS_EVERY: Duration = Duration::from_secs(5);

/// Run `config` in this process. The exit status and the run's figure line.
pub(crate) fn run<A: Application>(
    app: &mut A,
    config: &A::Config,
    common: &Common,
) -> Result<(Status, String), AppError> {
    let spec = app.spec(config)?;
    let limit = common.limit()?.unwrap_or_else(|| app.limit(config));
    let end = app.end(config);
    let rule_stated = end.is_stated();
    let exec = common.exec(app.exec(config));
    let record_to = common
        .record
        .clone()
        .or_else(|| app.default_record(config, common));
    let system = app.build(config, &Target::Whole)?;
    let contracts = contracts::live(&spec, &system)?;
    let (mut probes, seen) = Probes::new(PROBE_CAPACITY);
    app.probes(&mut probes, &|_| true);
    let mut watcher = app.watcher(config, common);
    let ros2 = Ros2Out::start(app, common, &spec, &system, None)?;
    let recorder = match &record_to {
        Some(file) => {
            let mut options = app.record_options(config);
            options
                .metadata
                .extend(crate::recorded_metadata::<A>(&spec, config)?);
            Some(record::create(file, &system, options)?)
        }
        None => None,
    };
    if !common.quiet
        && let Some(line) = app.announce(config)
    {
        output::err(format_args!("{line}"));
    }
    let watched = Watched {
        probes,
        seen,
        watcher: watcher.as_mut(),
        end,
        limit,
        quiet: common.quiet,
        transitions: common.transitions,
        contracts: contracts.clone(),
    };
    let (ran, recorder, ros2, mode) = if common.realtime {
        let config = RtConfig {
            exec,
            threading: common.threads.into(),
            ..RtConfig::realtime()
        };
        let mut ros2 = ros2;
        let ran = watched.realtime_observed(system, config, recorder.as_ref(), Some(&mut ros2));
        (ran?, recorder, ros2, Mode::RealTime)
    } else {
        match recorder {
            Some(r) => {
                let (ran, (r, ros2)) = watched.simulate(system, exec, (r, ros2))?;
                (ran, Some(r), ros2, Mode::Simulated)
            }
            None => {
                let (ran, (_, ros2)) = watched.simulate(system, exec, (NoObserver, ros2))?;
                (ran, None, ros2, Mode::Simulated)
            }
        }
    };
    let bridged = ros2.finish();
    conclude(
        app,
        common,
        &spec,
        (ran, mode, rule_stated),
        watcher.as_mut(),
        recorder,
        (bridged, contracts.as_ref(), exec.on_error),
    )
}

/// A system's run watched to its end: the probes on it, their reports, the
/// watcher that reads them, the end rule and the limit. For a program that
/// drives the layer's loops itself ([`Watched::simulate`],
/// [`Watched::realtime`]); the command line does the same for every run.
pub struct Watched<'w, M> {
    /// The probes on the system.
    pub probes: Probes<M>,
    /// Their reports.
    pub seen: Receiver<M>,
    /// What reads them, decides the end and judges.
    pub watcher: &'w mut dyn Watcher<M>,
    /// The layer's part of the end rule.
    pub end: End,
    /// The longest run: virtual time, or wall-clock time in real time.
    pub limit: Duration,
    /// No status line.
    pub quiet: bool,
    /// Print every FSM transition as it happens.
    pub transitions: bool,
    /// The spec's contracts, watched in the executor (`None`: a spec
    /// without contracts, or a run that does not watch them).
    pub contracts: Option<Live>,
}

/// A run that ended: its nodes, how it ended, its wall-clock time.
#[derive(Debug)]
pub struct Ran {
    /// The nodes, the environment, the links' counters and the report.
    pub finished: Finished,
    /// How it ended.
    pub ended: Ended,
    /// Wall-clock time of the run.
    pub wall: Duration,
}

impl Ran {
    /// Tell `watcher` the run's `last` reports (read off its nodes, as an
    /// application's [`finished`](crate::Application::finished) does), then
    /// that the run is finished ([`Watcher::ended`]): the end of a run a
    /// program drives itself, as the command line ends each of its runs.
    pub fn conclude<M>(&self, watcher: &mut dyn Watcher<M>, last: impl IntoIterator<Item = M>) {
        for m in last {
            watcher.see(m);
        }
        watcher.ended(true);
    }
}

/// The stop signal, if the program installed the handlers ([`Signals::get`]).
fn signalled() -> Option<&'static str> {
    Signals::installed().and_then(Signals::received)
}

impl<'w, M: Send + 'static> Watched<'w, M> {
    /// A run watched by `watcher` to `limit` (or to the watcher's end), with
    /// probes to install ([`Watched::probes`]): for a program (a library's
    /// function, a test) that runs a system itself, without the command
    /// line. No status line, no transition printed, no end rule but the
    /// watcher's and no contract watched; the fields say otherwise.
    pub fn new(watcher: &'w mut dyn Watcher<M>, limit: Duration) -> Self {
        let (probes, seen) = Probes::new(PROBE_CAPACITY);
        Watched {
            probes,
            seen,
            watcher,
            end: End::Limit,
            limit,
            quiet: true,
            transitions: false,
            contracts: None,
        }
    }

    /// [`Watched::realtime`], recorded to `record`'s file with its options
    /// when given (every thread's part of the run: what each node sent and
    /// read, its behaviour switches, the errors), without a word on standard
    /// output: the recording's summary is returned.
    pub fn realtime_recorded(
        self,
        system: System,
        config: RtConfig,
        record: Option<(&Path, RecordOptions)>,
    ) -> Result<(Ran, Option<RecordSummary>), AppError> {
        let recorder = match record {
            Some((path, options)) => Some(McapRecorder::create(path, &system, options)?),
            None => None,
        };
        let ran = self.realtime(system, config, recorder.as_ref())?;
        let summary = recorder.map(McapRecorder::finish).transpose()?;
        Ok((ran, summary))
    }

    /// Take the probes' reports in; whether the watcher says the run has
    /// ended.
    fn take(&mut self, finished: bool) -> bool {
        for m in self.seen.try_iter() {
            self.watcher.see(m);
        }
        self.watcher.ended(finished)
    }

    fn status(&self, at: Time) {
        if !self.quiet
            && let Some(s) = self.watcher.status()
        {
            output::err(format_args!("[{:9.2} s] {s}", at.as_secs_f64()));
        }
    }

    /// Run `system` in the deterministic executor, observed by `observer`
    /// (a recorder, say), until its end rule, its limit or a signal. The
    /// reports of the last instant are taken in; [`Watcher::ended`] with
    /// `finished` is the caller's to call, after its own last reports.
    pub fn simulate<O: Observer + 'static>(
        mut self,
        system: System,
        exec: ExecConfig,
        observer: O,
    ) -> Result<(Ran, O), AppError> {
        let halting = halting_nodes(&system, &self.end)?;
        let watch = self.contracts.as_ref().map(Live::watch);
        let observer = (observer, (Transitions::new(self.transitions), watch));
        let mut ex = Executor::with_observer(system, exec, observer);
        ex.watch(std::mem::replace(&mut self.probes, Probes::new(1).0));
        let end = Time::ZERO.saturating_add(self.limit);
        let wall = Instant::now();
        let mut next_status = wall + STATUS_EVERY;
        let mut failing = record::FailWatch::new();
        let ended = loop {
            if let Some(sig) = signalled() {
                break Ended::Stopped(format!("{sig} received"));
            }
            let Some(t) = ex.next_instant() else {
                break Ended::AllHalted;
            };
            if t >= end {
                break Ended::Limit;
            }
            if let Err(e) = ex.step() {
                break Ended::Failed(e.to_string());
            }
            if self.take(false) {
                break Ended::Rule("the application's end was reached".into());
            }
            if let Some(why) = all_halted(halting.as_deref(), |id| ex.is_halted(id)) {
                break Ended::Rule(why);
            }
            if Instant::now() >= next_status {
                next_status += STATUS_EVERY;
                self.status(ex.now());
                let any: &dyn std::any::Any = &ex.observer().0;
                failing.look(any.downcast_ref::<McapRecorder>().or_else(|| {
                    any.downcast_ref::<(McapRecorder, Ros2Out)>()
                        .map(|(r, _)| r)
                }));
            }
        };
        let wall = wall.elapsed();
        let (finished, (observer, _)) = ex.finish();
        for m in self.seen.try_iter() {
            self.watcher.see(m);
        }
        Ok((
            Ran {
                finished,
                ended,
                wall,
            },
            observer,
        ))
    }

    /// Run `system` in the real-time executor (recorded by `recorder`, whose
    /// threads' observers this installs) until its end rule, its limit or a
    /// signal, watched from this thread.
    pub fn realtime(
        self,
        system: System,
        config: RtConfig,
        recorder: Option<&McapRecorder>,
    ) -> Result<Ran, AppError> {
        self.realtime_observed(system, config, recorder, None)
    }

    /// [`Watched::realtime`] with the ROS 2 bridge (`ros2`): its observers
    /// see the threads, and the topics it subscribes feed their inputs.
    pub(crate) fn realtime_observed(
        mut self,
        system: System,
        config: RtConfig,
        recorder: Option<&McapRecorder>,
        mut ros2: Option<&mut Ros2Out>,
    ) -> Result<Ran, AppError> {
        let halting = halting_nodes(&system, &self.end)?;
        let exec = config.exec;
        let mut rt = RealTime::new(system, config);
        rt.watch(std::mem::replace(&mut self.probes, Probes::new(1).0));
        let threads = ros2.as_deref().and_then(Ros2Out::threads);
        transitions::observe(
            &mut rt,
            transitions::Observers {
                recorder,
                print: self.transitions,
                ros2: threads,
                contracts: self.contracts.as_ref(),
            },
        );
        if let Some(ros2) = ros2.as_deref_mut() {
            ros2.feed(&mut rt)?;
        }
        let running = rt.start(self.limit)?;
        if let Some(ros2) = ros2.as_deref() {
            ros2.started(&running);
        }
        let wall = Instant::now();
        let mut next_status = wall + STATUS_EVERY;
        let mut failing = record::FailWatch::new();
        let mut ended = None;
        loop {
            let finished = running.is_finished();
            if ended.is_none() {
                if let Some(sig) = signalled() {
                    ended = Some(Ended::Stopped(format!("{sig} received")));
                } else if self.take(false) {
                    ended = Some(Ended::Rule("the application's end was reached".into()));
                } else if let Some(why) = all_halted(halting.as_deref(), |id| running.is_halted(id))
                {
                    ended = Some(Ended::Rule(why));
                }
                if ended.is_some() {
                    running.stop();
                }
            }
            if finished {
                break;
            }
            if Instant::now() >= next_status {
                next_status += STATUS_EVERY;
                self.status(Time::ZERO.saturating_add(wall.elapsed()));
                failing.look(recorder);
            }
            std::thread::sleep(Duration::from_millis(2));
        }
        let finished = running.join()?;
        let wall = wall.elapsed();
        for m in self.seen.try_iter() {
            self.watcher.see(m);
        }
        let report = finished.report();
        let ended = ended.unwrap_or_else(|| {
            if exec.on_error == agent_core::OnError::Stop && report.error_count > 0 {
                Ended::Failed(
                    report
                        .errors
                        .first()
                        .map_or_else(|| "an executor error".to_owned(), ToString::to_string),
                )
            } else {
                Ended::Limit
            }
        });
        Ok(Ran {
            finished,
            ended,
            wall,
        })
    }
}

/// Whether the end rule's subsystems have all halted: the rule's words.
fn all_halted(
    nodes: Option<&[(NodeId, String)]>,
    is_halted: impl Fn(NodeId) -> bool,
) -> Option<String> {
    let nodes = nodes?;
    nodes.iter().all(|(id, _)| is_halted(*id)).then(|| {
        let names: Vec<&str> = nodes.iter().map(|(_, n)| n.as_str()).collect();
        format!("{} halted", names.join(", "))
    })
}

/// The nodes an [`End::Halted`] rule names, checked against the system.
pub(crate) fn halting_nodes(
    system: &System,
    end: &End,
) -> Result<Option<Vec<(NodeId, String)>>, AppError> {
    match end {
        End::Limit => Ok(None),
        End::Halted(names) => names
            .iter()
            .map(|n| {
                system.node(n).map(|id| (id, n.clone())).ok_or_else(|| {
                    AppError::invalid(format!(
                        "the end rule names `{n}`, which the system does not have (it has: {})",
                        system
                            .info()
                            .nodes
                            .iter()
                            .map(|n| n.name.as_str())
                            .collect::<Vec<_>>()
                            .join(", ")
                    ))
                })
            })
            .collect::<Result<Vec<_>, _>>()
            .map(Some),
    }
}

/// The end of every run in this process: the application's last reports, the
/// recording finished, the timing table, the summary and the judgement
/// (`bridged`: whether the ROS 2 bridge finished cleanly; if not, the run
/// fails).
fn conclude<A: Application>(
    app: &mut A,
    common: &Common,
    spec: &SpecFile,
    (ran, mode, rule_stated): (Ran, Mode, bool),
    watcher: &mut dyn Watcher<A::Seen>,
    recorder: Option<McapRecorder>,
    (bridged, contracts, on_error): (bool, Option<&Live>, OnError),
) -> Result<(Status, String), AppError> {
    ran.conclude(watcher, app.finished(&ran.finished));
    let Ran {
        finished,
        ended,
        wall,
    } = ran;
    let report = finished.report();
    if report.probe_dropped > 0 {
        output::warn(format_args!(
            "{} probe reports found their channel full and were dropped: the judgement lacks them",
            report.probe_dropped
        ));
    }
    // A real-time run's recording gets its timing statistics; a deterministic
    // run has no wall clock, and none.
    let recorded = recorder.is_none_or(|r| match mode {
        Mode::RealTime => record::finish_timed(r, report, "local"),
        _ => record::finish(r),
    }) && bridged;
    if mode == Mode::RealTime {
        if !common.quiet {
            output::err(format_args!("{report}"));
        }
        output::out(format_args!(
            "rt_priority={} overruns={} executor_errors={}\n",
            if report.rt_priority() { "yes" } else { "no" },
            report.nodes.iter().map(|n| n.overruns).sum::<u64>(),
            report.error_count
        ));
    }
    // Under `continue` a broken contract is reported, and the run judged as
    // if it had not been; otherwise it fails the run.
    let kept = contracts.is_none_or(|live| contracts::say(live, common.quiet))
        || on_error == OnError::Continue;
    if let Some(t) = report.safe_stopped {
        output::err(format_args!(
            "safe-stopped at t={:.6}s: every subsystem halted, every device made safe",
            t.as_secs_f64()
        ));
    }
    // ... and its errors are not the run's.
    let (errors, first_errors) = contracts::run_errors(report, contracts, on_error);
    let summary = RunSummary {
        spec: spec.spec.name.clone(),
        mode,
        rule_stated,
        ended,
        last: report.last_instant,
        wall,
        errors,
        first_errors,
    };
    let verdict = output::judgement(watcher, &summary, common.verbose.then_some(&spec.spec));
    Ok((
        summary.status(verdict.passed && kept, recorded),
        verdict.line,
    ))
}
