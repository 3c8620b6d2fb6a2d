//! A number picked out of a value by a field path ([`FieldPath`]: `"0"`,
//! `"pose.x"`), through the value's `Serialize` impl: a serializer that
//! descends along the path only, skips every other part of the value without
//! looking at it, allocates nothing and yields the number at the end
//! ([`ErasedPayload::number_at`](super::ErasedPayload::number_at)). What a
//! contract monitor's range reads of each value sent, without encoding it.
//!
//! The path is read as over the value's postcard bytes with its type's shape
//! (`agent-monitor`'s offline reader): a step is a struct field's name, or an
//! index into a tuple, a tuple struct, a fixed array or a sequence; a newtype
//! struct and a present `Option` are looked through. The end of the path
//! must be a number (an integer or a float; `bool` is not one). An absent
//! `Option`, a sequence shorter than the index, a map and an enum on the path
//! have no value there: `Ok(None)`.
//!
//! A value that is an `f64`, an array of them (`[f64; N]`, N up to 32) or a
//! `Vec<f64>` is read directly, by the index its path names, when the path
//! has at most one step ([`FieldPath::number_of`]): the same number the walk
//! would yield, without the walk (a range over a robot's wheel torques, its
//! joint positions). Any other value goes through its `Serialize` impl.

use std::any::Any;
use std::fmt;

use serde::Serialize;
use serde::ser::{
    self, SerializeMap, SerializeSeq, SerializeStruct, SerializeStructVariant, SerializeTuple,
    SerializeTupleStruct, SerializeTupleVariant, Serializer,
};

/// One step of a [`FieldPath`]: a field's name, and the index it reads as.
#[derive(Clone, Debug, PartialEq, Eq)]
struct Step {
    name: String,
    index: Option<usize>,
}

/// A path to a number inside a value, its steps separated by dots (see the
/// module docs); parsed once, read on every value.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FieldPath {
    steps: Vec<Step>,
    /// The path as read directly from numbers ([`FieldPath::number_of`]):
    /// the value itself, one index, or `None` for any other path.
    direct: Option<Direct>,
}

/// A path of at most one step, read directly from a number or an array of
/// them: the value itself (`""`) or the number at an index (`"2"`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Direct {
    Whole,
    Index(usize),
}

/// A value whose numbers are read without its `Serialize` impl.
pub(crate) enum Numbers<'a> {
    One(f64),
    Many(&'a [f64]),
}

/// The numbers of `value` when its type is `f64`, `[f64; N]` (N ≤ 32) or
/// `Vec<f64>` (`None` for any other type). Each test is of a type known when
/// the caller is compiled: for a given `T`, all but one fold away.
#[inline(always)]
pub(crate) fn numbers<T: Any>(value: &T) -> Option<Numbers<'_>> {
    let any: &dyn Any = value;
    if let Some(&x) = any.downcast_ref::<f64>() {
        return Some(Numbers::One(x));
    }
    if let Some(v) = any.downcast_ref::<Vec<f64>>() {
        return Some(Numbers::Many(v));
    }
    macro_rules! arrays {
        ($($n:literal)*) => {$(
            if let Some(a) = any.downcast_ref::<[f64; $n]>() {
                return Some(Numbers::Many(a));
            }
        )*};
    }
    arrays!(1 2 3 4 5 6 7 8 9 10 11 12 13 14 15 16 17 18 19 20 21 22 23 24 25 26 27 28 29 30 31 32);
    None
}

impl FieldPath {
    /// The path `path` (`""`: the value itself).
    pub fn parse(path: &str) -> FieldPath {
        if path.is_empty() {
            return FieldPath {
                steps: Vec::new(),
                direct: Some(Direct::Whole),
            };
        }
        let steps: Vec<Step> = path
            .split('.')
            .map(|s| Step {
                name: s.to_owned(),
                index: s.parse().ok(),
            })
            .collect();
        let direct = match steps.as_slice() {
            [one] => one.index.map(Direct::Index),
            _ => None,
        };
        FieldPath { steps, direct }
    }

    /// The number at this path in `value` (`Ok(None)`: none there).
    pub fn number<T: Serialize + ?Sized>(&self, value: &T) -> Result<Option<f64>, PickError> {
        value.serialize(Pick { path: &self.steps })
    }

    /// The path as read directly from numbers, if it can be.
    pub(crate) fn direct(&self) -> Option<Direct> {
        self.direct
    }

