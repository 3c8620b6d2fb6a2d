//! agent-core's byte transport over a Zenoh session.

use std::collections::HashMap;
use std::sync::{Arc, Mutex, PoisonError};

use agent_core::{Inbox, Policy, Publisher, Transport, TransportError};
use zenoh::Wait;
use zenoh::qos::CongestionControl;

/// Publishers and subscribers of one process's links, on its session.
///
/// Sample links publish with `CongestionControl::Drop` (under congestion the
/// latest value matters, and the receiver keeps only it); queue links with
/// `Block` (never dropped by Zenoh; Zenoh's TCP links are reliable, and the
/// receiver checks the sequence anyway). Both are `express` (not batched): a
/// control loop wants each value at once.
pub struct ZenohTransport {
    session: zenoh::Session,
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
            by_sender: Arc::default(),
            prefix: prefix.into(),
        }
    }

    /// The inboxes fed by each sending component (shared with the member that
    /// watches the other processes).
    pub(crate) fn senders(&self) -> Arc<Mutex<HashMap<String, Vec<Arc<Inbox>>>>> {
        self.by_sender.clone()
    }

    /// The component that sends on `key`: `<prefix>/<agent>/<component>/...`.
    fn sender_of<'k>(&self, key: &'k str) -> Option<&'k str> {
        let rest = key.strip_prefix(self.prefix.as_str())?.strip_prefix('/')?;
        rest.split('/').nth(1)
    }
}

struct ZenohPublisher {
    publisher: zenoh::pubsub::Publisher<'static>,
}

impl Publisher for ZenohPublisher {
    fn put(&mut self, message: &[u8]) -> Result<(), TransportError> {
        self.publisher
            .put(message.to_vec())
            .wait()
            .map_err(|e| TransportError(e.to_string()))
    }
}

impl Transport for ZenohTransport {
    fn publisher(
        &mut self,
        key: &str,
        policy: Policy,
    ) -> Result<Box<dyn Publisher>, TransportError> {
        let congestion = match policy {
            Policy::Queue { .. } => CongestionControl::Block,
            Policy::Sample => CongestionControl::Drop,
        };
        let publisher = self
            .session
            .declare_publisher(key.to_owned())
            .congestion_control(congestion)
            .express(true)
            .wait()
            .map_err(|e| TransportError(e.to_string()))?;
        Ok(Box::new(ZenohPublisher { publisher }))
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
