//! The NMPC on the peers' problem (`peers/casadi_nmpc.py`): the same model, OCP,
//! weights, bounds, figure-eight reference, start offset and closed loop (one lap,
//! 200 steps of 50 ms, the plant integrated with 10 RK4 steps per interval, no
//! parameter mismatch).
//!
//! ```text
//! cargo run --release -p rex-agent --example bench_nmpc [-- --peer PEERS_DIR] [--repeat K]
//! ```
//!
//! Timing is the wall-clock time of a whole real-time iteration (shift, exact
//! linearisation, QP, step) over steps 1..199 (step 0, the cold start, runs the
//! converged SQP and is reported apart): median, mean, p95, p99 and max, of the
//! run with the best median of `--repeat` runs (default 3). Three variants run
//! at the peer's horizon N = 20: real-time iteration with the structured QP (the
//! default: Riccati, and when a bound is active an interior-point method whose
//! Newton steps are Riccati recursions), real-time iteration with
//! every QP by Clarabel, and converged SQP every step; then the default at
//! N = 50. Each prints the share of steps whose QP had an active bound. With
//! `--peer DIR`, `DIR/casadi_nmpc.py`'s real-time iterations (HPIPM, qrqp) run
//! in the same session with the same repeat policy, in a Python environment the
//! bench makes once in `target/peer-venv` (`pip install casadi numpy`), each step
//! timed by a wrapper around the peer's step function with the same statistics,
//! and the peer's own split of a step into preparation (linearisation) and QP.
//! The last line is
//! `nmpc_median_ms=<..> nmpc_mean_ms=<..> nmpc_p95_ms=<..> nmpc_p99_ms=<..> rms_ss_m=<..> rms_m=<..>`
//! (N = 20, structured QPs).

use std::path::Path;
use std::time::Instant;

#[path = "common/peer_python.rs"]
mod common;
#[path = "common/stats.rs"]
mod stats;

use stats::{Stats, percentile};

use rex_agent::algorithms::mpc::{Nmpc, NmpcSettings, QpStrategy, Status};
use rex_agent::model::SlipParams;
use rex_bench::peer::{self, DT, INIT_OFFSET, N_SIM, PLANT_RK4_STEPS, SS_SKIP_S};

#[derive(Clone, Debug, Default)]
struct Run {
    step: Stats,
    cold_ms: f64,
    rms_m: f64,
    rms_ss_m: f64,
    max_ss_m: f64,
    max_tau: f64,
    clarabel_share: f64,
    clarabel_iters: f64,
    ipm_iters: f64,
    ipm_share: f64,
    fails: u64,
    sqp_iters: f64,
}

