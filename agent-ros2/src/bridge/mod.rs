//! The ROS 2 bridge: the buffers a spec's `ros2` section publishes become
//! topics of a ROS 2 node over rmw_zenoh, discovered by ROS 2 tools and
//! decoded by them, without blocking the nodes that send the values; the
//! topics it subscribes to feed input buffers, each value checked as a value
//! from another process is.
//!
//! # Outbound
//! 1. [`Plan::new`] reads the spec's (or a deployment's) `ros2` section
//!    against a built system: per published buffer the link whose values it
//!    takes, the fully qualified topic, the message (the one made from the
//!    buffer type in the section's package, or the standard one the spec
//!    names, made by an adapter of [`Adapters`]; across the plan one
//!    definition per message name, a helper or root that two buffer types
//!    define differently being numbered, `Item2`), its `RIHS01_` hash and the
//!    QoS (the spec's, else the link's: a queue of `n` is reliable keep-last
//!    `n`, a sample best effort keep-last 1). What cannot be published is a
//!    [`PlanError`] naming the buffer and topic, before anything runs. A
//!    process of a deployment publishes the buffers of the components it
//!    runs ([`Plan::only_components`]), under a node name of its own if
//!    wanted ([`Plan::named`]).
//! 2. [`Bridge::start`] opens a Zenoh session ([`SessionOptions`]: a client
//!    of rmw_zenohd at `tcp/localhost:7447` by default; or
//!    [`Bridge::on_session`] takes one), declares a publisher per topic and
//!    the liveliness tokens of the node and of each publisher (`MP`), and
//!    starts the publishing thread.
//! 3. The bridge is the run's [`Observer`] (the deterministic executor's; a
//!    real-time run takes [`Bridge::threads`]): each value sent into a
//!    published link is copied (its postcard bytes) into a slot of a
//!    wait-free ring and the publishing thread woken; a full ring drops the
//!    value and counts it; the node never blocks and, once the ring's buffers
//!    have grown to the values' size, never allocates.
//! 4. The publishing thread transcodes each value to CDR (the 4-byte header
//!    `00 01 00 00`, then the body): the recorder's transcoder for the
//!    buffer type's own message, or the adapter for a standard message (the
//!    stamp of its header is the bridge's epoch plus the value's instant),
//!    and puts it on the topic's key with the attachment (sequence number
//!    from 1, the wall-clock time the value was sent, the publisher's GID,
//!    the hash of its token as rmw_zenoh makes it). Every topic puts with
//!    Zenoh's blocking congestion control, best-effort ones too: only this
//!    thread waits, and a value lost is then lost in a tap's full ring,
//!    counted, not silently in Zenoh's queue (which may drop a sample of
//!    dropping congestion control when no batch is free soon enough: with
//!    it on best-effort topics, the interoperability test once lost one
//!    sample of 20 on a loaded machine).
//! 5. [`Bridge::finish`] publishes what the rings still hold, undeclares the
//!    tokens (ROS 2 tools see the node go) and publishers, closes a session
//!    it opened, each even if an earlier one fails, and returns the counts
//!    per topic ([`BridgeReport`]): published, dropped (ring full), failed
//!    to encode, refused by Zenoh; and what Zenoh refused to close.
//!
//! # Inbound
//! 1. [`Plan::new`] resolves each `subscribe` entry ([`Plan::subscriptions`])
//!    as it does a published one: the link into the input buffer
//!    `component.peer.buffer` (the input's values come from `peer` through
//!    it), the topic, the message (the buffer type's own, or the standard one
//!    the spec names, read by an adapter of [`Adapters::subscribe`], which
//!    may refuse a value), interned with the published ones, its hash and
//!    QoS. A process of a deployment feeds the inputs of the components it
//!    runs.
//! 2. The run makes the input's inbox (`RealTime::feed` on the link: a
//!    second source of the input beside the link's sender) and
//!    [`Bridge::subscribe`] takes it: it declares a Zenoh subscriber on every
//!    type of the topic (`<domain>/<topic>/*/*`) and the subscription's `MS`
//!    token. Once the run started, [`Bridge::set_inbound_zero`] gives it the
//!    run's instant zero.
//! 3. Zenoh's callback counts each sample and hands it to the bridge's
//!    inbound thread (a bounded backlog: beyond it, dropped and counted),
//!    which refuses, counting each reason, a sample on the key of another
//!    type or hash, one without rmw_zenoh's attachment or with a malformed
//!    one, and one numbered at or before its publisher's last (publishers
//!    are told apart by their GIDs; a gap in a publisher's numbering is
//!    counted as lost, and its sample taken). It decodes the CDR into the
//!    buffer type's postcard bytes (`read_cdr` by the type's shape, every
//!    length and value checked, or the adapter), refusing what does not
//!    decode, and delivers the value to the inbox as a message of the wire
//!    format between processes: the buffer type's fingerprint, the bridge's
//!    epoch, its own numbering from 1 (it is the inbox's one sender, whatever
//!    the publishers), and the instant the value arrived, since the run's
//!    instant zero. The inbox checks it as a value of another process (a
//!    value stamped too far ahead, a full queue: [`SubscriptionReport`]'s
//!    `inbox_problems`), and the node reads it without waiting.
//! 4. [`Bridge::finish`] undeclares the subscribers first and lets the
//!    thread deliver what it holds; the report counts, per subscribed topic,
//!    what was received, delivered, dropped, refused (by reason) and lost.
//!
//! A deterministic run takes no value from ROS 2: its instants are not the
//! wall clock's, so a value's arrival has no instant in it, and taking it
//! would make the run depend on when messages happen to arrive. Its caller
//! moves the subscriptions to [`Plan::unserved`] with
//! [`Plan::unserve_subscriptions`], and says so.
//!
//! In a secure deployment, the router's access control lets each process's
//! bridge subscribe to the topics that feed its components (their keys
//! `<domain>/<topic>/*/*`, every type, as the bridge subscribes) and ROS 2
//! nodes put only on those.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::SyncSender;
use std::thread::JoinHandle;
use std::time::{Duration, Instant, SystemTime, UNIX_EPOCH};

