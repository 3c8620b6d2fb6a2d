//! Agents and multi-agent systems: composing subsystems, drivers and links.
//!
//! A [`SystemBuilder`] collects agents, their components and the links between
//! buffers, checks the agent structure of the paper (Fig. 2) and reports every
//! problem at once from [`SystemBuilder::build`]:
//!
//! * every agent has exactly one control subsystem;
//! * a virtual effector exchanges buffers only with its own agent's control
//!   subsystem and real effectors; a virtual receptor only with its control
//!   subsystem and real receptors; real devices only with their virtual ones;
//! * agents talk only through their control subsystems (transmission buffers `T`);
//! * every input buffer is fed by at most one output.

use std::any::{Any, TypeId};
use std::borrow::Cow;
use std::collections::HashMap;
use std::fmt;
use std::marker::PhantomData;
use std::sync::Arc;

use crate::buffer::BufferPort;
use crate::buffer::{In, Out, Payload};
use crate::describe::PortTable;
use crate::error::{BuildError, BuildProblem};
use crate::fsm::Fsm;
use crate::kinds::{NodeKind, Policy};
use crate::link::{Access, ChannelPlan, InPlan, LinkId, OutPlan, Port};
use crate::node::{DriverCore, NodeSeed, SubsystemCore};
use crate::subsystem::{Driver, Subsystem};
use crate::time::Period;
use crate::trace::{LinkInfo, NodeInfo, SystemInfo};

/// Identifies an agent of a [`SystemBuilder`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct AgentId(usize);

/// Identifies a node (subsystem or driver): its index in declaration order, which is
/// also the executor's stepping order within an instant, but for real receptors,
/// which step last.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct NodeId(pub(crate) usize);

impl NodeId {
    /// The node's index.
    pub fn index(self) -> usize {
        self.0
    }
}

/// A typed handle to a subsystem added to a system.
pub struct SubsystemHandle<S> {
    node: usize,
    _s: PhantomData<fn() -> S>,
}

/// A typed handle to a driver added to a system.
pub struct DriverHandle<D> {
    node: usize,
    _d: PhantomData<fn() -> D>,
}

macro_rules! handle_impls {
    ($h:ident, $bound:ident) => {
        impl<X> Clone for $h<X> {
            fn clone(&self) -> Self {
                *self
            }
        }
        impl<X> Copy for $h<X> {}
        impl<X> fmt::Debug for $h<X> {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                write!(f, "{}({})", stringify!($h), self.node)
            }
        }
        impl<X: $bound> $h<X> {
            /// The node id.
            pub fn id(&self) -> NodeId {
                NodeId(self.node)
            }

            /// The output buffer `port` of this component, as the source of a link.
            pub fn output<T, A>(
                &self,
                port: Port<X::Output, Out<T>, A>,
            ) -> Source<X::Output, T, A> {
                Source {
                    node: self.node,
                    port,
                }
            }

            /// The input buffer `port` of this component, as the destination of a link.
            pub fn input<T, A>(&self, port: Port<X::Input, In<T>, A>) -> Sink<X::Input, T, A> {
                Sink {
                    node: self.node,
                    port,
                }
            }
        }
    };
}
handle_impls!(SubsystemHandle, Subsystem);
handle_impls!(DriverHandle, Driver);

/// The sending end of a link: an output buffer of one node.
pub struct Source<O, T, A> {
    node: usize,
    port: Port<O, Out<T>, A>,
}

/// The receiving end of a link: an input buffer of one node.
pub struct Sink<I, T, A> {
    node: usize,
    port: Port<I, In<T>, A>,
}

/// A checked system, ready for an executor.
///
/// A system is `Send`: build it on one thread and run it on another. It holds the
/// nodes and typed link plans; each executor instantiates them with its transport.
pub struct System {
    pub(crate) info: SystemInfo,
    pub(crate) nodes: Vec<Box<dyn NodeSeed>>,
    pub(crate) outs: Vec<(usize, Box<dyn OutPlan>)>,
    pub(crate) ins: Vec<(usize, Box<dyn InPlan>)>,
    pub(crate) channels: Vec<Box<dyn ChannelPlan>>,
    pub(crate) environment: Option<Box<dyn Any + Send>>,
}

