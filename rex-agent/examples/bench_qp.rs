//! The NMPC's QPs alone, against compiled solvers: every real-time-iteration QP
//! of the peers' figure-eight closed loop (`peers/casadi_nmpc.py`'s problem, as
//! in `bench_nmpc`: one lap, 200 steps, N = 20 unless `--horizon N`), recorded
//! as the controller meets them, then solved again by
//!
//! * ours: the Riccati recursion, and when a bound is active the interior-point
//!   method on the stages (`nmpc/ipm.rs`), as the controller solves them;
//! * Clarabel (Rust), set up once, its data updated in place for each QP;
//! * OSQP (C, through its Python package in `target/peer-venv`, installed the
//!   first time), set up once, data updated in place, warm-started from the
//!   previous QP's solution, timed by its own C timers (update + solve; the
//!   Python wall time of the same calls is printed beside).
//!
//! Same tolerance for all three (1e-6: our method's complementarity, Clarabel's
//! gap and feasibility, OSQP's `eps_abs` = `eps_rel`), each QP solved
//! `--repeat` times (default 5) in a row, its time the median of those; the
//! statistics are over the QPs: p50, p99, max, for all, for those with an
//! active bound, for the others. Accuracy: the largest difference of each
//! solver's step from Clarabel's at 1e-10, and the objectives.
//!
//! ```text
//! cargo run --release -p rex-agent --example bench_qp [-- --horizon 50] [--repeat K] [--no-osqp]
//! ```
//!
//! The last line is
//! `qp_us_p50_ours=.. qp_us_p99_ours=.. qp_us_p50_clarabel=.. qp_us_p99_clarabel=.. qp_us_p50_osqp=.. qp_us_p99_osqp=..`.

use std::io::Write;
use std::time::Instant;

#[path = "common/peer_python.rs"]
mod common;
#[path = "common/stats.rs"]
mod stats;

use stats::{Stats, percentile};

use rex_agent::algorithms::mpc::{FrozenQp, Nmpc, NmpcSettings, SparseQp};
use rex_agent::model::{Reduced, SlipParams};
use rex_bench::peer::{self, DT, INIT_OFFSET, N_SIM, PLANT_RK4_STEPS};

const TOL: f64 = 1e-6;

type Frozen = FrozenQp<Reduced, 5, 3>;

/// Every QP of one lap, as the controller met them (steps 1..N_SIM; step 0
/// is the cold start's converged SQP).
fn record(horizon: usize) -> Result<Vec<Frozen>, Box<dyn std::error::Error>> {
    let model = peer::model();
    let settings = NmpcSettings {
        horizon,
        ..NmpcSettings::default()
    };
    let reference = peer::reference_run(N_SIM + horizon + 1);
    let mut nmpc = Nmpc::new(model.clone(), settings)?;
    let p = SlipParams::NOMINAL.to_array();
    let mut x = reference[0];
    for (v, o) in x.iter_mut().zip(INIT_OFFSET) {
        *v += o;
    }
    let mut qps = Vec::new();
    for k in 0..N_SIM {
        let window = &reference[k..=k + horizon];
        let u = if k == 0 {
            nmpc.control(&x, window, &p)?.torques
        } else {
            nmpc.prepare(window, &p)?;
            qps.push(nmpc.freeze_qp(&x)?);
            nmpc.feedback(&x)?.torques
        };
        let u = u.map(|v| v.clamp(-10.0, 10.0));
        x = model.rk4_5(&x, &u, &SlipParams::NOMINAL, DT, PLANT_RK4_STEPS);
    }
    Ok(qps)
}

/// Per QP: the median time of `repeat` solves \[µs\], and the last solution.
fn timed<F: FnMut() -> Result<Vec<f64>, String>>(
    repeat: usize,
    mut solve: F,
) -> Result<(f64, Vec<f64>), String> {
    let mut times = Vec::with_capacity(repeat);
    let mut last = Vec::new();
    for _ in 0..repeat {
        let t = Instant::now();
        last = solve()?;
        times.push(t.elapsed().as_secs_f64() * 1e6);
    }
    Ok((percentile(&mut times, 0.5), last))
}

struct Solver {
    name: &'static str,
    us: Vec<f64>,
    /// Largest |Δw − Δw_ref| over the QPs, and the largest objective excess.
    error: f64,
    objective_excess: f64,
    violation: f64,
    note: String,
}

impl Solver {
    fn new(name: &'static str) -> Solver {
        Solver {
            name,
            us: Vec::new(),
            error: 0.0,
            objective_excess: f64::NEG_INFINITY,
            violation: 0.0,
            note: String::new(),
        }
    }

    fn compare(&mut self, qp: &SparseQp, z: &[f64], reference: &[f64]) {
        let e = z
            .iter()
            .zip(reference)
            .map(|(a, b)| (a - b).abs())
            .fold(0.0, f64::max);
        self.error = self.error.max(e);
        let excess = qp.objective(z) - qp.objective(reference);
        self.objective_excess = self.objective_excess.max(excess);
        self.violation = self.violation.max(qp.violation(z));
    }

