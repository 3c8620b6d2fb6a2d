//! How every part's cost grows with the system (issue 57).
//!
//! ```text
//! cargo run --release --example bench_scale [-- --quick]
//! ```
//!
//! One line per size and part, `key=value`:
//!
//! * `det n=<subsystems> action_ns_p50=.. action_ns_p99=.. bytes_per_subsystem=..
//!   build_ms=.. ..`: the deterministic executor on `n / 3` copies of a small agent
//!   (`c` with one `e` and one `r`, sample and queue links, a transmission buffer
//!   to the next agent's `c`), from 3 to 9,999 subsystems ([`det`]);
//! * `multirate n=<subsystems> fast_instant_ns=.. instant_ns=.. ..`: the same
//!   agents, the first every millisecond and the others every 100 ms, 99 to
//!   9,999 subsystems: the time of an instant at which only the fast agent
//!   runs, and of an instant on average ([`det::measure_rates`]);
//! * `rt n=<subsystems> mode=<pool|per_subsystem> jitter_us_p50=.. jitter_us_p99=..
//!   overruns=.. util_core<k>=.. ..`: the real-time executor on the same agents at
//!   100 Hz on the machine's cores, by its worker pool (pinned) and, up to 1,002
//!   subsystems, by a thread per subsystem; the largest size the pool ran with
//!   jitter p99 <= 1 ms and no overrun, and where it stopped ([`rt`]);
//! * `tools n_behaviours=.. check_ms=.. diagram_ms=.. new_ms=.. ..`: `embodied
//!   check` (with the arc proofs), `embodied diagram` and `embodied new` on
//!   generated specs up to 10,000 behaviours, 1,000 subsystems and a deployment
//!   of 100 processes ([`tools`]).
//!
//! and at the end exactly one line,
//!
//! ```text
//! scale action_ratio_10000=<..> rt_subsystems=<..> rt_jitter_us_p99=<..> zenoh_ratio_32=<..> fleet_robots=<..> fleet_cost_ratio=<..>
//! ```
//!
//! `action_ratio_10000`: the median time per action at the largest size over
//! the one at 3 subsystems (aim: at most 1.5). A figure not measured prints `na`.
//!
//! * `zenoh k=.. topology=.. hosts=.. p50_us=.. ..` and `zenoh_ratio_32=..`:
//!   agent-zenoh's `bench_zenoh_scale`, K processes over Zenoh; `fleet robots=..
//!   ..` and `fleet_robots=.. fleet_cost_ratio=..`: rex-agent's `fleet`, M Rex
//!   robots in one warehouse ([`external`]: each built and run by cargo).
//!
//! `--quick`: small sizes and few batches only, and not the other crates'
//! benchmarks (a test's run: a few seconds in a debug build). The figures are
//! then not comparable with a full run's. `--skip-external`: a full run
//! without the other crates' benchmarks. `--multirate`: the `multirate` lines
//! of a full run only. `--only det`: the `det` lines, the growth line and the
//! final line (its other figures `na`) only, in a few seconds; `--only rt`:
//! the real-time executor's pool lines (no thread per subsystem) and the final
//! line. With either, `--agents 1,334` chooses the sizes (agents of three
//! subsystems), `--batches N` the deterministic repeats, `--seconds S` the
//! real-time run of each size. `--no-huge-pages`: the deterministic executors
//! with `ExecConfig::huge_pages` off (the memory on the pages the allocator
//! gave). `--first-build AGENTS`: build the system of
//! that many agents once and print `first_build_us=<..>` (what a run asks of
//! fresh processes of this program for `first_build_us_per_subsystem`).

mod det;
mod external;
mod rt;
mod tools;

use std::alloc::{GlobalAlloc, Layout};
use std::fmt;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

use embodied::allocations::CountingAllocator;

/// Counts allocations (agent-core's [`CountingAllocator`], for
/// [`embodied::allocations::total`]) and the bytes live on the heap ([`heap::live`]).
#[global_allocator]
static GLOBAL: heap::Counting = heap::Counting;

/// The bytes live on the heap.
mod heap {
    use super::*;

    static LIVE: AtomicUsize = AtomicUsize::new(0);