impl fmt::Debug for System {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("System").field("info", &self.info).finish()
    }
}

impl System {
    /// Names, kinds, periods and links of the system.
    pub fn info(&self) -> &SystemInfo {
        &self.info
    }

    /// The shape of the payload of link `link` (an index into
    /// [`SystemInfo::links`]), traced when asked ([`crate::reflect`]): what a
    /// recorder needs to show its values without the type. `None` for an
    /// unknown link or a type the tracer cannot follow.
    pub fn payload_shape(&self, link: usize) -> Option<crate::TypeShape> {
        self.channels.get(link)?.shape()
    }

    /// The node of this name.
    pub fn node(&self, name: &str) -> Option<NodeId> {
        self.info
            .nodes
            .iter()
            .position(|n| n.name == name)
            .map(NodeId)
    }

    /// The fingerprint of the payload type of link `link` ([`crate::link::remote::fingerprint`]):
    /// what a recording keeps to tell the same type from a changed one.
    pub fn payload_fingerprint(&self, link: usize) -> Option<u64> {
        self.channels.get(link).map(|c| c.fingerprint())
    }
}

/// Builds a [`System`]: agents, their subsystems and drivers, and the links.
#[derive(Default)]
pub struct SystemBuilder {
    info: SystemInfo,
    nodes: Vec<Box<dyn NodeSeed>>,
    node_agent: Vec<usize>,
    names: HashMap<String, usize>,
    /// The agents by name (the first of each name).
    agent_names: HashMap<String, usize>,
    outs: Vec<(usize, Box<dyn OutPlan>)>,
    out_index: HashMap<(usize, &'static str), usize>,
    ins: Vec<(usize, Box<dyn InPlan>)>,
    fed: HashMap<(usize, &'static str), usize>,
    channels: Vec<Box<dyn ChannelPlan>>,
    ports: Vec<Option<PortTable>>,
    environment: Option<Box<dyn Any + Send>>,
    problems: Vec<BuildProblem>,
}

impl fmt::Debug for SystemBuilder {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("SystemBuilder")
            .field("info", &self.info)
            .field("problems", &self.problems)
            .finish()
    }
}

impl SystemBuilder {
    /// An empty system.
    pub fn new() -> Self {
        Self::default()
    }

    /// Give the system an environment: the world that real effectors act on and
    /// real receptors sense (a simulated plant, a scene). Drivers reach it with
    /// [`DriverContext::environment`](crate::DriverContext::environment); nothing
    /// else does, so components still talk only through buffers. Within an
    /// instant the executor steps real receptors after every other component: a
    /// receptor senses what the effectors did in that instant, whatever the
    /// declaration order. A second environment is a [`BuildProblem`].
    pub fn environment<W: Any + Send>(&mut self, world: W) -> &mut Self {
        if self.environment.is_some() {
            self.problems.push(BuildProblem::SeveralEnvironments);
        }
        self.environment = Some(Box::new(world));
        self
    }

    /// Declare an agent.
    pub fn agent(&mut self, name: impl Into<String>) -> AgentId {
        let name = name.into();
        if let Err(problem) = crate::names::check(&name) {
            self.problems.push(BuildProblem::InvalidName {
                what: "agent",
                name: name.clone(),
                problem,
            });
        }
        let id = self.info.agents.len();
        if self.agent_names.contains_key(&name) {
            self.problems
                .push(BuildProblem::DuplicateAgent(name.clone()));
        } else {
            self.agent_names.insert(name.clone(), id);
        }
        self.info.agents.push(name);
        AgentId(id)
    }