    fn quantiles(&self, pick: &[bool], want: bool) -> (f64, f64, f64, usize) {
        let mut v: Vec<f64> = self
            .us
            .iter()
            .zip(pick)
            .filter(|(_, a)| **a == want)
            .map(|(t, _)| *t)
            .collect();
        let n = v.len();
        (
            percentile(&mut v, 0.5),
            percentile(&mut v, 0.99),
            v.iter().copied().fold(f64::NAN, f64::max),
            n,
        )
    }
}

/// OSQP's answer to one QP.
struct OsqpAnswer {
    /// The median of its own timers over the repeats \[µs\].
    own_us: f64,
    /// The median Python wall time of the same calls \[µs\].
    wall_us: f64,
    iterations: usize,
    status: String,
    x: Vec<f64>,
}

/// OSQP on `qps` through Python.
fn osqp(qps: &[SparseQp], repeat: usize) -> Result<Vec<OsqpAnswer>, Box<dyn std::error::Error>> {
    let python = common::peer_python("import osqp, numpy, scipy", &["osqp", "numpy", "scipy"])?;
    let dir = std::env::temp_dir();
    let input = dir.join(format!("bench_qp_in_{}.json", std::process::id()));
    let output = dir.join(format!("bench_qp_out_{}.json", std::process::id()));
    let first = qps.first().ok_or("no QPs")?;
    {
        let mut f = std::io::BufWriter::new(std::fs::File::create(&input)?);
        let head = serde_json::json!({
            "n": first.n, "m": first.m, "p_diag": first.p_diag,
            "a_rows": first.a_rows, "a_cols": first.a_cols,
            "eps": TOL, "repeats": repeat,
        });
        writeln!(f, "{head}")?;
        for qp in qps {
            let line = serde_json::json!({
                "q": qp.q, "a_values": qp.a_values, "l": qp.l, "u": qp.u,
            });
            writeln!(f, "{line}")?;
        }
    }
    let script = include_str!("common/osqp_qps.py");
    let run = std::process::Command::new(&python)
        .args(["-c", script])
        .arg(&input)
        .arg(&output)
        .output()?;
    std::fs::remove_file(&input)?;
    if !run.status.success() {
        return Err(String::from_utf8_lossy(&run.stderr)
            .trim()
            .to_owned()
            .into());
    }
    let text = std::fs::read_to_string(&output)?;
    std::fs::remove_file(&output)?;
    let mut out = Vec::new();
    for line in text.lines() {
        let v: serde_json::Value = serde_json::from_str(line)?;
        let list = |key: &str| -> Result<Vec<f64>, String> {
            v[key]
                .as_array()
                .ok_or(format!("OSQP output without {key}"))?
                .iter()
                .map(|x| x.as_f64().ok_or(format!("OSQP output: {key} not numbers")))
                .collect()
        };
        let (mut own, mut wall) = (list("own_us")?, list("wall_us")?);
        out.push(OsqpAnswer {
            own_us: percentile(&mut own, 0.5),
            wall_us: percentile(&mut wall, 0.5),
            iterations: v["iter"].as_u64().unwrap_or(0) as usize,
            status: v["status"].as_str().unwrap_or("?").to_owned(),
            x: list("x")?,
        });
    }
    if out.len() != qps.len() {
        return Err(format!("OSQP answered {} of {} QPs", out.len(), qps.len()).into());
    }
    Ok(out)
}

/// The command line: `--horizon N`, `--repeat K`, `--no-osqp`.
struct Args {
    horizon: usize,
    repeat: usize,
    with_osqp: bool,
}

impl Args {
    fn parse() -> Result<Args, String> {
        let args: Vec<String> = std::env::args().collect();
        let value = |flag: &str, default: usize| -> Result<usize, String> {
            args.iter()
                .position(|a| a == flag)
                .map_or(Ok(default), |i| {
                    args.get(i + 1)
                        .and_then(|v| v.parse().ok())
                        .ok_or(format!("{flag} needs a number"))
                })
        };
        Ok(Args {
            horizon: value("--horizon", 20)?,
            repeat: value("--repeat", 5)?.max(1),
            with_osqp: !args.iter().any(|a| a == "--no-osqp"),
        })
    }
}

/// The lap's QPs solved by ours and by Clarabel: per QP whether a bound is
/// active, its sparse form and Clarabel's solution at 1e-10 (the reference).
struct Lap {
    active: Vec<bool>,
    sparse: Vec<SparseQp>,
    references: Vec<Vec<f64>>,
    ours: Solver,
    clarabel: Solver,
}

