//! The deterministic executor as the system grows.
//!
//! A small benchmark agent, built through agent-core's public API: a control
//! subsystem `c` with one virtual effector `e` and one virtual receptor `r`,
//! sample and queue links between them, and a transmission buffer from `c` to
//! the next agent's `c` (the agents form a ring; one agent alone has none).
//! Every subsystem has the same period, so every instant activates all of them:
//! an instant of `n` subsystems is `n` elementary actions. The copies share
//! their FSMs' definitions (each FSM built once and cloned, as `Fsm`'s clones
//! share it), each subsystem with its own state.
//!
//! For each size, the same measurements and the same repeat policy (the
//! rebuilds and the actions in a process that has started a thread, so that
//! the C library's allocator locks its arenas at every size:
//! [`with_threads`]):
//!
//! * `build_ms`: median over [`BUILDS`] builds of the time to declare the
//!   system on a [`SystemBuilder`], build it and make its [`Executor`]
//!   (FSMs included), each after the last was dropped, in the process that
//!   holds the measured executor of the same size: a rebuild, in a heap
//!   whose free memory is scattered over the last system's;
//! * `first_build_us_per_subsystem`: the same build as a program makes it,
//!   once, in a fresh process (this program run again with `--first-build
//!   AGENTS`), median over [`FIRST_BUILDS`] processes, per subsystem (`na`
//!   when no program to run is given). A build does not wait for the
//!   kernel to back the executor's memory with huge pages
//!   ([`ExecConfig::huge_pages`]: on a thread of the executor's);
//! * `huge_pages_ms`: how long that took the kernel for the measured
//!   executor ([`Executor::wait_for_huge_pages`], which waits for it before
//!   anything else is measured);
//! * `bytes_per_subsystem`: the heap that system and executor hold once warmed
//!   up (queues filled), per subsystem, counted by the byte-counting global
//!   allocator of `main.rs`;
//! * `action_ns_p50`, `action_ns_p99`: the time of an instant divided by its
//!   actions, over batches of about [`ACTIONS_PER_BATCH`] actions (whole
//!   instants), median and 99th percentile of the batches, after a warm-up of
//!   the same length;
//! * `allocs_per_action`: heap allocations per action over the measured batches.

use std::hint::black_box;
use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use embodied::*;

use super::heap;

// ---------------------------------------------------------------------------
// The agent: c, e, r.

macro_rules! group {
    ($name:ident, $peer:ident { $($field:ident: $ty:ty),* }) => {
        #[derive(Debug, Default)]
        struct $name {
            $($field: $ty),*
        }
        impl Group for $name {
            const PEER: NodeKind = NodeKind::$peer;
        }
    };
}
group!(CfromE, VirtualEffector { state: In<f64> });
group!(CfromR, VirtualReceptor { meas: In<f64>, count: In<u64> });
group!(CfromC, Control { t: In<f64> });
group!(CtoE, VirtualEffector { cmd: Out<f64>, seq: Out<u64> });
group!(CtoR, VirtualReceptor { gain: Out<f64> });
group!(CtoC, Control { t: Out<f64> });
group!(EfromC, Control { cmd: In<f64>, seq: In<u64> });
group!(EtoC, Control { state: Out<f64> });
group!(RfromC, Control { gain: In<f64> });
group!(RtoC, Control { meas: Out<f64>, count: Out<u64> });

#[derive(Debug, Default)]
struct CIn {
    e: CfromE,
    r: CfromR,
    n: CfromC,
}
#[derive(Debug, Default)]
struct COut {
    e: CtoE,
    r: CtoR,
    n: CtoC,
}
#[derive(Debug, Default)]
struct EIn {
    c: EfromC,
}
#[derive(Debug, Default)]
struct EOut {
    c: EtoC,
}
#[derive(Debug, Default)]
struct RIn {
    c: RfromC,
}
#[derive(Debug, Default)]
struct ROut {
    c: RtoC,
}

struct Ctl;
impl Subsystem for Ctl {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = u64;
    type Input = CIn;
    type Output = COut;
}

