//! The fleet on the application layer ([`embodied::app`]), as Rex is
//! (`crate::app`): the whole fleet in either executor, or one process of a
//! deployment of the fleet's spec over Zenoh, launched, killed and restarted,
//! recorded and replayed by the layer.
//!
//! * Its spec is the generated one ([`super::spec::fleet_spec`]); every process
//!   of a launch makes the same text from the same flags (`--robots M
//!   --per-process P`, `--short`), which the launcher passes on to its
//!   children, and a recording keeps them (its configuration) for `replay`.
//! * Its build makes the whole fleet ([`super::build`]), for the whole spec
//!   or for a deployment's process, whose part the layer runs: the robots
//!   whose `c1` runs in the process plan on a thread of their own (as Rex
//!   does in real time), the others' (never run here) inline; every `c1`
//!   of a start carries the start's epoch, so that the fleet's `c2` tells
//!   its restart and sends that robot's lost plans again.
//! * Its watcher reads every robot as Rex's watcher reads Rex (the same
//!   probes, tagged with the robot), the world process's truth every 10 ms,
//!   and judges every plan of every robot against that truth; the run ends
//!   once every robot's mission has ended, and passes if every plan was
//!   achieved and no two robots came closer than [`super::Fleet::safety_m`].
//!
//! ```text
//! cargo run --release -p rex-agent --example fleet -- launch --deployment grouped_without_vo \
//!     --robots 4 --per-process 2 --short --kill robots_1@5 --record fleet.mcap
//! cargo run --release -p rex-agent --example fleet -- replay fleet.mcap --subsystem c1_3
//! ```

use std::fmt::Write as _;
use std::time::Duration;

use embodied::app::{
    AppError, Application, Common, RunSummary, SpecFile, Target, Verdict, Watcher,
};
use embodied::record::RecordOptions;
use embodied::spec::model::Spec;
use embodied::{Finished, Probes, System};
use serde::{Deserialize, Serialize};

use super::spec::robot_name;
use super::{
    Fleet, FleetHandles, FleetOutcome, FleetSeen, FleetWatch, Printer, Warehouse, dispatch_counters,
};
use crate::a1::c1::trajgen::Runtime;
use crate::run::{Counters, Progress, Seen, judge::Verdict as PlanVerdict, last_reports};
use crate::system::RexConfig;

/// The most robots a fleet may have: one aisle each, every robot's agents in
/// the spec (the checker and the processes' builds grow with it).
pub const MAX_ROBOTS: usize = 1024;

/// The fleet's own flags (the layer adds `--for`, `--realtime`, `--record`,
/// `--deployment`, `--process`, `--port`, `launch`, `replay`...).
#[derive(clap::Args, Clone, Debug)]
pub struct FleetFlags {
    /// Robots in the fleet, one aisle of the warehouse each (1 to 1024).
    #[arg(long, global = true, value_name = "M", default_value_t = 4)]
    pub robots: usize,
    /// Robots whose a1 parts (c1, e11) share a process of the deployment
    /// `grouped_without_vo` (at least 1).
    #[arg(long, global = true, value_name = "P", default_value_t = 2)]
    pub per_process: usize,
    /// The short warehouse of the tests: aisles 6 m long, two short plans a
    /// robot (default: 12 m, two plans 9.5 m along the aisle).
    #[arg(long, global = true)]
    pub short: bool,
    /// Without visual odometry (a run of the whole fleet: the cameras and
    /// r11 are left out; the grouped deployment never has them).
    #[arg(long, global = true)]
    pub no_vo: bool,
}

impl Default for FleetFlags {
    fn default() -> Self {
        FleetFlags {
            robots: 4,
            per_process: 2,
            short: false,
            no_vo: false,
        }
    }
}

/// Everything a run of the fleet is built from (recorded with the run, so
/// that `replay` builds the same fleet).
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct FleetConfig {
    /// The warehouse (its aisles are the robots, its plans theirs).
    pub warehouse: Warehouse,
    /// Robots' a1 parts in each process of `grouped_without_vo`.
    pub per_process: usize,
    /// Whether the robots have visual odometry (a run of the whole fleet).
    pub visual_odometry: bool,
    /// The time limit without `--for` \[s\].
    pub limit_s: f64,
}

