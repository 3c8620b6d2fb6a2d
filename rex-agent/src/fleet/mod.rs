//! A fleet of Rex robots in one shared simulated warehouse (issue 57).
//!
//! * [`spec`]: the fleet's spec, generated from `specs/rex.ron`: per robot `i`
//!   the agents `a1_i` (c1_i, e11_i, E1_i; r11_i and R1_i with visual
//!   odometry) and `a3_i` (c3_i, r31_i, R3_i, its motion capture), and one
//!   ontology agent `a2` for the whole fleet, whose `c2`'s groups to and from
//!   the robots' `c1_i` are fans of M peers (`c2.c1[i].desired_plan`),
//!   checked by the same checker.
//! * [`ontology`]: that `c2`: every robot dispatched as Rex's `c2` dispatches
//!   Rex (its mission's plans one by one, the outcomes kept, the plans not
//!   settled sent again when the robot's `c1` restarts): one activation of
//!   Rex's `c2` FSM per robot, on Rex's memory, at each of its own.
//! * [`Warehouse`]: the shared world: walls around rows of shelves; between two
//!   rows, an aisle; robot `i` has aisle `i`, starts at its west end and is
//!   sent along it. One environment, [`FleetTruth`], holds every platform's
//!   true state; each robot's platform writes its entry, its motion capture
//!   (and camera) read it.
//! * [`run_fleet`]: the fleet in the deterministic executor; each robot judged
//!   as Rex is ([`crate::run::judge`]) against the truth, and the smallest
//!   distance between any two robots measured from the truth.
//! * [`app`]: the fleet on the application layer ([`app::FleetApp`]), as Rex
//!   is: the same judgement from the same probes in either executor, and
//!   the deployment `grouped_without_vo` launched over Zenoh (`fleet launch
//!   --deployment grouped_without_vo --robots M --per-process P`), a process
//!   of robots killed and restarted (`--kill robots_K@SECONDS`: its robots'
//!   platforms held by their watchdogs meanwhile, the fleet's `c2` sending
//!   those robots' lost plans again to their new `c1`, and only theirs),
//!   recorded and replayed. The shared world (with `c2`) is never restarted
//!   (`restarts: 0`: a new one would put every platform back at its start).
//!
//! # The collision rule: one aisle per robot
//!
//! Robots are kept apart by their maps: robot `i`'s map (the free space its
//! planner plans in and its `e11` stops the platform outside of) is the
//! warehouse cropped to its aisle, whose walls are the two rows of shelves
//! either side. Plans are checked to lie in it before the run
//! ([`Warehouse::mission`]), `c1` refuses a plan or a fragment outside it,
//! `e11` stops the platform whose estimate leaves it (less its clearance),
//! and the judge fails a plan during which the true pose left it. Aisles are
//! disjoint (a row of shelves between two), so two robots' centres are at
//! least `2 × clearance + shelf depth` apart as long as each keeps to its
//! free space, more than [`Fleet::safety_m`] (two footprints,
//! `2 × clearance_m`). The run measures it: [`FleetOutcome::min_separation_m`]
//! is the smallest distance between two robots' true positions, every 10 ms.

pub mod app;
pub mod ontology;
pub mod spec;

use std::time::Duration;

use embodied::app::{Watched, Watcher};
use embodied::spec::Assembly;
use embodied::spec::model::Spec;
use embodied::{Finished, NoObserver, OffloadMode, Probes, SubsystemHandle, System, Time};

use crate::a1::c1::c1_fsm;
use crate::a1::c1::trajgen::Runtime;
use crate::a1::e11::e11_fsm;
use crate::a1::r11::{R11Memory, r11_fsm};
use crate::mission::Mission;
use crate::payload::{Ack, Point2, Pose2};
use crate::run::{Counters, MissionWatch, Outcome, Progress, RunError, Seen, install_probes_as};
use crate::system::{self, RexConfig, RexError, RobotHandles};
use crate::world::camera::{Obstacle, Renderer, Room, SceneConfig};
use crate::world::devices::{FleetTruth, MotionCapture, Platform, StereoCamera, Truth};
use crate::world::partners::{MapMemory, MocapMemory, map_fsm, mocap_receptor_fsm};
use crate::world::{MapAgentHandles, WorldConfig, WorldError};
use ontology::{FleetOntology, FleetOntologyInput, FleetOntologyMemory, FleetOntologyOutput};
use spec::{ONTOLOGY, PARTS, robot_name};

