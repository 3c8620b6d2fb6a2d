// An input struct holds groups (a subsystem's) or buffers (a driver's), not both.
use embodied::*;

#[derive(Default, Group)]
#[group(peer = Control)]
struct FromC {
    go: In<bool>,
}

#[derive(Default, Buffers)]
struct Input {
    c: FromC,
    level: In<f64>,
}

fn main() {}