impl FleetConfig {
    /// The configuration the flags describe (invalid input named).
    pub fn of(flags: &FleetFlags) -> Result<FleetConfig, AppError> {
        if flags.robots == 0 || flags.robots > MAX_ROBOTS {
            return Err(AppError::invalid(format!(
                "--robots {}: a fleet has 1 to {MAX_ROBOTS} robots",
                flags.robots
            )));
        }
        if flags.per_process == 0 {
            return Err(AppError::invalid(
                "--per-process 0: a process of the grouped deployment runs at least one robot",
            ));
        }
        let warehouse = if flags.short {
            Warehouse::short(flags.robots)
        } else {
            Warehouse::standard(flags.robots)
        };
        Ok(FleetConfig {
            warehouse,
            per_process: flags.per_process,
            visual_odometry: !flags.no_vo,
            limit_s: 120.0,
        })
    }

    /// Check a configuration read back from a recording (`replay`): as many
    /// robots as a fleet may have, a warehouse of finite positive sizes, at
    /// least one robot a process, a positive time limit; every robot's plans
    /// on its aisle.
    pub fn validate(&self) -> Result<(), AppError> {
        let w = &self.warehouse;
        let invalid = |what: String| {
            Err(AppError::invalid(format!(
                "the fleet's configuration: {what}"
            )))
        };
        if w.aisles == 0 || w.aisles > MAX_ROBOTS {
            return invalid(format!("{} robots (1 to {MAX_ROBOTS})", w.aisles));
        }
        if self.per_process == 0 {
            return invalid("per_process 0".into());
        }
        let sizes = [
            ("length", w.length),
            ("aisle_width", w.aisle_width),
            ("shelf_depth", w.shelf_depth),
            ("shelf_height", w.shelf_height),
            ("limit_s", self.limit_s),
        ];
        if let Some((name, v)) = sizes.iter().find(|(_, v)| !(v.is_finite() && *v > 0.0)) {
            return invalid(format!("{name} = {v} (a finite positive number)"));
        }
        if !(w.cross.is_finite() && w.cross >= 0.0 && w.start_x.is_finite()) {
            return invalid(format!("cross = {}, start_x = {}", w.cross, w.start_x));
        }
        self.fleet()?.configs().map_err(AppError::invalid)?;
        Ok(())
    }

    /// The fleet it describes.
    pub fn fleet(&self) -> Result<Fleet, AppError> {
        let mut fleet = Fleet::in_warehouse(self.warehouse.clone(), self.visual_odometry)
            .map_err(AppError::invalid)?;
        fleet.per_process = self.per_process.max(1);
        Ok(fleet)
    }
}

/// The fleet as an [`Application`] of the layer.
#[derive(Debug, Default)]
pub struct FleetApp {
    /// The handles of the fleet last built (for its probes and last
    /// reports).
    handles: Option<FleetHandles>,
}

impl FleetApp {
    /// The robots' configurations for `target`: their `c1` planning on a
    /// thread where it runs in real time, carrying the start's epoch.
    fn configs(
        fleet: &Fleet,
        spec: &Spec,
        target: &Target<'_>,
    ) -> Result<Vec<RexConfig>, AppError> {
        let mut configs = fleet.configs().map_err(AppError::invalid)?;
        if let Target::Process {
            deployment,
            process,
            boot,
            ..
        } = target
        {
            let dep = spec.deployment(deployment);
            for (i, config) in configs.iter_mut().enumerate() {
                config.c1.boot = *boot;
                let here = dep
                    .and_then(|d| d.process_of(&robot_name("c1", i)))
                    .is_some_and(|p| p.name == *process);
                if here {
                    config.runtime = Runtime::Thread;
                }
            }
        }
        Ok(configs)
    }
}

/// The drivers of a robot that act on or sense the shared world.
const WORLD_DRIVERS: [&str; 3] = ["E1", "R1", "R3"];

/// Check that `deployment` keeps every robot's world drivers in one process:
/// they share the fleet's truth.
fn check_world(spec: &Spec, deployment: &str, robots: usize) -> Result<(), AppError> {
    let drivers: Vec<String> = (0..robots)
        .flat_map(|i| WORLD_DRIVERS.iter().map(move |d| robot_name(d, i)))
        .collect();
    let drivers: Vec<&str> = drivers.iter().map(String::as_str).collect();
    embodied::app::check_together(
        spec,
        deployment,
        &drivers,
        "the robots' platforms and sensors share the fleet's truth and must run in one process",
    )
}

