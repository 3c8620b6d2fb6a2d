//! Running the `embodied` binary (the `cli` feature) as a user would, from
//! the workspace's root, so that paths like `specs/rex.ron` resolve.

use std::process::Command;

/// Runs `embodied args` in the workspace's root: its exit status (-1 when a
/// signal ended it), standard output and standard error.
pub(crate) fn embodied(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_embodied"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("the binary runs");
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}
