//! The blinking lamp of the README's macros walk-through ("In Rust with the
//! macros"): c1 blinks, e1 ramps the brightness, E1 is the lamp. Built in code
//! (no spec file): the application layer exports its spec from what was built.

use embodied::*;

// c1, the blinker.
#[derive(Debug, Default, Memory)]
pub(crate) struct Count {
    actions: u32,
}

#[derive(Debug, Default, Group)]
#[group(peer = VirtualEffector)]
pub(crate) struct ToDimmer {
    on: Out<bool>,
}

#[derive(Debug, Default, Buffers)]
pub(crate) struct BlinkerOutput {
    dimmer: ToDimmer,
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
    brightness: f64,
}

#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub(crate) struct FromBlinker {
    on: In<bool>,
}

#[derive(Debug, Default, Buffers)]
pub(crate) struct DimmerInput {
    blinker: FromBlinker,
}

#[derive(Debug, Default, Group)]
#[group(peer = RealEffector)]
pub(crate) struct ToLamp {
    brightness: Out<f64>,
}

#[derive(Debug, Default, Buffers)]
pub(crate) struct DimmerOutput {
    lamp: ToLamp,
}

#[derive(Subsystem)]
#[subsystem(kind = VirtualEffector, memory = Level, input = DimmerInput, output = DimmerOutput)]
pub(crate) struct Dimmer;

/// Common part: the new brightness, a quarter step at a time.
fn ramp(l: &mut Level, x: &DimmerInput) {
    let target = if x.blinker.on.get() == Some(&true) {
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
    brightness: f64,
}

#[derive(Debug, Default, Buffers)]
pub(crate) struct LampInput {
    brightness: In<f64>,
}

impl Driver for Lamp {
    const KIND: DeviceKind = DeviceKind::Effector;
    type Input = LampInput;
    type Output = ();
    fn shape() -> Option<Shape> {
        Some(Shape::of_driver::<Self>())
    }
    fn step(&mut self, _: DriverContext<'_>, x: &LampInput, _: &mut ()) -> Result<(), DriverError> {
        match x.brightness.get() {
            Some(b) if b.is_finite() => self.brightness = b.clamp(0.0, 1.0),
            Some(b) => return Err(DriverError::new(format!("refusing brightness {b}"))),
            None => {}
        }
        Ok(())
    }
}

/// The lamp's system: c1 every 100 ms, e1 and E1 every 10 ms.
pub(crate) fn system() -> Result<System, Box<dyn std::error::Error + Send + Sync>> {
    let blinker = fsm! {
        subsystem Blinker;
        predicates { three }
        repeat on until three { dimmer <- switch_on, memory <- count }
        repeat off until three { dimmer <- switch_off, memory <- count }
        initial on;
        on -> off;
        off -> on;
    }?;
    let dimmer = fsm! {
        subsystem Dimmer;
        while ramp until false { common <- ramp, lamp <- drive }
        initial ramp;
    }?;
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
        c1.output(port!(BlinkerOutput, dimmer.on)),
        e1.input(port!(DimmerInput, blinker.on)),
        Policy::Sample,
    );
    sys.connect(
        e1.output(port!(DimmerOutput, lamp.brightness)),
        lamp.input(port!(LampInput, brightness)),
        Policy::Sample,
    );
    Ok(sys.build()?)
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
