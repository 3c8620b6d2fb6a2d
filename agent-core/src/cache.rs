//! Hints to the cache for the executor's walks over thousands of nodes.
//!
//! In a system of thousands of subsystems the nodes, their ports and their
//! channels no longer fit in the caches, and an instant's two walks over them
//! (every read, then every step) would wait on each one's lines. The
//! executor asks for them a few nodes ahead (`executor::reach`). Measured in
//! docs/scaling.md; elsewhere than on x86_64, nothing.

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
