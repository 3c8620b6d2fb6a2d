//! `rex`: the main job. Runs the whole Rex system (agents a1, a2, a3 and the
//! simulated platform) in the deterministic executor, shows progress, prints a
//! summary, writes a report folder, and ends with the line
//! `mission=… plans_acked=… rms_m=… max_m=… realtime_factor=…`.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Duration;

use clap::Parser;
use rex_agent::e11::{EstimatorKind, TrackerKind};
use rex_agent::mission::Mission;
use rex_agent::planner::PlannerKind;
use rex_agent::planner::trajgen::Runtime;
use rex_agent::rex::{RunSettings, load_spec};
use rex_agent::run::{Outcome, Progress, run_mission};
use rex_agent::{config, report};

/// Run Rex, the skid-steer robot of Janiak & Zieliński, through a mission.
///
/// The ontology agent a2 sends the plans of the mission, the locomotion agent a1
/// plans trajectories (c1) and tracks them (e11) on the simulated platform E1, the
/// map agent a3 supplies poses from motion capture. Every choice below can also be
/// written in a run file (`--config`, default `rex-agent/config/rex.ron`); a flag
/// overrides the file.
#[derive(Parser, Debug)]
#[command(name = "rex", version)]
struct Cli {
    /// Run file (RON): mission, world, surface, planner, tracker, estimator, limit.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Mission: `square`, `figure_eight`, `slalom`, a mission file, or `all` for the
    /// three shipped missions one after the other.
    #[arg(long, value_name = "NAME|FILE")]
    mission: Option<String>,
    /// World file (platform, surfaces, sensors, camera, room, motion capture).
    #[arg(long, value_name = "FILE")]
    world: Option<PathBuf>,
    /// One surface for the whole floor: a name from the world's `surfaces`
    /// (shipped: concrete, grass, ice).
    #[arg(long, value_name = "NAME")]
    surface: Option<String>,
    /// Trajectory planner of c1: `ecsa` (the paper's) or `polynomial`.
    #[arg(long, value_name = "NAME")]
    planner: Option<PlannerKind>,
    /// Where the planner runs: `thread` (a concurrent planning process) or `inline`.
    #[arg(long, value_name = "WHERE")]
    planning: Option<Runtime>,
    /// Tracker of e11: `nmpc` (the paper's) or `backstepping`.
    #[arg(long, value_name = "NAME")]
    tracker: Option<TrackerKind>,
    /// State estimator of e11: `mhe` (the paper's) or `ekf`.
    #[arg(long, value_name = "NAME")]
    estimator: Option<EstimatorKind>,
    /// Longest simulated time, in seconds.
    #[arg(long, value_name = "SECONDS")]
    limit: Option<f64>,
    /// Run without the virtual receptor r11 and the camera (no visual odometry:
    /// the spec's deployment `simulation_without_vo`).
    #[arg(long)]
    no_vo: bool,
    /// Report folder; one sub-folder per mission.
    #[arg(long, value_name = "DIR", default_value = "target/rex-report")]
    out: PathBuf,
    /// Do not write the report folder.
    #[arg(long)]
    no_report: bool,
    /// Print only the summary.
    #[arg(long, short)]
    quiet: bool,
}

/// Write to standard output; if it is closed (`rex | head`), stop quietly instead of
/// panicking.
fn emit(text: std::fmt::Arguments<'_>) {
    use std::io::Write;
    if std::io::stdout().lock().write_fmt(text).is_err() {
        std::process::exit(0);
    }
}

fn settings(cli: &Cli) -> Result<(RunSettings, PathBuf), config::ConfigError> {
    let (mut s, base) = match &cli.config {
        Some(path) => (
            RunSettings::load(path)?,
            path.parent().map_or_else(PathBuf::new, Path::to_path_buf),
        ),
        None => (RunSettings::shipped()?, config::config_dir()),
    };
    if let Some(m) = &cli.mission {
        s.mission = m.clone();
    }
    if let Some(w) = &cli.world {
        // A world given on the command line is relative to the current folder.
        s.world = Some(std::path::absolute(w).unwrap_or_else(|_| w.clone()));
    }
    if cli.surface.is_some() {
        s.surface = cli.surface.clone();
    }
    s.planner = cli.planner.unwrap_or(s.planner);
    s.planning = cli.planning.unwrap_or(s.planning);
    s.tracker = cli.tracker.unwrap_or(s.tracker);
    s.estimator = cli.estimator.unwrap_or(s.estimator);
    s.limit_s = cli.limit.unwrap_or(s.limit_s);
    if cli.no_vo {
        s.visual_odometry = false;
    }
    Ok((s, base))
}

fn run_one(cli: &Cli, s: &RunSettings, base: &Path) -> Result<Outcome, Box<dyn std::error::Error>> {
    // A mission file named on the command line is relative to the current folder.
    let base = if cli.mission.is_some() && !Mission::SHIPPED.contains(&s.mission.as_str()) {
        std::env::current_dir()?
    } else {
        base.to_owned()
    };
    let config = s.resolve(&base)?;
    let spec = load_spec(&config.spec)?;
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
    let outcome = run_mission(
        &config,
        Duration::from_secs_f64(s.limit_s),
        Duration::from_secs(5),
        |p| match p {
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
        },
    )?;
    emit(format_args!("{}", report::summary(&outcome)));
    if !cli.no_report {
        let dir = cli.out.join(&outcome.mission);
        let files = report::write(&dir, &outcome, &config, &spec)?;
        emit(format_args!(
            "report: {} ({} files)\n",
            dir.display(),
            files.len()
        ));
    }
    if !outcome.completed {
        emit(format_args!(
            "the mission did not complete within {} s of simulated time\n",
            s.limit_s
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

fn main() -> ExitCode {
    let cli = Cli::parse();
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
    let mut lines = Vec::new();
    let mut ok = true;
    for mission in missions {
        let s = RunSettings {
            mission,
            ..settings.clone()
        };
        match run_one(&cli, &s, &base) {
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