/// The warehouse: rows of shelves along x, an aisle between two rows, one aisle
/// a robot. Row `k` spans `y ∈ [k·pitch, k·pitch + shelf_depth]`, `x ∈ [0,
/// length]`; aisle `i` lies between rows `i` and `i + 1`; the walls stand
/// `cross` beyond the rows' ends (cross aisles no robot is sent into).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Warehouse {
    /// Aisles (robots).
    pub aisles: usize,
    /// Length of the rows of shelves and the aisles \[m\].
    pub length: f64,
    /// Width of an aisle between two rows \[m\].
    pub aisle_width: f64,
    /// Depth of a row of shelves \[m\].
    pub shelf_depth: f64,
    /// Height of the shelves \[m\].
    pub shelf_height: f64,
    /// Width of the cross aisles at both ends \[m\].
    pub cross: f64,
    /// The plans of each robot, along its aisle: points `(x, dy)`, `x` from
    /// the aisle's west end, `dy` from its centre line.
    pub plans: Vec<Vec<(f64, f64)>>,
    /// Where each robot starts, from its aisle's west end \[m\].
    pub start_x: f64,
}

impl Warehouse {
    /// The fleet's warehouse: aisles 12 m long and 2.4 m wide, rows of shelves
    /// 0.8 m deep; two plans a robot, 9.5 m along its aisle with a weave of
    /// ±0.25 m.
    pub fn standard(aisles: usize) -> Warehouse {
        Warehouse {
            aisles,
            length: 12.0,
            aisle_width: 2.4,
            shelf_depth: 0.8,
            shelf_height: 2.0,
            cross: 2.0,
            plans: vec![
                vec![(3.5, 0.25), (6.0, 0.0)],
                vec![(8.5, -0.25), (10.5, 0.0)],
            ],
            start_x: 1.0,
        }
    }

    /// A short warehouse for tests: aisles 6 m long, two short plans.
    pub fn short(aisles: usize) -> Warehouse {
        Warehouse {
            length: 6.0,
            plans: vec![vec![(2.5, 0.15), (3.3, 0.0)], vec![(4.6, 0.0)]],
            ..Warehouse::standard(aisles)
        }
    }

    /// Distance between two rows of shelves, centre to centre \[m\].
    pub fn pitch(&self) -> f64 {
        self.aisle_width + self.shelf_depth
    }

    /// The centre line of aisle `i` (y) \[m\].
    pub fn aisle_y(&self, i: usize) -> f64 {
        i as f64 * self.pitch() + self.shelf_depth + self.aisle_width / 2.0
    }

    /// Row of shelves `k`.
    pub fn row(&self, k: usize) -> Obstacle {
        let y0 = k as f64 * self.pitch();
        Obstacle {
            x0: 0.0,
            y0,
            x1: self.length,
            y1: y0 + self.shelf_depth,
            height: self.shelf_height,
        }
    }

    /// The whole warehouse: its walls and every row of shelves.
    pub fn scene(&self, texture_seed: u64) -> SceneConfig {
        SceneConfig {
            room: Room {
                x0: -self.cross,
                y0: 0.0,
                x1: self.length + self.cross,
                y1: self.aisles as f64 * self.pitch() + self.shelf_depth,
                height: 3.0,
            },
            obstacles: (0..=self.aisles).map(|k| self.row(k)).collect(),
            texture_seed,
        }
    }

    /// The warehouse as robot `i` knows it (its map and what its camera
    /// renders): cropped to its aisle, the two rows of shelves either side
    /// (the collision rule of the [module](self)).
    pub fn aisle_scene(&self, i: usize, texture_seed: u64) -> SceneConfig {
        let (below, above) = (self.row(i), self.row(i + 1));
        SceneConfig {
            room: Room {
                x0: 0.0,
                y0: below.y0,
                x1: self.length,
                y1: above.y1,
                height: 3.0,
            },
            obstacles: vec![below, above],
            texture_seed,
        }
    }