use agent_core::Inbox;
use agent_core::trace::{ErasedPayload, Observer, TransferEvent};
use zenoh::Wait;
use zenoh::qos::CongestionControl;

mod adapter;
mod inbound;
mod intern;
mod plan;
mod publish;
mod report;
mod session;
mod subscribe;
mod tap;

pub use adapter::{Adapters, TranscodeError};
pub use inbound::SubscribedTopic;
pub use plan::{Plan, PlanError, PublishedTopic, UnservedTopic};
pub use report::{BridgeReport, CloseError, SubscriptionReport, TopicReport};
pub use session::{Mode, ROUTER_ENDPOINT, SessionOptions};

use crate::wire::{EndpointKind, EntityToken, NameError, NodeToken, Zid};
use publish::Outgoing;
use subscribe::{BACKLOG, Clocks, InCounts, Inbound, Incoming};
use tap::{Counts, Shared, Tap};

/// Why a bridge did not start or finish cleanly.
#[derive(Debug, thiserror::Error)]
pub enum BridgeError {
    /// Zenoh refused a setting of the session's configuration.
    #[error("zenoh refused setting `{key}` to {value}: {reason}")]
    Setting {
        /// The configuration's key.
        key: String,
        /// The value given (JSON5).
        value: String,
        /// Zenoh's reason.
        reason: String,
    },
    /// The session did not open (as a client: no router at the endpoints).
    #[error("the bridge's Zenoh session (connecting to {endpoints}) did not open: {reason}")]
    Session {
        /// The endpoints it connects to.
        endpoints: String,
        /// Zenoh's reason.
        reason: String,
    },
    /// The node's or a topic's token has a name ROS 2 refuses.
    #[error("a liveliness token: {0}")]
    Name(#[from] NameError),
    /// Zenoh refused to declare a publisher or a token (what it refuses when
    /// the bridge finishes is a [`CloseError`] in the report).
    #[error("zenoh refused {what}: {reason}")]
    Declare {
        /// What was declared.
        what: String,
        /// Zenoh's reason.
        reason: String,
    },
    /// The publishing thread did not start.
    #[error("the bridge's publishing thread did not start: {0}")]
    Thread(#[from] std::io::Error),
    /// The publishing thread panicked (a bug); the counts of the values it
    /// was publishing then are lost.
    #[error("the bridge's publishing thread panicked")]
    Panicked,
    /// The inbound thread panicked (a bug): no subscribed topic is fed.
    #[error("the bridge's inbound thread panicked")]
    InboundPanicked,
    /// [`Bridge::subscribe`] was given an index the plan has no
    /// subscription of.
    #[error("the plan subscribes to {count} topics: there is no subscription {index}")]
    NoSubscription {
        /// The index given.
        index: usize,
        /// The plan's subscriptions.
        count: usize,
    },
    /// [`Bridge::subscribe`] was called twice for one topic.
    #[error("topic `{topic}` is subscribed already")]
    Subscribed {
        /// The fully qualified topic.
        topic: String,
    },
    /// [`Bridge::subscribe`] was given an inbox of another type than the
    /// subscribed buffer's (its fingerprint differs): every value would be
    /// refused.
    #[error(
        "the inbox `{inbox}` given for topic `{topic}` (buffer `{buffer}`) does not take values of the buffer's type `{payload}`"
    )]
    WrongInbox {
        /// The buffer.
        buffer: String,
        /// The fully qualified topic.
        topic: String,
        /// The buffer's Rust type.
        payload: String,
        /// The inbox's key.
        inbox: String,
    },
}

