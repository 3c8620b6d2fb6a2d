//! Fixtures shared by the tests that run members of a deployment: agent-core's
//! counter and recorder (re-exported) and a real-time run placed on a member's
//! process.

#![allow(dead_code, reason = "each test file uses part of the fixtures")]
#![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

#[path = "../../../agent-core/tests/common/mod.rs"]
mod fixtures;

pub(crate) use fixtures::*;

use agent_core::{ExecConfig, OnError, RealTime, RtConfig, System};
use agent_zenoh::Member;

/// A real-time run of `system` that reports an action's error and goes on
/// ([`OnError::Continue`]), its subsystems placed as `member`'s process runs
/// them.
pub(crate) fn placed(system: System, member: &mut Member) -> RealTime {
    let mut rt = RealTime::new(
        system,
        RtConfig {
            exec: ExecConfig {
                on_error: OnError::Continue,
                ..ExecConfig::default()
            },
            ..RtConfig::default()
        },
    );
    rt.place(member.placement().unwrap()).unwrap();
    rt
}
