//! Reading postcard, the executors' encoding of buffer values, without the
//! Rust type: the cursor the JSON and CDR writers walk a [`TypeShape`]'s
//! formats with.
//!
//! [`TypeShape`]: agent_core::TypeShape

use agent_core::TypeShape;
use agent_core::serde_reflection::ContainerFormat;

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
pub(crate) const MAX_DEPTH: usize = 128;

/// A position in a value's postcard bytes.
pub(crate) struct Cursor<'a> {
    pub(crate) bytes: &'a [u8],
    pub(crate) at: usize,
}

impl<'a> Cursor<'a> {
    pub(crate) fn new(bytes: &'a [u8]) -> Self {
        Cursor { bytes, at: 0 }
    }

    /// The container `name` stands for in `shape`.
    pub(crate) fn container<'s>(
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
    pub(crate) fn end(&self) -> Result<(), DecodeError> {
        if self.at == self.bytes.len() {
            Ok(())
        } else {
            Err(self.fail(format!("{} bytes left over", self.bytes.len() - self.at)))
        }
    }

    pub(crate) fn fail(&self, what: String) -> DecodeError {
        DecodeError {
            offset: self.at,
            what,
        }
    }

    pub(crate) fn take(&mut self, n: usize) -> Result<&'a [u8], DecodeError> {
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
    pub(crate) fn array<const N: usize>(&mut self) -> Result<[u8; N], DecodeError> {
        let s = self.take(N)?;
        let mut a = [0; N];
        a.copy_from_slice(s);
        Ok(a)
    }

    pub(crate) fn byte(&mut self) -> Result<u8, DecodeError> {
        Ok(self.take(1)?[0])
    }

    /// An unsigned LEB128 varint of at most `bits` bits.
    pub(crate) fn varint(&mut self, bits: u32) -> Result<u128, DecodeError> {
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

    pub(crate) fn signed(&mut self, bits: u32) -> Result<i128, DecodeError> {
        let z = self.varint(bits)?;
        // Zigzag.
        Ok(((z >> 1) as i128) ^ -((z & 1) as i128))
    }

    pub(crate) fn len(&mut self) -> Result<usize, DecodeError> {
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