/// How a bridge runs.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct BridgeOptions {
    /// The session it opens ([`Bridge::start`]).
    pub session: SessionOptions,
    /// The slots of each tap's ring: how many values the publishing thread
    /// may fall behind by, per executor thread, before values are dropped
    /// (or, with [`BridgeOptions::wait_when_full`], waited for).
    pub slots: usize,
    /// With a full ring, wait for the publishing thread to free a slot, for
    /// at most this long per value, instead of dropping the value at once:
    /// for a run that is not real time (the deterministic executor, which
    /// goes faster than the wall clock and may wait), so that it loses no
    /// value. `None` (the default, for real-time runs): never wait.
    pub wait_when_full: Option<std::time::Duration>,
    /// The wall-clock time of the run's instant zero, for the stamps of
    /// standard messages' headers, and for the instants of the values taken
    /// from ROS 2 (when each arrived, after it); default when the bridge
    /// starts.
    pub epoch: Option<SystemTime>,
}

impl Default for BridgeOptions {
    fn default() -> Self {
        Self {
            session: SessionOptions::default(),
            slots: 256,
            wait_when_full: None,
            epoch: None,
        }
    }
}

/// Node and entity ids, unique in the process (so in any session of it).
static NEXT_ID: AtomicU64 = AtomicU64::new(0);

fn next_id() -> u64 {
    NEXT_ID.fetch_add(1, Ordering::Relaxed)
}

/// A running bridge (see the module's documentation): an [`Observer`] of the
/// run whose published values it puts on ROS 2 topics, and the feeder of the
/// inputs its subscribed topics feed ([`Bridge::subscribe`]).
pub struct Bridge {
    plan: Plan,
    shared: Arc<Shared>,
    tap: Tap,
    thread: Option<JoinHandle<()>>,
    node: NodeToken,
    entities: Vec<EntityToken>,
    tokens: Vec<zenoh::liveliness::LivelinessToken>,
    publishers: Vec<Arc<zenoh::pubsub::Publisher<'static>>>,
    session: zenoh::Session,
    /// Whether the bridge opened the session (and closes it).
    owns_session: bool,
    /// The subscribed side.
    inlet: Inlet,
}