    /// [`CountingAllocator`] that also keeps the live bytes.
    pub(crate) struct Counting;

    // SAFETY: every method forwards to `CountingAllocator` (the system
    // allocator, counting) with the caller's arguments unchanged; the rest is
    // an atomic counter.
    #[expect(
        unsafe_code,
        reason = "a global allocator is an unsafe trait; this one only counts"
    )]
    unsafe impl GlobalAlloc for Counting {
        unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
            // SAFETY: the caller's contract, passed on.
            let p = unsafe { CountingAllocator.alloc(layout) };
            if !p.is_null() {
                LIVE.fetch_add(layout.size(), Ordering::Relaxed);
            }
            p
        }

        unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
            // SAFETY: the caller's contract, passed on.
            let p = unsafe { CountingAllocator.alloc_zeroed(layout) };
            if !p.is_null() {
                LIVE.fetch_add(layout.size(), Ordering::Relaxed);
            }
            p
        }

        unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
            // SAFETY: the caller's contract, passed on.
            let p = unsafe { CountingAllocator.realloc(ptr, layout, new_size) };
            if !p.is_null() {
                LIVE.fetch_add(new_size, Ordering::Relaxed);
                LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
            }
            p
        }

        unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
            // SAFETY: the caller's contract, passed on.
            unsafe { CountingAllocator.dealloc(ptr, layout) };
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
        }
    }

    /// The bytes allocated and not yet freed, by every thread.
    pub(crate) fn live() -> usize {
        LIVE.load(Ordering::Relaxed)
    }
}

/// The figures of the final line; `None` prints `na` (not measured).
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Scale {
    /// Median time per action at the largest size over that at 3 subsystems.
    pub(crate) action_ratio_10000: Option<f64>,
    /// The most subsystems the real-time executor ran at 100 Hz within the aim.
    pub(crate) rt_subsystems: Option<f64>,
    /// Its wake-up jitter, 99th percentile \[us\].
    pub(crate) rt_jitter_us_p99: Option<f64>,
    /// Zenoh's latency p50 at 32 processes over that at 2.
    pub(crate) zenoh_ratio_32: Option<f64>,
    /// The most Rex robots of the fleet run.
    pub(crate) fleet_robots: Option<f64>,
    /// The fleet's cost per robot at that size over one robot's.
    pub(crate) fleet_cost_ratio: Option<f64>,
}

impl fmt::Display for Scale {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v = |x: Option<f64>| match x {
            None => "na".to_owned(),
            Some(x) if x.fract() == 0.0 && x.abs() < 1e15 => format!("{x:.0}"),
            Some(x) => format!("{x:.3}"),
        };
        write!(
            f,
            "scale action_ratio_10000={} rt_subsystems={} rt_jitter_us_p99={} zenoh_ratio_32={} \
             fleet_robots={} fleet_cost_ratio={}",
            v(self.action_ratio_10000),
            v(self.rt_subsystems),
            v(self.rt_jitter_us_p99),
            v(self.zenoh_ratio_32),
            v(self.fleet_robots),
            v(self.fleet_cost_ratio)
        )
    }
}

/// The sizes and repeats of a run.
struct Plan {
    /// Agents of the deterministic executor's systems (3 subsystems each).
    det_agents: &'static [usize],
    /// Timed batches per size.
    det_batches: usize,
    /// Agents of the multi-rate systems (one fast, the others 100 times slower).
    rates_agents: &'static [usize],
    /// Agents of the generated specs (2 subsystems, 20 behaviours each).
    tool_agents: &'static [usize],
    /// Agents of the real-time executor's systems (3 subsystems each, 100 Hz).
    rt_agents: &'static [usize],
    /// Wall-clock seconds each real-time size runs.
    rt_seconds: f64,
    /// The most subsystems also run with a thread each (beside the pool).
    rt_per_subsystem_max: usize,
    /// Run the other crates' benchmarks (Zenoh between processes, the fleet).
    external: bool,
}

const FULL: Plan = Plan {
    det_agents: &[1, 10, 100, 1000, 3333],
    det_batches: 201,
    rates_agents: &[33, 333, 3333],
    tool_agents: &[5, 50, 500],
    rt_agents: &[1, 10, 100, 334, 1000, 3333],
    rt_seconds: 5.0,
    rt_per_subsystem_max: 1002,
    external: true,
};

