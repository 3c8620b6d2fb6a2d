//! `launch --deployment NAME`: every process of a deployment started as a
//! child of this program, their output prefixed with their names, a crashed
//! one restarted as often as the spec allows, the run watched through what the
//! processes report, ended by its rule (every process stopped then), and
//! judged once for the whole deployment.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

use agent_zenoh::{Child, Control, LaunchReport, Launcher, Line, Options, Watch};

use super::process::part_path;
use super::{NOTE, Note, SEEN};
use crate::error::{AppError, Status};
use crate::watch::{Ended, FIRST_ERRORS, Mode, RunSummary, Watcher};
use crate::{Application, Common, Signals, output};

/// How long processes get to end by themselves after the launcher asked them
/// to stop, before they are sent SIGTERM.
const STOP_GRACE: Duration = Duration::from_secs(10);

/// The flags `launch` gives its children, and the flags of its own that it
/// does not pass on (with whether they take a value).
const OWN_FLAGS: [(&str, bool); 5] = [
    ("--kill", true),
    ("--record", true),
    ("--launch-id", true),
    ("--launcher-pid", true),
    ("--incarnation", true),
];

/// The arguments of the children: this program's, without `launch` and its
/// own flags. An argument that is not UTF-8 is refused (the children are
/// given their arguments as text).
fn child_args() -> Result<Vec<String>, AppError> {
    let given: Vec<String> = std::env::args_os()
        .skip(1)
        .map(|a| {
            a.into_string().map_err(|a| {
                AppError::invalid(format!(
                    "launch: the argument {} is not UTF-8 text, which the processes are started with",
                    a.to_string_lossy()
                ))
            })
        })
        .collect::<Result<_, _>>()?;
    let mut args = Vec::new();
    let mut given = given.into_iter();
    let mut launch_seen = false;
    while let Some(a) = given.next() {
        if !launch_seen && a == "launch" {
            launch_seen = true;
            continue;
        }
        if let Some((_, takes)) = OWN_FLAGS.iter().find(|(f, _)| a == *f) {
            if *takes {
                given.next();
            }
            continue;
        }
        if OWN_FLAGS
            .iter()
            .any(|(f, takes)| *takes && a.starts_with(&format!("{f}=")))
        {
            continue;
        }
        args.push(a);
    }
    Ok(args)
}

/// The part of a recording each process writes: `<stem>.{process}.mcap`
/// beside `file`.
fn parts_pattern(file: &Path) -> PathBuf {
    let stem = file
        .file_stem()
        .map_or_else(|| "record".to_owned(), |s| s.to_string_lossy().into_owned());
    file.with_file_name(format!("{stem}.{{process}}.mcap"))
}

/// A new launch's identity: unique among the launches that meet on a network.
fn launch_id() -> String {
    format!("{:016x}", agent_core::link::remote::new_epoch())
}

/// What the launcher gathers from the processes' reports.
struct Gathered {
    halted: Vec<String>,
    errors: u64,
    refused: u64,
    acl_refused: u64,
    first_errors: Vec<String>,
    last_ns: u64,
    undecodable: u64,
}

