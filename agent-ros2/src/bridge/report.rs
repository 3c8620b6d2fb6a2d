//! What a bridge did, per topic: the counts a run's end reports.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, PoisonError};

use agent_core::Inbox;

use super::plan::Plan;
use super::subscribe::InCounts;
use super::tap::Counts;

/// One topic's counts.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TopicReport {
    /// The buffer.
    pub buffer: String,
    /// The fully qualified topic.
    pub topic: String,
    /// Values put on the topic's key.
    pub published: u64,
    /// Values dropped because the tap's ring was full (the publishing
    /// thread a whole ring behind).
    pub dropped: u64,
    /// Values that did not encode (postcard on the node's thread, CDR on the
    /// publishing thread): a bug in a type's serde form or an adapter.
    pub encode_failures: u64,
    /// Values Zenoh refused to put (the session closed under the bridge).
    pub put_failures: u64,
}

/// One subscribed topic's counts. Every sample received is delivered,
/// dropped, or refused for one reason: `received = delivered + dropped +
/// refused()`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SubscriptionReport {
    /// The input buffer fed.
    pub buffer: String,
    /// The fully qualified topic.
    pub topic: String,
    /// Whether the bridge was given the input's inbox
    /// ([`Bridge::subscribe`](super::Bridge::subscribe)): if not, nothing
    /// was taken from the topic.
    pub subscribed: bool,
    /// Samples on the topic's key (of any type) the subscriber got.
    pub received: u64,
    /// Values delivered to the input's inbox (which checks them as values
    /// from another process: see [`SubscriptionReport::inbox_problems`]).
    pub delivered: u64,
    /// Samples dropped because the bridge's inbound thread was a whole
    /// backlog behind.
    pub dropped: u64,
    /// Samples of another type or type hash than the plan's, refused.
    pub wrong_type: u64,
    /// Samples without rmw_zenoh's attachment or with a malformed one,
    /// refused.
    pub bad_attachment: u64,
    /// Samples numbered at or before their publisher's last one taken (a
    /// repeat, or out of order), refused.
    pub duplicate: u64,
    /// Samples whose CDR is not a message of the topic's type, refused.
    pub undecodable: u64,
    /// Messages an adapter refused (a value the buffer must not take).
    pub rejected: u64,
    /// Samples a publisher numbered and the bridge never received (the gaps
    /// in each publisher's sequence numbers, from the first of its samples
    /// received), counted, not refused.
    pub lost: u64,
    /// The problems the inbox met (values it refused, such as one stamped
    /// too far ahead or one past a full queue), as `Inbox::problem_count`
    /// says.
    pub inbox_problems: u64,
    /// Why the last refused sample was refused, if any was.
    pub last_refusal: Option<String>,
}

impl SubscriptionReport {
    /// Samples refused, for every reason.
    pub fn refused(&self) -> u64 {
        self.wrong_type + self.bad_attachment + self.duplicate + self.undecodable + self.rejected
    }
}

/// What Zenoh refused when the bridge finished: ROS 2 tools may still see
/// the node or a publisher until its token's session ends.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum CloseError {
    /// Undeclaring a liveliness token.
    #[error("zenoh refused to undeclare the liveliness token `{key}`: {reason}")]
    Token {
        /// The token's key expression.
        key: String,
        /// Zenoh's reason.
        reason: String,
    },
    /// Undeclaring a subscribed topic's subscriber.
    #[error("zenoh refused to undeclare the subscriber of `{key}`: {reason}")]
    Subscriber {
        /// The key expression it subscribed to.
        key: String,
        /// Zenoh's reason.
        reason: String,
    },
    /// Undeclaring a topic's publisher.
    #[error("zenoh refused to undeclare the publisher of `{key}`: {reason}")]
    Publisher {
        /// The topic's key expression.
        key: String,
        /// Zenoh's reason.
        reason: String,
    },
    /// Closing the session the bridge opened.
    #[error("zenoh refused to close the bridge's session: {reason}")]
    Session {
        /// Zenoh's reason.
        reason: String,
    },
}

