//! The formalism's vocabulary: the kinds of components and behaviours, and how links
//! deliver values.
//!
//! These types are shared by the runtime, the spec model (`agent-spec` reads and writes
//! them with serde, as they are spelled in RON specs) and the code generators, so
//! that one formalism has one set of words.

use std::fmt;

use serde::{Deserialize, Serialize};

/// The five kinds of components of an embodied agent.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub enum NodeKind {
    /// Control subsystem `c_j`.
    Control,
    /// Virtual effector `e_{j,n}`.
    VirtualEffector,
    /// Virtual receptor `r_{j,k}`.
    VirtualReceptor,
    /// Real effector `E_j` (hardware or simulator driver).
    RealEffector,
    /// Real receptor `R_j` (hardware or simulator driver).
    RealReceptor,
}

impl NodeKind {
    /// The paper's symbol for the kind: `c`, `e`, `r`, `E` or `R`.
    pub const fn symbol(self) -> &'static str {
        match self {
            NodeKind::Control => "c",
            NodeKind::VirtualEffector => "e",
            NodeKind::VirtualReceptor => "r",
            NodeKind::RealEffector => "E",
            NodeKind::RealReceptor => "R",
        }
    }
}

impl fmt::Display for NodeKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            NodeKind::Control => "control subsystem",
            NodeKind::VirtualEffector => "virtual effector",
            NodeKind::VirtualReceptor => "virtual receptor",
            NodeKind::RealEffector => "real effector",
            NodeKind::RealReceptor => "real receptor",
        })
    }
}

/// The kinds of subsystem a user implements with behaviours and an FSM.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum SubsystemKind {
    /// Control subsystem `c_j`: coordinates the agent and talks to other agents.
    Control,
    /// Virtual effector `e_{j,n}`: turns the control subsystem's commands into
    /// commands for the real effectors.
    VirtualEffector,
    /// Virtual receptor `r_{j,k}`: turns real receptor readings into concepts the
    /// control subsystem uses.
    VirtualReceptor,
}

impl From<SubsystemKind> for NodeKind {
    fn from(k: SubsystemKind) -> NodeKind {
        match k {
            SubsystemKind::Control => NodeKind::Control,
            SubsystemKind::VirtualEffector => NodeKind::VirtualEffector,
            SubsystemKind::VirtualReceptor => NodeKind::VirtualReceptor,
        }
    }
}

/// The kinds of real devices.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum DeviceKind {
    /// Real effector `E_j` (motors, valves, a simulated platform).
    Effector,
    /// Real receptor `R_j` (cameras, gauges, a simulated sensor).
    Receptor,
}

impl From<DeviceKind> for NodeKind {
    fn from(k: DeviceKind) -> NodeKind {
        match k {
            DeviceKind::Effector => NodeKind::RealEffector,
            DeviceKind::Receptor => NodeKind::RealReceptor,
        }
    }
}

/// The two behaviour patterns of the paper.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum BehaviourKind {
    /// Algorithm 2: `while f^τ = false do A`. The terminal condition is tested before
    /// every iteration, including the first, so the action may run zero times.
    While,
    /// Algorithm 3: `repeat A until f^τ = true`. The action runs at least once; the
    /// condition is tested after each iteration (on the inputs read at its end).
    Repeat,
}

impl fmt::Display for BehaviourKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            BehaviourKind::While => "while",
            BehaviourKind::Repeat => "repeat",
        })
    }
}

impl BehaviourKind {
    /// Whether the terminal condition is tested now: always for `While`; for
    /// `Repeat` only once at least one action of this activation of the behaviour ran.
    #[inline]
    pub fn tests_terminal(self, actions_done: bool) -> bool {
        match self {
            BehaviourKind::While => true,
            BehaviourKind::Repeat => actions_done,
        }
    }
}

/// How a link delivers values.
///
/// In a spec (RON) it is written `Sample` or `Queue(8)`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(from = "PolicyRepr", into = "PolicyRepr")]
pub enum Policy {
    /// Latest value wins.
    #[default]
    Sample,
    /// Lossless FIFO holding at most `bound` values.
    Queue {
        /// Capacity of the queue (at least 1).
        bound: usize,
    },
}

impl Policy {
    /// A queue of capacity `bound`.
    pub const fn queue(bound: usize) -> Policy {
        Policy::Queue { bound }
    }
}

impl fmt::Display for Policy {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Policy::Sample => f.write_str("sample"),
            Policy::Queue { bound } => write!(f, "queue({bound})"),
        }
    }
}

/// How a [`Policy`] is spelled in specs: `Sample` or `Queue(8)`.
#[derive(Clone, Copy, Serialize, Deserialize)]
#[serde(rename = "Policy")]
enum PolicyRepr {
    Sample,
    Queue(usize),
}

impl From<PolicyRepr> for Policy {
    fn from(r: PolicyRepr) -> Policy {
        match r {
            PolicyRepr::Sample => Policy::Sample,
            PolicyRepr::Queue(bound) => Policy::Queue { bound },
        }
    }
}

impl From<Policy> for PolicyRepr {
    fn from(p: Policy) -> PolicyRepr {
        match p {
            Policy::Sample => PolicyRepr::Sample,
            Policy::Queue { bound } => PolicyRepr::Queue(bound),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn policies_read_and_write_as_specs_spell_them() {
        for (text, policy) in [("Sample", Policy::Sample), ("Queue(8)", Policy::queue(8))] {
            let parsed: Policy = ron::from_str(text).expect("parses");
            assert_eq!(parsed, policy);
            assert_eq!(ron::to_string(&policy).expect("writes"), text);
        }
        assert!(ron::from_str::<Policy>("Queue").is_err());
    }

    #[test]
    fn kinds_read_as_specs_spell_them() {
        let k: SubsystemKind = ron::from_str("VirtualReceptor").expect("parses");
        assert_eq!(NodeKind::from(k), NodeKind::VirtualReceptor);
        let d: DeviceKind = ron::from_str("Effector").expect("parses");
        assert_eq!(NodeKind::from(d), NodeKind::RealEffector);
        let b: BehaviourKind = ron::from_str("Repeat").expect("parses");
        assert!(!b.tests_terminal(false));
    }
}
