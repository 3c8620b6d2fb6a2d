// The implementation forgets one function of the spec and misspells another.
use embodied::*;

embodied::agent!(spec = "../lamp.ron", agent = "house");

struct Lamp;

impl c1::Functions for Lamp {
    fn switch_of(_: &c1::Memory, _: &c1::Input, y: &mut c1::ToE1) -> Result<(), ActionError> {
        y.on.set(true);
        Ok(())
    }
    fn button(_: &c1::Memory, _: &c1::Input) -> bool {
        false
    }
}

fn main() {}
