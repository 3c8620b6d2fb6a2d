//! Buffers: the only way subsystems exchange data.
//!
//! In the paper a subsystem has input buffers `_x c`, output buffers `_y c` and an
//! internal memory `^c c`. Here an input buffer field is an [`In<T>`], an output
//! buffer field is an [`Out<T>`], and the memory is a plain struct of the user's.
//!
//! Buffers are grouped by the component they are connected to (the paper's leading
//! superscript: `^e_y c` are the outputs of `c` towards its virtual effector). A group
//! is a struct implementing [`Group`]; a transition function that writes towards one
//! target receives `&mut` to that group only, so it cannot write anywhere else.

use std::any::{Any, TypeId};
use std::borrow::Cow;
#[cfg(feature = "audit")]
use std::cell::Cell;
use std::fmt;

use serde::Serialize;
use serde::de::DeserializeOwned;

use crate::error::BufferError;
use crate::kinds::NodeKind;
use crate::time::Stamp;

/// What may travel through a buffer.
///
/// `Serialize`/`Deserialize` are required so that every transfer can be recorded,
/// replayed and sent between processes; `Clone` so that one output can feed several
/// inputs; `Debug` so that traces and test failures are readable.
pub trait Payload: Clone + fmt::Debug + Serialize + DeserializeOwned + Send + 'static {}

impl<T> Payload for T where T: Clone + fmt::Debug + Serialize + DeserializeOwned + Send + 'static {}

/// A group of buffers connected to one peer: the paper's leading superscript.
///
/// For a control subsystem, a group whose `PEER` is [`NodeKind::Control`] is a
/// group of transmission buffers towards (or from) another agent, the paper's `T`.
///
/// ```
/// use agent_core::{Group, NodeKind, Out};
/// /// `^e_y c`: what the control subsystem sends to its virtual effector.
/// #[derive(Debug, Default)]
/// struct ToValve {
///     flow: Out<f64>,
/// }
/// impl Group for ToValve {
///     const PEER: NodeKind = NodeKind::VirtualEffector;
/// }
/// ```
pub trait Group: Sized + Send + 'static {
    /// The kind of component at the other end of every buffer in this group.
    const PEER: NodeKind;

    /// The buffer `buffer` of this group, reached from a struct `B` through
    /// `group` (the field `group_name`), for links made by name. `#[derive(Group)]`
    /// writes it; a hand-written group has no buffers found by name.
    ///
    /// `group` is any projection (a `fn`, or a closure holding an index: a
    /// [`Fan`]'s element `k` is reached through one).
    fn buffer_port<B: Send + 'static>(
        group_name: &'static str,
        group: impl Access<B, Self>,
        buffer: &str,
    ) -> Option<BufferPort> {
        let _ = (group_name, group, buffer);
        None
    }
}

/// How a [`Port`](crate::Port) reaches its field: a projection from the buffer
/// struct `B` to the field `X`. Usually a closure made by [`port!`](crate::port),
/// which the compiler inlines into the link's transfer code; a [`Fan`]'s element
/// carries its index in it.
pub trait Access<B, X>: for<'a> Fn(&'a mut B) -> &'a mut X + Copy + Send + 'static {}

impl<B, X, F> Access<B, X> for F where F: for<'a> Fn(&'a mut B) -> &'a mut X + Copy + Send + 'static {}

/// Whether a buffer is an input or an output.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Direction {
    /// An [`In`] buffer.
    In,
    /// An [`Out`] buffer.
    Out,
}

