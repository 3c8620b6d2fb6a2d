//! A ROS 2 CDR message read back into a buffer value's postcard bytes, by the
//! same [`TypeShape`] and the same mapping as [`write_cdr`](super::write_cdr):
//! what a value that arrives from ROS 2 (an inbound topic) or from a CDR
//! channel becomes before anything acts on it.
//!
//! The bytes come from outside, so everything is checked and nothing is
//! trusted: the encapsulation header (little-endian CDR, `00 01`), every
//! length against the bytes left, booleans of 0 or 1, strings in UTF-8 with
//! their closing NUL, chars that are Unicode scalar values, an option's and a
//! variant's count of 0 or 1 (exactly the chosen variant's 1), the nesting
//! depth, and that the message ends where its last field does (CDR may pad
//! the end to 4 bytes). An error names the offset in the message.

use agent_core::TypeShape;
use agent_core::serde_reflection::{ContainerFormat, Format, VariantFormat};

use crate::postcard::{DecodeError, MAX_DEPTH};

/// The value of the CDR message `cdr` (with its 4-byte encapsulation header),
/// laid out as [`write_cdr`](super::write_cdr) lays out a value of `shape`,
/// as postcard bytes appended to `out`. On an error `out` holds a part of the
/// value.
pub fn read_cdr(shape: &TypeShape, cdr: &[u8], out: &mut Vec<u8>) -> Result<(), DecodeError> {
    match cdr {
        [0, 1, _, _, ..] => {}
        [0, 0, _, _, ..] => {
            return Err(DecodeError {
                offset: 0,
                what: "big-endian CDR (only little-endian is read)".into(),
            });
        }
        [_, _, _, _, ..] => {
            return Err(DecodeError {
                offset: 0,
                what: format!(
                    "an encapsulation of {:02x} {:02x}, not CDR (00 01)",
                    cdr[0], cdr[1]
                ),
            });
        }
        _ => {
            return Err(DecodeError {
                offset: 0,
                what: "no encapsulation header (4 bytes)".into(),
            });
        }
    }
    let mut r = Reader {
        shape,
        body: &cdr[4..],
        at: 0,
        depth: 0,
        out,
    };
    r.value(&shape.root)?;
    // A writer may pad the message to a multiple of 4 bytes.
    let left = r.body.len() - r.at;
    if left >= 4 || r.body[r.at..].iter().any(|b| *b != 0) {
        return Err(r.fail(format!("{left} bytes after the message")));
    }
    Ok(())
}

struct Reader<'a, 'o> {
    shape: &'a TypeShape,
    /// The message after its header (alignment counts from its start).
    body: &'a [u8],
    at: usize,
    depth: usize,
    out: &'o mut Vec<u8>,
}