    /// [`FieldPath::number`] of a sized value: an `f64`, an array of them
    /// or a `Vec<f64>` read directly by the path's index when the path has at
    /// most one step (see the module docs), any other through its
    /// `Serialize` impl. The same result either way.
    #[inline]
    pub fn number_of<T: Serialize + Any>(&self, value: &T) -> Result<Option<f64>, PickError> {
        if let Some(direct) = self.direct
            && let Some(numbers) = numbers(value)
        {
            return Ok(match (numbers, direct) {
                (Numbers::One(x), Direct::Whole) => Some(x),
                (Numbers::Many(xs), Direct::Index(i)) => xs.get(i).copied(),
                (Numbers::One(_), Direct::Index(_)) | (Numbers::Many(_), Direct::Whole) => None,
            });
        }
        self.number(value)
    }
}

impl Default for FieldPath {
    /// The value itself (`""`).
    fn default() -> Self {
        FieldPath::parse("")
    }
}

impl fmt::Display for FieldPath {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (k, s) in self.steps.iter().enumerate() {
            if k > 0 {
                f.write_str(".")?;
            }
            f.write_str(&s.name)?;
        }
        Ok(())
    }
}

/// A value's `Serialize` impl failed while a number was picked out of it.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("cannot read a field of a buffer value: {0}")]
pub struct PickError(String);

impl ser::Error for PickError {
    fn custom<T: fmt::Display>(msg: T) -> Self {
        PickError(msg.to_string())
    }
}

/// The serializer that follows `path`.
struct Pick<'p> {
    path: &'p [Step],
}

impl<'p> Pick<'p> {
    fn number(self, x: f64) -> Result<Option<f64>, PickError> {
        Ok(self.path.is_empty().then_some(x))
    }

    /// A container whose parts are read by index (`by_index`) or by name.
    fn parts(self, by_index: bool) -> Parts<'p> {
        let want = self.path.split_first().and_then(|(step, rest)| {
            if by_index {
                step.index.map(|i| (Want::Index(i), rest))
            } else {
                Some((Want::Name(&step.name), rest))
            }
        });
        Parts {
            want,
            next: 0,
            found: None,
        }
    }
}

/// Which part of a container the path goes on through.
#[derive(Clone, Copy)]
enum Want<'p> {
    Index(usize),
    Name(&'p str),
}

/// A container being serialized: its parts counted, the wanted one followed.
struct Parts<'p> {
    want: Option<(Want<'p>, &'p [Step])>,
    next: usize,
    found: Option<f64>,
}

/// Parts of which none is wanted (an enum's, a map's).
fn nothing<'p>() -> Parts<'p> {
    Parts {
        want: None,
        next: 0,
        found: None,
    }
}

impl Parts<'_> {
    fn item<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), PickError> {
        let k = self.next;
        self.next += 1;
        if let Some((Want::Index(i), rest)) = self.want
            && i == k
        {
            self.found = value.serialize(Pick { path: rest })?;
        }
        Ok(())
    }

    fn field<T: Serialize + ?Sized>(&mut self, key: &str, value: &T) -> Result<(), PickError> {
        if let Some((Want::Name(name), rest)) = self.want
            && name == key
        {
            self.want = None;
            self.found = value.serialize(Pick { path: rest })?;
        }
        Ok(())
    }
}

macro_rules! numbers {
    ($($method:ident: $t:ty),* $(,)?) => {
        $(
            #[inline]
            fn $method(self, v: $t) -> Result<Option<f64>, PickError> {
                self.number(v as f64)
            }
        )*
    };
}

impl<'p> Serializer for Pick<'p> {
    type Ok = Option<f64>;
    type Error = PickError;
    type SerializeSeq = Parts<'p>;
    type SerializeTuple = Parts<'p>;
    type SerializeTupleStruct = Parts<'p>;
    type SerializeTupleVariant = Parts<'p>;
    type SerializeMap = Parts<'p>;
    type SerializeStruct = Parts<'p>;
    type SerializeStructVariant = Parts<'p>;

    numbers!(
        serialize_i8: i8, serialize_i16: i16, serialize_i32: i32, serialize_i64: i64,
        serialize_i128: i128, serialize_u8: u8, serialize_u16: u16, serialize_u32: u32,
        serialize_u64: u64, serialize_u128: u128, serialize_f32: f32, serialize_f64: f64,
    );