/// One buffer of a component, found by its name (`e11.q_est`) rather than through
/// its type: what a link made from a spec needs. The derives write the lookup
/// ([`Buffers::port`](crate::Buffers::port)) with the constructors of the link
/// layer ([`BufferPort::input`], [`BufferPort::output`], [`BufferPort::in_group`],
/// [`BufferPort::out_group`]); the system builder checks that both ends carry the
/// same payload type and makes the same typed link plan as
/// [`SystemBuilder::connect`](crate::SystemBuilder::connect) does.
pub struct BufferPort {
    pub(crate) name: &'static str,
    pub(crate) peer: Option<NodeKind>,
    pub(crate) direction: Direction,
    pub(crate) payload: TypeId,
    pub(crate) payload_name: &'static str,
    /// The link layer's typed plan makers, erased: buffers and their descriptions
    /// name this type without depending on links.
    pub(crate) plans: Box<dyn Any>,
    /// For a buffer of one element of a [`Fan`]: which element, and how to
    /// count the fan's elements in the component's buffer struct (the builder
    /// checks the index against it).
    pub(crate) fan: Option<FanIndex>,
}

/// The element of a [`Fan`] a [`BufferPort`] reaches, checked when the link is
/// made: the fan's length is known only from the component's buffers.
pub(crate) struct FanIndex {
    /// The fan's field (`c1`).
    pub(crate) group: &'static str,
    /// The element (`3` in `c1[3].plan`).
    pub(crate) index: usize,
    /// The fan's length in a buffer struct given as `Any` (`None`: another type).
    pub(crate) len: FanLen,
}

/// How a [`FanIndex`] counts its fan's elements in an erased buffer struct.
pub(crate) type FanLen = Box<dyn Fn(&mut dyn Any) -> Option<usize>>;

impl fmt::Debug for BufferPort {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "BufferPort({} {:?}: {})",
            self.name, self.direction, self.payload_name
        )
    }
}

impl BufferPort {
    /// The buffer's path (`e11.q_est`).
    pub fn name(&self) -> &'static str {
        self.name
    }

    /// The peer kind declared by its group, if any.
    pub fn peer(&self) -> Option<NodeKind> {
        self.peer
    }

    /// Input or output.
    pub fn direction(&self) -> Direction {
        self.direction
    }

    /// The payload's Rust type name.
    pub fn payload_name(&self) -> &'static str {
        self.payload_name
    }

    pub(crate) fn payload(&self) -> TypeId {
        self.payload
    }
}

/// An input buffer: the latest value received, whether it is new, and its stamp.
///
/// `is_new()` is the paper's `isnew(buf)`: it is true during exactly the one
/// iteration whose read brought the value in, and false afterwards until another
/// value arrives. The value itself stays readable (`get()`) until it is replaced.
pub struct In<T> {
    value: Option<T>,
    new: bool,
    stamp: Option<Stamp>,
    /// The name of the link that feeds it, boxed (8 bytes here, none while
    /// unlinked): cold, read only by errors and descriptions, so that the
    /// buffer an action reads is 16 bytes smaller.
    name: Option<Box<Cow<'static, str>>>,
    /// Whether a transition function looked at the buffer since the last
    /// [`Buffer::take_read`](crate::describe::Buffer::take_read): what an audit
    /// of reads observes (`ExecConfig::audit`). Only with the `audit` feature: the
    /// mark costs a few nanoseconds per action.
    #[cfg(feature = "audit")]
    read: Cell<bool>,
}

impl<T> Default for In<T> {
    fn default() -> Self {
        In {
            value: None,
            new: false,
            stamp: None,
            name: None,
            #[cfg(feature = "audit")]
            read: Cell::new(false),
        }
    }
}

impl<T: Clone> Clone for In<T> {
    fn clone(&self) -> Self {
        In {
            value: self.value.clone(),
            new: self.new,
            stamp: self.stamp,
            name: self.name.clone(),
            #[cfg(feature = "audit")]
            read: Cell::new(false),
        }
    }
}

impl<T: fmt::Debug> fmt::Debug for In<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (&self.value, self.new) {
            (None, _) => f.write_str("∅"),
            (Some(v), true) => write!(f, "new {v:?}"),
            (Some(v), false) => write!(f, "old {v:?}"),
        }
    }
}

