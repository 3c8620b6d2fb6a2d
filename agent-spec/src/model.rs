//! The specification schema: what a RON spec file contains.
//!
//! Every struct denies unknown fields, so a misspelt field is an error that points at
//! it. Optional parts have defaults. Names are identifiers (`[A-Za-z_][A-Za-z0-9_]*`),
//! unique in their scope; component names (subsystems and devices) are unique in the
//! whole system, as in the paper (`c1`, `e11`, `r11`, `E1`, `R1`).
//!
//! References between entries are by name:
//!
//! * a buffer group names its *peer*, the component at the other end of its buffers
//!   (the paper's leading superscript: the group `e11` of `c1`'s outputs is `^e_y c`);
//! * a function reads buffers (`plan` for memory, `e11.ready` or `ready` for an input)
//!   and writes buffers of its one target (memory, or one output group);
//! * a link joins `component.group.buffer` of an output to that of an input;
//! * conditions are Boolean expressions over the subsystem's predicates.

use serde::{Deserialize, Serialize};

pub use crate::contracts::{
    Bound, Chain, Contracts, Freshness, Invariant, Latency, Rate, ReleaseJitter, Response, Timing,
    ValueRange, Wcet, Writes,
};

/// The formalism's vocabulary, shared with the runtime (`agent-core`): the kinds of
/// subsystems, devices and behaviours, link policies (`Sample`, `Queue(8)`) and the
/// relations between predicates that the arc proof assumes.
pub use agent_core::{BehaviourKind, DeviceKind, Policy, Relation, SubsystemKind};

/// A multi-agent system.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Spec {
    /// Name of the system.
    pub name: String,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub doc: Option<String>,
    /// The agents.
    pub agents: Vec<Agent>,
    /// Links from output buffers to input buffers.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub links: Vec<Link>,
    /// Ways to place the components on hosts and processes.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub deployments: Vec<Deployment>,
    /// The buffers the system shows to ROS 2, under which topics: in every
    /// deployment that has no `ros2` section of its own.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ros2: Option<Ros2>,
    /// What the system promises while it runs ([`crate::contracts`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub contracts: Option<Contracts>,
    /// What the timing analysis is given ([`crate::timing`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timing: Option<Timing>,
}

/// An embodied agent: one control subsystem, virtual effectors and receptors, and
/// real devices.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Agent {
    /// Name (`a1`).
    pub name: String,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub doc: Option<String>,
    /// Control subsystem, virtual effectors and virtual receptors.
    pub subsystems: Vec<Subsystem>,
    /// Real effectors and receptors.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub devices: Vec<Device>,
}

/// A subsystem: buffers, predicates, transition functions, behaviours and its FSM.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Subsystem {
    /// Unique component name (`c1`).
    pub name: String,
    /// Control subsystem, virtual effector or virtual receptor.
    pub kind: SubsystemKind,
    /// Period in milliseconds (positive).
    pub period_ms: f64,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub doc: Option<String>,
    /// Internal memory `^c c`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub memory: Vec<Buffer>,
    /// Input buffers `_x c`, grouped by peer.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub inputs: Vec<Group>,
    /// Output buffers `_y c`, grouped by peer.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub outputs: Vec<Group>,
    /// Named predicates: the atoms of conditions.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub predicates: Vec<Predicate>,
    /// Declared relations between predicates, used by the arc proof.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub relations: Vec<Relation>,
    /// Transition functions, each writing one target.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub functions: Vec<Function>,
    /// Behaviours: the nodes of the FSM.
    pub behaviours: Vec<Behaviour>,
    /// The FSM's initial node, arcs and final nodes.
    pub fsm: Fsm,
}

/// A buffer: a name and a (Rust) type.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Buffer {
    /// Name (`desired_plan`).
    pub name: String,
    /// Type, as a Rust type (`Vec<Point>`, `f64`, `[f64; 4]`); links compare it.
    #[serde(rename = "type")]
    pub ty: String,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub doc: Option<String>,
}

/// The buffers connected to one peer component.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Group {
    /// The component at the other end; for a fan, the fan's name.
    pub peer: String,
    /// Its buffers.
    pub buffers: Vec<Buffer>,
    /// A fan (agent-core's `Fan`: the group repeated once per peer, as many
    /// times as the system has peers): the component at the other end of each
    /// element, in order. A link names element `k`'s buffers
    /// `component.peer[k].buffer`; empty for an ordinary group.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub peers: Vec<String>,
}

