//! Links: how an output buffer of one component reaches an input buffer of another.
//!
//! A link has a [`Policy`]:
//!
//! * [`Policy::Sample`]: the receiver reads the latest value sent (a data port: state
//!   estimates, poses). A value overwritten before it was read is counted in the
//!   link's [`LinkStats::overwritten`]; that is the policy, not a loss.
//! * [`Policy::Queue`]: lossless, in order, bounded. Each read of the receiver takes
//!   one value. Sending into a full queue is a [`LinkError::QueueOverflow`](crate::error::LinkError::QueueOverflow) reported
//!   by the executor, never a silent drop.
//!
//! Transfers swap storage instead of copying where they can: a value written into an
//! [`Out`](crate::buffer::Out) moves into the link and then into the [`In`], and the storage it replaces
//! travels back, so `Vec`-like payloads reach a steady state without allocation.

use std::any::Any;
use std::cell::RefCell;
use std::collections::VecDeque;
use std::fmt;
use std::marker::PhantomData;
use std::rc::Rc;

use crate::buffer::{In, Payload};
use crate::kinds::{NodeKind, Policy};
use crate::time::{Stamp, Time};

mod by_name;

pub mod endpoint;
pub(crate) mod reads;
pub mod remote;
pub mod shape;
mod stats;
pub(crate) mod thread;

/// The halves of links between threads, by link index: each thread of the
/// real-time executor gets those of its own nodes' ports.
pub(crate) type ThreadHalves = Vec<Option<Box<dyn Any + Send>>>;

/// Identifies a link of a system (its index in declaration order).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct LinkId(pub(crate) usize);

impl LinkId {
    /// The index of the link in declaration order.
    pub fn index(self) -> usize {
        self.0
    }

    /// The id of link `index` of a system described by `info` (its
    /// [`SystemInfo::links`](crate::trace::SystemInfo::links)), if it has
    /// one: for code that finds a link in the description (a bridge feeding
    /// it).
    pub fn of(info: &crate::trace::SystemInfo, index: usize) -> Option<LinkId> {
        (index < info.links.len()).then_some(LinkId(index))
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
    /// Between processes: messages refused on arrival or at the read (every
    /// one counted, though only the first few wait to be reported as
    /// errors): undecodable, of another payload type, a repeat, from a second
    /// sender, stamped implausibly far ahead.
    pub refused: u64,
    /// Between processes: values that arrived after a read they were due
    /// for (stamped before its instant), counted by the receiver: the
    /// transport took longer than the time between their sending and the
    /// read.
    pub late: u64,
}

pub use crate::buffer::Access;

/// A [`Port`]'s fan element: the fan's name, the index, and how to count the
/// fan's elements in the buffer struct `B`.
pub(crate) type PortFan<B> = (&'static str, usize, fn(&mut B) -> usize);

/// A typed reference to one buffer field of a component's input or output struct.
///
/// Make one with the [`port!`](crate::port) macro, which records the field's path as
/// its name and, for fields inside a [`Group`](crate::Group), the group's peer kind.
pub struct Port<B, X, A = fn(&mut B) -> &mut X> {
    name: &'static str,
    access: A,
    peer: Option<NodeKind>,
    /// In a [`Fan`](crate::Fan)'s element: the fan's name, the index, and how
    /// to count the fan's elements (checked when the link is made).
    fan: Option<PortFan<B>>,
    _b: PhantomData<fn(&mut B) -> &mut X>,
}

impl<B, X, A: Copy> Clone for Port<B, X, A> {
    fn clone(&self) -> Self {
        *self
    }
}
impl<B, X, A: Copy> Copy for Port<B, X, A> {}

impl<B, X, A> fmt::Debug for Port<B, X, A> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Port({})", self.name)
    }
}

impl<B, X, A> Port<B, X, A>
where
    A: for<'a> Fn(&'a mut B) -> &'a mut X + Copy + Send + 'static,
{
    /// A port named `name` reached by `access`; `peer` is the kind of component the
    /// field's group is connected to, if it is in a group.
    pub fn new(name: &'static str, access: A, peer: Option<NodeKind>) -> Self {
        Port {
            name,
            access,
            peer,
            fan: None,
            _b: PhantomData,
        }
    }

    /// The port of a buffer of element `index` of the [`Fan`](crate::Fan)
    /// `group`, whose elements `len` counts: a link to it is a build problem
    /// unless the fan has that element. [`port!`](crate::port) calls it for
    /// `port!(Type, group[index].field)`.
    pub fn in_fan(mut self, group: &'static str, index: usize, len: fn(&mut B) -> usize) -> Self {
        self.fan = Some((group, index, len));
        self
    }

    /// The field path, e.g. `to_valve.flow`.
    pub fn name(&self) -> &'static str {
        self.name
    }

    /// The peer kind declared by the field's group, if any.
    pub fn peer(&self) -> Option<NodeKind> {
        self.peer
    }

    #[inline]
    pub(crate) fn get<'a>(&self, b: &'a mut B) -> &'a mut X {
        (self.access)(b)
    }
}

/// A [`Port`] to a buffer field.
///
/// `port!(Type, group.field)` names a field inside a [`Group`](crate::Group) (the
/// link is then checked against the group's peer kind); `port!(Type, field)` names a
/// top-level field (used by drivers, whose buffers need no groups);
/// `port!(Type, group[index].field)` names a field of element `index` of a
/// [`Fan`](crate::Fan) (whether the fan has it is checked when the link is made).
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
    ($ty:ty, $group:ident [ $index:expr ] . $field:ident) => {{
        let index: usize = $index;
        $crate::Port::new(
            $crate::__private::fan_port_name(stringify!($group), index, stringify!($field)),
            move |b: &mut $ty| &mut b.$group[index].$field,
            ::core::option::Option::Some($crate::__private::peer_of(|b: &mut $ty| &mut b.$group)),
        )
        .in_fan(stringify!($group), index, |b: &mut $ty| b.$group.len())
    }};
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

