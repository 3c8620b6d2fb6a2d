//! A part's batch of transfers and reads: the executor's thread appends each
//! event to a byte buffer and queues the buffer to the writer every
//! [`BATCH_BYTES`] (one queue operation, and at most one wake-up of the writer,
//! per batch instead of per value).
//!
//! An entry: a tag byte, the link (`u32`), the instant (`u64` ns), then for a
//! transfer the length (`u64`) and the value's wire bytes, for a read the
//! stamp read (iteration, instant: `u64`s); little-endian.

use agent_core::{Stamp, Time};

/// The size at which a part queues its batch.
pub(super) const BATCH_BYTES: usize = 64 * 1024;

const TRANSFER: u8 = 0;
const READ: u8 = 1;

/// One event of a batch.
#[derive(Debug, PartialEq, Eq)]
pub(super) enum Entry<'a> {
    /// A value sent on `link` at `time` (the sender's instant): its wire bytes.
    Transfer {
        link: u32,
        time: Time,
        bytes: &'a [u8],
    },
    /// A value of `link` taken at `time` (the receiver's instant).
    Read { link: u32, time: Time, stamp: Stamp },
}

pub(super) fn push_transfer(out: &mut Vec<u8>, link: u32, time: Time, bytes: &[u8]) {
    out.push(TRANSFER);
    out.extend_from_slice(&link.to_le_bytes());
    out.extend_from_slice(&time.as_nanos().to_le_bytes());
    out.extend_from_slice(&(bytes.len() as u64).to_le_bytes());
    out.extend_from_slice(bytes);
}

pub(super) fn push_read(out: &mut Vec<u8>, link: u32, time: Time, stamp: Stamp) {
    out.push(READ);
    out.extend_from_slice(&link.to_le_bytes());
    out.extend_from_slice(&time.as_nanos().to_le_bytes());
    out.extend_from_slice(&stamp.iteration.to_le_bytes());
    out.extend_from_slice(&stamp.time.as_nanos().to_le_bytes());
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
            TRANSFER => {
                let len = usize::try_from(u64_at(r, 12)?).ok()?;
                let bytes = r.get(20..20usize.checked_add(len)?)?;
                (Entry::Transfer { link, time, bytes }, 20 + len)
            }
            READ => {
                let stamp = Stamp::new(u64_at(r, 12)?, Time::from_nanos(u64_at(r, 20)?));
                (Entry::Read { link, time, stamp }, 28)
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

    #[test]
    fn entries_come_back_in_order_and_a_cut_batch_ends_at_the_cut() {
        let mut b = Vec::new();
        push_transfer(&mut b, 3, Time::from_nanos(10), b"abc");
        push_read(
            &mut b,
            4,
            Time::from_nanos(20),
            Stamp::new(7, Time::from_nanos(15)),
        );
        push_transfer(&mut b, u32::MAX, Time::from_nanos(u64::MAX), b"");
        let all: Vec<_> = entries(&b).collect();
        assert_eq!(
            all,
            [
                Entry::Transfer {
                    link: 3,
                    time: Time::from_nanos(10),
                    bytes: b"abc"
                },
                Entry::Read {
                    link: 4,
                    time: Time::from_nanos(20),
                    stamp: Stamp::new(7, Time::from_nanos(15))
                },
                Entry::Transfer {
                    link: u32::MAX,
                    time: Time::from_nanos(u64::MAX),
                    bytes: b""
                },
            ]
        );
        for cut in 0..b.len() {
            let n = entries(&b[..cut]).count();
            assert!(n < 3, "a batch cut at {cut} yields only whole entries");
        }
        assert_eq!(entries(&b[..24]).count(), 1, "the first entry is 24 bytes");
        assert_eq!(entries(&b[..23]).count(), 0);
    }
}
