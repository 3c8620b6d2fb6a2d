//! The application layer of embodied-agents: everything a robot program does
//! around its agents, for any agent crate.
//!
//! A crate gives the layer its spec, a function that builds the system from it
//! (for the whole spec, or for one process of a deployment), and optionally
//! hooks for what is its own (flags, probes and a watcher that decide when a
//! run has ended and judge it, files to write at the end). The layer gives it
//! a command line with the conventions of a Rust tool:
//!
//! * `run` (the default) in the deterministic executor, `--for SECONDS`, with a
//!   status line on standard error (`--quiet`) and a summary at the end;
//! * `--realtime`: the real-time executor and its timing table;
//! * `--record FILE.mcap` from either executor, and from every process of a
//!   deployment (each process's part, merged by the launcher);
//! * `--deployment NAME --process NAME`: one process of a deployment over
//!   Zenoh; `launch --deployment NAME [--kill PROCESS@SECONDS]...`: every
//!   process, restarted as the spec allows, one summary;
//! * `replay FILE.mcap --subsystem NAME`: the equivalence verdict or the first
//!   divergence;
//! * `--ros2[=ENDPOINT]` (feature `ros2`): the spec's `ros2` section's
//!   buffers published as ROS 2 topics over rmw_zenoh during any run;
//! * `check` and `diagram` of the crate's spec.
//!
//! Exit status: 0 the run succeeded, 1 it failed (or was stopped before its
//! end), 2 invalid input (nothing ran). SIGINT, SIGTERM and SIGHUP end every
//! run the same way as its own end does: each executor stops, prints its
//! summary and timing, and finishes its recording.
//!
//! The smallest program, for a crate whose spec lives in `spec.ron` and whose
//! `system::build` assembles it (see [`App`]):
//!
//! ```no_run
//! # mod system {
//! #     pub fn build(_: Option<&str>) -> Result<agent_core::System, agent_app::BoxError> {
//! #         unimplemented!("the crate's assembly of its spec")
//! #     }
//! # }
//! use agent_app::{App, End};
//!
//! fn main() -> std::process::ExitCode {
//!     App::new("spec.ron", include_str!("../../specs/tank.ron"))
//!         .build(|target| system::build(target.deployment()))
//!         .ends_when(End::halted(["c2"]))
//!         .main()
//! }
//! ```
//!
//! A larger program implements [`Application`] (Rex does: its missions, its
//! judgement against the simulation's truth, its report folder).

mod cli;
mod contracts;
mod credentials;
#[cfg(feature = "distributed")]
mod deploy;
mod error;
pub mod figures;
mod local;
mod output;
mod pair;
pub mod plot;
mod record;
mod replay;
pub mod report;
mod ros2;
pub mod settings;
mod signals;
mod simple;
mod spec_cmd;
pub mod table;
mod transitions;
mod watch;

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use agent_core::{ExecConfig, Finished, Probes, System};
use serde::Serialize;
use serde::de::DeserializeOwned;

/// `#[derive(Tally)]`: a struct's counts tallied field by field.
pub use agent_macros::Tally;
pub use cli::{
    BadFault, Cli, Command, Common, DiagramFormat, DiagramKind, NoFlags, OnErrorArg, ROS2_ENDPOINT,
    ThreadsArg, parse_fault,
};
pub use credentials::ROS2_LISTEN;
pub use error::{AppError, BoxError, Status};
pub use local::{Ran, Watched};
pub use output::{emit, writable_folder};
pub use pair::Pairs;
pub use signals::Signals;
pub use simple::App;
pub use watch::{End, Ended, Every, Mode, Quiet, RunSummary, Tally, Verdict, Watcher};

/// A spec as the layer uses it: the model, where it came from, its text (kept
/// in recordings).
#[derive(Clone, Debug)]
pub struct SpecFile {
    /// The checked model.
    pub spec: agent_spec::Spec,
    /// Its file name (for messages), or the name it was embedded under.
    pub path: String,
    /// Its text.
    pub text: String,
}

impl SpecFile {
    /// Load and check the spec in `text` (named `path` in messages): invalid
    /// input, with every finding, if it has an error.
    pub fn parse(path: impl Into<String>, text: impl Into<String>) -> Result<SpecFile, AppError> {
        let (path, text) = (path.into(), text.into());
        let (spec, report) = agent_spec::check_source(path.clone(), text.clone());
        match spec {
            Some(spec) if report.is_ok() => Ok(SpecFile { spec, path, text }),
            _ => Err(AppError::Invalid(format!(
                "specification {path}:\n{}",
                report.short()
            ))),
        }
    }