/// Start and watch every process of `--deployment`.
pub(crate) fn launch<A: Application>(
    app: &mut A,
    config: A::Config,
    common: &Common,
    kill: &[(String, f64)],
) -> Result<Status, AppError> {
    let signals = Signals::get();
    let spec = app.spec(&config)?;
    let (deployment, dep) = launched_deployment(app, &config, &spec, common, kill)?;
    let processes = dep.processes();
    let command = ChildCommand::make(&spec.spec, deployment, dep.is_secure(), common, signals)?;
    let watch = Watch::open(&spec.spec, deployment, &command.options)?;
    let children: Vec<Child> = processes
        .iter()
        .map(|(_, p, _)| command.child(&p.name, p.restart_budget()))
        .collect();
    let budgets: Vec<(String, u32)> = processes
        .iter()
        .map(|(_, p, _)| (p.name.clone(), p.restart_budget()))
        .collect();
    let end = app.end(&config);
    let rule: Vec<String> = match &end {
        crate::End::Limit => Vec::new(),
        crate::End::Halted(names) => names.clone(),
    };
    let mut watcher = app.watcher(&config, common);
    let mut monitor = Monitor::new(&watch, rule, kill.to_vec());
    let wall = Instant::now();
    let report = Launcher::new(children)
        .fatal_codes([2])
        .run(&signals.flag(), |line| monitor.on(line, watcher.as_mut()))?;
    let Monitor {
        mut gathered,
        ended,
        ..
    } = monitor;
    // What arrived after the processes ended.
    take(
        &watch,
        watcher.as_mut(),
        &mut gathered,
        Duration::from_millis(300),
    );
    watcher.ended(true);
    if gathered.undecodable > 0 {
        output::warn(format_args!(
            "{} reports of the processes did not decode (a process of another build?); the judgement lacks them",
            gathered.undecodable
        ));
    }
    // The parts are merged however the launch ended: a process that could
    // not start again (below) leaves what the others recorded.
    let recorded = match (&common.record, &command.pattern) {
        (Some(file), Some(pattern)) => {
            let parts = parts_of(pattern, &budgets, report.restarts);
            let none = parts.is_empty() && report.fatal.is_some();
            none || merge_parts(file, &parts, &command.launch, budgets.len())
        }
        _ => true,
    };
    if let Some((process, code)) = &report.fatal {
        return Err(AppError::invalid(format!(
            "process `{process}` cannot run (exit {code}: invalid input, see its lines above); the launch ended"
        )));
    }
    let ended = launch_end(&report, ended.map(|(e, _)| e), &budgets, signals);
    let summary = RunSummary {
        spec: spec.spec.name.clone(),
        mode: Mode::Launched {
            deployment: deployment.clone(),
            processes: report.processes,
            restarts: report.restarts,
        },
        rule_stated: end.is_stated(),
        ended,
        last: agent_core::Time::from_nanos(gathered.last_ns),
        wall: wall.elapsed(),
        errors: gathered.errors,
        first_errors: std::mem::take(&mut gathered.first_errors),
    };
    Ok(say_verdict(
        watcher.as_mut(),
        (&summary, common.verbose.then_some(&spec.spec)),
        &gathered,
        &report,
        recorded,
    ))
}

/// The deployment `--deployment` names, checked for a launch: `--process` not
/// given, its port, the application's own checks, the processes `--kill`
/// names (an unprotected deployment is said).
fn launched_deployment<'s, A: Application>(
    app: &A,
    config: &A::Config,
    spec: &'s crate::SpecFile,
    common: &'s Common,
    kill: &[(String, f64)],
) -> Result<(&'s String, &'s agent_spec::model::Deployment), AppError> {
    let Some(deployment) = &common.deployment else {
        return Err(AppError::invalid(format!(
            "`launch` needs `--deployment NAME` (the spec's deployments: {})",
            spec.spec.deployment_names()
        )));
    };
    let Some(dep) = spec.spec.deployment(deployment) else {
        return Err(AppError::invalid(format!(
            "spec `{}` has no deployment `{deployment}` (it has: {})",
            spec.spec.name,
            spec.spec.deployment_names()
        )));
    };
    if common.process.is_some() {
        return Err(AppError::invalid(
            "`launch` starts every process; `--process` runs one without it",
        ));
    }
    if let Some(endpoint) = &common.ros2
        && dep.is_secure()
        && common.credentials.is_none()
    {
        return Err(AppError::invalid(format!(
            "--ros2={endpoint}: deployment `{deployment}` is secure, and the ROS 2 router must know its certificates (credentials made for one launch would be unknown to it): make them with `{} credentials --deployment {deployment} DIR`, start the router with DIR/ros2_router.json5, and launch with --credentials DIR",
            output::program()
        )));
    }
    super::check_port(&spec.spec, deployment, common.port)?;
    app.check_deployment(config, deployment)?;
    super::say_unprotected(&spec.spec, deployment);
    let processes = dep.processes();
    if let Some((p, _)) = kill
        .iter()
        .find(|(p, _)| !processes.iter().any(|(_, q, _)| q.name == *p))
    {
        return Err(AppError::invalid(format!(
            "--kill: deployment `{deployment}` has no process `{p}`"
        )));
    }
    Ok((deployment, dep))
}

