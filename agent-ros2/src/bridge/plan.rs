//! The plan of a bridge: from a spec's `ros2` section and a built system,
//! which link carries each published buffer's values (and which link's input
//! each subscribed topic feeds: `inbound`), under which topic, as which
//! message (its type hash) and with which QoS. Everything that can be wrong
//! is found here, before anything runs. Across the plan, published and
//! subscribed alike, each message name has one definition (`intern`: a
//! helper or root defined differently by two topics is numbered, `Item2`).

use std::sync::Arc;

use agent_core::{System, SystemInfo};
use agent_mcap::cdr::root_name;
use agent_spec::model::{Deployment, Durability, Reliability, Spec};
use agent_spec::ros2::{self as spec_ros2, Interface as SpecInterface, QosProfile, Topic};

use super::adapter::{Adapters, Conversion, Encoder};
use super::inbound::{SubscribedTopic, subscribed};
use super::intern::one_definition_per_name;
use crate::types::standard::builtin_interfaces::Time;
use crate::types::{Messages, messages, type_hash};
use crate::wire::{Interface, Qos, TopicKey, TypeName};

/// Why a spec's `ros2` section cannot be published from a system.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PlanError {
    /// Neither the deployment nor the system has a `ros2` section.
    #[error("the spec has no `ros2` section: it shows nothing to ROS 2")]
    NoSection,
    /// A name of the section (the node's, its namespace, the package, a
    /// topic's full name) breaks ROS 2's rules as the spec checker applies
    /// them ([`agent_spec::ros2`]).
    #[error("the ROS 2 {entry} `{name}`: {source}")]
    Name {
        /// What the name names: `node name`, `namespace`, `package`, or
        /// ``topic of buffer `c.e.pose` ``.
        entry: String,
        /// The name (a topic's fully qualified).
        name: String,
        /// The rule broken.
        source: spec_ros2::NameError,
    },
    /// A published buffer that is no output of the spec.
    #[error("buffer `{buffer}` (topic `{topic}`) is no output of the spec")]
    UnknownBuffer {
        /// The buffer, `component.peer.buffer`.
        buffer: String,
        /// The topic as the spec writes it.
        topic: String,
    },
    /// A subscribed buffer that is no input of the spec.
    #[error("buffer `{buffer}` (topic `{topic}`) is no input of the spec")]
    UnknownInput {
        /// The buffer, `component.peer.buffer`.
        buffer: String,
        /// The topic as the spec writes it.
        topic: String,
    },
    /// A subscribed buffer no link of the system goes into: the bridge
    /// feeds an input beside the link that carries its values.
    #[error(
        "buffer `{buffer}` (topic `{topic}`) has no link in the system: no input takes values from it"
    )]
    NoInputLink {
        /// The buffer.
        buffer: String,
        /// The fully qualified topic.
        topic: String,
    },
    /// The spec feeds an input buffer from a standard message, and no
    /// adapter reads one into the buffer's type.
    #[error(
        "buffer `{buffer}` (topic `{topic}`) of type `{payload}` is fed from `{message}`, and no adapter reads one into that type{}",
        if available.is_empty() { String::new() } else { format!(" (adapters into the type read: {})", available.join(", ")) }
    )]
    NoInboundAdapter {
        /// The buffer.
        buffer: String,
        /// The fully qualified topic.
        topic: String,
        /// The buffer's Rust type.
        payload: String,
        /// The message the spec names.
        message: String,
        /// The messages adapters do read into the type.
        available: Vec<String>,
    },
    /// A published buffer no link of the system carries: the bridge sees
    /// values only as they are sent into links.
    #[error(
        "buffer `{buffer}` (topic `{topic}`) has no link in the system: no value of it is ever sent"
    )]
    NoLink {
        /// The buffer.
        buffer: String,
        /// The fully qualified topic.
        topic: String,
    },
    /// The buffer's type cannot be a ROS 2 message.
    #[error(
        "buffer `{buffer}` (topic `{topic}`) of type `{payload}` cannot be a ROS 2 message: {reason}"
    )]
    NotAMessage {
        /// The buffer.
        buffer: String,
        /// The fully qualified topic.
        topic: String,
        /// The buffer's Rust type.
        payload: String,
        /// Why not.
        reason: String,
    },
    /// The spec names a standard message, and no adapter makes it of the
    /// buffer's type.
    #[error(
        "buffer `{buffer}` (topic `{topic}`) of type `{payload}` is published as `{message}`, and no adapter makes one of that type{}",
        if available.is_empty() { String::new() } else { format!(" (adapters of the type make: {})", available.join(", ")) }
    )]
    NoAdapter {
        /// The buffer.
        buffer: String,
        /// The fully qualified topic.
        topic: String,
        /// The buffer's Rust type.
        payload: String,
        /// The message the spec names.
        message: String,
        /// The messages adapters do make of the type.
        available: Vec<String>,
    },
    /// Transient local durability: late joiners would need a publisher
    /// cache, which this bridge does not keep yet.
    #[error(
        "topic `{topic}` (buffer `{buffer}`) asks for transient local durability, which the bridge does not provide yet (volatile only)"
    )]
    TransientLocal {
        /// The buffer.
        buffer: String,
        /// The fully qualified topic.
        topic: String,
    },
}

