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
use std::cell::RefCell;
use std::collections::VecDeque;
use std::fmt;
use std::marker::PhantomData;
use std::rc::Rc;

use crate::buffer::{In, Out, Payload};
use crate::error::LinkError;
use crate::kinds::{NodeKind, Policy};
use crate::time::{Stamp, Time};
use crate::trace::{LinkEvents, LinkInfo, Observer, ReadEvent, TransferEvent};

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

/// The channels of all links of a system, by link index: typed (erased as `Any`, each
/// a `Shared<T>`) for the ports, and as [`AnyChannel`] for statistics. The
/// deterministic executor makes them one by one ([`Channels::make`]), in the
/// order its nodes first use them, so that they lie on the heap near their
/// ports.
pub(crate) struct Channels {
    typed: Vec<Option<Box<dyn Any>>>,
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
        self.typed
            .get(link)?
            .as_ref()?
            .downcast_ref::<Shared<T>>()
            .cloned()
    }
}

/// What ports need from the executor during a transfer.
pub(crate) struct LinkCx<'a> {
    /// The instant being executed.
    pub(crate) time: Time,
    pub(crate) observer: Option<&'a mut dyn Observer>,
    /// Per link, the sends and reads the observer needs (none given: all).
    pub(crate) wants: &'a [LinkEvents],
    pub(crate) links: &'a [LinkInfo],
    /// The system's environment, for drivers.
    pub(crate) environment: Option<&'a mut (dyn std::any::Any + Send)>,
}

// ---------------------------------------------------------------------------
// Ports: the per-component halves of links.

/// A value a link refused: which link, and why.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Refused {
    pub(crate) link: usize,
    pub(crate) cause: Cause,
}

/// Why a link refused a value.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) enum Cause {
    /// A full queue, of this capacity.
    Full(usize),
    /// A link to another process failed (key, problem).
    Remote(std::sync::Arc<str>, crate::error::RemoteProblem),
}

impl Refused {
    /// The error the executor reports.
    #[cold]
    pub(crate) fn into_error(self, stamp: Stamp, links: &[LinkInfo]) -> LinkError {
        let link = links
            .get(self.link)
            .map(|l| l.name.clone())
            .unwrap_or_default();
        match self.cause {
            Cause::Full(bound) => LinkError::QueueOverflow {
                link,
                bound,
                iteration: stamp.iteration,
                time: stamp.time,
            },
            Cause::Remote(key, problem) => LinkError::Remote {
                link,
                key: key.to_string(),
                problem,
            },
        }
    }
}

pub(crate) trait OutPort<O> {
    /// Send the buffer if it was written; every channel gets the value. A refusal
    /// (full queue) is returned as `(link, bound)`; the caller makes the error.
    fn send(&mut self, y: &mut O, stamp: Stamp, cx: &mut LinkCx<'_>) -> Result<(), Refused>;
    /// Forget a write (the action failed).
    fn discard(&mut self, y: &mut O);
    /// The node halts: a value held for a reader in another process is
    /// published now ([`remote::RemoteTx::flush`]).
    fn flush(&mut self) -> Result<(), Refused> {
        Ok(())
    }
}

pub(crate) trait InPort<I> {
    /// Take what the link holds into the buffer; a link between processes may
    /// report a problem instead (the buffer then ages).
    fn read(&mut self, x: &mut I, cx: &mut LinkCx<'_>) -> Result<(), LinkError>;
    /// Called once when the port is installed: names the buffer after its link.
    fn attach(&self, x: &mut I);
}

/// The sending half of in-process links: what an action's send touches, in
/// its first bytes (the port's accessor of the buffer, not its name and
/// checks, which the plan keeps), so that a port costs one cache line.
#[repr(C)]
pub(crate) struct LocalOut<O, T, A> {
    /// The first destination (link index, channel), inline: most outputs have one.
    first: (usize, Shared<T>),
    /// The output buffer, from the output struct.
    access: A,
    /// Further destinations of a fanned-out output, boxed (8 bytes; none for
    /// most outputs) so that the port is 24 bytes and its neighbours share
    /// its cache line.
    more: Option<Box<More<T>>>,
    _o: PhantomData<fn(&mut O)>,
}

/// The destinations of a fanned-out [`LocalOut`] after its first (link
/// index, channel).
struct More<T>(Vec<(usize, Shared<T>)>);

impl<O, T: Payload, A> LocalOut<O, T, A> {
    #[inline]
    fn put(
        &self,
        (link, channel): &(usize, Shared<T>),
        value: &mut Option<T>,
        last: bool,
        stamp: Stamp,
        cx: &mut LinkCx<'_>,
    ) -> Result<(), Refused> {
        if let (Some(obs), Some(v)) = (cx.observer.as_deref_mut(), value.as_ref())
            && cx.wants.get(*link).is_none_or(|w| w.transfer(v))
        {
            obs.transfer(&TransferEvent { link: *link, stamp }, v);
        }
        channel
            .borrow_mut()
            .put(value, last, stamp)
            .map_err(|bound| Refused {
                link: *link,
                cause: Cause::Full(bound),
            })
    }
}

impl<O: 'static, T: Payload, A: Access<O, Out<T>>> OutPort<O> for LocalOut<O, T, A> {
    #[inline]
    fn send(&mut self, y: &mut O, stamp: Stamp, cx: &mut LinkCx<'_>) -> Result<(), Refused> {
        let Some(value) = (self.access)(y).pending() else {
            return Ok(());
        };
        let Some(more) = &self.more else {
            return self.put(&self.first, value, true, stamp, cx);
        };
        // Fan-out: clone into all but the last destination; report the first refusal
        // after every destination had its chance.
        let mut result = self.put(&self.first, value, false, stamp, cx);
        let n = more.0.len();
        for (k, dest) in more.0.iter().enumerate() {
            let r = self.put(dest, value, k + 1 == n, stamp, cx);
            if result.is_ok() {
                result = r;
            }
        }
        result
    }

