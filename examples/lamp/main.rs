//! The blinking lamp, built in code, with the whole command line of the
//! application layer in one call: `cargo run --example lamp --features
//! app,distributed -- --help` (see docs/application.md, "A system built in
//! code").

#[path = "lamp.rs"]
mod lamp;

pub(crate) fn main() -> std::process::ExitCode {
    embodied::app::App::from_code("lamp", lamp::system)
        .deployment(lamp::SPLIT)
        .deployment(lamp::OPEN)
        .main()
}
