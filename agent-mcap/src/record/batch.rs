//! A part's batch of transfers and reads: the executor's thread appends each
//! event to a byte buffer and queues the buffer to the writer every
//! [`BATCH_BYTES`] (one queue operation, and at most one wake-up of the writer,
//! per batch instead of per value).
//!
//! An entry: a tag byte, the link (`u32`), the instant (`u64` ns), then for a
//! transfer the sender's iteration (`u64`), the length (`u64`) and the
//! value's postcard bytes (encoded in place: the wire header a raw message
//! carries is the writer's to make), for a read the stamp read (iteration,
//! instant: `u64`s), for a value received from another process as for a
//! transfer; for the predicates of a node after an activation, the node in
//! the link's place, the iteration, and the values' `known` and `value` bits
//! (`u64`s); little-endian.

use agent_core::{Stamp, Time, Valuation};

/// The size at which a part queues its batch.
pub(super) const BATCH_BYTES: usize = 64 * 1024;

/// The capacity a new batch buffer is made with: a batch is sent with the
/// first entry that takes it to [`BATCH_BYTES`], which for values of up to
/// 4 KiB fits without growing the buffer.
pub(super) const BATCH_CAPACITY: usize = BATCH_BYTES + 4 * 1024;

const TRANSFER: u8 = 0;
const READ: u8 = 1;
const RECEIVED: u8 = 2;
const PREDICATES: u8 = 3;

/// One event of a batch.
#[derive(Debug, PartialEq, Eq)]
pub(super) enum Entry<'a> {
    /// A value sent on `link` with `stamp` (the sender's): its postcard bytes.
    Transfer {
        link: u32,
        stamp: Stamp,
        body: &'a [u8],
    },
    /// A value of `link` taken at `time` (the receiver's instant).
    Read { link: u32, time: Time, stamp: Stamp },
    /// A value of `link` that came from another process, taken with `stamp`
    /// (the sender's): its postcard bytes.
    Received {
        link: u32,
        stamp: Stamp,
        body: &'a [u8],
    },
    /// The predicates of `node` after its activation at `time`.
    Predicates {
        node: u32,
        time: Time,
        iteration: u64,
        values: Valuation,
    },
}

/// Append a transfer whose bytes `encode` appends to `out`; if it fails,
/// `out` is cut back to where it was and the error returned.
pub(super) fn push_transfer<E>(
    out: &mut Vec<u8>,
    link: u32,
    stamp: Stamp,
    encode: impl FnOnce(&mut Vec<u8>) -> Result<(), E>,
) -> Result<(), E> {
    push_value(out, TRANSFER, link, stamp, encode)
}

/// Append a value received from another process, as [`push_transfer`] does a
/// value sent.
pub(super) fn push_received<E>(
    out: &mut Vec<u8>,
    link: u32,
    stamp: Stamp,
    encode: impl FnOnce(&mut Vec<u8>) -> Result<(), E>,
) -> Result<(), E> {
    push_value(out, RECEIVED, link, stamp, encode)
}

fn push_value<E>(
    out: &mut Vec<u8>,
    tag: u8,
    link: u32,
    stamp: Stamp,
    encode: impl FnOnce(&mut Vec<u8>) -> Result<(), E>,
) -> Result<(), E> {
    let start = out.len();
    out.push(tag);
    out.extend_from_slice(&link.to_le_bytes());
    out.extend_from_slice(&stamp.time.as_nanos().to_le_bytes());
    out.extend_from_slice(&stamp.iteration.to_le_bytes());
    let len_at = out.len();
    out.extend_from_slice(&0u64.to_le_bytes());
    if let Err(e) = encode(out) {
        out.truncate(start);
        return Err(e);
    }
    let len = (out.len() - len_at - 8) as u64;
    out[len_at..len_at + 8].copy_from_slice(&len.to_le_bytes());
    Ok(())
}

pub(super) fn push_read(out: &mut Vec<u8>, link: u32, time: Time, stamp: Stamp) {
    out.push(READ);
    out.extend_from_slice(&link.to_le_bytes());
    out.extend_from_slice(&time.as_nanos().to_le_bytes());
    out.extend_from_slice(&stamp.iteration.to_le_bytes());
    out.extend_from_slice(&stamp.time.as_nanos().to_le_bytes());
}

/// Append the predicates of `node` after its activation `iteration` at `time`.
pub(super) fn push_predicates(
    out: &mut Vec<u8>,
    node: u32,
    time: Time,
    iteration: u64,
    values: Valuation,
) {
    out.push(PREDICATES);
    out.extend_from_slice(&node.to_le_bytes());
    out.extend_from_slice(&time.as_nanos().to_le_bytes());
    out.extend_from_slice(&iteration.to_le_bytes());
    out.extend_from_slice(&values.known.to_le_bytes());
    out.extend_from_slice(&values.value.to_le_bytes());
}

