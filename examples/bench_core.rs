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
//! * The same three figures for the same pair and chooser written with the macros
//!   (`#[derive(Group, Buffers, Memory, Subsystem)]` and `fsm!`), measured in
//!   alternating batches with the hand-written ones, and the ratio macro/hand:
//!   `macro_action_ns=<..> macro_fsm_step_ns=<..> macro_allocs_per_cycle=<..>
//!   macro_over_hand_action=<..> macro_over_hand_fsm_step=<..>`. The macros add no
//!   dispatch or allocation: the ratios are 1 within the noise.
//!
//! * The monitors of Rex's contracts (specs/rex.ron: freshness, rates, a
//!   behaviour bound, the four torque ranges, a response, c2's invariant over
//!   the predicates the executor evaluates after each of its activations)
//!   watching a system with Rex's names, links, payload types and predicates
//!   where those contracts read
//!   (c1, e11, the platform E1, c2, c3, on one period: this crate cannot build
//!   Rex itself), as every run with a spec's contracts watches it: run without
//!   and with the watch in alternating batches, `monitor_ns_per_cycle` is the
//!   difference of their medians per cycle (5 actions), including what the
//!   executor does for an observer; `monitor_cost_ratio` is that cost per
//!   action over `action_ns` (the aim is 0.05; the median of 5 alternating
//!   runs 0.170 once a range on an array of numbers was checked by index
//!   rather than walked, from 0.249 before on an Intel Xeon guest; of 9,
//!   0.130 once the rates read the executor's table of last sends, from
//!   0.184 before; of 11, 0.204 once the ports and nodes kept what their observer needs, from
//!   0.259 before on the same busy host; of 9, 0.183 once the watch was told
//!   only the activations that change a monitor, from 0.263 before, 0.37 before the freshness and ranges were
//!   judged in the links, 0.48 before each event visited only the monitors it
//!   concerns and 1.38 before the ranges read the typed value: not yet the
//!   aim); `monitor_allocs_per_cycle` the watched cycles' allocations (0);
//!   `monitor_events_ns_per_cycle` what the same events cost an observer that
//!   judges nothing, run alongside (about a quarter of the watch's cost, 0.09
//!   of an action by itself: the floor of any observer called per event).
//!   The section is [`monitor`]. `timing_check_ms`: the median time of
//!   `embodied check --timing specs/rex.ron`'s work in process (load and check
//!   the spec, analyse its timing, write the certificate), over 21 runs.
//!
//! Medians over batches of 20 000 instants (40 000 actions); the last line reads
//! `action_ns=<..> fsm_step_ns=<..> allocs_per_cycle=<..>` (hand-written).

use std::hint::black_box;
use std::time::{Duration, Instant};

use embodied::*;
use serde::{Deserialize, Serialize};

#[path = "bench_core/monitor.rs"]
mod monitor;

use monitor::{REX_ACTIONS_PER_CYCLE, monitor_cost};

/// Counts every thread's allocations ([`allocations::total`]).
#[global_allocator]
static GLOBAL: allocations::CountingAllocator = allocations::CountingAllocator;

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

// ---------------------------------------------------------------------------
// The same pair and chooser, written with the macros.

mod with_macros {
    use embodied::*;

    use super::Pose;

    macro_rules! group {
        ($name:ident, $peer:ident, $kind:ident) => {
            #[derive(Debug, Default, Group)]
            #[group(peer = $peer)]
            pub(super) struct $name {
                pub(super) a: $kind<f64>,
                pub(super) b: $kind<Pose>,
                pub(super) c: $kind<u64>,
            }
        };
    }
    group!(CtoE, VirtualEffector, Out);
    group!(CfromE, VirtualEffector, In);
    group!(EtoC, Control, Out);
    group!(EfromC, Control, In);

    #[derive(Debug, Default, Buffers)]
    pub(super) struct COut {
        pub(super) e: CtoE,
    }
    #[derive(Debug, Default, Buffers)]
    pub(super) struct CIn {
        pub(super) e: CfromE,
    }
    #[derive(Debug, Default, Buffers)]
    pub(super) struct EOut {
        pub(super) c: EtoC,
    }
    #[derive(Debug, Default, Buffers)]
    pub(super) struct EIn {
        pub(super) c: EfromC,
    }

    #[derive(Debug, Default, Memory)]
    pub(super) struct Count {
        n: u64,
    }

    #[derive(Subsystem)]
    #[subsystem(kind = Control, memory = Count, input = CIn, output = COut)]
    pub(super) struct Ctl;

    #[derive(Subsystem)]
    #[subsystem(kind = VirtualEffector, memory = Count, input = EIn, output = EOut)]
    pub(super) struct Eff;

