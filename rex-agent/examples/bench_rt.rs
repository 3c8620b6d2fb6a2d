//! A 1 kHz node's wake-up jitter under the load of Rex running beside it.
//!
//! Two real-time systems share the machine: Rex's main job in real time (the
//! default mission, visual odometry on: the world with the 1 kHz plant, the camera's
//! renderer, the VO, NMPC and MHE on their threads) and a system of one control
//! subsystem with a 1 ms period, whose thread asks for the highest FIFO priority.
//! The last line gives that node's jitter (how late it woke after each absolute
//! deadline) and overruns, and whether the OS granted real-time priority; the
//! lines before it give Rex's own plant (E1) for comparison.
//!
//! ```text
//! cargo run --release -p rex-agent --example bench_rt
//! ```

use std::time::Duration;

use embodied::prelude::*;
use embodied::{RealTime, RtConfig};
use rex_agent::run::run_mission_realtime;
use rex_agent::system::{RexConfig, RunSettings};

/// A control subsystem that does nothing but keep its period.
struct Tick;

impl Subsystem for Tick {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = u64;
    type Input = ();
    type Output = ();
}

fn tick_system() -> Result<System, Box<dyn std::error::Error>> {
    let fsm = Fsm::single(Behaviour::while_loop(
        "tick",
        Action::<Tick>::new().memory(|n: &mut u64, _: &()| *n += 1),
        "false",
    ))?;
    let mut b = SystemBuilder::new();
    let a = b.agent("bench");
    b.subsystem(a, "tick", Period::from_millis(1)?, 0u64, fsm);
    Ok(b.build()?)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let settings = RunSettings::default();
    let config: RexConfig = settings.resolve(std::path::Path::new("."))?;
    let limit = Duration::from_secs_f64(settings.limit_s.clamp(1.0, 600.0));
    let tick = RealTime::new(
        tick_system()?,
        RtConfig {
            priority: Some(90),
            ..RtConfig::realtime()
        },
    )
    .start(Duration::from_secs(3600))?;
    let (outcome, rex) =
        run_mission_realtime(&config, limit, Duration::MAX, RtConfig::realtime(), |_| {})?;
    tick.stop();
    let tick = tick.join()?;
    let report = tick.report();
    let node = report.node("tick").ok_or("no tick node")?;
    println!("# Rex beside it: {}", outcome.summary_line());
    if let Some(e1) = rex.node("E1") {
        println!(
            "# Rex's plant E1 (1 kHz, world thread): jitter_us_p50={:.1} jitter_us_p99={:.1} jitter_us_max={:.1} overruns={}",
            e1.jitter.p50.as_secs_f64() * 1e6,
            e1.jitter.p99.as_secs_f64() * 1e6,
            e1.jitter.max.as_secs_f64() * 1e6,
            e1.overruns
        );
    }
    let p99 = node.jitter.p99.as_secs_f64() * 1e6;
    println!(
        "# the 1 kHz node: {} activations, jitter max {:.1} us, p99 / aim (100 us) = {:.2}",
        node.activations,
        node.jitter.max.as_secs_f64() * 1e6,
        p99 / 100.0
    );
    println!(
        "period_us={} jitter_us_p50={:.1} jitter_us_p99={:.1} overruns={} rt_priority={}",
        node.period.as_nanos() / 1000,
        node.jitter.p50.as_secs_f64() * 1e6,
        p99,
        node.overruns,
        if report.rt_priority() { "yes" } else { "no" }
    );
    Ok(())
}
