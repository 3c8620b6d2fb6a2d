//! The real effectors and receptors of the simulated world, as framework drivers:
//! the platform E1 (wheels, encoders, IMU, force sensors), the stereo camera R1 and
//! the motion-capture system R3 of the map agent.
//!
//! One file a device: `platform.rs` (E1), `stereo_camera.rs` (R1), `mocap.rs` (R3).
//!
//! The three devices share the simulated ground truth ([`SharedTruth`]): the platform
//! writes it every step, the camera and the motion capture read it. Within an instant
//! the executor steps the platform first (it is added first), so both see the pose
//! of that instant.

use std::sync::{Arc, Mutex};

use embodied::DriverError;

use crate::world::model::FullState;

mod mocap;
mod platform;
mod stereo_camera;

pub use mocap::{MocapOutput, MocapParams, MocapToR31, MotionCapture};
pub use platform::{
    Platform, PlatformFromE11, PlatformInput, PlatformOutput, PlatformToE11, SensorParams,
};
pub use stereo_camera::{CameraFromR11, CameraInput, CameraOutput, CameraToR11, StereoCamera};

/// What the simulation knows and the agents must estimate.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Truth {
    /// Simulation time [s].
    pub time: f64,
    /// The platform's full state.
    pub state: FullState,
}

/// The ground truth shared by the devices of the simulated world.
#[derive(Clone, Debug, Default)]
pub struct SharedTruth(Arc<Mutex<Truth>>);

impl SharedTruth {
    /// The current truth.
    pub fn get(&self) -> Result<Truth, DriverError> {
        self.0.lock().map(|t| *t).map_err(|_| poisoned())
    }

    fn set(&self, truth: Truth) -> Result<(), DriverError> {
        *self.0.lock().map_err(|_| poisoned())? = truth;
        Ok(())
    }
}

fn poisoned() -> DriverError {
    DriverError::new("the shared ground truth is poisoned (a device panicked)")
}

#[cfg(test)]
mod tests;
