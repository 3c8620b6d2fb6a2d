//! The ECSA trajectory planner's cost.
//!
//! ```text
//! cargo run --release -p rex-agent --example bench_planner [-- --peer PEERS_DIR]
//! ```
//!
//! Two sets of tasks:
//!
//! * the four tasks of `peers/ecsa_demo.py` (lane change, sideways shift, backwards
//!   turn, U-turn in place, from the origin, T = 10 s), solved to 1e-3 as the peer
//!   does and to 1e-5 as c1 does;
//! * the fragments of the figure-eight mission, chained as c1 chains them (each from
//!   the end of the previous one, desired orientations from `proc`), the planner's
//!   real work in the main job.
//!
//! Each task is planned 30 times; the figure per task is the median, the figure of a
//! set the median over its tasks. With `--peer DIR`, `DIR/ecsa_demo.py` runs in the
//! same session (it needs `pip install casadi numpy`) and its line is printed with
//! the ratio. The last line is
//! `ecsa_ms=<median ms per figure-eight fragment> ecsa_iters=<median iterations>`.

use std::time::Instant;

use rex_agent::a1::c1::{C1Params, proc};
use rex_agent::algorithms::planner::ecsa::Ecsa;
use rex_agent::algorithms::planner::{Planner, PlannerSettings, Waypoint};
use rex_agent::mission::Mission;
use rex_agent::payload::Plan;

const REPEAT: usize = 30;

fn median(v: &mut [f64]) -> f64 {
    v.sort_by(f64::total_cmp);
    match v.len() {
        0 => f64::NAN,
        n if n % 2 == 1 => v[n / 2],
        n => (v[n / 2 - 1] + v[n / 2]) / 2.0,
    }
}

/// Median ms over `REPEAT` runs of `f`, and what the last run returned.
fn time<T>(mut f: impl FnMut() -> T) -> (f64, T) {
    let mut ms = Vec::with_capacity(REPEAT);
    let t = Instant::now();
    let mut last = f();
    ms.push(t.elapsed().as_secs_f64() * 1e3);
    for _ in 1..REPEAT {
        let t = Instant::now();
        last = f();
        ms.push(t.elapsed().as_secs_f64() * 1e3);
    }
    (median(&mut ms), last)
}

fn peer_tasks(tolerance: f64) -> (f64, f64) {
    let tasks = [
        (2.0, 1.0, 0.0),
        (0.0, 1.0, 0.0),
        (-1.0, 0.5, std::f64::consts::FRAC_PI_2),
        (1.0, 0.0, std::f64::consts::PI),
    ];
    let mut planner = Ecsa::new(PlannerSettings::default());
    planner.ecsa.tolerance = tolerance;
    let (mut ms, mut iters) = (Vec::new(), Vec::new());
    for (x, y, phi) in tasks {
        // T = 10 s in 200 samples (400 RK4 steps; the peer takes 200).
        let (t, r) = time(|| planner.solve([0.0; 3], [x, y, phi], true, 10.0, 400));
        match r {
            Ok((_, stats)) => {
                println!(
                    "# task ({x}, {y}, {phi:.3}) tol {tolerance:e}: {} iterations, error {:.1e}, {t:.3} ms",
                    stats.iterations, stats.error
                );
                iters.push(stats.iterations as f64);
            }
            Err(e) => println!("# task ({x}, {y}, {phi:.3}): {e}"),
        }
        ms.push(t);
    }
    (median(&mut ms), median(&mut iters))
}

fn figure_eight() -> Result<(f64, f64, usize), Box<dyn std::error::Error>> {
    let mission = Mission::shipped("figure_eight")?;
    let settings = PlannerSettings {
        speed_max: 0.9,
        turn_rate_max: 1.2,
        ..PlannerSettings::default()
    };
    let mut planner = Ecsa::new(settings);
    let mut from = [0.0; 3];
    let (mut ms, mut iters) = (Vec::new(), Vec::new());
    for (k, points) in mission.plans.iter().enumerate() {
        let plan = Plan {
            id: k as u32 + 1,
            points: points.clone(),
            first: 0,
        };
        let waypoints = proc(&plan, &C1Params::default())?;
        for w in waypoints {
            let w: Waypoint = w;
            let (t, r) = time(|| planner.plan(from, &w));
            let (fragment, stats) = r?;
            ms.push(t);
            iters.push((stats.iterations + stats.restarts) as f64);
            if let Some(end) = fragment.end() {
                from = [end[0], end[1], end[2]];
            }
        }
    }
    let n = ms.len();
    Ok((median(&mut ms), median(&mut iters), n))
}

fn run_peer(dir: &str) -> Option<(f64, f64)> {
    let script = std::path::Path::new(dir).join("ecsa_demo.py");
    let out = std::process::Command::new("python3")
        .arg(&script)
        .output()
        .map_err(|e| eprintln!("peer: cannot run {}: {e}", script.display()))
        .ok()?;
    let text = String::from_utf8_lossy(&out.stdout);
    if !out.status.success() {
        eprintln!("peer: {}", String::from_utf8_lossy(&out.stderr).trim());
        return None;
    }
    let line = text.lines().find(|l| l.starts_with("ecsa median_iters="))?;
    println!("# peer: {line}");
    let field = |key: &str| {
        line.split_whitespace()
            .find_map(|kv| kv.strip_prefix(key))
            .and_then(|v| v.parse::<f64>().ok())
    };
    Some((field("median_ms=")?, field("median_iters=")?))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let peer = args
        .iter()
        .position(|a| a == "--peer")
        .and_then(|i| args.get(i + 1));
    let (peer_ms, peer_iters) = peer_tasks(1e-3);
    println!("peer_tasks tol=1e-3 ecsa_ms={peer_ms:.3} ecsa_iters={peer_iters:.0}");
    let (ms5, it5) = peer_tasks(1e-5);
    println!("peer_tasks tol=1e-5 ecsa_ms={ms5:.3} ecsa_iters={it5:.0}");
    if let Some(dir) = peer {
        match run_peer(dir) {
            Some((ms, iters)) => println!(
                "peer casadi median_ms={ms:.2} median_iters={iters:.0} ratio_ms={:.3} (ours / peer, same tasks and tolerance)",
                peer_ms / ms
            ),
            None => println!("peer: no figures"),
        }
    }
    let (ms, iters, n) = figure_eight()?;
    println!(
        "# figure_eight: {n} fragments, target ecsa_ms <= 1 (ratio {:.3}), ecsa_iters <= 15",
        ms / 1.0
    );
    println!("ecsa_ms={ms:.3} ecsa_iters={iters:.0}");
    Ok(())
}
