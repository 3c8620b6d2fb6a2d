//! The interpreter of the interoperability environment: `scripts/test`
//! installs the Python clients of tests/interop/requirements.txt (Eclipse
//! Zenoh, rosbags, the official ROS 2 message wheels, ...) in a virtual
//! environment and names its interpreter in `EMBODIED_INTEROP_PYTHON`.
//!
//! Shared by the ROS 2 interoperability tests of agent-ros2 and rex-agent,
//! each including it with `#[path]`.

use std::path::PathBuf;

/// The interpreter of the interoperability environment, if installed; if
/// not, the test says it is skipped (plain `cargo test` stays offline).
pub(crate) fn python() -> Option<PathBuf> {
    let python = std::env::var_os("EMBODIED_INTEROP_PYTHON").map(PathBuf::from);
    if python.is_none() {
        eprintln!(
            "skipped: EMBODIED_INTEROP_PYTHON is not set (`scripts/test` installs the Python clients of tests/interop/requirements.txt and sets it)"
        );
    }
    python
}