impl Application for FleetApp {
    type Flags = FleetFlags;
    type Config = FleetConfig;
    type Seen = FleetSeen;

    fn configure(
        &mut self,
        flags: &FleetFlags,
        common: &Common,
    ) -> Result<Vec<FleetConfig>, AppError> {
        let mut config = FleetConfig::of(flags)?;
        if let Some(limit) = common.limit()? {
            config.limit_s = limit.as_secs_f64();
        }
        // Every robot's plans on its aisle, before anything runs.
        config.validate()?;
        Ok(vec![config])
    }

    fn reconfigure(
        &mut self,
        recorded: FleetConfig,
        _: &FleetFlags,
        _: &Common,
    ) -> Result<FleetConfig, AppError> {
        // The recorded fleet is replayed whatever the flags say: its spec and
        // its robots are the recording's.
        recorded.validate()?;
        Ok(recorded)
    }

    fn spec(&self, config: &FleetConfig) -> Result<SpecFile, AppError> {
        let spec = config.fleet()?.spec();
        SpecFile::parse(
            format!("{}.ron (generated from specs/rex.ron)", spec.name),
            super::spec::to_text(&spec),
        )
    }

    fn build(&mut self, config: &FleetConfig, target: &Target<'_>) -> Result<System, AppError> {
        let fleet = config.fleet()?;
        let spec = fleet.spec();
        let configs = FleetApp::configs(&fleet, &spec, target)?;
        let deployment = target.deployment().unwrap_or(fleet.deployment());
        let (system, handles) =
            super::build(&spec, deployment, &configs).map_err(|e| AppError::Build(Box::new(e)))?;
        self.handles = Some(handles);
        Ok(system)
    }

    fn watcher(&mut self, config: &FleetConfig, common: &Common) -> Box<dyn Watcher<FleetSeen>> {
        let fleet = config.fleet();
        let configs = fleet.as_ref().ok().and_then(|f| f.configs().ok());
        match (fleet, configs) {
            (Ok(fleet), Some(configs)) => {
                let quiet = common.quiet;
                Box::new(FleetAppWatch {
                    watch: FleetWatch::new(&configs, Duration::from_secs(3600), |i| {
                        printer(i, quiet)
                    }),
                    safety_m: fleet.safety_m(),
                    limit_s: config.limit_s,
                })
            }
            // `configure` made both already: this does not happen.
            _ => Box::new(embodied::app::Quiet),
        }
    }

    fn probes(&mut self, probes: &mut Probes<FleetSeen>, here: &dyn Fn(&str) -> bool) {
        if let Some(handles) = &self.handles {
            super::install_probes(probes, handles, here);
        }
    }

    fn finished(&mut self, run: &Finished) -> Vec<FleetSeen> {
        let Some(handles) = &self.handles else {
            return Vec::new();
        };
        handles
            .robots
            .iter()
            .enumerate()
            .flat_map(|(i, h)| {
                last_reports(run, h).into_iter().map(move |mut seen| {
                    if let Seen::Counters(c) = &mut seen {
                        // The process's executor errors once, not once a
                        // robot: the layer counts them for the run.
                        c.executor_errors = 0;
                        // What the fleet's c2 counted of this robot, where
                        // it ran.
                        embodied::app::Tally::tally(
                            c.as_mut(),
                            dispatch_counters(run, &handles.c2, i),
                        );
                    }
                    FleetSeen::Robot(i, Box::new(seen))
                })
            })
            .collect()
    }

    fn limit(&self, config: &FleetConfig) -> Duration {
        Duration::try_from_secs_f64(config.limit_s).unwrap_or(Duration::from_secs(120))
    }

    fn announce(&self, config: &FleetConfig) -> Option<String> {
        let w = &config.warehouse;
        Some(format!(
            "fleet: {} robots, one aisle each ({} m long), {} plans a robot, visual odometry {}",
            w.aisles,
            w.length,
            w.plans.len(),
            if config.visual_odometry { "on" } else { "off" }
        ))
    }