impl<T> In<T> {
    /// An input buffer holding `value`, new in this iteration (for tests and
    /// environment models).
    pub fn new_value(value: T, stamp: Stamp) -> Self {
        In {
            value: Some(value),
            new: true,
            stamp: Some(stamp),
            name: None,
            #[cfg(feature = "audit")]
            read: Cell::new(false),
        }
    }

    /// `isnew(buf)`: whether the last read brought a value not seen before.
    #[inline]
    pub fn is_new(&self) -> bool {
        self.mark_read();
        self.new
    }

    /// The latest value received, new or not; `None` if nothing was ever received.
    #[inline]
    pub fn get(&self) -> Option<&T> {
        self.mark_read();
        self.value.as_ref()
    }

    /// The value only if it is new in this iteration.
    #[inline]
    pub fn fresh(&self) -> Option<&T> {
        self.mark_read();
        if self.new { self.value.as_ref() } else { None }
    }

    /// The latest value, or [`BufferError::NoData`] if nothing was ever received.
    ///
    /// Use it with `?` in a transition function that cannot proceed without data:
    /// the executor reports the error with the subsystem, behaviour and iteration.
    pub fn require(&self) -> Result<&T, BufferError> {
        self.mark_read();
        self.value.as_ref().ok_or_else(|| BufferError::NoData {
            buffer: match self.name.as_deref() {
                Some(name) if !name.is_empty() => name.clone(),
                _ => Cow::Borrowed("<unlinked>"),
            },
        })
    }

    /// Whether a value was ever received.
    pub fn has_data(&self) -> bool {
        self.mark_read();
        self.value.is_some()
    }

    /// When the current value was written (writer's iteration and time).
    pub fn stamp(&self) -> Option<Stamp> {
        self.mark_read();
        self.stamp
    }

    /// `isnew` without counting as a read (for the framework's own bookkeeping).
    #[inline]
    pub(crate) fn peek_new(&self) -> bool {
        self.new
    }

    /// Record a read (with the `audit` feature; nothing without it).
    #[inline(always)]
    fn mark_read(&self) {
        #[cfg(feature = "audit")]
        self.read.set(true);
    }

    /// Whether a transition function read the buffer since the last call; clears it.
    #[cfg(feature = "audit")]
    #[inline]
    pub(crate) fn take_read(&self) -> bool {
        self.read.replace(false)
    }

    /// Without the `audit` feature reads are not recorded: always false.
    #[cfg(not(feature = "audit"))]
    #[inline]
    pub(crate) fn take_read(&self) -> bool {
        false
    }

    /// The name of the link that feeds this buffer (empty until linked).
    pub fn name(&self) -> &str {
        self.name.as_deref().map_or("", |name| name.as_ref())
    }

    /// Deliver a new value, as a link does on a read (for environment models in tests).
    pub fn deliver(&mut self, value: T, stamp: Stamp) {
        self.value = Some(value);
        self.new = true;
        self.stamp = Some(stamp);
    }

    /// Mark the current value as already seen, as a read that brings nothing does.
    pub fn age(&mut self) {
        self.new = false;
    }

    /// Runtime side: whether the last read brought a value (without counting
    /// as the node's read of the buffer, as [`In::is_new`] does).
    pub(crate) fn took(&self) -> bool {
        self.new
    }

    /// Runtime side of a read: swap the slot with `incoming` (recycling storage) and
    /// mark it new.
    pub(crate) fn swap_in(&mut self, incoming: &mut Option<T>, stamp: Stamp) {
        std::mem::swap(&mut self.value, incoming);
        self.new = self.value.is_some();
        self.stamp = Some(stamp);
    }

    pub(crate) fn set_name(&mut self, name: Cow<'static, str>) {
        self.name = (!name.is_empty()).then(|| Box::new(name));
    }
}

/// An output buffer: the value written in the current iteration, if any.
///
/// Only the outputs written by an action are sent; an output not written in an
/// iteration sends nothing, so the receiver's `is_new()` stays false.
pub struct Out<T> {
    value: Option<T>,
    written: bool,
}