/// The entries of a batch, in the order they were pushed. A batch is made by
/// the functions above in this process; should one ever be cut short, the
/// iteration ends at the cut.
pub(super) fn entries(batch: &[u8]) -> impl Iterator<Item = Entry<'_>> {
    let mut rest = batch;
    std::iter::from_fn(move || {
        let (&tag, r) = rest.split_first()?;
        let link = u32::from_le_bytes(r.get(..4)?.try_into().ok()?);
        let time = Time::from_nanos(u64_at(r, 4)?);
        let (entry, used) = match tag {
            TRANSFER | RECEIVED => {
                let iteration = u64_at(r, 12)?;
                let len = usize::try_from(u64_at(r, 20)?).ok()?;
                let body = r.get(28..28usize.checked_add(len)?)?;
                let stamp = Stamp::new(iteration, time);
                let entry = if tag == TRANSFER {
                    Entry::Transfer { link, stamp, body }
                } else {
                    Entry::Received { link, stamp, body }
                };
                (entry, 28 + len)
            }
            READ => {
                let stamp = Stamp::new(u64_at(r, 12)?, Time::from_nanos(u64_at(r, 20)?));
                (Entry::Read { link, time, stamp }, 28)
            }
            PREDICATES => {
                let values = Valuation {
                    known: u64_at(r, 20)?,
                    value: u64_at(r, 28)?,
                };
                let iteration = u64_at(r, 12)?;
                let entry = Entry::Predicates {
                    node: link,
                    time,
                    iteration,
                    values,
                };
                (entry, 36)
            }
            _ => return None,
        };
        rest = &r[used..];
        Some(entry)
    })
}

fn u64_at(b: &[u8], at: usize) -> Option<u64> {
    Some(u64::from_le_bytes(b.get(at..at + 8)?.try_into().ok()?))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bytes(b: &'static [u8]) -> impl FnOnce(&mut Vec<u8>) -> Result<(), ()> {
        move |out| {
            out.extend_from_slice(b);
            Ok(())
        }
    }

    #[test]
    fn entries_come_back_in_order_and_a_cut_batch_ends_at_the_cut() {
        let mut b = Vec::new();
        let s = |i, t| Stamp::new(i, Time::from_nanos(t));
        push_transfer(&mut b, 3, s(2, 10), bytes(b"abc")).expect("pushed");
        push_read(&mut b, 4, Time::from_nanos(20), s(7, 15));
        push_transfer(&mut b, u32::MAX, s(u64::MAX, u64::MAX), bytes(b"")).expect("pushed");
        push_received(&mut b, 5, s(3, 30), bytes(b"rx")).expect("pushed");
        let values = Valuation {
            known: 0b1011,
            value: 0b0010,
        };
        push_predicates(&mut b, 6, Time::from_nanos(40), 9, values);
        let all: Vec<_> = entries(&b).collect();
        assert_eq!(
            all,
            [
                Entry::Transfer {
                    link: 3,
                    stamp: s(2, 10),
                    body: b"abc"
                },
                Entry::Read {
                    link: 4,
                    time: Time::from_nanos(20),
                    stamp: s(7, 15)
                },
                Entry::Transfer {
                    link: u32::MAX,
                    stamp: s(u64::MAX, u64::MAX),
                    body: b""
                },
                Entry::Received {
                    link: 5,
                    stamp: s(3, 30),
                    body: b"rx"
                },
                Entry::Predicates {
                    node: 6,
                    time: Time::from_nanos(40),
                    iteration: 9,
                    values
                },
            ]
        );
        for cut in 0..b.len() {
            let n = entries(&b[..cut]).count();
            assert!(n < 5, "a batch cut at {cut} yields only whole entries");
        }
        assert_eq!(entries(&b[..32]).count(), 1, "the first entry is 32 bytes");
        assert_eq!(entries(&b[..31]).count(), 0);
    }

    #[test]
    fn a_transfer_that_fails_to_encode_leaves_the_batch_as_it_was() {
        let mut b = Vec::new();
        let s = Stamp::new(1, Time::from_nanos(5));
        push_transfer(&mut b, 1, s, bytes(b"xy")).expect("pushed");
        let before = b.clone();
        let failed = push_transfer(&mut b, 2, s, |out| {
            out.extend_from_slice(b"half");
            Err("no")
        });
        assert_eq!(failed, Err("no"));
        assert_eq!(b, before);
        assert_eq!(entries(&b).count(), 1);
    }
}