/// How the children are started: this program, with this program's arguments
/// less the launcher's own and plus the launch's, and the launch's options.
struct ChildCommand {
    program: PathBuf,
    args: Vec<String>,
    /// The pattern of the recording's parts, if `--record` was given.
    pattern: Option<PathBuf>,
    /// The launch's identity ([`launch_id`]).
    launch: String,
    options: Options,
    /// Held to the launch's end, which removes them.
    _dev: Option<DevCredentials>,
}

impl ChildCommand {
    /// The command of a new launch of `deployment` (with credentials of its
    /// own for a secure one given none).
    fn make(
        spec: &agent_spec::Spec,
        deployment: &str,
        secure: bool,
        common: &Common,
        signals: &Signals,
    ) -> Result<ChildCommand, AppError> {
        let program = std::env::current_exe().map_err(|e| {
            AppError::Run(format!(
                "cannot find this program to start the processes: {e}"
            ))
        })?;
        let id = launch_id();
        let mut args = child_args()?;
        let pattern = common.record.as_deref().map(parts_pattern);
        if let Some(p) = &pattern {
            args.push("--record".into());
            args.push(p.to_string_lossy().into_owned());
        }
        args.extend([
            "--launch-id".to_owned(),
            id.clone(),
            "--launcher-pid".to_owned(),
            std::process::id().to_string(),
        ]);
        let mut options = Options {
            port: common.port,
            timeout: common.wait()?,
            credentials: common.credentials.clone(),
            launch: Some(id.clone()),
            launched: false,
            cancel: Some(signals.flag()),
        };
        let mut dev = None;
        if secure && options.credentials.is_none() {
            let made = DevCredentials::make(spec, deployment, &id)?;
            output::err(format_args!(
                "{}: deployment `{deployment}` is secure: a development authority and certificates for this launch in {} (removed at its end)",
                output::program(),
                made.dir.display()
            ));
            args.push("--credentials".into());
            args.push(made.dir.to_string_lossy().into_owned());
            options.credentials = Some(made.dir.clone());
            dev = Some(made);
        }
        Ok(ChildCommand {
            program,
            args,
            pattern,
            launch: id,
            options,
            _dev: dev,
        })
    }

    /// The child that runs process `name`, restarted at most `restarts` times.
    fn child(&self, name: &str, restarts: u32) -> Child {
        Child {
            restarts: Some(restarts),
            incarnation_flag: Some("--incarnation".into()),
            ..Child::new(
                name.to_owned(),
                self.program.clone(),
                self.args
                    .iter()
                    .cloned()
                    .chain(["--process".to_owned(), name.to_owned()])
                    .collect(),
            )
        }
    }
}

/// The launcher's view of the run while the processes run: what they
/// report, whether the run has reached its end, instant zero, the kills
/// `--kill` asked for.
struct Monitor<'w> {
    watch: &'w Watch,
    /// The end rule's subsystems: the run ends once all have halted.
    rule: Vec<String>,
    gathered: Gathered,
    /// How the run ended and when it was seen, once it has.
    ended: Option<(Ended, Instant)>,
    /// The deployment's instant zero once known, and when to look next.
    origin: Option<SystemTime>,
    next_origin_look: Instant,
    /// The kills not yet made: the process and when (s from instant zero).
    faults: Vec<(String, f64)>,
}

