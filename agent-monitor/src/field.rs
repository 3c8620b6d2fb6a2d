//! A number inside a buffer value's postcard bytes, found by a range's field
//! path (`"0"`, `"pose.x"`) through the value's layout, without decoding the
//! rest of the value and without allocating: what a range monitor reads of
//! each value in a recording.
//!
//! A [`Layout`] is a payload's [`TypeShape`] (its serde data model) made
//! owned and shareable between threads (the shape's formats are not `Send`).
//! A path step is a struct field's name, or an index into a tuple, a tuple
//! struct, a fixed array or a sequence; a newtype struct and a present
//! `Option` are looked through. The end of the path must be a number (an
//! integer or a float; `bool` is not one). An absent `Option`, a sequence
//! shorter than the index and an enum on the path have no value there:
//! `Ok(None)`, and the range is not judged for that value.
//!
//! A running watch reads the typed value itself ([`agent_core::trace::FieldPath`],
//! the same path read through the value's `Serialize` impl); it checks only
//! that a range's path can lead to a number ([`reaches_number`]). The bytes
//! are walked over a recording.
#![cfg_attr(
    not(any(feature = "recording", test)),
    allow(
        dead_code,
        reason = "without `recording` no bytes are walked: the live watch reads typed values"
    )
)]

use agent_core::TypeShape;
use agent_core::serde_reflection::{ContainerFormat, Format, Named, VariantFormat};
use agent_core::untyped::{Cursor, DecodeError, MAX_DEPTH};

/// Integer formats by their width in bits, signed or not; floats.
#[derive(Clone, Copy, Debug)]
enum Numeric {
    Unsigned(u32),
    Signed(u32),
    F32,
    F64,
}

/// A value's format, as postcard lays it out.
#[derive(Clone, Debug)]
enum Fmt {
    Unit,
    Bool,
    Num(Numeric),
    /// A string, bytes or a char: a length and that many bytes.
    Text,
    Option(Box<Fmt>),
    Seq(Box<Fmt>),
    Map(Box<Fmt>, Box<Fmt>),
    Tuple(Vec<Fmt>),
    Array(Box<Fmt>, usize),
    Struct(Vec<(String, Fmt)>),
    Newtype(Box<Fmt>),
    /// Variants by index, each's content (a `Tuple` of its fields, a
    /// `Struct`, or `Unit`).
    Enum(Vec<(u32, Fmt)>),
    /// A named container of the layout (by index: types may be recursive).
    Named(usize),
    /// A format the shape left open (never in a complete trace).
    Open,
}

/// A payload's layout (see the module docs).
#[derive(Clone, Debug)]
pub(crate) struct Layout {
    root: Fmt,
    named: Vec<Fmt>,
}

impl Layout {
    pub(crate) fn of(shape: &TypeShape) -> Layout {
        let names: Vec<&String> = shape.registry.keys().collect();
        let cx = |f: &Format| fmt(f, &names);
        let named = shape
            .registry
            .values()
            .map(|c| match c {
                ContainerFormat::UnitStruct => Fmt::Unit,
                ContainerFormat::NewTypeStruct(f) => Fmt::Newtype(Box::new(cx(f))),
                ContainerFormat::TupleStruct(fs) => Fmt::Tuple(fs.iter().map(cx).collect()),
                ContainerFormat::Struct(fields) => fields_of(fields, &names),
                ContainerFormat::Enum(variants) => Fmt::Enum(
                    variants
                        .iter()
                        .map(|(k, v)| {
                            let content = match &v.value {
                                VariantFormat::Unit => Fmt::Unit,
                                VariantFormat::NewType(f) => cx(f),
                                VariantFormat::Tuple(fs) => Fmt::Tuple(fs.iter().map(cx).collect()),
                                VariantFormat::Struct(fields) => fields_of(fields, &names),
                                VariantFormat::Variable(_) => Fmt::Open,
                            };
                            (*k, content)
                        })
                        .collect(),
                ),
            })
            .collect();
        Layout {
            root: cx(&shape.root),
            named,
        }
    }
}

