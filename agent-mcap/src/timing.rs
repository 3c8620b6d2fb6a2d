//! The real-time executor's timing statistics in a recording: the `/timing`
//! channel.
//!
//! When a real-time run (or one process of a deployment) finishes its
//! recording, the application layer writes one JSON message on `/timing`
//! ([`McapRecorder::timing`](crate::McapRecorder::timing)): a
//! [`TimingStats`], per node what `agent_core::RtReport` measured. Its log
//! time is the run's last instant. The channel has no schema and no metadata,
//! so the recordings of a deployment's processes merge into one `/timing`
//! channel holding every process's message ([`merge`](crate::merge())).
//!
//! A deterministic run has no wall clock, hence no timing statistics: its
//! recording has no `/timing` channel.
//!
//! [`read_timing`] reads every message back; [`measured_wcets`] takes the
//! largest execution time of each node over them (the measured WCETs the
//! timing analysis may take in place of the declared ones), and
//! [`measured_lateness`] its largest wake-up lateness (its release jitter).

use std::collections::BTreeMap;

use agent_core::RtReport;
use serde::{Deserialize, Serialize};

use crate::read::Recording;

/// The topic of the timing statistics.
pub const TIMING_TOPIC: &str = "/timing";

/// The message encoding of the timing statistics.
pub const TIMING_ENCODING: &str = "json";

/// One process's timing statistics: what its real-time executor measured.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TimingStats {
    /// The format's version (1).
    pub version: u32,
    /// The host the process ran on (its host name, or the deployment's name of
    /// it).
    pub host: String,
    /// The process (`local` for a run in one process).
    pub process: String,
    /// Whether every thread got the real-time priority it asked for.
    pub rt_priority: bool,
    /// Wall-clock time of the run \[ns\].
    pub wall_ns: u64,
    /// The last instant executed \[ns\].
    pub last_instant_ns: u64,
    /// Per node, in declaration order.
    pub nodes: Vec<NodeStats>,
}

/// What the executor measured of one node.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct NodeStats {
    /// The node's name (a component of the spec).
    pub node: String,
    /// The thread it ran on.
    pub thread: String,
    /// Its period \[ns\].
    pub period_ns: u64,
    /// Activations executed.
    pub activations: u64,
    /// Execution time of one activation (decide, act, send; the first node
    /// of an instant on its thread also carries every due node's reads,
    /// which all happen before any steps): largest \[ns\].
    pub exec_max_ns: u64,
    /// Execution time, 99th percentile \[ns\].
    pub exec_p99_ns: u64,
    /// Execution time, median \[ns\].
    pub exec_p50_ns: u64,
    /// How late the thread woke after the activation's release: largest
    /// \[ns\]. Under `SCHED_FIFO` it includes the time a higher-priority
    /// thread kept it from running after its timer fired (which the timing
    /// analysis also counts as interference: pessimistic, not unsound).
    pub lateness_max_ns: u64,
    /// Lateness, 99th percentile \[ns\].
    pub lateness_p99_ns: u64,
    /// Response time (from the release to the activation's end: lateness,
    /// reads, the nodes before it on its thread, its execution): largest
    /// \[ns\]; 0 in recordings made before it was measured.
    #[serde(default)]
    pub response_max_ns: u64,
    /// Response time, 99th percentile \[ns\].
    #[serde(default)]
    pub response_p99_ns: u64,
    /// Activations that ended after the node's next release.
    pub overruns: u64,
    /// The `SCHED_FIFO` priority its thread asked for (`None`: ordinary).
    pub priority_asked: Option<u8>,
    /// The priority granted (`None`: not asked, or refused).
    pub priority_granted: Option<u8>,
}

impl TimingStats {
    /// The message as the `/timing` channel carries it (JSON).
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }

    /// The statistics of `report`, a real-time run of process `process` on
    /// `host`.
    pub fn from_report(report: &RtReport, host: &str, process: &str) -> TimingStats {
        let nodes = report
            .nodes
            .iter()
            .map(|n| {
                let thread = report.threads.iter().find(|t| t.name == n.thread);
                let asked = thread.and_then(|t| t.priority_asked);
                let granted = thread.and_then(|t| {
                    if t.priority_refused.is_none() {
                        t.priority_asked
                    } else {
                        None
                    }
                });
                let ns = |d: std::time::Duration| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
                NodeStats {
                    node: n.name.clone(),
                    thread: n.thread.clone(),
                    period_ns: n.period.as_nanos(),
                    activations: n.activations,
                    exec_max_ns: ns(n.compute.max),
                    exec_p99_ns: ns(n.compute.p99),
                    exec_p50_ns: ns(n.compute.p50),
                    lateness_max_ns: ns(n.jitter.max),
                    lateness_p99_ns: ns(n.jitter.p99),
                    response_max_ns: ns(n.response.max),
                    response_p99_ns: ns(n.response.p99),
                    overruns: n.overruns,
                    priority_asked: asked,
                    priority_granted: granted,
                }
            })
            .collect();
        TimingStats {
            version: 1,
            host: host.to_owned(),
            process: process.to_owned(),
            rt_priority: report.rt_priority(),
            wall_ns: u64::try_from(report.wall.as_nanos()).unwrap_or(u64::MAX),
            last_instant_ns: report.last_instant.as_nanos(),
            nodes,
        }
    }
}

