//! The composition root: the whole Rex system of the paper's Fig. 3, the locomotion
//! agent a1 (c1, e11 and the platform E1; r11 and the camera R1 join with visual
//! odometry) in the simulated world with the ontology agent a2 and the map agent
//! a3, linked as in `specs/rex.ron`, and the settings of a run. The only module
//! below the runs and the program that knows both a1 and the world.
//!
//! Periods come from the spec, and a test checks that every link built here is a link
//! of the spec with the same policy, and that every spec link between deployed
//! components is built: the spec and the code cannot drift apart.

use std::path::{Path, PathBuf};

use embodied::spec::model::Spec;
use embodied::spec::{Assembly, AssemblyError};
use embodied::{DriverHandle, ExecConfig, OffloadMode, SubsystemHandle, System};
use serde::{Deserialize, Serialize};

use crate::a1::c1::trajgen::{Runtime, TrajGen};
use crate::a1::c1::{C1, C1Memory, C1Params, c1_fsm};
use crate::a1::e11::{E11, E11Memory, EstimatorKind, Safety, TrackerKind, e11_fsm};
use crate::a1::map::{Map, Rect};
use crate::a1::r11::{Odometry, R11, R11Memory, r11_fsm};
use crate::algorithms::planner::ground::GroundTiming;
use crate::algorithms::planner::{PlannerKind, PlannerSettings};
use crate::algorithms::vo::VoSettings;
use crate::config::{self, ConfigError, Invalid, Validate};
use crate::mission::Mission;
use crate::model::{Friction, Lateral};
use crate::world::camera::SceneConfig;
use crate::world::devices::{Platform, StereoCamera};
use crate::world::partners::Ontology;
use crate::world::{self, MapAgentHandles, WorldConfig, WorldError};

/// The choices of a Rex run, as written in a run file (`rex-agent/config/rex.ron`);
/// each field is also a flag of the main job (`--mission`, `--planner`...).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RunSettings {
    /// A shipped mission (`square`, `figure_eight`, `slalom`, or `listen`: no
    /// plans from a2, see [`Mission::listens`]) or a mission file.
    pub mission: String,
    /// The world file, relative to the run file; `None`: the shipped world.
    pub world: Option<PathBuf>,
    /// The spec Rex is built from, relative to the run file; `None`:
    /// `specs/rex.ron`.
    pub spec: Option<PathBuf>,
    /// One surface (by name, from the world's list) for the whole floor, replacing
    /// the world's default surface and patches; `None`: the world's floor.
    pub surface: Option<String>,
    /// The trajectory planner.
    pub planner: PlannerKind,
    /// Where the planner runs.
    pub planning: Runtime,
    /// Planning time in `c1` iterations (the result is ready this many iterations
    /// after `trajgenStart`, whatever the wall-clock time).
    pub planning_latency: u32,
    /// The tracker of `e11`.
    pub tracker: TrackerKind,
    /// The estimator of `e11`.
    pub estimator: EstimatorKind,
    /// Longest simulated time \[s\].
    pub limit_s: f64,
    /// Run the virtual receptor r11 (stereo visual odometry on the camera R1).
    pub visual_odometry: bool,
    /// Where the camera renders and r11 runs its odometry: `Worker` (threads of
    /// their own, concurrently with the rest of the system) or `Inline` (in their
    /// steps). The run is the same either way.
    pub vision: OffloadMode,
    /// Steps of r11 from a pair's arrival to its motion leaving, at most (it leaves
    /// earlier when the next pair arrives); 0: in the step the pair arrives, which
    /// leaves the odometry no time to run beside the rest.
    pub vo_latency: u32,
    /// The limits a1 keeps and the run is judged by.
    pub limits: Limits,
}

