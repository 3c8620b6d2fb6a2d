//! Links: how an output buffer of one component reaches an input buffer of another.
//!
//! A link has a [`Policy`]:
//!
//! * [`Policy::Sample`]: the receiver reads the latest value sent (a data port: state
//!   estimates, poses). A value overwritten before it was read is counted in the
//!   link's [`LinkStats::overwritten`]; that is the policy, not a loss.
//! * [`Policy::Queue`]: lossless, in order, bounded. Each read of the receiver takes
//!   one value. Sending into a full queue is a [`LinkError::QueueOverflow`] reported
//!   by the executor, never a silent drop.
//!
//! Transfers swap storage instead of copying where they can: a value written into an
//! [`Out`] moves into the link and then into the [`In`], and the storage it replaces
//! travels back, so `Vec`-like payloads reach a steady state without allocation.

use std::any::Any;
use std::borrow::Cow;
use std::collections::VecDeque;
use std::fmt;

use crate::buffer::{In, NodeKind, Out, Payload};
use crate::time::{Stamp, Time};
use crate::trace::{LinkInfo, Observer, TransferEvent};

/// How a link delivers values.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Policy {
    /// Latest value wins.
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

/// Identifies a link of a system (its index in declaration order).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct LinkId(pub(crate) usize);

impl LinkId {
    /// The index of the link in declaration order.
    pub fn index(self) -> usize {
        self.0
    }
}

/// Counters of one link.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LinkStats {
    /// Values sent into the link.
    pub sent: u64,
    /// Values delivered to the receiver.
    pub delivered: u64,
    /// Sample policy: values replaced by a newer one before the receiver read them.
    pub overwritten: u64,
    /// Queue policy: values refused because the queue was full (each one reported).
    pub overflowed: u64,
    /// Queue policy: the largest number of values waiting at once.
    pub max_pending: usize,
}

/// A transfer that could not be made.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LinkError {
    /// A value was sent into a full queue: the value was not delivered.
    #[error(
        "queue link `{link}` is full ({bound} values waiting): the value sent by iteration {iteration} at {time} was refused"
    )]
    QueueOverflow {
        /// The link's name.
        link: String,
        /// Its capacity.
        bound: usize,
        /// Iteration of the sender.
        iteration: u64,
        /// Virtual time of the send.
        time: Time,
    },
}

/// A typed reference to one buffer field of a component's input or output struct.
///
/// Make one with the [`port!`](crate::port) macro, which records the field's path as
/// its name and, for fields inside a [`Group`](crate::Group), the group's peer kind.
pub struct Port<B, X> {
    name: &'static str,
    access: fn(&mut B) -> &mut X,
    peer: Option<NodeKind>,
}

impl<B, X> Clone for Port<B, X> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<B, X> Copy for Port<B, X> {}

impl<B, X> fmt::Debug for Port<B, X> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Port({})", self.name)
    }
}

impl<B, X> Port<B, X> {
    /// A port named `name` reached by `access`; `peer` is the kind of component the
    /// field's group is connected to, if it is in a group.
    pub fn new(name: &'static str, access: fn(&mut B) -> &mut X, peer: Option<NodeKind>) -> Self {
        Port { name, access, peer }
    }

    /// The field path, e.g. `to_valve.flow`.
    pub fn name(&self) -> &'static str {
        self.name
    }

    /// The peer kind declared by the field's group, if any.
    pub fn peer(&self) -> Option<NodeKind> {
        self.peer
    }

    pub(crate) fn get<'a>(&self, b: &'a mut B) -> &'a mut X {
        (self.access)(b)
    }
}