const QUICK: Plan = Plan {
    det_agents: &[1, 10, 100],
    det_batches: 11,
    rates_agents: &[33, 333],
    tool_agents: &[2, 5],
    rt_agents: &[1, 10],
    rt_seconds: 0.3,
    rt_per_subsystem_max: 30,
    external: false,
};

/// What a run measures, and with what.
pub(crate) struct Options {
    /// Small sizes and few batches only (`--quick`).
    pub(crate) quick: bool,
    /// The `embodied` binary, for `embodied new` (and the structure diagram of
    /// large specs); `None`: not measured.
    pub(crate) embodied_bin: Option<PathBuf>,
    /// Leave out the other crates' benchmarks (`--skip-external`: Zenoh
    /// between processes, the fleet), which a full run builds and runs.
    pub(crate) skip_external: bool,
    /// This benchmark's binary, run again (`--first-build AGENTS`) for each
    /// first build of a system in a fresh process; `None`: not measured.
    pub(crate) program: Option<PathBuf>,
}

/// `cargo run --release --example bench_scale [-- --quick]`.
pub(crate) fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let quick = args.iter().any(|a| a == "--quick");
    let value = |key: &str| args.windows(2).find(|w| w[0] == key).map(|w| w[1].clone());
    if args.iter().any(|a| a == "--no-huge-pages") {
        det::NO_HUGE_PAGES.store(true, std::sync::atomic::Ordering::Relaxed);
    }
    if let Some(agents) = value("--first-build") {
        return det::first_build(count("--first-build", &agents)?);
    }
    let program = std::env::current_exe().ok();
    let only = value("--only");
    if let Some(part) = only.as_deref() {
        let mut scale = Scale::default();
        let out = &mut std::io::stdout();
        let mut plan = if quick { QUICK } else { FULL };
        // `--agents 1,3333`, `--batches 3`, `--seconds 5`: other sizes and
        // repeats (a profiler's run, an A/B of two builds).
        let agents: Option<&'static [usize]> = match value("--agents") {
            Some(list) => Some(
                list.split(',')
                    .map(|a| count("--agents", a))
                    .collect::<Result<Vec<_>, _>>()?
                    .leak(),
            ),
            None => None,
        };
        match part {
            "det" => {
                plan.det_agents = agents.unwrap_or(plan.det_agents);
                if let Some(batches) = value("--batches") {
                    plan.det_batches = batches.parse()?;
                }
                deterministic(&plan, program.as_deref(), out, &mut scale)?;
            }
            "rt" => {
                let seconds = value("--seconds").map(|s| s.parse()).transpose()?;
                if let Some((n, jitter)) = rt::run(
                    agents.unwrap_or(plan.rt_agents),
                    seconds.unwrap_or(plan.rt_seconds),
                    0,
                    out,
                )? {
                    scale.rt_subsystems = Some(n as f64);
                    scale.rt_jitter_us_p99 = Some(jitter);
                }
            }
            other => return Err(format!("--only {other}: `det` or `rt`").into()),
        }
        writeln!(out, "{scale}")?;
        return Ok(());
    }
    if args.iter().any(|a| a == "--multirate") {
        for figures in det::measure_rates(FULL.rates_agents, FULL.det_batches)? {
            println!("{}", figures.line());
        }
        return Ok(());
    }
    let options = Options {
        quick,
        skip_external: args.iter().any(|a| a == "--skip-external"),
        // A full run builds the `embodied` binary if it is not there (for
        // `embodied new`).
        embodied_bin: tools::embodied_bin()
            .or_else(|| (!quick).then(tools::build_embodied).flatten()),
        program,
    };
    run(&options, &mut std::io::stdout())?;
    Ok(())
}

/// A number of agents given with `flag`: a positive whole number.
pub(crate) fn count(flag: &str, given: &str) -> Result<usize, String> {
    match given.trim().parse::<usize>() {
        Ok(n) if n > 0 => Ok(n),
        _ => Err(format!(
            "{flag}: `{given}` is not a positive number of agents"
        )),
    }
}