/// The limits a1 keeps, and by which the run judges each plan (a section of the
/// run file). a1 measures with its own estimate; the run with the simulation's
/// truth.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Limits {
    /// How close the platform's centre may come to a wall or an obstacle \[m\]: its
    /// footprint. `e11` stops the platform closer; the run fails a plan during
    /// which the true pose came closer.
    pub clearance_m: f64,
    /// Plan points and planned fragments keep this much more \[m\].
    pub plan_margin_m: f64,
    /// `e11` stops the platform when its estimate is farther than this from the
    /// reference \[m\]; the run fails a plan whose true tracking error exceeded it.
    pub tracking_m: f64,
    /// A plan's last point is reached within this distance \[m\].
    pub final_m: f64,
    /// What `e11` allows for its estimate's own error when it reports a plan
    /// reached: only when the estimate is within `final_m − final_margin_m` of
    /// the last point, and within `final_margin_m` of the map poses of the last
    /// half second \[m\] (a success it reports is then one the truth confirms
    /// unless the estimate is off by more than this).
    pub final_margin_m: f64,
    /// How long `e11` waits, holding a plan's last point, for the platform to
    /// come within `final_m` \[s\].
    pub settle_s: f64,
    /// `e11` stops the platform when braking at this deceleration \[m/s²\] would end
    /// outside the free space.
    pub brake_decel: f64,
    /// The run fails a plan during which the estimate was farther than this from
    /// the true position while the motion capture delivered \[m\].
    pub estimate_m: f64,
    /// `c1` slows each fragment down until it asks at most this share of a
    /// wheel's traction on the ground `e11` estimates (the rest is left to the
    /// tracker); 0 leaves fragments as planned.
    pub traction_share: f64,
    /// The ground fragments are timed for until the estimate has settled (the
    /// slipperiest expected).
    pub cautious_ground: Friction,
    /// The torque `e11` commands at most per wheel \[N m\]; `None`: the
    /// platform's `torque_max` (the world file's). Above the platform's limit
    /// the platform clamps the commands, and the spec's contracts on `e11`'s
    /// torques (`torque_wheel_1..4`, ±10 N m) are broken when `e11` asks for more.
    pub torque_nm: Option<f64>,
    /// The share of each wheel's traction on the ground `e11` estimates that
    /// its NMPC's torques may use (above it the wheel spins); more than 1
    /// lets it ask what the ground cannot take (a stop then brakes harder
    /// than the wheels grip, up to `torque_nm`).
    pub traction_margin: f64,
}

impl Default for Limits {
    fn default() -> Self {
        Limits {
            clearance_m: 0.45,
            plan_margin_m: 0.1,
            tracking_m: 0.3,
            final_m: 0.1,
            final_margin_m: 0.03,
            settle_s: 3.0,
            brake_decel: 1.0,
            estimate_m: 0.1,
            traction_share: 0.8,
            cautious_ground: Friction {
                mu_long: 0.1,
                mu_lat: 0.07,
                rolling: 0.01,
            },
            torque_nm: None,
            traction_margin: crate::algorithms::tracking::TRACTION_MARGIN,
        }
    }
}

impl Validate for Limits {
    fn validate(&self) -> Result<(), Invalid> {
        config::positive("limits.clearance_m", self.clearance_m)?;
        config::non_negative("limits.plan_margin_m", self.plan_margin_m)?;
        config::positive("limits.tracking_m", self.tracking_m)?;
        config::positive("limits.final_m", self.final_m)?;
        config::non_negative("limits.final_margin_m", self.final_margin_m)?;
        if self.final_margin_m >= self.final_m {
            return Err((
                "limits.final_margin_m".into(),
                self.final_margin_m.to_string(),
                "must be less than limits.final_m (no plan could be reported reached)",
            ));
        }
        config::non_negative("limits.settle_s", self.settle_s)?;
        config::positive("limits.brake_decel", self.brake_decel)?;
        config::positive("limits.estimate_m", self.estimate_m)?;
        if !(0.0..=1.0).contains(&self.traction_share) {
            return Err((
                "limits.traction_share".into(),
                self.traction_share.to_string(),
                "must be a share of the traction, in [0, 1]",
            ));
        }
        config::positive(
            "limits.cautious_ground.mu_long",
            self.cautious_ground.mu_long,
        )?;
        config::positive("limits.cautious_ground.mu_lat", self.cautious_ground.mu_lat)?;
        config::non_negative(
            "limits.cautious_ground.rolling",
            self.cautious_ground.rolling,
        )?;
        if let Some(t) = self.torque_nm {
            config::positive("limits.torque_nm", t)?;
        }
        config::positive("limits.traction_margin", self.traction_margin)
    }
}

impl Limits {
    /// The free space of `world` with the clearance `e11` keeps.
    pub fn safety_map(&self, world: &WorldConfig) -> Map {
        Map::of_scene(&world.scene, self.clearance_m)
    }

