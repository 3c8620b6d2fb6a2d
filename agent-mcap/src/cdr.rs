//! A buffer value's postcard bytes as ROS 2 CDR, and the `ros2msg` schema of
//! its type, both read off the type's [`TypeShape`]: the binary form Foxglove
//! (and every ROS 2 tool) decodes and plots without a line of the user's code;
//! and back ([`read_cdr`]: a CDR message from outside, checked, as the value's
//! postcard bytes).
//!
//! Against [`json`](crate::json) it costs no float formatting and no field
//! names per message: a value of `f64` fields is its bytes, aligned (recording
//! Rex's figure-eight without images, the JSON channels were 13.6 MB of the
//! 22.6 MB the writer compressed, and writing them was most of the recording's
//! cost). The JSON form stays for types ROS 2 messages cannot express.
//!
//! # The mapping
//!
//! | serde data model | `ros2msg` | CDR (little-endian, `CDR_LE`) |
//! |---|---|---|
//! | `bool`, `u8`..`u64`, `i8`..`i64`, `f32`, `f64` | `bool`, `uint8`..`uint64`, `int8`..`int64`, `float32`, `float64` | aligned to its size |
//! | `u128`, `i128` | `uint8[16]` | little-endian bytes |
//! | `char` | `uint32` | the code point |
//! | string | `string` | length + 1, bytes, NUL |
//! | bytes | `uint8[]` | length, bytes |
//! | `Option<T>` | `T[<=1]` | 0, or 1 and the value |
//! | sequence | `T[]` | length, values |
//! | `[T; N]`, tuple array | `T[N]` | values |
//! | map | `XEntry[]` (`key`, `value`) | length, pairs |
//! | tuple, tuple struct | a message, fields `item0`, `item1`, ... | fields |
//! | struct | a message of its fields | fields |
//! | unit, unit struct, empty struct | an empty message | one byte, 0 (as ROS 2) |
//! | newtype struct | its content | its content |
//! | enum | a message: `uint32 variant` (constants name each variant, `NAME=k`), and per variant with data a field `name` of type `T[<=1]` | the variant, then per variant with data 0, or 1 and its data |
//!
//! ROS 2 messages nest no arrays in arrays: an array whose elements are arrays
//! (`Vec<Vec<f64>>`, `Option<[u8; 4]>`) has a message of one field `value` as
//! its element, which CDR encodes as the field itself.
//!
//! The messages are made as data first ([`messages`]: [`Messages`] of a
//! package the caller names, `embodied` for recordings, each [`Message`]'s
//! fields with their ROS 2 [`FieldType`]s), then rendered as `.msg` text;
//! REP 2011's type descriptions and hashes are made from the same data.
//!
//! What cannot be a ROS 2 message gives [`Unsupported`] when the schema is
//! made, never a wrong message: a type that contains itself, a field name
//! `ros2msg` does not allow (`^[a-z][a-z0-9_]*$`, no `__`, no trailing `_`),
//! or formats left unknown by the tracer. The recorder then writes JSON.

use agent_core::TypeShape;
use agent_core::serde_reflection::{ContainerFormat, Format, VariantFormat};

use crate::postcard::{Cursor, MAX_DEPTH};

mod model;
mod read;
mod shape;

pub use crate::postcard::DecodeError;
pub use model::{
    Arity, BaseType, Constant, Field, FieldType, Message, Messages, MsgName, Primitive,
};
pub use read::read_cdr;
pub use shape::messages;

/// The package of the messages made for a recording.
pub const PACKAGE: &str = "embodied";

/// Why a type has no `ros2msg` form.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("no ROS 2 message for this type: {0}")]
pub struct Unsupported(pub String);

/// The `ros2msg` schema of a payload type: the root message's name
/// (`embodied/msg/Name`, the name MCAP's `ros2` profile gives a schema record)
/// and the text, the root's definition followed by every message it uses.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Ros2Schema {
    /// `embodied/msg/<Root>`.
    pub name: String,
    /// The concatenated definitions.
    pub text: String,
}

/// The `ros2msg` schema of the values [`write_cdr`] makes for `shape`, in the
/// recordings' package [`PACKAGE`]: [`messages`] rendered; `root` names the
/// root message when the type is not a named struct or enum itself (a
/// sequence, a primitive).
pub fn ros2msg_schema(shape: &TypeShape, root: &str) -> Result<Ros2Schema, Unsupported> {
    let messages = messages(shape, PACKAGE, root)?;
    Ok(Ros2Schema {
        name: messages.name().to_string(),
        text: messages.msg_text(),
    })
}