impl PlanError {
    /// The buffer whose Rust type cannot be its topic's message
    /// ([`PlanError::NotAMessage`], [`PlanError::NoAdapter`],
    /// [`PlanError::NoInboundAdapter`]): what only the program finds, for it
    /// to point at the spec's entry (`agent_spec::ros2::entry_span`).
    pub fn mistyped_buffer(&self) -> Option<&str> {
        match self {
            PlanError::NotAMessage { buffer, .. }
            | PlanError::NoAdapter { buffer, .. }
            | PlanError::NoInboundAdapter { buffer, .. } => Some(buffer),
            _ => None,
        }
    }
}

/// One buffer published on one topic.
#[derive(Clone)]
pub struct PublishedTopic {
    /// The buffer, `component.peer.buffer`.
    pub buffer: String,
    /// The link whose values are published (the first of the buffer's).
    pub link: usize,
    /// The buffer's Rust type.
    pub payload: &'static str,
    /// The message and every message it uses (their `.msg` texts).
    pub messages: Messages,
    /// The data key: domain, fully qualified topic, type and type hash.
    pub key: TopicKey,
    /// The quality of service the publisher announces.
    pub qos: Qos,
    pub(crate) encoder: Encoder,
}

impl std::fmt::Debug for PublishedTopic {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("PublishedTopic")
            .field("buffer", &self.buffer)
            .field("link", &self.link)
            .field("key", &self.key.to_string())
            .field("qos", &self.qos.to_compact())
            .finish()
    }
}

/// A topic of the spec's `subscribe` entries that the plan does not serve
/// ([`Plan::unserve_subscriptions`]), and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct UnservedTopic {
    /// The input buffer, `component.peer.buffer`.
    pub buffer: String,
    /// The fully qualified topic.
    pub topic: String,
    /// Why it is not served.
    pub reason: &'static str,
}

/// `topic `/x` (buffer `e.c.x`) is not subscribed: <reason>`, for a warning.
impl std::fmt::Display for UnservedTopic {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "topic `{}` (buffer `{}`) is not subscribed: {}",
            self.topic, self.buffer, self.reason
        )
    }
}

/// What a bridge publishes and subscribes to: the node it presents and its
/// topics.
#[derive(Clone, Debug)]
pub struct Plan {
    /// `ROS_DOMAIN_ID`.
    pub domain: u32,
    /// The node's name.
    pub node: String,
    /// The node's namespace (`/` for the root).
    pub namespace: String,
    /// The package of the messages made from buffer types.
    pub package: String,
    /// The published buffers, in the spec's order.
    pub topics: Vec<PublishedTopic>,
    /// The subscribed topics, each feeding an input buffer, in the spec's
    /// order ([`Bridge::subscribe`](super::Bridge::subscribe) takes their
    /// indices).
    pub subscriptions: Vec<SubscribedTopic>,
    /// The subscribed topics not served, in the spec's order.
    unserved: Vec<UnservedTopic>,
}

