//! Every mission on every surface, with the paper's control (NMPC tracker +
//! MHE) and with the baseline (Kanayama's backstepping law + EKF), back to back
//! in one process: the main job's `--no-vo` runs, deterministic, so one run
//! each is the figure (no timing involved).
//!
//! Prints the RMS tracking error (truth against reference, m) per mission and
//! surface, then the plans each side achieved (acknowledged done, reported
//! reached by `e11` and confirmed by the simulation's truth), and ends with
//! `worst_ratio=<max over the missions on concrete and grass of rms(NMPC+MHE) /
//! rms(baseline)> ice_rms_m=<max RMS of NMPC+MHE over the missions on ice>
//! ice_done=<plans acknowledged done>/<plans>` (NMPC+MHE, on ice).
//!
//! ```text
//! cargo run --release -p rex-agent --example bench_missions [-- --vo]
//! ```
//!
//! `--vo` runs with visual odometry (the main job's default; much slower).

use std::path::Path;
use std::time::Duration;

use rex_agent::a1::e11::{EstimatorKind, TrackerKind};
use rex_agent::run::{Outcome, run_mission};
use rex_agent::system::RunSettings;

const MISSIONS: [&str; 3] = ["square", "figure_eight", "slalom"];
const SURFACES: [&str; 3] = ["concrete", "grass", "ice"];

fn run(
    mission: &str,
    surface: &str,
    tracker: TrackerKind,
    estimator: EstimatorKind,
    vo: bool,
) -> Result<Outcome, Box<dyn std::error::Error>> {
    let settings = RunSettings {
        mission: mission.to_owned(),
        surface: Some(surface.to_owned()),
        tracker,
        estimator,
        visual_odometry: vo,
        ..RunSettings::default()
    };
    let config = settings.resolve(Path::new("."))?;
    let limit = Duration::from_secs(600);
    Ok(run_mission(&config, limit, limit, |_| {})?)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let vo = std::env::args().any(|a| a == "--vo");
    println!(
        "RMS tracking error [m], NMPC+MHE vs Kanayama+EKF ({})",
        if vo {
            "with visual odometry"
        } else {
            "--no-vo"
        }
    );
    println!("| surface | {} |", MISSIONS.join(" | "));
    println!("|---|{}", "---|".repeat(MISSIONS.len()));
    let mut worst_ratio = 0.0f64;
    let mut ice_rms = 0.0f64;
    let (mut ice_done, mut ice_plans) = (0, 0);
    let mut achieved = Vec::new();
    for surface in SURFACES {
        let mut cells = Vec::new();
        for mission in MISSIONS {
            let ours = run(mission, surface, TrackerKind::Nmpc, EstimatorKind::Mhe, vo)?;
            let base = run(
                mission,
                surface,
                TrackerKind::Backstepping,
                EstimatorKind::Ekf,
                vo,
            )?;
            let (a, b) = (ours.rms(), base.rms());
            cells.push(format!("{a:.4} vs {b:.4}"));
            if surface == "ice" {
                ice_rms = ice_rms.max(a);
                ice_done += ours.plans_done();
                ice_plans += ours.plans;
            } else {
                worst_ratio = worst_ratio.max(a / b);
            }
            let friction = ours.friction_estimate().map_or("none".to_owned(), |p| {
                format!("mu_long {:.3} mu_lat {:.3} rolling {:.3}", p[0], p[1], p[2])
            });
            achieved.push(format!(
                "{surface}/{mission}: achieved {}/{} vs {}/{}; done {} vs {}; false successes {} vs {}; \
                 simulated {:.1} s vs {:.1} s; friction estimated at the end: {friction}",
                ours.plans_achieved(),
                ours.plans,
                base.plans_achieved(),
                base.plans,
                ours.plans_done(),
                base.plans_done(),
                ours.false_done(),
                base.false_done(),
                ours.sim_s,
                base.sim_s,
            ));
        }
        println!("| {surface} | {} |", cells.join(" | "));
    }
    println!("plans and durations (NMPC+MHE vs Kanayama+EKF):");
    for line in achieved {
        println!("  {line}");
    }
    println!("worst_ratio={worst_ratio:.3} ice_rms_m={ice_rms:.3} ice_done={ice_done}/{ice_plans}");
    Ok(())
}