    /// Robot `i`'s start pose: the west end of its aisle, facing east.
    pub fn start(&self, i: usize) -> Pose2 {
        Pose2 {
            x: self.start_x,
            y: self.aisle_y(i),
            phi: 0.0,
        }
    }

    /// The dispatch: robot `i`'s mission, its plans along its own aisle.
    pub fn mission(&self, i: usize) -> Mission {
        let y = self.aisle_y(i);
        Mission {
            name: format!("aisle_{i}"),
            plans: self
                .plans
                .iter()
                .map(|plan| {
                    plan.iter()
                        .map(|&(x, dy)| Point2 { x, y: y + dy })
                        .collect()
                })
                .collect(),
        }
    }
}

/// A fleet: the warehouse and the settings every robot shares.
#[derive(Clone, Debug)]
pub struct Fleet {
    /// The warehouse (its aisles are the robots).
    pub warehouse: Warehouse,
    /// Rex's configuration every robot starts from (the world's platform,
    /// sensors, motion capture, camera; the planner, tracker, estimator and
    /// limits); each robot gets its own start, aisle, mission and noise seeds.
    pub base: RexConfig,
    /// Rex's spec, the template of each robot's.
    pub rex: Spec,
    /// a1 parts of this many robots in a process of the grouped deployment.
    pub per_process: usize,
}

