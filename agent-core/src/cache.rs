//! Hints to the cache for the executor's walks over thousands of nodes.

/// Ask the cache for the first `lines` cache lines (64 bytes each) of `x`:
/// a node a few places ahead of the executor's walk over the nodes due (its
/// FSM state, buffers and port tables). In a system of
/// thousands of subsystems the nodes no longer fit in the caches, and an
/// instant's two walks over them (every read, then every step) would wait on
/// each node's lines. Measured in docs/scaling.md; elsewhere than on x86_64,
/// nothing.
#[inline(always)]
pub(crate) fn prefetch<T: ?Sized>(x: &T, lines: usize) {
    #[cfg(target_arch = "x86_64")]
    #[allow(unsafe_code, reason = "a cache hint: it reads nothing")]
    // SAFETY: a prefetch is a hint to the cache: it neither reads nor writes
    // memory as the program sees it and cannot fault, whatever the address
    // (here a live value's and the lines after it); SSE is part of every
    // x86_64 target.
    unsafe {
        let p = (x as *const T).cast::<i8>();
        for line in 0..lines {
            std::arch::x86_64::_mm_prefetch::<{ std::arch::x86_64::_MM_HINT_T0 }>(
                p.wrapping_add(64 * line),
            );
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (x, lines);
}
