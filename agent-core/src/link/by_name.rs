//! Buffers found by name (links made from a spec): the link layer's
//! constructors of [`BufferPort`], which carry the typed plans of their end.

use std::any::TypeId;
use std::borrow::Cow;

use crate::buffer::{BufferPort, Direction, FanIndex, In, Out, Payload};
use crate::kinds::Policy;

use super::{Access, ChannelPlan, InPlan, OutPlan, Port, TypedInPlan, TypedOutPlan, channel_plan};

// ---------------------------------------------------------------------------
// Buffers found by name (links made from a spec)

/// What the link layer keeps in a [`BufferPort`]: how to make the link's channel
/// and the typed plan of this end.
struct PlanMakers {
    channel: fn(Policy) -> Box<dyn ChannelPlan>,
    plan: PlanMaker,
}

enum PlanMaker {
    Out(Box<dyn Fn(usize) -> Box<dyn OutPlan>>),
    In(Box<dyn Fn(usize, Cow<'static, str>) -> Box<dyn InPlan>>),
}

/// The link layer's constructors of [`BufferPort`] (defined with the buffers, so
/// that describing buffers does not depend on links).
impl BufferPort {
    /// The output buffer `port` of struct `O`.
    pub fn output<O, T, A>(port: Port<O, Out<T>, A>) -> BufferPort
    where
        O: Send + 'static,
        T: Payload,
        A: Access<O, Out<T>>,
    {
        BufferPort {
            name: port.name,
            peer: port.peer,
            direction: Direction::Out,
            payload: TypeId::of::<T>(),
            payload_name: std::any::type_name::<T>(),
            fan: port.fan.map(fan_index::<O>),
            plans: Box::new(PlanMakers {
                channel: channel_plan::<T>,
                plan: PlanMaker::Out(Box::new(move |link| {
                    Box::new(TypedOutPlan {
                        port,
                        links: vec![link],
                    })
                })),
            }),
        }
    }

    /// The input buffer `port` of struct `I`.
    pub fn input<I, T, A>(port: Port<I, In<T>, A>) -> BufferPort
    where
        I: Send + 'static,
        T: Payload,
        A: Access<I, In<T>>,
    {
        BufferPort {
            name: port.name,
            peer: port.peer,
            direction: Direction::In,
            payload: TypeId::of::<T>(),
            payload_name: std::any::type_name::<T>(),
            fan: port.fan.map(fan_index::<I>),
            plans: Box::new(PlanMakers {
                channel: channel_plan::<T>,
                plan: PlanMaker::In(Box::new(move |link, name| {
                    Box::new(TypedInPlan { port, link, name })
                })),
            }),
        }
    }

    /// The buffer `field` of the group that `group` (a projection from `B`: a
    /// `fn`, or a closure holding a [`Fan`](crate::Fan)'s index) returns; the
    /// port is named `group_name.field`. For derived code: `Group` lookups.
    pub fn in_group<B, G, T>(
        group_name: &'static str,
        group: impl Access<B, G>,
        field_name: &'static str,
        field: fn(&mut G) -> &mut In<T>,
    ) -> BufferPort
    where
        B: Send + 'static,
        G: crate::Group,
        T: Payload,
    {
        BufferPort::input(Port::new(
            intern(group_name, field_name),
            move |b: &mut B| field(group(b)),
            Some(G::PEER),
        ))
    }

    /// As [`BufferPort::in_group`], for an output buffer.
    pub fn out_group<B, G, T>(
        group_name: &'static str,
        group: impl Access<B, G>,
        field_name: &'static str,
        field: fn(&mut G) -> &mut Out<T>,
    ) -> BufferPort
    where
        B: Send + 'static,
        G: crate::Group,
        T: Payload,
    {
        BufferPort::output(Port::new(
            intern(group_name, field_name),
            move |b: &mut B| field(group(b)),
            Some(G::PEER),
        ))
    }

    fn makers(&self) -> Option<&PlanMakers> {
        self.plans.downcast_ref()
    }

    /// The channel of a link from this buffer (`None` only for a port not made
    /// by these constructors, which cannot be).
    pub(crate) fn channel(&self, policy: Policy) -> Option<Box<dyn ChannelPlan>> {
        Some((self.makers()?.channel)(policy))
    }

    pub(crate) fn out_plan(&self, link: usize) -> Option<Box<dyn OutPlan>> {
        match &self.makers()?.plan {
            PlanMaker::Out(make) => Some(make(link)),
            PlanMaker::In(_) => None,
        }
    }

    pub(crate) fn in_plan(&self, link: usize, name: Cow<'static, str>) -> Option<Box<dyn InPlan>> {
        match &self.makers()?.plan {
            PlanMaker::In(make) => Some(make(link, name)),
            PlanMaker::Out(_) => None,
        }
    }
}

/// A typed port's fan element as the builder checks it.
fn fan_index<B: 'static>(
    (group, index, len): (&'static str, usize, fn(&mut B) -> usize),
) -> FanIndex {
    FanIndex {
        group,
        index,
        len: Box::new(move |any| any.downcast_mut::<B>().map(len)),
    }
}

/// `group.field` as a `&'static str` ([`intern_name`](crate::names::intern_name)).
fn intern(group: &str, field: &str) -> &'static str {
    crate::names::intern_name(format!("{group}.{field}"))
}