/// A named predicate over memory and inputs.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Predicate {
    /// Name, used in conditions.
    pub name: String,
    /// Buffers it looks at (for the data-flow diagrams).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub reads: Vec<String>,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub doc: Option<String>,
}

/// What a transition function writes.
#[derive(Clone, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Target {
    /// The next memory (`f_{c,c}`), computed last.
    Memory,
    /// Intermediate results in memory shared by other parts, computed first.
    Common,
    /// The output group towards `peer` (`f_{c,e}`, `f_{c,T}`...).
    Output(String),
}

/// A transition function (one part of a behaviour's decomposed transition function).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Function {
    /// Name.
    pub name: String,
    /// Its target.
    pub target: Target,
    /// Buffers it reads: memory names, input names, or `group.name`.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub reads: Vec<String>,
    /// Buffers it writes, all in its target.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub writes: Vec<String>,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub doc: Option<String>,
}

/// A behaviour: an elementary action repeated until a terminal condition.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Behaviour {
    /// Name (`B1`).
    pub name: String,
    /// While or repeat.
    pub kind: BehaviourKind,
    /// The transition functions of its elementary action.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub functions: Vec<String>,
    /// The terminal condition (`"false"`: never ends).
    pub terminal: String,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub doc: Option<String>,
}

/// The FSM of a subsystem.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Fsm {
    /// The initial behaviour.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub initial: Option<String>,
    /// Arcs with initial conditions.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub arcs: Vec<FsmArc>,
    /// Behaviours after which the subsystem halts.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub finals: Vec<String>,
}

/// An arc of an FSM.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FsmArc {
    /// Source behaviour.
    pub from: String,
    /// Target behaviour.
    pub to: String,
    /// Initial condition.
    pub when: String,
}

/// A real effector or receptor.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Device {
    /// Unique component name (`E1`).
    pub name: String,
    /// Effector or receptor.
    pub kind: DeviceKind,
    /// Period in milliseconds (positive).
    pub period_ms: f64,
    /// Free text.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub doc: Option<String>,
    /// Commands, grouped by peer.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub inputs: Vec<Group>,
    /// Readings, grouped by peer.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub outputs: Vec<Group>,
}

/// A link from an output buffer to an input buffer.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Link {
    /// `component.group.buffer` of an output.
    pub from: String,
    /// `component.group.buffer` of an input.
    pub to: String,
    /// Delivery policy (default: sample).
    #[serde(default)]
    pub policy: Policy,
}

/// A placement of components on hosts and processes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Deployment {
    /// Name (`paper`, `simulation`).
    pub name: String,
    /// Hosts.
    pub hosts: Vec<Host>,
    /// Components deliberately not deployed.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub omit: Vec<String>,
    /// The first port of the processes' default endpoints: the `k`-th process
    /// (in order, over every host) listens on `tcp/<host address>:<port + k>`
    /// unless it names its own `listen`. Default [`Deployment::DEFAULT_PORT`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub port: Option<u16>,
    /// A Zenoh router every process connects to as well (`tcp/10.0.0.1:7447`),
    /// for networks where the processes cannot reach each other directly.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub router: Option<String>,
    /// How long a process waits for the others (to appear, to answer) before it
    /// fails with an error that names them, in ms. Default
    /// [`Deployment::DEFAULT_TIMEOUT_MS`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub timeout_ms: Option<u64>,
    /// Whether the links between its processes are secured: mutual
    /// authentication over QUIC (TLS 1.3; each process proves itself with a
    /// certificate of the deployment's authority) and an access control list
    /// generated from the spec (a process may publish only the output buffers
    /// of the components it runs, and subscribe only to their inputs). Secure
    /// unless the spec says `secure: false`: an unprotected deployment is one
    /// asked for by name ([`Deployment::is_secure`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub secure: Option<bool>,
    /// What this deployment shows to ROS 2, in place of the system's `ros2`
    /// section (the whole section is replaced, not merged).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub ros2: Option<Ros2>,
}

