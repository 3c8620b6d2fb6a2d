//! Hints to the cache for the executor's walks over thousands of nodes.
//!
//! In a system of thousands of subsystems the nodes, their ports and their
//! channels no longer fit in the caches, and an instant's two walks over them
//! (every read, then every step) would wait on each one's lines. The
//! executor asks for them a few nodes ahead (`executor::reach`), and asks
//! the kernel to back the memory they lie in with huge pages ([`Collapse`]),
//! whose entries in the TLB cover 512 times more. Measured in
//! docs/scaling.md; the prefetch elsewhere than on x86_64 and the huge pages
//! elsewhere than on Linux, nothing.

use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// Ask the cache for the first `lines` cache lines (64 bytes each) of `x`
/// (a node: its FSM state, buffers and port tables).
#[inline(always)]
pub(crate) fn prefetch<T: ?Sized>(x: &T, lines: usize) {
    prefetch_addr(std::ptr::from_ref(x).addr(), lines);
}

/// Ask the cache for the `lines` cache lines from the address `addr`.
#[inline(always)]
pub(crate) fn prefetch_addr(addr: usize, lines: usize) {
    #[cfg(target_arch = "x86_64")]
    #[allow(unsafe_code, reason = "a cache hint: it reads nothing")]
    // SAFETY: a prefetch is a hint to the cache: it neither reads nor writes
    // memory as the program sees it and cannot fault, whatever the address
    // (here a live value's and the lines after it); SSE is part of every
    // x86_64 target.
    unsafe {
        let p = std::ptr::without_provenance::<i8>(addr);
        for line in 0..lines {
            std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
                p.wrapping_add(64 * line),
            );
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (addr, lines);
}

/// Push onto `to` the address of `value`, unless it has no bytes (an
/// empty port table: its address is no allocation's).
pub(crate) fn address_of<T: ?Sized>(value: &T, to: &mut Vec<usize>) {
    if size_of_val(value) > 0 {
        to.push(std::ptr::from_ref(value).addr());
    }
}

/// The size of a huge page on x86_64 and aarch64 Linux: 2 MiB.
const HUGE_PAGE: usize = 2 << 20;

/// The huge-page regions (their indices) that hold `addresses`, each once.
fn regions(addresses: impl IntoIterator<Item = usize>) -> Vec<usize> {
    let mut regions: Vec<usize> = addresses.into_iter().map(|a| a / HUGE_PAGE).collect();
    regions.sort_unstable();
    regions.dedup();
    regions
}

/// Collapse `regions` one after the other.
fn collapse_all(regions: &[usize]) -> HugePages {
    let start = Instant::now();
    let collapsed = regions.iter().filter(|&&r| collapse(r * HUGE_PAGE)).count();
    HugePages {
        regions: regions.len(),
        collapsed,
        took: start.elapsed(),
    }
}

/// Regions asked for where the executor is made rather than on a thread of
/// their own: at most this many (a thread's start, 20 to 90 µs and now and
/// then near a millisecond on the machine of docs/scaling.md, costs more
/// than their copy).
const INLINE_REGIONS: usize = 2;

/// What the kernel did with an executor's request for huge pages
/// ([`ExecConfig::huge_pages`](crate::ExecConfig::huge_pages), told by
/// [`Executor::wait_for_huge_pages`](crate::Executor::wait_for_huge_pages)).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
#[non_exhaustive]
pub struct HugePages {
    /// The 2 MiB regions that hold the executor's nodes, ports and channels
    /// (none when it asked for none).
    pub regions: usize,
    /// Those the kernel backed with a huge page: a region the allocator's
    /// mapping does not wholly cover, or that the kernel refuses (no huge
    /// page free, Linux before 6.1, another system), stays as it was.
    pub collapsed: usize,
    /// How long the kernel took over them.
    pub took: Duration,
}

/// An executor's request for huge pages, on a thread of its own when it is
/// more than a few regions: the kernel copies each region's small pages into
/// a huge page (0.2 to 1.4 ms a region of fresh memory: from a few to tens of
/// milliseconds for 10,000 subsystems), and since nothing the program sees
/// changes meanwhile, the executor need not wait for it before it steps (its
/// actions are the faster once the copy is done). Dropped before the copy
/// is done (with its executor), it waits for it: the executor's memory goes
/// back to the allocator on huge pages, as it would have without the thread,
/// and no region is copied once its memory is another's.
pub(crate) struct Collapse(Stage);

/// Where a [`Collapse`] is.
enum Stage {
    /// Done: what it came to.
    Done(HugePages),
    /// The thread at work.
    Running(JoinHandle<HugePages>),
}

impl Collapse {
    /// Nothing asked for.
    pub(crate) fn none() -> Collapse {
        Collapse(Stage::Done(HugePages::default()))
    }

    /// Ask the kernel to back the huge-page-sized regions (2 MiB) that hold
    /// `addresses` with huge pages (Linux's `MADV_COLLAPSE`, 6.1 and later;
    /// whatever the system's transparent-huge-page setting): here when they
    /// are few ([`INLINE_REGIONS`]) or no thread can be started, else on a
    /// thread of their own. A node, its ports and its channels are then
    /// reached through a TLB entry shared with hundreds of others, not one of
    /// their own. Each region is asked alone: one the allocator's mapping
    /// does not wholly cover (at the ends of the heap), or that the kernel
    /// cannot collapse (no huge page free, an older kernel), stays as it is.
    /// The memory a region's unused pages take becomes resident (at most
    /// 2 MiB a region).
    pub(crate) fn start(addresses: impl IntoIterator<Item = usize>) -> Collapse {
        let regions = regions(addresses);
        if regions.len() > INLINE_REGIONS {
            let theirs = regions.clone();
            let spawned = std::thread::Builder::new()
                .name("huge-pages".into())
                .spawn(move || collapse_all(&theirs));
            if let Ok(thread) = spawned {
                return Collapse(Stage::Running(thread));
            }
        }
        Collapse(Stage::Done(collapse_all(&regions)))
    }

    /// Wait until the kernel is done; what it did.
    pub(crate) fn wait(&mut self) -> HugePages {
        let done = match std::mem::replace(&mut self.0, Stage::Done(HugePages::default())) {
            Stage::Done(done) => done,
            // A thread that panicked (nothing in it can) is counted as
            // having collapsed nothing.
            Stage::Running(thread) => thread.join().unwrap_or_default(),
        };
        self.0 = Stage::Done(done);
        done
    }
}

impl Drop for Collapse {
    fn drop(&mut self) {
        self.wait();
    }
}

/// Collapse the huge-page region at `start` (aligned) into one huge page.
#[cfg(target_os = "linux")]
fn collapse(start: usize) -> bool {
    /// `MADV_COLLAPSE` in Linux's UAPI headers, on every architecture.
    const MADV_COLLAPSE: libc::c_int = 25;
    #[allow(
        unsafe_code,
        reason = "madvise: a hint about memory the program already owns"
    )]
    // SAFETY: MADV_COLLAPSE neither reads nor changes memory as the program
    // sees it: the kernel copies a region's pages into one huge page under
    // its own locks, the contents and the addresses kept, while other
    // threads may use them. A region not wholly mapped is refused with an
    // error (ENOMEM), never faulted; the address is only passed to the
    // kernel, never dereferenced here.
    let r = unsafe {
        libc::madvise(
            std::ptr::without_provenance_mut(start),
            HUGE_PAGE,
            MADV_COLLAPSE,
        )
    };
    r == 0
}

