//! The command line every application gets: the layer's flags and commands,
//! with the application's own flags beside them.

use std::path::PathBuf;
use std::time::Duration;

use clap::{Args, Parser, Subcommand, ValueEnum};

use crate::error::AppError;

/// No flags of the application's own.
#[derive(Args, Clone, Debug, Default)]
pub struct NoFlags {}

/// The whole command line: the layer's flags, the application's `F`, a command.
#[derive(Parser, Debug)]
#[command(args_override_self = true)]
pub struct Cli<F: Args> {
    /// The layer's flags.
    #[command(flatten)]
    pub common: Common,
    /// The application's own flags.
    #[command(flatten)]
    pub flags: F,
    /// What to do (default: run).
    #[command(subcommand)]
    pub command: Option<Command>,
}

/// `--on-error`: the executors' error policy ([`agent_core::OnError`]).
#[derive(ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum OnErrorArg {
    /// Stop the run at the error.
    Stop,
    /// Report the error and go on.
    Continue,
    /// Safe-stop: halt every subsystem, make every device safe, go on.
    SafeStop,
}

impl From<OnErrorArg> for agent_core::OnError {
    fn from(a: OnErrorArg) -> Self {
        match a {
            OnErrorArg::Stop => agent_core::OnError::Stop,
            OnErrorArg::Continue => agent_core::OnError::Continue,
            OnErrorArg::SafeStop => agent_core::OnError::SafeStop,
        }
    }
}

/// How `--realtime` (and each process of a deployment) puts subsystems on
/// threads ([`agent_core::Threading`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum ThreadsArg {
    /// A worker per core and period, the agents dealt over the cores (the
    /// default).
    #[default]
    Pool,
    /// The pool, each worker pinned to its core.
    Pinned,
    /// A thread per subsystem.
    PerSubsystem,
}

impl From<ThreadsArg> for agent_core::Threading {
    fn from(a: ThreadsArg) -> Self {
        match a {
            ThreadsArg::Pool => agent_core::Threading::default(),
            ThreadsArg::Pinned => agent_core::Threading::pinned(0),
            ThreadsArg::PerSubsystem => agent_core::Threading::PerSubsystem,
        }
    }
}

