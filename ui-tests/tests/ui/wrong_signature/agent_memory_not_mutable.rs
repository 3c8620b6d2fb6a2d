// A memory function of the spec implemented without `&mut` to the memory.
use embodied::*;

embodied::agent!(spec = "../lamp.ron", agent = "house");

struct Lamp;

impl c1::Functions for Lamp {
    fn switch_on(_: &c1::Memory, _: &c1::Input, y: &mut c1::ToE1) -> Result<(), ActionError> {
        y.on.set(true);
        Ok(())
    }
    fn count(_: &c1::Memory, _: &c1::Input) -> Result<(), ActionError> {
        Ok(())
    }
    fn button(_: &c1::Memory, _: &c1::Input) -> bool {
        false
    }
}

fn main() {}