    /// Read, load and check the spec file at `path`.
    pub fn read(path: &Path) -> Result<SpecFile, AppError> {
        let text = std::fs::read_to_string(path)
            .map_err(|e| AppError::invalid(format!("specification {}: {e}", path.display())))?;
        SpecFile::parse(path.display().to_string(), text)
    }
}

/// What a system is built for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Target<'a> {
    /// The whole system in this process (`run`, `--realtime`).
    Whole,
    /// One process of a deployment: the system of the deployment is built (so
    /// its structure is checked the same everywhere) and the layer runs only
    /// the process's components.
    Process {
        /// The deployment.
        deployment: &'a str,
        /// The process.
        process: &'a str,
        /// A number new at every start of the process (0 for the first, `k`
        /// after the `k`-th restart).
        incarnation: u32,
        /// A number unique to this start of the process (an epoch), for a
        /// component that must tell its peers it started again; a replay
        /// gives the recorded one.
        boot: u64,
    },
}

impl Target<'_> {
    /// The deployment, if one process of one is built.
    pub fn deployment(&self) -> Option<&str> {
        match self {
            Target::Whole => None,
            Target::Process { deployment, .. } => Some(deployment),
        }
    }
}

/// Check that the components `names` run in one process of `deployment` in
/// `spec` (drivers that share the system's environment, say: a simulated
/// world), for [`Application::check_deployment`]. If not, invalid input that
/// says `why` (the rule, as the start of a sentence) and where each runs.
/// A deployment the spec lacks, and components it does not place, pass (the
/// layer names those).
pub fn check_together(
    spec: &agent_spec::Spec,
    deployment: &str,
    names: &[&str],
    why: &str,
) -> Result<(), AppError> {
    let Some(dep) = spec.deployment(deployment) else {
        return Ok(());
    };
    let mut places: Vec<(String, &str)> = names
        .iter()
        .filter_map(|n| Some((dep.process_of(n)?.name.clone(), *n)))
        .collect();
    places.sort();
    if places.windows(2).all(|w| w[0].0 == w[1].0) {
        return Ok(());
    }
    let places: Vec<String> = places
        .iter()
        .map(|(p, n)| format!("{n} runs in `{p}`"))
        .collect();
    Err(AppError::invalid(format!(
        "deployment `{deployment}`: {why}, but {}",
        places.join(", ")
    )))
}

/// What a program built on the layer is: its flags, the configurations of its
/// runs, how it builds its system, and what it watches. Only
/// [`configure`](Application::configure), [`spec`](Application::spec),
/// [`build`](Application::build) and [`watcher`](Application::watcher) have no
/// default. [`App`] implements it for a crate that needs no more than a spec
/// and a build function.
pub trait Application {
    /// The program's own flags, parsed beside the layer's ([`NoFlags`]: none).
    type Flags: clap::Args + Clone + fmt::Debug;
    /// Everything one run is built from, made from the command line. It is
    /// recorded with the run (as JSON), so it should be self-contained
    /// (absolute paths), and `replay` builds the same system from it.
    type Config: Serialize + DeserializeOwned + Clone + fmt::Debug;
    /// What the probes report to the watcher: it crosses processes in a
    /// deployment (postcard).
    type Seen: Serialize + DeserializeOwned + Send + 'static;

    /// The configurations to run from the command line (several run one after
    /// the other; a deployment, a recording and a replay take one). An error
    /// is invalid input: exit 2, nothing runs.
    fn configure(
        &mut self,
        flags: &Self::Flags,
        common: &Common,
    ) -> Result<Vec<Self::Config>, AppError>;

    /// The spec a configuration is built from.
    fn spec(&self, config: &Self::Config) -> Result<SpecFile, AppError>;

