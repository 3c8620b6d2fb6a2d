//! Long missions: random patrols of ten minutes and more, run with each estimator
//! and tracker, with and without visual odometry and motion-capture dropouts, and
//! judged against the simulation's truth (the `soak` example and the soak test).

use std::time::Duration;

use crate::a1::e11::{EstimatorKind, TrackerKind};
use crate::a1::map::Map;
use crate::math::geometry::wrap;
use crate::math::rng::Rng;
use crate::mission::Mission;
use crate::payload::Point2;
use crate::run::{RunError, Sample, run_mission};
use crate::system::RexConfig;
use crate::world::WorldConfig;

/// One way of running Rex through a soak.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SoakCase {
    /// The estimator of `e11`.
    pub estimator: EstimatorKind,
    /// The tracker of `e11`.
    pub tracker: TrackerKind,
    /// With `r11` and the camera.
    pub visual_odometry: bool,
    /// With motion-capture dropouts of 3 s starting at 0.5 % per sample (about
    /// half of the poses lost), instead of the shipped world's short ones.
    pub dropouts: bool,
}

impl std::fmt::Display for SoakCase {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "{:?}+{:?}{}{}",
            self.estimator,
            self.tracker,
            if self.visual_odometry { "+vo" } else { "" },
            if self.dropouts { "+dropouts" } else { "" }
        )
    }
}

impl SoakCase {
    /// Every estimator and tracker, with and without dropouts; with visual
    /// odometry only where an estimator uses it (the MHE).
    pub fn all() -> Vec<SoakCase> {
        let mut cases = Vec::new();
        for estimator in [EstimatorKind::Mhe, EstimatorKind::Ekf] {
            for tracker in [TrackerKind::Nmpc, TrackerKind::Backstepping] {
                for dropouts in [false, true] {
                    for visual_odometry in [false, true] {
                        if visual_odometry && estimator == EstimatorKind::Ekf {
                            continue;
                        }
                        cases.push(SoakCase {
                            estimator,
                            tracker,
                            visual_odometry,
                            dropouts,
                        });
                    }
                }
            }
        }
        cases
    }
}

/// A patrol of random points in the free space of `world`'s room (keeping 1.5 m
/// from walls and obstacles), long enough for about `minutes` of driving: plans of
/// five points, consecutive points 0.8 to 2.5 m apart, the route turning by at
/// most 100° at a point (a route, not a random walk: no reversals).
pub fn patrol(world: &WorldConfig, minutes: f64, seed: u64) -> Mission {
    let map = Map::of_scene(&world.scene, 1.5);
    let mut rng = Rng::stream(seed, "patrol");
    let mut at = Point2 { x: 0.0, y: 0.0 };
    let mut heading: Option<f64> = Some(0.0);
    let mut plans = Vec::new();
    // About 1.6 s per point and 2 s per metre on Rex's planner settings.
    let mut seconds = 0.0;
    while seconds < minutes * 60.0 {
        let mut plan = Vec::with_capacity(5);
        let mut tries = 0u32;
        while plan.len() < 5 {
            tries += 1;
            let x = map.room.x0 + rng.uniform() * (map.room.x1 - map.room.x0);
            let y = map.room.y0 + rng.uniform() * (map.room.y1 - map.room.y0);
            let d = (x - at.x).hypot(y - at.y);
            let towards = (y - at.y).atan2(x - at.x);
            let turn = heading.map_or(0.0, |h| wrap(towards - h).abs());
            // Cornered (every way within 100° is blocked): turn back.
            let max_turn = if tries > 1000 { 180.0 } else { 100.0 };
            if map.check(x, y).is_ok()
                && (0.8..=2.5).contains(&d)
                && turn <= f64::to_radians(max_turn)
            {
                tries = 0;
                at = Point2 { x, y };
                heading = Some(towards);
                plan.push(at);
                seconds += 1.6 + 2.0 * d;
            }
        }
        plans.push(plan);
    }
    Mission {
        name: format!("patrol{seed}"),
        plans,
    }
}