    fn discard(&mut self, y: &mut O) {
        (self.access)(y).discard();
    }
}

/// The receiving half of an in-process link: what a read touches first (see
/// [`LocalOut`]), the buffer's name (given once) last.
#[repr(C)]
pub(crate) struct LocalIn<I, T, A> {
    channel: Shared<T>,
    link: usize,
    /// The input buffer, from the input struct.
    access: A,
    /// Given to the buffer once ([`InPort::attach`]), boxed (8 bytes) so that
    /// the port is 24 bytes and its neighbours share its cache line.
    name: Box<Cow<'static, str>>,
    _i: PhantomData<fn(&mut I)>,
}

/// Tell the observer that the buffer `x` just took a value from `link` (if it
/// did), or holds one older than the observer's bound
/// ([`LinkEvents::older_than`]).
#[inline]
pub(crate) fn observe_read<T>(x: &In<T>, link: usize, cx: &mut LinkCx<'_>) {
    let Some(obs) = cx.observer.as_deref_mut() else {
        return;
    };
    let new = x.is_new();
    let Some(stamp) = x.stamp() else {
        return;
    };
    let told = match cx.wants.get(link) {
        Some(w) => w.read(new, cx.time.as_nanos(), stamp.time.as_nanos()),
        None => new.then_some(true),
    };
    let Some(new) = told else {
        return;
    };
    let e = ReadEvent {
        time: cx.time,
        link,
        stamp,
    };
    if new {
        obs.read(&e);
    } else {
        obs.held(&e);
    }
}

impl<I: 'static, T: Payload, A: Access<I, In<T>>> InPort<I> for LocalIn<I, T, A> {
    #[inline]
    fn read(&mut self, x: &mut I, cx: &mut LinkCx<'_>) -> Result<(), LinkError> {
        let x = (self.access)(x);
        self.channel.borrow_mut().take_into(x);
        observe_read(x, self.link, cx);
        Ok(())
    }

    fn attach(&self, x: &mut I) {
        (self.access)(x).set_name((*self.name).clone());
    }
}

// ---------------------------------------------------------------------------
// Plans: typed descriptions of links kept by the system until an executor
// instantiates them with its own transport.

/// The typed sending half of one or more links (fan-out), kept until an executor
/// instantiates it.
pub(crate) trait OutPlan: Send {
    fn add_link(&mut self, link: usize);
    /// The links it sends into.
    fn links(&self) -> &[usize];
    /// A `Box<dyn OutPort<O>>` for the in-process executor, erased as `Any`.
    fn local(&self, channels: &Channels) -> Option<Box<dyn Any>>;
    /// A `Box<dyn OutPort<O>>` over links between threads, erased as `Any`; takes
    /// the sending halves of its links out of `txs`.
    fn threaded(&self, txs: &mut ThreadHalves) -> Option<Box<dyn Any>>;
}

