//! Rex's main job (preliminary).
use rex_agent::mission::Mission;
use rex_agent::rex::RexConfig;
use rex_agent::run::run_mission;
use rex_agent::world::WorldConfig;
use std::time::Duration;
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let name = std::env::args().nth(1).unwrap_or("figure_eight".into());
    let config = RexConfig::new(WorldConfig::shipped()?, Mission::shipped(&name)?);
    let out = run_mission(&config, Duration::from_secs(600), |t, a| {
        println!("[{t:7.2} s] plan {} {:?}", a.plan, a.status)
    })?;
    println!(
        "fragments {} rejected {} clamped {} planner {:?} completed {}",
        out.fragments, out.rejected_measurements, out.clamped_torques, out.planner, out.completed
    );
    for s in out.samples.iter().step_by(40) {
        println!(
            "t={:.1} truth={:.2?} ref={:.2?} err={:.3?} b={}",
            s.t,
            s.truth,
            s.reference,
            s.error(),
            s.behaviour
        );
    }
    println!("{}", out.summary_line());
    Ok(())
}
