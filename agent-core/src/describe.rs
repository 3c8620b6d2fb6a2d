//! Static descriptions of components: the name and type of every memory field and
//! buffer, the groups buffers form, and which buffers are fresh.
//!
//! The runtime and the spec tools read these descriptions; nobody writes them by hand:
//! the derives of the macros crate (`#[derive(Group)]`, `#[derive(Buffers)]`,
//! `#[derive(Memory)]`, `#[derive(Subsystem)]`) generate them from the structs. They
//! are `const` data, so describing a component costs nothing at run time.
//!
//! * [`Fields`]: the named fields of a memory struct or of one group of buffers.
//! * [`Buffers`]: the groups of an input or output struct (or the flat buffers of a
//!   driver), and [`Buffers::fresh`], the paper's `isnew` of every buffer at once.
//! * [`Shape`]: a whole component, returned by [`Subsystem::shape`] and
//!   [`Driver::shape`]; the system builder records it in [`NodeInfo`], from which
//!   `agent-spec` exports a RON spec.
//!
//! [`Subsystem::shape`]: crate::Subsystem::shape
//! [`Driver::shape`]: crate::Driver::shape
//! [`NodeInfo`]: crate::NodeInfo

use std::fmt;

use crate::buffer::{BufferPort, Direction, In, Out};
use crate::kinds::NodeKind;

/// A memory field or a buffer: its name and its Rust type as written in the source.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Field {
    /// The field's name (`level`).
    pub name: &'static str,
    /// The Rust type of the value (`f64`, `Option<Order>`; for a buffer the payload
    /// type, without `In<...>` or `Out<...>`).
    pub ty: &'static str,
}

/// Types whose named fields are described: memory structs and groups of buffers.
#[diagnostic::on_unimplemented(
    message = "`{Self}` does not describe its fields",
    label = "no field description",
    note = "derive it: `#[derive(Memory)]` on a memory struct, `#[derive(Group)]` on a group of buffers"
)]
pub trait Fields {
    /// Every field, in declaration order.
    const FIELDS: &'static [Field];
}

/// A subsystem without memory.
impl Fields for () {
    const FIELDS: &'static [Field] = &[];
}

/// [`In`] and [`Out`]: the two kinds of buffer field.
pub trait Buffer {
    /// Input or output.
    const DIRECTION: Direction;
    /// `isnew(buf)` for an input (a value arrived with the last read); for an output,
    /// whether the current iteration wrote it.
    fn is_fresh(&self) -> bool;

    /// For an input: whether a transition function read it since the last call
    /// (which clears the mark); always false for an output. What an audit of reads
    /// observes ([`ExecConfig::audit`](crate::ExecConfig::audit)).
    fn take_read(&self) -> bool {
        false
    }
}

impl<T> Buffer for In<T> {
    const DIRECTION: Direction = Direction::In;
    #[inline]
    fn is_fresh(&self) -> bool {
        self.peek_new()
    }
    #[inline]
    fn take_read(&self) -> bool {
        In::take_read(self)
    }
}

impl<T> Buffer for Out<T> {
    const DIRECTION: Direction = Direction::Out;
    #[inline]
    fn is_fresh(&self) -> bool {
        self.is_written()
    }
}

/// One group of buffers of a component: the buffers connected to one peer.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct GroupShape {
    /// The field holding the group (`pump`); empty for the flat buffers of a driver.
    pub name: &'static str,
    /// The kind of component at the other end, if the group declares it.
    pub peer: Option<NodeKind>,
    /// The group's Rust type as written (`FlowToPumpControl`); empty for flat buffers.
    pub ty: &'static str,
    /// Input or output buffers.
    pub direction: Direction,
    /// The buffers.
    pub buffers: &'static [Field],
}

/// The most buffers one input or output struct may have: [`Fresh`] is a bit set.
pub const MAX_BUFFERS: usize = 128;

/// Which buffers of an input or output struct are fresh: bit `k` is the `k`-th
/// buffer of [`Buffers::GROUPS`], counted across the groups in order.
#[derive(Clone, Copy, Default, PartialEq, Eq, Hash)]
pub struct Fresh(pub u128);

impl Fresh {
    /// Whether buffer number `k` is fresh.
    #[inline]
    pub fn contains(self, k: usize) -> bool {
        k < MAX_BUFFERS && self.0 >> k & 1 == 1
    }

    /// How many buffers are fresh.
    pub fn count(self) -> u32 {
        self.0.count_ones()
    }

    /// Whether no buffer is fresh.
    pub fn is_empty(self) -> bool {
        self.0 == 0
    }

    /// The fresh buffers of `groups` as `(group, buffer)` names.
    pub fn names(
        self,
        groups: &'static [GroupShape],
    ) -> impl Iterator<Item = (&'static str, &'static str)> {
        groups
            .iter()
            .flat_map(|g| g.buffers.iter().map(move |b| (g.name, b.name)))
            .enumerate()
            .filter(move |(k, _)| self.contains(*k))
            .map(|(_, names)| names)
    }
}

impl fmt::Debug for Fresh {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "Fresh({:#b})", self.0)
    }
}

