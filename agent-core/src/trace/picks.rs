//! The numbers at several field paths of one value, read in one walk of its
//! `Serialize` impl ([`any_broken`]): what a link's compiled range checks
//! ([`NumberBound`]) read of each value sent. The paths are followed as
//! [`FieldPath`](super::FieldPath) follows one (the same steps, the same
//! parts looked through, the same parts without a number); a part is visited
//! when some path goes through it, and at most 64 paths share a walk.

use serde::Serialize;
use serde::ser::{
    SerializeMap, SerializeSeq, SerializeStruct, SerializeStructVariant, SerializeTuple,
    SerializeTupleStruct, SerializeTupleVariant, Serializer,
};

use super::pick::{PickError, Step};
use super::wants::{NumberBound, within};

/// Whether `value` breaks one of `bounds` (see [`NumberBound::broken_by`]),
/// in one walk of the value for up to 64 bounds.
#[inline]
pub(crate) fn any_broken<T: Serialize + ?Sized>(bounds: &[NumberBound], value: &T) -> bool {
    if bounds.len() > 64 {
        return bounds.iter().any(|b| b.broken_by(value));
    }
    let mut broken = 0u64;
    let all = if bounds.len() == 64 {
        u64::MAX
    } else {
        (1u64 << bounds.len()) - 1
    };
    let walk = Walk {
        bounds,
        mask: all,
        depth: 0,
        broken: &mut broken,
    };
    value.serialize(walk).is_err() || broken != 0
}

/// The walk at one part of the value: the bounds whose paths reach it
/// (`mask`), `depth` steps down.
struct Walk<'a> {
    bounds: &'a [NumberBound],
    mask: u64,
    depth: usize,
    /// The bounds found broken.
    broken: &'a mut u64,
}

/// The bounds of `mask` whose path goes on, `depth` steps down, through
/// the part `want` accepts.
fn through(bounds: &[NumberBound], mask: u64, depth: usize, want: impl Fn(&Step) -> bool) -> u64 {
    let mut m = 0;
    for (k, b) in bounds.iter().enumerate() {
        if mask >> k & 1 == 1 && b.path.step(depth).is_some_and(&want) {
            m |= 1 << k;
        }
    }
    m
}

impl<'a> Walk<'a> {
    fn number(self, x: f64) -> Result<(), PickError> {
        for (k, b) in self.bounds.iter().enumerate() {
            if self.mask >> k & 1 == 1 && b.path.len() == self.depth && !within(x, b.min, b.max) {
                *self.broken |= 1 << k;
            }
        }
        Ok(())
    }

    fn parts(self, by_index: bool) -> Parts<'a> {
        Parts {
            by_index,
            bounds: self.bounds,
            mask: self.mask,
            depth: self.depth,
            broken: self.broken,
            next: 0,
        }
    }
}

/// A container being walked: its parts counted, those some path goes
/// through followed.
struct Parts<'a> {
    by_index: bool,
    bounds: &'a [NumberBound],
    mask: u64,
    depth: usize,
    broken: &'a mut u64,
    next: usize,
}

impl Parts<'_> {
    fn walk<T: Serialize + ?Sized>(&mut self, mask: u64, value: &T) -> Result<(), PickError> {
        if mask == 0 {
            return Ok(());
        }
        value.serialize(Walk {
            bounds: self.bounds,
            mask,
            depth: self.depth + 1,
            broken: &mut *self.broken,
        })
    }

    fn item<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), PickError> {
        let k = self.next;
        self.next += 1;
        if !self.by_index {
            return Ok(());
        }
        let mask = through(self.bounds, self.mask, self.depth, |s| s.index == Some(k));
        self.walk(mask, value)
    }

    fn field<T: Serialize + ?Sized>(&mut self, key: &str, value: &T) -> Result<(), PickError> {
        if self.by_index {
            return Ok(());
        }
        let mask = through(self.bounds, self.mask, self.depth, |s| s.name == key);
        self.walk(mask, value)
    }
}