    /// The free space of `world` with the clearance plans keep.
    pub fn plan_map(&self, world: &WorldConfig) -> Map {
        Map::of_scene(&world.scene, self.clearance_m + self.plan_margin_m)
    }

    /// How `c1` times fragments for the ground (`None` when `traction_share` is
    /// 0), fragments at most `max_duration` seconds long.
    pub fn ground_timing(&self, world: &WorldConfig, max_duration: f64) -> Option<GroundTiming> {
        (self.traction_share > 0.0).then(|| GroundTiming {
            model: Lateral::new(world.platform.clone()),
            margin: self.traction_share,
            max_duration,
            cautious: self.cautious_ground,
        })
    }

    /// `e11`'s safety settings in `world`.
    pub fn safety(&self, world: &WorldConfig) -> Safety {
        Safety {
            map: self.safety_map(world),
            max_tracking_error: self.tracking_m,
            final_tolerance: self.final_m,
            final_margin: self.final_margin_m,
            settle: self.settle_s,
            brake_decel: self.brake_decel,
            torque_max: self.torque_nm,
            traction_margin: self.traction_margin,
        }
    }
}

impl Default for RunSettings {
    fn default() -> Self {
        RunSettings {
            mission: "figure_eight".into(),
            world: None,
            spec: None,
            surface: None,
            planner: PlannerKind::Ecsa,
            planning: Runtime::Thread,
            planning_latency: 3,
            tracker: TrackerKind::Nmpc,
            estimator: EstimatorKind::Mhe,
            limit_s: 600.0,
            visual_odometry: true,
            vision: OffloadMode::Worker,
            vo_latency: 10,
            limits: Limits::default(),
        }
    }
}

impl Validate for RunSettings {
    fn validate(&self) -> Result<(), Invalid> {
        if !(self.limit_s.is_finite() && self.limit_s > 0.0 && self.limit_s <= 1e7) {
            return Err((
                "limit_s".into(),
                self.limit_s.to_string(),
                "must be a positive number of seconds, at most 10,000,000",
            ));
        }
        self.limits.validate()?;
        if self.planning_latency == 0 {
            return Err((
                "planning_latency".into(),
                "0".into(),
                "planning takes at least one iteration of c1",
            ));
        }
        Ok(())
    }
}

impl RunSettings {
    /// Load a run file.
    pub fn load(path: &Path) -> Result<RunSettings, ConfigError> {
        config::load(path)
    }

    /// The shipped run file (`rex-agent/config/rex.ron`).
    pub fn shipped() -> Result<RunSettings, ConfigError> {
        RunSettings::load(&config::config_dir().join("rex.ron"))
    }

    /// The configuration these settings describe; relative paths are taken from
    /// `base` (the run file's folder).
    pub fn resolve(&self, base: &Path) -> Result<RexConfig, ConfigError> {
        self.validate()
            .map_err(|(field, value, reason)| ConfigError::Invalid {
                path: PathBuf::from("<run settings>"),
                field,
                value,
                reason,
            })?;
        let mut world = match &self.world {
            Some(path) => WorldConfig::load(&base.join(path))?,
            None => WorldConfig::shipped()?,
        };
        if let Some(name) = &self.surface {
            if !world.surfaces.surfaces.iter().any(|s| &s.name == name) {
                return Err(ConfigError::Invalid {
                    path: PathBuf::from("<run settings>"),
                    field: "surface".into(),
                    value: name.clone(),
                    reason: "not a surface of the world (its `surfaces` list names them)",
                });
            }
            world.surfaces.default = name.clone();
            world.surfaces.patches.clear();
        }
        let (mission, mission_path) = if Mission::is_shipped(&self.mission) {
            (
                Mission::shipped(&self.mission)?,
                config::missions_dir().join(format!("{}.ron", self.mission)),
            )
        } else {
            let path = base.join(&self.mission);
            (Mission::load(&path)?, path)
        };
        // Every point of every plan in the free space a1 plans in: otherwise c1
        // would refuse the plan at run time; say so before.
        let map = self.limits.plan_map(&world);
        for (i, plan) in mission.plans.iter().enumerate() {
            for (k, p) in plan.iter().enumerate() {
                if let Err(why) = map.explain(p.x, p.y) {
                    return Err(ConfigError::Mismatch {
                        path: mission_path,
                        field: format!("plans[{i}][{k}]"),
                        reason: format!("is off the world's free space: {why}"),
                    });
                }
            }
        }
        let mut config = RexConfig::new(world, mission);
        config.planner = self.planner;
        config.runtime = self.planning;
        config.planning_latency = self.planning_latency;
        config.tracker = self.tracker;
        config.estimator = self.estimator;
        config.visual_odometry = self.visual_odometry;
        config.vision = self.vision;
        config.vo_latency = self.vo_latency;
        config.limits = self.limits.clone();
        if let Some(spec) = &self.spec {
            config.spec = base.join(spec);
        }
        Ok(config)
    }
}

