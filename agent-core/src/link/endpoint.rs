//! The two ends of a link outside an executor: for code that runs its own
//! threads (a camera's acquisition thread, a bridge to other middleware, a
//! monitor, a benchmark) and still wants the link semantics (sample: latest
//! value; queue: lossless, bounded, in order, overflow an error) and the wire
//! format between processes.
//!
//! ```
//! use agent_core::link::endpoint;
//! use agent_core::{Policy, Stamp, Time};
//! let (mut tx, mut rx) = endpoint::between_threads::<u32>(Policy::queue(2));
//! let t = std::thread::spawn(move || {
//!     for i in 0..2 {
//!         tx.send(i, Stamp::new(i as u64, Time::ZERO)).unwrap();
//!     }
//! });
//! t.join().unwrap();
//! assert_eq!(rx.recv().unwrap(), Some(&0));
//! assert_eq!(rx.recv().unwrap(), Some(&1));
//! assert_eq!(rx.recv().unwrap(), None);
//! ```

use std::sync::Arc;

use crate::buffer::{In, Payload};
use crate::error::{LinkError, RemoteProblem};
use crate::kinds::Policy;
use crate::time::{Stamp, Time};

use super::Cause;
use super::LinkStats;
use super::remote::{self, Inbox, RemoteRx, RemoteTx, Transport, TransportError};
use super::thread::{self, SharedStats, ThreadRx, ThreadTx};

/// The sending end of a link.
pub struct Sender<T: Payload> {
    tx: ThreadTx<T>,
    value: Option<T>,
    name: String,
    stats: Arc<SharedStats>,
}

/// The receiving end of a link.
pub struct Receiver<T: Payload> {
    rx: ThreadRx<T>,
    buffer: In<T>,
    name: String,
    stats: Arc<SharedStats>,
    _subscription: Option<Box<dyn std::any::Any + Send>>,
}

impl<T: Payload> std::fmt::Debug for Sender<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Sender({})", self.name)
    }
}

impl<T: Payload> std::fmt::Debug for Receiver<T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Receiver({})", self.name)
    }
}

/// A link between two threads of this process (wait-free: a triple buffer for
/// a sample link, a ring for a queue).
pub fn between_threads<T: Payload>(policy: Policy) -> (Sender<T>, Receiver<T>) {
    let (tx, rx, stats) = thread::channel::<T>(policy);
    (
        Sender {
            tx,
            value: None,
            name: "thread link".into(),
            stats: stats.clone(),
        },
        Receiver {
            rx,
            buffer: In::default(),
            name: "thread link".into(),
            stats,
            _subscription: None,
        },
    )
}

/// The sending end of a link to other processes, publishing on `key`.
pub fn to_processes<T: Payload>(
    transport: &mut dyn Transport,
    key: &str,
    policy: Policy,
) -> Result<Sender<T>, TransportError> {
    let publisher = transport.publisher(key, policy)?;
    let stats = Arc::new(SharedStats::default());
    let tx = RemoteTx::new(
        Some(publisher),
        key.into(),
        remote::fingerprint::<T>(),
        remote::new_epoch(),
        stats.clone(),
    );
    Ok(Sender {
        tx: ThreadTx::Remote(tx),
        value: None,
        name: key.to_owned(),
        stats,
    })
}

/// The receiving end of a link from another process, subscribed to `key`.
pub fn from_process<T: Payload>(
    transport: &mut dyn Transport,
    key: &str,
    policy: Policy,
) -> Result<Receiver<T>, TransportError> {
    let stats = Arc::new(SharedStats::default());
    let inbox = Arc::new(Inbox::new(
        key.into(),
        remote::fingerprint::<T>(),
        std::any::type_name::<T>(),
        policy,
        stats.clone(),
    ));
    let subscription = transport.subscribe(key, inbox.clone())?;
    Ok(Receiver {
        rx: ThreadRx::Remote(RemoteRx { inbox }),
        buffer: In::default(),
        name: key.to_owned(),
        stats,
        _subscription: Some(subscription),
    })
}

/// An inbox for values of `T` from outside any system, under `key` (a name
/// for errors), and the receiving end that takes them: for a feeder's tests
/// (a bridge from another middleware writes the messages of the wire format
/// into the inbox, as it would into one from
/// [`RealTime::feed`](crate::RealTime::feed)).
pub fn fed<T: Payload>(key: &str, policy: Policy) -> (Arc<Inbox>, Receiver<T>) {
    let stats = Arc::new(SharedStats::default());
    let inbox = Arc::new(Inbox::new(
        key.into(),
        remote::fingerprint::<T>(),
        std::any::type_name::<T>(),
        policy,
        stats.clone(),
    ));
    let receiver = Receiver {
        rx: ThreadRx::Remote(RemoteRx {
            inbox: inbox.clone(),
        }),
        buffer: In::default(),
        name: key.to_owned(),
        stats,
        _subscription: None,
    };
    (inbox, receiver)
}

impl<T: Payload> Sender<T> {
    /// Send `value` with `stamp`. A full queue or a failed transport is an
    /// error (the value is not sent).
    pub fn send(&mut self, value: T, stamp: Stamp) -> Result<(), LinkError> {
        self.value = Some(value);
        self.tx
            .put(&mut self.value, true, stamp)
            .map_err(|cause| match cause {
                Cause::Full(bound) => LinkError::QueueOverflow {
                    link: self.name.clone(),
                    bound,
                    iteration: stamp.iteration,
                    time: stamp.time,
                },
                Cause::Remote(key, problem) => LinkError::Remote {
                    link: self.name.clone(),
                    key: key.to_string(),
                    problem,
                },
            })
    }

    /// The link's counters.
    pub fn stats(&self) -> LinkStats {
        self.stats.snapshot()
    }
}

impl<T: Payload> Receiver<T> {
    /// The next value if one arrived since the last call (sample: the latest;
    /// queue: the oldest waiting), or a problem of a link between processes.
    pub fn recv(&mut self) -> Result<Option<&T>, LinkError> {
        match self.rx.take_into(&mut self.buffer, Time::NEVER) {
            Ok(()) => Ok(self.buffer.fresh()),
            Err((key, problem)) => Err(remote_error(&self.name, &key, problem)),
        }
    }

    /// The stamp of the value last received.
    pub fn stamp(&self) -> Option<Stamp> {
        self.buffer.stamp()
    }

    /// The link's counters.
    pub fn stats(&self) -> LinkStats {
        self.stats.snapshot()
    }
}

fn remote_error(link: &str, key: &str, problem: RemoteProblem) -> LinkError {
    LinkError::Remote {
        link: link.to_owned(),
        key: key.to_owned(),
        problem,
    }
}
