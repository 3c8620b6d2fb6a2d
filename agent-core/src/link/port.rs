//! Ports: the per-component halves of links. The in-process halves
//! ([`LocalOut`], [`LocalIn`]) keep only what a transfer touches, so that a
//! port costs one cache line; the observer hears of a transfer or a read only
//! when it asked for it ([`LinkEvents`](crate::trace::LinkEvents)).

use std::borrow::Cow;
use std::marker::PhantomData;

use super::{Access, Shared};
use crate::buffer::{In, Out, Payload};
use crate::error::LinkError;
use crate::time::{Stamp, Time};
use crate::trace::{
    LinkInfo, LinkWant, NodeEvents, Observer, ReadEvent, SendStamps, TransferEvent,
};

/// The events an observer needs, asked at the start of a run
/// ([`Observer::link_events`], [`Observer::node_events`]); an entry not
/// given (an executor that asks nothing) is every event.
#[derive(Debug, Default)]
pub(crate) struct Wants {
    /// Per link, its sends and reads.
    pub(crate) links: Vec<LinkWant>,
    /// Per node, its transitions and activations.
    pub(crate) nodes: Vec<NodeEvents>,
}

impl Wants {
    /// Every event of every link and node.
    pub(crate) const ALL: Wants = Wants {
        links: Vec::new(),
        nodes: Vec::new(),
    };
}

/// What ports need from the executor during a transfer.
pub(crate) struct LinkCx<'a> {
    /// The instant being executed.
    pub(crate) time: Time,
    pub(crate) observer: Option<&'a mut dyn Observer>,
    /// The events the observer needs (one reference: a transfer without an
    /// observer pays nothing for it).
    pub(crate) wants: &'a Wants,
    pub(crate) links: &'a [LinkInfo],
    /// The last sends' instants the observer asked the executor to keep
    /// ([`LinkEvents::stamps`]).
    pub(crate) stamps: Option<&'a SendStamps>,
    /// The system's environment, for drivers.
    pub(crate) environment: Option<&'a mut (dyn std::any::Any + Send)>,
}

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
    /// The observer's needs, per link, once at the start of a run: a port
    /// may leave out, before anything else, the sends of links whose
    /// observer needs none of them. A port never told keeps every event.
    fn observe(&mut self, _links: &[LinkWant]) {}
    /// The addresses a send touches beyond the port itself (its channels'),
    /// pushed onto `to`: what the executor asks the cache for a few nodes
    /// ahead ([`crate::cache`]). A port that touches nothing else pushes
    /// nothing.
    fn reach(&self, _to: &mut Vec<usize>) {}
}

pub(crate) trait InPort<I> {
    /// Take what the link holds into the buffer; a link between processes may
    /// report a problem instead (the buffer then ages).
    fn read(&mut self, x: &mut I, cx: &mut LinkCx<'_>) -> Result<(), LinkError>;
    /// Called once when the port is installed: names the buffer after its link.
    fn attach(&self, x: &mut I);
    /// As [`OutPort::observe`], for the reads.
    fn observe(&mut self, _links: &[LinkWant]) {}
    /// As [`OutPort::reach`], for a read.
    fn reach(&self, _to: &mut Vec<usize>) {}
}

/// One destination of an in-process send: its link, whether the observer
/// needs any of the link's sends ([`OutPort::observe`]; every send until
/// told) and their instants kept ([`LinkEvents::stamps`]), and its channel.
pub(crate) struct Dest<T> {
    pub(super) link: u32,
    pub(super) observed: bool,
    pub(super) stamped: bool,
    pub(super) channel: Shared<T>,
}

impl<T> Dest<T> {
    /// `None` for a link index past 32 bits (a system that large would not
    /// fit in memory).
    pub(super) fn new(link: usize, channel: Shared<T>) -> Option<Dest<T>> {
        Some(Dest {
            link: u32::try_from(link).ok()?,
            observed: true,
            stamped: false,
            channel,
        })
    }

