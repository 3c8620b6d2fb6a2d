// The blinking lamp of the guide's macros walk-through (docs/writing-an-agent.md,
// "In Rust with the macros"): c1 blinks, e1 ramps the brightness, E1 is the
// lamp. Built in code (no spec file): the application layer exports its spec from
// what was built. (Plain comments, not `//!`: the guide's examples `include!` this
// file.)

use embodied::*;

// c1, the blinker.
#[derive(Debug, Default, Clone, Memory)]
pub(crate) struct Count {
    pub(crate) actions: u32,
}

#[derive(Debug, Default, Group)]
#[group(peer = VirtualEffector)]
pub(crate) struct ToDimmer {
    on: Out<bool>,
}

#[derive(Debug, Default, Buffers)]
pub(crate) struct BlinkerOutput {
    e1: ToDimmer,
}

#[derive(Subsystem)]
#[subsystem(kind = Control, memory = Count, input = (), output = BlinkerOutput)]
pub(crate) struct Blinker;

fn switch_on(_: &Count, _: &(), y: &mut ToDimmer) {
    y.on.set(true)
}
fn switch_off(_: &Count, _: &(), y: &mut ToDimmer) {
    y.on.set(false)
}
fn count(n: &mut Count, _: &()) {
    n.actions += 1
}
fn three(n: &Count, _: &()) -> bool {
    n.actions.is_multiple_of(3)
}

// e1, the dimmer, between c1 and the lamp.
#[derive(Debug, Default, Memory)]
pub(crate) struct Level {
    pub(crate) brightness: f64,
}

#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub(crate) struct FromBlinker {
    on: In<bool>,
}

#[derive(Debug, Default, Buffers)]
pub(crate) struct DimmerInput {
    c1: FromBlinker,
}

#[derive(Debug, Default, Group)]
#[group(peer = RealEffector)]
pub(crate) struct ToLamp {
    brightness: Out<f64>,
}

#[derive(Debug, Default, Buffers)]
#[expect(
    non_snake_case,
    reason = "a group is named after its peer: the paper's E1"
)]
pub(crate) struct DimmerOutput {
    E1: ToLamp,
}

#[derive(Subsystem)]
#[subsystem(kind = VirtualEffector, memory = Level, input = DimmerInput, output = DimmerOutput)]
pub(crate) struct Dimmer;

/// Common part: the new brightness, a quarter step at a time.
fn ramp(l: &mut Level, x: &DimmerInput) {
    let target = if x.c1.on.get() == Some(&true) {
        1.0
    } else {
        0.0
    };
    l.brightness += (target - l.brightness).clamp(-0.25, 0.25);
}
fn drive(l: &Level, _: &DimmerInput, y: &mut ToLamp) {
    y.brightness.set(l.brightness)
}

// E1: the lamp, a real effector (simulated here).
#[derive(Default)]
pub(crate) struct Lamp {
    pub(crate) brightness: f64,
}

#[derive(Debug, Default, Group)]
#[group(peer = VirtualEffector)]
pub(crate) struct FromDimmer {
    brightness: In<f64>,
}

#[derive(Debug, Default, Buffers)]
pub(crate) struct LampInput {
    e1: FromDimmer,
}

impl Driver for Lamp {
    const KIND: DeviceKind = DeviceKind::Effector;
    type Input = LampInput;
    type Output = ();
    fn step(&mut self, _: DriverContext<'_>, x: &LampInput, _: &mut ()) -> Result<(), DriverError> {
        match x.e1.brightness.get() {
            Some(b) if b.is_finite() => self.brightness = b.clamp(0.0, 1.0),
            Some(b) => return Err(DriverError::new(format!("refusing brightness {b}"))),
            None => {}
        }
        Ok(())
    }
}

/// c1's FSM: three actions on, three off.
pub(crate) fn blinker() -> Result<Fsm<Blinker>, FsmBuildError> {
    fsm! {
        subsystem Blinker;
        predicates { three }
        repeat on until three { e1 <- switch_on, memory <- count }
        repeat off until three { e1 <- switch_off, memory <- count }
        initial on;
        on -> off;
        off -> on;
    }
}

/// e1's FSM: one behaviour that never ends.
pub(crate) fn dimmer() -> Result<Fsm<Dimmer>, FsmBuildError> {
    fsm! {
        subsystem Dimmer;
        while ramp until false { common <- ramp, E1 <- drive }
        initial ramp;
    }
}

/// The lamp's system: c1 every 100 ms, e1 and E1 every 10 ms.
pub(crate) fn system() -> Result<System, Box<dyn std::error::Error + Send + Sync>> {
    Ok(parts()?.system)
}

/// The lamp's system with the handles of its parts, to look at them in a run.
#[allow(
    dead_code,
    reason = "the guide's examples use the handles (docs/runtime.md)"
)]
pub(crate) struct Parts {
    pub(crate) system: System,
    pub(crate) c1: SubsystemHandle<Blinker>,
    pub(crate) e1: SubsystemHandle<Dimmer>,
    pub(crate) lamp: DriverHandle<Lamp>,
    /// e1's brightness to the lamp.
    pub(crate) brightness: LinkId,
}

/// [`system`], with the handles of its parts.
pub(crate) fn parts() -> Result<Parts, Box<dyn std::error::Error + Send + Sync>> {
    let (blinker, dimmer) = (blinker()?, dimmer()?);
    let mut sys = SystemBuilder::new();
    let a1 = sys.agent("a1");
    let c1 = sys.subsystem(
        a1,
        "c1",
        Period::from_millis(100)?,
        Count::default(),
        blinker,
    );
    let e1 = sys.subsystem(a1, "e1", Period::from_millis(10)?, Level::default(), dimmer);
    let lamp = sys.driver(a1, "E1", Period::from_millis(10)?, Lamp::default());
    sys.connect(
        c1.output(port!(BlinkerOutput, e1.on)),
        e1.input(port!(DimmerInput, c1.on)),
        Policy::Sample,
    );
    let brightness = sys.connect(
        e1.output(port!(DimmerOutput, E1.brightness)),
        lamp.input(port!(LampInput, e1.brightness)),
        Policy::Sample,
    );
    Ok(Parts {
        system: sys.build()?,
        c1,
        e1,
        lamp,
        brightness,
    })
}

/// A deployment of the lamp in two processes on this machine: the blinker
/// alone, the dimmer with the lamp (secure: the launch makes its certificates).
pub(crate) const SPLIT: &str = r#"(
    name: "split",
    hosts: [(name: "localhost", processes: [
        (name: "blinker", runs: ["c1"]),
        (name: "lamp", runs: ["e1", "E1"]),
    ])],
)"#;

/// The same two processes unprotected (asked for by name), so that one process
/// can be started alone, by hand, without the launch's certificates.
pub(crate) const OPEN: &str = r#"(
    name: "open",
    hosts: [(name: "localhost", processes: [
        (name: "blinker", runs: ["c1"]),
        (name: "lamp", runs: ["e1", "E1"]),
    ])],
    secure: false,
)"#;