impl<'w> Monitor<'w> {
    fn new(watch: &'w Watch, rule: Vec<String>, faults: Vec<(String, f64)>) -> Self {
        Monitor {
            watch,
            rule,
            gathered: Gathered {
                halted: Vec::new(),
                errors: 0,
                refused: 0,
                acl_refused: 0,
                first_errors: Vec::new(),
                last_ns: 0,
                undecodable: 0,
            },
            ended: None,
            origin: None,
            next_origin_look: Instant::now(),
            faults,
        }
    }

    /// One line or exit of a child (or a moment idle): said, the reports
    /// taken in, and what the launcher does next.
    fn on<M: serde::de::DeserializeOwned>(
        &mut self,
        line: &Line,
        watcher: &mut dyn Watcher<M>,
    ) -> Control {
        say_line(line);
        take(self.watch, watcher, &mut self.gathered, Duration::ZERO);
        self.look_for_end(watcher);
        if let Some((_, since)) = &self.ended {
            // The run is over and its processes are stopping: a kill now
            // would be taken for a crash and restarted.
            return if since.elapsed() > STOP_GRACE {
                Control::Stop
            } else {
                Control::Continue
            };
        }
        self.look_for_origin();
        self.fault_due()
    }

    /// Whether the run has reached its end (the application's, or the end
    /// rule's subsystems all halted): then every process is asked to stop.
    fn look_for_end<M>(&mut self, watcher: &mut dyn Watcher<M>) {
        if self.ended.is_some() {
            return;
        }
        let by_rule =
            !self.rule.is_empty() && self.rule.iter().all(|r| self.gathered.halted.contains(r));
        if watcher.ended(false) {
            self.ended = Some((
                Ended::Rule("the application's end was reached".into()),
                Instant::now(),
            ));
        } else if by_rule {
            self.ended = Some((
                Ended::Rule(format!("{} halted", self.rule.join(", "))),
                Instant::now(),
            ));
        }
        if self.ended.is_some() {
            self.watch.stop();
        }
    }

    /// The deployment's instant zero, looked for every 500 ms until known.
    fn look_for_origin(&mut self) {
        if self.origin.is_none() && Instant::now() >= self.next_origin_look {
            self.origin = self.watch.origin();
            self.next_origin_look = Instant::now() + Duration::from_millis(500);
        }
    }

    /// The kill `--kill` asks for now, if any (said), else go on.
    fn fault_due(&mut self) -> Control {
        let now = self
            .origin
            .and_then(|o| SystemTime::now().duration_since(o).ok())
            .map_or(0.0, |d| d.as_secs_f64());
        let origin = self.origin;
        if let Some(k) = self
            .faults
            .iter()
            .position(|(_, at)| origin.is_some() && now >= *at)
        {
            let (process, at) = self.faults.remove(k);
            output::err(format_args!(
                "{}: killing `{process}` at {now:.2} s (--kill {process}@{at})",
                output::program()
            ));
            return Control::Kill(process);
        }
        Control::Continue
    }
}

/// A child's line, prefixed with its name, or its exit.
fn say_line(line: &Line) {
    match line {
        Line::Output { process, text } => {
            output::err(format_args!("[{process}] {text}"));
        }
        Line::Exited {
            process,
            code,
            restarting,
        } => output::err(format_args!(
            "[{process}] exited ({}){}",
            code.map_or("killed by a signal".to_owned(), |c| format!("status {c}")),
            if *restarting { "; restarting it" } else { "" }
        )),
        Line::Idle => {}
    }
}

