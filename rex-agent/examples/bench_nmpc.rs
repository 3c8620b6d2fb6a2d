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
//! linearisation, QP, step), median and 95th percentile over steps 1..199 (step 0,
//! the cold start, runs the converged SQP and is reported apart), best of `--repeat`
//! runs (default 3). Three variants run: real-time iteration with the structured
//! QP (the default: Riccati, Clarabel when a bound is active), real-time iteration
//! with every QP by Clarabel, and converged SQP every step. With `--peer DIR`,
//! `DIR/casadi_nmpc.py` runs in the same session (`pip install casadi numpy`).
//! The last line is
//! `nmpc_median_ms=<..> nmpc_p95_ms=<..> rms_ss_m=<..> rms_m=<..>`.

use std::time::Instant;

use rex_agent::algorithms::mpc::peer::{self, DT, INIT_OFFSET, N_SIM, PLANT_RK4_STEPS, SS_SKIP_S};
use rex_agent::algorithms::mpc::{Nmpc, NmpcSettings, QpStrategy, Status};
use rex_agent::world::model::SlipParams;

#[derive(Clone, Debug, Default)]
struct Run {
    median_ms: f64,
    p95_ms: f64,
    cold_ms: f64,
    rms_m: f64,
    rms_ss_m: f64,
    max_ss_m: f64,
    max_tau: f64,
    clarabel_share: f64,
    clarabel_iters: f64,
    fails: u64,
    sqp_iters: f64,
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    let i = (q * (v.len() - 1) as f64).round() as usize;
    v[i.min(v.len() - 1)]
}

fn closed_loop(qp: QpStrategy, converged: bool) -> Result<Run, Box<dyn std::error::Error>> {
    let model = peer::model();
    let settings = NmpcSettings {
        qp,
        ..NmpcSettings::default()
    };
    let n = settings.horizon;
    let reference = peer::reference_run(N_SIM + n + 1);
    let mut nmpc = Nmpc::new(model.clone(), settings)?;
    let p = SlipParams::NOMINAL;
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
            nmpc.torques()[0]
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
        x = model.rk4(&x, &u, &p, DT, PLANT_RK4_STEPS);
        err.push((x[0] - reference[k + 1][0]).hypot(x[1] - reference[k + 1][1]));
    }
    let rms = |e: &[f64]| (e.iter().map(|v| v * v).sum::<f64>() / e.len() as f64).sqrt();
    let skip = (SS_SKIP_S / DT).round() as usize;
    let stats = nmpc.stats();
    Ok(Run {
        median_ms: percentile(&mut times.clone(), 0.5),
        p95_ms: percentile(&mut times, 0.95),
        cold_ms: cold,
        rms_m: rms(&err),
        rms_ss_m: rms(&err[skip..]),
        max_ss_m: err[skip..].iter().fold(0.0, |m: f64, v| m.max(*v)),
        max_tau,
        clarabel_share: stats.clarabel as f64 / stats.qps.max(1) as f64,
        clarabel_iters: stats.clarabel_iterations as f64 / stats.clarabel.max(1) as f64,
        fails,
        sqp_iters: if iters.is_empty() {
            0.0
        } else {
            percentile(&mut iters, 0.5)
        },
    })
}

fn best(qp: QpStrategy, converged: bool, repeat: usize) -> Result<Run, Box<dyn std::error::Error>> {
    let mut best: Option<Run> = None;
    for _ in 0..repeat.max(1) {
        let r = closed_loop(qp, converged)?;
        if best.as_ref().is_none_or(|b| r.median_ms < b.median_ms) {
            best = Some(r);
        }
    }
    best.ok_or_else(|| "no run".into())
}

fn print(name: &str, r: &Run) {
    println!(
        "# {name}: median {:.4} ms, p95 {:.4} ms, cold {:.2} ms | rms {:.4} m, rms_ss {:.4} m, max_ss {:.4} m, max|tau| {:.2} | QPs by Clarabel {:.1} % ({:.1} IPM iterations each), failures {}{}",
        r.median_ms,
        r.p95_ms,
        r.cold_ms,
        r.rms_m,
        r.rms_ss_m,
        r.max_ss_m,
        r.max_tau,
        100.0 * r.clarabel_share,
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

fn peer_lines(dir: &str) -> Vec<String> {
    let script = std::path::Path::new(dir).join("casadi_nmpc.py");
    match std::process::Command::new("python3")
        .arg(&script)
        .args(["--solver", "rti_hpipm,rti_qrqp,ipopt"])
        .output()
    {
        Ok(out) if out.status.success() => String::from_utf8_lossy(&out.stdout)
            .lines()
            .filter(|l| l.starts_with("casadi_"))
            .map(str::to_owned)
            .collect(),
        Ok(out) => {
            eprintln!("peer: {}", String::from_utf8_lossy(&out.stderr).trim());
            Vec::new()
        }
        Err(e) => {
            eprintln!("peer: cannot run {}: {e}", script.display());
            Vec::new()
        }
    }
}

fn field(line: &str, key: &str) -> Option<f64> {
    line.split_whitespace()
        .find_map(|kv| kv.strip_prefix(key))
        .and_then(|v| v.parse().ok())
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
    let clarabel = best(QpStrategy::Clarabel, false, repeat)?;
    print("rti, every QP by Clarabel", &clarabel);
    let sqp = best(QpStrategy::Structured, true, 1)?;
    print("converged SQP every step (structured QPs)", &sqp);
    let rti = best(QpStrategy::Structured, false, repeat)?;
    print(
        "rti, structured QPs (Riccati; Clarabel when a bound is active)",
        &rti,
    );
    println!("# load average after: {}", load());
    if let Some(dir) = arg("--peer") {
        for line in peer_lines(dir) {
            println!("# peer: {line}");
            if let Some(ms) = field(&line, "median_ms=") {
                let name = line.split_whitespace().next().unwrap_or("peer");
                println!(
                    "#   ours / {name}: median {:.3} (rti structured), {:.3} (rti Clarabel only)",
                    rti.median_ms / ms,
                    clarabel.median_ms / ms
                );
            }
        }
        println!("# load average after the peer: {}", load());
    }
    println!(
        "# target: median <= 0.45 ms (ratio {:.3}), rms_ss <= 0.002 m (ratio {:.3})",
        rti.median_ms / 0.45,
        rti.rms_ss_m / 0.002
    );
    println!(
        "nmpc_median_ms={:.4} nmpc_p95_ms={:.4} rms_ss_m={:.4} rms_m={:.4}",
        rti.median_ms, rti.p95_ms, rti.rms_ss_m, rti.rms_m
    );
    Ok(())
}
