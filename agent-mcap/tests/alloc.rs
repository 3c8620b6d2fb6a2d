//! Recording costs the executor's thread no allocation per value for `Copy`
//! payloads: it encodes each value into a batch of its own and hands whole
//! batches to the writer thread, which gives the buffers back to be reused.
//! A counting allocator watches only the executor's thread (the test's): a
//! recorded run allocates there at most once per batch (a new buffer when the
//! writer has none to give back yet), never per value; a run paced so that
//! the writer keeps up allocates nothing once the buffers circulate.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::sync::Mutex;
use std::time::Duration;

use agent_core::allocations::{CountingAllocator, count};
use agent_core::*;
use agent_mcap::record::{McapRecorder, RecordOptions};
use serde::{Deserialize, Serialize};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

/// One test at a time: the other's threads would take the CPU the writer
/// thread (in the background, `SCHED_IDLE`) needs to keep up.
static ONE_AT_A_TIME: Mutex<()> = Mutex::new(());

/// Allocations on this thread while `f` runs.
fn allocations<T>(f: impl FnOnce() -> T) -> (u64, T) {
    count(f).expect("the counting allocator is installed above")
}

/// A `Copy` payload: what a controller sends at 1 kHz.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
struct Wheels {
    left: f64,
    right: f64,
    seq: u32,
}

struct Controller;

#[derive(Debug, Default)]
struct ToE {
    wheels: Out<Wheels>,
    speed: Out<f64>,
}
impl Group for ToE {
    const PEER: NodeKind = NodeKind::VirtualEffector;
}

#[derive(Debug, Default)]
struct ControllerOut {
    e: ToE,
}

#[derive(Debug, Default, Clone)]
struct FromE {
    echo: In<u32>,
}
impl Group for FromE {
    const PEER: NodeKind = NodeKind::VirtualEffector;
}

#[derive(Debug, Default, Clone)]
struct ControllerIn {
    e: FromE,
}

impl Subsystem for Controller {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = u32;
    type Input = ControllerIn;
    type Output = ControllerOut;
}

struct Effector;

#[derive(Debug, Default, Clone)]
struct FromC {
    wheels: In<Wheels>,
    speed: In<f64>,
}
impl Group for FromC {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Debug, Default, Clone)]
struct EffectorIn {
    c: FromC,
}

#[derive(Debug, Default)]
struct ToC {
    echo: Out<u32>,
}
impl Group for ToC {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Debug, Default)]
struct EffectorOut {
    c: ToC,
}

impl Subsystem for Effector {
    const KIND: SubsystemKind = SubsystemKind::VirtualEffector;
    type Memory = ();
    type Input = EffectorIn;
    type Output = EffectorOut;
}

/// c sends e two `Copy` values every millisecond; e echoes the count back.
fn system() -> System {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let period = Period::from_millis(1).unwrap();
    let drive = Fsm::single(Behaviour::while_loop(
        "drive",
        Action::<Controller>::new()
            .output(
                |y| &mut y.e,
                |n: &u32, x: &ControllerIn, y: &mut ToE| {
                    let echo = x.e.echo.get().copied().unwrap_or(0);
                    let t = f64::from(*n) * 1e-3;
                    y.wheels.set(Wheels {
                        left: t.sin(),
                        right: t.cos(),
                        seq: *n,
                    });
                    y.speed.set(f64::from(echo) * 0.5);
                },
            )
            .memory(|n: &mut u32, _: &ControllerIn| *n += 1),
        "false",
    ))
    .unwrap();
    let act = Fsm::single(Behaviour::while_loop(
        "act",
        Action::<Effector>::new().output(
            |y| &mut y.c,
            |_: &(), x: &EffectorIn, y: &mut ToC| {
                y.echo.set(x.c.wheels.get().map_or(0, |w| w.seq));
            },
        ),
        "false",
    ))
    .unwrap();
    let c = b.subsystem(a, "c", period, 0u32, drive);
    let e = b.subsystem(a, "e", period, (), act);
    b.connect(
        c.output(port!(ControllerOut, e.wheels)),
        e.input(port!(EffectorIn, c.wheels)),
        Policy::Sample,
    );
    b.connect(
        c.output(port!(ControllerOut, e.speed)),
        e.input(port!(EffectorIn, c.speed)),
        Policy::Sample,
    );
    b.connect(
        e.output(port!(EffectorOut, c.echo)),
        c.input(port!(ControllerIn, e.echo)),
        Policy::Sample,
    );
    b.build().unwrap()
}

fn recorder(name: &str, s: &System) -> McapRecorder {
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    McapRecorder::create(&path, s, RecordOptions::default()).unwrap()
}

/// The executor's own allocations over 20 s of the system, unrecorded: the
/// baseline a recording adds to.
fn plain() -> u64 {
    let mut exec = Executor::new(system(), ExecConfig::default());
    exec.run_for(Duration::from_secs(1)).unwrap();
    allocations(|| exec.run_for(Duration::from_secs(20)).unwrap()).0
}

#[test]
fn a_recorded_run_allocates_at_most_once_a_batch_on_the_executors_thread() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let s = system();
    let recorder = recorder("alloc_fast.mcap", &s);
    let mut exec = Executor::with_observer(s, ExecConfig::default(), recorder);
    exec.run_for(Duration::from_secs(1)).unwrap();
    // 20 s as fast as the executor goes: 20,000 iterations of each node,
    // 60,000 transfers and as many reads, more than a writer thread can keep
    // up with, so some batches find no buffer to reuse.
    let (recorded, ()) = allocations(|| exec.run_for(Duration::from_secs(20)).unwrap());
    let summary = exec.into_observer().finish().unwrap();
    let base = plain();
    let values = 2 * 60_000;
    // The batches carry about 200 bytes a millisecond (three transfers and
    // three reads, 29 bytes of entry each, and the values): about 63 batches
    // of 64 KiB in 20 s, each at most one new buffer made at its full size
    // (55 measured). The bound, values / 1,000 = 120, leaves a margin of two;
    // one allocation per value would be 120,000, and buffers grown value by
    // value (as before this test) 873.
    assert!(
        recorded <= base + values / 1_000,
        "{recorded} allocations recorded, {base} plain, for {values} values; {summary:?}"
    );
    assert!(summary.messages > 60_000, "{summary:?}");
}

#[test]
fn a_paced_recorded_run_allocates_nothing_on_the_executors_thread_once_warm() {
    let _one = ONE_AT_A_TIME.lock().unwrap_or_else(|e| e.into_inner());
    let s = system();
    let recorder = recorder("alloc_paced.mcap", &s);
    let mut exec = Executor::with_observer(s, ExecConfig::default(), recorder);
    // Paced in steps of 200 ms of the system's time, each followed by a wait
    // until the writer has caught up, as it does in a real-time run: a batch
    // (about 320 ms of the system) finds the buffer the writer gave back.
    let step = |exec: &mut Executor<McapRecorder>| {
        exec.run_for(Duration::from_millis(200)).unwrap();
        let t = std::time::Instant::now();
        while exec.observer().backlog_bytes() > 0 {
            assert!(t.elapsed() < Duration::from_secs(60), "the writer is stuck");
            std::thread::sleep(Duration::from_millis(1));
        }
    };
    for _ in 0..20 {
        step(&mut exec);
    }
    let base = plain();
    let (recorded, ()) = allocations(|| {
        for _ in 0..50 {
            step(&mut exec);
        }
    });
    let summary = exec.into_observer().finish().unwrap();
    assert!(
        recorded <= base,
        "{recorded} allocations in 10 s recorded, {base} in 20 s plain; {summary:?}"
    );
}