/// What a system (or one deployment) shows to ROS 2: the node the bridge
/// presents, the buffers it publishes and the input buffers ROS 2 topics may
/// feed. Names follow ROS 2's rules ([`crate::ros2`]); defaults are applied by
/// [`crate::ros2::interface`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2 {
    /// `ROS_DOMAIN_ID`, 0 to [`crate::ros2::DOMAIN_MAX`]; default 0.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub domain: Option<u32>,
    /// The node's name; default the system's name.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub node: Option<String>,
    /// The node's namespace (absolute); default `/`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub namespace: Option<String>,
    /// The package of the messages made from buffer types; default
    /// `<system name>_msgs`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub package: Option<String>,
    /// Output buffers published on ROS 2 topics.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub publish: Vec<Ros2Topic>,
    /// Input buffers fed by ROS 2 topics.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub subscribe: Vec<Ros2Topic>,
}

/// One buffer shown to ROS 2 under one topic.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Ros2Topic {
    /// `component.group.buffer`, as in a link: an output to publish, an input
    /// to feed.
    pub buffer: String,
    /// The topic: relative to the node's namespace (`pose`), absolute
    /// (`/pose`) or private to the node (`~/pose`).
    pub topic: String,
    /// A standard message (`geometry_msgs/msg/PoseStamped`) the bridge
    /// converts the buffer's values to and from; default the message made
    /// from the buffer's type, in the section's `package`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub message: Option<String>,
    /// Quality of service; what it leaves out comes from the buffer's link.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub qos: Option<Qos>,
}

/// A topic's quality of service as a spec writes it: every field optional.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Qos {
    /// Whether lost samples are sent again.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reliability: Option<Reliability>,
    /// How many samples are kept (keep-last), at least 1.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub depth: Option<u32>,
    /// Whether late subscribers get the samples kept.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub durability: Option<Durability>,
}

/// ROS 2's reliability policy.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Reliability {
    /// Every sample is delivered (sent again if lost).
    Reliable,
    /// Samples may be lost; none is sent again.
    BestEffort,
}

/// ROS 2's durability policy.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum Durability {
    /// Only subscribers present when a sample is published get it.
    Volatile,
    /// The publisher keeps its last `depth` samples for late subscribers.
    TransientLocal,
}

/// A machine.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Host {
    /// Name (`PC1`).
    pub name: String,
    /// The address the other hosts reach it at (`10.0.0.2`); default `127.0.0.1`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub address: Option<String>,
    /// Processes on it.
    pub processes: Vec<Process>,
}

/// An operating-system process.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Process {
    /// Name.
    pub name: String,
    /// Components it runs.
    pub runs: Vec<String>,
    /// The Zenoh endpoint it listens on (`tcp/10.0.0.2:7451`); default from the
    /// host's address and the deployment's port.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub listen: Option<String>,
    /// How many times a launcher may start it again after a crash; `0`:
    /// never (a process whose state cannot be rebuilt, such as a simulated
    /// world: its crash ends the launch). Default
    /// [`Process::DEFAULT_RESTARTS`].
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub restarts: Option<u32>,
}

impl Process {
    /// How many times a launcher restarts a crashed process unless the spec
    /// says otherwise.
    pub const DEFAULT_RESTARTS: u32 = 3;

    /// How many times a launcher may restart it ([`Process::restarts`]).
    pub fn restart_budget(&self) -> u32 {
        self.restarts.unwrap_or(Process::DEFAULT_RESTARTS)
    }
}

impl Spec {
    /// The deployment called `name`.
    pub fn deployment(&self, name: &str) -> Option<&Deployment> {
        self.deployments.iter().find(|d| d.name == name)
    }