/// The judgement of the whole deployment's run, said with what the
/// processes refused and the launch's figures (and the spec's timing
/// certificate, given `timing`: `--verbose`): its status.
fn say_verdict<M>(
    watcher: &mut dyn Watcher<M>,
    (summary, timing): (&RunSummary, Option<&agent_spec::Spec>),
    gathered: &Gathered,
    report: &LaunchReport,
    recorded: bool,
) -> Status {
    let verdict = output::judgement(watcher, summary, timing);
    if gathered.acl_refused > 0 {
        output::out(format_args!(
            "security acl_refused={} (messages the access control refused; each process names them)\n",
            gathered.acl_refused
        ));
    }
    if gathered.refused > 0 {
        output::out(format_args!(
            "links refused={} (messages from outside the deployment, undecodable or implausible; each process names its links)\n",
            gathered.refused
        ));
    }
    output::out(format_args!(
        "{} processes={} restarts={}\n",
        verdict.line, report.processes, report.restarts
    ));
    summary.status(verdict.passed, recorded)
}

/// How a launch ended.
fn launch_end(
    report: &LaunchReport,
    by_rule: Option<Ended>,
    budgets: &[(String, u32)],
    signals: &Signals,
) -> Ended {
    if let Some((process, code, restarts)) = &report.lost {
        let how = code.map_or("killed by a signal".to_owned(), |c| format!("status {c}"));
        let budget = budgets
            .iter()
            .find(|(p, _)| p == process)
            .map_or(0, |(_, b)| *b);
        return Ended::Stopped(if budget == 0 {
            format!(
                "process `{process}` ended ({how}) and may not be restarted (`restarts: 0` in the spec)"
            )
        } else {
            format!(
                "process `{process}` ended ({how}) after {restarts} restarts, all the spec allows (`restarts: {budget}`)"
            )
        });
    }
    if let Some(sig) = signals.received() {
        return Ended::Stopped(format!("{sig} received"));
    }
    by_rule.unwrap_or(Ended::Limit)
}

/// Take the processes' reports in (waiting at most `wait` for the first).
fn take<M: serde::de::DeserializeOwned>(
    watch: &Watch,
    watcher: &mut dyn Watcher<M>,
    g: &mut Gathered,
    wait: Duration,
) {
    let mut wait = wait;
    while let Some((process, name, bytes)) = watch.next(wait) {
        wait = Duration::ZERO.max(wait.min(Duration::from_millis(100)));
        match name.as_str() {
            SEEN => match postcard::from_bytes::<M>(&bytes) {
                Ok(m) => watcher.see(m),
                Err(e) => {
                    if g.undecodable == 0 {
                        output::warn(format_args!("a report of `{process}` does not decode: {e}"));
                    }
                    g.undecodable += 1;
                }
            },
            NOTE => match postcard::from_bytes::<Note>(&bytes) {
                Ok(Note::Halted(node)) => {
                    if !g.halted.contains(&node) {
                        g.halted.push(node);
                    }
                }
                Ok(Note::Ended {
                    errors,
                    first_errors,
                    last_ns,
                    refused,
                    acl_refused,
                    ..
                }) => {
                    g.errors = g.errors.saturating_add(errors);
                    g.refused = g.refused.saturating_add(refused);
                    g.acl_refused = g.acl_refused.saturating_add(acl_refused);
                    g.first_errors.extend(
                        first_errors
                            .into_iter()
                            .map(|e| format!("{process}: {e}"))
                            .take(FIRST_ERRORS.saturating_sub(g.first_errors.len())),
                    );
                    g.last_ns = g.last_ns.max(last_ns);
                }
                Err(_) => g.undecodable += 1,
            },
            _ => g.undecodable += 1,
        }
    }
}

/// The parts of the recording named by `pattern` that are on disk, of each
/// start a launch with `restarts` restarts in all can have had (no process
/// restarted more often than that, nor than its budget).
fn parts_of(pattern: &Path, processes: &[(String, u32)], restarts: u32) -> Vec<PathBuf> {
    processes
        .iter()
        .flat_map(|(p, budget)| (0..=restarts.min(*budget)).map(move |k| part_path(pattern, p, k)))
        .filter(|f| f.exists())
        .collect()
}

