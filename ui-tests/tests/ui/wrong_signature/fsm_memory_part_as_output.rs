// A memory function used as an output part: the signature does not fit.
#[path = "../common.rs"]
mod common;
use common::*;
use embodied::*;

fn main() {
    let _ = fsm! {
        subsystem Lamp;
        predicates { pressed }
        while on until pressed { lamp <- count }
        repeat off until false { }
        initial on;
        on -> off;
    };
}
