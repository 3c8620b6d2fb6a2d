// A driver is described by its types: its input and output structs derive `Buffers`
// (or are `()`), which gives the driver its shape and ports. Forgetting the derive
// is a compile error at the type, not a driver missing from exported specs.
use embodied::*;

#[derive(Default)]
struct Command {
    flow: In<f64>,
}

struct Pump;

impl Driver for Pump {
    const KIND: DeviceKind = DeviceKind::Effector;
    type Input = Command;
    type Output = ();
    fn step(&mut self, _: DriverContext<'_>, _: &Command, _: &mut ()) -> Result<(), DriverError> {
        Ok(())
    }
}

fn main() {}