    fn add_node(
        &mut self,
        agent: AgentId,
        info: NodeInfo,
        node: Box<dyn NodeSeed>,
        ports: Option<PortTable>,
    ) -> usize {
        let index = self.nodes.len();
        if let Err(problem) = crate::names::check(&info.name) {
            self.problems.push(BuildProblem::InvalidName {
                what: match info.kind {
                    NodeKind::RealEffector | NodeKind::RealReceptor => "driver",
                    _ => "subsystem",
                },
                name: info.name.clone(),
                problem,
            });
        }
        if self.names.insert(info.name.clone(), index).is_some() {
            self.problems
                .push(BuildProblem::DuplicateNode(info.name.clone()));
        }
        if agent.0 >= self.info.agents.len() {
            self.problems.push(BuildProblem::ForeignHandle(format!(
                "the agent of `{}`",
                info.name
            )));
        }
        self.info.nodes.push(info);
        self.nodes.push(node);
        self.node_agent.push(agent.0);
        self.ports.push(ports);
        index
    }

    /// Add subsystem `name` of kind `S::KIND` to `agent`, with its period, initial
    /// memory and FSM.
    pub fn subsystem<S: Subsystem>(
        &mut self,
        agent: AgentId,
        name: impl Into<String>,
        period: Period,
        memory: S::Memory,
        fsm: Fsm<S>,
    ) -> SubsystemHandle<S> {
        let info = NodeInfo {
            name: name.into(),
            kind: S::KIND.into(),
            agent: self.agent_name(agent),
            period,
            behaviours: fsm.behaviour_names(),
            shape: S::shape(),
            fsm: Some(fsm.shape()),
        };
        let node = Box::new(SubsystemCore::new(&info.name, memory, fsm));
        SubsystemHandle {
            node: self.add_node(agent, info, node, S::ports()),
            _s: PhantomData,
        }
    }

