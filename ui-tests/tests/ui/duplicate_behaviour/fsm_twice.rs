// Two behaviours with one name.
#[path = "../common.rs"]
mod common;
use common::*;
use embodied::*;

fn main() {
    let _ = fsm! {
        subsystem Lamp;
        predicates { pressed }
        while on until pressed { lamp <- switch_on }
        repeat on until false { }
        initial on;
        on -> on;
    };
}