struct Eff;
impl Subsystem for Eff {
    const KIND: SubsystemKind = SubsystemKind::VirtualEffector;
    type Memory = f64;
    type Input = EIn;
    type Output = EOut;
}

struct Rec;
impl Subsystem for Rec {
    const KIND: SubsystemKind = SubsystemKind::VirtualReceptor;
    type Memory = u64;
    type Input = RIn;
    type Output = ROut;
}

fn value<T: Copy + Default>(x: &In<T>) -> T {
    x.get().copied().unwrap_or_default()
}

/// `c`: commands `e` (a sample and a sequence number on a queue), tunes `r`,
/// passes a value on to the next agent, counts what `r` queued.
fn ctl_fsm() -> Result<Fsm<Ctl>, FsmBuildError> {
    Fsm::single(Behaviour::while_loop(
        "run",
        Action::<Ctl>::new()
            .output(
                |y| &mut y.e,
                |m: &u64, x: &CIn, y: &mut CtoE| {
                    y.cmd.set(value(&x.e.state) + 0.5 * value(&x.n.t));
                    y.seq.set(*m);
                },
            )
            .output(
                |y| &mut y.r,
                |_: &u64, x: &CIn, y: &mut CtoR| y.gain.set(1.0 + 0.1 * value(&x.r.meas)),
            )
            .output(
                |y| &mut y.n,
                |_: &u64, x: &CIn, y: &mut CtoC| y.t.set(0.9 * value(&x.r.meas)),
            )
            .memory(|m: &mut u64, x: &CIn| *m += 1 + (value(&x.r.count) & 1)),
        "false",
    ))
}

/// `e`: follows the command, reports its state.
fn eff_fsm() -> Result<Fsm<Eff>, FsmBuildError> {
    Fsm::single(Behaviour::while_loop(
        "run",
        Action::<Eff>::new()
            .output(
                |y| &mut y.c,
                |m: &f64, _: &EIn, y: &mut EtoC| y.state.set(*m),
            )
            .memory(|m: &mut f64, x: &EIn| {
                *m += 0.5 * (value(&x.c.cmd) - *m) + (value(&x.c.seq) & 1) as f64 * 1e-3;
            }),
        "false",
    ))
}

/// `r`: a measurement (a sample) and a count (on a queue).
fn rec_fsm() -> Result<Fsm<Rec>, FsmBuildError> {
    Fsm::single(Behaviour::while_loop(
        "run",
        Action::<Rec>::new()
            .output(
                |y| &mut y.c,
                |m: &u64, x: &RIn, y: &mut RtoC| {
                    y.meas.set(value(&x.c.gain) * (*m % 7) as f64);
                    y.count.set(*m);
                },
            )
            .memory(|m: &mut u64, _: &RIn| *m += 1),
        "false",
    ))
}

/// `agents` copies of the agent in a ring, every subsystem every millisecond
/// (see [`system_at`]).
pub(crate) fn system(agents: usize) -> Result<(System, Vec<NodeId>), Box<dyn std::error::Error>> {
    system_at(agents, Period::from_millis(1)?)
}

/// `agents` copies of the agent in a ring: `3 * agents` subsystems of period
/// `period`, 7 links per agent (6 within it, 1 to the next agent's `c`; none
/// for one agent alone); and the subsystems' ids.
pub(crate) fn system_at(
    agents: usize,
    period: Period,
) -> Result<(System, Vec<NodeId>), Box<dyn std::error::Error>> {
    system_with(agents, |_| period)
}