    /// Build the system of `config` for `target`. Keep what the probes and
    /// [`Application::finished`] need (handles) in `self`.
    fn build(&mut self, config: &Self::Config, target: &Target<'_>) -> Result<System, AppError>;

    /// The watcher of one run of `config`.
    fn watcher(&mut self, config: &Self::Config, common: &Common) -> Box<dyn Watcher<Self::Seen>>;

    /// Probes on the system just built, on the components `here` says this
    /// process runs. None by default.
    fn probes(&mut self, probes: &mut Probes<Self::Seen>, here: &dyn Fn(&str) -> bool) {
        let _ = (probes, here);
    }

    /// What to report when a run has ended, read from the nodes this process
    /// ran (counters kept in memories, for example). Nothing by default.
    fn finished(&mut self, run: &Finished) -> Vec<Self::Seen> {
        let _ = run;
        Vec::new()
    }

    /// The layer's part of the end rule (the watcher's is
    /// [`Watcher::ended`]). By default, only the time limit.
    fn end(&self, config: &Self::Config) -> End {
        let _ = config;
        End::Limit
    }

    /// The time limit when `--for` is not given. 10 s by default.
    fn limit(&self, config: &Self::Config) -> Duration {
        let _ = config;
        Duration::from_secs(10)
    }

    /// The executors' settings (error policy). Stop on the first error by
    /// default.
    fn exec(&self, config: &Self::Config) -> ExecConfig {
        let _ = config;
        ExecConfig::default()
    }

    /// A line said before a run starts (what runs), on standard error unless
    /// `--quiet`.
    fn announce(&self, config: &Self::Config) -> Option<String> {
        let _ = config;
        None
    }

    /// How runs are recorded (derived channels, codecs); the layer adds the
    /// spec and the configuration to its metadata.
    fn record_options(&self, config: &Self::Config) -> agent_mcap::RecordOptions {
        let _ = config;
        agent_mcap::RecordOptions::default()
    }

    /// How recordings are replayed. By default as they were recorded: with
    /// the codecs [`record_options`](Application::record_options) gives
    /// and the error policy of [`exec`](Application::exec).
    fn replay_options(&self, config: &Self::Config) -> agent_mcap::ReplayOptions {
        agent_mcap::ReplayOptions {
            exec: self.exec(config),
            codecs: self.record_options(config).codecs,
            ..agent_mcap::ReplayOptions::default()
        }
    }

    /// Where a run is recorded when `--record` is not given. Nowhere by
    /// default.
    fn default_record(&self, config: &Self::Config, common: &Common) -> Option<PathBuf> {
        let _ = (config, common);
        None
    }

    /// A recorded configuration, with the flags given to `replay` applied
    /// (the recorded one by default).
    fn reconfigure(
        &mut self,
        recorded: Self::Config,
        flags: &Self::Flags,
        common: &Common,
    ) -> Result<Self::Config, AppError> {
        let _ = (flags, common);
        Ok(recorded)
    }

    /// Checks of a deployment beyond the spec's (Rex: the simulated world's
    /// drivers in one process), made before a process or a launch runs.
    fn check_deployment(&self, config: &Self::Config, deployment: &str) -> Result<(), AppError> {
        let _ = (config, deployment);
        Ok(())
    }

    /// The adapters that make the standard ROS 2 messages the spec's `ros2`
    /// section names from buffer values (`--ros2`). None by default.
    #[cfg(feature = "ros2")]
    fn ros2_adapters(&self) -> agent_ros2::bridge::Adapters {
        agent_ros2::bridge::Adapters::new()
    }
}

/// What `--help` and `--version` say of a program.
#[derive(Clone, Copy, Debug)]
pub struct Program<'a> {
    /// Its name (`rex`).
    pub name: &'a str,
    /// Its version (`env!("CARGO_PKG_VERSION")`).
    pub version: &'a str,
    /// What it does, the text above the flags.
    pub about: &'a str,
}

/// Parse the command line and run `app`: the whole program.
pub fn main<A: Application>(app: A) -> ExitCode {
    run_main(app, None).into()
}

/// [`main`] with the program's name, version and description for `--help`.
pub fn main_with<A: Application>(app: A, program: Program<'_>) -> ExitCode {
    run_main(app, Some(program)).into()
}

fn run_main<A: Application>(mut app: A, program: Option<Program<'_>>) -> Status {
    use clap::{CommandFactory, FromArgMatches};
    let mut command = Cli::<A::Flags>::command();
    if let Some(p) = program {
        command = command
            .name(p.name.to_owned())
            .version(p.version.to_owned())
            .long_about(p.about.to_owned())
            .about(p.about.lines().next().unwrap_or_default().to_owned());
    } else if let Some(name) = std::env::args().next().and_then(|a| {
        Path::new(&a)
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
    }) {
        command = command.name(name);
    }
    let matches = command.get_matches();
    let cli = match Cli::<A::Flags>::from_arg_matches(&matches) {
        Ok(c) => c,
        Err(e) => e.exit(),
    };
    run(&mut app, &cli)
}

/// Run `app` as the command line `cli` says (for a program that parses its
/// command line itself); the exit status.
pub fn run<A: Application>(app: &mut A, cli: &Cli<A::Flags>) -> Status {
    // A run (in this process, one process of a deployment, a launch) stops at
    // a signal with its summary and its recording finished; the other
    // commands (a replay, the checker, a diagram) keep the signals' default
    // and end at once.
    if matches!(
        cli.command,
        None | Some(Command::Run | Command::Launch { .. })
    ) {
        let signals = Signals::get();
        if let Some(why) = signals.refused() {
            output::warn(format_args!(
                "cannot catch SIGINT/SIGTERM ({why}): a signal ends the program without its summary"
            ));
        }
    }
    match dispatch(app, cli) {
        Ok(status) => status,
        Err(e) => {
            output::error(&e);
            e.status()
        }
    }
}