/// Merge the `parts` of the `processes` processes that launch `launch`
/// recorded into `file`; whether it went. A part an earlier launch left
/// under the same name is left out, and said.
fn merge_parts(file: &Path, parts: &[PathBuf], launch: &str, processes: usize) -> bool {
    match agent_mcap::merge_launch(parts, file, launch) {
        Ok(m) => {
            let size = std::fs::metadata(file).map_or(0, |m| m.len());
            let restarts = m.files.saturating_sub(processes);
            output::out(format_args!(
                "record: {} (merged from {} processes{}: {} messages on {} channels, {:.1} MB{})\n",
                file.display(),
                m.files - restarts,
                if restarts > 0 {
                    format!(" and {restarts} restarts")
                } else {
                    String::new()
                },
                m.messages,
                m.channels,
                size as f64 / 1e6,
                if m.finished {
                    ""
                } else {
                    "; a process did not finish its part"
                }
            ));
            for cut in &m.cut_short {
                output::out(format_args!(
                    "record: a part cut short, kept up to there: {cut}\n"
                ));
            }
            for old in &m.left_out {
                output::out(format_args!(
                    "record: {} left out: another launch recorded it\n",
                    old.display()
                ));
            }
            true
        }
        Err(e) => {
            output::error(&format_args!("--record {}: {e}", file.display()));
            false
        }
    }
}

/// A development authority and certificates made for one launch of a
/// deployment, in the run's folder
/// (`target/<program>-credentials/<deployment>/<launch>/`), removed when the
/// launch ends. Each launch its own: two launches of one deployment at once do
/// not overwrite each other's keys under their running processes (a process
/// restarted would read the other's and no longer be trusted), and a process
/// of one launch cannot even connect to another's.
struct DevCredentials {
    dir: PathBuf,
}

impl DevCredentials {
    /// The file naming a launch's launcher in its folder.
    const LAUNCHER: &'static str = "launcher.pid";

    fn make(spec: &agent_spec::Spec, deployment: &str, launch: &str) -> Result<Self, AppError> {
        use agent_zenoh::security::{AccessPolicy, create_dev_authority};
        let parent = PathBuf::from("target")
            .join(format!("{}-credentials", output::program()))
            .join(deployment);
        Self::sweep(&parent);
        let dir = parent.join(launch);
        let policy = AccessPolicy::of(spec, deployment).map_err(AppError::invalid)?;
        let hosts: Vec<String> = spec
            .deployment(deployment)
            .into_iter()
            .flat_map(|d| &d.hosts)
            .filter_map(|h| h.address.clone())
            .collect();
        // From here the folder is this launch's: removed on any way out.
        let made = DevCredentials { dir };
        create_dev_authority(&made.dir, &policy, &hosts)
            .map_err(|e| AppError::Run(e.to_string()))?;
        std::fs::write(
            made.dir.join(Self::LAUNCHER),
            std::process::id().to_string(),
        )
        .map_err(|e| {
            AppError::Run(format!(
                "cannot write {}: {e}",
                made.dir.join(Self::LAUNCHER).display()
            ))
        })?;
        Ok(made)
    }

    /// Remove the folders of launches whose launcher is gone (killed before
    /// it could remove them).
    fn sweep(parent: &Path) {
        let Ok(entries) = std::fs::read_dir(parent) else {
            return;
        };
        for entry in entries.flatten() {
            let dir = entry.path();
            let pid = std::fs::read_to_string(dir.join(Self::LAUNCHER))
                .ok()
                .and_then(|text| text.trim().parse::<i32>().ok());
            let gone = pid.is_some_and(|pid| {
                nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid), None)
                    == Err(nix::errno::Errno::ESRCH)
            });
            if gone {
                let _ = std::fs::remove_dir_all(&dir);
            }
        }
    }
}

impl Drop for DevCredentials {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}
