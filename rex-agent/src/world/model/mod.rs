//! The skid-steer platform: parameters, the reduced model for controllers and
//! estimators (§1.3), and the full model that is the simulated plant (§1.4).

pub mod full;
pub mod params;
pub mod reduced;

pub use full::{CommandStats, FullState, IntegrationStats, Plant};
pub use params::{Patch, PlatformParams, Region, SlipParams, Surface, SurfaceMap};
pub use reduced::{Jacobians, Reduced, State5, Torques};