/// Everything that chooses how Rex runs.
#[derive(Clone, Debug)]
pub struct RexConfig {
    /// The simulated world.
    pub world: WorldConfig,
    /// The mission of a2.
    pub mission: Mission,
    /// The trajectory planner.
    pub planner: PlannerKind,
    /// The planner's limits and preferences (`dt` is set to the period of `e11`).
    pub planner_settings: PlannerSettings,
    /// Where the planner runs.
    pub runtime: Runtime,
    /// Planning time in c1 iterations.
    pub planning_latency: u32,
    /// The tracker of e11.
    pub tracker: TrackerKind,
    /// The estimator of e11.
    pub estimator: EstimatorKind,
    /// c1's settings.
    pub c1: C1Params,
    /// The spec the system follows (periods).
    pub spec: PathBuf,
    /// The executor's error policy.
    pub exec: ExecConfig,
    /// Whether a1 has its virtual receptor r11 (visual odometry) and the camera R1:
    /// the spec's deployment `simulation`, else `simulation_without_vo`.
    pub visual_odometry: bool,
    /// r11 commands a stereo pair every this many of its steps.
    pub acquire_every: u32,
    /// Where the camera renders and r11 runs its odometry.
    pub vision: OffloadMode,
    /// Steps of r11 from a pair's arrival to its motion leaving, at most.
    pub vo_latency: u32,
    /// The limits a1 keeps (c1's map is made from them and the world's scene
    /// when the system is built).
    pub limits: Limits,
}

impl RexConfig {
    /// The world, the mission, and the run settings' defaults (ECSA on a thread,
    /// NMPC and MHE, the default limits).
    pub fn new(world: WorldConfig, mission: Mission) -> RexConfig {
        let defaults = RunSettings::default();
        // Plan well inside the platform's bounds: turning is what costs torque on a
        // skid-steer platform, and the tracker needs a margin to correct errors.
        let planner_settings = PlannerSettings {
            speed_max: world.platform.speed_max * 0.6,
            turn_rate_max: world.platform.yaw_rate_max * 0.6,
            ..PlannerSettings::default()
        };
        RexConfig {
            planner_settings,
            c1: C1Params::default(),
            world,
            mission,
            planner: defaults.planner,
            runtime: defaults.planning,
            planning_latency: defaults.planning_latency,
            tracker: defaults.tracker,
            estimator: defaults.estimator,
            spec: default_spec(),
            exec: ExecConfig::default(),
            visual_odometry: defaults.visual_odometry,
            acquire_every: 5,
            vision: defaults.vision,
            vo_latency: defaults.vo_latency,
            limits: defaults.limits,
        }
    }
}

/// `specs/rex.ron` of this workspace.
pub fn default_spec() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../specs/rex.ron")
}

/// Handles to the parts of a built Rex system: a robot's parts with its own
/// ontology agent a2 ([`RexHandles::robot`] gives them as a robot's of any
/// kind, [`RobotHandles`]).
#[derive(Clone, Copy, Debug)]
pub struct RexHandles {
    /// a1's control subsystem.
    pub c1: SubsystemHandle<C1>,
    /// a1's virtual effector.
    pub e11: SubsystemHandle<E11>,
    /// The platform.
    pub platform: DriverHandle<Platform>,
    /// a2's control subsystem.
    pub c2: SubsystemHandle<Ontology>,
    /// The map agent.
    pub map: MapAgentHandles,
    /// a1's virtual receptor and the camera, when visual odometry runs.
    pub vision: Option<(SubsystemHandle<R11>, DriverHandle<StereoCamera>)>,
}

