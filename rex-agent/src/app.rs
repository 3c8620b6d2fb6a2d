//! Rex on the application layer ([`embodied::app`]): what is Rex's own in the
//! `rex` program. Its flags and run files (the configuration of a run is the
//! run settings, made self-contained), its missions (`--mission all` runs the
//! three shipped ones in turn), its probes and their pairing with the
//! simulation's truth, the judgement of every plan against that truth, the
//! report folder, and the check that a deployment keeps the simulated world in
//! one process. Everything else (executors, recording, replay, deployments,
//! the launcher, signals, exit status) is the layer's.

use std::path::{Path, PathBuf};
use std::time::Duration;

use embodied::app::report::ReportFlags;
use embodied::app::settings::{absolute, run_file};
use embodied::app::{
    AppError, Application, Common, Mode, RunSummary, SpecFile, Target, Verdict, Watcher,
};
use embodied::record::RecordOptions;
use embodied::{Finished, OffloadMode, Probes, System};

use crate::a1::c1::trajgen::Runtime;
use crate::a1::e11::{EstimatorKind, TrackerKind};
use crate::algorithms::planner::PlannerKind;
use crate::config;
use crate::mission::Mission;
use crate::run::{MissionWatch, Progress, Seen, install_probes, last_reports};
use crate::system::{RexConfig, RexHandles, RunSettings, build, build_deployment, deployment};

/// Rex's own flags (the layer adds `--for/--limit`, `--realtime`, `--record`,
/// `--quiet`, `--verbose`, `--deployment`, `--process`, `--port`, `--wait`,
/// `--credentials`). Every choice can also be written in a run file
/// (`--config`, default `rex-agent/config/rex.ron`); a flag overrides the file.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct RexFlags {
    /// Run file (RON): mission, world, surface, planner, tracker, estimator, limit.
    #[arg(long, global = true, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Mission: `square`, `figure_eight`, `slalom`, a mission file, or `all` for the
    /// three shipped missions one after the other; `listen` (or a file with
    /// `plans: []`): a2 sends no plan, c1 takes plans from elsewhere (with
    /// `--realtime --ros2`: the ROS 2 topic /rex/plan) until `--for SECONDS`
    /// or SIGINT/SIGTERM, and every plan it took is judged.
    #[arg(long, global = true, value_name = "NAME|FILE")]
    pub mission: Option<String>,
    /// World file (platform, surfaces, sensors, camera, room, motion capture).
    #[arg(long, global = true, value_name = "FILE")]
    pub world: Option<PathBuf>,
    /// The spec Rex is built from (default: `specs/rex.ron`): its components,
    /// periods and links; checked before anything runs.
    #[arg(long, global = true, value_name = "FILE")]
    pub spec: Option<PathBuf>,
    /// One surface for the whole floor: a name from the world's `surfaces`
    /// (shipped: concrete, grass, ice).
    #[arg(long, global = true, value_name = "NAME")]
    pub surface: Option<String>,
    /// Trajectory planner of c1: `ecsa` (the paper's) or `polynomial`.
    #[arg(long, global = true, value_name = "NAME")]
    pub planner: Option<PlannerKind>,
    /// Where the planner runs: `thread` (a concurrent planning process) or `inline`.
    #[arg(long, global = true, value_name = "WHERE")]
    pub planning: Option<Runtime>,
    /// Tracker of e11: `nmpc` (the paper's) or `backstepping`.
    #[arg(long, global = true, value_name = "NAME")]
    pub tracker: Option<TrackerKind>,
    /// State estimator of e11: `mhe` (the paper's) or `ekf`.
    #[arg(long, global = true, value_name = "NAME")]
    pub estimator: Option<EstimatorKind>,
    /// Run without the virtual receptor r11 and the camera (no visual odometry:
    /// the spec's deployment `simulation_without_vo`).
    #[arg(long, global = true)]
    pub no_vo: bool,
    /// Where the camera renders and r11 runs its odometry: `worker` (threads of
    /// their own, beside the rest of the system) or `inline` (in their steps). The
    /// run is the same, bit for bit; only the wall-clock time differs.
    #[arg(long, global = true, value_name = "WHERE")]
    pub vision: Option<OffloadMode>,
    /// Steps of r11 (20 ms) from a stereo pair to its motion, at most: the time the
    /// odometry has to run beside the rest (the motion leaves sooner when the next
    /// pair arrives); 0: in the step the pair arrives.
    #[arg(long, global = true, value_name = "STEPS")]
    pub vo_latency: Option<u32>,
    /// The report folder (`--out`, default `target/rex-report`, one
    /// sub-folder per mission), `--no-report`, `--no-record`.
    #[command(flatten)]
    pub report: ReportFlags,
}