#[cfg(not(target_os = "linux"))]
fn collapse(_: usize) -> bool {
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    fn pattern(i: usize) -> u64 {
        (i as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15)
    }

    /// The kernel's count of huge pages in the mapping that holds `addr`
    /// (kB), from /proc/self/smaps.
    #[cfg(target_os = "linux")]
    fn huge_kb_at(addr: usize) -> Option<u64> {
        let smaps = std::fs::read_to_string("/proc/self/smaps").ok()?;
        let mut inside = false;
        for line in smaps.lines() {
            let mut words = line.split_whitespace();
            let first = words.next()?;
            if let Some((from, to)) = first.split_once('-')
                && let (Ok(from), Ok(to)) = (
                    usize::from_str_radix(from, 16),
                    usize::from_str_radix(to, 16),
                )
            {
                inside = (from..to).contains(&addr);
            } else if inside && first == "AnonHugePages:" {
                return words.next()?.parse().ok();
            }
        }
        None
    }

    #[test]
    fn collapsed_memory_keeps_its_values_and_is_counted_as_huge_by_the_kernel() {
        // 8 MiB: at least three whole regions of 2 MiB inside it.
        let values: Vec<u64> = (0..1 << 20).map(pattern).collect();
        let base = values.as_ptr().addr();
        let every_page = (0..values.len()).step_by(512).map(|i| base + 8 * i);
        let done = Collapse::start(every_page).wait();
        let collapsed = done.collapsed;
        assert!((4..=5).contains(&done.regions), "{done:?}: an 8 MiB vector");
        assert!(collapsed <= done.regions, "{done:?}");
        let changed = (values.iter().enumerate()).find(|&(i, &v)| v != pattern(i));
        assert_eq!(changed, None, "a value changed by the collapse");
        // What it says it collapsed, the kernel counts as huge pages (the
        // kernel may refuse: an older one, or no huge page free).
        #[cfg(target_os = "linux")]
        if collapsed > 0 {
            let huge = huge_kb_at(base).unwrap_or(0);
            assert!(
                huge >= 2048 * collapsed as u64,
                "{huge} kB huge, {collapsed} collapsed"
            );
        }
    }

    #[test]
    fn a_region_not_wholly_mapped_is_left_as_it_is() {
        // The first 2 MiB of the address space are never all mapped.
        let done = Collapse::start([0x1000, 0x2000]).wait();
        assert_eq!((done.regions, done.collapsed), (1, 0));
        let done = Collapse::start([]).wait();
        assert_eq!((done.regions, done.collapsed), (0, 0));
        assert_eq!(Collapse::none().wait(), HugePages::default());
    }

    #[test]
    fn memory_written_while_its_regions_collapse_on_their_thread_keeps_every_value() {
        // 32 MiB: the kernel copies region after region while this thread
        // writes every value again, page by page.
        let mut values: Vec<u64> = (0..1 << 22).map(pattern).collect();
        let base = values.as_ptr().addr();
        let every_page = (0..values.len()).step_by(512).map(|i| base + 8 * i);
        let mut collapse = Collapse::start(every_page);
        assert!(
            matches!(collapse.0, Stage::Running(_)),
            "16 regions or more, asked on a thread"
        );
        for round in 1..=4u64 {
            for (i, v) in values.iter_mut().enumerate() {
                *v = pattern(i) ^ round;
            }
        }
        let done = collapse.wait();
        assert!(
            done.regions >= 16 && done.collapsed <= done.regions,
            "{done:?}"
        );
        assert_eq!(collapse.wait(), done, "told again once done");
        let changed = (values.iter().enumerate()).find(|&(i, &v)| v != pattern(i) ^ 4);
        assert_eq!(changed, None, "a value lost to the collapse");
    }
}
