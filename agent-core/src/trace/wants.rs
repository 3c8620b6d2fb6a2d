//! Which of a link's events an observer needs ([`LinkEvents`], asked once per
//! link at the start of a run, [`Observer::link_events`](super::Observer::link_events)):
//! the executor leaves out the others where the link sends or reads, before
//! any call to the observer. A contract monitor's range is a check compiled
//! into the sending link this way ([`NumberBound`]): the number at its field
//! path is read from the typed value as it is sent, and the observer hears of
//! the value only when it is out of bounds (or cannot be read).

use std::any::Any;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use serde::Serialize;

use super::pick::{Direct, FieldPath, Numbers, numbers};
use crate::time::Time;

/// Whether `x` lies within `[min, max]` (either end open when `None`; NaN
/// lies beyond any end given): the one definition of a range, shared by the checks
/// compiled into links and the monitors that judge them.
#[inline]
pub fn within(x: f64, min: Option<f64>, max: Option<f64>) -> bool {
    min.is_none_or(|m| x >= m) && max.is_none_or(|m| x <= m)
}

/// The instant of the last value sent into each link whose observer asked
/// for it ([`LinkEvents::stamps`]): kept by the deterministic executor, one
/// store a send, and read by the observer when it needs it
/// ([`Observer::stamps`](super::Observer::stamps)). A clone shares the table;
/// only the executor writes it.
#[derive(Clone, Debug)]
pub struct SendStamps(Arc<[AtomicU64]>);

impl SendStamps {
    /// A table for `links` links, nothing sent yet.
    pub(crate) fn new(links: usize) -> SendStamps {
        SendStamps((0..links).map(|_| AtomicU64::new(0)).collect())
    }

    /// A value was sent into `link` at `time` (a link past the table's is
    /// not kept).
    #[inline]
    pub(crate) fn sent(&self, link: usize, time: Time) {
        if let Some(at) = self.0.get(link) {
            // 0 is "nothing sent": an instant is kept one nanosecond late.
            at.store(time.as_nanos().saturating_add(1), Ordering::Relaxed);
        }
    }

    /// The instant of the last value sent into `link`, if any was (and the
    /// link is in the table).
    #[inline]
    pub fn last(&self, link: usize) -> Option<Time> {
        let at = self.0.get(link)?.load(Ordering::Relaxed);
        (at != 0).then(|| Time::from_nanos(at - 1))
    }
}

/// A number inside a link's values, by its field path, and the bounds it is
/// expected within.
#[derive(Clone, Debug, PartialEq)]
pub struct NumberBound {
    /// Where the number is in each value.
    pub path: FieldPath,
    /// The least expected.
    pub min: Option<f64>,
    /// The greatest expected.
    pub max: Option<f64>,
}

impl NumberBound {
    /// Whether `value` breaks the bound: its number is outside it, or it
    /// cannot be read (a failing `Serialize` impl). A value without a number
    /// at the path breaks nothing.
    #[inline]
    pub fn broken_by<T: Serialize + ?Sized>(&self, value: &T) -> bool {
        match self.path.number(value) {
            Ok(Some(x)) => !within(x, self.min, self.max),
            Ok(None) => false,
            Err(_) => true,
        }
    }
}

/// The events of one link an observer needs (see the module docs). It is a
/// hint: an executor may deliver more (a pair of observers gets the union of
/// their needs, the real-time executor every event), and an observer judges
/// the same whether or not it gets the events it did not ask for.
#[derive(Clone, Debug, PartialEq)]
pub struct LinkEvents {
    /// Every value sent ([`Observer::transfer`](super::Observer::transfer)).
    pub transfers: bool,
    /// Without `transfers`: the values sent that break one of these bounds,
    /// checked on the typed value where it is sent.
    pub out_of: Vec<NumberBound>,
    /// Every value taken ([`Observer::read`](super::Observer::read)).
    pub reads: bool,
    /// At each read by the link's reader, whether it takes a new value or
    /// not: a value older than this (ns, the read's instant less the value's
    /// stamp) is told, a new one through
    /// [`Observer::read`](super::Observer::read) (without `reads`, the new
    /// values this old only) and one the buffer still holds through
    /// [`Observer::held`](super::Observer::held). A freshness bound judged
    /// where the value is read.
    pub older_than: Option<u64>,
    /// Without `transfers`: the instant of the last value sent kept in the
    /// table given to [`Observer::stamps`](super::Observer::stamps), for an
    /// observer that reads it when it needs it (a rate judged when its
    /// window closes) rather than hear of every send. The deterministic
    /// executor keeps it; other executors tell every send instead.
    pub stamps: bool,
}