    fn record_options(&self, _: &FleetConfig) -> RecordOptions {
        RecordOptions {
            codecs: crate::record::codecs(),
            ..RecordOptions::default()
        }
    }

    fn check_deployment(&self, config: &FleetConfig, deployment: &str) -> Result<(), AppError> {
        let spec = self.spec(config)?.spec;
        check_world(&spec, deployment, config.warehouse.aisles)
    }
}

/// Robot `i`'s progress: its acknowledgements (nothing when `quiet`).
fn printer(i: usize, quiet: bool) -> Printer {
    Box::new(move |p: Progress<'_>| {
        if let (Progress::Ack { t, ack }, false) = (p, quiet) {
            eprintln!(
                "[{t:7.2} s] robot {i}: plan {} acknowledged: {:?}",
                ack.plan, ack.status
            );
        }
    })
}

/// The fleet's watcher on the layer: every robot's reports paired with the
/// truth, the separation, and the judgement of every plan.
struct FleetAppWatch {
    watch: FleetWatch,
    /// The distance two robots must keep \[m\].
    safety_m: f64,
    /// The run's time limit \[s\].
    limit_s: f64,
}

impl Watcher<FleetSeen> for FleetAppWatch {
    fn see(&mut self, seen: FleetSeen) {
        self.watch.see(seen);
    }

    fn ended(&mut self, finished: bool) -> bool {
        self.watch.ended(finished)
    }

    fn status(&self) -> Option<String> {
        Some(format!(
            "{} of {} robots' missions ended",
            self.watch.robots_done(),
            self.watch.robots.len()
        ))
    }

    fn judge(&mut self, run: &RunSummary) -> Verdict {
        let (wall, sim) = (run.wall.as_secs_f64(), run.last.as_secs_f64());
        let robots: Vec<_> = self
            .watch
            .robots
            .iter_mut()
            .map(|w| w.outcome(wall, sim))
            .collect();
        let out = FleetOutcome {
            completed: robots.iter().all(|o| o.completed),
            sim_s: sim,
            wall_s: wall,
            min_separation_m: self.watch.min_separation,
            closest: self.watch.closest,
            robots,
        };
        let text = judgement(&out, self.safety_m, self.limit_s);
        Verdict {
            passed: out.completed
                && out.achieved() == out.plans()
                && out.min_separation_m >= self.safety_m,
            text,
            line: launch_line(&out),
        }
    }
}

/// The counters of every robot, added up.
fn counters(out: &FleetOutcome) -> Counters {
    let mut all = Counters::default();
    for robot in &out.robots {
        embodied::app::Tally::tally(&mut all, robot.counters.clone());
    }
    all
}

/// The summary of a fleet's run: every plan of every robot as judged, each
/// robot's line, the recovery and the separation.
fn judgement(out: &FleetOutcome, safety_m: f64, limit_s: f64) -> String {
    let mut text = String::new();
    for (i, robot) in out.robots.iter().enumerate() {
        for r in &robot.reports {
            let _ = writeln!(text, "robot {i}: {r}");
        }
        let _ = writeln!(text, "robot {i}: {}", robot.summary_line());
        // What the fleet's c2 counted of this robot: a restart of its c1,
        // and what was sent to it again.
        let c = &robot.counters;
        let _ = writeln!(
            text,
            "robot {i}: recovery c1_restarts={} plans_resent={} fragments_repeated={}",
            c.c1_restarts, c.plans_resent, c.fragments_repeated
        );
    }
    let c = counters(out);
    let _ = writeln!(
        text,
        "recovery c1_restarts={} plans_resent={} fragments_repeated={} watchdog_steps={}",
        c.c1_restarts, c.plans_resent, c.fragments_repeated, c.watchdog_steps
    );
    match out.closest {
        Some((t, a, b)) => {
            let _ = writeln!(
                text,
                "separation: robots {a} and {b} came closest, {:.3} m apart at t={t:.2} s (they must keep {safety_m:.2} m)",
                out.min_separation_m
            );
        }
        None => text.push_str("separation: one robot, or no truth seen\n"),
    }
    if out.min_separation_m < safety_m {
        let _ = writeln!(text, "robots closer than {safety_m:.2} m");
    }
    if !out.completed {
        let _ = writeln!(
            text,
            "not every robot's mission ended (time limit {limit_s} s)"
        );
    }
    let failed: usize = out
        .robots
        .iter()
        .flat_map(|o| &o.reports)
        .filter(|r| r.verdict != PlanVerdict::Achieved)
        .count();
    if failed > 0 {
        let _ = writeln!(
            text,
            "{failed} of {} plans not achieved (see the robots' lines above)",
            out.plans()
        );
    }
    text
}

