// Two arcs may hold at once, and none may hold: the arc proof fails at compile time.
#[path = "../common.rs"]
mod common;
use common::*;
use embodied::*;

fn main() {
    let _ = fsm! {
        subsystem Lamp;
        predicates { pressed, tired: |m: &LampMemory, _: &LampInput| m.presses > 3 }
        repeat on until true { lamp <- switch_on, memory <- count }
        while off until false { }
        while rest until false { }
        initial on;
        on -> off when pressed;
        on -> rest when tired;
    };
}