/// A [`Port`] to a buffer field.
///
/// `port!(Type, group.field)` names a field inside a [`Group`](crate::Group) (the
/// link is then checked against the group's peer kind); `port!(Type, field)` names a
/// top-level field (used by drivers, whose buffers need no groups).
///
/// ```
/// use agent_core::{port, Group, NodeKind, Out};
/// #[derive(Default)] struct ToValve { flow: Out<f64> }
/// impl Group for ToValve { const PEER: NodeKind = NodeKind::VirtualEffector; }
/// #[derive(Default)] struct Output { to_valve: ToValve }
/// let p = port!(Output, to_valve.flow);
/// assert_eq!(p.name(), "to_valve.flow");
/// assert_eq!(p.peer(), Some(NodeKind::VirtualEffector));
/// ```
#[macro_export]
macro_rules! port {
    ($ty:ty, $group:ident . $field:ident) => {
        $crate::Port::new(
            concat!(stringify!($group), ".", stringify!($field)),
            |b: &mut $ty| &mut b.$group.$field,
            ::core::option::Option::Some($crate::__private::peer_of(|b: &mut $ty| &mut b.$group)),
        )
    };
    ($ty:ty, $field:ident) => {
        $crate::Port::new(
            stringify!($field),
            |b: &mut $ty| &mut b.$field,
            ::core::option::Option::None,
        )
    };
}

// ---------------------------------------------------------------------------
// Channels (the link's own storage in the in-process executor)

enum ChannelState<T> {
    Sample {
        slot: Option<T>,
        stamp: Stamp,
        unread: bool,
    },
    Queue {
        items: VecDeque<(T, Stamp)>,
        bound: usize,
    },
}

pub(crate) struct Channel<T> {
    state: ChannelState<T>,
    stats: LinkStats,
}

impl<T> Channel<T> {
    pub(crate) fn new(policy: Policy) -> Self {
        let state = match policy {
            Policy::Sample => ChannelState::Sample {
                slot: None,
                stamp: Stamp::new(0, Time::ZERO),
                unread: false,
            },
            Policy::Queue { bound } => ChannelState::Queue {
                items: VecDeque::with_capacity(bound),
                bound,
            },
        };
        Channel {
            state,
            stats: LinkStats::default(),
        }
    }
}

impl<T: Clone> Channel<T> {
    /// Put the value held in `value` into the channel. With `last`, the value may be
    /// moved (the storage it replaces is left in `value`); otherwise it is cloned.
    fn put(&mut self, value: &mut Option<T>, last: bool, stamp: Stamp) -> Result<(), usize> {
        match &mut self.state {
            ChannelState::Sample {
                slot,
                stamp: s,
                unread,
            } => {
                if *unread {
                    self.stats.overwritten += 1;
                }
                if last {
                    std::mem::swap(slot, value);
                } else {
                    slot.clone_from(value);
                }
                *s = stamp;
                *unread = true;
            }
            ChannelState::Queue { items, bound } => {
                if items.len() >= *bound {
                    self.stats.overflowed += 1;
                    return Err(*bound);
                }
                let v = if last { value.take() } else { value.clone() };
                if let Some(v) = v {
                    items.push_back((v, stamp));
                }
                self.stats.max_pending = self.stats.max_pending.max(items.len());
            }
        }
        self.stats.sent += 1;
        Ok(())
    }

    fn take_into(&mut self, x: &mut In<T>) {
        match &mut self.state {
            ChannelState::Sample {
                slot,
                stamp,
                unread,
            } => {
                if *unread {
                    *unread = false;
                    x.swap_in(slot, *stamp);
                    self.stats.delivered += 1;
                } else {
                    x.age();
                }
            }
            ChannelState::Queue { items, .. } => match items.pop_front() {
                Some((v, stamp)) => {
                    x.swap_in(&mut Some(v), stamp);
                    self.stats.delivered += 1;
                }
                None => x.age(),
            },
        }
    }
}

/// Type-erased channel, as stored in the executor's arena.
pub(crate) trait AnyChannel: Send {
    fn stats(&self) -> &LinkStats;
    fn pending(&self) -> usize;
    fn as_any_mut(&mut self) -> &mut dyn Any;
}

impl<T: Payload> AnyChannel for Channel<T> {
    fn stats(&self) -> &LinkStats {
        &self.stats
    }
    fn pending(&self) -> usize {
        match &self.state {
            ChannelState::Sample { unread, .. } => usize::from(*unread),
            ChannelState::Queue { items, .. } => items.len(),
        }
    }
    fn as_any_mut(&mut self) -> &mut dyn Any {
        self
    }
}