fn dispatch<A: Application>(app: &mut A, cli: &Cli<A::Flags>) -> Result<Status, AppError> {
    let common = &cli.common;
    let command = cli.command.clone().unwrap_or(Command::Run);
    if let Command::Replay {
        file,
        subsystem,
        incarnation,
    } = &command
    {
        // What a replay does not take: it runs as long and as its recording.
        let run_only = [
            (common.limit.is_some(), "--for/--limit"),
            (common.realtime, "--realtime"),
            (common.record.is_some(), "--record"),
            (common.deployment.is_some(), "--deployment"),
            (common.process.is_some(), "--process"),
            (common.ros2.is_some(), "--ros2"),
        ];
        if let Some((_, flag)) = run_only.iter().find(|(given, _)| *given) {
            return Err(AppError::invalid(format!(
                "replay {}: {flag} is not for a replay (it runs as long as the recording, in the deterministic executor)",
                file.display()
            )));
        }
        return replay::replay(app, &cli.flags, common, file, subsystem, *incarnation);
    }
    common.limit()?;
    common.wait()?;
    let configs = app.configure(&cli.flags, common)?;
    let first = configs
        .first()
        .ok_or_else(|| AppError::invalid("nothing to run (no configuration)"))?;
    match command {
        Command::Check => return spec_cmd::check(&app.spec(first)?),
        Command::Diagram {
            kind,
            subsystem,
            format,
            output,
        } => {
            return spec_cmd::diagram(
                &app.spec(first)?,
                kind,
                subsystem.as_deref(),
                format,
                output.as_deref(),
            );
        }
        Command::Ros2Package { dir } => {
            let config = first.clone();
            return ros2::package(app, &config, common, &dir);
        }
        Command::Credentials { dir, ros2_listen } => {
            let config = first.clone();
            return credentials::credentials(app, &config, common, &dir, ros2_listen.as_deref());
        }
        Command::Replay { .. } | Command::Run | Command::Launch { .. } => {}
    }
    let one = |what: &str| -> Result<&A::Config, AppError> {
        match configs.as_slice() {
            [one] => Ok(one),
            _ => Err(AppError::invalid(format!(
                "{what} takes one run at a time ({} configurations given)",
                configs.len()
            ))),
        }
    };
    if let Some(file) = &common.record {
        record::check_target(file)
            .map_err(|e| AppError::invalid(format!("--record {}: {e}", file.display())))?;
        one(&format!("--record {}", file.display()))?;
    }
    if let Command::Launch { kill } = &command {
        let config = one("launch")?.clone();
        return launch(app, config, common, kill);
    }
    if common.process.is_some() {
        let config = one("--process")?.clone();
        return process(app, config, common);
    }
    if common.deployment.is_some() {
        return Err(AppError::invalid(
            "--deployment runs a deployment with `launch` (every process) or with `--process NAME` (one of them)",
        ));
    }
    run_each(app, &configs, common)
}

/// Run each configuration in this process, in turn, until a signal; then
/// print their figure lines, also when a later run could not be made (its
/// error then decides the status).
fn run_each<A: Application>(
    app: &mut A,
    configs: &[A::Config],
    common: &Common,
) -> Result<Status, AppError> {
    let mut status = Status::Success;
    let mut lines = Vec::new();
    let mut failed = None;
    for config in configs {
        match local::run(app, config, common) {
            Ok((s, line)) => {
                status = status.and(s);
                lines.push(line);
            }
            Err(e) => {
                failed = Some(e);
                break;
            }
        }
        if Signals::get().stopping() {
            break;
        }
    }
    for line in lines {
        output::out(format_args!("{line}\n"));
    }
    match failed {
        Some(e) => Err(e),
        None => Ok(status),
    }
}

#[cfg(feature = "distributed")]
fn launch<A: Application>(
    app: &mut A,
    config: A::Config,
    common: &Common,
    kill: &[(String, f64)],
) -> Result<Status, AppError> {
    deploy::launch::launch(app, config, common, kill)
}

#[cfg(feature = "distributed")]
fn process<A: Application>(
    app: &mut A,
    config: A::Config,
    common: &Common,
) -> Result<Status, AppError> {
    deploy::process::run(app, config, common)
}