/// `agents` copies of the agent in a ring, agent `i`'s subsystems of period
/// `period(i)` (see [`system_at`]).
fn system_with(
    agents: usize,
    period: impl Fn(usize) -> Period,
) -> Result<(System, Vec<NodeId>), Box<dyn std::error::Error>> {
    let queue = Policy::queue(4);
    let mut b = SystemBuilder::new();
    let mut controls = Vec::with_capacity(agents);
    let mut ids = Vec::with_capacity(3 * agents);
    // One definition of each FSM, shared by every copy of the agent (an
    // `Fsm`'s clones share it), as a fleet's robots share theirs.
    let (ctl, eff, rec) = (ctl_fsm()?, eff_fsm()?, rec_fsm()?);
    for i in 0..agents {
        let a = b.agent(format!("a{i}"));
        let period = period(i);
        let c = b.subsystem(a, format!("c{i}"), period, 0, ctl.clone());
        let e = b.subsystem(a, format!("e{i}"), period, 0.0, eff.clone());
        let r = b.subsystem(a, format!("r{i}"), period, 0, rec.clone());
        b.connect(
            c.output(port!(COut, e.cmd)),
            e.input(port!(EIn, c.cmd)),
            Policy::Sample,
        );
        b.connect(
            c.output(port!(COut, e.seq)),
            e.input(port!(EIn, c.seq)),
            queue,
        );
        b.connect(
            e.output(port!(EOut, c.state)),
            c.input(port!(CIn, e.state)),
            Policy::Sample,
        );
        b.connect(
            c.output(port!(COut, r.gain)),
            r.input(port!(RIn, c.gain)),
            Policy::Sample,
        );
        b.connect(
            r.output(port!(ROut, c.meas)),
            c.input(port!(CIn, r.meas)),
            Policy::Sample,
        );
        b.connect(
            r.output(port!(ROut, c.count)),
            c.input(port!(CIn, r.count)),
            queue,
        );
        controls.push(c);
        ids.extend([c.id(), e.id(), r.id()]);
    }
    if agents > 1 {
        for i in 0..agents {
            let (from, to) = (controls[i], controls[(i + 1) % agents]);
            b.connect(
                from.output(port!(COut, n.t)),
                to.input(port!(CIn, n.t)),
                Policy::Sample,
            );
        }
    }
    Ok((b.build()?, ids))
}

// ---------------------------------------------------------------------------
// Measuring.

/// Builds per size (the median is reported).
const BUILDS: usize = 5;
/// Fresh processes per size that each build the system once (the median is
/// reported).
const FIRST_BUILDS: usize = 5;
/// Elementary actions per timed batch (rounded to whole instants).
pub(crate) const ACTIONS_PER_BATCH: u64 = 40_000;

/// What one size measured.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Figures {
    /// Subsystems.
    pub(crate) n: usize,
    /// Median time per elementary action over the batches \[ns\].
    pub(crate) action_ns_p50: f64,
    /// 99th percentile of the batches' time per action \[ns\].
    pub(crate) action_ns_p99: f64,
    /// Heap held by the warmed-up executor, per subsystem \[bytes\].
    pub(crate) bytes_per_subsystem: f64,
    /// Median time to build the system and its executor again \[ms\].
    pub(crate) build_ms: f64,
    /// Median time of a fresh process's one build, per subsystem \[us\].
    pub(crate) first_build_us: Option<f64>,
    /// How long the kernel took to back the measured executor's memory with
    /// huge pages, on the executor's thread for it (the builds do not wait
    /// for it) \[ms\].
    pub(crate) huge_pages_ms: f64,
    /// Heap allocations per measured action.
    pub(crate) allocs_per_action: f64,
}

impl Figures {
    /// The `det ...` line.
    pub(crate) fn line(&self) -> String {
        format!(
            "det n={} action_ns_p50={:.1} action_ns_p99={:.1} bytes_per_subsystem={:.0} \
             build_ms={:.3} build_us_per_subsystem={:.2} first_build_us_per_subsystem={} \
             huge_pages_ms={:.3} allocs_per_action={}",
            self.n,
            self.action_ns_p50,
            self.action_ns_p99,
            self.bytes_per_subsystem,
            self.build_ms,
            self.build_ms * 1e3 / self.n as f64,
            self.first_build_us
                .map_or_else(|| "na".to_owned(), |us| format!("{us:.2}")),
            self.huge_pages_ms,
            self.allocs_per_action
        )
    }
}

