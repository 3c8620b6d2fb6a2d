//! `rex`: the main job. Runs the whole Rex system (agents a1, a2, a3 and the
//! simulated platform) in the deterministic executor, shows progress, prints a
//! summary, writes a report folder, and ends with the line
//! `mission=… plans_acked=… rms_m=… max_m=… realtime_factor=…`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;
use embodied::record::{McapRecorder, RecordOptions};
use embodied::spec::Spec;
use embodied::{OffloadMode, RtConfig};
use rex_agent::a1::c1::trajgen::Runtime;
use rex_agent::a1::e11::{EstimatorKind, TrackerKind};
use rex_agent::a1::{RexConfig, RunSettings, deployment, load_spec};
use rex_agent::algorithms::planner::PlannerKind;
use rex_agent::mission::Mission;
use rex_agent::run::{
    Outcome, Progress, run_mission, run_mission_observed, run_mission_realtime,
    run_mission_realtime_recorded,
};
use rex_agent::{config, report};

mod cli;
#[cfg(feature = "distributed")]
use cli::deploy::distributed;
use cli::replay::replay;

/// Run Rex, the skid-steer robot of Janiak & Zieliński, through a mission.
///
/// The ontology agent a2 sends the plans of the mission, the locomotion agent a1
/// plans trajectories (c1) and tracks them (e11) on the simulated platform E1, the
/// map agent a3 supplies poses from motion capture. Every choice below can also be
/// written in a run file (`--config`, default `rex-agent/config/rex.ron`); a flag
/// overrides the file.
///
/// Exit status: 0 when every plan was achieved (acknowledged, reported reached by
/// a1, and confirmed by the simulation's truth); 1 when a plan failed or the
/// mission did not complete (the summary names each plan and how it ended); 2
/// when the command line or a configuration file is invalid (nothing runs).
#[derive(Parser, Debug)]
#[command(name = "rex", version)]
struct Cli {
    /// Run file (RON): mission, world, surface, planner, tracker, estimator, limit.
    #[arg(long, global = true, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Mission: `square`, `figure_eight`, `slalom`, a mission file, or `all` for the
    /// three shipped missions one after the other.
    #[arg(long, global = true, value_name = "NAME|FILE")]
    mission: Option<String>,
    /// World file (platform, surfaces, sensors, camera, room, motion capture).
    #[arg(long, global = true, value_name = "FILE")]
    world: Option<PathBuf>,
    /// The spec Rex is built from (default: `specs/rex.ron`): its components,
    /// periods and links; checked before anything runs.
    #[arg(long, global = true, value_name = "FILE")]
    spec: Option<PathBuf>,
    /// One surface for the whole floor: a name from the world's `surfaces`
    /// (shipped: concrete, grass, ice).
    #[arg(long, global = true, value_name = "NAME")]
    surface: Option<String>,
    /// Trajectory planner of c1: `ecsa` (the paper's) or `polynomial`.
    #[arg(long, global = true, value_name = "NAME")]
    planner: Option<PlannerKind>,
    /// Where the planner runs: `thread` (a concurrent planning process) or `inline`.
    #[arg(long, global = true, value_name = "WHERE")]
    planning: Option<Runtime>,
    /// Tracker of e11: `nmpc` (the paper's) or `backstepping`.
    #[arg(long, global = true, value_name = "NAME")]
    tracker: Option<TrackerKind>,
    /// State estimator of e11: `mhe` (the paper's) or `ekf`.
    #[arg(long, global = true, value_name = "NAME")]
    estimator: Option<EstimatorKind>,
    /// Longest simulated time, in seconds (positive, at most 10,000,000).
    #[arg(
        long,
        global = true,
        value_name = "SECONDS",
        allow_negative_numbers = true
    )]
    limit: Option<f64>,
    /// Run without the virtual receptor r11 and the camera (no visual odometry:
    /// the spec's deployment `simulation_without_vo`).
    #[arg(long, global = true)]
    no_vo: bool,
    /// Where the camera renders and r11 runs its odometry: `worker` (threads of
    /// their own, beside the rest of the system) or `inline` (in their steps). The
    /// run is the same, bit for bit; only the wall-clock time differs.
    #[arg(long, global = true, value_name = "WHERE")]
    vision: Option<OffloadMode>,
    /// Steps of r11 (20 ms) from a stereo pair to its motion, at most: the time the
    /// odometry has to run beside the rest (the motion leaves sooner when the next
    /// pair arrives); 0: in the step the pair arrives.
    #[arg(long, global = true, value_name = "STEPS")]
    vo_latency: Option<u32>,
    /// Report folder; one sub-folder per mission.
    #[arg(
        long,
        global = true,
        value_name = "DIR",
        default_value = "target/rex-report"
    )]
    out: PathBuf,
    /// Do not write the report folder.
    #[arg(long, global = true)]
    no_report: bool,
    /// Do not record the run into the report folder (`<out>/<mission>/run.mcap`,
    /// made by default: it costs a few percent of the run's time with the
    /// camera, about 160 MB for the figure-eight; see `--record`).
    #[arg(long, global = true)]
    no_record: bool,
    /// Record the run to this MCAP file (open it in Foxglove): every buffer
    /// transfer as JSON with its type's schema and as exact bytes, c1's and
    /// every subsystem's behaviour switches with the value of each predicate,
    /// errors, the spec and the settings; one mission (by default the report
    /// folder holds `run.mcap`, see `--no-record`). With `--realtime`,
    /// also which value each activation read (the threads' timing decides
    /// it). With `--process`, this process's part (`{process}` in the path is
    /// its name); with `launch`, every process records `<stem>.<process>.mcap`
    /// and the parts are merged into FILE when they end.
    #[arg(long, global = true, value_name = "FILE")]
    record: Option<PathBuf>,
    /// Print only the summary.
    #[arg(long, short, global = true)]
    quiet: bool,
    /// Run in real time, as on the robot: every subsystem on its own thread and
    /// the world (the 1 kHz plant, the camera, the motion capture) on one, on
    /// absolute deadlines of the wall clock, with SCHED_FIFO priority and locked
    /// memory where the OS grants them (what it refuses is reported). Prints each
    /// node's period, wake-up jitter, compute time and overruns.
    #[arg(long, global = true)]
    realtime: bool,
    /// A deployment of the spec to run split into processes over Zenoh (with
    /// `--process`, or `launch`). `split` is the paper's Fig. 10: the world and
    /// the partner agents; c1 with e11; r11 on its own.
    #[arg(long, global = true, value_name = "NAME")]
    deployment: Option<String>,
    /// Run only this process of `--deployment`, in real time; the others are
    /// reached over Zenoh at the endpoints the spec gives.
    #[arg(long, global = true, value_name = "NAME", requires = "deployment")]
    process: Option<String>,
    /// The first port of the deployment's endpoints (replaces the spec's, so that
    /// two runs of a deployment do not meet).
    #[arg(long, global = true, value_name = "PORT")]
    port: Option<u16>,
    /// How long a process waits for the others before it fails naming them, in
    /// seconds (replaces the spec's `timeout_ms`).
    #[arg(long, global = true, value_name = "SECONDS")]
    wait: Option<f64>,
    /// The credentials of a secure deployment (`secure: true` in the spec): a
    /// folder with the authority's `ca.pem` and each process's `<process>.pem`
    /// and `<process>.key` (their common names `<process>.<deployment>.<spec>`).
    /// Without it, `launch` makes a development authority under
    /// `target/rex-credentials/<deployment>/`.
    #[arg(long, global = true, value_name = "DIR")]
    credentials: Option<PathBuf>,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(clap::Subcommand, Debug)]