impl Default for LinkEvents {
    /// Every event.
    fn default() -> Self {
        LinkEvents::all()
    }
}

impl LinkEvents {
    /// Every event of the link.
    pub fn all() -> LinkEvents {
        LinkEvents {
            transfers: true,
            out_of: Vec::new(),
            reads: true,
            older_than: None,
            stamps: false,
        }
    }

    /// None of the link's sends and reads.
    pub fn none() -> LinkEvents {
        LinkEvents {
            transfers: false,
            out_of: Vec::new(),
            reads: false,
            older_than: None,
            stamps: false,
        }
    }

    /// What either `self` or `other` needs.
    pub fn union(mut self, other: LinkEvents) -> LinkEvents {
        self.transfers |= other.transfers;
        self.reads |= other.reads;
        self.stamps |= other.stamps;
        self.older_than = match (self.older_than, other.older_than) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
        if self.transfers {
            self.out_of.clear();
        } else {
            self.out_of.extend(other.out_of);
        }
        self
    }

    /// Whether the observer needs the send of `value`.
    #[inline]
    pub fn transfer<T: Serialize + ?Sized>(&self, value: &T) -> bool {
        self.transfers || self.out_of.iter().any(|b| b.broken_by(value))
    }

    /// How the observer is told of a read at `now` of a value stamped
    /// `stamp`, `new` or still held: `Some(true)` through
    /// [`Observer::read`](super::Observer::read), `Some(false)` through
    /// [`Observer::held`](super::Observer::held), `None` not at all.
    #[inline]
    pub fn read(&self, new: bool, now: u64, stamp: u64) -> Option<bool> {
        let old = || {
            self.older_than
                .is_some_and(|max| now.saturating_sub(stamp) > max)
        };
        match new {
            true => (self.reads || old()).then_some(true),
            false => old().then_some(false),
        }
    }
}

/// A link's [`LinkEvents`] as the deterministic executor keeps them for its
/// ports: the bounds whose paths read a number directly (the value itself,
/// or one index: [`FieldPath::number_of`]) also compiled into a flat list,
/// each missing end an infinity, checked without a walk on a value that is
/// an `f64`, an array of them or a `Vec<f64>` (a robot's wheel torques).
#[derive(Clone, Debug)]
pub(crate) struct LinkWant {
    pub(crate) events: LinkEvents,
    /// Every bound of `events.out_of` that can break, when each of them
    /// reads directly (`None`: some path does not).
    direct: Option<Box<[DirectBound]>>,
}

/// A bound read directly: where, and its ends (an infinity for a missing
/// one; `!(x >= lo && x <= hi)` then breaks exactly where
/// [`within`] does not hold, NaN included).
#[derive(Clone, Copy, Debug)]
struct DirectBound {
    /// The index read, [`WHOLE`] for the value itself.
    at: usize,
    lo: f64,
    hi: f64,
}

/// [`DirectBound::at`] of a bound on the value itself (no array is that
/// long).
const WHOLE: usize = usize::MAX;

impl DirectBound {
    #[inline(always)]
    fn broken_by(&self, x: f64) -> bool {
        !(x >= self.lo && x <= self.hi)
    }
}