/// The value at quantile `q` of `v` (nearest rank).
pub(crate) fn quantile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    let rank = ((q * v.len() as f64).ceil() as usize).clamp(1, v.len());
    v[rank - 1]
}

/// Make this process one that has started a thread, once, before anything
/// is built or timed in it. The C library's allocator skips its arenas'
/// locks in a process that never started one and takes them from the first
/// thread on; a large system's executor starts one for its huge pages
/// ([`ExecConfig::huge_pages`]), which would move the rebuilds of the sizes
/// after it onto the slower path mid-run. Every rebuild is timed on the
/// locked path (that of every program with threads: Zenoh's, a recorder's,
/// the real-time executor's), 15 to 25 % slower than the other at every size
/// (docs/scaling.md). A first build, in a fresh process, is timed before any
/// thread starts.
fn with_threads() {
    static STARTED: std::sync::Once = std::sync::Once::new();
    STARTED.call_once(|| {
        // A thread that cannot start leaves the process as it was: the
        // figures are then the single-threaded allocator's.
        let _ = std::thread::Builder::new().spawn(|| ()).map(|t| t.join());
    });
}

/// Whether the executors measured leave their memory on the pages the
/// allocator gave (`--no-huge-pages`: [`ExecConfig::huge_pages`] off).
pub(crate) static NO_HUGE_PAGES: AtomicBool = AtomicBool::new(false);

/// The executor's settings: the default, but for `--no-huge-pages`.
fn config() -> ExecConfig {
    ExecConfig {
        huge_pages: !NO_HUGE_PAGES.load(Ordering::Relaxed),
        ..ExecConfig::default()
    }
}

fn executor(agents: usize) -> Result<(Executor, Vec<NodeId>), Box<dyn std::error::Error>> {
    let (system, ids) = system(agents)?;
    Ok((Executor::new(system, config()), ids))
}

/// One size's executor, batch by batch.
struct Bench {
    n: usize,
    exec: Executor,
    ids: Vec<NodeId>,
    /// Instants per batch.
    per_batch: u64,
    warm_up: u64,
    bytes: usize,
    huge_pages_ms: f64,
    build_ms: Vec<f64>,
    action_ns: Vec<f64>,
    allocations: u64,
}

impl Bench {
    /// The executor of `agents` agents, warmed up: the heap it holds then.
    fn new(agents: usize) -> Result<Bench, Box<dyn std::error::Error>> {
        with_threads();
        let n = 3 * agents;
        let before = heap::live();
        let (mut exec, ids) = executor(agents)?;
        // Its memory on huge pages before anything is measured.
        let huge_pages_ms = exec.wait_for_huge_pages().took.as_secs_f64() * 1e3;
        let per_batch = (ACTIONS_PER_BATCH / n as u64).max(1);
        for _ in 0..per_batch {
            exec.step()?; // warm-up: every buffer written, every queue in use
        }
        let ids_bytes = ids.capacity() * std::mem::size_of::<NodeId>();
        let bytes = heap::live().saturating_sub(before + ids_bytes);
        let warm_up = exec.report().instants;
        Ok(Bench {
            n,
            exec,
            ids,
            per_batch,
            warm_up,
            bytes,
            huge_pages_ms,
            build_ms: Vec::new(),
            action_ns: Vec::new(),
            allocations: 0,
        })
    }

    /// One timed build of a system of the same size, and its executor.
    fn build(&mut self) -> Result<(), Box<dyn std::error::Error>> {
        let start = Instant::now();
        let exec = black_box(executor(self.n / 3)?);
        self.build_ms.push(start.elapsed().as_secs_f64() * 1e3);
        drop(exec);
        Ok(())
    }

    /// One timed batch.
    fn batch(&mut self) -> Result<(), ExecError> {
        let allocations = allocations::total();
        let start = Instant::now();
        for _ in 0..self.per_batch {
            self.exec.step()?;
        }
        let ns = start.elapsed().as_nanos() as f64;
        self.allocations += allocations::total() - allocations;
        self.action_ns
            .push(ns / (self.per_batch * self.n as u64) as f64);
        Ok(())
    }