enum Command {
    /// Start every process of `--deployment` (this program, once per process),
    /// print their output prefixed with their names, restart a crashed one, stop
    /// them together on Ctrl-C or when the mission has ended, and print the
    /// mission's summary with `processes=<n> restarts=<n>`.
    Launch {
        /// Kill a process with SIGKILL when the mission's time reaches SECONDS
        /// (fault injection, repeatable): the launcher restarts it, and the
        /// agents recover (a2 resends what c1 lost; a1 goes on without visual
        /// odometry while r11 is away).
        #[arg(long, value_name = "PROCESS@SECONDS", value_parser = parse_fault)]
        kill: Vec<(String, f64)>,
    },
    /// Replay one subsystem of a recorded run (`--record FILE.mcap`) against
    /// the recording: build Rex from this program's code with the recorded
    /// settings (a flag given here overrides one: `--spec`, `--planner`...),
    /// feed the subsystem the recorded inputs at the recorded instants, and
    /// compare what it sends and its behaviour switches with the recording,
    /// bit for bit. Prints `equivalent: ...` (exit 0) or the first divergence
    /// (exit 1); exit 2 when the file cannot be read.
    Replay {
        /// The recording.
        #[arg(value_name = "FILE.mcap")]
        file: PathBuf,
        /// The subsystem to replay: c1, e11, r11, or a partner's (c2, c3, r31).
        #[arg(long, value_name = "NAME")]
        subsystem: String,
    },
}