/// The buffers of an input or output struct: a struct of groups (a subsystem's), a
/// struct of buffers (a driver's), or one group.
#[diagnostic::on_unimplemented(
    message = "`{Self}` does not describe its buffers",
    label = "no buffer description",
    note = "derive it: `#[derive(Buffers)]` on an input or output struct, `#[derive(Group)]` on a group"
)]
pub trait Buffers {
    /// The groups, in declaration order.
    const GROUPS: &'static [GroupShape];

    /// Which buffers are fresh now (inputs: new in this iteration; outputs: written
    /// in this iteration), in the order of [`Buffers::GROUPS`].
    fn fresh(&self) -> Fresh;

    /// Which buffers a transition function read since the last call (inputs only),
    /// in the order of [`Buffers::GROUPS`]; clears the marks. `#[derive(Buffers)]`
    /// writes it; the default sees nothing.
    fn take_reads(&self) -> Fresh {
        Fresh(0)
    }

    /// The buffer at `path` (`group.buffer`, or `buffer` in a driver's flat struct),
    /// for links made by name (from a spec). `#[derive(Buffers)]` writes it; the
    /// default finds nothing.
    fn port(path: &str) -> Option<BufferPort>
    where
        Self: Sized,
    {
        let _ = path;
        None
    }
}

/// How a component's buffers are found by name: the lookups of its input and
/// output structs. [`Subsystem::ports`](crate::Subsystem::ports) and
/// [`Driver::ports`](crate::Driver::ports) return it; the system builder uses it
/// to make links by name.
#[derive(Clone, Copy)]
pub struct PortTable {
    /// Finds an input buffer.
    pub inputs: fn(&str) -> Option<BufferPort>,
    /// Finds an output buffer.
    pub outputs: fn(&str) -> Option<BufferPort>,
}

impl fmt::Debug for PortTable {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("PortTable")
    }
}

impl PortTable {
    /// The lookups of input struct `I` and output struct `O` (what the provided
    /// `Driver::ports` and a derived `Subsystem` return).
    pub fn of<I: Buffers, O: Buffers>() -> PortTable {
        PortTable {
            inputs: I::port,
            outputs: O::port,
        }
    }
}

impl Buffers for () {
    const GROUPS: &'static [GroupShape] = &[];
    fn fresh(&self) -> Fresh {
        Fresh(0)
    }
}

/// The number of buffers in `groups` (for derives: the bit offset of the next group).
pub const fn buffer_count(groups: &[GroupShape]) -> usize {
    let mut n = 0;
    let mut i = 0;
    while i < groups.len() {
        n += groups[i].buffers.len();
        i += 1;
    }
    n
}

/// The description of a whole component.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Shape {
    /// The memory fields (`None` for a driver, whose state is its own business).
    pub memory: Option<&'static [Field]>,
    /// The input groups.
    pub inputs: &'static [GroupShape],
    /// The output groups.
    pub outputs: &'static [GroupShape],
}

/// A fan is described as its group ([`Fan`](crate::buffer::Fan)).
impl<G: Fields> Fields for crate::buffer::Fan<G> {
    const FIELDS: &'static [Field] = G::FIELDS;
}

impl<G: Buffers> Buffers for crate::buffer::Fan<G> {
    const GROUPS: &'static [GroupShape] = G::GROUPS;

    /// A buffer is fresh when it is fresh in any element.
    fn fresh(&self) -> Fresh {
        Fresh(self.iter().fold(0, |bits, g| bits | g.fresh().0))
    }

    fn take_reads(&self) -> Fresh {
        Fresh(self.iter().fold(0, |bits, g| bits | g.take_reads().0))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::time::{Stamp, Time};

    const A: &[Field] = &[
        Field {
            name: "a",
            ty: "f64",
        },
        Field {
            name: "b",
            ty: "u32",
        },
    ];
    const B: &[Field] = &[Field {
        name: "a",
        ty: "f64",
    }];
    const GROUPS: &[GroupShape] = &[
        GroupShape {
            name: "x",
            peer: Some(NodeKind::Control),
            ty: "X",
            direction: Direction::In,
            buffers: A,
        },
        GroupShape {
            name: "y",
            peer: None,
            ty: "Y",
            direction: Direction::In,
            buffers: B,
        },
    ];

    #[test]
    fn fresh_names_follow_the_groups() {
        assert_eq!(buffer_count(GROUPS), 3);
        let fresh = Fresh(0b101);
        assert_eq!(fresh.count(), 2);
        assert!(fresh.contains(2) && !fresh.contains(1) && !fresh.contains(200));
        let names: Vec<_> = fresh.names(GROUPS).collect();
        assert_eq!(names, [("x", "a"), ("y", "a")]);
    }

    #[test]
    fn buffers_report_their_freshness() {
        let mut x = In::<u8>::default();
        assert!(!x.is_fresh());
        x.deliver(1, Stamp::new(0, Time::ZERO));
        assert!(x.is_fresh());
        let mut y = Out::<u8>::default();
        y.set(2);
        assert!(y.is_fresh());
        assert_eq!(<In<u8> as Buffer>::DIRECTION, Direction::In);
    }
}