impl RexHandles {
    /// The same parts as a robot's, which is what the probes and counters
    /// shared with the fleet take.
    pub fn robot(&self) -> RobotHandles {
        RobotHandles {
            c1: self.c1,
            e11: self.e11,
            platform: self.platform,
            c2: Some(self.c2),
            map: self.map,
            vision: self.vision,
        }
    }
}

impl From<&RexHandles> for RobotHandles {
    fn from(h: &RexHandles) -> RobotHandles {
        h.robot()
    }
}

impl From<&RobotHandles> for RobotHandles {
    fn from(h: &RobotHandles) -> RobotHandles {
        *h
    }
}

/// Handles to the parts of one robot of Rex's kind: a whole Rex's
/// ([`RexHandles`]) or a robot's of a fleet (`crate::fleet`).
#[derive(Clone, Copy, Debug)]
pub struct RobotHandles {
    /// a1's control subsystem.
    pub c1: SubsystemHandle<C1>,
    /// a1's virtual effector.
    pub e11: SubsystemHandle<E11>,
    /// The platform.
    pub platform: DriverHandle<Platform>,
    /// The robot's own a2's control subsystem: a whole Rex's; none for a
    /// robot of a fleet, whose plans come from the fleet's one `c2`.
    pub c2: Option<SubsystemHandle<Ontology>>,
    /// The map agent.
    pub map: MapAgentHandles,
    /// a1's virtual receptor and the camera, when visual odometry runs.
    pub vision: Option<(SubsystemHandle<R11>, DriverHandle<StereoCamera>)>,
}

