//! Plans: typed descriptions of links kept by the system until an executor
//! instantiates them with its own transport (in-process channels, threads,
//! processes).

use std::any::Any;
use std::borrow::Cow;
use std::cell::RefCell;
use std::marker::PhantomData;
use std::rc::Rc;

use super::port::{Dest, InPort, LocalIn, LocalOut, More, OutPort};
use super::{AnyChannel, Channel, Channels, Port, Shared, ThreadHalves, remote, thread};
use crate::buffer::{Access, In, Out, Payload};
use crate::kinds::Policy;

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
        let mut dests = (self.links.iter()).map(|&l| Dest::new(l, channels.shared::<T>(l)?));
        let first = dests.next()??;
        // The further destinations of a fan-out (none: no allocation).
        let more = dests.collect::<Option<Vec<_>>>()?;
        let port: Box<dyn OutPort<O>> = Box::new(LocalOut {
            first,
            access: self.port.access,
            more: (!more.is_empty()).then(|| Box::new(More(more))),
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
            // 32 bits: a system of more links would not fit in memory.
            link: u32::try_from(self.link).ok()?,
            observed: true,
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
    /// The channel, erased twice: as `Any` (a `Shared<T>`) and for its
    /// statistics (one allocation: both are the same `Rc`).
    fn local(&self) -> (Rc<dyn Any>, Rc<RefCell<dyn AnyChannel>>);
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
    fn local(&self) -> (Rc<dyn Any>, Rc<RefCell<dyn AnyChannel>>) {
        let shared: Shared<T> = Rc::new(RefCell::new(Channel::new(self.policy)));
        let stats: Rc<RefCell<dyn AnyChannel>> = shared.clone();
        (shared, stats)
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