/// The flags of every application built on the layer.
#[derive(Args, Clone, Debug, Default)]
pub struct Common {
    /// Run for at most SECONDS: virtual time in the deterministic executor,
    /// wall-clock time in real time (positive, at most 10,000,000). The run
    /// ends earlier by its own rule.
    #[arg(
        long = "for",
        visible_alias = "limit",
        global = true,
        value_name = "SECONDS",
        allow_negative_numbers = true
    )]
    pub limit: Option<f64>,
    /// Run in real time, as on the robot: the subsystems on worker threads
    /// (`--threads`) and the drivers that share the world on one, on absolute
    /// deadlines of the wall clock, with SCHED_FIFO priority and locked memory
    /// where the OS grants them (what it refuses is reported). Prints each
    /// node's period, wake-up jitter, compute time and overruns.
    #[arg(long, global = true)]
    pub realtime: bool,
    /// How a real-time run (`--realtime`, each process of a deployment) puts
    /// subsystems on threads: `pool` (a worker per core and period), `pinned`
    /// (the pool, each worker pinned to its core), `per-subsystem` (a thread
    /// each).
    #[arg(
        long,
        global = true,
        value_enum,
        value_name = "HOW",
        default_value = "pool"
    )]
    pub threads: ThreadsArg,
    /// Record the run to this MCAP file (open it in Foxglove; `replay` it):
    /// every value sent on a link, with its type's schema, and as exact bytes;
    /// each behaviour switch with its predicates' values; errors; the spec and
    /// the run's configuration. With `--process`, this process's part
    /// (`{process}` in the path is its name); with `launch`, every process
    /// records `<stem>.<process>.mcap` (a restart `<stem>.<process>.<k>.mcap`)
    /// and the parts are merged into FILE at the end.
    #[arg(long, global = true, value_name = "FILE")]
    pub record: Option<PathBuf>,
    /// Print only the summary (no progress, no timing table).
    #[arg(long, short, global = true)]
    pub quiet: bool,
    /// What an error does, a node's or a broken contract's (the spec's
    /// `contracts`, watched in every executor and process): `stop` the run
    /// there (it fails), `continue` (report it and go on; a broken contract
    /// is counted in `contracts_violated=` but does not fail the run), or
    /// `safe-stop` (every subsystem halted and every device made safe, Rex's
    /// platform braking and holding, the run going on to its end, and
    /// failing). Default: the application's (a deployment's processes:
    /// `continue`).
    #[arg(long, global = true, value_name = "POLICY")]
    pub on_error: Option<OnErrorArg>,
    /// Print every FSM transition as it happens (`t=0.100000 s c2: ask ->
    /// wait (arc 0, when true)`), on standard output.
    #[arg(long, global = true)]
    pub transitions: bool,
    /// Also print the spec's timing certificate after the summary (the text
    /// of a report folder's `timing.txt`: `embodied check --timing`'s
    /// analysis of the spec as one process on one host).
    #[arg(long, global = true)]
    pub verbose: bool,
    /// A deployment of the spec to run split into processes over Zenoh (with
    /// `--process`, or `launch`).
    #[arg(long, global = true, value_name = "NAME")]
    pub deployment: Option<String>,
    /// Run only this process of `--deployment`, in real time; the others are
    /// reached over Zenoh at the endpoints the spec gives.
    #[arg(long, global = true, value_name = "NAME", requires = "deployment")]
    pub process: Option<String>,
    /// The first port of the deployment's endpoints (replaces the spec's, so
    /// that two runs of a deployment do not meet; 1024-65535, and the last
    /// process's port must fit too).
    #[arg(long, global = true, value_name = "PORT")]
    pub port: Option<u16>,
    /// How long a process waits for the others before it fails naming them,
    /// in seconds (replaces the spec's `timeout_ms`).
    #[arg(long, global = true, value_name = "SECONDS")]
    pub wait: Option<f64>,
    /// The credentials of a secure deployment: a folder with the authority's
    /// `ca.pem` and each process's `<process>.pem` and `<process>.key`. Without
    /// it, `launch` makes a development authority in the run's folder.
    #[arg(long, global = true, value_name = "DIR")]
    pub credentials: Option<PathBuf>,
    /// The launch this process belongs to (given by `launch` to its children):
    /// processes of different launches never exchange a value.
    #[arg(long, global = true, value_name = "ID", hide = true)]
    pub launch_id: Option<String>,
    /// The launcher's process id (given by `launch`): a child ends when its
    /// launcher is gone.
    #[arg(long, global = true, value_name = "PID", hide = true)]
    pub launcher_pid: Option<u32>,
    /// Which start of this process this is (0 first; given by `launch`).
    #[arg(long, global = true, value_name = "K", hide = true)]
    pub incarnation: Option<u32>,
    /// Show the spec's `ros2` section's buffers as ROS 2 topics over
    /// rmw_zenoh, through a Zenoh router such as rmw_zenohd listening on
    /// ENDPOINT (default tcp/localhost:7447; given as `--ros2=ENDPOINT`, so
    /// that `--ros2 launch` is the flag and the command), for the whole run.
    /// With `--realtime` (and in every process of a deployment) the topics
    /// the section subscribes to feed their input buffers too; a
    /// deterministic run only publishes. With `--process`, this process's
    /// buffers, as node `<node>_<process>`; `launch` gives it to every
    /// process. Exit 2 when the router cannot be reached.
    #[arg(
        long,
        global = true,
        value_name = "ENDPOINT",
        num_args = 0..=1,
        require_equals = true,
        default_missing_value = ROS2_ENDPOINT
    )]
    pub ros2: Option<String>,
}

/// Where `--ros2` finds its Zenoh router when given no endpoint: where
/// rmw_zenohd listens by default.
pub const ROS2_ENDPOINT: &str = "tcp/localhost:7447";

/// The longest run the layer accepts \[s\].
pub(crate) const MAX_SECONDS: f64 = 1e7;

impl Common {
    /// `--for`, checked: `None` when not given.
    pub fn limit(&self) -> Result<Option<Duration>, AppError> {
        seconds("--for/--limit", self.limit)
    }

    /// `--wait`, checked.
    pub fn wait(&self) -> Result<Option<Duration>, AppError> {
        seconds("--wait", self.wait)
    }