/// Why a fleet could not be made.
#[derive(Debug, thiserror::Error)]
pub enum FleetError {
    /// Rex's configuration or spec could not be read.
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    /// The fleet could not be built.
    #[error(transparent)]
    Build(#[from] RexError),
    /// The run failed.
    #[error(transparent)]
    Run(#[from] RunError),
    /// A plan is off its robot's aisle.
    #[error("robot {robot}: plan {plan} point {point} is off its aisle: {why}")]
    OffAisle {
        /// The robot.
        robot: usize,
        /// The plan (0-based).
        plan: usize,
        /// The point (0-based).
        point: usize,
        /// Why.
        why: String,
    },
}

impl Fleet {
    /// `robots` robots in [`Warehouse::standard`], with the shipped world's
    /// platform and sensors, visual odometry as `visual_odometry` says.
    pub fn new(robots: usize, visual_odometry: bool) -> Result<Fleet, FleetError> {
        Fleet::in_warehouse(Warehouse::standard(robots), visual_odometry)
    }

    /// A fleet in `warehouse`, one robot an aisle.
    pub fn in_warehouse(warehouse: Warehouse, visual_odometry: bool) -> Result<Fleet, FleetError> {
        let mut world = WorldConfig::shipped()?;
        // A warehouse's floor: concrete everywhere.
        world.surfaces.patches.clear();
        let mut base = RexConfig::new(world, Mission::default());
        base.visual_odometry = visual_odometry;
        // One thread runs the whole fleet: the planner and the odometry in
        // their subsystems' steps (the same results as on workers).
        base.runtime = Runtime::Inline;
        base.vision = OffloadMode::Inline;
        let rex = system::load_spec(&base.spec)?;
        Ok(Fleet {
            warehouse,
            base,
            rex,
            per_process: 2,
        })
    }

    /// Robots in the fleet.
    pub fn robots(&self) -> usize {
        self.warehouse.aisles
    }

    /// The distance two robots' centres must keep: two footprints
    /// (`2 × clearance_m`) \[m\].
    pub fn safety_m(&self) -> f64 {
        2.0 * self.base.limits.clearance_m
    }

    /// The fleet's spec ([`spec::fleet_spec`]).
    pub fn spec(&self) -> Spec {
        spec::fleet_spec(&self.rex, self.robots(), self.per_process)
    }

    /// The spec's deployment the fleet runs in one process.
    pub fn deployment(&self) -> &'static str {
        if self.base.visual_odometry {
            "simulation"
        } else {
            "simulation_without_vo"
        }
    }

    /// Robot `i`'s configuration: Rex's, in its aisle, with its mission and its
    /// own noise (seeds offset by `i`; robot 0 has the shipped world's).
    pub fn robot(&self, i: usize) -> Result<RexConfig, FleetError> {
        let w = &self.warehouse;
        let mut config = self.base.clone();
        let world = &mut config.world;
        world.scene = w.aisle_scene(i, world.scene.texture_seed + i as u64);
        world.start = w.start(i);
        world.sensors.seed += i as u64;
        world.mocap.seed += i as u64;
        config.mission = w.mission(i);
        let map = config.limits.plan_map(&config.world);
        for (plan, points) in config.mission.plans.iter().enumerate() {
            for (point, p) in points.iter().enumerate() {
                if let Err(why) = map.explain(p.x, p.y) {
                    return Err(FleetError::OffAisle {
                        robot: i,
                        plan,
                        point,
                        why,
                    });
                }
            }
        }
        Ok(config)
    }

    /// Every robot's configuration.
    pub fn configs(&self) -> Result<Vec<RexConfig>, FleetError> {
        (0..self.robots()).map(|i| self.robot(i)).collect()
    }
}

/// Handles to the parts of a built fleet.
#[derive(Clone, Debug)]
pub struct FleetHandles {
    /// Each robot's parts (a1 and a3), in robot order; none has a `c2` of
    /// its own ([`RobotHandles::c2`] is `None`).
    pub robots: Vec<RobotHandles>,
    /// The fleet's one `c2`, dispatching to every robot.
    pub c2: SubsystemHandle<FleetOntology>,
}

/// Build the fleet (as the spec's deployment `deployment` says, in one process)
/// with the robots' configurations `configs` (from [`Fleet::configs`]):
/// every robot's parts, Rex's code under the robot's names, the one `c2`
/// with a fan of `configs.len()` robots, one environment.
pub fn build(
    spec: &Spec,
    deployment: &str,
    configs: &[RexConfig],
) -> Result<(System, FleetHandles), RexError> {
    let mut fleet = Assembly::new(spec, deployment)?;
    let mut truth = FleetTruth::default();
    for (i, config) in configs.iter().enumerate() {
        let plant = config.world.plant().map_err(WorldError::from)?;
        truth.robots.push(Truth {
            time: 0.0,
            state: plant.state,
        });
        for part in PARTS {
            fleet.alias(&robot_name(part, i), part);
        }
    }
    fleet.environment(truth);
    let robots = configs.len();
    let c2 = fleet.subsystem_with_buffers(
        ONTOLOGY.1,
        FleetOntologyMemory::new(configs.iter().map(|c| c.mission.clone())),
        ontology::fleet_ontology_fsm()?,
        FleetOntologyInput::new(robots),
        FleetOntologyOutput::new(robots),
    )?;
    let mut handles = Vec::with_capacity(robots);
    // Every robot's FSMs are one definition each, with the spec's graph
    // (the robots' are the same): each robot's subsystems share it.
    let first = |part: &str| robot_name(part, 0);
    let fsms = (
        fleet.graphed(&first("c1"), c1_fsm()?)?,
        fleet.graphed(&first("e11"), e11_fsm()?)?,
        fleet.graphed(&first("c3"), map_fsm()?)?,
        fleet.graphed(&first("r31"), mocap_receptor_fsm()?)?,
        fleet.graphed(&first("r11"), r11_fsm()?)?,
    );
    for (i, config) in configs.iter().enumerate() {
        let name = |part: &str| robot_name(part, i);
        let dt = fleet.period(&name("e11"))?.as_secs_f64();
        let c1 = fleet.subsystem(&name("c1"), system::c1_memory(config, dt), fsms.0.clone())?;
        let e1_period = fleet.period(&name("E1"))?.as_secs_f64();
        let e11 = fleet.subsystem(
            &name("e11"),
            system::e11_memory(config, dt, e1_period)?,
            fsms.1.clone(),
        )?;
        let world = &config.world;
        let platform = Platform::new(
            world.plant().map_err(WorldError::from)?,
            world.sensors.clone(),
        )
        .map_err(WorldError::from)?
        .in_fleet(i);
        let platform = fleet.driver(&name("E1"), platform)?;
        let c3 = fleet.subsystem(&name("c3"), MapMemory::default(), fsms.2.clone())?;
        let r31 = fleet.subsystem(
            &name("r31"),
            MocapMemory {
                max_speed: 3.0 * world.platform.speed_max,
                ..MocapMemory::default()
            },
            fsms.3.clone(),
        )?;
        let mocap = MotionCapture::new(world.mocap.clone())
            .map_err(WorldError::from)?
            .in_fleet(i);
        let mocap = fleet.driver(&name("R3"), mocap)?;
        let vision = if fleet.runs(&name("r11")) {
            let r11 = fleet.subsystem(
                &name("r11"),
                R11Memory::new(system::odometry(config)?, config.acquire_every),
                fsms.4.clone(),
            )?;
            let renderer = Renderer::new(world.camera.clone(), world.scene.clone())
                .map_err(WorldError::from)?;
            let camera = StereoCamera::new(renderer, config.vision).in_fleet(i);
            Some((r11, fleet.driver(&name("R1"), camera)?))
        } else {
            None
        };
        handles.push(RobotHandles {
            c1,
            e11,
            platform,
            c2: None,
            map: MapAgentHandles { c3, r31, mocap },
            vision,
        });
    }
    Ok((
        fleet.build()?,
        FleetHandles {
            robots: handles,
            c2,
        },
    ))
}

/// What a fleet's run produced.
#[derive(Clone, Debug, Default)]
pub struct FleetOutcome {
    /// Each robot's run, judged as Rex's ([`Outcome::reports`]).
    pub robots: Vec<Outcome>,
    /// The smallest distance between two robots' true positions, every 10 ms
    /// (infinite with one robot) \[m\].
    pub min_separation_m: f64,
    /// When it was smallest \[s\], and which two robots.
    pub closest: Option<(f64, usize, usize)>,
    /// Simulated time \[s\].
    pub sim_s: f64,
    /// Wall-clock time \[s\].
    pub wall_s: f64,
    /// Whether every robot's mission ended before the time limit.
    pub completed: bool,
}

impl FleetOutcome {
    /// Plans sent to the robots, in all.
    pub fn plans(&self) -> usize {
        self.robots.iter().map(|o| o.plans).sum()
    }