    fn observe(&mut self, links: &[LinkWant]) {
        let wants = links.get(self.link as usize).map(|w| &w.events);
        self.observed = wants.is_none_or(|w| w.transfers || !w.out_of.is_empty());
        self.stamped = wants.is_some_and(|w| w.stamps);
    }
}

/// The sending half of in-process links: what an action's send touches, in
/// its first bytes (the port's accessor of the buffer, not its name and
/// checks, which the plan keeps), so that a port costs one cache line.
#[repr(C)]
pub(crate) struct LocalOut<O, T, A> {
    /// The first destination, inline: most outputs have one.
    pub(super) first: Dest<T>,
    /// The output buffer, from the output struct.
    pub(super) access: A,
    /// Further destinations of a fanned-out output, boxed (8 bytes; none for
    /// most outputs) so that the port is 24 bytes and its neighbours share
    /// its cache line.
    pub(super) more: Option<Box<More<T>>>,
    pub(super) _o: PhantomData<fn(&mut O)>,
}

/// The destinations of a fanned-out [`LocalOut`] after its first.
pub(super) struct More<T>(pub(super) Vec<Dest<T>>);

impl<O, T: Payload, A> LocalOut<O, T, A> {
    #[inline(always)]
    fn put(
        &self,
        dest: &Dest<T>,
        value: &mut Option<T>,
        last: bool,
        stamp: Stamp,
        cx: &mut LinkCx<'_>,
    ) -> Result<(), Refused> {
        let link = dest.link as usize;
        // Without an observer, one test: a run unobserved pays nothing more.
        if let Some(obs) = cx.observer.as_deref_mut() {
            if dest.stamped
                && let Some(stamps) = cx.stamps
            {
                stamps.sent(link, stamp.time);
            }
            if let Some(v) = value.as_ref()
                && dest.observed
                && cx.wants.links.get(link).is_none_or(|w| w.transfer(v))
            {
                obs.transfer(&TransferEvent { link, stamp }, v);
            }
        }
        dest.channel
            .borrow_mut()
            .put(value, last, stamp)
            .map_err(|bound| Refused {
                link,
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

    fn observe(&mut self, links: &[LinkWant]) {
        self.first.observe(links);
        if let Some(more) = &mut self.more {
            more.0.iter_mut().for_each(|d| d.observe(links));
        }
    }

    fn reach(&self, to: &mut Vec<usize>) {
        super::reach(&self.first.channel, to);
        if let Some(more) = &self.more {
            // The box (the list's header), then the list.
            crate::cache::address_of(&**more, to);
            crate::cache::address_of(more.0.as_slice(), to);
            more.0.iter().for_each(|d| super::reach(&d.channel, to));
        }
    }
}

/// The receiving half of an in-process link: what a read touches first (see
/// [`LocalOut`]), the buffer's name (given once) last.
#[repr(C)]
pub(crate) struct LocalIn<I, T, A> {
    pub(super) channel: Shared<T>,
    pub(super) link: u32,
    /// Whether the observer needs any of the link's reads
    /// ([`InPort::observe`]; every read until told).
    pub(super) observed: bool,
    /// The input buffer, from the input struct.
    pub(super) access: A,
    /// Given to the buffer once ([`InPort::attach`]), boxed (8 bytes) so that
    /// the port is 24 bytes and its neighbours share its cache line.
    pub(super) name: Box<Cow<'static, str>>,
    pub(super) _i: PhantomData<fn(&mut I)>,
}

/// Tell the observer that the buffer `x` just took a value from `link` (if it
/// did), or holds one older than the observer's bound
/// ([`LinkEvents::older_than`](crate::trace::LinkEvents::older_than)).
#[inline]
pub(crate) fn observe_read<T>(x: &In<T>, link: usize, cx: &mut LinkCx<'_>) {
    let Some(obs) = cx.observer.as_deref_mut() else {
        return;
    };
    let new = x.is_new();
    let Some(stamp) = x.stamp() else {
        return;
    };
    let told = match cx.wants.links.get(link) {
        Some(w) => w
            .events
            .read(new, cx.time.as_nanos(), stamp.time.as_nanos()),
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
        if cx.observer.is_some() && self.observed {
            observe_read(x, self.link as usize, cx);
        }
        Ok(())
    }

    fn attach(&self, x: &mut I) {
        (self.access)(x).set_name((*self.name).clone());
    }

    fn observe(&mut self, links: &[LinkWant]) {
        self.observed = (links.get(self.link as usize))
            .is_none_or(|w| w.events.reads || w.events.older_than.is_some());
    }

    fn reach(&self, to: &mut Vec<usize>) {
        super::reach(&self.channel, to);
    }
}