impl LinkWant {
    pub(crate) fn new(events: LinkEvents) -> LinkWant {
        let direct = events
            .out_of
            .iter()
            // A bound without ends breaks with no number (`within`).
            .filter(|b| b.min.is_some() || b.max.is_some())
            .map(|b| {
                Some(DirectBound {
                    at: match b.path.direct()? {
                        Direct::Whole => WHOLE,
                        Direct::Index(i) => i.min(WHOLE - 1),
                    },
                    lo: b.min.unwrap_or(f64::NEG_INFINITY),
                    hi: b.max.unwrap_or(f64::INFINITY),
                })
            })
            .collect();
        LinkWant { events, direct }
    }

    /// [`LinkEvents::transfer`], a value of numbers checked against the
    /// compiled bounds: the same answer.
    #[inline(always)]
    pub(crate) fn transfer<T: Serialize + Any>(&self, value: &T) -> bool {
        if self.events.transfers {
            return true;
        }
        if let Some(direct) = &self.direct
            && let Some(numbers) = numbers(value)
        {
            return match numbers {
                Numbers::Many(xs) => direct
                    .iter()
                    .any(|b| xs.get(b.at).is_some_and(|&x| b.broken_by(x))),
                Numbers::One(x) => direct.iter().any(|b| b.at == WHOLE && b.broken_by(x)),
            };
        }
        self.events.transfer(value)
    }
}

/// The activations of one node an observer needs, asked once per node at the
/// start of a run of the deterministic executor
/// ([`Observer::node_events`](super::Observer::node_events)), which leaves out
/// the others. A hint, as [`LinkEvents`] is: other executors and observers may
/// deliver more. The predicates an observer wants are told after every
/// activation whether or not its action is
/// ([`Observer::predicates_wanted`](super::Observer::predicates_wanted)).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NodeEvents {
    /// Its FSM's transitions ([`Observer::transition`](super::Observer::transition)).
    pub transitions: bool,
    /// Its activations ([`Observer::action`](super::Observer::action)) in
    /// these behaviours: bit `b` for the FSM's behaviour `b` (bit 63 also for
    /// every behaviour past it); a driver's steps when any bit is set.
    pub actions: u64,
}

impl Default for NodeEvents {
    /// Every event.
    fn default() -> Self {
        NodeEvents::all()
    }
}

impl NodeEvents {
    /// Every transition and activation of the node.
    pub const fn all() -> NodeEvents {
        NodeEvents {
            transitions: true,
            actions: u64::MAX,
        }
    }

    /// None of them.
    pub const fn none() -> NodeEvents {
        NodeEvents {
            transitions: false,
            actions: 0,
        }
    }

    /// What either `self` or `other` needs.
    pub const fn union(self, other: NodeEvents) -> NodeEvents {
        NodeEvents {
            transitions: self.transitions || other.transitions,
            actions: self.actions | other.actions,
        }
    }

