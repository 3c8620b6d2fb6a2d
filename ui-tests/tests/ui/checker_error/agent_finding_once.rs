// The spec's one error is in agent a2: a2's `agent!` reports it in full, a1's says
// in one line that there is an error elsewhere (so that a crate generating only a1
// does not compile a broken spec), and the code using the generated modules raises
// no further error.
mod a1 {
    embodied::agent!(spec = "mini_typo.ron", agent = "a1");
}
mod a2 {
    embodied::agent!(spec = "mini_typo.ron", agent = "a2");
}

fn fsm_of<F: a2::c2::Functions>() -> bool {
    a2::c2::fsm::<F>().is_ok()
}

struct C2;

impl a2::c2::Functions for C2 {
    fn send(_: &a2::c2::Memory, _: &a2::c2::Input, y: &mut a2::c2::ToC1) -> Result<(), embodied::ActionError> {
        y.order.set(1.0);
        Ok(())
    }
    fn acked(_: &a2::c2::Memory, x: &a2::c2::Input) -> bool {
        x.c1.ack.fresh() == Some(&true)
    }
}

fn main() {
    let _ = (a1::c1::NAME, a1::e1::PERIOD_MS, a2::c2::NAME, fsm_of::<C2>());
}
