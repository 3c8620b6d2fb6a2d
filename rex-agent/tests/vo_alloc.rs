//! The visual odometry allocates nothing per pair once its buffers have grown (on
//! one thread: with more, the scoped threads of a pair allocate their stacks).
//! A counting allocator watches this test's thread while it processes pairs it has
//! seen before; the test is alone in its binary so nothing else counts.

use std::alloc::{GlobalAlloc, Layout, System};
use std::cell::Cell;
use std::sync::atomic::{AtomicUsize, Ordering};

use rex_agent::algorithms::vo::{StereoOdometry, VoSettings};
use rex_agent::world::camera::{CameraConfig, Renderer, SceneConfig};

struct Counting;

static ALLOCATIONS: AtomicUsize = AtomicUsize::new(0);

thread_local! {
    static WATCHED: Cell<bool> = const { Cell::new(false) };
}

fn count() {
    // `try_with`: the thread-local may be gone while a thread exits.
    if WATCHED.try_with(Cell::get).unwrap_or(false) {
        ALLOCATIONS.fetch_add(1, Ordering::Relaxed);
    }
}

// SAFETY: every method forwards to the system allocator with the caller's arguments
// unchanged; counting has no effect on the memory handed out.
#[expect(
    unsafe_code,
    reason = "a global allocator is an unsafe trait; this one only counts"
)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: the caller's contract, passed on.
        unsafe { System.alloc(layout) }
    }

    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        count();
        // SAFETY: as above.
        unsafe { System.alloc_zeroed(layout) }
    }

    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        count();
        // SAFETY: as above.
        unsafe { System.realloc(ptr, layout, new_size) }
    }

    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: as above.
        unsafe { System.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

#[test]
fn a_pair_allocates_nothing_once_the_buffers_have_grown() {
    let camera = CameraConfig::default();
    let renderer = Renderer::new(camera.clone(), SceneConfig::default_room()).unwrap();
    let (w, h) = (camera.width as usize, camera.height as usize);
    // Five pairs 8 cm and 1.5° apart, rendered before anything is counted.
    let pairs: Vec<(Vec<u8>, Vec<u8>)> = (0..5)
        .map(|k| {
            let k = f64::from(k);
            let (mut l, mut r) = (Vec::new(), Vec::new());
            renderer.render_pair(
                [0.08 * k, 0.3, 0.2 + 1.5f64.to_radians() * k],
                &mut l,
                &mut r,
            );
            (l, r)
        })
        .collect();
    let mut vo = StereoOdometry::new(camera.calibration(), VoSettings::default()).unwrap();
    // Grow the buffers: the sequence once.
    for (l, r) in &pairs {
        assert!(vo.process(l, r, w, h).is_ok());
    }
    // The same pairs again (the first one of them after a jump back), counted.
    let mut motions = 0;
    WATCHED.with(|c| c.set(true));
    for (l, r) in &pairs[1..] {
        motions += usize::from(matches!(vo.process(l, r, w, h), Ok(Some(_))));
    }
    WATCHED.with(|c| c.set(false));
    let allocations = ALLOCATIONS.load(Ordering::Relaxed);
    assert_eq!(motions, 4, "every pair gave a motion");
    assert_eq!(allocations, 0, "allocations while processing 4 pairs");
}