    /// The executors' settings: the application's, with `--on-error`'s policy
    /// if given.
    pub fn exec(&self, application: agent_core::ExecConfig) -> agent_core::ExecConfig {
        agent_core::ExecConfig {
            on_error: self.on_error.map_or(application.on_error, Into::into),
            ..application
        }
    }
}

/// The seconds `flag` gave, checked: `None` when not given; else a positive
/// number of at most [`MAX_SECONDS`].
fn seconds(flag: &str, value: Option<f64>) -> Result<Option<Duration>, AppError> {
    match value {
        None => Ok(None),
        Some(s) if s.is_finite() && s > 0.0 && s <= MAX_SECONDS => {
            Ok(Duration::try_from_secs_f64(s).ok())
        }
        Some(s) => Err(AppError::invalid(format!(
            "{flag} {s}: must be a positive number of seconds, at most 10,000,000"
        ))),
    }
}

/// What to do.
#[derive(Subcommand, Clone, Debug)]
pub enum Command {
    /// Run the system (the default): in the deterministic executor, or in real
    /// time with `--realtime`, or one process of a deployment with
    /// `--deployment D --process P`.
    Run,
    /// Start every process of `--deployment` (this program, once per process),
    /// print their output prefixed with their names, restart a crashed one (as
    /// often as the spec's `restarts` allows), stop them together on Ctrl-C,
    /// SIGTERM or when the run has ended, and print one summary with
    /// `processes=<n> restarts=<n>`.
    Launch {
        /// Kill a process with SIGKILL when the run's time reaches SECONDS
        /// (fault injection, repeatable): the launcher restarts it if the spec
        /// allows.
        #[arg(long, value_name = "PROCESS@SECONDS", value_parser = parse_fault)]
        kill: Vec<(String, f64)>,
    },
    /// Replay one subsystem of a recorded run (`--record FILE.mcap`) against
    /// the recording: build the system from this program's code with the
    /// recorded configuration (a flag given here overrides one), feed the
    /// subsystem its recorded inputs at the recorded instants, and compare
    /// what it sends and its behaviour switches with the recording, bit for
    /// bit. Prints `equivalent: ...` (exit 0) or the first divergence (exit 1);
    /// exit 2 when the file cannot be read.
    Replay {
        /// The recording.
        #[arg(value_name = "FILE.mcap")]
        file: PathBuf,
        /// The subsystem to replay.
        #[arg(long, value_name = "NAME")]
        subsystem: String,
        /// Which start of the subsystem's process to replay, when the
        /// recording holds several (a process restarted by its launcher);
        /// default: each in turn.
        #[arg(long, value_name = "K")]
        incarnation: Option<u32>,
    },
    /// Check the spec: names, types, wiring, agent structure, FSMs (with the
    /// proof that arcs are exclusive and complete), periods and deployments.
    /// Exit 2 if it has an error (an invalid spec is invalid input, as for
    /// every command).
    Check,
    /// Write the ROS 2 interface package of the messages `--ros2` makes
    /// from this program's buffer types (the spec's `ros2` section's
    /// package: `DIR/<package>/msg/*.msg`, `package.xml`, `CMakeLists.txt`),
    /// for ROS 2 users to build with colcon: their tools then decode and
    /// publish those messages with the type hashes the bridge announces.
    /// With `--deployment`, of that deployment's section.
    #[command(name = "ros2-package")]
    Ros2Package {
        /// The folder to write the package's folder into.
        #[arg(value_name = "DIR")]
        dir: PathBuf,
    },
    /// Make development credentials for secure `--deployment D` in DIR, to
    /// keep and give to `launch --credentials DIR`: an authority (`ca.pem`,
    /// `ca.key`) and, for every process and the launcher, `<process>.pem` and
    /// `<process>.key`. When D (or the system) has a `ros2` section, the ROS
    /// 2 side's too: `ros2.pem`/`ros2.key` for ROS 2 nodes,
    /// `ros2_router.pem`/`ros2_router.key` for their router, the router's
    /// Zenoh configuration `ros2_router.json5` (mutual TLS, the access control
    /// generated from the spec; rmw_zenohd's `ZENOH_ROUTER_CONFIG_URI`) and
    /// the nodes' `ros2_session.json5` (`ZENOH_SESSION_CONFIG_URI`). Prints
    /// the files and what to type next. Exit 2 for an unknown or unprotected
    /// deployment, or a DIR that holds an authority already (never
    /// overwritten).
    Credentials {
        /// The folder to write them into (made if missing).
        #[arg(value_name = "DIR")]
        dir: PathBuf,
        /// Where the ROS 2 router listens: a `tls/HOST:PORT` endpoint (a
        /// wildcard host is reached at `localhost`); default
        /// `tls/localhost:7447`.
        #[arg(long, value_name = "ENDPOINT")]
        ros2_listen: Option<String>,
    },
    /// Draw a diagram of the spec without Graphviz.
    Diagram {
        /// What to draw.
        #[arg(long, value_enum)]
        kind: DiagramKind,
        /// Only this subsystem (for `structure`: only its agent).
        #[arg(long, value_name = "NAME")]
        subsystem: Option<String>,
        /// Output format.
        #[arg(long, value_enum, default_value_t = DiagramFormat::Svg)]
        format: DiagramFormat,
        /// Write to this file instead of standard output.
        #[arg(short, long, value_name = "PATH")]
        output: Option<PathBuf>,
    },
}

