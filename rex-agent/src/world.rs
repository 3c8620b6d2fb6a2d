//! Rex's simulated world, configured from RON (`rex-agent/config/world.ron`), and the
//! functions that add its devices and the partner agents to a system.

use std::path::Path;

use embodied::{
    AgentId, DriverHandle, Period, PeriodError, Policy, SubsystemHandle, SystemBuilder, port,
};
use serde::{Deserialize, Serialize};

use crate::camera::{CameraConfig, Renderer, SceneConfig};
use crate::config::{self, ConfigError, Invalid, Validate, finite};
use crate::devices::{
    MocapOutput, MocapParams, MotionCapture, Platform, SensorParams, SharedTruth, StereoCamera,
};
use crate::mission::Mission;
use crate::model::{Plant, PlatformParams, SurfaceMap};
use crate::partners::{
    MapAgent, MapInput, MapMemory, MocapMemory, MocapReceptor, MocapReceptorInput,
    MocapReceptorOutput, Ontology, OntologyMemory, map_fsm, mocap_receptor_fsm, ontology_fsm,
};
use crate::types::Pose2;

/// Periods of the world's components [ms] (the same as in `specs/rex.ron`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldPeriods {
    /// The platform E1 (its integration step).
    pub platform_ms: f64,
    /// The stereo camera R1.
    pub camera_ms: f64,
    /// The motion capture R3.
    pub mocap_ms: f64,
    /// The map agent's virtual receptor r31.
    pub r31_ms: f64,
    /// The map agent's control subsystem c3.
    pub c3_ms: f64,
    /// The ontology agent's control subsystem c2.
    pub c2_ms: f64,
}

impl Default for WorldPeriods {
    fn default() -> Self {
        WorldPeriods {
            platform_ms: 1.0,
            camera_ms: 20.0,
            mocap_ms: 10.0,
            r31_ms: 10.0,
            c3_ms: 20.0,
            c2_ms: 100.0,
        }
    }
}

/// Everything about the simulated world.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldConfig {
    /// The platform.
    pub platform: PlatformParams,
    /// The ground.
    pub surfaces: SurfaceMap,
    /// The platform's sensors.
    pub sensors: SensorParams,
    /// The stereo camera.
    pub camera: CameraConfig,
    /// What the camera sees.
    pub scene: SceneConfig,
    /// The map agent's motion capture.
    pub mocap: MocapParams,
    /// Where the platform starts.
    pub start: Pose2,
    /// Periods.
    #[serde(default)]
    pub periods: WorldPeriods,
}

impl Default for WorldConfig {
    fn default() -> Self {
        WorldConfig {
            platform: PlatformParams::peer_default(),
            surfaces: SurfaceMap::concrete(),
            sensors: SensorParams::default(),
            camera: CameraConfig::default(),
            scene: SceneConfig::default_room(),
            mocap: MocapParams::default(),
            start: Pose2::default(),
            periods: WorldPeriods::default(),
        }
    }
}

impl Validate for WorldConfig {
    fn validate(&self) -> Result<(), Invalid> {
        let prefix = |p: &str, (f, v, r): Invalid| (format!("{p}.{f}"), v, r);
        self.platform
            .validate()
            .map_err(|e| prefix("platform", e))?;
        self.surfaces
            .validate()
            .map_err(|e| prefix("surfaces", e))?;
        self.sensors.validate().map_err(|e| prefix("sensors", e))?;
        self.camera.validate().map_err(|e| prefix("camera", e))?;
        self.scene.validate().map_err(|e| prefix("scene", e))?;
        self.mocap.validate().map_err(|e| prefix("mocap", e))?;
        finite("start.x", self.start.x)?;
        finite("start.y", self.start.y)?;
        finite("start.phi", self.start.phi)?;
        let p = &self.periods;
        for (f, v) in [
            ("periods.platform_ms", p.platform_ms),
            ("periods.camera_ms", p.camera_ms),
            ("periods.mocap_ms", p.mocap_ms),
            ("periods.r31_ms", p.r31_ms),
            ("periods.c3_ms", p.c3_ms),
            ("periods.c2_ms", p.c2_ms),
        ] {
            config::period_ms(f, v)?;
        }
        Ok(())
    }
}

impl WorldConfig {
    /// Load a world file.
    pub fn load(path: &Path) -> Result<WorldConfig, ConfigError> {
        config::load(path)
    }

    /// The shipped world (`rex-agent/config/world.ron`).
    pub fn shipped() -> Result<WorldConfig, ConfigError> {
        WorldConfig::load(&config::config_dir().join("world.ron"))
    }

    /// The simulated platform at the start pose (an error if the platform, the
    /// ground or the pose is invalid).
    pub fn plant(&self) -> Result<Plant, ConfigError> {
        Plant::new(
            self.platform.clone(),
            self.surfaces.clone(),
            [self.start.x, self.start.y, self.start.phi],
        )
    }
}

fn ms(v: f64) -> Result<Period, PeriodError> {
    Period::from_millis_f64(v)
}

/// Add the platform E1 to agent `a1` (an error if its configuration is invalid).
pub fn add_platform(
    sys: &mut SystemBuilder,
    a1: AgentId,
    config: &WorldConfig,
    truth: &SharedTruth,
) -> Result<DriverHandle<Platform>, WorldError> {
    let platform = Platform::new(config.plant()?, config.sensors.clone(), truth.clone())?;
    Ok(sys.driver(a1, "E1", ms(config.periods.platform_ms)?, platform))
}

