//! Soak: Rex on random patrols of ten simulated minutes and more, with each
//! estimator and tracker, with and without visual odometry and motion-capture
//! dropouts, judged against the simulation's truth.
//!
//! ```sh
//! cargo run --release -p rex-agent --example soak                 # 12 cases x 10 min, seed 100
//! cargo run --release -p rex-agent --example soak -- --minutes 20 --seed 3
//! cargo run --release -p rex-agent --example soak -- --no-vo      # 8 cases, a minute
//! ```
//!
//! One line per run, then the figures:
//! `soak_sim_min=<..> runs=<..> max_est_err_m=<..> max_track_err_m=<..> false_done=<..> panics=<..>`.
//! The estimate's error is measured while the motion capture delivers (in
//! dropouts, and the second after them, it is printed per run); the tracking error
//! over the samples that follow a fragment. Runs go in parallel on the machine's
//! cores.

use std::process::ExitCode;
use std::sync::Mutex;

use rex_agent::soak::{SoakCase, SoakResult, run_case};

struct Args {
    minutes: f64,
    seed: u64,
    camera_scale: f64,
    threads: usize,
    vo: bool,
}

fn parse() -> Result<Args, String> {
    let mut a = Args {
        minutes: 10.0,
        // Not a seed the trackers and estimators were tuned on (those were 1 and
        // 11-15, the soak test's).
        seed: 100,
        camera_scale: 1.0,
        threads: std::thread::available_parallelism().map_or(1, |n| n.get()),
        vo: true,
    };
    let mut it = std::env::args().skip(1);
    while let Some(flag) = it.next() {
        let mut value = |name: &str| -> Result<String, String> {
            it.next().ok_or_else(|| format!("{name} needs a value"))
        };
        match flag.as_str() {
            "--minutes" => {
                a.minutes = value("--minutes")?
                    .parse()
                    .map_err(|e| format!("--minutes: {e}"))?;
            }
            "--seed" => {
                a.seed = value("--seed")?
                    .parse()
                    .map_err(|e| format!("--seed: {e}"))?
            }
            "--camera-scale" => {
                a.camera_scale = value("--camera-scale")?
                    .parse()
                    .map_err(|e| format!("--camera-scale: {e}"))?;
            }
            "--threads" => {
                a.threads = value("--threads")?
                    .parse()
                    .map_err(|e| format!("--threads: {e}"))?;
            }
            "--no-vo" => a.vo = false,
            "-h" | "--help" => {
                return Err(
                    "usage: soak [--minutes M] [--seed S] [--camera-scale F] [--threads N] [--no-vo]"
                        .into(),
                );
            }
            other => return Err(format!("unknown argument `{other}`")),
        }
    }
    if !(a.minutes.is_finite() && a.minutes > 0.0 && a.minutes <= 24.0 * 60.0) {
        return Err(format!("--minutes must be in (0, 1440], got {}", a.minutes));
    }
    if !(a.camera_scale > 0.05 && a.camera_scale <= 1.0) {
        return Err(format!(
            "--camera-scale must be in (0.05, 1], got {}",
            a.camera_scale
        ));
    }
    a.threads = a.threads.max(1);
    Ok(a)
}

fn main() -> ExitCode {
    let args = match parse() {
        Ok(a) => a,
        Err(e) => {
            eprintln!("soak: {e}");
            return ExitCode::from(2);
        }
    };
    // The slow cases (visual odometry) first, so that they overlap the others.
    let mut cases = SoakCase::all();
    cases.retain(|c| args.vo || !c.visual_odometry);
    cases.sort_by_key(|c| !c.visual_odometry);
    let queue = Mutex::new(cases.into_iter());
    let results: Mutex<Vec<Result<SoakResult, String>>> = Mutex::new(Vec::new());
    std::thread::scope(|s| {
        for _ in 0..args.threads {
            s.spawn(|| {
                while let Some(case) = queue.lock().ok().and_then(|mut q| q.next()) {
                    let run = std::panic::catch_unwind(|| {
                        run_case(case, args.minutes, args.seed, args.camera_scale)
                    });
                    let r = match run {
                        Ok(Ok(r)) => {
                            println!(
                                "{case}: sim_min={:.1} plans={}/{} completed={} max_est_err_m={:.4} (in dropouts {:.4}) max_track_err_m={:.4} rms_m={:.4} false_done={} wall_s={:.1} faults: {}",
                                r.sim_min,
                                r.achieved.0,
                                r.achieved.1,
                                r.completed,
                                r.max_est_err_m,
                                r.max_est_err_dropout_m,
                                r.max_track_err_m,
                                r.rms_m,
                                r.false_done,
                                r.wall_s,
                                r.faults
                            );
                            Ok(r)
                        }
                        Ok(Err(e)) => Err(format!("{case}: {e}")),
                        Err(_) => Err(format!("{case}: panicked")),
                    };
                    if let Ok(mut all) = results.lock() {
                        all.push(r);
                    }
                }
            });
        }
    });
    let results = results.into_inner().unwrap_or_default();
    let ok: Vec<&SoakResult> = results.iter().filter_map(|r| r.as_ref().ok()).collect();
    let panics = results
        .iter()
        .filter(|r| matches!(r, Err(e) if e.ends_with("panicked")))
        .count();
    for e in results.iter().filter_map(|r| r.as_ref().err()) {
        eprintln!("soak: {e}");
    }
    let max = |f: fn(&SoakResult) -> f64| ok.iter().map(|r| f(r)).fold(0.0, f64::max);
    println!(
        "soak_sim_min={:.1} runs={} max_est_err_m={:.4} max_track_err_m={:.4} false_done={} panics={panics}",
        ok.iter().map(|r| r.sim_min).sum::<f64>(),
        ok.len(),
        max(|r| r.max_est_err_m),
        max(|r| r.max_track_err_m),
        ok.iter().map(|r| r.false_done).sum::<usize>(),
    );
    if ok.len() == results.len() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    }
}
