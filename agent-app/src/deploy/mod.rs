//! Deployments over Zenoh: one process of a deployment (`--deployment D
//! --process P`), and the launcher of all of them (`launch`).
//!
//! A launch has an identity, made when it starts and given to every process
//! it starts: the runtime's keys (presence, instant zero, the stop signal,
//! observations) carry it, so two launches never take each other's processes
//! for their own, whatever their ports. A process ends with its launcher: the
//! OS stops it when the launcher dies (a parent-death signal), and it stops
//! when the launcher's presence leaves the deployment (the launcher's host
//! lost).

pub(crate) mod holder;
pub(crate) mod launch;
pub(crate) mod process;

use serde::{Deserialize, Serialize};

/// What the layer itself reports from a process to its launcher (beside the
/// application's reports), on the observation `_layer`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub(crate) enum Note {
    /// A subsystem of the process halted.
    Halted(String),
    /// The process's run ended: its errors, the first of them, its last
    /// instant \[ns\], its overruns, the messages its links refused, and those
    /// the access control refused (a secure deployment).
    Ended {
        errors: u64,
        first_errors: Vec<String>,
        last_ns: u64,
        overruns: u64,
        refused: u64,
        acl_refused: u64,
    },
}

/// The observation that carries the application's reports.
pub(crate) const SEEN: &str = "seen";
/// The observation that carries the layer's [`Note`]s.
pub(crate) const NOTE: &str = "_layer";

/// The endpoint process `process` of `deployment` listens on, with the first
/// port replaced by `port` (a secure deployment's over QUIC, as
/// `agent_zenoh::Member` opens it).
pub(crate) fn endpoint_of(
    spec: &agent_spec::Spec,
    deployment: &str,
    process: &str,
    port: Option<u16>,
) -> Option<String> {
    let mut dep = spec.deployment(deployment)?.clone();
    if port.is_some() {
        dep.port = port;
    }
    let endpoint = dep
        .processes()
        .into_iter()
        .find(|(_, p, _)| p.name == process)
        .map(|(_, _, e)| e)?;
    Some(match endpoint.split_once('/') {
        Some(("tcp" | "tls", rest)) if dep.is_secure() => format!("quic/{rest}"),
        _ => endpoint,
    })
}

/// Check `--port` against the deployment: every process's port must be a
/// port a program may listen on (1024 to 65535).
pub(crate) fn check_port(
    spec: &agent_spec::Spec,
    deployment: &str,
    port: Option<u16>,
) -> Result<(), crate::AppError> {
    let Some(port) = port else {
        return Ok(());
    };
    let n = spec
        .deployment(deployment)
        .map_or(1, |d| d.processes().len().max(1));
    let last = u32::from(port) + u32::try_from(n).unwrap_or(u32::MAX) - 1;
    if port < 1024 || last > 65535 {
        return Err(crate::AppError::invalid(format!(
            "--port {port}: the deployment's {n} processes listen on ports {port} to {last}; they must lie within 1024-65535"
        )));
    }
    Ok(())
}

/// Say at start that `deployment` runs unprotected (the spec asked for it by
/// name, `secure: false`).
pub(crate) fn say_unprotected(spec: &agent_spec::Spec, deployment: &str) {
    if spec.deployment(deployment).is_some_and(|d| !d.is_secure()) {
        crate::output::warn(format_args!(
            "deployment `{deployment}` is unprotected (`secure: false` in the spec): whoever reaches its endpoints may read and write its links"
        ));
    }
}