    fn command(m: &Count, x: &CIn, y: &mut CtoE) {
        let a = x.e.a.get().copied().unwrap_or(0.0);
        let p = x.e.b.get().copied().unwrap_or_default();
        y.a.set(a + 1.0);
        y.b.set(Pose {
            x: p.x + 0.5,
            y: p.y,
            phi: a,
        });
        y.c.set(m.n);
    }

    fn count_parity(m: &mut Count, x: &CIn) {
        m.n += x.e.c.get().copied().unwrap_or(1) & 1;
    }

    fn answer(m: &Count, x: &EIn, y: &mut EtoC) {
        y.a.set(x.c.a.get().copied().unwrap_or(0.0) * 0.5);
        y.b.set(x.c.b.get().copied().unwrap_or_default());
        y.c.set(m.n + 1);
    }

    fn tick(m: &mut Count, _: &EIn) {
        m.n += 1;
    }

    pub(super) fn pair() -> Result<System, Box<dyn std::error::Error>> {
        let period = Period::from_millis(1)?;
        let mut b = SystemBuilder::new();
        let a = b.agent("bench");
        let ctl = fsm! {
            subsystem Ctl;
            while run until false { e <- command, memory <- count_parity }
            initial run;
        }?;
        let eff = fsm! {
            subsystem Eff;
            while run until false { c <- answer, memory <- tick }
            initial run;
        }?;
        let c = b.subsystem(a, "c", period, Count::default(), ctl);
        let e = b.subsystem(a, "e", period, Count::default(), eff);
        let queue = Policy::queue(4);
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
        b.connect(c.output(port!(COut, e.c)), e.input(port!(EIn, c.c)), queue);
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
        b.connect(e.output(port!(EOut, c.c)), c.input(port!(CIn, e.c)), queue);
        Ok(b.build()?)
    }

    #[derive(Debug, Default, Memory)]
    pub(super) struct Tick {
        pub(super) n: u64,
    }

    #[derive(Subsystem)]
    #[subsystem(kind = Control, memory = Tick, input = (), output = ())]
    pub(super) struct Chooser;

    fn done(m: &Tick, _: &()) -> bool {
        m.n < u64::MAX
    }

    fn odd(m: &Tick, _: &()) -> bool {
        m.n & 1 == 1
    }

    pub(super) fn chooser_fsm() -> Result<Fsm<Chooser>, FsmBuildError> {
        fsm! {
            subsystem Chooser;
            predicates { done, odd }
            while a until done { }
            while b until done { }
            while c until done { }
            initial a;
            a -> b when odd;
            a -> c when !odd;
            b -> c when odd;
            b -> a when !odd;
            c -> a when odd;
            c -> b when !odd;
        }
    }
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

/// Elementary actions of one executor, batch by batch.
struct ActionBench {
    exec: Executor,
    warm_up: u64,
    action_ns: Vec<f64>,
    allocations: u64,
    cycles: u64,
}

impl ActionBench {
    fn new(system: System) -> Result<ActionBench, ExecError> {
        let mut exec = Executor::new(system, ExecConfig::default());
        exec.run_for(Duration::from_millis(BATCH))?; // warm-up: buffers and queues filled
        let warm_up = exec.report().instants;
        Ok(ActionBench {
            exec,
            warm_up,
            action_ns: Vec::with_capacity(BATCHES),
            allocations: 0,
            cycles: 0,
        })
    }

    fn batch(&mut self) -> Result<(), ExecError> {
        let before = allocations::total();
        let start = Instant::now();
        for _ in 0..BATCH {
            self.exec.step()?;
        }
        let elapsed = start.elapsed();
        self.allocations += allocations::total() - before;
        self.cycles += BATCH;
        self.action_ns
            .push(elapsed.as_nanos() as f64 / (ACTIONS_PER_CYCLE * BATCH) as f64);
        Ok(())
    }

