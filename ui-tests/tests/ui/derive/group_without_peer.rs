// A group must say what kind of component is at its other end.
use embodied::*;

#[derive(Default, Group)]
struct ToLamp {
    on: Out<bool>,
}

fn main() {}
