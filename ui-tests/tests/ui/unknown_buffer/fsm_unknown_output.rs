// A part writes an output group the subsystem does not have.
#[path = "../common.rs"]
mod common;
use common::*;
use embodied::*;

fn main() {
    let _ = fsm! {
        subsystem Lamp;
        predicates { pressed }
        while on until pressed { lamps <- switch_on }
        repeat off until false { }
        initial on;
        on -> off;
    };
}
