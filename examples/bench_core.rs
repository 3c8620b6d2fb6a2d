//! The runtime's own cost.
//!
//! ```text
//! cargo run --release --example bench_core
//! ```
//!
//! * `action_ns`: median wall time per elementary action in the deterministic
//!   executor, in-process: two subsystems exchanging 3 buffers each way, so each
//!   action reads 3 inputs, decides (terminal test), computes and sends 3 outputs;
//!   the executor's scheduling is included.
//! * `fsm_step_ns`: median time of one FSM decision that ends a behaviour: the
//!   terminal test plus the selection of the one arc that holds among two.
//! * `allocs_per_cycle`: heap allocations per steady-state cycle, counted by a
//!   counting global allocator. A cycle is one instant of the executor
//!   ([`Executor::step`]): both subsystems (same period) read, decide, compute and
//!   send once, so a cycle holds two elementary actions. Counted over every
//!   measured instant, after a warm-up that fills the buffers and queues.
//!
//! Medians over batches of 20 000 instants (40 000 actions); the last line reads
//! `action_ns=<..> fsm_step_ns=<..> allocs_per_cycle=<..>`.

use std::alloc::{GlobalAlloc, Layout, System as SystemAlloc};
use std::hint::black_box;
use std::sync::atomic::{AtomicU64, Ordering::Relaxed};
use std::time::{Duration, Instant};

use embodied::*;
use serde::{Deserialize, Serialize};

struct Counting;

static ALLOCATIONS: AtomicU64 = AtomicU64::new(0);

// SAFETY: every method forwards to the system allocator with the caller's arguments
// unchanged; counting has no effect on the memory handed out.
#[expect(
    unsafe_code,
    reason = "a global allocator is an unsafe trait; this one only counts"
)]
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Relaxed);
        // SAFETY: same contract as our caller's.
        unsafe { SystemAlloc.alloc(layout) }
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Relaxed);
        // SAFETY: same contract as our caller's.
        unsafe { SystemAlloc.alloc_zeroed(layout) }
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        ALLOCATIONS.fetch_add(1, Relaxed);
        // SAFETY: same contract as our caller's.
        unsafe { SystemAlloc.realloc(ptr, layout, new_size) }
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        // SAFETY: same contract as our caller's.
        unsafe { SystemAlloc.dealloc(ptr, layout) }
    }
}

#[global_allocator]
static GLOBAL: Counting = Counting;

// ---------------------------------------------------------------------------
// Two subsystems with three buffers each way.

#[derive(Clone, Copy, Debug, Default, Serialize, Deserialize)]
struct Pose {
    x: f64,
    y: f64,
    phi: f64,
}

macro_rules! group {
    ($name:ident, $peer:ident, $kind:ident) => {
        #[derive(Debug, Default)]
        struct $name {
            a: $kind<f64>,
            b: $kind<Pose>,
            c: $kind<u64>,
        }
        impl Group for $name {
            const PEER: NodeKind = NodeKind::$peer;
        }
    };
}
group!(CtoE, VirtualEffector, Out);
group!(CfromE, VirtualEffector, In);
group!(EtoC, Control, Out);
group!(EfromC, Control, In);

#[derive(Debug, Default)]
struct COut {
    e: CtoE,
}
#[derive(Debug, Default)]
struct CIn {
    e: CfromE,
}
#[derive(Debug, Default)]
struct EOut {
    c: EtoC,
}
#[derive(Debug, Default)]
struct EIn {
    c: EfromC,
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
    type Memory = u64;
    type Input = EIn;
    type Output = EOut;
}

fn ctl_fsm() -> Result<Fsm<Ctl>, FsmBuildError> {
    Fsm::single(Behaviour::while_loop(
        "run",
        Action::<Ctl>::new()
            .output(
                |y| &mut y.e,
                |m: &u64, x: &CIn, y: &mut CtoE| {
                    let a = x.e.a.get().copied().unwrap_or(0.0);
                    let p = x.e.b.get().copied().unwrap_or_default();
                    y.a.set(a + 1.0);
                    y.b.set(Pose {
                        x: p.x + 0.5,
                        y: p.y,
                        phi: a,
                    });
                    y.c.set(*m);
                },
            )
            .memory(|m: &mut u64, x: &CIn| *m += x.e.c.get().copied().unwrap_or(1) & 1),
        "false",
    ))
}

fn eff_fsm() -> Result<Fsm<Eff>, FsmBuildError> {
    Fsm::single(Behaviour::while_loop(
        "run",
        Action::<Eff>::new()
            .output(
                |y| &mut y.c,
                |m: &u64, x: &EIn, y: &mut EtoC| {
                    y.a.set(x.c.a.get().copied().unwrap_or(0.0) * 0.5);
                    y.b.set(x.c.b.get().copied().unwrap_or_default());
                    y.c.set(*m + 1);
                },
            )
            .memory(|m: &mut u64, _: &EIn| *m += 1),
        "false",
    ))
}

