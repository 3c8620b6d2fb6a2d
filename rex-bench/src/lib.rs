//! Rex's benchmark problems and data sets, outside the library: what the
//! benches, the examples and the tests measure Rex on, which no mission runs.
//!
//! * [`peer`]: the peers' NMPC/MHE problem (`peers/casadi_nmpc.py`,
//!   `peers/casadi_mhe.py`): the figure-eight reference, the closed loop, the
//!   MHE's data set;
//!
//! rex-agent's examples (`bench_nmpc`, `bench_mhe`, `bench_qp`) use it as a
//! dev-dependency; the tests of the NMPC, the MHE and the EKF on the peers'
//! problem are this crate's (`tests/peer/`), against rex-agent's public API.

pub mod peer;