pub(crate) struct TypedOutPlan<O, T, A> {
    pub(crate) port: Port<O, Out<T>, A>,
    pub(crate) links: Vec<usize>,
}

impl<O: Send + 'static, T: Payload, A: Access<O, Out<T>>> OutPlan for TypedOutPlan<O, T, A> {
    fn add_link(&mut self, link: usize) {
        self.links.push(link);
    }
    fn links(&self) -> &[usize] {
        &self.links
    }
    fn local(&self, channels: &Channels) -> Option<Box<dyn Any>> {
        let mut links = self
            .links
            .iter()
            .map(|&l| Some((l, channels.shared::<T>(l)?)))
            .collect::<Option<Vec<_>>>()?;
        if links.is_empty() {
            return None;
        }
        let first = links.remove(0);
        let port: Box<dyn OutPort<O>> = Box::new(LocalOut {
            first,
            access: self.port.access,
            more: (!links.is_empty()).then(|| Box::new(More(links))),
            _o: PhantomData,
        });
        Some(Box::new(port))
    }
    fn threaded(&self, txs: &mut ThreadHalves) -> Option<Box<dyn Any>> {
        let links = self
            .links
            .iter()
            .map(|&l| {
                let tx = txs.get_mut(l)?.take()?;
                Some((l, *tx.downcast::<thread::ThreadTx<T>>().ok()?))
            })
            .collect::<Option<Vec<_>>>()?;
        let away = links
            .iter()
            .any(|(_, tx)| matches!(tx, thread::ThreadTx::Remote(_)));
        let port: Box<dyn OutPort<O>> = Box::new(thread::ThreadOut {
            port: self.port,
            links,
            away,
        });
        Some(Box::new(port))
    }
}

/// The typed receiving half of a link.
pub(crate) trait InPlan: Send {
    /// The link it reads.
    fn link(&self) -> usize;
    /// A `Box<dyn InPort<I>>` for the in-process executor, erased as `Any`.
    fn local(&self, channels: &Channels) -> Option<Box<dyn Any>>;
    /// A `Box<dyn InPort<I>>` over a link between threads, erased as `Any`; takes
    /// the receiving half of its link out of `rxs`.
    fn threaded(&self, rxs: &mut ThreadHalves) -> Option<Box<dyn Any>>;
}

pub(crate) struct TypedInPlan<I, T, A> {
    pub(crate) port: Port<I, In<T>, A>,
    pub(crate) link: usize,
    pub(crate) name: Cow<'static, str>,
}

impl<I: Send + 'static, T: Payload, A: Access<I, In<T>>> InPlan for TypedInPlan<I, T, A> {
    fn link(&self) -> usize {
        self.link
    }
    fn local(&self, channels: &Channels) -> Option<Box<dyn Any>> {
        let port: Box<dyn InPort<I>> = Box::new(LocalIn {
            channel: channels.shared::<T>(self.link)?,
            link: self.link,
            access: self.port.access,
            name: Box::new(self.name.clone()),
            _i: PhantomData,
        });
        Some(Box::new(port))
    }
    fn threaded(&self, rxs: &mut ThreadHalves) -> Option<Box<dyn Any>> {
        let rx = rxs.get_mut(self.link)?.take()?;
        let port: Box<dyn InPort<I>> = Box::new(thread::ThreadIn {
            port: self.port,
            rx: *rx.downcast::<thread::ThreadRx<T>>().ok()?,
            name: self.name.clone(),
            link: self.link,
        });
        Some(Box::new(port))
    }
}

