//! What a bridge did, per topic: the counts a run's end reports.

use std::sync::atomic::Ordering;

use super::plan::Plan;
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
    /// Per topic.
    pub topics: Vec<TopicReport>,
    /// What Zenoh refused when the bridge finished, in the order tried
    /// (tokens, publishers, session); empty before and after a clean finish.
    pub close_errors: Vec<CloseError>,
}

impl BridgeReport {
    pub(crate) fn of(plan: &Plan, counts: &[Counts]) -> Self {
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
            close_errors: Vec::new(),
        }
    }

    /// Values published, over every topic.
    pub fn published(&self) -> u64 {
        self.topics.iter().map(|t| t.published).sum()
    }

    /// Values dropped by full rings, over every topic.
    pub fn dropped(&self) -> u64 {
        self.topics.iter().map(|t| t.dropped).sum()
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
}