    fn serialize_bool(self, _: bool) -> Result<Option<f64>, PickError> {
        Ok(None)
    }
    fn serialize_char(self, _: char) -> Result<Option<f64>, PickError> {
        Ok(None)
    }
    fn serialize_str(self, _: &str) -> Result<Option<f64>, PickError> {
        Ok(None)
    }
    fn serialize_bytes(self, _: &[u8]) -> Result<Option<f64>, PickError> {
        Ok(None)
    }
    fn serialize_none(self) -> Result<Option<f64>, PickError> {
        Ok(None)
    }
    fn serialize_some<T: Serialize + ?Sized>(self, value: &T) -> Result<Option<f64>, PickError> {
        value.serialize(self)
    }
    fn serialize_unit(self) -> Result<Option<f64>, PickError> {
        Ok(None)
    }
    fn serialize_unit_struct(self, _: &'static str) -> Result<Option<f64>, PickError> {
        Ok(None)
    }
    fn serialize_unit_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
    ) -> Result<Option<f64>, PickError> {
        Ok(None)
    }
    fn serialize_newtype_struct<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        value: &T,
    ) -> Result<Option<f64>, PickError> {
        value.serialize(self)
    }
    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: &T,
    ) -> Result<Option<f64>, PickError> {
        Ok(None)
    }
    fn serialize_seq(self, _: Option<usize>) -> Result<Parts<'p>, PickError> {
        Ok(self.parts(true))
    }
    fn serialize_tuple(self, _: usize) -> Result<Parts<'p>, PickError> {
        Ok(self.parts(true))
    }
    fn serialize_tuple_struct(self, _: &'static str, _: usize) -> Result<Parts<'p>, PickError> {
        Ok(self.parts(true))
    }
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Parts<'p>, PickError> {
        Ok(nothing())
    }
    fn serialize_map(self, _: Option<usize>) -> Result<Parts<'p>, PickError> {
        Ok(nothing())
    }
    fn serialize_struct(self, _: &'static str, _: usize) -> Result<Parts<'p>, PickError> {
        Ok(self.parts(false))
    }
    fn serialize_struct_variant(
        self,
        _: &'static str,
        _: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Parts<'p>, PickError> {
        Ok(nothing())
    }
    fn is_human_readable(&self) -> bool {
        // As postcard, whose bytes the offline reader walks.
        false
    }
}

impl SerializeSeq for Parts<'_> {
    type Ok = Option<f64>;
    type Error = PickError;
    fn serialize_element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), PickError> {
        self.item(value)
    }
    fn end(self) -> Result<Option<f64>, PickError> {
        Ok(self.found)
    }
}

impl SerializeTuple for Parts<'_> {
    type Ok = Option<f64>;
    type Error = PickError;
    fn serialize_element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), PickError> {
        self.item(value)
    }
    fn end(self) -> Result<Option<f64>, PickError> {
        Ok(self.found)
    }
}

impl SerializeTupleStruct for Parts<'_> {
    type Ok = Option<f64>;
    type Error = PickError;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), PickError> {
        self.item(value)
    }
    fn end(self) -> Result<Option<f64>, PickError> {
        Ok(self.found)
    }
}

impl SerializeTupleVariant for Parts<'_> {
    type Ok = Option<f64>;
    type Error = PickError;
    fn serialize_field<T: Serialize + ?Sized>(&mut self, _: &T) -> Result<(), PickError> {
        Ok(())
    }
    fn end(self) -> Result<Option<f64>, PickError> {
        Ok(None)
    }
}

impl SerializeMap for Parts<'_> {
    type Ok = Option<f64>;
    type Error = PickError;
    fn serialize_key<T: Serialize + ?Sized>(&mut self, _: &T) -> Result<(), PickError> {
        Ok(())
    }
    fn serialize_value<T: Serialize + ?Sized>(&mut self, _: &T) -> Result<(), PickError> {
        Ok(())
    }
    fn end(self) -> Result<Option<f64>, PickError> {
        Ok(None)
    }
}

impl SerializeStruct for Parts<'_> {
    type Ok = Option<f64>;
    type Error = PickError;
    fn serialize_field<T: Serialize + ?Sized>(
        &mut self,
        key: &'static str,
        value: &T,
    ) -> Result<(), PickError> {
        self.field(key, value)
    }
    fn end(self) -> Result<Option<f64>, PickError> {
        Ok(self.found)
    }
}

