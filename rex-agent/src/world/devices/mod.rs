//! The real effectors and receptors of the simulated world, as framework drivers:
//! the platform E1 (wheels, encoders, IMU, force sensors), the stereo camera R1 and
//! the motion-capture system R3 of the map agent.
//!
//! One file a device: `platform.rs` (E1), `stereo_camera.rs` (R1), `mocap.rs` (R3).
//!
//! The three devices share the simulated world, [`Truth`], which is the system's
//! environment (`SystemBuilder::environment`): the platform writes it every step,
//! the camera and the motion capture read it through their `DriverContext`. The
//! executor steps the real receptors after the effectors within an instant, so
//! both see the pose of that instant whatever the order of declaration; nothing
//! is shared between drivers behind the framework's back.

use crate::model::FullState;

mod mocap;
mod platform;
mod stereo_camera;

pub use mocap::{MocapOutput, MocapParams, MocapToR31, MotionCapture};
pub use platform::{
    Platform, PlatformFromE11, PlatformInput, PlatformOutput, PlatformToE11, SensorParams,
};
pub use stereo_camera::{CameraFromR11, CameraInput, CameraOutput, CameraToR11, StereoCamera};

/// What the simulation knows and the agents must estimate: the environment of the
/// simulated system.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Truth {
    /// Simulation time \[s\].
    pub time: f64,
    /// The platform's full state.
    pub state: FullState,
}

/// The simulated world of a fleet (`crate::fleet`): each robot's [`Truth`], by
/// the robot's index. A device of robot `i` (made with its `in_fleet(i)`) writes
/// or reads `robots[i]`; a device of a single Rex, the system's [`Truth`].
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FleetTruth {
    /// Each robot's truth.
    pub robots: Vec<Truth>,
}

/// The truth a device of `robot` (`None`: the single Rex) acts on or senses.
fn truth<'a>(
    cx: &'a mut embodied::DriverContext<'_>,
    robot: Option<usize>,
) -> Result<&'a mut Truth, embodied::DriverError> {
    match robot {
        None => cx.environment::<Truth>(),
        Some(i) => {
            let fleet = cx.environment::<FleetTruth>()?;
            let n = fleet.robots.len();
            fleet.robots.get_mut(i).ok_or_else(|| {
                embodied::DriverError::new(format!(
                    "robot {i} is not in the fleet's truth ({n} robots)"
                ))
            })
        }
    }
}

#[cfg(test)]
mod tests;
