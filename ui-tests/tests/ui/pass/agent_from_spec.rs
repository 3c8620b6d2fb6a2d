// A subsystem generated from a spec, implemented and built.
use embodied::*;

embodied::agent!(spec = "../lamp.ron", agent = "house");

struct Lamp;

impl c1::Functions for Lamp {
    fn switch_on(_: &c1::Memory, _: &c1::Input, y: &mut c1::ToE1) -> Result<(), ActionError> {
        y.on.set(true);
        Ok(())
    }
    fn count(m: &mut c1::Memory, x: &c1::Input) -> Result<(), ActionError> {
        m.presses += u32::from(x.e1.pressed.fresh() == Some(&true));
        Ok(())
    }
    fn button(_: &c1::Memory, x: &c1::Input) -> bool {
        x.e1.pressed.fresh() == Some(&true)
    }
}

fn main() -> Result<(), FsmBuildError> {
    let fsm = c1::fsm::<Lamp>()?;
    assert_eq!(fsm.behaviour_name(fsm.initial()), "on");
    Ok(())
}