fn fields_of(fields: &[Named<Format>], names: &[&String]) -> Fmt {
    Fmt::Struct(
        fields
            .iter()
            .map(|n| (n.name.clone(), fmt(&n.value, names)))
            .collect(),
    )
}

fn fmt(f: &Format, names: &[&String]) -> Fmt {
    let boxed = |f: &Format| Box::new(fmt(f, names));
    match f {
        Format::Unit => Fmt::Unit,
        Format::Bool => Fmt::Bool,
        Format::U8 => Fmt::Num(Numeric::Unsigned(8)),
        Format::U16 => Fmt::Num(Numeric::Unsigned(16)),
        Format::U32 => Fmt::Num(Numeric::Unsigned(32)),
        Format::U64 => Fmt::Num(Numeric::Unsigned(64)),
        Format::U128 => Fmt::Num(Numeric::Unsigned(128)),
        Format::I8 => Fmt::Num(Numeric::Signed(8)),
        Format::I16 => Fmt::Num(Numeric::Signed(16)),
        Format::I32 => Fmt::Num(Numeric::Signed(32)),
        Format::I64 => Fmt::Num(Numeric::Signed(64)),
        Format::I128 => Fmt::Num(Numeric::Signed(128)),
        Format::F32 => Fmt::Num(Numeric::F32),
        Format::F64 => Fmt::Num(Numeric::F64),
        Format::Char | Format::Str | Format::Bytes => Fmt::Text,
        Format::Option(i) => Fmt::Option(boxed(i)),
        Format::Seq(i) => Fmt::Seq(boxed(i)),
        Format::Map { key, value } => Fmt::Map(boxed(key), boxed(value)),
        Format::Tuple(items) => Fmt::Tuple(items.iter().map(|f| fmt(f, names)).collect()),
        Format::TupleArray { content, size } => Fmt::Array(boxed(content), *size),
        Format::TypeName(n) => names
            .iter()
            .position(|x| *x == n)
            .map_or(Fmt::Open, Fmt::Named),
        Format::Variable(_) => Fmt::Open,
    }
}

/// The number at `path` in the value `bytes`, laid out as `layout`.
pub(crate) fn number(
    layout: &Layout,
    bytes: &[u8],
    path: &[String],
) -> Result<Option<f64>, DecodeError> {
    let mut w = Walk {
        layout,
        c: Cursor::new(bytes),
        depth: 0,
    };
    w.find(&layout.root, path)
}

/// Whether `path` can lead to a number in values of `layout` (checked once,
/// when a monitor is made; `false` also for a path through an enum).
pub(crate) fn reaches_number(layout: &Layout, path: &[String]) -> bool {
    fn go(l: &Layout, f: &Fmt, path: &[String], depth: usize) -> bool {
        if depth > MAX_DEPTH {
            return false;
        }
        let f = match f {
            Fmt::Named(k) => match l.named.get(*k) {
                Some(f) => f,
                None => return false,
            },
            f => f,
        };
        if let Fmt::Option(inner) | Fmt::Newtype(inner) = f {
            return go(l, inner, path, depth + 1);
        }
        let Some((step, rest)) = path.split_first() else {
            return matches!(f, Fmt::Num(_));
        };
        let index = step.parse::<usize>().ok();
        match f {
            Fmt::Tuple(items) => index
                .and_then(|i| items.get(i))
                .is_some_and(|f| go(l, f, rest, depth + 1)),
            Fmt::Array(content, size) => {
                index.is_some_and(|i| i < *size) && go(l, content, rest, depth + 1)
            }
            Fmt::Seq(content) => index.is_some() && go(l, content, rest, depth + 1),
            Fmt::Struct(fields) => fields
                .iter()
                .find(|(n, _)| n == step)
                .is_some_and(|(_, f)| go(l, f, rest, depth + 1)),
            _ => false,
        }
    }
    go(layout, &layout.root, path, 0)
}

struct Walk<'a> {
    layout: &'a Layout,
    c: Cursor<'a>,
    depth: usize,
}