    /// Median ns per action and allocations per cycle, after checking that every
    /// measured instant ran without error.
    fn result(self) -> Result<(f64, f64, u64), Box<dyn std::error::Error>> {
        let report = self.exec.report();
        let executed = report.instants - self.warm_up;
        if executed != self.cycles || report.error_count != 0 {
            return Err(format!(
                "expected {} error-free instants, the executor ran {executed} ({} errors)",
                self.cycles, report.error_count
            )
            .into());
        }
        Ok((
            median(self.action_ns),
            self.allocations as f64 / self.cycles as f64,
            self.allocations,
        ))
    }
}

/// One batch of FSM decisions that each end a behaviour: ns per decision.
fn fsm_batch<S: Subsystem<Input = ()>>(
    fsm: &Fsm<S>,
    state: &mut FsmState,
    memory: &mut S::Memory,
    bump: fn(&mut S::Memory),
) -> Result<f64, FsmError> {
    let start = Instant::now();
    for _ in 0..BATCH {
        bump(memory);
        let step = fsm.step(state, black_box(&*memory), &())?;
        black_box(step);
    }
    Ok(start.elapsed().as_nanos() as f64 / BATCH as f64)
}

/// Rex's spec: its contracts are watched, its timing analysed.
const REX_SPEC: &str = include_str!("../specs/rex.ron");
/// Runs of the check and timing analysis of Rex's spec.
const TIMING_RUNS: usize = 21;

/// Median wall time of `embodied check --timing specs/rex.ron`'s work, in
/// process: load and check the spec, analyse its timing, write the certificate.
fn timing_check_ms() -> Result<f64, Box<dyn std::error::Error>> {
    let mut ms = Vec::with_capacity(TIMING_RUNS);
    for _ in 0..TIMING_RUNS {
        let start = Instant::now();
        let loaded = embodied::spec::load("specs/rex.ron", REX_SPEC).map_err(|r| r.short())?;
        let report = embodied::spec::check(&loaded);
        let analysis = embodied::spec::timing::analyse(&loaded.spec, loaded.index.as_ref(), None)?;
        black_box((report.errors(), analysis.to_string()));
        ms.push(start.elapsed().as_secs_f64() * 1e3);
    }
    Ok(median(ms))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // Elementary actions in the executor: hand-written and macro-built pairs in
    // alternating batches, so that both see the same machine state.
    let mut hand = ActionBench::new(pair()?)?;
    let mut macros = ActionBench::new(with_macros::pair()?)?;
    for _ in 0..BATCHES {
        hand.batch()?;
        macros.batch()?;
    }
    let cycles = hand.cycles;
    let actions = ACTIONS_PER_CYCLE * cycles;
    let (action, allocs, allocations) = hand.result()?;
    let (macro_action, macro_allocs, _) = macros.result()?;

    // FSM decisions, alternating likewise.
    let (fsm, macro_fsm) = (chooser_fsm()?, with_macros::chooser_fsm()?);
    let (mut state, mut macro_state) = (fsm.start(), macro_fsm.start());
    let (mut m, mut macro_m) = (0u64, with_macros::Tick::default());
    let (mut fsm_ns, mut macro_fsm_ns) = (Vec::new(), Vec::new());
    for _ in 0..BATCHES {
        fsm_ns.push(fsm_batch(&fsm, &mut state, &mut m, |m| {
            *m = m.wrapping_add(1)
        })?);
        macro_fsm_ns.push(fsm_batch(
            &macro_fsm,
            &mut macro_state,
            &mut macro_m,
            |m| m.n = m.n.wrapping_add(1),
        )?);
    }
    let (decision, macro_decision) = (median(fsm_ns), median(macro_fsm_ns));

    println!(
        "{cycles} cycles = {actions} actions per pair ({BATCHES} batches of {BATCH} instants, \
         {ACTIONS_PER_CYCLE} actions each), {allocations} allocations in them (hand-written), \
         {} FSM decisions each",
        BATCHES as u64 * BATCH
    );
    println!(
        "macro_action_ns={macro_action:.1} macro_fsm_step_ns={macro_decision:.1} \
         macro_allocs_per_cycle={macro_allocs} macro_over_hand_action={:.3} \
         macro_over_hand_fsm_step={:.3}",
        macro_action / action,
        macro_decision / decision
    );
    // Rex's contracts watched, and its timing analysed.
    let cost = monitor_cost()?;
    let per_action = cost.watch_ns / REX_ACTIONS_PER_CYCLE as f64;
    let timing_ms = timing_check_ms()?;
    println!(
        "Rex's contracts: {} judged, {} violated; Rex-shaped cycle ({REX_ACTIONS_PER_CYCLE} actions) \
         {:.1} ns unwatched, the watch adds {:.1} ns per action",
        cost.judged, cost.violated, cost.plain_ns, per_action
    );
    println!(
        "monitor_ns_per_cycle={:.1} monitor_cost_ratio={:.3} monitor_allocs_per_cycle={} \
         monitor_events_ns_per_cycle={:.1} timing_check_ms={timing_ms:.2}",
        cost.watch_ns,
        per_action / action,
        cost.allocs_per_cycle,
        cost.events_ns
    );
    println!(
        "against the targets: action {:.2}x of 50 ns, FSM step {:.2}x of 20 ns (below 1 is better)",
        action / 50.0,
        decision / 20.0
    );
    println!("action_ns={action:.1} fsm_step_ns={decision:.1} allocs_per_cycle={allocs}");
    Ok(())
}