impl<T> Default for Out<T> {
    fn default() -> Self {
        Out {
            value: None,
            written: false,
        }
    }
}

impl<T: fmt::Debug> fmt::Debug for Out<T> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.written() {
            Some(v) => write!(f, "{v:?}"),
            None => f.write_str("–"),
        }
    }
}

impl<T> Out<T> {
    /// Write `value`; it is sent at the end of the current elementary action.
    pub fn set(&mut self, value: T) {
        self.value = Some(value);
        self.written = true;
    }

    /// Write in place, reusing the storage of an earlier transfer (no allocation for
    /// `Vec`-like payloads once warmed up). The storage holds an unspecified earlier
    /// value (or `T::default()`); overwrite it completely.
    pub fn write_recycled(&mut self) -> &mut T
    where
        T: Default,
    {
        self.written = true;
        self.value.get_or_insert_with(T::default)
    }

    /// The value written in the current iteration, if any.
    pub fn written(&self) -> Option<&T> {
        if self.written {
            self.value.as_ref()
        } else {
            None
        }
    }

    /// Whether the current iteration wrote this output.
    pub fn is_written(&self) -> bool {
        self.written
    }

    /// Forget a write made in the current iteration (the executor does this when an
    /// action fails, so that a failed action sends nothing).
    pub fn discard(&mut self) {
        self.written = false;
    }

    /// Runtime side of a send: the slot to move or clone the value from, if written.
    pub(crate) fn pending(&mut self) -> Option<&mut Option<T>> {
        if self.written {
            self.written = false;
            Some(&mut self.value)
        } else {
            None
        }
    }
}

/// A group repeated once per peer, as many times as the system has peers: the
/// buffers of a subsystem towards M components of one kind when M is known
/// only when the system is built (an ontology agent dispatching plans to every
/// robot of a fleet).
///
/// A field `c1: Fan<FromRobot>` of an input or output struct is a group whose
/// element `k` is reached by name as `c1[k]` (a link made from a spec names
/// `c2.c1[3].plan`) or by [`port!`](crate::port) as `port!(Input, c1[3].plan)`.
/// Its length is fixed when the subsystem's buffers are made
/// ([`Fan::new`], given to
/// [`SystemBuilder::subsystem_with_buffers`](crate::SystemBuilder::subsystem_with_buffers));
/// a [`Default`] fan has no element, and a link to an element it does not have
/// is a build problem. A fan cannot grow or shrink: it derefs to a slice.
///
/// Described as its group (the same [`GroupShape`](crate::describe::GroupShape)
/// and fields); a buffer of the fan is fresh when it is fresh in any element.
///
/// ```
/// use agent_core::{Fan, Group, In, NodeKind};
/// #[derive(Debug, Default)]
/// struct FromRobot { ack: In<u32> }
/// impl Group for FromRobot { const PEER: NodeKind = NodeKind::Control; }
/// let robots: Fan<FromRobot> = Fan::new(3);
/// assert_eq!(robots.len(), 3);
/// assert!(robots.iter().all(|r| r.ack.get().is_none()));
/// ```
pub struct Fan<G> {
    groups: Box<[G]>,
}

impl<G> Default for Fan<G> {
    fn default() -> Self {
        Fan {
            groups: Box::new([]),
        }
    }
}

impl<G: Default> Fan<G> {
    /// A fan of `peers` groups, each its default (empty buffers).
    pub fn new(peers: usize) -> Self {
        Fan {
            groups: (0..peers).map(|_| G::default()).collect(),
        }
    }
}

impl<G> std::ops::Deref for Fan<G> {
    type Target = [G];
    fn deref(&self) -> &[G] {
        &self.groups
    }
}

impl<G> std::ops::DerefMut for Fan<G> {
    fn deref_mut(&mut self) -> &mut [G] {
        &mut self.groups
    }
}

/// A copy of every element (the input of a subsystem whose inputs are
/// `Clone`, as `agent!` makes them).
impl<G: Clone> Clone for Fan<G> {
    fn clone(&self) -> Self {
        Fan {
            groups: self.groups.clone(),
        }
    }
}