/// The value encoded (postcard) in `bytes`, as a CDR message (with its
/// encapsulation header) of the schema [`ros2msg_schema`] makes for `shape`,
/// appended to `out`. All the bytes must be used. On an error `out` holds a
/// part of the message.
pub fn write_cdr(shape: &TypeShape, bytes: &[u8], out: &mut Vec<u8>) -> Result<(), DecodeError> {
    // CDR_LE; alignment counts from after these four bytes.
    out.extend_from_slice(&[0, 1, 0, 0]);
    let mut w = Writer {
        shape,
        c: Cursor::new(bytes),
        depth: 0,
        base: out.len(),
        out,
    };
    w.value(&shape.root)?;
    w.c.end()
}

/// The name of a payload type's root message when the type is not a named
/// struct or enum: its last path segment (`alloc::vec::Vec<f64>` -> `Vec`).
/// The recorder names schemas so, and the ROS 2 bridge its own messages.
pub fn root_name(payload: &str) -> &str {
    let head = payload.split('<').next().unwrap_or(payload);
    head.rsplit("::").next().unwrap_or(head)
}

struct Writer<'a, 'o> {
    shape: &'a TypeShape,
    c: Cursor<'a>,
    depth: usize,
    /// Where the message's body starts in `out` (alignment counts from here).
    base: usize,
    out: &'o mut Vec<u8>,
}

impl Writer<'_, '_> {
    fn align(&mut self, n: usize) {
        let pad = (n - (self.out.len() - self.base) % n) % n;
        self.out.resize(self.out.len() + pad, 0);
    }

    fn put<const N: usize>(&mut self, bytes: [u8; N]) {
        self.align(N);
        self.out.extend_from_slice(&bytes);
    }

    /// A CDR length or count.
    fn count(&mut self, n: usize) -> Result<(), DecodeError> {
        let n = u32::try_from(n).map_err(|_| self.c.fail(format!("a length of {n}")))?;
        self.put(n.to_le_bytes());
        Ok(())
    }