/// The subscribed side of a bridge.
struct Inlet {
    /// The wall clock of the run's instant zero \[ns since the UNIX
    /// epoch\], for the instants of the values taken.
    zero: Arc<AtomicU64>,
    /// To the inbound thread (Zenoh's callbacks hold clones).
    to_thread: SyncSender<Inbound>,
    /// The inbound thread; `None` when the plan subscribes to nothing, or
    /// once it ended.
    thread: Option<JoinHandle<()>>,
    /// The counts, per subscription.
    counts: Arc<[InCounts]>,
    /// The inbox each subscription feeds, once subscribed.
    inboxes: Vec<Option<Arc<Inbox>>>,
    /// The subscriptions' liveliness tokens, in the order subscribed.
    entities: Vec<EntityToken>,
    tokens: Vec<zenoh::liveliness::LivelinessToken>,
    subscribers: Vec<zenoh::pubsub::Subscriber<()>>,
}

impl std::fmt::Debug for Bridge {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bridge")
            .field("node", &self.node.key_expr())
            .field("topics", &self.plan.topics)
            .field("subscriptions", &self.plan.subscriptions)
            .finish()
    }
}

impl Bridge {
    /// Start publishing `plan` on a session opened as `options` say.
    pub fn start(plan: Plan, options: BridgeOptions) -> Result<Bridge, BridgeError> {
        let session = options.session.open()?;
        Self::begin(plan, session, true, &options)
    }

    /// Start publishing `plan` on `session` (left open at the end).
    pub fn on_session(
        plan: Plan,
        session: zenoh::Session,
        options: &BridgeOptions,
    ) -> Result<Bridge, BridgeError> {
        Self::begin(plan, session, false, options)
    }

    fn begin(
        plan: Plan,
        session: zenoh::Session,
        owns_session: bool,
        options: &BridgeOptions,
    ) -> Result<Bridge, BridgeError> {
        let zid = Zid::from_le_bytes(session.zid().to_le_bytes());
        let node = NodeToken::new(plan.domain, zid, next_id(), &plan.namespace, &plan.node)?;
        let mut entities = Vec::with_capacity(plan.topics.len());
        let mut publishers = Vec::with_capacity(plan.topics.len());
        let mut outgoing = Vec::with_capacity(plan.topics.len());
        for topic in &plan.topics {
            let key = topic.key.clone();
            let entity = EntityToken::new(
                node.clone(),
                next_id(),
                EndpointKind::Publisher,
                key.topic(),
                key.type_name().clone(),
                *key.type_hash(),
                topic.qos,
            )?;
            let publisher = session
                .declare_publisher(key.to_string())
                .congestion_control(CongestionControl::Block)
                .express(true)
                .wait()
                .map_err(|e| BridgeError::Declare {
                    what: format!("the publisher of `{key}`"),
                    reason: e.to_string(),
                })?;
            let publisher = Arc::new(publisher);
            outgoing.push(Outgoing {
                publisher: publisher.clone(),
                gid: entity.gid(),
                encoder: topic.encoder.clone(),
                sequence: 0,
                scratch: Vec::new(),
            });
            publishers.push(publisher);
            entities.push(entity);
        }
        let tokens = declare_tokens(&session, &node, &entities)?;
        let shared = Arc::new(shared_of(&plan, options.slots, options.wait_when_full));
        let epoch = options.epoch.unwrap_or_else(SystemTime::now);
        let epoch_ns = epoch
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        let theirs = shared.clone();
        let thread = std::thread::Builder::new()
            .name("ros2-out".into())
            .spawn(move || publish::run(&theirs, outgoing, epoch_ns))?;
        let tap = Tap::new(shared.clone(), thread.thread().clone());
        let inlet = Inlet::start(&plan, epoch_ns)?;
        Ok(Bridge {
            plan,
            shared,
            tap,
            thread: Some(thread),
            node,
            entities,
            tokens,
            publishers,
            session,
            owns_session,
            inlet,
        })
    }