impl Plan {
    /// The plan of what `spec` shows to ROS 2 and takes from it when
    /// `deployment` runs (`None`: the system's section) from `system` (built
    /// from the spec), standard messages made and read by `adapters`.
    /// Buffers of components the deployment does not run are left out. The
    /// node, namespace, package and every topic's full name are held to the
    /// spec checker's rules ([`agent_spec::ros2`]), so a plan of an unchecked
    /// spec announces no name the checker refuses. Every `subscribe` entry
    /// is served ([`Plan::subscriptions`]) until the caller says otherwise
    /// ([`Plan::unserve_subscriptions`]).
    pub fn new(
        spec: &Spec,
        deployment: Option<&Deployment>,
        system: &System,
        adapters: &Adapters,
    ) -> Result<Plan, PlanError> {
        let section = spec_ros2::section(spec, deployment).ok_or(PlanError::NoSection)?;
        if let Some(entry) = section
            .publish
            .iter()
            .find(|e| spec_ros2::buffer_type(spec, &e.buffer, true).is_none())
        {
            return Err(PlanError::UnknownBuffer {
                buffer: entry.buffer.clone(),
                topic: entry.topic.clone(),
            });
        }
        if let Some(entry) = section
            .subscribe
            .iter()
            .find(|e| spec_ros2::buffer_type(spec, &e.buffer, false).is_none())
        {
            return Err(PlanError::UnknownInput {
                buffer: entry.buffer.clone(),
                topic: entry.topic.clone(),
            });
        }
        let interface = spec_ros2::interface(spec, deployment).ok_or(PlanError::NoSection)?;
        check_names(&interface)?;
        let mut topics: Vec<PublishedTopic> = interface
            .publish
            .iter()
            .map(|t| published(t, &interface, system, adapters))
            .collect::<Result<_, _>>()?;
        let mut subscriptions: Vec<SubscribedTopic> = interface
            .subscribe
            .iter()
            .map(|t| subscribed(t, &interface, system, adapters))
            .collect::<Result<_, _>>()?;
        consistent(interface.domain, &mut topics, &mut subscriptions)?;
        Ok(Plan {
            domain: interface.domain,
            node: interface.node,
            namespace: interface.namespace,
            package: interface.package,
            topics,
            subscriptions,
            unserved: Vec::new(),
        })
    }

    /// The topics of the section's `subscribe` entries (of the components
    /// run) that this plan does not serve, each with the reason given to
    /// [`Plan::unserve_subscriptions`]; empty when every one is served. The
    /// bridge logs nothing: a caller prints them as warnings if it wants.
    pub fn unserved(&self) -> &[UnservedTopic] {
        &self.unserved
    }

    /// This plan serving no subscribed topic: each moves to
    /// [`Plan::unserved`] with `reason` (a run that cannot take values from
    /// ROS 2, as a deterministic one, which is not on the wall clock). Their
    /// messages keep the names they were given beside the published ones.
    pub fn unserve_subscriptions(mut self, reason: &'static str) -> Plan {
        let moved = self.subscriptions.drain(..).map(|t| UnservedTopic {
            topic: t.key.topic().to_owned(),
            buffer: t.buffer,
            reason,
        });
        self.unserved.extend(moved);
        self
    }
}

impl Plan {
    /// This plan for one process of a deployment: only the buffers of the
    /// components it runs (`runs`, as the deployment's process lists them),
    /// since a process sees only the values its own nodes send, and feeds
    /// only the inputs of its own nodes. The node's
    /// name stays: give each process's bridge its own with [`Plan::named`]
    /// if ROS 2 should tell them apart.
    pub fn only_components<S: AsRef<str>>(mut self, runs: &[S]) -> Plan {
        let run = |buffer: &str| {
            let component = buffer.split('.').next().unwrap_or_default();
            runs.iter().any(|r| r.as_ref() == component)
        };
        self.topics.retain(|t| run(&t.buffer));
        self.subscriptions.retain(|t| run(&t.buffer));
        self.unserved.retain(|t| run(&t.buffer));
        self
    }

    /// This plan with the node named `node` (a ROS 2 node name, as the spec
    /// checker's [`check_node`](agent_spec::ros2::check_node) accepts).
    pub fn named(mut self, node: &str) -> Result<Plan, PlanError> {
        checked("node name", node, spec_ros2::check_node)?;
        node.clone_into(&mut self.node);
        Ok(self)
    }
}

/// `name` checked by `check`, one of the spec checker's rules; the error
/// names `entry`.
fn checked(
    entry: &str,
    name: &str,
    check: fn(&str) -> Result<(), spec_ros2::NameError>,
) -> Result<(), PlanError> {
    check(name).map_err(|source| PlanError::Name {
        entry: entry.to_owned(),
        name: name.to_owned(),
        source,
    })
}

/// The interface's node, namespace, package and every topic's full name
/// (published or subscribed), by the spec checker's rules.
fn check_names(interface: &SpecInterface) -> Result<(), PlanError> {
    checked("node name", &interface.node, spec_ros2::check_node)?;
    checked(
        "namespace",
        &interface.namespace,
        spec_ros2::check_namespace,
    )?;
    checked("package", &interface.package, spec_ros2::check_package)?;
    for t in interface.publish.iter().chain(&interface.subscribe) {
        let entry = format!("topic of buffer `{}`", t.buffer);
        checked(&entry, &t.name, spec_ros2::check_full_topic)?;
    }
    Ok(())
}