/// Why a recording's timing statistics could not be read.
#[derive(Debug, thiserror::Error)]
pub enum TimingReadError {
    /// The recording has no `/timing` channel (a deterministic run, or one
    /// recorded before the channel existed).
    #[error(
        "{0} has no `/timing` channel: only real-time runs record timing statistics (a deterministic run has no wall clock)"
    )]
    NoChannel(String),
    /// A message is not the format of [`TimingStats`].
    #[error("{file}: `/timing` message {sequence}: {reason}")]
    Malformed {
        /// The file.
        file: String,
        /// The message's sequence number.
        sequence: u32,
        /// What is wrong.
        reason: String,
    },
}

/// Every `/timing` message of `recording` (one per process that recorded).
pub fn read_timing(recording: &Recording) -> Result<Vec<TimingStats>, TimingReadError> {
    let file = recording.path.display().to_string();
    let ids: Vec<u16> = recording
        .channels
        .values()
        .filter(|c| c.topic == TIMING_TOPIC)
        .map(|c| c.id)
        .collect();
    if ids.is_empty() {
        return Err(TimingReadError::NoChannel(file));
    }
    recording
        .messages
        .iter()
        .filter(|m| ids.contains(&m.channel))
        .map(|m| {
            serde_json::from_slice::<TimingStats>(&m.data).map_err(|e| TimingReadError::Malformed {
                file: file.clone(),
                sequence: m.sequence,
                reason: e.to_string(),
            })
        })
        .collect()
}

/// Per node, the largest execution time measured over `stats` \[ns\] (nodes
/// that never ran are left out). Nodes that shared a thread (the drivers of a
/// simulated environment run on one) keep their own times: the analysis
/// places them on threads of their own, where the one of the shorter period
/// (higher priority) delays the other, as running before it on the shared
/// thread does.
pub fn measured_wcets(stats: &[TimingStats]) -> BTreeMap<String, u64> {
    largest(stats, |n| n.exec_max_ns)
}

/// The largest wake-up lateness of each node over `stats` \[ns\]: how late
/// its thread started an activation after its release, the release jitter
/// the timing analysis may take (`--wcet-from`); nodes that never ran are
/// left out.
pub fn measured_lateness(stats: &[TimingStats]) -> BTreeMap<String, u64> {
    largest(stats, |n| n.lateness_max_ns)
}

/// The largest `figure` of each node that ran, over every process.
fn largest(stats: &[TimingStats], figure: impl Fn(&NodeStats) -> u64) -> BTreeMap<String, u64> {
    let mut out = BTreeMap::new();
    for s in stats {
        for n in s.nodes.iter().filter(|n| n.activations > 0) {
            let e = out.entry(n.node.clone()).or_insert(0u64);
            *e = (*e).max(figure(n));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn node(name: &str, max: u64, activations: u64) -> NodeStats {
        NodeStats {
            node: name.into(),
            thread: name.into(),
            period_ns: 1_000_000,
            activations,
            exec_max_ns: max,
            exec_p99_ns: max / 2,
            exec_p50_ns: max / 4,
            lateness_max_ns: 10,
            lateness_p99_ns: 5,
            response_max_ns: 0,
            response_p99_ns: 0,
            overruns: 0,
            priority_asked: Some(80),
            priority_granted: None,
        }
    }

    #[test]
    fn the_largest_execution_time_of_each_node_over_every_process() {
        let a = TimingStats {
            version: 1,
            host: "h".into(),
            process: "p1".into(),
            rt_priority: false,
            wall_ns: 1,
            last_instant_ns: 1,
            nodes: vec![node("c1", 300, 5), node("e11", 50, 5), node("idle", 900, 0)],
        };
        let mut b = a.clone();
        b.process = "p2".into();
        b.nodes = vec![node("c1", 700, 3)];
        let mut b2 = b.clone();
        b2.nodes = vec![node("R1", 20, 4), node("R3", 30, 4)];
        b2.nodes[1].thread = "R1".into();
        let w = measured_wcets(&[a.clone(), b, b2]);
        assert_eq!(w.get("R1"), Some(&20), "drivers on one thread: their own");
        assert_eq!(w.get("R3"), Some(&30));
        assert_eq!(w.get("c1"), Some(&700));
        assert_eq!(w.get("e11"), Some(&50));
        assert_eq!(
            w.get("idle"),
            None,
            "a node that never ran measured nothing"
        );
        let mut late = a.clone();
        late.nodes[0].lateness_max_ns = 600_000;
        let j = measured_lateness(&[a.clone(), late]);
        assert_eq!(j.get("c1"), Some(&600_000), "the largest lateness");
        assert_eq!(j.get("e11"), Some(&10));
        assert_eq!(j.get("idle"), None, "a node that never ran woke never");
        let text = serde_json::to_string(&a).unwrap_or_default();
        let back: TimingStats = serde_json::from_str(&text).unwrap_or_else(|_| b_default());
        assert_eq!(back, a);
    }

    fn b_default() -> TimingStats {
        TimingStats {
            version: 0,
            host: String::new(),
            process: String::new(),
            rt_priority: false,
            wall_ns: 0,
            last_instant_ns: 0,
            nodes: Vec::new(),
        }
    }
}