    /// Whether the observer needs an activation in `behaviour` (`None`: a
    /// driver's step).
    #[inline]
    pub const fn action(&self, behaviour: Option<usize>) -> bool {
        match behaviour {
            Some(b) => self.actions >> (if b < 63 { b } else { 63 }) & 1 == 1,
            None => self.actions != 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bound(path: &str, min: f64, max: f64) -> NumberBound {
        NumberBound {
            path: FieldPath::parse(path),
            min: Some(min),
            max: Some(max),
        }
    }

    #[test]
    fn a_value_is_delivered_when_it_breaks_a_bound_only() {
        let w = LinkEvents {
            transfers: false,
            out_of: vec![bound("0", -1.0, 1.0), bound("2", 0.0, 0.0)],
            reads: false,
            older_than: None,
            stamps: false,
        };
        assert!(!w.transfer(&[0.5f64, 9.0, 0.0]), "within both");
        assert!(
            !w.transfer(&[1.0f64, 9.0, 0.0]),
            "a bound is never broken by equality"
        );
        assert!(w.transfer(&[1.5f64, 0.0, 0.0]), "the first broken");
        assert!(w.transfer(&[0.0f64, 0.0, -0.1]), "the second broken");
        assert!(w.transfer(&[f64::NAN, 0.0, 0.0]), "NaN is within nothing");
        assert!(!w.transfer(&[0.0f64]), "no number at the second path");
        assert!(!LinkEvents::none().transfer(&[99.0f64]));
        assert!(LinkEvents::all().transfer(&[0.0f64]));
    }

    #[test]
    fn a_union_needs_what_either_needs() {
        let some = LinkEvents {
            transfers: false,
            out_of: vec![bound("0", -1.0, 1.0)],
            reads: false,
            older_than: None,
            stamps: false,
        };
        let u = some.clone().union(LinkEvents::none());
        assert_eq!(u, some);
        let u = LinkEvents::none().union(some.clone());
        assert_eq!(u, some);
        let u = some.clone().union(LinkEvents::all());
        assert_eq!(u, LinkEvents::all(), "every value: the bounds are moot");
        let u = some.clone().union(some.clone());
        assert_eq!(u.out_of.len(), 2);
        assert!(within(1.0, None, Some(1.0)) && !within(f64::NAN, Some(0.0), None));
        let bounded = |ns| LinkEvents {
            older_than: Some(ns),
            ..LinkEvents::none()
        };
        assert_eq!(bounded(50).union(bounded(20)).older_than, Some(20));
        let u = LinkEvents::all().union(bounded(50));
        assert!(
            u.reads && u.older_than == Some(50),
            "every read, and the held"
        );
        assert_eq!(some.union(bounded(50)).older_than, Some(50));
        let stamped = LinkEvents {
            stamps: true,
            ..LinkEvents::none()
        };
        let u = stamped.clone().union(LinkEvents::all());
        assert!(u.stamps && u.transfers, "both, each for its observer");
        assert_eq!(LinkEvents::none().union(stamped.clone()), stamped);
    }

    /// Numbers a range meets at its edges: the ends, just past them, the
    /// infinities and NaN.
    fn edgy() -> impl proptest::strategy::Strategy<Value = f64> {
        use proptest::prelude::*;
        prop_oneof![
            -12.0..12.0f64,
            Just(10.0),
            Just(-10.0),
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(f64::NEG_INFINITY),
        ]
    }

    /// Bounds on paths that read directly ("", "0".."5"), past an array's
    /// end, and that do not ("0.x", "x"); each end there or not, NaN too.
    fn bounds() -> impl proptest::strategy::Strategy<Value = Vec<NumberBound>> {
        use proptest::prelude::*;
        let path = prop_oneof![
            Just(String::new()),
            (0usize..6).prop_map(|i| i.to_string()),
            Just("0.x".to_owned()),
            Just("x".to_owned()),
        ];
        let end = proptest::option::of(prop_oneof![-10.0..10.0f64, Just(f64::NAN)]);
        let bound = (path, end.clone(), end).prop_map(|(p, min, max)| NumberBound {
            path: FieldPath::parse(&p),
            min,
            max,
        });
        proptest::collection::vec(bound, 0..5)
    }

    fn want(out_of: Vec<NumberBound>) -> (LinkEvents, LinkWant) {
        let events = LinkEvents {
            out_of,
            ..LinkEvents::none()
        };
        (events.clone(), LinkWant::new(events))
    }

    proptest::proptest! {
        /// The bounds compiled for values of numbers answer as the walk of
        /// each value through its `Serialize` impl does.
        #[test]
        fn compiled_bounds_answer_as_the_walk(
            out_of in bounds(),
            x in edgy(),
            four in proptest::array::uniform4(edgy()),
            some in proptest::collection::vec(edgy(), 0..6),
        ) {
            let (events, compiled) = want(out_of);
            proptest::prop_assert_eq!(compiled.transfer(&x), events.transfer(&x));
            proptest::prop_assert_eq!(compiled.transfer(&four), events.transfer(&four));
            proptest::prop_assert_eq!(compiled.transfer(&some), events.transfer(&some));
            // Not numbers: the walk itself.
            let pair = (four[0], some.clone());
            proptest::prop_assert_eq!(compiled.transfer(&pair), events.transfer(&pair));
        }
    }

    #[test]
    fn a_value_of_numbers_is_checked_without_a_walk_and_alike() {
        let (events, compiled) = want(vec![
            bound("1", -1.0, 1.0),
            NumberBound {
                path: FieldPath::parse("3"),
                min: None,
                max: Some(5.0),
            },
        ]);
        assert!(compiled.direct.as_ref().is_some_and(|d| d.len() == 2));
        for (value, broken) in [
            ([0.0, 0.5, 0.0, 5.0], false),
            ([9.0, -1.0, 9.0, f64::NEG_INFINITY], false),
            ([0.0, 1.5, 0.0, 0.0], true),
            ([0.0, 0.0, 0.0, 5.5], true),
            ([0.0, f64::NAN, 0.0, 0.0], true),
        ] {
            assert_eq!(compiled.transfer(&value), broken, "{value:?}");
            assert_eq!(events.transfer(&value), broken, "{value:?}");
            assert_eq!(compiled.transfer(&value.to_vec()), broken, "{value:?}");
        }
        assert!(!compiled.transfer(&[9.0f64]), "no number at either path");
        assert!(!compiled.transfer(&9.0f64), "a number has no parts");
        // A path that does not read directly: every bound walks.
        let (_, walked) = want(vec![bound("0.x", 0.0, 1.0), bound("0", 0.0, 1.0)]);
        assert!(walked.direct.is_none());
        assert!(walked.transfer(&[2.0f64]) && !walked.transfer(&[0.5f64]));
        // Without ends a bound breaks with nothing, NaN included.
        let (_, open) = want(vec![NumberBound {
            path: FieldPath::parse(""),
            min: None,
            max: None,
        }]);
        assert!(!open.transfer(&f64::NAN));
        assert_eq!(FieldPath::parse(""), FieldPath::default());
    }

    #[test]
    fn a_stamp_table_keeps_the_last_send_of_each_link() {
        let s = SendStamps::new(2);
        assert_eq!((s.last(0), s.last(1), s.last(2)), (None, None, None));
        s.sent(0, Time::ZERO);
        s.sent(1, Time::from_nanos(7));
        s.sent(1, Time::from_nanos(9));
        s.sent(5, Time::from_nanos(1));
        let shared = s.clone();
        assert_eq!(shared.last(0), Some(Time::ZERO), "an instant 0 is kept");
        assert_eq!(shared.last(1), Some(Time::from_nanos(9)), "the last");
        assert_eq!(shared.last(5), None, "past the table");
    }

    #[test]
    fn a_node_s_activations_are_told_in_the_behaviours_asked_for() {
        let bounded = NodeEvents {
            transitions: true,
            actions: 1 << 2,
        };
        assert!(bounded.action(Some(2)) && !bounded.action(Some(1)));
        assert!(bounded.action(None), "a driver's step: any bit");
        assert!(!NodeEvents::none().action(None) && !NodeEvents::none().action(Some(0)));
        let last = NodeEvents {
            transitions: false,
            actions: 1 << 63,
        };
        assert!(last.action(Some(63)) && last.action(Some(200)) && !last.action(Some(62)));
        assert!(NodeEvents::all().action(Some(500)));
        let u = bounded.union(last);
        assert!(u.transitions && u.action(Some(2)) && u.action(Some(99)) && !u.action(Some(0)));
        assert_eq!(NodeEvents::none().union(bounded), bounded);
    }

    #[test]
    fn a_read_is_told_when_asked_for_or_older_than_the_bound() {
        let fresh = LinkEvents {
            older_than: Some(50),
            ..LinkEvents::none()
        };
        assert_eq!(fresh.read(true, 150, 100), None, "exactly 50 old: fresh");
        assert_eq!(
            fresh.read(true, 151, 100),
            Some(true),
            "a new value too old"
        );
        assert_eq!(fresh.read(false, 151, 100), Some(false), "held too old");
        assert_eq!(fresh.read(false, 150, 100), None);
        assert_eq!(fresh.read(true, 10, 100), None, "a stamp after the read");
        assert_eq!(LinkEvents::all().read(true, 0, 0), Some(true));
        assert_eq!(LinkEvents::all().read(false, 999, 0), None);
        assert_eq!(LinkEvents::none().read(true, 999, 0), None);
    }
}
