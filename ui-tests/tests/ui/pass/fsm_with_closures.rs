// Parts and predicates may be closures whose argument types the compiler infers.
#[path = "../common.rs"]
mod common;
use common::*;
use embodied::*;

fn main() -> Result<(), FsmBuildError> {
    let fsm = fsm! {
        subsystem Lamp;
        predicates { pressed, tired: |m, _| m.presses > 3 }
        relations { exclusive(pressed, tired) }
        while on until pressed || tired {
            lamp <- switch_on,
            memory <- |m, x| count(m, x),
        }
        repeat off until false { lamp <- |_, _, y| y.on.set(false) }
        initial on;
        on -> off;
    }?;
    assert_eq!(fsm.len(), 2);
    Ok(())
}