/// Why Rex could not be built.
#[derive(Debug, thiserror::Error)]
pub enum RexError {
    /// The spec could not be read or is invalid.
    #[error("specification {path}: {message}")]
    Spec {
        /// The spec file.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A world part failed.
    #[error(transparent)]
    World(#[from] WorldError),
    /// The system does not follow the spec.
    #[error(transparent)]
    Assembly(#[from] AssemblyError),
    /// An FSM is malformed.
    #[error(transparent)]
    Fsm(#[from] embodied::FsmBuildError),
    /// A period is invalid.
    #[error(transparent)]
    Period(#[from] embodied::PeriodError),
    /// The NMPC's settings are invalid.
    #[error(transparent)]
    Nmpc(#[from] crate::algorithms::mpc::NmpcError),
    /// The MHE's settings are invalid.
    #[error(transparent)]
    Mhe(#[from] crate::algorithms::mpc::MheError),
}

/// Load and check the spec; errors carry the rendered findings.
pub fn load_spec(path: &Path) -> Result<Spec, RexError> {
    let (spec, report) = embodied::spec::check_file(path).map_err(|e| RexError::Spec {
        path: path.to_owned(),
        message: e.to_string(),
    })?;
    match spec {
        Some(spec) if report.is_ok() => Ok(spec),
        _ => Err(RexError::Spec {
            path: path.to_owned(),
            message: report.short(),
        }),
    }
}

/// The spec's deployment that `config` runs: `simulation`, or
/// `simulation_without_vo` without visual odometry.
pub fn deployment(config: &RexConfig) -> &'static str {
    if config.visual_odometry {
        "simulation"
    } else {
        "simulation_without_vo"
    }
}

/// Build Rex as the spec's deployment `simulation` (or `simulation_without_vo`)
/// says: a1 = c1 + e11 + E1 (+ r11 and R1 with visual odometry), a2, a3, each in
/// its agent with its period, linked by the spec's links. Only what a spec cannot
/// hold is written here: the initial memories, the FSMs' functions, the drivers.
pub fn build(config: &RexConfig) -> Result<(System, RexHandles), RexError> {
    build_deployment(config, deployment(config))
}

/// Build Rex as deployment `name` of the spec says, in one process: the components
/// it runs (visual odometry if it runs r11), linked by the spec's links.
pub fn build_deployment(config: &RexConfig, name: &str) -> Result<(System, RexHandles), RexError> {
    let spec = load_spec(&config.spec)?;
    let mut rex = Assembly::new(&spec, name)?;
    world::add_environment(&mut rex);
    let dt = rex.period("e11")?.as_secs_f64();
    let c1 = rex.subsystem("c1", c1_memory(config, dt), c1_fsm()?)?;
    let e11_memory = e11_memory(config, dt, rex.period("E1")?.as_secs_f64())?;
    let e11 = rex.subsystem("e11", e11_memory, e11_fsm()?)?;
    let platform = world::add_platform(&mut rex, &config.world)?;
    let c2 = world::add_ontology(&mut rex, config.mission.clone())?;
    let map = world::add_map_agent(&mut rex, &config.world)?;
    let vision = if rex.runs("r11") {
        let r11 = rex.subsystem(
            "r11",
            R11Memory::new(odometry(config)?, config.acquire_every),
            r11_fsm()?,
        )?;
        let camera = world::add_camera(&mut rex, &config.world, config.vision)?;
        Some((r11, camera))
    } else {
        None
    };
    let system = rex.build()?;
    Ok((
        system,
        RexHandles {
            c1,
            e11,
            platform,
            c2,
            map,
            vision,
        },
    ))
}

/// The planner's settings for fragments stepped every `dt` seconds (e11's period).
fn planner_settings(config: &RexConfig, dt: f64) -> PlannerSettings {
    PlannerSettings {
        dt,
        ..config.planner_settings.clone()
    }
}

/// c1's initial memory for `config`: its planner, its map (the world's scene
/// with the clearance plans keep) and its settings; `dt` is e11's period \[s\].
pub fn c1_memory(config: &RexConfig, dt: f64) -> C1Memory {
    let settings = planner_settings(config, dt);
    let trajgen = TrajGen::new(
        config.planner,
        settings.clone(),
        config.runtime,
        config.planning_latency,
    );
    C1Memory::new(
        trajgen,
        C1Params {
            map: config.limits.plan_map(&config.world),
            ground: config
                .limits
                .ground_timing(&config.world, settings.max_duration),
            ..config.c1.clone()
        },
    )
}

/// e11's initial memory for `config`: its tracker, its estimator and its safety
/// monitor; `dt` is its period and `e1_period` the platform's \[s\].
pub fn e11_memory(config: &RexConfig, dt: f64, e1_period: f64) -> Result<E11Memory, RexError> {
    let settings = planner_settings(config, dt);
    let p = config.world.platform.clone();
    Ok(E11Memory::new(
        config.tracker.build(p.clone(), dt)?,
        config.estimator.build(
            p,
            settings.slip,
            config.limits.cautious_ground,
            dt,
            config.world.sensors.encoder_window(e1_period),
        )?,
        dt,
        settings.slip.x_icr,
    )
    .with_safety(config.limits.safety(&config.world)))
}

/// r11's visual odometry for `config`: the camera's calibration and mount,
/// on workers or inline as `config.vision` says.
pub fn odometry(config: &RexConfig) -> Result<Odometry, RexError> {
    let camera_config = &config.world.camera;
    // On workers, the odometry takes the cores the rest leaves: the renderer's
    // worker, the executor and the recorder's writer keep about one busy. Its
    // helpers then match the circles and refine the matches (the same motions
    // on any number: each is found and refined alone). On two cores, one
    // thread: its helpers only competed with the renderer there (the main
    // job alternated six times, one thread against two: `realtime_factor`
    // 1.00-1.15x, median 1.01x, with the report; 0.99-1.32x, median 1.05x,
    // without; never slower by more than 1 %).
    let threads = match config.vision {
        OffloadMode::Worker => std::thread::available_parallelism()
            .map_or(1, |n| n.get().saturating_sub(1).clamp(1, 4)),
        OffloadMode::Inline => 1,
    };
    Odometry::pipelined(
        camera_config.calibration(),
        camera_config.mount(),
        VoSettings {
            threads,
            ..VoSettings::default()
        },
        config.vision,
        config.vo_latency,
    )
    .map_err(|e| RexError::Spec {
        path: config.spec.clone(),
        message: e.to_string(),
    })
}

/// The map a1 is given: the scene the camera renders (the same room and boxes).
/// Here, in the composition root, because a1 knows its map and not the
/// simulated world it is made from.
impl Map {
    /// The map of the scene the camera renders (the same room and boxes).
    pub fn of_scene(scene: &SceneConfig, clearance: f64) -> Map {
        let r = &scene.room;
        Map {
            room: Rect {
                x0: r.x0,
                y0: r.y0,
                x1: r.x1,
                y1: r.y1,
            },
            obstacles: scene
                .obstacles
                .iter()
                .map(|o| Rect {
                    x0: o.x0,
                    y0: o.y0,
                    x1: o.x1,
                    y1: o.y1,
                })
                .collect(),
            clearance,
        }
    }
}