/// What `diagram` draws.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum DiagramKind {
    /// The FSM of each subsystem.
    Fsm,
    /// The agents: components, buffers and links.
    Structure,
    /// The data flow of each behaviour's transition functions.
    Dataflow,
}

/// The format of a diagram.
#[derive(Clone, Copy, Debug, ValueEnum)]
pub enum DiagramFormat {
    /// Graphviz source.
    Dot,
    /// Mermaid.
    Mermaid,
    /// A standalone SVG image.
    Svg,
}

/// `PROCESS@SECONDS` of `--kill`.
pub fn parse_fault(s: &str) -> Result<(String, f64), BadFault> {
    let (process, at) = s
        .split_once('@')
        .ok_or_else(|| BadFault::NoTime(s.to_owned()))?;
    let at: f64 = at.parse().map_err(|e| BadFault::NotSeconds {
        given: at.to_owned(),
        why: format!("{e}"),
    })?;
    if process.is_empty() || !(at.is_finite() && (0.0..=MAX_SECONDS).contains(&at)) {
        return Err(BadFault::OutOfRange(s.to_owned()));
    }
    Ok((process.to_owned(), at))
}

/// A `--kill` argument that is not `PROCESS@SECONDS`.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum BadFault {
    /// No `@`.
    #[error("`{0}`: expected PROCESS@SECONDS, e.g. locomotion@8")]
    NoTime(String),
    /// The time is not a number.
    #[error("`{given}` is not a number of seconds: {why}")]
    NotSeconds {
        /// What was given after the `@`.
        given: String,
        /// Why it does not parse.
        why: String,
    },
    /// No process name, or a time that is negative, not finite or beyond a run.
    #[error("`{0}`: expected a process name and a time of at least 0 s")]
    OutOfRange(String),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn limits_outside_a_run_are_refused_with_the_flag_named() {
        for bad in [0.0, -1.0, f64::NAN, f64::INFINITY, 1e20] {
            let c = Common {
                limit: Some(bad),
                ..Common::default()
            };
            let e = c.limit().expect_err("refused").to_string();
            assert!(e.contains("--limit") && e.contains("positive"), "{e}");
        }
        let c = Common {
            limit: Some(2.5),
            ..Common::default()
        };
        assert_eq!(c.limit().ok().flatten(), Some(Duration::from_millis(2500)));
    }

    #[test]
    fn faults_name_a_process_and_a_time() {
        assert_eq!(parse_fault("world@5"), Ok(("world".to_owned(), 5.0)));
        for bad in ["@5", "world@-1", "world@nan", "world@inf"] {
            assert_eq!(parse_fault(bad), Err(BadFault::OutOfRange(bad.into())));
        }
        assert_eq!(parse_fault("world"), Err(BadFault::NoTime("world".into())));
        let e = parse_fault("world@x").expect_err("not seconds");
        assert!(matches!(&e, BadFault::NotSeconds { given, .. } if given == "x"));
        assert!(
            e.to_string().starts_with("`x` is not a number of seconds"),
            "{e}"
        );
    }
}