/// The channels of all links of a system, indexed by [`LinkId`].
pub(crate) struct Channels {
    pub(crate) items: Vec<Box<dyn AnyChannel>>,
}

impl Channels {
    #[inline]
    fn get<T: Payload>(&mut self, id: usize) -> Option<&mut Channel<T>> {
        self.items
            .get_mut(id)
            .and_then(|c| c.as_any_mut().downcast_mut::<Channel<T>>())
    }
}

/// What ports need from the executor during a transfer.
pub(crate) struct LinkCx<'a> {
    pub(crate) channels: &'a mut Channels,
    pub(crate) observer: Option<&'a mut dyn Observer>,
    pub(crate) links: &'a [LinkInfo],
}

// ---------------------------------------------------------------------------
// Ports: the per-component halves of links.

pub(crate) trait OutPort<O>: Send {
    /// Send the buffer if it was written; every channel gets the value.
    fn send(&mut self, y: &mut O, stamp: Stamp, cx: &mut LinkCx<'_>) -> Result<(), LinkError>;
    /// Forget a write (the action failed).
    fn discard(&mut self, y: &mut O);
}

pub(crate) trait InPort<I>: Send {
    fn read(&mut self, x: &mut I, cx: &mut LinkCx<'_>);
    /// Called once when the port is installed: names the buffer after its link.
    fn attach(&self, x: &mut I);
}

pub(crate) struct LocalOut<O, T> {
    pub(crate) port: Port<O, Out<T>>,
    pub(crate) links: Vec<usize>,
}

impl<O: 'static, T: Payload> OutPort<O> for LocalOut<O, T> {
    #[inline]
    fn send(&mut self, y: &mut O, stamp: Stamp, cx: &mut LinkCx<'_>) -> Result<(), LinkError> {
        let Some(value) = self.port.get(y).pending() else {
            return Ok(());
        };
        let mut result = Ok(());
        let n = self.links.len();
        for (k, &link) in self.links.iter().enumerate() {
            if let (Some(obs), Some(v)) = (cx.observer.as_deref_mut(), value.as_ref()) {
                obs.transfer(&TransferEvent { link, stamp }, v);
            }
            let Some(channel) = cx.channels.get::<T>(link) else {
                continue;
            };
            if let Err(bound) = channel.put(value, k + 1 == n, stamp) {
                if result.is_ok() {
                    result = Err(LinkError::QueueOverflow {
                        link: cx
                            .links
                            .get(link)
                            .map(|l| l.name.clone())
                            .unwrap_or_default(),
                        bound,
                        iteration: stamp.iteration,
                        time: stamp.time,
                    });
                }
            }
        }
        result
    }

    fn discard(&mut self, y: &mut O) {
        self.port.get(y).discard();
    }
}

pub(crate) struct LocalIn<I, T> {
    pub(crate) port: Port<I, In<T>>,
    pub(crate) link: usize,
    pub(crate) name: Cow<'static, str>,
}

impl<I: 'static, T: Payload> InPort<I> for LocalIn<I, T> {
    #[inline]
    fn read(&mut self, x: &mut I, cx: &mut LinkCx<'_>) {
        if let Some(channel) = cx.channels.get::<T>(self.link) {
            channel.take_into(self.port.get(x));
        }
    }

    fn attach(&self, x: &mut I) {
        self.port.get(x).set_name(self.name.clone());
    }
}

// ---------------------------------------------------------------------------
// Plans: typed descriptions of links kept by the system until an executor
// instantiates them with its own transport.

/// The typed halves of a link, kept until an executor instantiates them.
pub(crate) trait OutPlan: Send {
    fn add_link(&mut self, link: usize);
    /// A `Box<Box<dyn OutPort<O>>>` for the in-process executor, erased.
    fn local(&self) -> Box<dyn Any>;
}

pub(crate) struct TypedOutPlan<O, T> {
    pub(crate) port: Port<O, Out<T>>,
    pub(crate) links: Vec<usize>,
}

