//! agent-core's byte transport over a Zenoh session.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, PoisonError};

use agent_core::{Inbox, Policy, Publisher, Transport, TransportError};
use zenoh::Wait;
use zenoh::qos::CongestionControl;

use crate::outbox::{Outbox, Sink, WhenFull};

/// The inboxes of the links into this process, by receiving component.
pub(crate) type Senders = Arc<Mutex<HashMap<String, Vec<Arc<Inbox>>>>>;

/// Publishers and subscribers of one process's links, on its session.
///
/// Sample links publish with `CongestionControl::Drop` (under congestion the
/// latest value matters, and the receiver keeps only it); queue links with
/// `Block` (never dropped by Zenoh; Zenoh's TCP links are reliable, and the
/// receiver checks the sequence anyway). Both are `express` (not batched): a
/// control loop wants each value at once.
///
/// A node's `put` never enters Zenoh: it hands the message to a wait-free ring
/// that the transport's publishing thread (`zenoh-out`) drains into Zenoh, so a
/// real-time node never blocks on Zenoh's locks or congestion (see
/// [`ZenohTransport::dropped`] for what a full ring does). The thread outlives
/// the transport while publishers made by it live; [`ZenohTransport::flush`]
/// waits until what they put is in Zenoh's hands (before closing the session).
pub struct ZenohTransport {
    session: zenoh::Session,
    outbox: Arc<Outbox>,
    /// The inboxes fed by each sending component, to tell them when it vanishes.
    by_sender: Arc<Mutex<HashMap<String, Vec<Arc<Inbox>>>>>,
    prefix: String,
}

impl std::fmt::Debug for ZenohTransport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("ZenohTransport")
            .field("prefix", &self.prefix)
            .finish()
    }
}

impl ZenohTransport {
    /// A transport on `session` for the links under `prefix` (the system's name).
    pub fn new(session: zenoh::Session, prefix: impl Into<String>) -> Self {
        ZenohTransport {
            session,
            outbox: Arc::new(Outbox::new("zenoh-out")),
            by_sender: Arc::default(),
            prefix: prefix.into(),
        }
    }

    /// The inboxes fed by each sending component (shared with the member that
    /// watches the other processes).
    pub(crate) fn senders(&self) -> Senders {
        self.by_sender.clone()
    }

    /// The component that sends on `key`: `<prefix>/<agent>/<component>/...`.
    fn sender_of<'k>(&self, key: &'k str) -> Option<&'k str> {
        let rest = key.strip_prefix(self.prefix.as_str())?.strip_prefix('/')?;
        rest.split('/').nth(1)
    }

    /// Sample messages dropped because the publishing thread was behind on
    /// their link by 1024 messages or 10 MB (as Zenoh's own congestion control
    /// drops them); a queue link's message is refused with an error instead,
    /// 1024 messages behind.
    pub fn dropped(&self) -> u64 {
        self.outbox.dropped()
    }

    /// Wait until every message put so far on this transport's publishers is
    /// in Zenoh's hands, for at most `timeout`; whether it is.
    pub fn flush(&self, timeout: std::time::Duration) -> bool {
        self.outbox.flush(timeout)
    }

    /// The outbox, for the member that closes the session after the run.
    pub(crate) fn outbox(&self) -> Arc<Outbox> {
        self.outbox.clone()
    }
}

impl Sink for zenoh::pubsub::Publisher<'static> {
    fn send(&mut self, message: Vec<u8>) -> Result<(), String> {
        self.put(message).wait().map_err(|e| e.to_string())
    }
}

impl Transport for ZenohTransport {
    fn publisher(
        &mut self,
        key: &str,
        policy: Policy,
    ) -> Result<Box<dyn Publisher>, TransportError> {
        let (congestion, when_full) = match policy {
            Policy::Queue { .. } => (CongestionControl::Block, WhenFull::Refuse),
            Policy::Sample => (CongestionControl::Drop, WhenFull::Drop),
        };
        let publisher = self
            .session
            .declare_publisher(key.to_owned())
            .congestion_control(congestion)
            .express(true)
            .wait()
            .map_err(|e| TransportError(e.to_string()))?;
        let publisher = self
            .outbox
            .publisher(Box::new(publisher), when_full)
            .map_err(|e| TransportError(format!("starting the publishing thread: {e}")))?;
        Ok(Box::new(publisher))
    }

    fn subscribe(
        &mut self,
        key: &str,
        inbox: Arc<Inbox>,
    ) -> Result<Box<dyn std::any::Any + Send>, TransportError> {
        if let Some(sender) = self.sender_of(key) {
            self.by_sender
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .entry(sender.to_owned())
                .or_default()
                .push(inbox.clone());
        }
        let subscriber = self
            .session
            .declare_subscriber(key.to_owned())
            .callback(move |sample| inbox.deliver(&sample.payload().to_bytes()))
            .wait()
            .map_err(|e| TransportError(e.to_string()))?;
        Ok(Box::new(subscriber))
    }
}