    /// The names of its deployments, as a list for a message.
    pub fn deployment_names(&self) -> String {
        self.deployments
            .iter()
            .map(|d| d.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// Every subsystem, with its agent.
    pub fn subsystems(&self) -> impl Iterator<Item = (&Agent, &Subsystem)> {
        self.agents
            .iter()
            .flat_map(|a| a.subsystems.iter().map(move |s| (a, s)))
    }

    /// The subsystem called `name`.
    pub fn subsystem(&self, name: &str) -> Option<&Subsystem> {
        self.subsystems().map(|(_, s)| s).find(|s| s.name == name)
    }

    /// The structure without what a person writes for people and what code cannot
    /// tell: docs, the `reads` and `writes` of functions and predicates,
    /// deployments, the ROS 2 section, contracts and timing; without functions no behaviour uses (dead entries, a warning of
    /// the checker, that an FSM built from the spec does not hold); and without
    /// orders that mean nothing: functions and predicates are sorted by name, and so
    /// are the functions of each behaviour (their evaluation order is fixed by their
    /// targets: common, outputs, memory) and the arcs (exactly one holds when a
    /// behaviour ends). Two specs with the same structure describe the same system;
    /// the spec exported from code ([`crate::export`]) has only this much.
    pub fn structure(&self) -> Spec {
        let mut spec = self.clone();
        spec.doc = None;
        spec.deployments.clear();
        spec.ros2 = None;
        spec.contracts = None;
        spec.timing = None;
        let clear_groups = |groups: &mut Vec<Group>| {
            for g in groups {
                g.buffers.iter_mut().for_each(|b| b.doc = None);
            }
        };
        for a in &mut spec.agents {
            a.doc = None;
            for s in &mut a.subsystems {
                s.doc = None;
                s.memory.iter_mut().for_each(|m| m.doc = None);
                clear_groups(&mut s.inputs);
                clear_groups(&mut s.outputs);
                for p in &mut s.predicates {
                    p.doc = None;
                    p.reads.clear();
                }
                for f in &mut s.functions {
                    f.doc = None;
                    f.reads.clear();
                    f.writes.clear();
                }
                let used: Vec<String> = s
                    .behaviours
                    .iter()
                    .flat_map(|b| b.functions.iter().cloned())
                    .collect();
                s.functions.retain(|f| used.contains(&f.name));
                s.functions.sort_by(|a, b| a.name.cmp(&b.name));
                s.fsm
                    .arcs
                    .sort_by(|a, b| (&a.from, &a.to, &a.when).cmp(&(&b.from, &b.to, &b.when)));
                s.predicates.sort_by(|a, b| a.name.cmp(&b.name));
                for b in &mut s.behaviours {
                    b.doc = None;
                    b.functions.sort();
                }
            }
            for d in &mut a.devices {
                d.doc = None;
                clear_groups(&mut d.inputs);
                clear_groups(&mut d.outputs);
            }
        }
        spec
    }
}

impl Deployment {
    /// The first port of the default endpoints.
    pub const DEFAULT_PORT: u16 = 7450;
    /// The default wait for the other processes, in ms.
    pub const DEFAULT_TIMEOUT_MS: u64 = 10_000;

    /// Every process with its host and the endpoint it listens on, in order.
    pub fn processes(&self) -> Vec<(&Host, &Process, String)> {
        let base = self.port.unwrap_or(Self::DEFAULT_PORT);
        self.hosts
            .iter()
            .flat_map(|h| h.processes.iter().map(move |p| (h, p)))
            .enumerate()
            .map(|(k, (h, p))| {
                let endpoint = p.listen.clone().unwrap_or_else(|| {
                    let port = u16::try_from(k)
                        .ok()
                        .and_then(|k| base.checked_add(k))
                        .unwrap_or(base);
                    format!("tcp/{}:{port}", h.address.as_deref().unwrap_or("127.0.0.1"))
                });
                (h, p, endpoint)
            })
            .collect()
    }

    /// The process called `name`, with its host.
    pub fn process(&self, name: &str) -> Option<(&Host, &Process)> {
        self.hosts
            .iter()
            .flat_map(|h| h.processes.iter().map(move |p| (h, p)))
            .find(|(_, p)| p.name == name)
    }

    /// The process that runs component `component`.
    pub fn process_of(&self, component: &str) -> Option<&Process> {
        self.hosts
            .iter()
            .flat_map(|h| &h.processes)
            .find(|p| p.runs.iter().any(|r| r == component))
    }

    /// Whether its links are secured: unless the spec says `secure: false`.
    pub fn is_secure(&self) -> bool {
        self.secure != Some(false)
    }

    /// How long to wait for the other processes.
    pub fn timeout(&self) -> std::time::Duration {
        std::time::Duration::from_millis(self.timeout_ms.unwrap_or(Self::DEFAULT_TIMEOUT_MS))
    }

    /// The components it runs, on every host and in every process, in order.
    pub fn runs(&self) -> impl Iterator<Item = &str> {
        self.hosts
            .iter()
            .flat_map(|h| &h.processes)
            .flat_map(|p| &p.runs)
            .map(String::as_str)
    }
}

impl Subsystem {
    /// The function called `name`.
    pub fn function(&self, name: &str) -> Option<&Function> {
        self.functions.iter().find(|f| f.name == name)
    }
}