    /// As [`SystemBuilder::subsystem`], with the subsystem's first input and
    /// output buffers given rather than their defaults: how the length of a
    /// [`Fan`](crate::Fan) (one group per peer) is fixed when the system is
    /// built (`Input { c1: Fan::new(robots), .. }`).
    #[allow(
        clippy::too_many_arguments,
        reason = "SystemBuilder::subsystem's five, and the two buffer structs"
    )]
    pub fn subsystem_with_buffers<S: Subsystem>(
        &mut self,
        agent: AgentId,
        name: impl Into<String>,
        period: Period,
        memory: S::Memory,
        fsm: Fsm<S>,
        input: S::Input,
        output: S::Output,
    ) -> SubsystemHandle<S> {
        let handle = self.subsystem(agent, name, period, memory, fsm);
        if let Some(node) = self.nodes.get_mut(handle.node) {
            if let Some(x) = node.buffers_any(false).downcast_mut::<S::Input>() {
                *x = input;
            }
            if let Some(y) = node.buffers_any(true).downcast_mut::<S::Output>() {
                *y = output;
            }
        }
        handle
    }

    /// Add driver `name` (a real effector or receptor) to `agent`, stepped every `period`.
    pub fn driver<D: Driver>(
        &mut self,
        agent: AgentId,
        name: impl Into<String>,
        period: Period,
        driver: D,
    ) -> DriverHandle<D> {
        let info = NodeInfo {
            name: name.into(),
            kind: D::KIND.into(),
            agent: self.agent_name(agent),
            period,
            behaviours: Arc::from([]),
            shape: D::shape(),
            fsm: None,
        };
        let node = Box::new(DriverCore::new(info.clone(), driver));
        DriverHandle {
            node: self.add_node(agent, info, node, D::ports()),
            _d: PhantomData,
        }
    }

    fn agent_name(&self, agent: AgentId) -> String {
        self.info
            .agents
            .get(agent.0)
            .cloned()
            .unwrap_or_else(|| format!("<agent #{}>", agent.0))
    }

    /// Link the output buffer `src` to the input buffer `dst` with `policy`.
    ///
    /// Connecting one output to several inputs fans it out (each input gets the
    /// value); connecting two outputs to one input is a [`BuildProblem`].
    pub fn connect<O, I, T, AO, AI>(
        &mut self,
        src: Source<O, T, AO>,
        dst: Sink<I, T, AI>,
        policy: Policy,
    ) -> LinkId
    where
        O: Send + 'static,
        I: Send + 'static,
        T: Payload,
        AO: Access<O, Out<T>>,
        AI: Access<I, In<T>>,
    {
        let buffer_types = |n: usize| self.nodes.get(n).map(|node| node.buffer_types());
        let src_ok = buffer_types(src.node).is_some_and(|(_, o)| o == TypeId::of::<O>());
        let dst_ok = buffer_types(dst.node).is_some_and(|(i, _)| i == TypeId::of::<I>());
        if !(src_ok && dst_ok) {
            let name = self.link_name(src.node, src.port.name(), dst.node, dst.port.name());
            self.problems.push(BuildProblem::ForeignHandle(format!(
                "a handle used in link `{name}`"
            )));
        }
        self.link(
            src.node,
            BufferPort::output(src.port),
            dst.node,
            BufferPort::input(dst.port),
            policy,
        )
    }

    /// The component called `name`, if it was added.
    pub fn node(&self, name: &str) -> Option<NodeId> {
        self.names.get(name).map(|&n| NodeId(n))
    }

    /// The agent called `name`, if it was declared.
    pub fn agent_id(&self, name: &str) -> Option<AgentId> {
        self.agent_names.get(name).map(|&a| AgentId(a))
    }

    /// Link the output buffer at path `src_buffer` (`e11.q_est`) of component `src`
    /// to the input buffer at `dst_buffer` of `dst`, found by name, with `policy`:
    /// how links are made from a spec. The components must describe their ports
    /// ([`Subsystem::ports`], [`Driver::ports`]: the derives do); a missing
    /// component or buffer and different payload types are [`BuildProblem`]s,
    /// reported by [`SystemBuilder::build`] with the others. Returns `None` when
    /// the link could not be made.
    pub fn connect_named(
        &mut self,
        src: &str,
        src_buffer: &str,
        dst: &str,
        dst_buffer: &str,
        policy: Policy,
    ) -> Option<LinkId> {
        let link = format!("{src}.{src_buffer} -> {dst}.{dst_buffer}");
        let mut end = |node: &str, buffer: &str, output: bool| -> Option<(usize, BufferPort)> {
            let Some(&n) = self.names.get(node) else {
                self.problems.push(BuildProblem::UnknownNode {
                    link: link.clone(),
                    node: node.to_owned(),
                });
                return None;
            };
            let Some(table) = self.ports[n] else {
                self.problems.push(BuildProblem::NoPorts {
                    link: link.clone(),
                    node: node.to_owned(),
                });
                return None;
            };
            let lookup = if output { table.outputs } else { table.inputs };
            match lookup(buffer) {
                Some(port) => Some((n, port)),
                None => {
                    let shape = self.info.nodes[n].shape;
                    let groups =
                        shape.map_or(&[][..], |s| if output { s.outputs } else { s.inputs });
                    let names: Vec<String> = groups
                        .iter()
                        .flat_map(|g| {
                            g.buffers.iter().map(move |b| {
                                if g.name.is_empty() {
                                    b.name.to_owned()
                                } else {
                                    format!("{}.{}", g.name, b.name)
                                }
                            })
                        })
                        .collect();
                    self.problems.push(BuildProblem::UnknownBuffer {
                        link: link.clone(),
                        node: node.to_owned(),
                        direction: if output { "output" } else { "input" },
                        buffer: buffer.to_owned(),
                        known: if names.is_empty() {
                            String::new()
                        } else {
                            format!(" (it has: {})", names.join(", "))
                        },
                    });
                    None
                }
            }
        };
        let from = end(src, src_buffer, true);
        let to = end(dst, dst_buffer, false);
        let ((s, out), (d, inp)) = (from?, to?);
        if out.payload() != inp.payload() {
            self.problems.push(BuildProblem::TypeMismatch {
                link,
                from: out.payload_name(),
                to: inp.payload_name(),
            });
            return None;
        }
        Some(self.link(s, out, d, inp, policy))
    }

    fn link_name(&self, src: usize, src_port: &str, dst: usize, dst_port: &str) -> String {
        format!(
            "{}.{src_port} -> {}.{dst_port}",
            self.node_name(src),
            self.node_name(dst)
        )
    }

    /// Node `n`'s name, borrowed (a system of thousands of links copies none
    /// of its nodes' names to name them).
    fn node_name(&self, n: usize) -> Cow<'_, str> {
        self.info.nodes.get(n).map_or_else(
            || Cow::Owned(format!("<node #{n}>")),
            |i| Cow::Borrowed(i.name.as_str()),
        )
    }

    /// The one way a link is made: both ends as [`BufferPort`]s of the same payload
    /// type (checked by the callers).
    fn link(
        &mut self,
        src: usize,
        out: BufferPort,
        dst: usize,
        inp: BufferPort,
        policy: Policy,
    ) -> LinkId {
        let link = self.info.links.len();
        let name = self.link_name(src, out.name(), dst, inp.name());
        // A zero bound is reported below; the channel gets capacity 1 so that the
        // executor never sees an impossible queue.
        let safe_policy = match policy {
            Policy::Queue { bound: 0 } => Policy::queue(1),
            p => p,
        };
        // Only the link layer's constructors make `BufferPort`s, and they always
        // carry their plans; a port without them makes no link and fails the build.
        let Some(channel) = out.channel(safe_policy) else {
            self.problems.push(BuildProblem::Structure {
                link: name,
                reason: format!("`{}` carries no link plan", out.name()),
            });
            return LinkId(link);
        };
        let input = format!("{}.{}", self.node_name(dst), inp.name());
        if src < self.info.nodes.len() && dst < self.info.nodes.len() {
            self.check_link(&name, src, &out, dst, &inp, policy);
            self.check_fan(&name, src, &out, true);
            self.check_fan(&name, dst, &inp, false);
        }
        let dst_key = (dst, inp.name());
        if let Some(&first) = self.fed.get(&dst_key) {
            self.problems.push(BuildProblem::InputFedTwice {
                input: input.clone(),
                first: self.info.links[first].name.clone(),
                second: name.clone(),
            });
        } else {
            self.fed.insert(dst_key, link);
        }
        let src_key = (src, out.name());
        match self.out_index.get(&src_key) {
            Some(&i) => self.outs[i].1.add_link(link),
            None => {
                if let Some(plan) = out.out_plan(link) {
                    self.out_index.insert(src_key, self.outs.len());
                    self.outs.push((src, plan));
                }
            }
        }
        if let Some(plan) = inp.in_plan(link, Cow::Owned(input)) {
            self.ins.push((dst, plan));
        }
        self.channels.push(channel);
        self.info.links.push(LinkInfo {
            name,
            from: src,
            from_port: out.name(),
            to: dst,
            to_port: inp.name(),
            policy,
            payload: out.payload_name(),
        });
        LinkId(link)
    }

    fn check_link(
        &mut self,
        name: &str,
        src: usize,
        out: &BufferPort,
        dst: usize,
        inp: &BufferPort,
        policy: Policy,
    ) {
        if policy == Policy::queue(0) {
            self.problems
                .push(BuildProblem::ZeroQueueBound(name.to_owned()));
        }
        let (s, d) = (&self.info.nodes[src], &self.info.nodes[dst]);
        let same_agent = self.node_agent[src] == self.node_agent[dst];
        if let Some(reason) = structure_violation(s.kind, d.kind, same_agent) {
            self.problems.push(BuildProblem::Structure {
                link: name.to_owned(),
                reason: reason.to_owned(),
            });
        }
        for (port, declared, actual) in [
            (out.name(), out.peer(), d.kind),
            (inp.name(), inp.peer(), s.kind),
        ] {
            if let Some(declared) = declared.filter(|k| *k != actual) {
                self.problems.push(BuildProblem::PeerMismatch {
                    link: name.to_owned(),
                    port: port.to_owned(),
                    declared,
                    actual,
                });
            }
        }
    }

    /// A link to element `k` of a fan of `node`: the fan must have it (a
    /// [`BuildProblem::NoFanElement`] otherwise, and the executor never reaches
    /// an element the fan lacks).
    fn check_fan(&mut self, link: &str, node: usize, port: &BufferPort, output: bool) {
        let (Some(fan), Some(seed)) = (port.fan.as_ref(), self.nodes.get_mut(node)) else {
            return;
        };
        let len = (fan.len)(seed.buffers_any(output)).unwrap_or(0);
        if fan.index >= len {
            self.problems.push(BuildProblem::NoFanElement {
                link: link.to_owned(),
                node: self.info.nodes[node].name.clone(),
                group: fan.group.to_owned(),
                index: fan.index,
                len,
            });
        }
    }

    /// Check the whole composition and build the system.
    pub fn build(mut self) -> Result<System, BuildError> {
        // Each agent's control subsystems, in one pass over the nodes (not one
        // per agent: a system of thousands of agents builds in linear time).
        let mut controls: Vec<Vec<&str>> = vec![Vec::new(); self.info.agents.len()];
        for (n, &owner) in self.info.nodes.iter().zip(&self.node_agent) {
            if n.kind == NodeKind::Control
                && let Some(c) = controls.get_mut(owner)
            {
                c.push(n.name.as_str());
            }
        }
        for (agent, controls) in self.info.agents.iter().zip(controls) {
            match controls.len() {
                1 => {}
                0 => self.problems.push(BuildProblem::NoControl(agent.clone())),
                count => self.problems.push(BuildProblem::SeveralControls {
                    agent: agent.clone(),
                    count,
                    names: controls.join(", "),
                }),
            }
        }
        if !self.problems.is_empty() {
            return Err(BuildError {
                problems: self.problems,
            });
        }
        Ok(System {
            info: self.info,
            nodes: self.nodes,
            outs: self.outs,
            ins: self.ins,
            channels: self.channels,
            environment: self.environment,
        })
    }
}

