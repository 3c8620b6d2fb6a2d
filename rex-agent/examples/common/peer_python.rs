//! The Python the benches run their peers with: a virtual environment the
//! benches make in `target/peer-venv` the first time, with each bench's
//! packages installed into it when its import fails.

use std::path::{Path, PathBuf};
use std::process::Command;

/// `target/peer-venv`'s Python, in which `import` (for example
/// `"import cv2, numpy"`) succeeds, installing `packages` with pip when it
/// does not yet.
pub(crate) fn peer_python(import: &str, packages: &[&str]) -> Result<PathBuf, String> {
    let venv = PathBuf::from("target/peer-venv");
    let python = venv.join("bin/python");
    let imports = |p: &Path| {
        Command::new(p)
            .args(["-c", import])
            .output()
            .is_ok_and(|o| o.status.success())
    };
    if imports(&python) {
        return Ok(python);
    }
    if !python.exists() {
        eprintln!("making {} (once)", venv.display());
        let made = Command::new("python3")
            .args(["-m", "venv"])
            .arg(&venv)
            .status()
            .map_err(|e| format!("python3 -m venv: {e}"))?;
        if !made.success() {
            return Err("python3 -m venv failed".into());
        }
    }
    eprintln!(
        "installing {} into {} (once)",
        packages.join(" "),
        venv.display()
    );
    let pip = Command::new(&python)
        .args(["-m", "pip", "install", "--quiet"])
        .args(packages)
        .status()
        .map_err(|e| format!("pip: {e}"))?;
    if !pip.success() || !imports(&python) {
        return Err(format!("pip install {} failed", packages.join(" ")));
    }
    Ok(python)
}

/// Run `script` with `python`; what it wrote to `out` (removed afterwards), or
/// its error output.
#[allow(
    dead_code,
    reason = "bench_vo shares this file and runs its peer with arguments of its own"
)]
pub(crate) fn run_script(python: &Path, script: &str, out: &Path) -> Result<String, String> {
    let run = Command::new(python)
        .args(["-c", script])
        .output()
        .map_err(|e| format!("{}: {e}", python.display()))?;
    if !run.status.success() {
        return Err(String::from_utf8_lossy(&run.stderr).trim().to_owned());
    }
    let text = std::fs::read_to_string(out).map_err(|e| format!("{}: {e}", out.display()))?;
    std::fs::remove_file(out).map_err(|e| format!("{}: {e}", out.display()))?;
    Ok(text)
}
