//! Rex's benchmark problems and data sets, outside the library: what the
//! benches, the examples and the tests measure Rex on, which no mission runs.
//!
//! * [`peer`]: the peers' NMPC/MHE problem (`peers/casadi_nmpc.py`,
//!   `peers/casadi_mhe.py`): the figure-eight reference, the closed loop, the
//!   MHE's data set;
//! * [`kitti`]: KITTI-format sequences of the simulated camera along scripted
//!   paths, any sequence read back, the visual odometry run and scored over one
//!   (the writer the camera records with stays in rex-agent:
//!   [`rex_agent::world::camera::kitti`]).
//!
//! rex-agent's examples (`bench_nmpc`, `bench_mhe`, `bench_qp`, `bench_vo`, `vo`,
//! `kitti_sequence`) use it as a dev-dependency; the tests of the NMPC, the MHE
//! and the EKF on the peers' problem are this crate's (`tests/peer/`), against
//! rex-agent's public API.

pub mod kitti;
pub mod peer;