    /// Feed `inbox` (the input buffer's, from `RealTime::feed` on the
    /// subscription's link) from the plan's subscription `index`: announce
    /// the subscription (its `MS` token, with its QoS) and take every
    /// sample put on the topic, by any publisher, of the plan's type and
    /// hash, checked and decoded, into the inbox as the one sender of its
    /// values (see the module's documentation). Call it after the bridge
    /// starts and before the run does. An inbox of another type than the
    /// buffer's, an unknown index and a topic subscribed already are
    /// refused.
    pub fn subscribe(&mut self, index: usize, inbox: Arc<Inbox>) -> Result<(), BridgeError> {
        let count = self.plan.subscriptions.len();
        let topic = self
            .plan
            .subscriptions
            .get(index)
            .ok_or(BridgeError::NoSubscription { index, count })?;
        let key = &topic.key;
        if self.inlet.inboxes.get(index).is_some_and(Option::is_some) {
            return Err(BridgeError::Subscribed {
                topic: key.topic().to_owned(),
            });
        }
        if inbox.fingerprint() != topic.fingerprint {
            return Err(BridgeError::WrongInbox {
                buffer: topic.buffer.clone(),
                topic: key.topic().to_owned(),
                payload: topic.payload.to_owned(),
                inbox: inbox.key().to_owned(),
            });
        }
        let entity = EntityToken::new(
            self.node.clone(),
            next_id(),
            EndpointKind::Subscription,
            key.topic(),
            key.type_name().clone(),
            *key.type_hash(),
            topic.qos,
        )?;
        // Before the subscriber: the thread knows the inbox before any sample.
        self.inlet
            .to_thread
            .send(Inbound::Subscribe {
                index,
                inbox: inbox.clone(),
            })
            .map_err(|_| BridgeError::InboundPanicked)?;
        // Every type on the topic: another type or hash is counted, not unseen.
        let every_type = format!(
            "{}/{}/*/*",
            key.domain(),
            key.topic().trim_start_matches('/')
        );
        let callback = subscribe::callback(
            index,
            self.inlet.to_thread.clone(),
            self.inlet.counts.clone(),
        );
        let subscriber = self
            .session
            .declare_subscriber(every_type.clone())
            .callback(callback)
            .wait()
            .map_err(|e| BridgeError::Declare {
                what: format!("the subscriber of `{every_type}`"),
                reason: e.to_string(),
            })?;
        let token = declare_token(&self.session, entity.key_expr())?;
        self.inlet.subscribers.push(subscriber);
        self.inlet.tokens.push(token);
        self.inlet.entities.push(entity);
        if let Some(slot) = self.inlet.inboxes.get_mut(index) {
            *slot = Some(inbox);
        }
        Ok(())
    }

    /// What the bridge publishes.
    pub fn plan(&self) -> &Plan {
        &self.plan
    }

    /// The node's liveliness token.
    pub fn node_token(&self) -> &NodeToken {
        &self.node
    }

    /// The publishers' liveliness tokens, in the plan's order.
    pub fn publisher_tokens(&self) -> &[EntityToken] {
        &self.entities
    }

    /// Count the instants of the values taken from ROS 2 from `zero`, the
    /// wall-clock time of the run's instant zero (`Running::zero` once a
    /// real-time run started: the run fixes it when it starts, after the
    /// bridge subscribed); until then they count from
    /// [`BridgeOptions::epoch`]. A value's instant is when it arrived: an
    /// input's reads take it at their first activation at or after it. The
    /// stamps of published standard messages keep counting from
    /// [`BridgeOptions::epoch`].
    pub fn set_inbound_zero(&self, zero: SystemTime) {
        let ns = zero
            .duration_since(UNIX_EPOCH)
            .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
        self.inlet.zero.store(ns, Ordering::Relaxed);
    }

    /// The subscriptions' liveliness tokens, in the order subscribed.
    pub fn subscription_tokens(&self) -> &[EntityToken] {
        &self.inlet.entities
    }

