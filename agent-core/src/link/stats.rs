//! The counters of a link between threads or processes, shared by its two
//! halves: a leaf that `thread`, `remote` and `endpoint` each use, so that
//! neither of the first two needs the other for them.

use std::sync::atomic::{AtomicU64, AtomicUsize, Ordering};

use super::LinkStats;

/// The counters of one link, shared by its two threads (relaxed atomics: they
/// are statistics, read after the threads are joined or while they run).
#[derive(Debug, Default)]
pub(crate) struct SharedStats {
    pub(crate) sent: AtomicU64,
    pub(crate) delivered: AtomicU64,
    pub(crate) overwritten: AtomicU64,
    pub(crate) overflowed: AtomicU64,
    pub(crate) max_pending: AtomicUsize,
    pub(crate) refused: AtomicU64,
    pub(crate) late: AtomicU64,
}

impl SharedStats {
    pub(crate) fn snapshot(&self) -> LinkStats {
        LinkStats {
            sent: self.sent.load(Ordering::Relaxed),
            delivered: self.delivered.load(Ordering::Relaxed),
            overwritten: self.overwritten.load(Ordering::Relaxed),
            overflowed: self.overflowed.load(Ordering::Relaxed),
            max_pending: self.max_pending.load(Ordering::Relaxed),
            refused: self.refused.load(Ordering::Relaxed),
            late: self.late.load(Ordering::Relaxed),
        }
    }
}
