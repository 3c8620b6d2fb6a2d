//! Speed of Rex's simulated world.
//!
//! ```text
//! cargo run --release -p rex-agent --example bench_world
//! ```
//!
//! * `plant_realtime_factor`: simulated seconds per wall-clock second of the platform
//!   alone (full model at 1 kHz with its encoders, IMU and force sensors), driven by
//!   a torque profile that accelerates, turns both ways and brakes.
//! * `render_ms`: median wall time to render one 640×480 stereo pair on one core, at
//!   60 poses along a path through the shipped room, the path rendered three times
//!   (the mean, p95, p99 and max over the 180 pairs are printed above it).

use std::time::Instant;

// Shared with the other benches; this one prints no ratios.
#[allow(dead_code, reason = "the module is shared; this bench uses part of it")]
#[path = "common/stats.rs"]
mod stats;

use rex_agent::world::WorldConfig;
use rex_agent::world::camera::Renderer;
use rex_agent::world::devices::Platform;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let config = WorldConfig::shipped()?;

    // The platform alone.
    let mut platform = Platform::new(config.plant()?, config.sensors.clone())?;
    let dt = 1e-3;
    let seconds = 120.0;
    let steps = (seconds / dt) as usize;
    let profile = |t: f64| -> [f64; 4] {
        let phase = (t / 6.0).floor() as i64 % 4;
        match phase {
            0 => [3.0, 3.0, 3.0, 3.0],
            1 => [-1.0, -1.0, 6.0, 6.0],
            2 => [6.0, 6.0, -1.0, -1.0],
            _ => [-2.0, -2.0, -2.0, -2.0],
        }
    };
    let start = Instant::now();
    let mut check = 0.0;
    for k in 0..steps {
        let (imu, loads, enc) = platform.advance(profile(k as f64 * dt), dt);
        check += imu.yaw_rate + loads.load[0] * 1e-6 + enc.rate[3] * 1e-6;
    }
    let wall = start.elapsed().as_secs_f64();
    let factor = seconds / wall;
    let s = platform.plant().state;
    println!(
        "platform: {seconds} s simulated in {:.3} s wall ({:.2} us per 1 ms step); final pose ({:.2}, {:.2}, {:.2}) [{check:.3}]",
        wall,
        wall / steps as f64 * 1e6,
        s.x,
        s.y,
        s.phi
    );

    // Rendering.
    let renderer = Renderer::new(config.camera.clone(), config.scene.clone())?;
    let (mut left, mut right) = (Vec::new(), Vec::new());
    let mut times = Vec::new();
    for _ in 0..3 {
        for k in 0..60 {
            let t = k as f64 * 0.1;
            let pose = [2.0 * (0.5 * t).sin(), (1.0 * t).sin(), 0.5 * t];
            let start = Instant::now();
            renderer.render_pair(pose, &mut left, &mut right);
            times.push(start.elapsed().as_secs_f64() * 1e3);
        }
    }
    let stats = stats::Stats::of(&times);
    let render_ms = stats.median;
    println!(
        "render: {}x{} stereo pair, {stats} over {} pairs (60 poses, 3 times)",
        config.camera.width,
        config.camera.height,
        times.len()
    );
    println!(
        "against the targets: plant factor {:.1}x of 200 (above 1 is better), render {:.2}x of 15 ms (below 1 is better)",
        factor / 200.0,
        render_ms / 15.0
    );
    println!("plant_realtime_factor={factor:.0} render_ms={render_ms:.2}");
    Ok(())
}