    /// The observers of a real-time run, one per thread, for
    /// `RealTime::observe`: each hands its thread's values to this bridge's
    /// publishing thread through rings of its own. Finish the bridge after
    /// the run's `join`.
    pub fn threads(&self) -> impl FnMut(&str, &[usize]) -> Box<dyn Observer> + Send + 'static {
        let shared = self.shared.clone();
        let thread = self.thread.as_ref().map(|t| t.thread().clone());
        move |_thread: &str, _nodes: &[usize]| -> Box<dyn Observer> {
            match &thread {
                Some(t) => Box::new(Tap::new(shared.clone(), t.clone())),
                None => Box::new(agent_core::NoObserver),
            }
        }
    }

    /// Wait until every topic has a subscriber in the Zenoh network (a ROS 2
    /// node's, or any other's), for at most `timeout`; whether all have.
    /// Samples put before a subscriber is known are not delivered to it.
    pub fn wait_for_subscribers(&self, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        loop {
            let all = self.publishers.iter().all(|p| {
                p.matching_status()
                    .wait()
                    .is_ok_and(|status| status.matching())
            });
            if all {
                return true;
            }
            if Instant::now() >= deadline {
                return false;
            }
            std::thread::sleep(Duration::from_millis(10));
        }
    }

    /// The counts so far.
    pub fn report(&self) -> BridgeReport {
        BridgeReport::of(
            &self.plan,
            &self.shared.counts,
            &self.inlet.counts,
            &self.inlet.inboxes,
        )
    }

    /// Stop taking values from ROS 2 (undeclare the subscribers, let the
    /// inbound thread deliver what it holds), publish what the rings still
    /// hold (values sent after this call are not published), undeclare the
    /// tokens and publishers, close the session if the bridge opened it, and
    /// say what was published and received. Each of these steps is taken
    /// even when an earlier one fails; what Zenoh refused is in the report's
    /// [`BridgeReport::close_errors`]. An error only when the publishing or
    /// the inbound thread panicked (the tokens and session are closed all
    /// the same).
    pub fn finish(mut self) -> Result<BridgeReport, BridgeError> {
        let mut close_errors = Vec::new();
        for subscriber in std::mem::take(&mut self.inlet.subscribers) {
            let key = subscriber.key_expr().to_string();
            if let Err(e) = subscriber.undeclare().wait() {
                close_errors.push(CloseError::Subscriber {
                    key,
                    reason: e.to_string(),
                });
            }
        }
        let inbound = self.inlet.stop();
        let stopped = self.stop();
        let mut report = self.report();
        report.close_errors = close_errors;
        let keys = std::iter::once(self.node.key_expr())
            .chain(self.entities.iter().map(EntityToken::key_expr))
            .chain(self.inlet.entities.iter().map(EntityToken::key_expr))
            .collect::<Vec<_>>();
        let mut tokens = std::mem::take(&mut self.tokens);
        tokens.append(&mut self.inlet.tokens);
        for (token, key) in tokens.into_iter().zip(keys).rev() {
            if let Err(e) = token.undeclare().wait() {
                report.close_errors.push(CloseError::Token {
                    key,
                    reason: e.to_string(),
                });
            }
        }
        for publisher in std::mem::take(&mut self.publishers) {
            // The publishing thread has ended, so the bridge holds the last
            // reference; otherwise dropping it undeclares it.
            let Ok(publisher) = Arc::try_unwrap(publisher) else {
                continue;
            };
            let key = publisher.key_expr().to_string();
            if let Err(e) = publisher.undeclare().wait() {
                report.close_errors.push(CloseError::Publisher {
                    key,
                    reason: e.to_string(),
                });
            }
        }
        if self.owns_session
            && let Err(e) = self.session.close().wait()
        {
            report.close_errors.push(CloseError::Session {
                reason: e.to_string(),
            });
        }
        stopped.and(inbound).map(|()| report)
    }

    /// End the publishing thread after its last drain.
    fn stop(&mut self) -> Result<(), BridgeError> {
        self.shared.stop.store(true, Ordering::Release);
        let Some(thread) = self.thread.take() else {
            return Ok(());
        };
        thread.thread().unpark();
        thread.join().map_err(|_| BridgeError::Panicked)
    }
}

