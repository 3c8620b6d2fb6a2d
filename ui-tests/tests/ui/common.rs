// A small subsystem shared by the UI tests: a lamp controller that switches a lamp
// on until a button is pressed.
use embodied::*;

#[derive(Debug, Default, Memory)]
pub struct LampMemory {
    pub on: bool,
    pub presses: u32,
}

#[derive(Debug, Default, Clone, Group)]
#[group(peer = VirtualReceptor)]
pub struct FromButton {
    pub pressed: In<bool>,
}

#[derive(Debug, Default, Clone, Buffers)]
pub struct LampInput {
    pub button: FromButton,
}

#[derive(Debug, Default, Group)]
#[group(peer = VirtualEffector)]
pub struct ToLamp {
    pub on: Out<bool>,
}

#[derive(Debug, Default, Buffers)]
pub struct LampOutput {
    pub lamp: ToLamp,
}

#[derive(Subsystem)]
#[subsystem(kind = Control, memory = LampMemory, input = LampInput, output = LampOutput)]
pub struct Lamp;

pub fn switch_on(_: &LampMemory, _: &LampInput, y: &mut ToLamp) {
    y.on.set(true);
}

pub fn count(m: &mut LampMemory, x: &LampInput) {
    if x.button.pressed.fresh() == Some(&true) {
        m.presses += 1;
    }
}

pub fn pressed(_: &LampMemory, x: &LampInput) -> bool {
    x.button.pressed.fresh() == Some(&true)
}
