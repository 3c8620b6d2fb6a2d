//! Hints to the cache for the executor's walks over thousands of nodes.
//!
//! In a system of thousands of subsystems the nodes, their ports and their
//! channels no longer fit in the caches, and an instant's two walks over them
//! (every read, then every step) would wait on each one's lines. The
//! executor asks for them a few nodes ahead (`executor::reach`), and asks
//! the kernel to back the memory they lie in with huge pages ([`huge_pages`]),
//! whose entries in the TLB cover 512 times more. Measured in
//! docs/scaling.md; the prefetch elsewhere than on x86_64 and the huge pages
//! elsewhere than on Linux, nothing.

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

/// Ask the kernel to back the huge-page-sized regions (2 MiB) that hold
/// `addresses` with huge pages, now (Linux's `MADV_COLLAPSE`, 6.1 and
/// later; whatever the system's transparent-huge-page setting). A node, its
/// ports and its channels are then reached through a TLB entry shared with
/// hundreds of others, not one of their own. Each region is asked alone: one
/// the allocator's mapping does not wholly cover (at the ends of the heap), or
/// that the kernel cannot collapse (no huge page free, an older kernel), stays
/// as it is. Returns how many regions were collapsed. The memory a region's
/// unused pages take becomes resident (at most 2 MiB a region).
pub(crate) fn huge_pages(addresses: impl IntoIterator<Item = usize>) -> usize {
    let mut regions: Vec<usize> = addresses.into_iter().map(|a| a / HUGE_PAGE).collect();
    regions.sort_unstable();
    regions.dedup();
    regions
        .into_iter()
        .filter(|&r| collapse(r * HUGE_PAGE))
        .count()
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
        let collapsed = huge_pages(every_page);
        assert!(collapsed <= 5, "{collapsed} regions of an 8 MiB vector");
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
        assert_eq!(huge_pages([0x1000, 0x2000]), 0);
        assert_eq!(huge_pages([]), 0);
    }
}