#[cfg(not(feature = "distributed"))]
fn launch<A: Application>(
    _: &mut A,
    _: A::Config,
    _: &Common,
    _: &[(String, f64)],
) -> Result<Status, AppError> {
    Err(AppError::invalid(
        "built without the feature `distributed`: no deployments over Zenoh",
    ))
}

#[cfg(not(feature = "distributed"))]
fn process<A: Application>(_: &mut A, _: A::Config, _: &Common) -> Result<Status, AppError> {
    Err(AppError::invalid(
        "built without the feature `distributed`: no deployments over Zenoh",
    ))
}

/// The metadata a recording of `config` keeps: the spec and the configuration.
pub(crate) fn recorded_metadata<A: Application>(
    spec: &SpecFile,
    config: &A::Config,
) -> Result<BTreeMap<String, BTreeMap<String, String>>, AppError> {
    let config = serde_json::to_string(config)
        .map_err(|e| AppError::invalid(format!("the run's configuration does not record: {e}")))?;
    Ok(BTreeMap::from([
        (
            "spec".to_owned(),
            BTreeMap::from([
                ("name".to_owned(), spec.spec.name.clone()),
                ("path".to_owned(), spec.path.clone()),
                ("text".to_owned(), spec.text.clone()),
            ]),
        ),
        (
            "app".to_owned(),
            BTreeMap::from([
                ("config".to_owned(), config),
                (
                    "layer".to_owned(),
                    concat!("agent-app ", env!("CARGO_PKG_VERSION")).to_owned(),
                ),
            ]),
        ),
    ]))
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use agent_core::OnError;

    use super::*;

    /// A codec that encodes a value as its own bytes.
    struct Plain;

    impl agent_mcap::Codec for Plain {
        fn payload(&self) -> &str {
            "u8"
        }
        fn name(&self) -> &str {
            "plain/1"
        }
        fn encode(&self, body: &[u8], out: &mut Vec<u8>) {
            out.extend_from_slice(body);
        }
        fn decode(&self, data: &[u8], out: &mut Vec<u8>) -> Result<(), agent_mcap::DecodeError> {
            out.extend_from_slice(data);
            Ok(())
        }
    }

    /// A program that records with a codec and continues on errors, and
    /// says nothing of how it replays.
    struct Coded;

    impl Application for Coded {
        type Flags = NoFlags;
        type Config = ();
        type Seen = ();

        fn configure(&mut self, _: &NoFlags, _: &Common) -> Result<Vec<()>, AppError> {
            Ok(vec![()])
        }
        fn spec(&self, _: &()) -> Result<SpecFile, AppError> {
            SpecFile::parse("tank.ron", include_str!("../../specs/tank.ron"))
        }
        fn build(&mut self, _: &(), _: &Target<'_>) -> Result<System, AppError> {
            Err(AppError::invalid("not built in this test"))
        }
        fn watcher(&mut self, _: &(), _: &Common) -> Box<dyn Watcher<()>> {
            Box::new(Quiet)
        }
        fn exec(&self, _: &()) -> ExecConfig {
            ExecConfig {
                on_error: OnError::Continue,
                ..ExecConfig::default()
            }
        }
        fn record_options(&self, _: &()) -> agent_mcap::RecordOptions {
            agent_mcap::RecordOptions {
                codecs: vec![Arc::new(Plain)],
                ..agent_mcap::RecordOptions::default()
            }
        }
    }

    #[test]
    fn a_recording_replays_by_default_with_its_codecs_and_error_policy() {
        let options = Coded.replay_options(&());
        let codecs: Vec<&str> = options.codecs.iter().map(|c| c.name()).collect();
        assert_eq!(codecs, ["plain/1"]);
        assert_eq!(options.exec.on_error, OnError::Continue);
        assert_eq!(options.window, None);
    }

    #[test]
    fn components_apart_in_a_deployment_are_named_with_their_processes() {
        let tank = SpecFile::parse("tank.ron", include_str!("../../specs/tank.ron"));
        let Ok(tank) = tank else {
            panic!("the tank's spec is valid");
        };
        let why = "they share the tank and must run in one process";
        for deployment in ["split", "simulation", "no such deployment"] {
            assert!(check_together(&tank.spec, deployment, &["E1", "R1"], why).is_ok());
        }
        let apart = check_together(&tank.spec, "split", &["E1", "c2", "R1"], why);
        assert_eq!(
            apart.map_err(|e| e.to_string()),
            Err(
                "deployment `split`: they share the tank and must run in one process, but c2 runs in `operator`, E1 runs in `station`, R1 runs in `station`"
                    .to_owned()
            )
        );
    }
}