    /// The figures, after checking that every measured instant ran every
    /// subsystem once, without error.
    fn figures(mut self) -> Result<Figures, Box<dyn std::error::Error>> {
        let n = self.n;
        let report = self.exec.report();
        let instants = report.instants - self.warm_up;
        let expected = self.per_batch * self.action_ns.len() as u64;
        let iterations: u64 = self
            .ids
            .iter()
            .filter_map(|&i| self.exec.iteration(i))
            .sum();
        if instants != expected
            || report.error_count != 0
            || iterations != (expected + self.warm_up) * n as u64
        {
            return Err(format!(
                "n={n}: expected {expected} error-free instants of {n} actions each; ran \
                 {instants} ({} errors, {iterations} actions in all)",
                report.error_count
            )
            .into());
        }
        let actions = (expected * n as u64) as f64;
        Ok(Figures {
            n,
            action_ns_p50: quantile(&mut self.action_ns, 0.5),
            action_ns_p99: quantile(&mut self.action_ns, 0.99),
            bytes_per_subsystem: self.bytes as f64 / n as f64,
            build_ms: quantile(&mut self.build_ms, 0.5),
            first_build_us: None,
            huge_pages_ms: self.huge_pages_ms,
            allocs_per_action: self.allocations as f64 / actions,
        })
    }
}

/// Measures systems of `agents` agents each (`3 * agents` subsystems), one
/// size after the other: its builds, then its executor alone on the machine,
/// as a program runs one system. (Sizes taking turns batch by batch would
/// measure each with its caches filled by the others: a large system's time
/// per action then doubles.)
///
/// `program`: this benchmark's binary, run again for each first build
/// ([`first_build`]); `None`: not measured.
pub(crate) fn measure(
    agents: &[usize],
    batches: usize,
    program: Option<&Path>,
) -> Result<Vec<Figures>, Box<dyn std::error::Error>> {
    let mut figures = Vec::with_capacity(agents.len());
    for &a in agents {
        let first = match program {
            Some(program) => Some(first_builds(program, a)?),
            None => None,
        };
        let mut bench = Bench::new(a)?;
        for _ in 0..BUILDS {
            bench.build()?;
        }
        for _ in 0..batches {
            bench.batch()?;
        }
        figures.push(Figures {
            first_build_us: first,
            ..bench.figures()?
        });
    }
    Ok(figures)
}

/// The median over [`FIRST_BUILDS`] fresh processes (`program --first-build
/// AGENTS`) of their one build's time per subsystem \[us\].
fn first_builds(program: &Path, agents: usize) -> Result<f64, Box<dyn std::error::Error>> {
    let mut us = Vec::with_capacity(FIRST_BUILDS);
    for _ in 0..FIRST_BUILDS {
        let huge = NO_HUGE_PAGES
            .load(Ordering::Relaxed)
            .then_some("--no-huge-pages");
        let out = Command::new(program)
            .args(["--first-build", &agents.to_string()])
            .args(huge)
            .stderr(Stdio::inherit())
            .output()?;
        let said = String::from_utf8_lossy(&out.stdout);
        let value = said.lines().find_map(|l| l.strip_prefix("first_build_us="));
        match (out.status.success(), value.map(str::parse::<f64>)) {
            (true, Some(Ok(total))) => us.push(total / (3 * agents) as f64),
            _ => {
                return Err(format!(
                    "{} --first-build {agents}: {}; said `{}`",
                    program.display(),
                    out.status,
                    said.trim()
                )
                .into());
            }
        }
    }
    Ok(quantile(&mut us, 0.5))
}

/// `--first-build AGENTS`: build the system of `agents` agents and its
/// executor once, as a program does, and print `first_build_us=<..>` (the
/// whole build \[us\]).
pub(crate) fn first_build(agents: usize) -> Result<(), Box<dyn std::error::Error>> {
    let start = Instant::now();
    let exec = black_box(executor(agents)?);
    let us = start.elapsed().as_secs_f64() * 1e6;
    drop(exec);
    println!("first_build_us={us:.1}");
    Ok(())
}