/// The plan of one published buffer.
fn published(
    t: &Topic,
    interface: &SpecInterface,
    system: &System,
    adapters: &Adapters,
) -> Result<PublishedTopic, PlanError> {
    let info = system.info();
    let link = link_of(info, &t.buffer).ok_or_else(|| PlanError::NoLink {
        buffer: t.buffer.clone(),
        topic: t.name.clone(),
    })?;
    let payload = info.links[link].payload;
    let plan = message_plan(
        t,
        interface,
        system,
        link,
        payload,
        |message, fingerprint| {
            let adapter =
                adapters
                    .find(fingerprint, message)
                    .ok_or_else(|| PlanError::NoAdapter {
                        buffer: t.buffer.clone(),
                        topic: t.name.clone(),
                        payload: payload.to_owned(),
                        message: message.to_owned(),
                        available: adapters.messages_of(fingerprint),
                    })?;
            Ok((adapter.traceable, &adapter.messages, &adapter.make))
        },
    )?;
    Ok(PublishedTopic {
        buffer: t.buffer.clone(),
        link,
        payload,
        messages: plan.messages,
        key: plan.key,
        qos: plan.qos,
        encoder: plan.conversion,
    })
}

/// What the plans of a published and of a subscribed topic share, past the
/// link: the message, how the bridge converts it, its key and QoS.
pub(crate) struct MessagePlan<F: ?Sized> {
    /// The message and every message it uses.
    pub(crate) messages: Messages,
    /// The buffer type's own message (its shape as JSON), or the adapter's.
    pub(crate) conversion: Conversion<F>,
    /// The data key.
    pub(crate) key: TopicKey,
    /// The quality of service.
    pub(crate) qos: Qos,
}

/// An adapter as [`message_plan`] takes it: whether its message's shape can
/// be traced, its messages, and what makes its conversion.
pub(crate) type FoundAdapter<'a, F> = (
    bool,
    &'a Messages,
    &'a Arc<dyn Fn() -> Option<Box<F>> + Send + Sync>,
);

/// The plan of topic `t` on link `link` (of buffer type `payload`): without
/// a message named in the spec, the message made from the buffer type's
/// shape; with one, the adapter `adapter` finds for it and the buffer type's
/// fingerprint (or the error it gives), refused when its message's shape
/// cannot be traced; then the key and the QoS.
pub(crate) fn message_plan<'a, F: ?Sized + 'a>(
    t: &Topic,
    interface: &SpecInterface,
    system: &System,
    link: usize,
    payload: &'static str,
    adapter: impl FnOnce(&str, u64) -> Result<FoundAdapter<'a, F>, PlanError>,
) -> Result<MessagePlan<F>, PlanError> {
    let not_a_message = |reason: String| PlanError::NotAMessage {
        buffer: t.buffer.clone(),
        topic: t.name.clone(),
        payload: payload.to_owned(),
        reason,
    };
    let (messages, conversion) = match &t.message {
        None => {
            let shape = system
                .payload_shape(link)
                .ok_or_else(|| not_a_message("its type's shape cannot be traced".to_owned()))?;
            let made = messages(&shape, &interface.package, root_name(payload))
                .map_err(|e| not_a_message(e.to_string()))?;
            let json = serde_json::to_string(&(&shape.root, &shape.registry))
                .map_err(|e| not_a_message(format!("its shape: {e}")))?;
            (made, Conversion::Own(json))
        }
        Some(message) => {
            let fingerprint = system.payload_fingerprint(link).unwrap_or(0);
            let (traceable, messages, make) = adapter(message, fingerprint)?;
            if !traceable {
                return Err(not_a_message(format!(
                    "the shape of `{message}`'s Rust type cannot be traced"
                )));
            }
            (messages.clone(), Conversion::Adapted(make.clone()))
        }
    };
    let key = key_of(interface.domain, &t.name, &messages).map_err(not_a_message)?;
    let qos = qos_of(t.qos).ok_or_else(|| PlanError::TransientLocal {
        buffer: t.buffer.clone(),
        topic: t.name.clone(),
    })?;
    Ok(MessagePlan {
        messages,
        conversion,
        key,
        qos,
    })
}

