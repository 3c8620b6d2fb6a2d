//! The tank example's system, which the recording tests record, merge and
//! replay, and where they write.

use std::path::{Path, PathBuf};

use embodied::{NodeKind, System};

#[path = "../../examples/tank/agent.rs"]
mod agent;

/// `name` in the tests' scratch folder.
pub(crate) fn tmp(name: &str) -> PathBuf {
    Path::new(env!("CARGO_TARGET_TMPDIR")).join(name)
}

/// The tank example with its default mission.
pub(crate) fn system() -> System {
    agent::build(agent::default_mission(), 0.2, 7).unwrap().0
}

/// Its subsystems: the nodes a replay can rebuild (not the real effectors
/// and receptors).
pub(crate) fn subsystems() -> Vec<String> {
    system()
        .info()
        .nodes
        .iter()
        .filter(|n| !matches!(n.kind, NodeKind::RealEffector | NodeKind::RealReceptor))
        .map(|n| n.name.clone())
        .collect()
}