/// What `rex --help` says above the flags.
pub const ABOUT: &str = "\
Run Rex, the skid-steer robot of Janiak & Zieliński, through a mission.

The ontology agent a2 sends the plans of the mission, the locomotion agent a1
plans trajectories (c1) and tracks them (e11) on the simulated platform E1, the
map agent a3 supplies poses from motion capture.

Plans from ROS 2: `--mission listen` sends none from a2; c1 takes the plans
published on /rex/plan (`rex --realtime --ros2 --mission listen --for 300`): the
first with any id, then each numbered newest + 1 (a number beyond is refused
as out of sequence, one already taken ignored as a copy), acknowledged on
/rex/ack and /rex/outcome. The run ends at --for or
on SIGINT/SIGTERM; its summary judges every plan c1 took
(`mission=listen plans_acked=N/M`, M the plans taken).

Exit status: 0 when every plan was achieved (acknowledged, reported reached by
a1, and confirmed by the simulation's truth); for `listen`, when the run
reached --for with every plan c1 took achieved and none still executing (also
when none came); 1 when a plan failed or the mission did not complete (the
summary names each plan and how it ended), and after SIGINT/SIGTERM (a run
stopped before its end; the summary is printed all the same); 2 when the
command line or a configuration file is invalid (nothing runs).";

/// The drivers that act on or sense the simulated world: they share it, so a
/// deployment must run them in one process.
const WORLD_DRIVERS: [&str; 3] = ["E1", "R1", "R3"];

/// Rex as an [`Application`] of the layer.
#[derive(Debug, Default)]
pub struct RexApp {
    flags: RexFlags,
    /// The handles of the system last built (for its probes and last reports).
    handles: Option<RexHandles>,
}

impl RexApp {
    /// The run file's settings with the command line's flags over them, and
    /// the folder the file's relative paths are taken from.
    fn settings(flags: &RexFlags, common: &Common) -> Result<(RunSettings, PathBuf), AppError> {
        let shipped = config::config_dir().join("rex.ron");
        let (mut s, base) = run_file(flags.config.as_deref(), &shipped, RunSettings::load)?;
        overrides(flags, common, &mut s)?;
        Ok((s, base))
    }

    /// The configuration `s` describes (its paths absolute).
    fn resolve(s: &RunSettings) -> Result<RexConfig, AppError> {
        s.resolve(Path::new("/")).map_err(AppError::invalid)
    }
}

/// The flags over the settings `s`.
fn overrides(flags: &RexFlags, common: &Common, s: &mut RunSettings) -> Result<(), AppError> {
    if let Some(m) = &flags.mission {
        s.mission = m.clone();
    }
    // A file given on the command line is relative to the current folder.
    if let Some(w) = &flags.world {
        s.world = Some(absolute(Path::new(""), w));
    }
    if let Some(spec) = &flags.spec {
        s.spec = Some(absolute(Path::new(""), spec));
    }
    if flags.surface.is_some() {
        s.surface = flags.surface.clone();
    }
    s.planner = flags.planner.unwrap_or(s.planner);
    s.planning = flags.planning.unwrap_or(s.planning);
    s.tracker = flags.tracker.unwrap_or(s.tracker);
    s.estimator = flags.estimator.unwrap_or(s.estimator);
    s.vision = flags.vision.unwrap_or(s.vision);
    s.vo_latency = flags.vo_latency.unwrap_or(s.vo_latency);
    if let Some(limit) = common.limit()? {
        s.limit_s = limit.as_secs_f64();
    }
    if flags.no_vo {
        s.visual_odometry = false;
    }
    Ok(())
}

/// The settings `s` (paths relative to `base`) with every path made absolute,
/// so that a recording's settings build the same Rex from any folder.
fn self_contained(flags: &RexFlags, s: &RunSettings, base: &Path) -> RunSettings {
    let mut s = s.clone();
    s.world = s.world.map(|w| absolute(base, &w));
    let spec = s.spec.unwrap_or_else(crate::system::default_spec);
    s.spec = Some(absolute(base, &spec));
    if !Mission::is_shipped(&s.mission) {
        // A mission file named on the command line is relative to the
        // current folder; one in a run file, to the run file's.
        let from = if flags.mission.is_some() {
            std::env::current_dir().unwrap_or_default()
        } else {
            base.to_owned()
        };
        s.mission = absolute(&from, Path::new(&s.mission)).display().to_string();
    }
    s
}

/// Prints acknowledgements and a line every few seconds (nothing when `quiet`).
pub fn printer(quiet: bool) -> impl FnMut(Progress<'_>) + Send + 'static {
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

impl Application for RexApp {
    type Flags = RexFlags;
    type Config = RunSettings;
    type Seen = Seen;

    fn configure(
        &mut self,
        flags: &RexFlags,
        common: &Common,
    ) -> Result<Vec<RunSettings>, AppError> {
        self.flags = flags.clone();
        let (settings, base) = RexApp::settings(flags, common)?;
        // The report folder is checked before the simulation, not after it.
        flags.report.check()?;
        let missions: Vec<String> = if settings.mission == "all" {
            Mission::SHIPPED.iter().map(|m| (*m).to_owned()).collect()
        } else {
            vec![settings.mission.clone()]
        };
        // Every mission's configuration is checked before anything runs.
        let mut runs = Vec::new();
        for mission in missions {
            let s = self_contained(
                flags,
                &RunSettings {
                    mission,
                    ..settings.clone()
                },
                &base,
            );
            RexApp::resolve(&s)?;
            self.spec(&s)?;
            Duration::try_from_secs_f64(s.limit_s)
                .map_err(|e| AppError::invalid(format!("limit_s = {}: {e}", s.limit_s)))?;
            runs.push(s);
        }
        Ok(runs)
    }

    fn spec(&self, config: &RunSettings) -> Result<SpecFile, AppError> {
        let path = config
            .spec
            .clone()
            .unwrap_or_else(crate::system::default_spec);
        SpecFile::read(&path)
    }

    fn build(&mut self, config: &RunSettings, target: &Target<'_>) -> Result<System, AppError> {
        let mut rex = RexApp::resolve(config)?;
        let built = match target {
            Target::Whole => build(&rex),
            Target::Process {
                deployment, boot, ..
            } => {
                // Each start of the process that runs c1 is a new incarnation
                // of it: a2 tells a restart by it and sends the lost plans again.
                rex.c1.boot = *boot;
                build_deployment(&rex, deployment)
            }
        };
        let (system, handles) = built.map_err(|e| AppError::Build(Box::new(e)))?;
        self.handles = Some(handles);
        Ok(system)
    }

    fn watcher(&mut self, config: &RunSettings, common: &Common) -> Box<dyn Watcher<Seen>> {
        let rex = RexApp::resolve(config).ok();
        match (rex, self.spec(config)) {
            (Some(rex), Ok(spec)) => Box::new(RexWatch {
                watch: MissionWatch::new(
                    &rex,
                    Duration::from_secs(5),
                    Box::new(printer(common.quiet)),
                ),
                spec: spec.spec,
                report: self.flags.report.clone(),
                limit_s: config.limit_s,
            }),
            // `configure` resolved it already: this does not happen.
            _ => Box::new(embodied::app::Quiet),
        }
    }

    fn probes(&mut self, probes: &mut Probes<Seen>, here: &dyn Fn(&str) -> bool) {
        if let Some(h) = &self.handles {
            install_probes(probes, h, here);
        }
    }

    fn finished(&mut self, run: &Finished) -> Vec<Seen> {
        self.handles
            .as_ref()
            .map_or_else(Vec::new, |h| last_reports(run, h))
    }

    fn limit(&self, config: &RunSettings) -> Duration {
        Duration::try_from_secs_f64(config.limit_s).unwrap_or(Duration::from_secs(300))
    }

    fn announce(&self, config: &RunSettings) -> Option<String> {
        let c = RexApp::resolve(config).ok()?;
        let plans = if c.mission.listens() {
            "no plans from a2: c1 takes plans from elsewhere, ROS 2 /rex/plan with --ros2, until the time limit".to_owned()
        } else {
            format!("{} plans", c.mission.plans.len())
        };
        Some(format!(
            "rex: mission `{}` ({plans}), planner {}, tracker {:?}, estimator {:?}, planning {:?}, visual odometry {}",
            c.mission.name,
            c.planner.name(),
            c.tracker,
            c.estimator,
            c.runtime,
            if c.visual_odometry { "on" } else { "off" }
        ))
    }

    fn record_options(&self, config: &RunSettings) -> RecordOptions {
        let mut options = crate::record::options();
        if let Ok(c) = RexApp::resolve(config) {
            options.metadata.insert(
                "run".into(),
                [
                    ("mission", c.mission.name.clone()),
                    ("deployment", deployment(&c).to_owned()),
                    ("planner", c.planner.name().to_owned()),
                    ("tracker", format!("{:?}", c.tracker)),
                    ("estimator", format!("{:?}", c.estimator)),
                    ("rex", env!("CARGO_PKG_VERSION").to_owned()),
                ]
                .into_iter()
                .map(|(k, v)| (k.to_owned(), v))
                .collect(),
            );
        }
        options
    }

    fn default_record(&self, config: &RunSettings, _: &Common) -> Option<PathBuf> {
        let rex = RexApp::resolve(config).ok()?;
        self.flags.report.recording(&rex.mission.name)
    }

    fn reconfigure(
        &mut self,
        mut recorded: RunSettings,
        flags: &RexFlags,
        common: &Common,
    ) -> Result<RunSettings, AppError> {
        self.flags = flags.clone();
        overrides(flags, common, &mut recorded)?;
        Ok(recorded)
    }

    #[cfg(feature = "ros2")]
    fn ros2_adapters(&self) -> embodied::ros2::bridge::Adapters {
        crate::ros2::adapters()
    }

    fn check_deployment(&self, config: &RunSettings, deployment: &str) -> Result<(), AppError> {
        let spec = self.spec(config)?.spec;
        if !config.visual_odometry
            && spec
                .deployment(deployment)
                .is_some_and(|d| d.process_of("r11").is_some())
        {
            return Err(AppError::invalid(format!(
                "--no-vo: deployment `{deployment}` runs the visual odometry (r11); choose one that omits it (split_without_vo, split_secure_without_vo)"
            )));
        }
        embodied::app::check_together(
            &spec,
            deployment,
            &WORLD_DRIVERS,
            "the simulated world's drivers share one environment and must run in one process",
        )
    }
}

/// A progress printer that travels with the watcher.
type Printer = Box<dyn FnMut(Progress<'_>) + Send>;

/// Rex's watcher: the mission's reports paired with the truth, and the
/// judgement of every plan, with the report folder.
struct RexWatch {
    watch: MissionWatch<Printer>,
    spec: embodied::spec::Spec,
    /// The report folder's flags.
    report: ReportFlags,
    /// The run's time limit \[s\].
    limit_s: f64,
}

impl Watcher<Seen> for RexWatch {
    fn see(&mut self, seen: Seen) {
        self.watch.see(seen);
    }

    fn ended(&mut self, finished: bool) -> bool {
        self.watch.ended(finished)
    }

    fn judge(&mut self, run: &RunSummary) -> Verdict {
        let out = self
            .watch
            .outcome(run.wall.as_secs_f64(), run.last.as_secs_f64());
        let mut text = crate::report::summary(&out);
        let (config, spec) = (&self.watch.config, &self.spec);
        let write = |dir: &Path| crate::report::write(dir, &out, config, spec);
        text.push_str(&self.report.write(&out.mission, write).unwrap_or_default());
        let listens = self.watch.config.mission.listens();
        if listens {
            text.push_str(&match out.foreign.len() {
                0 => "listened: c1 took no plan\n".to_owned(),
                1 => "listened: c1 took 1 plan from elsewhere\n".to_owned(),
                n => format!("listened: c1 took {n} plans from elsewhere\n"),
            });
        }
        if !out.completed && listens {
            text.push_str("the run ended with a plan c1 took not yet executed to its end\n");
        } else if !out.completed {
            match run.mode {
                Mode::Launched { .. } => text.push_str("the mission did not complete\n"),
                _ => text.push_str(&format!(
                    "the mission did not complete within {} s of simulated time\n",
                    self.limit_s
                )),
            }
        }
        let failed = out.plans - out.plans_achieved();
        if failed > 0 {
            text.push_str(&format!(
                "{failed} of {} plans not achieved (see the plan lines above)\n",
                out.plans
            ));
        }
        Verdict {
            passed: out.succeeded(),
            text,
            line: out.summary_line(),
        }
    }
}
