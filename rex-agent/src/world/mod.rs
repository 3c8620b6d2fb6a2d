//! Rex's simulated world, configured from RON (`rex-agent/config/world.ron`), and the
//! functions that add its devices and the partner agents to a system.
//!
//! * the plant: the full model of the skid-steer platform ([`crate::model`], which
//!   a1's controllers share in its reduced form);
//! * [`devices`]: the real effector `E1` (the platform) and receptors `R1` (stereo
//!   camera) and `R3` (motion capture), as framework drivers;
//! * [`camera`]: the stereo rig, the room it sees, the ray-cast renderer, KITTI
//!   sequences on disk;
//! * [`partners`]: the partner agents `a2` (ontology: the mission's plans) and `a3`
//!   (map: poses from the motion capture).

pub mod camera;
pub mod devices;
pub mod partners;

use std::path::Path;

use embodied::spec::{Assembly, AssemblyError};
use embodied::{DriverHandle, SubsystemHandle};
use serde::{Deserialize, Serialize};

use crate::config::{self, ConfigError, Invalid, Validate, finite};
use crate::mission::Mission;
use crate::model::{Plant, PlatformParams, SurfaceMap};
use crate::payload::Pose2;
use camera::{CameraConfig, Renderer, SceneConfig};
use devices::{MocapParams, MotionCapture, Platform, SensorParams, StereoCamera, Truth};
use partners::{
    MapAgent, MapMemory, MocapMemory, MocapReceptor, Ontology, OntologyMemory, map_fsm,
    mocap_receptor_fsm, ontology_fsm,
};

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

/// Give the system the simulated world, the environment its devices act on and
/// sense: the platform writes the [`Truth`], the camera and the motion capture read it.
pub fn add_environment(rex: &mut Assembly<'_>) {
    rex.environment(Truth::default());
}

/// Add the platform E1 (an error if its configuration is invalid).
pub fn add_platform(
    rex: &mut Assembly<'_>,
    config: &WorldConfig,
) -> Result<DriverHandle<Platform>, WorldError> {
    let platform = Platform::new(config.plant()?, config.sensors.clone())?;
    Ok(rex.driver("E1", platform)?)
}

/// Add the stereo camera R1, rendering on a worker thread or inline (`mode`; the
/// pairs are the same either way); an error if the camera or the scene is invalid.
pub fn add_camera(
    rex: &mut Assembly<'_>,
    config: &WorldConfig,
    mode: embodied::OffloadMode,
) -> Result<DriverHandle<StereoCamera>, WorldError> {
    let renderer = Renderer::new(config.camera.clone(), config.scene.clone())?;
    Ok(rex.driver("R1", StereoCamera::new(renderer, mode))?)
}

/// Add the ontology agent's `c2` with `mission`.
pub fn add_ontology(
    rex: &mut Assembly<'_>,
    mission: Mission,
) -> Result<SubsystemHandle<Ontology>, WorldError> {
    Ok(rex.subsystem("c2", OntologyMemory::new(mission), ontology_fsm()?)?)
}

/// The map agent's parts.
#[derive(Clone, Copy, Debug)]
pub struct MapAgentHandles {
    /// Its control subsystem `c3`.
    pub c3: SubsystemHandle<MapAgent>,
    /// Its virtual receptor `r31`.
    pub r31: SubsystemHandle<MocapReceptor>,
    /// Its motion capture `R3`.
    pub mocap: DriverHandle<MotionCapture>,
}

/// Add the map agent `a3`: c3, r31 and the motion capture R3.
pub fn add_map_agent(
    rex: &mut Assembly<'_>,
    config: &WorldConfig,
) -> Result<MapAgentHandles, WorldError> {
    let mocap = MotionCapture::new(config.mocap.clone())?;
    let c3 = rex.subsystem("c3", MapMemory::default(), map_fsm()?)?;
    let r31 = rex.subsystem(
        "r31",
        MocapMemory {
            max_speed: 3.0 * config.platform.speed_max,
            ..MocapMemory::default()
        },
        mocap_receptor_fsm()?,
    )?;
    let mocap = rex.driver("R3", mocap)?;
    Ok(MapAgentHandles { c3, r31, mocap })
}

/// Why the world could not be added.
#[derive(Debug, thiserror::Error)]
pub enum WorldError {
    /// The component is not where the spec puts it.
    #[error(transparent)]
    Assembly(#[from] AssemblyError),
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
        let mut config = WorldConfig::default();
        config.camera.width = 0;
        config
            .surfaces
            .surfaces
            .push(config.surfaces.surfaces[0].clone());
        let spec = crate::system::load_spec(&crate::system::default_spec()).unwrap();
        let mut rex = Assembly::new(&spec, "simulation").unwrap();
        let err = add_camera(&mut rex, &config, embodied::OffloadMode::Inline).unwrap_err();
        assert!(
            err.to_string().contains("<camera>: width x height = 0x480"),
            "{err}"
        );
        let err = add_platform(&mut rex, &config).unwrap_err();
        assert!(
            err.to_string().contains("<surfaces>: surfaces[1].name"),
            "{err}"
        );
        config.mocap.latency = -1.0;
        let err = add_map_agent(&mut rex, &config).unwrap_err();
        assert!(err.to_string().contains("<mocap>: latency = -1"), "{err}");
    }
}