fn closed_loop(
    qp: QpStrategy,
    converged: bool,
    horizon: usize,
) -> Result<Run, Box<dyn std::error::Error>> {
    let model = peer::model();
    let settings = NmpcSettings {
        qp,
        horizon,
        ..NmpcSettings::default()
    };
    let n = settings.horizon;
    let reference = peer::reference_run(N_SIM + n + 1);
    let mut nmpc = Nmpc::new(model.clone(), settings)?;
    let p = SlipParams::NOMINAL.to_array();
    let mut x = reference[0];
    for i in 0..5 {
        x[i] += INIT_OFFSET[i];
    }
    let mut err = vec![(x[0] - reference[0][0]).hypot(x[1] - reference[0][1])];
    let (mut times, mut cold, mut max_tau, mut fails, mut iters) =
        (Vec::new(), 0.0, 0.0f64, 0u64, Vec::new());
    for k in 0..N_SIM {
        let window = &reference[k..=k + n];
        let t = Instant::now();
        let u = if converged {
            match nmpc.solve(&x, window, &p) {
                Ok(it) => iters.push(it as f64),
                Err(_) => fails += 1,
            }
            nmpc.torques()[0].into()
        } else {
            let c = nmpc.control(&x, window, &p)?;
            if !matches!(c.status, Status::Solved { .. }) {
                fails += 1;
            }
            c.torques
        };
        let ms = t.elapsed().as_secs_f64() * 1e3;
        if k == 0 {
            cold = ms;
        } else {
            times.push(ms);
        }
        let u = u.map(|v| v.clamp(-10.0, 10.0));
        max_tau = max_tau.max(u.iter().fold(0.0f64, |m, v| m.max(v.abs())));
        x = model.rk4_5(&x, &u, &SlipParams::NOMINAL, DT, PLANT_RK4_STEPS);
        err.push((x[0] - reference[k + 1][0]).hypot(x[1] - reference[k + 1][1]));
    }
    let rms = |e: &[f64]| (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt();
    let skip = (SS_SKIP_S / DT).round() as usize;
    let stats = nmpc.stats();
    Ok(Run {
        step: Stats::of(&times),
        cold_ms: cold,
        rms_m: rms(&err),
        rms_ss_m: rms(&err[skip..]),
        max_ss_m: err[skip..].iter().fold(0.0, |m: f64, v| m.max(*v)),
        max_tau,
        clarabel_share: (stats.clarabel + stats.ipm) as f64 / stats.qps.max(1) as f64,
        ipm_iters: stats.ipm_iterations as f64 / stats.ipm.max(1) as f64,
        ipm_share: stats.ipm as f64 / (stats.clarabel + stats.ipm).max(1) as f64,
        clarabel_iters: stats.clarabel_iterations as f64 / stats.clarabel.max(1) as f64,
        fails,
        sqp_iters: if iters.is_empty() {
            0.0
        } else {
            percentile(&mut iters, 0.5)
        },
    })
}

fn best(
    qp: QpStrategy,
    converged: bool,
    horizon: usize,
    repeat: usize,
) -> Result<Run, Box<dyn std::error::Error>> {
    let mut best: Option<Run> = None;
    for _ in 0..repeat.max(1) {
        let r = closed_loop(qp, converged, horizon)?;
        if best.as_ref().is_none_or(|b| r.step.median < b.step.median) {
            best = Some(r);
        }
    }
    best.ok_or_else(|| "no run".into())
}

fn print(name: &str, r: &Run) {
    println!(
        "# {name}: {}, cold {:.2} ms | rms {:.4} m, rms_ss {:.4} m, max_ss {:.4} m, max|tau| {:.2} | steps with an active bound {:.1} % (by the structured IPM {:.1} %, {:.1} iterations each; by Clarabel {:.1} iterations each), failures {}{}",
        r.step,
        r.cold_ms,
        r.rms_m,
        r.rms_ss_m,
        r.max_ss_m,
        r.max_tau,
        100.0 * r.clarabel_share,
        100.0 * r.ipm_share,
        r.ipm_iters,
        r.clarabel_iters,
        r.fails,
        if r.sqp_iters > 0.0 {
            format!(", median SQP iterations {}", r.sqp_iters)
        } else {
            String::new()
        }
    );
}

fn load() -> String {
    std::fs::read_to_string("/proc/loadavg")
        .map(|s| s.split_whitespace().take(3).collect::<Vec<_>>().join(" "))
        .unwrap_or_else(|_| "unknown".into())
}

/// One closed-loop run of a peer variant: its step times (ms, steps
/// 1..199), its preparation and QP times, its tracking error.
struct PeerRun {
    step: Stats,
    prep_median: f64,
    qp_median: f64,
    rms_ss_m: f64,
}

/// `variant` of `DIR/casadi_nmpc.py` (`rti_hpipm`, `rti_qrqp`), the best
/// median of `repeat` closed loops, each step timed around the peer's step
/// function (as the peer times it: `perf_counter` before and after).
fn peer_run(
    python: &Path,
    dir: &str,
    variant: &str,
    repeat: usize,
) -> Result<PeerRun, Box<dyn std::error::Error>> {
    let out = std::env::temp_dir().join(format!("bench_nmpc_peer_{}.txt", std::process::id()));
    let script = format!(
        r#"
import sys, time
sys.path.insert(0, {dir:?})
import casadi_nmpc as p
variant = {variant:?}
conic = variant.split("_", 1)[1]
best = None
for _ in range({repeat}):
    steps = []
    holder = {{}}
    def make():
        inner = p.make_rti(conic)
        holder["timing"] = inner.timing
        def timed(x, ref, k):
            t = time.perf_counter()
            r = inner(x, ref, k)
            steps.append(1e3 * (time.perf_counter() - t))
            return r
        return timed
    res = p.run_closed_loop(variant, make)
    t = holder["timing"]
    run = (steps[1:], [1e3 * v for v in t["prep"][1:]], [1e3 * v for v in t["qp"][1:]], res["rms_ss_m"])
    warm = sorted(run[0])
    if best is None or warm[len(warm) // 2] < best[0]:
        best = (warm[len(warm) // 2], run)
steps, prep, qp, rms_ss = best[1]
with open({out:?}, "w") as f:
    f.write("%r\n" % rms_ss)
    for a, b, c in zip(steps, prep, qp):
        f.write("%.6f %.6f %.6f\n" % (a, b, c))
"#,
        out = out.display().to_string(),
    );
    let text = common::run_script(python, &script, &out)?;
    let mut lines = text.lines();
    let rms_ss_m: f64 = lines.next().ok_or("empty peer output")?.parse()?;
    let (mut steps, mut prep, mut qp) = (Vec::new(), Vec::new(), Vec::new());
    for line in lines {
        let v: Vec<f64> = line
            .split_whitespace()
            .map(str::parse)
            .collect::<Result<_, _>>()?;
        if let [a, b, c] = v[..] {
            steps.push(a);
            prep.push(b);
            qp.push(c);
        } else {
            return Err(format!("peer output line {line:?}").into());
        }
    }
    if steps.len() + 1 != N_SIM {
        return Err(format!("the peer timed {} steps, not {}", steps.len(), N_SIM - 1).into());
    }
    Ok(PeerRun {
        step: Stats::of(&steps),
        prep_median: percentile(&mut prep, 0.5),
        qp_median: percentile(&mut qp, 0.5),
        rms_ss_m,
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let arg = |name: &str| {
        args.iter()
            .position(|a| a == name)
            .and_then(|i| args.get(i + 1))
    };
    let repeat = arg("--repeat").and_then(|v| v.parse().ok()).unwrap_or(3);
    println!("# load average before: {}", load());
    let clarabel = best(QpStrategy::Clarabel, false, 20, repeat)?;
    print("N=20 rti, every QP by Clarabel", &clarabel);
    let sqp = best(QpStrategy::Structured, true, 20, 1)?;
    print("N=20 converged SQP every step (structured QPs)", &sqp);
    let rti = best(QpStrategy::Structured, false, 20, repeat)?;
    print(
        "N=20 rti, structured QPs (Riccati; with a bound active, the interior-point method on the stages)",
        &rti,
    );
    let rti50 = best(QpStrategy::Structured, false, 50, repeat)?;
    print("N=50 rti, structured QPs", &rti50);
    println!("# load average after: {}", load());
    let mut hpipm = None;
    if let Some(dir) = arg("--peer") {
        match common::peer_python("import casadi, numpy", &["casadi", "numpy"]) {
            Ok(python) => {
                for variant in ["rti_hpipm", "rti_qrqp"] {
                    match peer_run(&python, dir, variant, repeat) {
                        Ok(p) => {
                            println!(
                                "# peer casadi_{variant} (N=20): {} | preparation median {:.4} ms, QP median {:.4} ms | rms_ss {:.4} m",
                                p.step, p.prep_median, p.qp_median, p.rms_ss_m
                            );
                            println!(
                                "#   ours (rti, structured) / casadi_{variant}: {}",
                                rti.step.ratios(&p.step)
                            );
                            if variant == "rti_hpipm" {
                                hpipm = Some(p);
                            }
                        }
                        Err(e) => eprintln!("peer casadi_{variant}: {e}"),
                    }
                }
            }
            Err(e) => eprintln!("peer: {e}"),
        }
        println!("# load average after the peer: {}", load());
    }
    println!(
        "# aims: N=20 p99 <= 0.15 ms (ratio {:.3}){}; N=50 p99 <= 0.3 ms (ratio {:.3}); rms_ss <= 0.002 m (ratio {:.3})",
        rti.step.p99 / 0.15,
        hpipm.as_ref().map_or(String::new(), |p| format!(
            " and <= 0.2x the peer's median (HPIPM: {:.3}x, ratio {:.3})",
            rti.step.p99 / p.step.median,
            rti.step.p99 / p.step.median / 0.2
        )),
        rti50.step.p99 / 0.3,
        rti.rms_ss_m / 0.002
    );
    println!(
        "nmpc_median_ms={:.4} nmpc_mean_ms={:.4} nmpc_p95_ms={:.4} nmpc_p99_ms={:.4} rms_ss_m={:.4} rms_m={:.4}",
        rti.step.median, rti.step.mean, rti.step.p95, rti.step.p99, rti.rms_ss_m, rti.rms_m
    );
    Ok(())
}