/// Type-erased view of a channel, for statistics.
pub(crate) trait AnyChannel {
    fn stats(&self) -> &LinkStats;
    fn pending(&self) -> usize;
    /// Put a value given as its postcard encoding (a replay's input).
    fn put_encoded(&mut self, body: &[u8], stamp: Stamp) -> Result<(), InjectError>;
    /// Drop every value waiting (a replay drains what no node reads).
    fn clear(&mut self);
}

/// A value could not be put into a link ([`Executor::inject`](crate::Executor::inject)).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum InjectError {
    /// No link has this index.
    #[error("no link {0}")]
    NoLink(usize),
    /// The bytes are not a value of the link's payload type.
    #[error("a `{type_name}` that does not decode: {message}")]
    Decode {
        /// The payload type.
        type_name: &'static str,
        /// postcard's reason.
        message: String,
    },
    /// The link's queue is full.
    #[error("the link's queue is full ({bound} values)")]
    Full {
        /// Its bound.
        bound: usize,
    },
}

impl<T: Payload> AnyChannel for Channel<T> {
    fn stats(&self) -> &LinkStats {
        &self.stats
    }
    fn put_encoded(&mut self, body: &[u8], stamp: Stamp) -> Result<(), InjectError> {
        let value = postcard::from_bytes::<T>(body).map_err(|e| InjectError::Decode {
            type_name: std::any::type_name::<T>(),
            message: e.to_string(),
        })?;
        self.put(&mut Some(value), true, stamp)
            .map_err(|bound| InjectError::Full { bound })
    }
    fn clear(&mut self) {
        match &mut self.state {
            ChannelState::Sample { unread, .. } => *unread = false,
            ChannelState::Queue { items, .. } => items.clear(),
        }
    }
    fn pending(&self) -> usize {
        match &self.state {
            ChannelState::Sample { unread, .. } => usize::from(*unread),
            ChannelState::Queue { items, .. } => items.len(),
        }
    }
}

/// A channel shared by the two halves of an in-process link. The deterministic
/// executor is single-threaded, so sharing needs no lock.
pub(crate) type Shared<T> = Rc<RefCell<Channel<T>>>;

/// The addresses a transfer through `channel` touches (pushed onto `to`):
/// the channel's (its `RefCell`'s flag, then the channel), and a queue's
/// storage (made once, at its bound: it never moves; `as_slices` of the
/// queue, empty when the executor is made, starts at the storage's
/// start). For the executor's prefetch ([`OutPort::reach`](port::OutPort::reach)).
pub(crate) fn reach<T>(channel: &Shared<T>, to: &mut Vec<usize>) {
    crate::cache::address_of(&**channel, to);
    if let Ok(c) = channel.try_borrow()
        && let ChannelState::Queue { items, .. } = &c.state
    {
        to.push(items.as_slices().0.as_ptr().addr());
    }
}

/// The channels of all links of a system, by link index: typed (an `Rc` erased as
/// `Any`, each a `Shared<T>`) for the ports, and as [`AnyChannel`] for statistics. The
/// deterministic executor makes them one by one ([`Channels::make`]), in the
/// order its nodes first use them, so that they lie on the heap near their
/// ports.
pub(crate) struct Channels {
    typed: Vec<Option<Rc<dyn Any>>>,
    stats: Vec<Option<Rc<RefCell<dyn AnyChannel>>>>,
}

impl Channels {
    /// The channels of `links` links, none made yet.
    pub(crate) fn unmade(links: usize) -> Channels {
        Channels {
            typed: (0..links).map(|_| None).collect(),
            stats: (0..links).map(|_| None).collect(),
        }
    }

    /// Make the channel of link `link` from its plan in `plans`, unless it
    /// is made already (or there is no such link).
    pub(crate) fn make(&mut self, link: usize, plans: &[Box<dyn ChannelPlan>]) {
        if let (Some(typed @ None), Some(stats), Some(plan)) = (
            self.typed.get_mut(link),
            self.stats.get_mut(link),
            plans.get(link),
        ) {
            let (t, s) = plan.local();
            *typed = Some(t);
            *stats = Some(s);
        }
    }

    /// The channel of link `link`, erased, for its statistics.
    pub(crate) fn stats(&self, link: usize) -> Option<&Rc<RefCell<dyn AnyChannel>>> {
        self.stats.get(link)?.as_ref()
    }

    /// Every link's counters, by link index (a link without a channel counts
    /// nothing).
    pub(crate) fn all_stats(&self) -> Vec<LinkStats> {
        self.stats
            .iter()
            .map(|c| c.as_ref().map(|c| *c.borrow().stats()).unwrap_or_default())
            .collect()
    }

    fn shared<T: Payload>(&self, link: usize) -> Option<Shared<T>> {
        let any = self.typed.get(link)?.as_ref()?;
        Rc::clone(any).downcast::<RefCell<Channel<T>>>().ok()
    }
}

mod plan;
mod port;
pub(crate) use plan::*;
pub(crate) use port::*;

#[cfg(test)]
#[path = "channel_tests.rs"]
mod tests;
