//! The skid-steer platform: parameters, the reduced model for controllers and
//! estimators (§1.3), and the full model that is the simulated plant (§1.4).

pub mod dynamics;
pub mod full;
pub mod lateral;
pub mod params;
pub mod reduced;
pub mod settling;

pub use dynamics::{
    Dynamics, EarlierReading, Linearised, Matrix, Measured, NOT_READ, NU, SpinRead, Vector,
    WheelSpin,
};
pub use full::{CommandStats, FullState, IntegrationStats, Plant};
pub use lateral::{Lateral, State6};
pub use params::{Friction, Patch, PlatformParams, Region, SlipParams, Surface, SurfaceMap};
pub use reduced::{Reduced, State5, Torques};