    fn value(&mut self, f: &Format) -> Result<(), DecodeError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(self.c.fail(format!("nested deeper than {MAX_DEPTH}")));
        }
        let v = self.inner(f);
        self.depth -= 1;
        v
    }

    /// An unsigned varint of `bits` bits, as `N` little-endian bytes.
    fn unsigned<const N: usize>(&mut self) -> Result<(), DecodeError> {
        let v = self.c.varint(8 * N as u32)?;
        let mut b = [0; N];
        b.copy_from_slice(&v.to_le_bytes()[..N]);
        self.put(b);
        Ok(())
    }

    /// A zigzag varint of `bits` bits, as `N` little-endian bytes.
    fn signed<const N: usize>(&mut self) -> Result<(), DecodeError> {
        let v = self.c.signed(8 * N as u32)?;
        let mut b = [0; N];
        b.copy_from_slice(&v.to_le_bytes()[..N]);
        self.put(b);
        Ok(())
    }

    fn inner(&mut self, f: &Format) -> Result<(), DecodeError> {
        match f {
            Format::Unit => self.out.push(0),
            Format::Bool => match self.c.byte()? {
                b @ (0 | 1) => self.out.push(b),
                b => {
                    self.c.at -= 1;
                    return Err(self.c.fail(format!("a bool byte of {b}")));
                }
            },
            Format::U8 | Format::I8 => {
                let b = self.c.byte()?;
                self.out.push(b);
            }
            Format::U16 => self.unsigned::<2>()?,
            Format::U32 => self.unsigned::<4>()?,
            Format::U64 => self.unsigned::<8>()?,
            // A byte array: no alignment.
            Format::U128 => {
                let v = self.c.varint(128)?;
                self.out.extend_from_slice(&v.to_le_bytes());
            }
            Format::I16 => self.signed::<2>()?,
            Format::I32 => self.signed::<4>()?,
            Format::I64 => self.signed::<8>()?,
            Format::I128 => {
                let v = self.c.signed(128)?;
                self.out.extend_from_slice(&v.to_le_bytes());
            }
            Format::F32 => {
                let b = self.c.array::<4>()?;
                self.put(b);
            }
            Format::F64 => {
                let b = self.c.array::<8>()?;
                self.put(b);
            }
            Format::Char => self.char()?,
            Format::Str => self.string()?,
            Format::Bytes => {
                let n = self.c.length()?;
                let s = self.c.take(n)?;
                self.count(n)?;
                self.out.extend_from_slice(s);
            }
            Format::Option(inner) => self.option(inner)?,
            Format::Seq(inner) => {
                let n = self.c.length()?;
                self.count(n)?;
                for _ in 0..n {
                    self.value(inner)?;
                }
            }
            Format::Map { key, value } => {
                let n = self.c.length()?;
                self.count(n)?;
                for _ in 0..n {
                    self.value(key)?;
                    self.value(value)?;
                }
            }
            Format::Tuple(items) => self.all(items.iter())?,
            Format::TupleArray { content, size } => {
                for _ in 0..*size {
                    self.value(content)?;
                }
            }
            Format::TypeName(name) => {
                let c = self.c.container(self.shape, name)?;
                self.container(c)?;
            }
            Format::Variable(_) => {
                return Err(self.c.fail("a format left unknown by the tracer".into()));
            }
        }
        Ok(())
    }

    /// A char (postcard: its UTF-8 bytes behind their length) as CDR's
    /// 32-bit code point.
    fn char(&mut self) -> Result<(), DecodeError> {
        let n = self.c.length()?;
        let at = self.c.at;
        let s = self.c.take(n)?;
        let mut cs = std::str::from_utf8(s).ok().map(str::chars);
        match cs.as_mut().map(|cs| (cs.next(), cs.next())) {
            Some((Some(ch), None)) => self.put(u32::from(ch).to_le_bytes()),
            _ => {
                return Err(DecodeError {
                    offset: at,
                    what: "a char that is not one UTF-8 character".into(),
                });
            }
        }
        Ok(())
    }

    /// A string as CDR's: its length counting a closing NUL, its bytes, the NUL.
    fn string(&mut self) -> Result<(), DecodeError> {
        let n = self.c.length()?;
        let at = self.c.at;
        let s = self.c.take(n)?;
        std::str::from_utf8(s).map_err(|e| DecodeError {
            offset: at,
            what: format!("a string that is not UTF-8: {e}"),
        })?;
        self.count(n + 1)?;
        self.out.extend_from_slice(s);
        self.out.push(0);
        Ok(())
    }

    /// An option as a sequence of at most one element.
    fn option(&mut self, inner: &Format) -> Result<(), DecodeError> {
        match self.c.byte()? {
            0 => self.count(0)?,
            1 => {
                self.count(1)?;
                self.value(inner)?;
            }
            b => {
                self.c.at -= 1;
                return Err(self.c.fail(format!("an option tag of {b}")));
            }
        }
        Ok(())
    }

    /// The fields of a message, in order (an empty message is one byte).
    fn all<'f>(
        &mut self,
        fs: impl ExactSizeIterator<Item = &'f Format>,
    ) -> Result<(), DecodeError> {
        if fs.len() == 0 {
            self.out.push(0);
        }
        for f in fs {
            self.value(f)?;
        }
        Ok(())
    }

    fn container(&mut self, c: &ContainerFormat) -> Result<(), DecodeError> {
        match c {
            ContainerFormat::UnitStruct => self.out.push(0),
            ContainerFormat::NewTypeStruct(f) => self.value(f)?,
            ContainerFormat::TupleStruct(fs) => self.all(fs.iter())?,
            ContainerFormat::Struct(fs) => self.all(fs.iter().map(|f| &f.value))?,
            ContainerFormat::Enum(variants) => {
                let at = self.c.at;
                let k = self.c.varint(32)?;
                let chosen = u32::try_from(k).ok().filter(|k| variants.contains_key(k));
                let Some(chosen) = chosen else {
                    return Err(DecodeError {
                        offset: at,
                        what: format!("variant {k} of an enum of {}", variants.len()),
                    });
                };
                self.put(chosen.to_le_bytes());
                for (k, v) in variants {
                    let fields: &[Format] = match &v.value {
                        VariantFormat::Unit => continue,
                        VariantFormat::NewType(f) => std::slice::from_ref(&**f),
                        VariantFormat::Tuple(fs) => fs,
                        VariantFormat::Struct(fs) => {
                            // A struct variant: its message of named fields.
                            if *k != chosen {
                                self.count(0)?;
                                continue;
                            }
                            self.count(1)?;
                            self.all(fs.iter().map(|f| &f.value))?;
                            continue;
                        }
                        VariantFormat::Variable(_) => {
                            return Err(self.c.fail("a variant left unknown by the tracer".into()));
                        }
                    };
                    if *k != chosen {
                        self.count(0)?;
                        continue;
                    }
                    self.count(1)?;
                    match &v.value {
                        // A newtype's content is the element itself.
                        VariantFormat::NewType(f) => self.value(f)?,
                        _ => self.all(fields.iter())?,
                    }
                }
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;