/// The deterministic executor's part of a run: its `det` lines and the growth
/// line, written to `out`; `action_ratio_10000` into `scale`. Alone, as
/// `--only det`, it is followed by the final line (the other figures `na`).
/// `program`: this benchmark's binary, for the first builds.
fn deterministic(
    plan: &Plan,
    program: Option<&Path>,
    out: &mut dyn Write,
    scale: &mut Scale,
) -> Result<(), Box<dyn std::error::Error>> {
    let det = det::measure(plan.det_agents, plan.det_batches, program)?;
    for figures in &det {
        writeln!(out, "{}", figures.line())?;
    }
    // Linear is judged from the first size of at least 300 subsystems: a
    // smaller system's memory and build per subsystem hold the costs that do
    // not grow with it (the executor's own tables, a first region's page).
    let from = det.iter().find(|f| f.n >= 300).or(det.first());
    if let (Some(first), Some(from), Some(last)) = (det.first(), from, det.last()) {
        scale.action_ratio_10000 = Some(last.action_ns_p50 / first.action_ns_p50);
        let per = |f: &det::Figures| f.build_ms / f.n as f64;
        let first_build = match (from.first_build_us, last.first_build_us) {
            (Some(a), Some(b)) => format!("{:.2}x", b / a),
            _ => "na".to_owned(),
        };
        writeln!(
            out,
            "det growth: action {:.2}x from n={} to n={} (aim <= 1.5); from n={} to n={} \
             (1 is linear): bytes per subsystem {:.2}x, build time per subsystem {first_build} \
             (a program's one build, in a fresh process), {:.2}x (rebuilt in the process \
             that holds one, which has threads)",
            last.action_ns_p50 / first.action_ns_p50,
            first.n,
            last.n,
            from.n,
            last.n,
            last.bytes_per_subsystem / from.bytes_per_subsystem,
            per(last) / per(from)
        )?;
    }
    Ok(())
}

/// Measures, writing the lines to `out`; the figures of the final line.
pub(crate) fn run(
    options: &Options,
    out: &mut dyn Write,
) -> Result<Scale, Box<dyn std::error::Error>> {
    let plan = if options.quick { QUICK } else { FULL };
    let mut scale = Scale::default();

    deterministic(&plan, options.program.as_deref(), out, &mut scale)?;

    // The deterministic executor, several rates.
    for figures in det::measure_rates(plan.rates_agents, plan.det_batches)? {
        writeln!(out, "{}", figures.line())?;
    }

    // The real-time executor.
    if let Some((n, jitter)) = rt::run(
        plan.rt_agents,
        plan.rt_seconds,
        plan.rt_per_subsystem_max,
        out,
    )? {
        scale.rt_subsystems = Some(n as f64);
        scale.rt_jitter_us_p99 = Some(jitter);
    }

    // The checker and the tools.
    let dir = std::env::temp_dir().join(format!("bench_scale_{}", std::process::id()));
    std::fs::create_dir_all(&dir)?;
    let bin = options.embodied_bin.as_deref();
    let tools = plan
        .tool_agents
        .iter()
        .map(|&agents| tools::measure(agents, &dir, bin))
        .collect::<Result<Vec<_>, _>>();
    let _ = std::fs::remove_dir_all(&dir);
    for figures in &tools? {
        writeln!(out, "{}", figures.line())?;
    }
    if bin.is_none() {
        writeln!(
            out,
            "tools: new_ms=na: the `embodied` binary is not built \
             (cargo build --release --features cli --bin embodied, or set EMBODIED_BIN)"
        )?;
    }

    // Zenoh between processes and the fleet: the other crates' benchmarks.
    if plan.external && !options.skip_external {
        let zenoh = external::run("agent-zenoh", "bench_zenoh_scale", &[], out)?;
        scale.zenoh_ratio_32 = external::figure(&zenoh, "zenoh_ratio_32");
        let fleet = external::run(
            "rex-agent",
            "fleet",
            &["--robots", "1,4,16,64", "--no-vo"],
            out,
        )?;
        scale.fleet_robots = external::figure(&fleet, "fleet_robots");
        scale.fleet_cost_ratio = external::figure(&fleet, "fleet_cost_ratio");
    }

    writeln!(out, "{scale}")?;
    Ok(scale)
}