/// `PROCESS@SECONDS` of `--kill`.
fn parse_fault(s: &str) -> Result<(String, f64), String> {
    let (process, at) = s
        .split_once('@')
        .ok_or_else(|| format!("`{s}`: expected PROCESS@SECONDS, e.g. locomotion@8"))?;
    let at: f64 = at
        .parse()
        .map_err(|e| format!("`{at}` is not a number of seconds: {e}"))?;
    if process.is_empty() || !(at.is_finite() && at >= 0.0) {
        return Err(format!(
            "`{s}`: expected a process name and a time of at least 0 s"
        ));
    }
    Ok((process.to_owned(), at))
}

/// Write to standard output; if it is closed (`rex | head`), stop quietly instead of
/// panicking.
fn emit(text: std::fmt::Arguments<'_>) {
    use std::io::Write;
    if std::io::stdout().lock().write_fmt(text).is_err() {
        std::process::exit(0);
    }
}

/// Whether a report folder can be made at `dir`: it is (or can be created as) a
/// folder, and a file can be written in it.
fn writable(dir: &Path) -> std::io::Result<()> {
    if dir.exists() && !dir.is_dir() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::NotADirectory,
            "exists and is not a folder",
        ));
    }
    std::fs::create_dir_all(dir)?;
    let probe = dir.join(".rex-write-test");
    std::fs::write(&probe, b"")?;
    std::fs::remove_file(&probe)
}

fn settings(cli: &Cli) -> Result<(RunSettings, PathBuf), config::ConfigError> {
    let (mut s, base) = match &cli.config {
        Some(path) => (
            RunSettings::load(path)?,
            path.parent().map_or_else(PathBuf::new, Path::to_path_buf),
        ),
        None => (RunSettings::shipped()?, config::config_dir()),
    };
    overrides(cli, &mut s)?;
    Ok((s, base))
}

/// The command line's flags over the settings `s`.
fn overrides(cli: &Cli, s: &mut RunSettings) -> Result<(), config::ConfigError> {
    if let Some(m) = &cli.mission {
        s.mission = m.clone();
    }
    if let Some(w) = &cli.world {
        // A world given on the command line is relative to the current folder.
        s.world = Some(std::path::absolute(w).unwrap_or_else(|_| w.clone()));
    }
    if let Some(spec) = &cli.spec {
        s.spec = Some(std::path::absolute(spec).unwrap_or_else(|_| spec.clone()));
    }
    if cli.surface.is_some() {
        s.surface = cli.surface.clone();
    }
    s.planner = cli.planner.unwrap_or(s.planner);
    s.planning = cli.planning.unwrap_or(s.planning);
    s.tracker = cli.tracker.unwrap_or(s.tracker);
    s.estimator = cli.estimator.unwrap_or(s.estimator);
    s.vision = cli.vision.unwrap_or(s.vision);
    s.vo_latency = cli.vo_latency.unwrap_or(s.vo_latency);
    s.limit_s = cli.limit.unwrap_or(s.limit_s);
    if let Some(limit) = cli.limit
        && !(limit.is_finite() && limit > 0.0 && limit <= 1e7)
    {
        return Err(config::ConfigError::Invalid {
            path: PathBuf::from("--limit"),
            field: "SECONDS".into(),
            value: limit.to_string(),
            reason: "must be a positive number of seconds, at most 10,000,000",
        });
    }
    if cli.no_vo {
        s.visual_odometry = false;
    }
    Ok(())
}

/// The settings `s` (paths relative to `base`) with every path made absolute,
/// as `prepare` resolves them: what a recording keeps so that a replay builds
/// the same Rex from any folder.
fn self_contained(cli: &Cli, s: &RunSettings, base: &Path) -> RunSettings {
    let mut s = s.clone();
    let absolute = |p: &Path| std::path::absolute(base.join(p)).unwrap_or_else(|_| base.join(p));
    s.world = s.world.as_deref().map(absolute);
    s.spec = s.spec.as_deref().map(absolute);
    if !Mission::SHIPPED.contains(&s.mission.as_str()) {
        let mission_base = if cli.mission.is_some() {
            std::env::current_dir().unwrap_or_default()
        } else {
            base.to_owned()
        };
        let path = mission_base.join(&s.mission);
        s.mission = std::path::absolute(&path)
            .unwrap_or(path)
            .display()
            .to_string();
    }
    s
}