impl<'a> Reader<'a, '_> {
    fn fail(&self, what: String) -> DecodeError {
        // Offsets count from the start of the message, header included.
        DecodeError {
            offset: self.at + 4,
            what,
        }
    }

    fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        let end = self
            .at
            .checked_add(n)
            .filter(|e| *e <= self.body.len())
            .ok_or_else(|| self.fail(format!("{n} more bytes expected, the message ends")))?;
        let s = &self.body[self.at..end];
        self.at = end;
        Ok(s)
    }

    fn aligned<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        let pad = (N - self.at % N) % N;
        self.take(pad)?;
        let mut a = [0; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }

    fn byte(&mut self) -> Result<u8, DecodeError> {
        Ok(self.take(1)?[0])
    }

    /// A CDR length or count, at most the bytes left (`min_each`: the fewest
    /// bytes an element takes, so a count cannot promise more than is there).
    fn count(&mut self, min_each: usize) -> Result<usize, DecodeError> {
        let n = u32::from_le_bytes(self.aligned::<4>()?) as usize;
        let left = self.body.len() - self.at;
        if n.saturating_mul(min_each.max(1)) > left && n > 0 {
            self.at -= 4;
            return Err(self.fail(format!("a count of {n} with {left} bytes left")));
        }
        Ok(n)
    }

    /// A count that must be 0 or 1 (an option, a variant's data).
    fn zero_or_one(&mut self, what: &str) -> Result<bool, DecodeError> {
        match u32::from_le_bytes(self.aligned::<4>()?) {
            0 => Ok(false),
            1 => Ok(true),
            n => {
                self.at -= 4;
                Err(self.fail(format!("{what} with a count of {n}, not 0 or 1")))
            }
        }
    }

    fn varint(&mut self, mut v: u128) {
        while v >= 0x80 {
            self.out.push((v as u8) | 0x80);
            v >>= 7;
        }
        self.out.push(v as u8);
    }

    fn zigzag(&mut self, v: i128) {
        self.varint(((v << 1) ^ (v >> 127)) as u128);
    }

    fn value(&mut self, f: &Format) -> Result<(), DecodeError> {
        self.depth += 1;
        if self.depth > MAX_DEPTH {
            return Err(self.fail(format!("nested deeper than {MAX_DEPTH}")));
        }
        let v = self.inner(f);
        self.depth -= 1;
        v
    }

    fn inner(&mut self, f: &Format) -> Result<(), DecodeError> {
        match f {
            Format::Unit => self.empty()?,
            Format::Bool => match self.byte()? {
                b @ (0 | 1) => self.out.push(b),
                b => {
                    self.at -= 1;
                    return Err(self.fail(format!("a bool byte of {b}")));
                }
            },
            Format::U8 | Format::I8 => {
                let b = self.byte()?;
                self.out.push(b);
            }
            Format::U16 => {
                let v = u16::from_le_bytes(self.aligned()?);
                self.varint(v.into());
            }
            Format::U32 => {
                let v = u32::from_le_bytes(self.aligned()?);
                self.varint(v.into());
            }
            Format::U64 => {
                let v = u64::from_le_bytes(self.aligned()?);
                self.varint(v.into());
            }
            Format::U128 => {
                let mut b = [0; 16];
                b.copy_from_slice(self.take(16)?);
                self.varint(u128::from_le_bytes(b));
            }
            Format::I16 => {
                let v = i16::from_le_bytes(self.aligned()?);
                self.zigzag(v.into());
            }
            Format::I32 => {
                let v = i32::from_le_bytes(self.aligned()?);
                self.zigzag(v.into());
            }
            Format::I64 => {
                let v = i64::from_le_bytes(self.aligned()?);
                self.zigzag(v.into());
            }
            Format::I128 => {
                let mut b = [0; 16];
                b.copy_from_slice(self.take(16)?);
                self.zigzag(i128::from_le_bytes(b));
            }
            Format::F32 => {
                let b = self.aligned::<4>()?;
                self.out.extend_from_slice(&b);
            }
            Format::F64 => {
                let b = self.aligned::<8>()?;
                self.out.extend_from_slice(&b);
            }
            Format::Char => self.char()?,
            Format::Str => self.string()?,
            Format::Bytes => {
                let n = self.count(1)?;
                let s = self.take(n)?;
                self.varint(n as u128);
                self.out.extend_from_slice(s);
            }
            Format::Option(inner) => {
                if self.zero_or_one("an option")? {
                    self.out.push(1);
                    self.value(inner)?;
                } else {
                    self.out.push(0);
                }
            }
            Format::Seq(inner) => self.seq(&[inner])?,
            Format::Map { key, value } => self.seq(&[key, value])?,
            Format::Tuple(items) => self.all(items.iter())?,
            Format::TupleArray { content, size } => {
                for _ in 0..*size {
                    self.value(content)?;
                }
            }
            Format::TypeName(name) => {
                let shape = self.shape;
                let c = shape
                    .registry
                    .get(name)
                    .ok_or_else(|| self.fail(format!("type `{name}` is not in the shape")))?;
                self.container(c)?;
            }
            Format::Variable(_) => {
                return Err(self.fail("a format left unknown by the tracer".into()));
            }
        }
        Ok(())
    }

    /// An empty message: one byte, 0.
    fn empty(&mut self) -> Result<(), DecodeError> {
        match self.byte()? {
            0 => Ok(()),
            b => {
                self.at -= 1;
                Err(self.fail(format!("an empty message's byte of {b}, not 0")))
            }
        }
    }

    /// A sequence (of values, or of a map's key and value pairs).
    fn seq(&mut self, each: &[&Format]) -> Result<(), DecodeError> {
        let n = self.count(1)?;
        self.varint(n as u128);
        for _ in 0..n {
            for f in each {
                self.value(f)?;
            }
        }
        Ok(())
    }

    /// CDR's 32-bit code point as postcard's char: its UTF-8 behind its length.
    fn char(&mut self) -> Result<(), DecodeError> {
        let v = u32::from_le_bytes(self.aligned()?);
        let Some(ch) = char::from_u32(v) else {
            self.at -= 4;
            return Err(self.fail(format!("a char of {v:#x}, not a Unicode scalar value")));
        };
        let mut buf = [0; 4];
        let s = ch.encode_utf8(&mut buf);
        self.varint(s.len() as u128);
        self.out.extend_from_slice(s.as_bytes());
        Ok(())
    }

    /// CDR's string (its length counting the closing NUL, its bytes, the NUL)
    /// as postcard's (its length, its bytes).
    fn string(&mut self) -> Result<(), DecodeError> {
        let at = self.at;
        let n = self.count(1)?;
        let s = self.take(n)?;
        let Some((0, text)) = s.split_last() else {
            self.at = at;
            return Err(self.fail("a string without its closing NUL".into()));
        };
        if let Err(e) = std::str::from_utf8(text) {
            self.at = at;
            return Err(self.fail(format!("a string that is not UTF-8: {e}")));
        }
        self.varint(text.len() as u128);
        self.out.extend_from_slice(text);
        Ok(())
    }

    /// The fields of a message in order (an empty message is one byte, 0).
    fn all<'f>(
        &mut self,
        fs: impl ExactSizeIterator<Item = &'f Format>,
    ) -> Result<(), DecodeError> {
        if fs.len() == 0 {
            return self.empty();
        }
        for f in fs {
            self.value(f)?;
        }
        Ok(())
    }

    fn container(&mut self, c: &'a ContainerFormat) -> Result<(), DecodeError> {
        match c {
            ContainerFormat::UnitStruct => self.empty(),
            ContainerFormat::NewTypeStruct(f) => self.value(f),
            ContainerFormat::TupleStruct(fs) => self.all(fs.iter()),
            ContainerFormat::Struct(fs) => self.all(fs.iter().map(|f| &f.value)),
            ContainerFormat::Enum(variants) => {
                let at = self.at;
                let chosen = u32::from_le_bytes(self.aligned()?);
                if !variants.contains_key(&chosen) {
                    self.at = at;
                    return Err(
                        self.fail(format!("variant {chosen} of an enum of {}", variants.len()))
                    );
                }
                self.varint(chosen.into());
                for (k, v) in variants {
                    self.variant(*k == chosen, &v.value)?;
                }
                Ok(())
            }
        }
    }

    /// One variant's optional data: present (count 1) exactly when `chosen`.
    fn variant(&mut self, chosen: bool, v: &VariantFormat) -> Result<(), DecodeError> {
        let at = self.at;
        let present = match v {
            VariantFormat::Unit => return Ok(()),
            VariantFormat::Variable(_) => {
                return Err(self.fail("a variant left unknown by the tracer".into()));
            }
            _ => self.zero_or_one("a variant's data")?,
        };
        if present != chosen {
            self.at = at;
            return Err(self.fail(if chosen {
                "the chosen variant without its data".into()
            } else {
                "data for a variant that is not the chosen one".into()
            }));
        }
        if !chosen {
            return Ok(());
        }
        match v {
            VariantFormat::NewType(f) => self.value(f),
            VariantFormat::Tuple(fs) => self.all(fs.iter()),
            VariantFormat::Struct(fs) => self.all(fs.iter().map(|f| &f.value)),
            VariantFormat::Unit | VariantFormat::Variable(_) => Ok(()),
        }
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;
    use serde::{Deserialize, Serialize};

    use super::read_cdr;
    use crate::cdr::write_cdr;
    use crate::json::tests::{everything, shape};

    fn round_trip(shape: &agent_core::TypeShape, bytes: &[u8]) -> Vec<u8> {
        let mut cdr = Vec::new();
        write_cdr(shape, bytes, &mut cdr).unwrap();
        let mut back = Vec::new();
        read_cdr(shape, &cdr, &mut back).unwrap();
        back
    }

    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    struct Nested {
        rows: Vec<Vec<f64>>,
        maybe: Option<[u8; 4]>,
        names: Vec<String>,
        empty: Empty,
        tag: Tag,
    }

    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    struct Empty {}

    #[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
    enum Tag {
        None,
        Code(u32),
        At { x: f32, y: f32 },
    }

    fn nested() -> impl Strategy<Value = Nested> {
        let tag = prop_oneof![
            Just(Tag::None),
            any::<u32>().prop_map(Tag::Code),
            (any::<f32>(), any::<f32>()).prop_map(|(x, y)| Tag::At { x, y }),
        ];
        (
            prop::collection::vec(prop::collection::vec(any::<f64>(), 0..4), 0..4),
            any::<Option<[u8; 4]>>(),
            prop::collection::vec(".{0,6}", 0..3),
            tag,
        )
            .prop_map(|(rows, maybe, names, tag)| Nested {
                rows,
                maybe,
                names,
                empty: Empty {},
                tag,
            })
    }

    proptest! {
        #[test]
        fn what_write_cdr_wrote_reads_back_to_the_same_postcard_bytes(v in everything()) {
            let bytes = postcard::to_allocvec(&v).unwrap();
            prop_assert_eq!(round_trip(&shape(), &bytes), bytes);
        }

        #[test]
        fn nested_arrays_options_empty_messages_and_enums_read_back(v in nested()) {
            let shape = agent_core::reflect::<Nested>().unwrap();
            let bytes = postcard::to_allocvec(&v).unwrap();
            let back = round_trip(&shape, &bytes);
            prop_assert_eq!(postcard::from_bytes::<Nested>(&back).unwrap(), v);
        }

        #[test]
        fn hostile_messages_give_an_error_never_a_panic(body in prop::collection::vec(any::<u8>(), 0..300)) {
            let mut cdr = vec![0, 1, 0, 0];
            cdr.extend(body);
            let _ = read_cdr(&shape(), &cdr, &mut Vec::new());
            let _ = read_cdr(&agent_core::reflect::<Nested>().unwrap(), &cdr, &mut Vec::new());
        }
    }

    fn error(shape: &agent_core::TypeShape, cdr: &[u8]) -> String {
        read_cdr(shape, cdr, &mut Vec::new())
            .unwrap_err()
            .to_string()
    }

    #[test]
    fn the_header_says_little_endian_cdr() {
        let s = agent_core::reflect::<u32>().unwrap();
        assert!(error(&s, &[0, 0, 0, 0, 0, 0, 0, 1]).contains("big-endian"));
        assert!(error(&s, &[0, 3, 0, 0, 1, 0, 0, 0]).contains("not CDR"));
        assert!(error(&s, &[0, 1]).contains("no encapsulation header"));
        let mut ok = Vec::new();
        read_cdr(&s, &[0, 1, 0, 0, 0x2c, 1, 0, 0], &mut ok).unwrap();
        assert_eq!(postcard::from_bytes::<u32>(&ok).unwrap(), 300);
    }

    #[test]
    fn values_cdr_cannot_hold_for_the_type_are_refused_with_their_offset() {
        let flag = agent_core::reflect::<bool>().unwrap();
        assert_eq!(error(&flag, &[0, 1, 0, 0, 2]), "byte 4: a bool byte of 2");
        let text = agent_core::reflect::<String>().unwrap();
        // "hi" without its NUL; then not UTF-8.
        assert!(error(&text, &[0, 1, 0, 0, 2, 0, 0, 0, b'h', b'i']).contains("closing NUL"));
        assert!(error(&text, &[0, 1, 0, 0, 2, 0, 0, 0, 0xff, 0]).contains("not UTF-8"));
        // A count far beyond the message: refused before any loop.
        assert!(error(&text, &[0, 1, 0, 0, 0xff, 0xff, 0xff, 0x7f]).contains("a count of"));
        let option = agent_core::reflect::<Option<u8>>().unwrap();
        assert!(error(&option, &[0, 1, 0, 0, 2, 0, 0, 0, 7]).contains("not 0 or 1"));
        let ch = agent_core::reflect::<char>().unwrap();
        assert!(error(&ch, &[0, 1, 0, 0, 0, 0xd8, 0, 0]).contains("not a Unicode scalar value"));
        // Trailing bytes beyond CDR's padding.
        let n = agent_core::reflect::<u8>().unwrap();
        assert!(error(&n, &[0, 1, 0, 0, 7, 0, 0, 0, 0]).contains("bytes after the message"));
        assert!(error(&n, &[0, 1, 0, 0, 7, 1]).contains("bytes after the message"));
        let mut ok = Vec::new();
        read_cdr(&n, &[0, 1, 0, 0, 7, 0, 0, 0], &mut ok).unwrap();
        assert_eq!(ok, [7]);
    }

    #[test]
    fn an_enum_carries_exactly_its_chosen_variants_data() {
        let s = agent_core::reflect::<Tag>().unwrap();
        // Variant 1 (Code) with its data, and At's count 0.
        let good = [0, 1, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 9, 0, 0, 0, 0, 0, 0, 0];
        let mut out = Vec::new();
        read_cdr(&s, &good, &mut out).unwrap();
        assert_eq!(postcard::from_bytes::<Tag>(&out).unwrap(), Tag::Code(9));
        let mut without = good;
        without[8] = 0;
        assert!(error(&s, &without[..12]).contains("without its data"));
        let other = [
            0, 1, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 9, 0, 0, 0, 1, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
        ];
        assert!(error(&s, &other).contains("not the chosen one"));
        assert!(error(&s, &[0, 1, 0, 0, 7, 0, 0, 0]).contains("variant 7 of an enum of 3"));
    }
}