/// Add the stereo camera R1 to agent `a1` (an error if the camera or the scene is
/// invalid).
pub fn add_camera(
    sys: &mut SystemBuilder,
    a1: AgentId,
    config: &WorldConfig,
    truth: &SharedTruth,
) -> Result<DriverHandle<StereoCamera>, WorldError> {
    let renderer = Renderer::new(config.camera.clone(), config.scene.clone())?;
    Ok(sys.driver(
        a1,
        "R1",
        ms(config.periods.camera_ms)?,
        StereoCamera::new(renderer, truth.clone()),
    ))
}

/// Add the ontology agent `a2` with `mission`; returns its agent and `c2`.
pub fn add_ontology(
    sys: &mut SystemBuilder,
    config: &WorldConfig,
    mission: Mission,
) -> Result<(AgentId, SubsystemHandle<Ontology>), WorldError> {
    let a2 = sys.agent("a2");
    let c2 = sys.subsystem(
        a2,
        "c2",
        ms(config.periods.c2_ms)?,
        OntologyMemory::new(mission),
        ontology_fsm()?,
    );
    Ok((a2, c2))
}

/// The map agent's parts.
#[derive(Clone, Copy, Debug)]
pub struct MapAgentHandles {
    /// The agent.
    pub agent: AgentId,
    /// Its control subsystem `c3`.
    pub c3: SubsystemHandle<MapAgent>,
    /// Its virtual receptor `r31`.
    pub r31: SubsystemHandle<MocapReceptor>,
    /// Its motion capture `R3`.
    pub mocap: DriverHandle<MotionCapture>,
}

/// Add the map agent `a3` (c3, r31 and the motion capture R3, linked together).
pub fn add_map_agent(
    sys: &mut SystemBuilder,
    config: &WorldConfig,
    truth: &SharedTruth,
) -> Result<MapAgentHandles, WorldError> {
    let a3 = sys.agent("a3");
    let p = &config.periods;
    let c3 = sys.subsystem(a3, "c3", ms(p.c3_ms)?, MapMemory::default(), map_fsm()?);
    let r31 = sys.subsystem(
        a3,
        "r31",
        ms(p.r31_ms)?,
        MocapMemory {
            max_speed: 3.0 * config.platform.speed_max,
            ..MocapMemory::default()
        },
        mocap_receptor_fsm()?,
    );
    let mocap = sys.driver(
        a3,
        "R3",
        ms(p.mocap_ms)?,
        MotionCapture::new(config.mocap.clone(), truth.clone())?,
    );
    sys.connect(
        mocap.output(port!(MocapOutput, r31.pose)),
        r31.input(port!(MocapReceptorInput, R3.pose)),
        Policy::Sample,
    );
    sys.connect(
        r31.output(port!(MocapReceptorOutput, c3.pose)),
        c3.input(port!(MapInput, r31.pose)),
        Policy::Sample,
    );
    Ok(MapAgentHandles {
        agent: a3,
        c3,
        r31,
        mocap,
    })
}

/// Why the world could not be added.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// A period is not positive.
    #[error(transparent)]
    Period(#[from] PeriodError),
    /// An FSM is malformed (a bug in this crate).
    #[error(transparent)]
    Fsm(#[from] embodied::FsmBuildError),
    /// A configuration value is invalid.
    #[error(transparent)]
    Invalid(#[from] ConfigError),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shipped_world_loads_and_bad_values_name_their_field() {
        let w = WorldConfig::shipped().unwrap();
        assert_eq!(w.camera.width, 640);
        let mut bad = w.clone();
        bad.platform.mass = -1.0;
        let text = ron::to_string(&bad).unwrap();
        let err = config::parse::<WorldConfig>(Path::new("w.ron"), &text).unwrap_err();
        assert!(err.to_string().contains("platform.mass = -1"), "{err}");
        bad = w;
        bad.surfaces.surfaces[0].mu_lat = f64::NAN;
        let text = ron::to_string(&bad).unwrap();
        let err = config::parse::<WorldConfig>(Path::new("w.ron"), &text).unwrap_err();
        assert!(err.to_string().contains("mu_lat"), "{err}");
    }

    #[test]
    fn a_world_built_in_code_is_validated_when_its_devices_are_added() {
        let truth = SharedTruth::default();
        let mut config = WorldConfig::default();
        config.camera.width = 0;
        config
            .surfaces
            .surfaces
            .push(config.surfaces.surfaces[0].clone());
        let mut sys = SystemBuilder::new();
        let a1 = sys.agent("a1");
        let err = add_camera(&mut sys, a1, &config, &truth).unwrap_err();
        assert!(
            err.to_string().contains("<camera>: width x height = 0x480"),
            "{err}"
        );
        let err = add_platform(&mut sys, a1, &config, &truth).unwrap_err();
        assert!(
            err.to_string().contains("<surfaces>: surfaces[1].name"),
            "{err}"
        );
        config.mocap.latency = -1.0;
        let err = add_map_agent(&mut sys, &config, &truth).unwrap_err();
        assert!(err.to_string().contains("<mocap>: latency = -1"), "{err}");
    }
}
