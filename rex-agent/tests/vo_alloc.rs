//! The visual odometry allocates nothing per pair once its buffers have grown (on
//! one thread: with more, the scoped threads of a pair allocate their stacks).
//! agent-core's counting allocator counts this test's thread while it processes
//! pairs it has seen before.

use embodied::allocations::{CountingAllocator, count};
use rex_agent::algorithms::vo::{StereoOdometry, VoSettings};
use rex_agent::world::camera::{CameraConfig, Renderer, SceneConfig};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

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
    let (allocations, motions) = count(|| {
        pairs[1..]
            .iter()
            .filter(|(l, r)| matches!(vo.process(l, r, w, h), Ok(Some(_))))
            .count()
    })
    .unwrap();
    assert_eq!(motions, 4, "every pair gave a motion");
    assert_eq!(allocations, 0, "allocations while processing 4 pairs");
}
