//! Rex's controllers and estimators on the peers' problem ([`rex_bench::peer`]),
//! through rex-agent's public API: the NMPC (`nmpc`), the MHE (`mhe`) and the
//! baseline EKF (`ekf`). One test binary for the three (each links all of Rex).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

mod ekf;
mod mhe;
mod nmpc;