impl<G: fmt::Debug> fmt::Debug for Fan<G> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list().entries(self.groups.iter()).finish()
    }
}

/// `[3].plan` (what follows a fan's name in a buffer's path): the element and
/// the buffer. The index is written in decimal without leading zeros, so that
/// one element has one name.
pub(crate) fn fan_element(rest: &str) -> Option<(usize, &str)> {
    let (index, buffer) = rest.strip_prefix('[')?.split_once("].")?;
    let canonical = !index.is_empty()
        && index.bytes().all(|b| b.is_ascii_digit())
        && (index == "0" || !index.starts_with('0'));
    if !canonical || buffer.is_empty() {
        return None;
    }
    Some((index.parse().ok()?, buffer))
}

impl<G: Group> Group for Fan<G> {
    const PEER: NodeKind = G::PEER;

    /// `buffer` is `[k].name`: buffer `name` of element `k`, whose port is
    /// named `group_name[k].name`. Whether the fan has element `k` is checked
    /// when the link is made.
    fn buffer_port<B: Send + 'static>(
        group_name: &'static str,
        group: impl Access<B, Self>,
        buffer: &str,
    ) -> Option<BufferPort> {
        let (index, buffer) = fan_element(buffer)?;
        let element = crate::names::intern_name(format!("{group_name}[{index}]"));
        let mut port = G::buffer_port(
            element,
            move |b: &mut B| &mut group(b).groups[index],
            buffer,
        )?;
        if port.fan.is_some() {
            // A fan of fans: one index is checked, so none is made.
            return None;
        }
        port.fan = Some(FanIndex {
            group: group_name,
            index,
            len: Box::new(move |any| any.downcast_mut::<B>().map(|b| group(b).len())),
        });
        Some(port)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::time::Time;

    #[test]
    fn in_buffer_freshness() {
        let mut x: In<u32> = In::default();
        assert!(!x.is_new());
        assert_eq!(x.get(), None);
        assert_eq!(
            x.require(),
            Err(BufferError::NoData {
                buffer: "<unlinked>".into()
            })
        );
        let stamp = Stamp::new(3, Time::from_nanos(10));
        x.deliver(7, stamp);
        assert!(x.is_new());
        assert_eq!(x.fresh(), Some(&7));
        assert_eq!(x.stamp(), Some(stamp));
        x.age();
        assert!(!x.is_new());
        assert_eq!(x.fresh(), None);
        assert_eq!(x.get(), Some(&7), "an old value stays readable");
        assert_eq!(format!("{x:?}"), "old 7");
    }

    #[test]
    fn an_in_buffer_is_named_after_its_link_and_errors_say_so() {
        let mut x: In<u32> = In::default();
        assert_eq!(x.name(), "");
        x.set_name(Cow::Borrowed("c.plan"));
        assert_eq!(x.name(), "c.plan");
        assert_eq!(x.clone().name(), "c.plan", "a copy keeps the name");
        assert_eq!(
            x.require(),
            Err(BufferError::NoData {
                buffer: "c.plan".into()
            })
        );
        x.set_name(Cow::Owned(String::new()));
        assert_eq!(x.name(), "");
        assert_eq!(
            x.require(),
            Err(BufferError::NoData {
                buffer: "<unlinked>".into()
            })
        );
    }

    #[test]
    fn out_buffer_sends_only_what_was_written() {
        let mut y: Out<Vec<u8>> = Out::default();
        assert!(y.pending().is_none());
        y.set(vec![1, 2]);
        assert_eq!(y.written(), Some(&vec![1, 2]));
        let slot = y.pending().expect("written");
        assert_eq!(slot.as_deref(), Some(&[1u8, 2][..]));
        assert!(y.pending().is_none(), "sent once");
        y.write_recycled().push(3);
        y.discard();
        assert!(y.pending().is_none(), "a discarded write is not sent");
    }
}