    /// Plans achieved (judged against the truth), in all.
    pub fn achieved(&self) -> usize {
        self.robots.iter().map(Outcome::plans_achieved).sum()
    }

    /// Plans not achieved: failed, refused, broken a limit, or unfinished.
    pub fn failed(&self) -> usize {
        self.plans() - self.achieved()
    }

    /// Simulated seconds per wall-clock second.
    pub fn realtime_factor(&self) -> f64 {
        self.sim_s / self.wall_s.max(1e-9)
    }

    /// Wall-clock milliseconds per simulated second per robot.
    pub fn cost_per_robot_ms(&self) -> f64 {
        1e3 * self.wall_s / self.sim_s.max(1e-9) / self.robots.len().max(1) as f64
    }

    /// The summary line of a fleet's run (`cost_ratio` is the caller's).
    pub fn line(&self, cost_ratio: f64) -> String {
        format!(
            "fleet robots={} plans={} achieved={} failed={} min_separation_m={:.3} realtime_factor={:.2} cost_per_robot_ms={:.2} cost_ratio={:.2}",
            self.robots.len(),
            self.plans(),
            self.achieved(),
            self.failed(),
            self.min_separation_m,
            self.realtime_factor(),
            self.cost_per_robot_ms(),
            cost_ratio
        )
    }
}

/// What the fleet's probes report (in one process, or from every process
/// of a deployment to its launcher): a robot's report (Rex's), or every
/// robot's true pose at an instant.
#[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
pub enum FleetSeen {
    /// Robot `.0`'s report, as Rex's probes make it.
    Robot(usize, Box<Seen>),
    /// What the fleet's `c2` did for the robots it has news of: for each,
    /// what Rex's `c2` probe reports ([`Seen::C2`]: its new
    /// acknowledgements, whether its mission ended, the plans sent).
    Dispatch(Vec<(usize, Seen)>),
    /// Every robot's true pose `(X, Y, φ)` at `at`, in robot order.
    Truths {
        /// The instant of the poses.
        at: Time,
        /// The poses.
        poses: Vec<[f64; 3]>,
    },
}

/// What a robot's watch tells of its progress (acknowledgements, ticks).
pub(crate) type Printer = Box<dyn FnMut(Progress<'_>) + Send>;

fn quiet(_: Progress<'_>) {}

/// Reads the fleet's run: one Rex watch a robot, and the separation.
pub(crate) struct FleetWatch {
    pub(crate) robots: Vec<MissionWatch<Printer>>,
    dirty: Vec<bool>,
    done: Vec<bool>,
    pub(crate) min_separation: f64,
    pub(crate) closest: Option<(f64, usize, usize)>,
    order: Vec<usize>,
}

impl FleetWatch {
    /// A watch of the robots configured by `configs`, each telling its
    /// progress to the printer `printer(i)` makes (a tick every `tick`).
    pub(crate) fn new(
        configs: &[RexConfig],
        tick: Duration,
        mut printer: impl FnMut(usize) -> Printer,
    ) -> FleetWatch {
        FleetWatch {
            robots: configs
                .iter()
                .enumerate()
                .map(|(i, c)| MissionWatch::new(c, tick, printer(i)))
                .collect(),
            dirty: vec![false; configs.len()],
            done: vec![false; configs.len()],
            min_separation: f64::INFINITY,
            closest: None,
            order: Vec::with_capacity(configs.len()),
        }
    }

    /// Robots whose mission has ended.
    pub(crate) fn robots_done(&self) -> usize {
        self.done.iter().filter(|&&d| d).count()
    }

    /// The smallest distance between two of `poses`, sweeping them in y order
    /// (the aisles are stacked in y).
    fn separation(&mut self, t: f64, poses: &[[f64; 3]]) {
        self.order.clear();
        self.order.extend(0..poses.len());
        self.order
            .sort_by(|&a, &b| poses[a][1].total_cmp(&poses[b][1]));
        for (k, &a) in self.order.iter().enumerate() {
            for &b in &self.order[k + 1..] {
                let dy = poses[b][1] - poses[a][1];
                if dy >= self.min_separation {
                    break;
                }
                let d = (poses[b][0] - poses[a][0]).hypot(dy);
                if d < self.min_separation {
                    self.min_separation = d;
                    self.closest = Some((t, a.min(b), a.max(b)));
                }
            }
        }
    }
}

impl Watcher<FleetSeen> for FleetWatch {
    fn see(&mut self, seen: FleetSeen) {
        match seen {
            // A report of a robot the fleet does not have (another build's
            // process) is not this run's: left out.
            FleetSeen::Robot(i, seen) => {
                if let Some(watch) = self.robots.get_mut(i) {
                    watch.see(*seen);
                    self.dirty[i] = true;
                }
            }
            FleetSeen::Dispatch(robots) => {
                for (i, seen) in robots {
                    if let Some(watch) = self.robots.get_mut(i) {
                        watch.see(seen);
                        self.dirty[i] = true;
                    }
                }
            }
            FleetSeen::Truths { at, poses } => {
                if poses.len() != self.robots.len() {
                    return;
                }
                self.separation(at.as_secs_f64(), &poses);
                for (i, pose) in poses.into_iter().enumerate() {
                    self.robots[i].see(Seen::Truth { at, pose });
                    self.dirty[i] = true;
                }
            }
        }
    }

    fn ended(&mut self, finished: bool) -> bool {
        for (i, watch) in self.robots.iter_mut().enumerate() {
            if finished || self.dirty[i] {
                self.dirty[i] = false;
                self.done[i] = watch.ended(finished);
            }
        }
        self.done.iter().all(|&d| d)
    }
}

/// Probes on the fleet's robots (`handles`) for the components `here` says
/// run in this process (the spec's names, `c1_3`, `c2`): each robot's as
/// Rex's, tagged with the robot, but for the truth, read whole every
/// [`TRUTH_EVERY_NS`] where the platforms run, and for `c2`, the fleet's one,
/// whose news of every robot come together ([`FleetSeen::Dispatch`]).
pub(crate) fn install_probes(
    probes: &mut Probes<FleetSeen>,
    handles: &FleetHandles,
    here: &dyn Fn(&str) -> bool,
) {
    for (i, h) in handles.robots.iter().enumerate() {
        let here = |name: &str| name != "E1" && here(&robot_name(name, i));
        install_probes_as(probes, h, &here, move |seen| {
            FleetSeen::Robot(i, Box::new(seen))
        });
    }
    if here(ONTOLOGY.1) {
        install_dispatch_probe(probes, &handles.c2);
    }
    if !(0..handles.robots.len()).any(|i| here(&robot_name("E1", i))) {
        return;
    }
    probes.environment(|_, w: &FleetTruth| {
        let first = w.robots.first()?;
        let at = Time::from_nanos((first.time * 1e9).round().max(0.0) as u64);
        at.as_nanos()
            .is_multiple_of(TRUTH_EVERY_NS)
            .then(|| FleetSeen::Truths {
                at,
                poses: w
                    .robots
                    .iter()
                    .map(|t| [t.state.x, t.state.y, t.state.phi])
                    .collect(),
            })
    });
}

/// A probe on the fleet's `c2`: for every robot with news (new
/// acknowledgements, plans sent, its mission ended), what Rex's probe on
/// Rex's `c2` reports ([`Seen::C2`]).
fn install_dispatch_probe(probes: &mut Probes<FleetSeen>, c2: &SubsystemHandle<FleetOntology>) {
    // Per robot: the acknowledgements and plans sent already told, and
    // whether its end was.
    let mut told: Vec<(usize, usize, bool)> = Vec::new();
    probes.subsystem(c2, move |p| {
        let robots = &p.memory.robots;
        told.resize(robots.len(), (0, 0, false));
        let mut news = Vec::new();
        for (i, (r, told)) in robots.iter().zip(told.iter_mut()).enumerate() {
            let m = &r.ontology;
            let halted = p.halted || r.halted();
            if m.acks.len() == told.0 && m.next == told.1 && halted == told.2 {
                continue;
            }
            let acks: Vec<Ack> = m.acks.get(told.0..).unwrap_or_default().to_vec();
            *told = (m.acks.len(), m.next, halted);
            news.push((
                i,
                Seen::C2 {
                    t: p.time,
                    acks,
                    halted,
                    sent: m.next,
                },
            ));
        }
        (!news.is_empty()).then_some(FleetSeen::Dispatch(news))
    });
}

/// What the fleet's `c2` counted of robot `robot` (its `c1`'s restarts, the
/// plans it sent again, the fragments reported twice), as Rex's counters
/// count them of Rex's `c2`; zero where `c2` did not run.
pub(crate) fn dispatch_counters(
    run: &Finished,
    c2: &SubsystemHandle<FleetOntology>,
    robot: usize,
) -> Counters {
    let mut c = Counters::default();
    if let Some(r) = run.memory(c2).and_then(|m| m.robots.get(robot)) {
        c.c1_restarts = r.ontology.restarts;
        c.plans_resent = r.ontology.resent;
        c.fragments_repeated = r.ontology.repeated;
    }
    c
}

/// Every how many nanoseconds the truth is read (for the separation and to
/// pair with e11's samples, whose period is a multiple of it).
const TRUTH_EVERY_NS: u64 = 10_000_000;

/// Run `fleet` in the deterministic executor until every robot's mission has
/// ended (or `limit` of simulated time): each robot judged against the truth,
/// the smallest separation measured.
pub fn run_fleet(fleet: &Fleet, limit: Duration) -> Result<FleetOutcome, FleetError> {
    let spec = fleet.spec();
    let configs = fleet.configs()?;
    let (system, handles) = build(&spec, fleet.deployment(), &configs)?;
    let tick = Duration::from_secs(3600);
    let mut watch = FleetWatch::new(&configs, tick, |_| Box::new(quiet));
    let exec = fleet.base.exec;
    let mut run = Watched::new(&mut watch, limit);
    install_probes(&mut run.probes, &handles, &|_| true);
    let (ran, _) = run.simulate(system, exec, NoObserver)?;
    let robots: Vec<Outcome> = watch
        .robots
        .iter_mut()
        .zip(&handles.robots)
        .enumerate()
        .map(|(i, (w, h))| {
            let dispatched = dispatch_counters(&ran.finished, &handles.c2, i);
            w.see(Seen::Counters(Box::new(dispatched)));
            w.conclude(&ran, h)
        })
        .collect();
    Ok(FleetOutcome {
        completed: robots.iter().all(|o| o.completed),
        sim_s: ran.finished.report().last_instant.as_secs_f64(),
        wall_s: ran.wall.as_secs_f64(),
        min_separation_m: watch.min_separation,
        closest: watch.closest,
        robots,
    })
}
