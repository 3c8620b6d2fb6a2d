//! When the readers of a sample link in other processes read: its writer
//! publishes only the values they can see.
//!
//! A sample link's reader sees, at each of its activations, the latest value
//! written before it; a value written over before the next read is never seen
//! (in-process it is counted as overwritten). Every node runs at the multiples
//! of its period from the instant zero its deployment shares, so the writer's
//! process knows every read instant of a reader in another process, and its
//! own next activation: a value is published at the writer's last activation
//! before the read that sees it (at once when the writer writes at that
//! activation, which a writer that writes at every activation always does).
//! So is the last value written before a fallback instant a tenth of the
//! reader's period before each read ([`FALLBACK`]): what a read takes when its
//! own value arrives after it. A 1 kHz sensor read every 50 ms crosses 40
//! times a second, not 1,000.
//!
//! The values read are those of a link between threads at the same instants:
//! the deterministic executor's rule (a value sent at `t` is read at the
//! reader's first activation strictly after `t`) picks which value each read
//! sees, and the real-time reader takes it if it arrived (as over any link
//! between processes), else the fallback. A queue link is never thinned
//! (every value is read).

use crate::time::{Period, Time};

/// The read instants of a sample link's readers in other processes, and its
/// writer's period.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct ReadGrid {
    /// The writer's period \[ns\]: after an activation at `t`, its next is at
    /// `t + writer`.
    writer: u64,
    /// The instants a value is published for, as (period, lead) \[ns\]: the
    /// multiples of `period` less `lead`. Each reader's reads (lead 0; none
    /// whose period is a multiple of another's: its reads are among that
    /// one's), and its fallbacks ([`FALLBACK`]).
    instants: Vec<(u64, u64)>,
}

/// A reader's fallback instant is this fraction of its period before each of
/// its reads: the last value written before it is published too, so that a
/// read whose own value arrives late (the transport's latency is not zero,
/// and the writer publishes one writer period before the read) takes one
/// written a tenth of a period before, not nothing. On time, the read's own
/// value replaces it before the read, which takes what a link in one process
/// gives.
pub(crate) const FALLBACK: u64 = 10;

impl ReadGrid {
    /// The grid of a writer of period `writer` whose readers elsewhere have
    /// the periods `readers`; `None` when every written value is seen (no
    /// reader, or one as fast as the writer): then every value is published.
    pub(crate) fn new(
        writer: Period,
        readers: impl IntoIterator<Item = Period>,
    ) -> Option<ReadGrid> {
        let writer = writer.as_nanos();
        let mut periods: Vec<u64> = readers.into_iter().map(Period::as_nanos).collect();
        periods.sort_unstable();
        periods.dedup();
        if periods.first().is_none_or(|&fastest| fastest <= writer) {
            return None;
        }
        let mut instants: Vec<(u64, u64)> = Vec::with_capacity(2 * periods.len());
        for &p in &periods {
            if !instants.iter().any(|&(r, _)| p.is_multiple_of(r)) {
                instants.push((p, 0));
            }
        }
        // A fallback at least a writer period before the read: another value.
        for p in periods {
            let lead = p / FALLBACK;
            if lead > writer {
                instants.push((p, lead));
            }
        }
        Some(ReadGrid { writer, instants })
    }

    /// The first instant strictly after `t` that a value is published for
    /// \[ns\]: a value written at `t` is read at the first read after it
    /// (`u64::MAX` past the end of time).
    pub(crate) fn next_read(&self, t: Time) -> u64 {
        let t = t.as_nanos();
        self.instants
            .iter()
            .map(|&(r, lead)| {
                (t.saturating_add(lead) / r)
                    .saturating_add(1)
                    .saturating_mul(r)
                    .saturating_sub(lead)
            })
            .min()
            .unwrap_or(u64::MAX)
    }

    /// Whether the writer's activation at `now` is its last before the read
    /// at `read`: its next activation is not before that read (or `now` is
    /// already past it: activations were skipped, and the value is late).
    pub(crate) fn last_before(&self, now: Time, read: u64) -> bool {
        now.as_nanos().saturating_add(self.writer) >= read
    }
}

/// A value written and not yet published: its message, and the read that
/// sees it.
#[derive(Debug, Default)]
pub(crate) struct Held {
    /// The read instant that sees the value, if one is held \[ns\].
    pub(crate) read: Option<u64>,
    /// The message, encoded when the value was written.
    pub(crate) message: Vec<u8>,
}

// Beside this file, as remote_tests.rs: agent-core's module-graph test reads
// one folder level per top-level module.
#[cfg(test)]
#[path = "reads_tests.rs"]
mod tests;