/// What a soak run measured.
#[derive(Clone, Debug, PartialEq)]
pub struct SoakResult {
    /// The case.
    pub case: SoakCase,
    /// Simulated minutes.
    pub sim_min: f64,
    /// Largest error of the estimated position while the motion capture
    /// delivered \[m\].
    pub max_est_err_m: f64,
    /// Largest error of the estimated position otherwise: in dropouts and the
    /// second after them \[m\].
    pub max_est_err_dropout_m: f64,
    /// Largest tracking error while following fragments \[m\].
    pub max_track_err_m: f64,
    /// RMS tracking error \[m\].
    pub rms_m: f64,
    /// Plans reported reached whose end point was not reached.
    pub false_done: usize,
    /// Plans achieved, and plans.
    pub achieved: (usize, usize),
    /// Whether the mission completed.
    pub completed: bool,
    /// The summary's fault line.
    pub faults: String,
    /// Wall-clock seconds.
    pub wall_s: f64,
}

/// Run `case` over a patrol of `minutes` (seed `seed`) on a concrete floor; the
/// world's camera at `camera_scale` of its resolution (1: as shipped).
pub fn run_case(
    case: SoakCase,
    minutes: f64,
    seed: u64,
    camera_scale: f64,
) -> Result<SoakResult, RunError> {
    let mut world = WorldConfig::shipped()
        .map_err(|e| RunError::Build(Box::new(crate::system::RexError::World(e.into()))))?;
    // The camera's resolution changes; its calibration follows from it.
    world.surfaces.default = "concrete".into();
    world.surfaces.patches.clear();
    if case.dropouts {
        world.mocap.dropout_rate = 0.005;
        world.mocap.dropout_length = 3.0;
    }
    if camera_scale != 1.0 {
        let c = &mut world.camera;
        c.width = ((f64::from(c.width) * camera_scale).round() as u32).max(64);
        c.height = ((f64::from(c.height) * camera_scale).round() as u32).max(48);
        c.focal *= camera_scale;
    }
    // The patrol's duration is an estimate (each plan ends at rest, some turn
    // more than others): ask for a quarter more.
    let mission = patrol(&world, minutes * 1.25, seed);
    let mut config = RexConfig::new(world, mission);
    config.estimator = case.estimator;
    config.tracker = case.tracker;
    config.visual_odometry = case.visual_odometry;
    // Generous: the patrol's estimate is rough, and a run that does not complete
    // shows as such.
    let limit = Duration::from_secs_f64(minutes * 60.0 * 2.0 + 120.0);
    let out = run_mission(&config, limit, Duration::from_secs(3600), |_| {})?;
    let max_est = |mocap: bool| {
        out.samples
            .iter()
            .filter(|s| s.with_mocap() == mocap)
            .map(Sample::estimate_error)
            .fold(0.0, f64::max)
    };
    Ok(SoakResult {
        case,
        sim_min: out.sim_s / 60.0,
        max_est_err_m: max_est(true),
        max_est_err_dropout_m: max_est(false),
        max_track_err_m: out.max_error(),
        rms_m: out.rms(),
        false_done: out.false_done(),
        achieved: (out.plans_achieved(), out.plans),
        completed: out.completed,
        faults: crate::report::faults(&out),
        wall_s: out.wall_s,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn patrols_stay_in_the_free_space_and_last_long_enough() {
        let world = WorldConfig::default();
        let m = patrol(&world, 10.0, 7);
        let map = Map::of_scene(&world.scene, 1.5);
        let points: Vec<&Point2> = m.plans.iter().flatten().collect();
        assert!(points.iter().all(|p| map.check(p.x, p.y).is_ok()));
        let length: f64 = points
            .windows(2)
            .map(|w| (w[1].x - w[0].x).hypot(w[1].y - w[0].y))
            .sum();
        assert!(length > 100.0, "{length} m");
        assert_eq!(patrol(&world, 10.0, 7), m, "seeded");
        assert_ne!(patrol(&world, 10.0, 8), m);
    }
}