/// Parts of which none is followed (an enum's, a map's).
fn nothing(w: Walk<'_>) -> Parts<'_> {
    let mut p = w.parts(true);
    p.mask = 0;
    p
}

macro_rules! numbers {
    ($($method:ident: $t:ty),* $(,)?) => {
        $(
            #[inline]
            fn $method(self, v: $t) -> Result<(), PickError> {
                self.number(v as f64)
            }
        )*
    };
}

impl<'a> Serializer for Walk<'a> {
    type Ok = ();
    type Error = PickError;
    type SerializeSeq = Parts<'a>;
    type SerializeTuple = Parts<'a>;
    type SerializeTupleStruct = Parts<'a>;
    type SerializeTupleVariant = Parts<'a>;
    type SerializeMap = Parts<'a>;
    type SerializeStruct = Parts<'a>;
    type SerializeStructVariant = Parts<'a>;

    numbers!(
        serialize_i8: i8, serialize_i16: i16, serialize_i32: i32, serialize_i64: i64,
        serialize_i128: i128, serialize_u8: u8, serialize_u16: u16, serialize_u32: u32,
        serialize_u64: u64, serialize_u128: u128, serialize_f32: f32, serialize_f64: f64,
    );

    fn serialize_bool(self, _: bool) -> Result<(), PickError> {
        Ok(())
    }
    fn serialize_char(self, _: char) -> Result<(), PickError> {
        Ok(())
    }
    fn serialize_str(self, _: &str) -> Result<(), PickError> {
        Ok(())
    }
    fn serialize_bytes(self, _: &[u8]) -> Result<(), PickError> {
        Ok(())
    }
    fn serialize_none(self) -> Result<(), PickError> {
        Ok(())
    }
    fn serialize_some<T: Serialize + ?Sized>(self, value: &T) -> Result<(), PickError> {
        value.serialize(self)
    }
    fn serialize_unit(self) -> Result<(), PickError> {
        Ok(())
    }
    fn serialize_unit_struct(self, _: &'static str) -> Result<(), PickError> {
        Ok(())
    }
    fn serialize_unit_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
    ) -> Result<(), PickError> {
        Ok(())
    }
    fn serialize_newtype_struct<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        value: &T,
    ) -> Result<(), PickError> {
        value.serialize(self)
    }
    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: &T,
    ) -> Result<(), PickError> {
        Ok(())
    }
    fn serialize_seq(self, _: Option<usize>) -> Result<Parts<'a>, PickError> {
        Ok(self.parts(true))
    }
    fn serialize_tuple(self, _: usize) -> Result<Parts<'a>, PickError> {
        Ok(self.parts(true))
    }
    fn serialize_tuple_struct(self, _: &'static str, _: usize) -> Result<Parts<'a>, PickError> {
        Ok(self.parts(true))
    }
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Parts<'a>, PickError> {
        Ok(nothing(self))
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Parts<'a>, PickError> {
        Ok(nothing(self))
    }
    fn serialize_struct(self, _: &'static str, _: usize) -> Result<Parts<'a>, PickError> {
        Ok(self.parts(false))
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Parts<'a>, PickError> {
        Ok(nothing(self))
    }
    fn is_human_readable(&self) -> bool {
        false
    }
}

macro_rules! parts {
    ($($tr:ident: $method:ident),* $(,)?) => {
        $(
            impl $tr for Parts<'_> {
                type Ok = ();
                type Error = PickError;
                fn $method<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), PickError> {
                    self.item(value)
                }
                fn end(self) -> Result<(), PickError> {
                    Ok(())
                }
            }
        )*
    };
}

parts!(
    SerializeSeq: serialize_element,
    SerializeTuple: serialize_element,
    SerializeTupleStruct: serialize_field,
    SerializeTupleVariant: serialize_field,
);

impl SerializeMap for Parts<'_> {
    type Ok = ();
    type Error = PickError;
    fn serialize_key<T: Serialize + ?Sized>(&mut self, _: &T) -> Result<(), PickError> {
        Ok(())
    }
    fn serialize_value<T: Serialize + ?Sized>(&mut self, _: &T) -> Result<(), PickError> {
        Ok(())
    }
    fn end(self) -> Result<(), PickError> {
        Ok(())
    }
}

impl SerializeStruct for Parts<'_> {
    type Ok = ();
    type Error = PickError;
    fn serialize_field<T: Serialize + ?Sized>(
        &mut self,
        key: &'static str,
        value: &T,
    ) -> Result<(), PickError> {
        self.field(key, value)
    }
    fn end(self) -> Result<(), PickError> {
        Ok(())
    }
}