/// Why a link from a `src` node to a `dst` node breaks the agent structure, if it does.
pub fn structure_violation(src: NodeKind, dst: NodeKind, same_agent: bool) -> Option<&'static str> {
    use NodeKind::*;
    let allowed_within_agent = matches!(
        (src, dst),
        (Control, VirtualEffector | VirtualReceptor)
            | (VirtualEffector | VirtualReceptor, Control)
            | (VirtualEffector, RealEffector)
            | (RealEffector, VirtualEffector)
            | (VirtualReceptor, RealReceptor)
            | (RealReceptor, VirtualReceptor)
    );
    match (src, dst) {
        (Control, Control) if same_agent => {
            Some("a control subsystem links to control subsystems of other agents only")
        }
        (Control, Control) => None,
        _ if allowed_within_agent && same_agent => None,
        _ if allowed_within_agent => Some(
            "components of different agents exchange buffers only through their control subsystems (transmission buffers)",
        ),
        (VirtualEffector, _) | (_, VirtualEffector) => Some(
            "a virtual effector exchanges buffers only with its own control subsystem and real effectors",
        ),
        (VirtualReceptor, _) | (_, VirtualReceptor) => Some(
            "a virtual receptor exchanges buffers only with its own control subsystem and real receptors",
        ),
        _ => Some(
            "real effectors and receptors exchange buffers only with their agent's virtual effectors and receptors",
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use NodeKind::*;

    #[test]
    fn structure_rules() {
        let ok = [
            (Control, VirtualEffector),
            (VirtualEffector, Control),
            (Control, VirtualReceptor),
            (VirtualReceptor, Control),
            (VirtualEffector, RealEffector),
            (RealEffector, VirtualEffector),
            (VirtualReceptor, RealReceptor),
            (RealReceptor, VirtualReceptor),
        ];
        let all = [
            Control,
            VirtualEffector,
            VirtualReceptor,
            RealEffector,
            RealReceptor,
        ];
        for s in all {
            for d in all {
                let within = structure_violation(s, d, true).is_none();
                let across = structure_violation(s, d, false).is_none();
                assert_eq!(
                    within,
                    ok.contains(&(s, d)),
                    "{s:?} -> {d:?} within an agent"
                );
                assert_eq!(
                    across,
                    (s, d) == (Control, Control),
                    "{s:?} -> {d:?} across agents"
                );
            }
        }
    }
}