/// The configuration of one mission, checked: the run's settings, the world,
/// the mission, the spec.
fn prepare(
    cli: &Cli,
    s: &RunSettings,
    base: &Path,
) -> Result<(RexConfig, Spec, Duration), Box<dyn std::error::Error>> {
    // A mission file named on the command line is relative to the current folder.
    let base = if cli.mission.is_some() && !Mission::SHIPPED.contains(&s.mission.as_str()) {
        std::env::current_dir()?
    } else {
        base.to_owned()
    };
    let config = s.resolve(&base)?;
    let spec = load_spec(&config.spec)?;
    let limit = Duration::try_from_secs_f64(s.limit_s)
        .map_err(|e| format!("limit_s = {}: {e}", s.limit_s))?;
    Ok((config, spec, limit))
}

/// Prints acknowledgements and a line every few seconds (nothing when `quiet`).
fn printer(quiet: bool) -> impl FnMut(Progress<'_>) {
    move |p: Progress<'_>| match p {
        _ if quiet => {}
        Progress::Ack { t, ack } => {
            eprintln!(
                "[{t:7.2} s] plan {} acknowledged: {:?}",
                ack.plan, ack.status
            )
        }
        Progress::Tick { t, sample } => eprintln!(
            "[{t:7.2} s] c1 in B{}, e11 {}, tracking error {}",
            sample.behaviour + 1,
            sample
                .fragment
                .map_or("holding".to_owned(), |(p, i)| format!(
                    "on fragment {p}.{i}"
                )),
            sample
                .error()
                .filter(|_| sample.executing)
                .map_or("-".to_owned(), |e| format!("{:.1} mm", e * 1e3)),
        ),
    }
}

/// What a recording says about its run: the spec, the settings (whole, as RON:
/// what `rex replay` builds Rex from), the versions.
fn record_options(config: &RexConfig, spec: &Spec, settings: &RunSettings) -> RecordOptions {
    let mut options = rex_agent::record::options();
    let text = std::fs::read_to_string(&config.spec).unwrap_or_default();
    options.metadata.insert(
        "spec".into(),
        [
            ("name".to_owned(), spec.name.clone()),
            ("path".to_owned(), config.spec.display().to_string()),
            ("text".to_owned(), text),
        ]
        .into(),
    );
    options.metadata.insert(
        "run".into(),
        [
            ("mission".to_owned(), config.mission.name.clone()),
            ("deployment".to_owned(), deployment(config).to_owned()),
            ("planner".to_owned(), config.planner.name().to_owned()),
            ("tracker".to_owned(), format!("{:?}", config.tracker)),
            ("estimator".to_owned(), format!("{:?}", config.estimator)),
            ("rex".to_owned(), env!("CARGO_PKG_VERSION").to_owned()),
            (
                "settings".to_owned(),
                ron::ser::to_string_pretty(settings, ron::ser::PrettyConfig::default())
                    .unwrap_or_default(),
            ),
        ]
        .into(),
    );
    options
}

fn run_one(
    cli: &Cli,
    (config, spec, limit): (&RexConfig, &Spec, Duration),
    settings: &RunSettings,
) -> Result<Outcome, Box<dyn std::error::Error>> {
    if !cli.quiet {
        eprintln!(
            "rex: mission `{}` ({} plans), planner {}, tracker {:?}, estimator {:?}, planning {:?}, visual odometry {}",
            config.mission.name,
            config.mission.plans.len(),
            config.planner.name(),
            config.tracker,
            config.estimator,
            config.runtime,
            if config.visual_odometry { "on" } else { "off" }
        );
    }
    let quiet = cli.quiet;
    let progress = printer(quiet);
    // `--record FILE`, else the report folder's `run.mcap` unless told not to.
    let default_record;
    let record = match &cli.record {
        Some(file) => Some(file),
        None if !cli.no_report && !cli.no_record => {
            let dir = cli.out.join(&config.mission.name);
            std::fs::create_dir_all(&dir)?;
            default_record = dir.join("run.mcap");
            Some(&default_record)
        }
        None => None,
    };
    let outcome = if cli.realtime {
        let rt = RtConfig::realtime();
        let tick = Duration::from_secs(5);
        let (outcome, timing) = match record {
            Some(file) => {
                let options = record_options(config, spec, settings);
                let (outcome, timing, s) = run_mission_realtime_recorded(
                    config,
                    limit,
                    tick,
                    rt,
                    (file, options),
                    progress,
                )?;
                print_recorded(file, &s);
                (outcome, timing)
            }
            None => run_mission_realtime(config, limit, tick, rt, progress)?,
        };
        if !quiet {
            eprintln!("{timing}");
        }
        emit(format_args!(
            "rt_priority={} overruns={} executor_errors={}\n",
            if timing.rt_priority() { "yes" } else { "no" },
            timing.nodes.iter().map(|n| n.overruns).sum::<u64>(),
            timing.error_count
        ));
        outcome
    } else if let Some(file) = record {
        let options = record_options(config, spec, settings);
        let (outcome, recorder) = run_mission_observed(
            config,
            limit,
            Duration::from_secs(5),
            |system| Ok(McapRecorder::create(file, system, options)?),
            progress,
        )?;
        print_recorded(file, &recorder.finish()?);
        outcome
    } else {
        run_mission(config, limit, Duration::from_secs(5), progress)?
    };
    emit(format_args!("{}", report::summary(&outcome)));
    if !cli.no_report {
        let dir = cli.out.join(&outcome.mission);
        let files = report::write(&dir, &outcome, config, spec)?;
        emit(format_args!(
            "report: {} ({} files)\n",
            dir.display(),
            files.len()
        ));
    }
    if !outcome.completed {
        emit(format_args!(
            "the mission did not complete within {} s of simulated time\n",
            limit.as_secs_f64()
        ));
    }
    let failed = outcome.plans - outcome.plans_achieved();
    if failed > 0 {
        emit(format_args!(
            "{failed} of {} plans not achieved (see the plan lines above)\n",
            outcome.plans
        ));
    }
    Ok(outcome)
}

