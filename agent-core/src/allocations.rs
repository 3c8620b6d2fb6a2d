//! Counting heap allocations: to show that a transition function, an
//! executor's cycle or a recorder's send allocates nothing in steady state.
//!
//! Make [`CountingAllocator`] the global allocator of a test or benchmark
//! binary (one per binary: it counts for the whole process), then [`count`]
//! what one thread allocates while a closure runs, or read [`total`] for the
//! whole process. Allocations, zeroed allocations and reallocations count;
//! deallocations do not. The memory itself comes from the system allocator,
//! unchanged.
//!
//! ```
//! use agent_core::allocations::{CountingAllocator, count};
//!
//! #[global_allocator]
//! static ALLOCATOR: CountingAllocator = CountingAllocator;
//!
//! fn main() {
//!     let mut buffer = Vec::with_capacity(8);
//!     let (n, ()) = count(|| buffer.extend([1u8, 2, 3])).unwrap();
//!     assert_eq!(n, 0, "within capacity");
//!     let (n, ()) = count(|| buffer.extend([0u8; 64])).unwrap();
//!     assert_eq!(n, 1, "one reallocation");
//!     // Nested: the outer count includes the inner one's.
//!     let (outer, inner) = count(|| {
//!         let v = vec![0u8; 16];
//!         let (inner, ()) = count(|| drop(vec![1u8; 16])).unwrap();
//!         drop(v);
//!         inner
//!     })
//!     .unwrap();
//!     assert_eq!((outer, inner), (2, 1));
//! }
//! ```
//!
//! Without the allocator installed, [`count`] is an error rather than a count
//! of zero that would prove nothing.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};

/// The system allocator, counting (see the [module](self) documentation).
#[derive(Clone, Copy, Debug, Default)]
pub struct CountingAllocator;

static TOTAL: AtomicU64 = AtomicU64::new(0);

thread_local! {
    /// Whether this thread's allocations are counted, and how many so far.
    /// `const`-initialised: reading them never allocates.
    static WATCHED: Cell<bool> = const { Cell::new(false) };
    static COUNT: Cell<u64> = const { Cell::new(0) };
}

fn counted() {
    TOTAL.fetch_add(1, Ordering::Relaxed);
    // `try_with`: a thread being torn down has no locals left (not counted
    // per thread, still in the total).
    let _ = WATCHED.try_with(|watched| {
        if watched.get() {
            let _ = COUNT.try_with(|c| c.set(c.get() + 1));
        }
    });
}

// SAFETY: every method forwards to the system allocator with the caller's
// arguments unchanged; counting touches an atomic and `const`-initialised
// thread locals only, which never allocate.
#[expect(
    unsafe_code,
    reason = "a global allocator is an unsafe trait; this one only counts"
)]
unsafe impl GlobalAlloc for CountingAllocator {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        counted();
        // SAFETY: the caller's contract, passed on.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        counted();
        // SAFETY: the caller's contract, passed on.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        counted();
        // SAFETY: the caller's contract, passed on.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: the caller's contract, passed on.
        unsafe { System.dealloc(ptr, layout) }
    }
}

/// [`CountingAllocator`] is not the program's global allocator: nothing is
/// counted.
#[derive(Clone, Copy, Debug, PartialEq, Eq, thiserror::Error)]
#[error(
    "CountingAllocator is not this program's global allocator (add \
     `#[global_allocator] static ALLOCATOR: CountingAllocator = CountingAllocator;`)"
)]
pub struct NotInstalled;

/// The allocations this thread makes while `f` runs (other threads' are not
/// counted), and what `f` returns. Calls may nest: an inner call's
/// allocations count in the outer one too.
///
/// # Errors
/// [`NotInstalled`] (before `f` runs) when [`CountingAllocator`] is not the
/// global allocator: a probe allocation was not counted.
pub fn count<T>(f: impl FnOnce() -> T) -> Result<(u64, T), NotInstalled> {
    let (outer, before) = (WATCHED.with(Cell::get), COUNT.with(Cell::get));
    COUNT.with(|c| c.set(0));
    WATCHED.with(|w| w.set(true));
    drop(std::hint::black_box(Box::new(0u8)));
    if COUNT.with(Cell::get) != 1 {
        WATCHED.with(|w| w.set(outer));
        COUNT.with(|c| c.set(before));
        return Err(NotInstalled);
    }
    COUNT.with(|c| c.set(0));
    // Restores the outer state even if `f` unwinds.
    let restore = Restore { outer, before };
    let out = f();
    let n = COUNT.with(Cell::get);
    drop(restore);
    Ok((n, out))
}

/// The watching state of an enclosing [`count`] (or none), restored on drop,
/// with what the inner one counted added to it.
struct Restore {
    outer: bool,
    before: u64,
}

impl Drop for Restore {
    fn drop(&mut self) {
        let n = COUNT.with(Cell::get);
        WATCHED.with(|w| w.set(self.outer));
        COUNT.with(|c| c.set(self.before + n));
    }
}

/// The allocations of the whole process so far (every thread), when
/// [`CountingAllocator`] is the global allocator; 0 otherwise.
pub fn total() -> u64 {
    TOTAL.load(Ordering::Relaxed)
}

#[cfg(test)]
mod tests {
    #[test]
    fn without_the_allocator_installed_count_is_an_error() {
        // This crate's unit tests run on the system allocator.
        assert_eq!(super::count(|| ()), Err(super::NotInstalled));
        assert!(
            super::NotInstalled
                .to_string()
                .contains("#[global_allocator]")
        );
    }
}