impl SerializeStructVariant for Parts<'_> {
    type Ok = ();
    type Error = PickError;
    fn serialize_field<T: Serialize + ?Sized>(
        &mut self,
        _: &'static str,
        _: &T,
    ) -> Result<(), PickError> {
        Ok(())
    }
    fn end(self) -> Result<(), PickError> {
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

    use std::collections::BTreeMap;

    use serde::Serializer;

    use super::*;
    use crate::trace::FieldPath;

    #[derive(Serialize)]
    struct Value {
        name: String,
        xy: [f64; 2],
        tags: Vec<u32>,
        heading: Option<f32>,
        none: Option<f32>,
        mode: Mode,
        flag: bool,
        table: BTreeMap<u8, f64>,
        pair: (u8, Wrapped),
    }

    #[derive(Serialize)]
    enum Mode {
        Go(u8),
    }

    #[derive(Serialize)]
    struct Wrapped(Inner);

    #[derive(Serialize)]
    struct Inner(i16, f64);

    fn value() -> Value {
        Value {
            name: "n".into(),
            xy: [1.5, f64::NAN],
            tags: vec![7, 300],
            heading: Some(0.25),
            none: None,
            mode: Mode::Go(3),
            flag: true,
            table: BTreeMap::from([(1, 2.0)]),
            pair: (9, Wrapped(Inner(-7, 4.0))),
        }
    }

    const PATHS: [&str; 16] = [
        "xy.0", "xy.1", "xy.2", "tags.1", "tags.5", "heading", "none", "mode.0", "flag", "table.1",
        "pair.0", "pair.1.0", "pair.1.1", "name", "nope", "",
    ];

    /// Bounds on every path, each either around its number or away from it.
    fn bounds(shift: u32) -> Vec<NumberBound> {
        PATHS
            .iter()
            .enumerate()
            .map(|(k, p)| {
                let (min, max) = if (shift >> (k % 8)) & 1 == 1 {
                    (Some(-10.0), Some(500.0))
                } else {
                    (Some(1000.0), None)
                };
                NumberBound {
                    path: FieldPath::parse(p),
                    min,
                    max,
                }
            })
            .collect()
    }

    #[test]
    fn one_walk_finds_what_each_path_alone_finds() {
        let v = value();
        for shift in 0..256u32 {
            let all = bounds(shift);
            // Every bound alone, every pair, and all of them.
            for i in 0..all.len() {
                for j in i..all.len() {
                    let some = [all[i].clone(), all[j].clone()];
                    let alone = some.iter().any(|b| b.broken_by(&v));
                    assert_eq!(any_broken(&some, &v), alone, "{shift} {i} {j}");
                }
            }
            let alone = all.iter().any(|b| b.broken_by(&v));
            assert_eq!(any_broken(&all, &v), alone, "{shift}");
        }
        // NaN is out of any bound given; a number within is not.
        let nan = [NumberBound {
            path: FieldPath::parse("xy.1"),
            min: None,
            max: Some(1.0),
        }];
        assert!(any_broken(&nan, &v));
        let within = [NumberBound {
            path: FieldPath::parse("pair.1.1"),
            min: Some(4.0),
            max: Some(4.0),
        }];
        assert!(!any_broken(&within, &v));
        assert!(!any_broken(&[], &v));
    }

    /// A value whose `Serialize` impl fails.
    struct Failing;

    impl Serialize for Failing {
        fn serialize<S: Serializer>(&self, _: S) -> Result<S::Ok, S::Error> {
            Err(serde::ser::Error::custom("broken on purpose"))
        }
    }

    #[test]
    fn a_failing_part_breaks_the_bounds_only_when_a_path_reads_it() {
        let v = (1.0f64, Failing);
        let first = NumberBound {
            path: FieldPath::parse("0"),
            min: None,
            max: Some(2.0),
        };
        let second = NumberBound {
            path: FieldPath::parse("1"),
            ..first.clone()
        };
        assert!(!any_broken(std::slice::from_ref(&first), &v));
        assert!(any_broken(&[first, second], &v));
        // Past 64 bounds, each is read alone: the same answers.
        let many: Vec<NumberBound> = (0..70)
            .map(|k| NumberBound {
                path: FieldPath::parse("0"),
                min: Some(f64::from(k)),
                max: None,
            })
            .collect();
        assert!(any_broken(&many, &v));
        assert!(!any_broken(&many[..2], &v));
    }
}