/// The data key of `topic` carrying `messages`' root, with its hash; the
/// reason when there is none.
pub(crate) fn key_of(domain: u32, topic: &str, messages: &Messages) -> Result<TopicKey, String> {
    let name = messages.name();
    let type_name =
        TypeName::new(&name.package, Interface::Msg, &name.name).map_err(|e| e.to_string())?;
    let hash = type_hash(messages).map_err(|e| e.to_string())?;
    TopicKey::new(domain, topic, type_name, hash).map_err(|e| format!("the topic: {e}"))
}

/// A topic of the plan, published or subscribed.
#[derive(Clone, Copy)]
enum Either {
    Published(usize),
    Subscribed(usize),
}

/// `topics` and `subscriptions` with one definition per message name across
/// them all ([`one_definition_per_name`]; standard messages, through
/// adapters, keep their names first, then published topics before
/// subscribed ones), each key made again with its message's name and hash.
fn consistent(
    domain: u32,
    topics: &mut [PublishedTopic],
    subscriptions: &mut [SubscribedTopic],
) -> Result<(), PlanError> {
    let own = |e: &Either| match *e {
        Either::Published(k) => matches!(topics[k].encoder, Encoder::Own(_)),
        Either::Subscribed(k) => subscriptions[k].is_own(),
    };
    let mut order: Vec<Either> = (0..topics.len())
        .map(Either::Published)
        .chain((0..subscriptions.len()).map(Either::Subscribed))
        .collect();
    order.sort_by_key(own);
    let sets: Vec<&Messages> = order
        .iter()
        .map(|e| match *e {
            Either::Published(k) => &topics[k].messages,
            Either::Subscribed(k) => &subscriptions[k].messages,
        })
        .collect();
    let made = one_definition_per_name(&sets);
    for (e, messages) in order.into_iter().zip(made) {
        let (buffer, payload, key, slot) = match e {
            Either::Published(k) => {
                let t = &mut topics[k];
                (&t.buffer, t.payload, &mut t.key, &mut t.messages)
            }
            Either::Subscribed(k) => {
                let t = &mut subscriptions[k];
                (&t.buffer, t.payload, &mut t.key, &mut t.messages)
            }
        };
        *key = key_of(domain, key.topic(), &messages).map_err(|reason| PlanError::NotAMessage {
            buffer: buffer.clone(),
            topic: key.topic().to_owned(),
            payload: payload.to_owned(),
            reason,
        })?;
        *slot = messages;
    }
    Ok(())
}

/// The first link whose values come from output `component.peer.buffer`.
fn link_of(info: &SystemInfo, buffer: &str) -> Option<usize> {
    let (component, port) = buffer.split_once('.')?;
    let node = info.nodes.iter().position(|n| n.name == component)?;
    info.links
        .iter()
        .position(|l| l.from == node && l.from_port == port)
}

/// The wire's QoS of a spec's profile; `None` for transient local, which the
/// bridge does not provide.
pub(crate) fn qos_of(profile: QosProfile) -> Option<Qos> {
    let qos = Qos::keep_last(u64::from(profile.depth));
    let qos = match profile.reliability {
        Reliability::Reliable => qos,
        Reliability::BestEffort => qos.best_effort(),
    };
    match profile.durability {
        Durability::Volatile => Some(qos),
        Durability::TransientLocal => None,
    }
}

/// A ROS time \[s, ns\] of `ns` nanoseconds since the UNIX epoch (seconds
/// saturate at `i32::MAX`, in 2038).
pub(crate) fn ros_time(ns: u64) -> Time {
    let sec = i32::try_from(ns / 1_000_000_000).unwrap_or(i32::MAX);
    let nanosec = u32::try_from(ns % 1_000_000_000).unwrap_or(0);
    Time { sec, nanosec }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn qos_follows_the_profile() {
        let queue = QosProfile::of_link(Some(agent_core::Policy::queue(8)));
        assert_eq!(qos_of(queue), Some(Qos::keep_last(8)));
        let sample = QosProfile::of_link(Some(agent_core::Policy::Sample));
        assert_eq!(qos_of(sample), Some(Qos::keep_last(1).best_effort()));
        let late = QosProfile {
            durability: Durability::TransientLocal,
            ..queue
        };
        assert_eq!(qos_of(late), None);
    }

    #[test]
    fn ros_times_split_seconds_and_nanoseconds() {
        assert_eq!(
            ros_time(1_700_000_000_123_456_789),
            Time {
                sec: 1_700_000_000,
                nanosec: 123_456_789
            }
        );
    }
}