/// The line that says where a recording went and what it holds.
fn print_recorded(file: &Path, s: &embodied::record::RecordSummary) {
    let size = std::fs::metadata(file).map_or(0, |m| m.len());
    emit(format_args!(
        "record: {} ({} messages on {} channels, {:.1} MB)\n",
        file.display(),
        s.messages,
        s.channels,
        size as f64 / 1e6
    ));
    for link in &s.json_values {
        emit(format_args!("record: values in JSON, not CDR: {link}\n"));
    }
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    if let Some(Command::Replay { file, subsystem }) = &cli.command {
        return replay(&cli, file, subsystem);
    }
    let (settings, base) = match settings(&cli) {
        Ok(v) => v,
        Err(e) => {
            eprintln!("rex: {e}");
            return ExitCode::from(2);
        }
    };
    let missions: Vec<String> = if settings.mission == "all" {
        Mission::SHIPPED.iter().map(|m| (*m).to_owned()).collect()
    } else {
        vec![settings.mission.clone()]
    };
    // The report folder is checked before the simulation, not after it.
    if !cli.no_report
        && let Err(e) = writable(&cli.out)
    {
        eprintln!("rex: --out {}: {e}", cli.out.display());
        return ExitCode::from(2);
    }
    // Every mission's configuration is checked before anything runs (exit 2).
    let mut prepared = Vec::new();
    let mut recorded = Vec::new();
    for mission in missions {
        let s = RunSettings {
            mission,
            ..settings.clone()
        };
        recorded.push(self_contained(&cli, &s, &base));
        match prepare(&cli, &s, &base) {
            Ok(p) => prepared.push(p),
            Err(e) => {
                eprintln!("rex: {e}");
                return ExitCode::from(2);
            }
        }
    }
    if let Some(file) = &cli.record {
        let why = if prepared.len() > 1 {
            Some("records one mission (not `all`)")
        } else {
            None
        };
        if let Some(why) = why {
            eprintln!("rex: --record {}: {why}", file.display());
            return ExitCode::from(2);
        }
    }
    if cli.process.is_some() || cli.command.is_some() {
        return distributed(&cli, &prepared, &recorded);
    }
    let mut lines = Vec::new();
    let mut ok = true;
    for ((config, spec, limit), settings) in prepared.iter().zip(&recorded) {
        match run_one(&cli, (config, spec, *limit), settings) {
            Ok(outcome) => {
                ok &= outcome.succeeded();
                lines.push(outcome.summary_line());
            }
            Err(e) => {
                eprintln!("rex: {e}");
                return ExitCode::FAILURE;
            }
        }
    }
    // The figures, one line per mission; the last line is the last mission's.
    for line in &lines {
        emit(format_args!("{line}\n"));
    }
    if ok {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}

#[cfg(not(feature = "distributed"))]
fn distributed(_: &Cli, _: &[(RexConfig, Spec, Duration)], _: &[RunSettings]) -> ExitCode {
    eprintln!("rex: built without the feature `distributed`: no deployments over Zenoh");
    ExitCode::from(2)
}