/// Makes the in-process channel of one link.
pub(crate) trait ChannelPlan: Send {
    fn local(&self) -> (Box<dyn Any>, Rc<RefCell<dyn AnyChannel>>);
    /// The two halves of a link between threads (a `ThreadTx<T>` and a
    /// `ThreadRx<T>`, erased) and its counters.
    fn threaded(
        &self,
    ) -> (
        Box<dyn Any + Send>,
        Box<dyn Any + Send>,
        std::sync::Arc<thread::SharedStats>,
    );
    /// The sending half of a link to another process (a `ThreadTx<T>`, erased).
    fn remote_tx(&self, tx: remote::RemoteTx) -> Box<dyn Any + Send>;
    /// The receiving half of a link from another process, its inbox (to give to
    /// the transport) and the link's counters.
    fn remote_rx(
        &self,
        key: std::sync::Arc<str>,
    ) -> (
        Box<dyn Any + Send>,
        std::sync::Arc<remote::Inbox>,
        std::sync::Arc<thread::SharedStats>,
    );
    /// An inbox for values of the link's type and policy from outside the
    /// system, with counters of its own.
    fn feed_inbox(&self, key: std::sync::Arc<str>) -> std::sync::Arc<remote::Inbox>;
    /// `rx` (a receiving half made by this plan) with `feed` beside it;
    /// `None` if `rx` is not of this plan's type.
    fn fed(
        &self,
        rx: Box<dyn Any + Send>,
        feed: std::sync::Arc<remote::Inbox>,
    ) -> Option<Box<dyn Any + Send>>;
    /// The payload type's fingerprint.
    fn fingerprint(&self) -> u64;
    /// The payload type's shape.
    fn shape(&self) -> Option<remote::TypeShape>;
}

struct TypedChannelPlan<T> {
    policy: Policy,
    _t: std::marker::PhantomData<fn() -> T>,
}

impl<T: Payload> ChannelPlan for TypedChannelPlan<T> {
    fn local(&self) -> (Box<dyn Any>, Rc<RefCell<dyn AnyChannel>>) {
        let shared: Shared<T> = Rc::new(RefCell::new(Channel::new(self.policy)));
        let stats: Rc<RefCell<dyn AnyChannel>> = shared.clone();
        (Box::new(shared), stats)
    }
    fn threaded(
        &self,
    ) -> (
        Box<dyn Any + Send>,
        Box<dyn Any + Send>,
        std::sync::Arc<thread::SharedStats>,
    ) {
        let (tx, rx, stats) = thread::channel::<T>(self.policy);
        (Box::new(tx), Box::new(rx), stats)
    }
    fn remote_tx(&self, tx: remote::RemoteTx) -> Box<dyn Any + Send> {
        Box::new(thread::ThreadTx::<T>::Remote(tx))
    }
    fn remote_rx(
        &self,
        key: std::sync::Arc<str>,
    ) -> (
        Box<dyn Any + Send>,
        std::sync::Arc<remote::Inbox>,
        std::sync::Arc<thread::SharedStats>,
    ) {
        let stats = std::sync::Arc::new(thread::SharedStats::default());
        let inbox = std::sync::Arc::new(remote::Inbox::new(
            key,
            remote::fingerprint::<T>(),
            std::any::type_name::<T>(),
            self.policy,
            stats.clone(),
        ));
        let rx = thread::ThreadRx::<T>::Remote(remote::RemoteRx {
            inbox: inbox.clone(),
        });
        (Box::new(rx), inbox, stats)
    }
    fn feed_inbox(&self, key: std::sync::Arc<str>) -> std::sync::Arc<remote::Inbox> {
        std::sync::Arc::new(remote::Inbox::new(
            key,
            remote::fingerprint::<T>(),
            std::any::type_name::<T>(),
            self.policy,
            std::sync::Arc::new(thread::SharedStats::default()),
        ))
    }
    fn fed(
        &self,
        rx: Box<dyn Any + Send>,
        feed: std::sync::Arc<remote::Inbox>,
    ) -> Option<Box<dyn Any + Send>> {
        let link = *rx.downcast::<thread::ThreadRx<T>>().ok()?;
        Some(Box::new(thread::ThreadRx::<T>::Fed(Box::new(
            thread::Fed {
                link,
                feed: remote::RemoteRx { inbox: feed },
                feed_first: true,
                from_feed: false,
            },
        ))))
    }
    fn fingerprint(&self) -> u64 {
        remote::fingerprint::<T>()
    }
    fn shape(&self) -> Option<remote::TypeShape> {
        remote::reflect::<T>()
    }
}

pub(crate) fn channel_plan<T: Payload>(policy: Policy) -> Box<dyn ChannelPlan> {
    Box::new(TypedChannelPlan::<T> {
        policy,
        _t: std::marker::PhantomData,
    })
}

#[cfg(test)]
#[path = "channel_tests.rs"]
mod tests;
