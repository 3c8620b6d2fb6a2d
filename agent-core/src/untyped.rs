//! Reading postcard, the executors' encoding of buffer values, without the
//! Rust type: the cursor that a recording's JSON and CDR writers and a
//! contract monitor's range walk a [`TypeShape`]'s formats with. Nothing here
//! allocates but an error's message.

use crate::TypeShape;
use serde_reflection::ContainerFormat;

/// Why bytes did not decode as the shape says.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("byte {offset}: {what}")]
pub struct DecodeError {
    /// Where in the bytes.
    pub offset: usize,
    /// What was expected or found.
    pub what: String,
}

/// Deeper nesting than this is refused (a recursive type fed hostile bytes).
pub const MAX_DEPTH: usize = 128;

/// A position in a value's postcard bytes.
#[derive(Clone, Debug)]
pub struct Cursor<'a> {
    /// The value's bytes.
    pub bytes: &'a [u8],
    /// The next byte to read.
    pub at: usize,
}

impl<'a> Cursor<'a> {
    /// A cursor at the start of `bytes`.
    pub fn new(bytes: &'a [u8]) -> Self {
        Cursor { bytes, at: 0 }
    }

    /// The container `name` stands for in `shape`.
    pub fn container<'s>(
        &self,
        shape: &'s TypeShape,
        name: &str,
    ) -> Result<&'s ContainerFormat, DecodeError> {
        shape
            .registry
            .get(name)
            .ok_or_else(|| self.fail(format!("type `{name}` is not in the shape")))
    }

    /// Every byte was read.
    pub fn end(&self) -> Result<(), DecodeError> {
        if self.at == self.bytes.len() {
            Ok(())
        } else {
            Err(self.fail(format!("{} bytes left over", self.bytes.len() - self.at)))
        }
    }

    /// An error at the cursor.
    pub fn fail(&self, what: String) -> DecodeError {
        DecodeError {
            offset: self.at,
            what,
        }
    }

    /// The next `n` bytes.
    pub fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
        let end = self
            .at
            .checked_add(n)
            .filter(|e| *e <= self.bytes.len())
            .ok_or_else(|| self.fail(format!("{n} more bytes expected, the value ends")))?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }

    /// The next `N` bytes (a float's).
    pub fn array<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        let s = self.take(N)?;
        let mut a = [0; N];
        a.copy_from_slice(s);
        Ok(a)
    }

    /// The next byte.
    pub fn byte(&mut self) -> Result<u8, DecodeError> {
        Ok(self.take(1)?[0])
    }

    /// An unsigned LEB128 varint of at most `bits` bits.
    pub fn varint(&mut self, bits: u32) -> Result<u128, DecodeError> {
        let start = self.at;
        let mut v: u128 = 0;
        let mut shift = 0u32;
        loop {
            let b = self.byte()?;
            if shift >= bits || (shift > 0 && u128::from(b & 0x7f) >> (bits - shift) != 0) {
                self.at = start;
                return Err(self.fail(format!("a varint longer than {bits} bits")));
            }
            v |= u128::from(b & 0x7f) << shift;
            if b & 0x80 == 0 {
                return Ok(v);
            }
            shift += 7;
        }
    }

    /// A zigzag-encoded signed varint of at most `bits` bits.
    pub fn signed(&mut self, bits: u32) -> Result<i128, DecodeError> {
        let z = self.varint(bits)?;
        // Zigzag.
        Ok(((z >> 1) as i128) ^ -((z & 1) as i128))
    }

    /// A sequence's, string's or map's length (refused when longer than the
    /// bytes left could hold).
    pub fn length(&mut self) -> Result<usize, DecodeError> {
        let n = self.varint(64)?;
        let n = usize::try_from(n).map_err(|_| self.fail(format!("a length of {n}")))?;
        // Every element takes a byte at least (except units): a longer length
        // than the bytes left is a corrupt one, not an allocation to make.
        if n > self.bytes.len() - self.at && n > 0 {
            return Err(self.fail(format!(
                "a length of {n} with {} bytes left",
                self.bytes.len() - self.at
            )));
        }
        Ok(n)
    }
}