impl SerializeStructVariant for Parts<'_> {
    type Ok = Option<f64>;
    type Error = PickError;
    fn serialize_field<T: Serialize + ?Sized>(
        &mut self,
        _: &'static str,
        _: &T,
    ) -> Result<(), PickError> {
        Ok(())
    }
    fn end(self) -> Result<Option<f64>, PickError> {
        Ok(None)
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

    use std::collections::BTreeMap;

    use serde::Deserialize;

    use super::*;

    #[derive(Serialize, Deserialize, Default, Debug, Clone, PartialEq)]
    struct Pose {
        name: String,
        xy: [f64; 2],
        tags: Vec<u32>,
        heading: Option<f32>,
        mode: Mode,
        count: i64,
        flag: bool,
        table: BTreeMap<u8, f64>,
        pair: (u8, Wrapped),
    }

    #[derive(Serialize, Deserialize, Default, Debug, Clone, PartialEq)]
    enum Mode {
        #[default]
        Idle,
        Go(u8, String),
        At {
            x: f64,
        },
    }

    #[derive(Serialize, Deserialize, Default, Debug, Clone, PartialEq)]
    struct Wrapped(Inner);

    #[derive(Serialize, Deserialize, Default, Debug, Clone, PartialEq)]
    struct Inner(u128, i16);

    fn at<T: Serialize>(v: &T, p: &str) -> Option<f64> {
        FieldPath::parse(p).number(v).unwrap()
    }

    #[test]
    fn numbers_are_read_directly_as_the_walk_reads_them() {
        let four = [1.0f64, -2.0, f64::NAN, 4.0];
        let many = four.to_vec();
        for path in ["", "0", "1", "3", "4", "0.x", "x"] {
            let p = FieldPath::parse(path);
            let same = |a: Option<f64>, b: Option<f64>| a.map(f64::to_bits) == b.map(f64::to_bits);
            assert!(
                same(p.number_of(&four).unwrap(), p.number(&four).unwrap()),
                "{path}"
            );
            assert!(
                same(p.number_of(&many).unwrap(), p.number(&many).unwrap()),
                "{path}"
            );
            assert!(
                same(p.number_of(&7.5f64).unwrap(), p.number(&7.5f64).unwrap()),
                "{path}"
            );
        }
        assert_eq!(FieldPath::parse("1").number_of(&four).unwrap(), Some(-2.0));
        assert_eq!(FieldPath::parse("").number_of(&7.5f64).unwrap(), Some(7.5));
        assert_eq!(
            FieldPath::parse("").number_of(&four).unwrap(),
            None,
            "an array is no number"
        );
        // Not numbers: walked.
        assert_eq!(
            FieldPath::parse("1").number_of(&(1u8, 2.5f32)).unwrap(),
            Some(2.5)
        );
    }

    #[test]
    fn picks_numbers_along_the_path_as_the_offline_reader_does() {
        let v = Pose {
            name: "a long name".into(),
            xy: [1.5, -2.5],
            tags: vec![7, 300, 70_000],
            heading: Some(0.25),
            mode: Mode::Go(3, "fast".into()),
            count: -12,
            flag: true,
            table: BTreeMap::from([(1, 2.0)]),
            pair: (9, Wrapped(Inner(1 << 70, -7))),
        };
        assert_eq!(at(&v, "xy.0"), Some(1.5));
        assert_eq!(at(&v, "xy.1"), Some(-2.5));
        assert_eq!(at(&v, "xy.2"), None, "past the array");
        assert_eq!(at(&v, "tags.2"), Some(70_000.0));
        assert_eq!(at(&v, "tags.3"), None, "past the sequence");
        assert_eq!(at(&v, "heading"), Some(0.25));
        assert_eq!(at(&v, "count"), Some(-12.0));
        assert_eq!(at(&v, "pair.0"), Some(9.0));
        assert_eq!(at(&v, "pair.1.0"), Some((1u128 << 70) as f64), "newtypes");
        assert_eq!(at(&v, "pair.1.1"), Some(-7.0));
        assert_eq!(at(&v, "name"), None, "a string is no number");
        assert_eq!(at(&v, "flag"), None, "a bool is no number");
        assert_eq!(at(&v, "xy"), None, "an array is no number");
        assert_eq!(at(&v, "xy.x"), None, "an array has no named parts");
        assert_eq!(at(&v, "mode.0"), None, "no path through an enum");
        assert_eq!(at(&v, "table.1"), None, "no path through a map");
        assert_eq!(at(&v, "nope"), None);
        assert_eq!(at(&v, "count.0"), None, "a path past a number");
        let at_mode = Pose {
            mode: Mode::At { x: 1.0 },
            ..Pose::default()
        };
        assert_eq!(at(&at_mode, "mode.x"), None);
        assert_eq!(at(&Pose::default(), "heading"), None, "an absent option");
        assert_eq!(at(&Pose::default(), "count"), Some(0.0));
        assert_eq!(at(&[1.0f64, 2.0, f64::NAN, -4.0], "3"), Some(-4.0));
        assert!(at(&[1.0f64, 2.0, f64::NAN, -4.0], "2").unwrap().is_nan());
        assert_eq!(at(&3u8, ""), Some(3.0), "the empty path: the value itself");
        assert_eq!(FieldPath::parse("pose.x").to_string(), "pose.x");
    }

    /// A value whose `Serialize` impl fails.
    struct Broken;

    impl Serialize for Broken {
        fn serialize<S: Serializer>(&self, _: S) -> Result<S::Ok, S::Error> {
            Err(ser::Error::custom("broken on purpose"))
        }
    }

    #[test]
    fn a_failing_serialize_impl_is_an_error_where_the_path_reads_it() {
        let v = (1.0f64, Broken);
        assert_eq!(at(&v, "0"), Some(1.0), "a part not read is not serialized");
        let e = FieldPath::parse("1").number(&v).unwrap_err();
        assert!(e.to_string().contains("broken on purpose"), "{e}");
    }
}