/// The figures of a fleet's run on one line (a launch adds its processes
/// and restarts).
fn launch_line(out: &FleetOutcome) -> String {
    let c = counters(out);
    format!(
        "fleet robots={} plans={} achieved={} failed={} min_separation_m={:.3} c1_restarts={} plans_resent={} fragments_repeated={} realtime_factor={:.2}",
        out.robots.len(),
        out.plans(),
        out.achieved(),
        out.failed(),
        out.min_separation_m,
        c.c1_restarts,
        c.plans_resent,
        c.fragments_repeated,
        out.realtime_factor()
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flags(robots: usize, per_process: usize) -> FleetFlags {
        FleetFlags {
            robots,
            per_process,
            short: true,
            no_vo: true,
        }
    }

    #[test]
    fn a_fleet_without_robots_or_processes_without_robots_is_invalid_input() {
        for (robots, per_process, says) in [
            (0, 2, "--robots 0"),
            (MAX_ROBOTS + 1, 2, "--robots 1025"),
            (3, 0, "--per-process 0"),
        ] {
            let e = FleetConfig::of(&flags(robots, per_process)).expect_err(says);
            assert!(matches!(e, AppError::Invalid(_)), "{e}");
            assert!(e.to_string().contains(says), "{e}");
        }
    }

    #[test]
    fn a_recorded_configuration_out_of_bounds_is_invalid_input() {
        let good = FleetConfig::of(&flags(2, 1)).expect("valid flags");
        assert!(good.validate().is_ok());
        let mut huge = good.clone();
        huge.warehouse.aisles = usize::MAX;
        let mut nan = good.clone();
        nan.warehouse.length = f64::NAN;
        let mut none = good.clone();
        none.per_process = 0;
        let mut off = good;
        off.warehouse.plans = vec![vec![(3.0, 5.0)]];
        for (bad, says) in [
            (huge, "robots"),
            (nan, "length = NaN"),
            (none, "per_process 0"),
            (off, "off its aisle"),
        ] {
            let e = bad.validate().expect_err(says);
            assert!(matches!(e, AppError::Invalid(_)), "{e}");
            assert!(e.to_string().contains(says), "{says}: {e}");
        }
    }

    #[test]
    fn the_world_split_over_processes_is_refused_and_the_grouped_deployment_passes() {
        let config = FleetConfig::of(&flags(2, 1)).expect("valid flags");
        let mut spec = config.fleet().expect("a fleet").spec();
        assert!(check_world(&spec, "grouped_without_vo", 2).is_ok());
        let dep = spec
            .deployments
            .iter_mut()
            .find(|d| d.name == "grouped_without_vo")
            .expect("the grouped deployment");
        let processes = &mut dep.hosts[0].processes;
        processes[0].runs.retain(|n| n != "E1_1");
        processes[1].runs.push("E1_1".into());
        let e = check_world(&spec, "grouped_without_vo", 2).expect_err("split world");
        assert!(e.to_string().contains("E1_1 runs in `robots_0`"), "{e}");
    }

    #[test]
    fn a_process_builds_its_robots_c1_planning_on_a_thread_with_the_starts_epoch() {
        let config = FleetConfig::of(&flags(4, 2)).expect("valid flags");
        let fleet = config.fleet().expect("a fleet");
        let spec = fleet.spec();
        let target = Target::Process {
            deployment: "grouped_without_vo",
            process: "robots_1",
            incarnation: 1,
            boot: 77,
        };
        let configs = FleetApp::configs(&fleet, &spec, &target).expect("configs");
        let threads: Vec<bool> = configs
            .iter()
            .map(|c| c.runtime == Runtime::Thread)
            .collect();
        assert_eq!(threads, [false, false, true, true]);
        assert!(configs.iter().all(|c| c.c1.boot == 77));
    }
}