/// The node's token, then each publisher's, declared.
fn declare_tokens(
    session: &zenoh::Session,
    node: &NodeToken,
    entities: &[EntityToken],
) -> Result<Vec<zenoh::liveliness::LivelinessToken>, BridgeError> {
    let keys = std::iter::once(node.key_expr()).chain(entities.iter().map(EntityToken::key_expr));
    keys.map(|key| declare_token(session, key)).collect()
}

/// The liveliness token `key`, declared.
fn declare_token(
    session: &zenoh::Session,
    key: String,
) -> Result<zenoh::liveliness::LivelinessToken, BridgeError> {
    session
        .liveliness()
        .declare_token(key.clone())
        .wait()
        .map_err(|e| BridgeError::Declare {
            what: format!("the liveliness token `{key}`"),
            reason: e.to_string(),
        })
}

impl Inlet {
    /// The inbound side of `plan`: its thread started if the plan subscribes
    /// to anything; the instants of the values taken count from `zero_ns`
    /// (until [`Bridge::set_inbound_zero`])
    /// \[ns since the UNIX epoch\].
    fn start(plan: &Plan, zero_ns: u64) -> Result<Inlet, BridgeError> {
        let zero = Arc::new(AtomicU64::new(zero_ns));
        let (to_thread, from_callbacks) = std::sync::mpsc::sync_channel(BACKLOG);
        let counts: Arc<[InCounts]> = plan
            .subscriptions
            .iter()
            .map(|_| InCounts::default())
            .collect();
        let thread = if plan.subscriptions.is_empty() {
            None
        } else {
            let incoming: Vec<Incoming> = plan
                .subscriptions
                .iter()
                .map(|t| Incoming {
                    key: t.key.to_string(),
                    decoder: t.decoder.clone(),
                    fingerprint: t.fingerprint,
                })
                .collect();
            let clocks = Clocks {
                zero_ns: zero.clone(),
                epoch: agent_core::link::remote::new_epoch(),
            };
            let theirs = counts.clone();
            Some(
                std::thread::Builder::new()
                    .name("ros2-in".into())
                    .spawn(move || subscribe::run(&from_callbacks, incoming, &theirs, clocks))?,
            )
        };
        Ok(Inlet {
            zero,
            to_thread,
            thread,
            counts,
            inboxes: vec![None; plan.subscriptions.len()],
            entities: Vec::new(),
            tokens: Vec::new(),
            subscribers: Vec::new(),
        })
    }

    /// End the inbound thread after what it holds (call once the
    /// subscribers are undeclared).
    fn stop(&mut self) -> Result<(), BridgeError> {
        let Some(thread) = self.thread.take() else {
            return Ok(());
        };
        // A thread that ended already (it panicked) has dropped its receiver.
        let _ = self.to_thread.send(Inbound::Stop);
        thread.join().map_err(|_| BridgeError::InboundPanicked)
    }
}

/// What the taps and the publishing thread of `plan` share.
fn shared_of(plan: &Plan, slots: usize, wait: Option<Duration>) -> Shared {
    let links = plan.topics.iter().map(|t| t.link + 1).max().unwrap_or(0);
    let mut by_link = vec![Vec::new(); links];
    for (k, topic) in plan.topics.iter().enumerate() {
        by_link[topic.link].push(k);
    }
    Shared {
        by_link,
        counts: plan.topics.iter().map(|_| Counts::default()).collect(),
        new: std::sync::Mutex::new(Vec::new()),
        stop: std::sync::atomic::AtomicBool::new(false),
        slots,
        wait,
    }
}

impl Observer for Bridge {
    fn transfer(&mut self, event: &TransferEvent, value: &dyn ErasedPayload) {
        self.tap.transfer(event, value);
    }
}

impl Drop for Bridge {
    fn drop(&mut self) {
        // Not finished: end the threads; the tokens, publishers and
        // subscribers undeclare themselves when dropped.
        self.inlet.subscribers.clear();
        let _ = self.inlet.stop();
        let _ = self.stop();
    }
}