fn pair() -> Result<System, Box<dyn std::error::Error>> {
    let period = Period::from_millis(1)?;
    let mut b = SystemBuilder::new();
    let a = b.agent("bench");
    let c = b.subsystem(a, "c", period, 0, ctl_fsm()?);
    let e = b.subsystem(a, "e", period, 0, eff_fsm()?);
    b.connect(
        c.output(port!(COut, e.a)),
        e.input(port!(EIn, c.a)),
        Policy::Sample,
    );
    b.connect(
        c.output(port!(COut, e.b)),
        e.input(port!(EIn, c.b)),
        Policy::Sample,
    );
    b.connect(
        c.output(port!(COut, e.c)),
        e.input(port!(EIn, c.c)),
        Policy::queue(4),
    );
    b.connect(
        e.output(port!(EOut, c.a)),
        c.input(port!(CIn, e.a)),
        Policy::Sample,
    );
    b.connect(
        e.output(port!(EOut, c.b)),
        c.input(port!(CIn, e.b)),
        Policy::Sample,
    );
    b.connect(
        e.output(port!(EOut, c.c)),
        c.input(port!(CIn, e.c)),
        Policy::queue(4),
    );
    Ok(b.build()?)
}

// ---------------------------------------------------------------------------
// An FSM whose every decision ends a behaviour and picks one of two arcs.

struct Chooser;
impl Subsystem for Chooser {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = u64;
    type Input = ();
    type Output = ();
}

fn chooser_fsm() -> Result<Fsm<Chooser>, FsmBuildError> {
    let behaviour =
        |name: &'static str| Behaviour::while_loop(name, Action::<Chooser>::new(), "done");
    Fsm::builder()
        .predicate("done", |m: &u64, _| *m < u64::MAX)
        .predicate("odd", |m: &u64, _| m & 1 == 1)
        .behaviour(behaviour("a"))
        .behaviour(behaviour("b"))
        .behaviour(behaviour("c"))
        .initial("a")
        .arc("a", "b", "odd")
        .arc("a", "c", "!odd")
        .arc("b", "c", "odd")
        .arc("b", "a", "!odd")
        .arc("c", "a", "odd")
        .arc("c", "b", "!odd")
        .build()
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Instants (cycles) per timed batch.
const BATCH: u64 = 20_000;
/// Elementary actions per cycle: the two subsystems of [`pair`] share one period.
const ACTIONS_PER_CYCLE: u64 = 2;
const BATCHES: usize = 101;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // Elementary actions in the executor.
    let mut exec = Executor::new(pair()?, ExecConfig::default());
    exec.run_for(Duration::from_millis(BATCH))?; // warm-up: buffers and queues filled
    let warm_up = exec.report().instants;
    let mut action_ns = Vec::with_capacity(BATCHES);
    let mut allocations = 0;
    let mut cycles = 0;
    let mut actions = 0;
    for _ in 0..BATCHES {
        let before = ALLOCATIONS.load(Relaxed);
        let start = Instant::now();
        for _ in 0..BATCH {
            exec.step()?;
        }
        let elapsed = start.elapsed();
        allocations += ALLOCATIONS.load(Relaxed) - before;
        cycles += BATCH;
        actions += ACTIONS_PER_CYCLE * BATCH;
        action_ns.push(elapsed.as_nanos() as f64 / (ACTIONS_PER_CYCLE * BATCH) as f64);
    }
    let executed = exec.report().instants - warm_up;
    if executed != cycles || exec.report().error_count != 0 {
        return Err(format!(
            "expected {cycles} error-free instants, the executor ran {executed} ({} errors)",
            exec.report().error_count
        )
        .into());
    }
    let action = median(action_ns);
    // Per cycle (one executor instant), not per action.
    let allocs = allocations as f64 / cycles as f64;

    // FSM decisions.
    let fsm = chooser_fsm()?;
    let mut state = fsm.start();
    let mut fsm_ns = Vec::with_capacity(BATCHES);
    let mut m = 0u64;
    for _ in 0..BATCHES {
        let start = Instant::now();
        for _ in 0..BATCH {
            m = m.wrapping_add(1);
            let step = fsm.step(&mut state, black_box(&m), &())?;
            black_box(step);
        }
        fsm_ns.push(start.elapsed().as_nanos() as f64 / BATCH as f64);
    }
    let decision = median(fsm_ns);

    println!(
        "{cycles} cycles = {actions} actions ({BATCHES} batches of {BATCH} instants, \
         {ACTIONS_PER_CYCLE} actions each), {allocations} allocations in them, {} FSM decisions",
        BATCHES as u64 * BATCH
    );
    println!(
        "against the targets: action {:.2}x of 50 ns, FSM step {:.2}x of 20 ns (below 1 is better)",
        action / 50.0,
        decision / 20.0
    );
    println!("action_ns={action:.1} fsm_step_ns={decision:.1} allocs_per_cycle={allocs}");
    Ok(())
}