// ---------------------------------------------------------------------------
// Several rates.

/// The slow agents' period over the fast agent's.
const RATIO: u64 = 100;

/// What one size of the multi-rate system measured.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Rates {
    /// Subsystems (3 of them fast).
    pub(crate) n: usize,
    /// Median over the batches of the mean time of an instant at which only
    /// the fast agent runs (3 actions) \[ns\].
    pub(crate) fast_instant_ns: f64,
    /// Median over the batches of the mean time of an instant, all instants
    /// of whole slow periods counted \[ns\].
    pub(crate) instant_ns: f64,
    /// Heap allocations per measured instant.
    pub(crate) allocs_per_instant: f64,
}

impl Rates {
    /// The `multirate ...` line.
    pub(crate) fn line(&self) -> String {
        format!(
            "multirate n={} fast_n=3 ratio={RATIO} fast_instant_ns={:.1} instant_ns={:.1} \
             allocs_per_instant={}",
            self.n, self.fast_instant_ns, self.instant_ns, self.allocs_per_instant
        )
    }
}

/// Systems of `agents` agents (`3 * agents` subsystems) of which the first
/// runs every millisecond and the others every [`RATIO`] milliseconds: each
/// slow period is `RATIO - 1` instants of the fast agent's 3 actions and one
/// instant of every subsystem. Batches of whole slow periods (about
/// [`ACTIONS_PER_BATCH`] actions), each instant timed, after a warm-up of a
/// batch; checks that every subsystem ran at every instant of its period.
pub(crate) fn measure_rates(
    agents: &[usize],
    batches: usize,
) -> Result<Vec<Rates>, Box<dyn std::error::Error>> {
    with_threads();
    let (fast, slow) = (Period::from_millis(1)?, Period::from_millis(RATIO)?);
    let mut figures = Vec::with_capacity(agents.len());
    for &a in agents {
        let n = 3 * a;
        let (system, ids) = system_with(a, |i| if i == 0 { fast } else { slow })?;
        let mut exec = Executor::new(system, config());
        exec.wait_for_huge_pages();
        let per_slow_period = 3 * (RATIO - 1) + n as u64;
        let periods = (ACTIONS_PER_BATCH / per_slow_period).max(1);
        let instants = periods * RATIO;
        for _ in 0..instants {
            exec.step()?;
        }
        let (mut fast_ns, mut instant_ns) = (Vec::new(), Vec::new());
        let mut allocs = 0;
        for _ in 0..batches {
            let (mut fast_total, mut total) = (0u128, 0u128);
            let before = allocations::total();
            for _ in 0..instants {
                let start = Instant::now();
                let t = exec.step()?;
                let ns = start.elapsed().as_nanos();
                total += ns;
                if t.is_some_and(|t| t.as_nanos() % (RATIO * 1_000_000) != 0) {
                    fast_total += ns;
                }
            }
            allocs += allocations::total() - before;
            fast_ns.push(fast_total as f64 / (periods * (RATIO - 1)) as f64);
            instant_ns.push(total as f64 / instants as f64);
        }
        let done = instants * (batches as u64 + 1);
        let ran = |i: usize| exec.iteration(ids[i]).unwrap_or(0);
        if exec.report().instants != done
            || exec.report().error_count != 0
            || (0..3).any(|i| ran(i) != done)
            || (3..n).any(|i| ran(i) != done / RATIO)
        {
            return Err(format!(
                "n={n}: expected {done} error-free instants, the fast agent at each, the others \
                 at one in {RATIO}"
            )
            .into());
        }
        figures.push(Rates {
            n,
            fast_instant_ns: quantile(&mut fast_ns, 0.5),
            instant_ns: quantile(&mut instant_ns, 0.5),
            allocs_per_instant: allocs as f64 / (instants * batches as u64) as f64,
        });
    }
    Ok(figures)
}