impl<O: Send + 'static, T: Payload> OutPlan for TypedOutPlan<O, T> {
    fn add_link(&mut self, link: usize) {
        self.links.push(link);
    }
    fn local(&self) -> Box<dyn Any> {
        let port: Box<dyn OutPort<O>> = Box::new(LocalOut {
            port: self.port,
            links: self.links.clone(),
        });
        Box::new(port)
    }
}

pub(crate) trait InPlan: Send {
    /// A `Box<Box<dyn InPort<I>>>` for the in-process executor, erased.
    fn local(&self) -> Box<dyn Any>;
}

pub(crate) struct TypedInPlan<I, T> {
    pub(crate) port: Port<I, In<T>>,
    pub(crate) link: usize,
    pub(crate) name: Cow<'static, str>,
}

impl<I: Send + 'static, T: Payload> InPlan for TypedInPlan<I, T> {
    fn local(&self) -> Box<dyn Any> {
        let port: Box<dyn InPort<I>> = Box::new(LocalIn {
            port: self.port,
            link: self.link,
            name: self.name.clone(),
        });
        Box::new(port)
    }
}

/// Makes the channel of one link.
pub(crate) type ChannelFactory = Box<dyn Fn() -> Box<dyn AnyChannel> + Send>;

pub(crate) fn channel_factory<T: Payload>(policy: Policy) -> ChannelFactory {
    Box::new(move || Box::new(Channel::<T>::new(policy)))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stamp(i: u64) -> Stamp {
        Stamp::new(i, Time::from_nanos(i))
    }

    #[test]
    fn sample_keeps_latest_and_counts_overwrites() {
        let mut c = Channel::<u32>::new(Policy::Sample);
        let mut x = In::default();
        c.take_into(&mut x);
        assert!(!x.is_new() && !x.has_data());
        c.put(&mut Some(1), true, stamp(1)).unwrap();
        c.put(&mut Some(2), true, stamp(2)).unwrap();
        c.take_into(&mut x);
        assert_eq!((x.fresh(), x.stamp()), (Some(&2), Some(stamp(2))));
        c.take_into(&mut x);
        assert!(!x.is_new());
        assert_eq!(x.get(), Some(&2));
        assert_eq!(c.stats.overwritten, 1);
        assert_eq!((c.stats.sent, c.stats.delivered), (2, 1));
    }

    #[test]
    fn queue_is_lossless_ordered_and_bounded() {
        let mut c = Channel::<u32>::new(Policy::queue(2));
        c.put(&mut Some(1), true, stamp(1)).unwrap();
        c.put(&mut Some(2), false, stamp(2)).unwrap();
        assert_eq!(c.put(&mut Some(3), true, stamp(3)), Err(2));
        assert_eq!(c.stats.overflowed, 1);
        let mut x = In::default();
        for expect in [Some(1), Some(2)] {
            c.take_into(&mut x);
            assert_eq!(x.fresh().copied(), expect);
        }
        c.take_into(&mut x);
        assert!(!x.is_new(), "an empty queue brings nothing new");
        assert_eq!(c.stats.max_pending, 2);
    }

    #[test]
    fn moving_sends_recycle_storage() {
        let mut c = Channel::<Vec<u8>>::new(Policy::Sample);
        let mut x = In::default();
        let mut v = Some(Vec::with_capacity(64));
        c.put(&mut v, true, stamp(1)).unwrap();
        c.take_into(&mut x);
        // The receiver's previous storage (none yet) went back into the channel; on
        // the next round the storage cycles around instead of being reallocated.
        let mut w = Some(vec![9u8]);
        c.put(&mut w, true, stamp(2)).unwrap();
        c.take_into(&mut x);
        assert_eq!(x.get().map(Vec::as_slice), Some(&[9u8][..]));
        let mut u = Some(vec![7u8]);
        c.put(&mut u, true, stamp(3)).unwrap();
        assert_eq!(
            u.map(|v| v.capacity()),
            Some(64),
            "the sender got back the first buffer's storage"
        );
    }
}