/// Every topic's counts, in the plan's order, and what did not close.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct BridgeReport {
    /// Per published topic.
    pub topics: Vec<TopicReport>,
    /// Per subscribed topic.
    pub subscriptions: Vec<SubscriptionReport>,
    /// What Zenoh refused when the bridge finished, in the order tried
    /// (subscribers, tokens, publishers, session); empty before and after a
    /// clean finish.
    pub close_errors: Vec<CloseError>,
}

impl BridgeReport {
    pub(crate) fn of(
        plan: &Plan,
        counts: &[Counts],
        in_counts: &[InCounts],
        inboxes: &[Option<Arc<Inbox>>],
    ) -> Self {
        let n = |count: &AtomicU64| count.load(Ordering::Relaxed);
        let subscriptions = plan
            .subscriptions
            .iter()
            .zip(in_counts)
            .zip(inboxes)
            .map(|((t, c), inbox)| SubscriptionReport {
                buffer: t.buffer.clone(),
                topic: t.key.topic().to_owned(),
                subscribed: inbox.is_some(),
                received: n(&c.received),
                delivered: n(&c.delivered),
                dropped: n(&c.dropped),
                wrong_type: n(&c.wrong_type),
                bad_attachment: n(&c.bad_attachment),
                duplicate: n(&c.duplicate),
                undecodable: n(&c.undecodable),
                rejected: n(&c.rejected),
                lost: n(&c.lost),
                inbox_problems: inbox.as_ref().map_or(0, |i| i.problem_count()),
                last_refusal: c
                    .last_refusal
                    .lock()
                    .unwrap_or_else(PoisonError::into_inner)
                    .clone(),
            })
            .collect();
        let topics = plan
            .topics
            .iter()
            .zip(counts)
            .map(|(t, c)| TopicReport {
                buffer: t.buffer.clone(),
                topic: t.key.topic().to_owned(),
                published: c.published.load(Ordering::Relaxed),
                dropped: c.dropped.load(Ordering::Relaxed),
                encode_failures: c.encode_failures.load(Ordering::Relaxed),
                put_failures: c.put_failures.load(Ordering::Relaxed),
            })
            .collect();
        Self {
            topics,
            subscriptions,
            close_errors: Vec::new(),
        }
    }

    /// Values published, over every topic.
    pub fn published(&self) -> u64 {
        self.topics.iter().map(|t| t.published).sum()
    }

    /// Values dropped, over every topic: by full rings on their way out,
    /// by a full backlog on their way in.
    pub fn dropped(&self) -> u64 {
        let inbound: u64 = self.subscriptions.iter().map(|t| t.dropped).sum();
        self.topics.iter().map(|t| t.dropped).sum::<u64>() + inbound
    }

    /// Samples received on subscribed topics.
    pub fn received(&self) -> u64 {
        self.subscriptions.iter().map(|t| t.received).sum()
    }

    /// Values delivered to the inputs' inboxes.
    pub fn delivered(&self) -> u64 {
        self.subscriptions.iter().map(|t| t.delivered).sum()
    }

    /// Samples refused on subscribed topics, for every reason.
    pub fn refused(&self) -> u64 {
        self.subscriptions
            .iter()
            .map(SubscriptionReport::refused)
            .sum()
    }

    /// Samples lost on subscribed topics (gaps in their publishers'
    /// numbering).
    pub fn lost(&self) -> u64 {
        self.subscriptions.iter().map(|t| t.lost).sum()
    }

    /// Values that failed to encode, over every topic.
    pub fn encode_failures(&self) -> u64 {
        self.topics.iter().map(|t| t.encode_failures).sum()
    }

    /// Values Zenoh refused, over every topic.
    pub fn put_failures(&self) -> u64 {
        self.topics.iter().map(|t| t.put_failures).sum()
    }

    /// The counts of `topic` (fully qualified), if published.
    pub fn topic(&self, topic: &str) -> Option<&TopicReport> {
        self.topics.iter().find(|t| t.topic == topic)
    }

    /// The counts of `topic` (fully qualified), if subscribed.
    pub fn subscription(&self, topic: &str) -> Option<&SubscriptionReport> {
        self.subscriptions.iter().find(|t| t.topic == topic)
    }
}