/// Every QP of `qps` solved `repeat` times by ours and by Clarabel (at
/// [`TOL`], set up once), timed and compared with the reference.
fn ours_and_clarabel(qps: &mut [Frozen], repeat: usize) -> Result<Lap, Box<dyn std::error::Error>> {
    let first = qps.first().ok_or("the lap gave no QPs")?;
    let mut fast = first.clarabel(TOL)?;
    let mut tight = first.clarabel(1e-10)?;
    let mut active = Vec::new();
    let mut sparse = Vec::new();
    let mut references = Vec::new();
    let (mut ours, mut clarabel) = (Solver::new("ours"), Solver::new("clarabel"));
    let (mut ipm_iters, mut clarabel_iters) = (0usize, 0usize);
    for qp in qps.iter_mut() {
        active.push(qp.active()?);
        let reference = qp.solve_clarabel(&mut tight)?.step;
        let s = qp.sparse();
        let (t, z) = timed(repeat, || {
            qp.solve_structured()
                .map(|s| {
                    ipm_iters += s.iterations;
                    s.step
                })
                .map_err(|e| e.to_string())
        })?;
        ours.us.push(t);
        ours.compare(&s, &z, &reference);
        let (t, z) = timed(repeat, || {
            qp.solve_clarabel(&mut fast)
                .map(|s| {
                    clarabel_iters += s.iterations;
                    s.step
                })
                .map_err(|e| e.to_string())
        })?;
        clarabel.us.push(t);
        clarabel.compare(&s, &z, &reference);
        sparse.push(s);
        references.push(reference);
    }
    let n_active = active.iter().filter(|a| **a).count();
    ours.note = format!(
        "{:.1} interior-point iterations per QP with an active bound",
        ipm_iters as f64 / (repeat * n_active.max(1)) as f64
    );
    clarabel.note = format!(
        "{:.1} iterations per QP",
        clarabel_iters as f64 / (repeat * qps.len()) as f64
    );
    Ok(Lap {
        active,
        sparse,
        references,
        ours,
        clarabel,
    })
}

/// OSQP on the lap's QPs, its times by its own timers, compared with the
/// references.
fn osqp_solver(
    sparse: &[SparseQp],
    references: &[Vec<f64>],
    repeat: usize,
) -> Result<Solver, Box<dyn std::error::Error>> {
    let mut s = Solver::new("osqp");
    let results = osqp(sparse, repeat)?;
    let (mut iters, mut unsolved, mut wall) = (0, 0, Vec::new());
    for (a, (qp, reference)) in results.into_iter().zip(sparse.iter().zip(references)) {
        s.us.push(a.own_us);
        wall.push(a.wall_us);
        iters += a.iterations;
        let status = a.status.to_lowercase();
        if !status.contains("solved") || status.contains("inaccurate") {
            unsolved += 1;
        }
        s.compare(qp, &a.x, reference);
    }
    s.note = format!(
        "{:.1} ADMM iterations per QP, {unsolved} not solved to tolerance; Python wall time p50 {:.1} µs, p99 {:.1}",
        iters as f64 / sparse.len() as f64,
        percentile(&mut wall.clone(), 0.5),
        percentile(&mut wall, 0.99),
    );
    Ok(s)
}

/// Per solver its times (all QPs, those with an active bound, the others)
/// and accuracy, ours against each other, then the last line.
fn report(solvers: &[Solver], active: &[bool]) {
    let all: Vec<Stats> = solvers.iter().map(|s| Stats::of(&s.us)).collect();
    for (s, a) in solvers.iter().zip(&all) {
        let (p50, p99, max, n) = s.quantiles(active, true);
        let (f50, f99, fmax, m) = s.quantiles(active, false);
        println!(
            "# {:9} all: p50 {:.1} p99 {:.1} max {:.1} | active bound ({n}): p50 {p50:.1} p99 {p99:.1} max {max:.1} | none ({m}): p50 {f50:.1} p99 {f99:.1} max {fmax:.1}",
            s.name, a.median, a.p99, a.max,
        );
        println!(
            "#           max |Δw − Clarabel(1e-10)| {:.1e}, objective above it by at most {:.1e}, constraint violation {:.1e}; {}",
            s.error, s.objective_excess, s.violation, s.note
        );
    }
    for (s, a) in solvers.iter().zip(&all).skip(1) {
        println!("# ours / {}: {}", s.name, all[0].ratios(a));
    }
    let line: Vec<String> = solvers
        .iter()
        .map(|s| {
            let mut v = s.us.clone();
            format!(
                "qp_us_p50_{0}={1:.1} qp_us_p99_{0}={2:.1}",
                s.name,
                percentile(&mut v.clone(), 0.5),
                percentile(&mut v, 0.99)
            )
        })
        .collect();
    println!("{}", line.join(" "));
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let Args {
        horizon,
        repeat,
        with_osqp,
    } = Args::parse()?;
    let mut qps = record(horizon)?;
    let Lap {
        active,
        sparse,
        references,
        ours,
        clarabel,
    } = ours_and_clarabel(&mut qps, repeat)?;
    let mut solvers = vec![ours, clarabel];
    if with_osqp {
        solvers.push(osqp_solver(&sparse, &references, repeat)?);
    }
    let n_active = active.iter().filter(|a| **a).count();
    println!(
        "# {} QPs of the figure-eight lap (N={horizon}, {} variables, {} rows), {n_active} with an active bound; each solved {repeat} times, the median kept; µs",
        qps.len(),
        sparse[0].n,
        sparse[0].m
    );
    report(&solvers, &active);
    Ok(())
}
