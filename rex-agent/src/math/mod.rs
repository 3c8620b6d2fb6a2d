//! The numerics everything else uses, with nothing of Rex in them: small dense
//! linear solves on nalgebra (`linsolve`, crate-private), angles and rigid transforms
//! ([`geometry`]), and the seeded random generator ([`rng`]).

pub mod geometry;
pub(crate) mod linsolve;
pub mod rng;