impl<'a> Walk<'a> {
    fn deeper(&mut self) -> Result<(), DecodeError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(self.c.fail(format!("nested deeper than {MAX_DEPTH}")));
        }
        Ok(())
    }

    /// A named container's format.
    fn resolve(&self, f: &'a Fmt) -> Result<&'a Fmt, DecodeError> {
        match f {
            Fmt::Named(k) => self
                .layout
                .named
                .get(*k)
                .ok_or_else(|| self.c.fail(format!("no container {k} in the layout"))),
            f => Ok(f),
        }
    }

    /// The number at `path` from a value of format `f` at the cursor.
    fn find(&mut self, f: &'a Fmt, path: &[String]) -> Result<Option<f64>, DecodeError> {
        self.deeper()?;
        let found = self.find_in(f, path);
        self.depth -= 1;
        found
    }

    fn find_in(&mut self, f: &'a Fmt, path: &[String]) -> Result<Option<f64>, DecodeError> {
        let f = self.resolve(f)?;
        match f {
            Fmt::Newtype(inner) => return self.find(inner, path),
            Fmt::Option(inner) => {
                return match self.c.byte()? {
                    0 => Ok(None),
                    1 => self.find(inner, path),
                    b => Err(self.c.fail(format!("option tag {b}"))),
                };
            }
            _ => {}
        }
        let Some((step, rest)) = path.split_first() else {
            return match f {
                Fmt::Num(n) => self.read(*n).map(Some),
                _ => Ok(None),
            };
        };
        let index = step.parse::<usize>().ok();
        match f {
            Fmt::Tuple(items) => match index.filter(|i| *i < items.len()) {
                Some(i) => self.nth(items.iter(), i, rest),
                None => Ok(None),
            },
            Fmt::Array(content, size) => match index.filter(|i| i < size) {
                Some(i) => self.nth(std::iter::repeat_n(&**content, *size), i, rest),
                None => Ok(None),
            },
            Fmt::Seq(content) => {
                let n = self.c.length()?;
                match index.filter(|i| *i < n) {
                    Some(i) => self.nth(std::iter::repeat_n(&**content, n), i, rest),
                    None => Ok(None),
                }
            }
            Fmt::Struct(fields) => {
                for (name, f) in fields {
                    if name == step {
                        return self.find(f, rest);
                    }
                    self.skip(f)?;
                }
                Ok(None)
            }
            _ => Ok(None),
        }
    }

    /// Item `i` of `items` (the ones before it skipped).
    fn nth(
        &mut self,
        items: impl Iterator<Item = &'a Fmt>,
        i: usize,
        rest: &[String],
    ) -> Result<Option<f64>, DecodeError> {
        for (k, f) in items.enumerate() {
            if k == i {
                return self.find(f, rest);
            }
            self.skip(f)?;
        }
        Ok(None)
    }

    fn read(&mut self, n: Numeric) -> Result<f64, DecodeError> {
        Ok(match n {
            Numeric::Unsigned(8) => f64::from(self.c.byte()?),
            Numeric::Signed(8) => f64::from(self.c.byte()? as i8),
            Numeric::Unsigned(bits) => self.c.varint(bits)? as f64,
            Numeric::Signed(bits) => self.c.signed(bits)? as f64,
            Numeric::F32 => f64::from(f32::from_le_bytes(self.c.array()?)),
            Numeric::F64 => f64::from_le_bytes(self.c.array()?),
        })
    }

    /// Past a value of format `f`.
    fn skip(&mut self, f: &'a Fmt) -> Result<(), DecodeError> {
        self.deeper()?;
        let done = self.skip_in(f);
        self.depth -= 1;
        done
    }

    fn skip_in(&mut self, f: &'a Fmt) -> Result<(), DecodeError> {
        match self.resolve(f)? {
            Fmt::Unit => {}
            Fmt::Bool => {
                self.c.byte()?;
            }
            Fmt::Num(n) => {
                self.read(*n)?;
            }
            Fmt::Text => {
                let n = self.c.length()?;
                self.c.take(n)?;
            }
            Fmt::Option(inner) => match self.c.byte()? {
                0 => {}
                1 => self.skip(inner)?,
                b => return Err(self.c.fail(format!("option tag {b}"))),
            },
            Fmt::Newtype(inner) => self.skip(inner)?,
            Fmt::Seq(inner) => {
                for _ in 0..self.c.length()? {
                    self.skip(inner)?;
                }
            }
            Fmt::Map(key, value) => {
                for _ in 0..self.c.length()? {
                    self.skip(key)?;
                    self.skip(value)?;
                }
            }
            Fmt::Tuple(items) => {
                for f in items {
                    self.skip(f)?;
                }
            }
            Fmt::Array(content, size) => {
                for _ in 0..*size {
                    self.skip(content)?;
                }
            }
            Fmt::Struct(fields) => {
                for (_, f) in fields {
                    self.skip(f)?;
                }
            }
            Fmt::Enum(variants) => {
                let k = self.c.varint(32)?;
                let content = variants
                    .iter()
                    .find(|(v, _)| u128::from(*v) == k)
                    .map(|(_, c)| c)
                    .ok_or_else(|| self.c.fail(format!("no variant {k}")))?;
                self.skip(content)?;
            }
            Fmt::Named(_) | Fmt::Open => {
                return Err(self.c.fail("a format the shape left open".to_owned()));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

    use super::*;
    use serde::Serialize;

    #[derive(Serialize, serde::Deserialize, Default, Debug, Clone, PartialEq)]
    struct Pose {
        name: String,
        xy: [f64; 2],
        tags: Vec<u32>,
        heading: Option<f32>,
        mode: Mode,
        count: i64,
    }

    #[derive(Serialize, serde::Deserialize, Default, Debug, Clone, PartialEq)]
    enum Mode {
        #[default]
        Idle,
        Go(u8, String),
    }

    #[derive(Serialize, serde::Deserialize, Default, Debug, Clone, PartialEq)]
    struct Torques([f64; 4]);

    fn path(p: &str) -> Vec<String> {
        p.split('.').map(str::to_owned).collect()
    }

    #[test]
    fn finds_numbers_past_every_kind_of_value_and_allocates_nothing_else() {
        let shape = Layout::of(&agent_core::reflect::<Pose>().unwrap());
        let v = Pose {
            name: "a long name".into(),
            xy: [1.5, -2.5],
            tags: vec![7, 300, 70_000],
            heading: Some(0.25),
            mode: Mode::Go(3, "fast".into()),
            count: -12,
        };
        let bytes = postcard::to_allocvec(&v).unwrap();
        let at = |p: &str| number(&shape, &bytes, &path(p)).unwrap();
        assert_eq!(at("xy.0"), Some(1.5));
        assert_eq!(at("xy.1"), Some(-2.5));
        assert_eq!(at("xy.2"), None, "past the array");
        assert_eq!(at("tags.2"), Some(70_000.0));
        assert_eq!(at("tags.3"), None, "past the sequence");
        assert_eq!(at("heading"), Some(0.25));
        assert_eq!(at("count"), Some(-12.0));
        assert_eq!(at("name"), None, "a string is no number");
        assert_eq!(at("nope"), None);
        let none = postcard::to_allocvec(&Pose::default()).unwrap();
        assert_eq!(number(&shape, &none, &path("heading")).unwrap(), None);
        assert_eq!(number(&shape, &none, &path("count")).unwrap(), Some(0.0));
        assert!(reaches_number(&shape, &path("xy.1")));
        assert!(reaches_number(&shape, &path("heading")));
        assert!(!reaches_number(&shape, &path("xy.2")));
        assert!(!reaches_number(&shape, &path("name")));
        assert!(
            !reaches_number(&shape, &path("mode.0")),
            "no path through an enum"
        );
    }

    #[test]
    fn a_newtype_of_an_array_is_indexed_and_bad_bytes_are_an_error() {
        let shape = Layout::of(&agent_core::reflect::<Torques>().unwrap());
        let bytes = postcard::to_allocvec(&Torques([1.0, 2.0, f64::NAN, -4.0])).unwrap();
        let at = |p: &str| number(&shape, &bytes, &path(p)).unwrap();
        assert_eq!(at("1"), Some(2.0));
        assert!(at("2").unwrap().is_nan());
        assert_eq!(at("3"), Some(-4.0));
        assert!(reaches_number(&shape, &path("3")));
        assert!(
            number(&shape, &bytes[..10], &path("3")).is_err(),
            "truncated"
        );
    }
}
