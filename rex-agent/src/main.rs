//! `rex`: the main job. Runs the whole Rex system (agents a1, a2, a3 and the
//! simulated platform) in the deterministic executor, shows progress, prints a
//! summary, writes a report folder, and ends with the line
//! `mission=… plans_acked=… rms_m=… max_m=… realtime_factor=…`.
//!
//! The command line is the application layer's (`embodied::app`): `--realtime`,
//! `--record`, `replay`, `--deployment D --process P`, `launch`, `check` and
//! `diagram` come with it; what is Rex's own is [`rex_agent::app`].

use std::process::ExitCode;

use embodied::app::Program;
use rex_agent::app::{ABOUT, RexApp};

fn main() -> ExitCode {
    embodied::app::main_with(
        RexApp::default(),
        Program {
            name: "rex",
            version: env!("CARGO_PKG_VERSION"),
            about: ABOUT,
        },
    )
}
