//! `rex ros2-package DIR`: the ROS 2 interface package of Rex's own messages
//! (`rex_msgs`), what a ROS 2 user builds with colcon to decode and publish
//! them. Offline: the files are written, one `.msg` per message, with the
//! definitions the bridge announces. With the interoperability environment
//! (`scripts/test`, which sets `EMBODIED_INTEROP_PYTHON`): rosbags reads the
//! package's `.msg` files as a ROS 2 tool would and computes, from them
//! alone, the type hash of every Rex message the bridge publishes or takes,
//! which must equal the hash in the bridge's keys.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

mod common;

use std::path::PathBuf;
use std::process::{Command, Output};

use common::bridge_plan;
use serde_json::{Value, json};

/// The root messages of Rex's own package among the bridge's topics, with
/// the type hash each key carries: `[name, hash]`.
fn own_roots() -> Vec<Value> {
    let (plan, _) = bridge_plan("square", true);
    let published = plan.topics.iter().map(|t| (&t.messages, &t.key));
    let taken = plan.subscriptions.iter().map(|t| (&t.messages, &t.key));
    published
        .chain(taken)
        .filter(|(m, _)| m.name().package == "rex_msgs")
        .map(|(m, key)| json!([m.name().to_string(), key.type_hash().to_string()]))
        .collect()
}

/// `command`'s output, once it has exited 0.
fn succeeded(command: &mut Command) -> Output {
    let out = command.output().unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    out
}

#[test]
fn the_package_holds_every_own_message_with_the_hashes_the_bridge_announces() {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("ros2_package");
    let _ = std::fs::remove_dir_all(&dir);
    let out = succeeded(
        Command::new(env!("CARGO_BIN_EXE_rex"))
            .arg("ros2-package")
            .arg(&dir),
    );
    let package = dir.join("rex_msgs");
    let listed: Vec<PathBuf> = String::from_utf8(out.stdout)
        .unwrap()
        .lines()
        .map(PathBuf::from)
        .collect();
    for file in [
        "package.xml",
        "CMakeLists.txt",
        "msg/Plan.msg",
        "msg/Ack.msg",
    ] {
        assert!(listed.contains(&package.join(file)), "{file}: {listed:?}");
    }
    let plan = std::fs::read_to_string(package.join("msg/Plan.msg")).unwrap();
    assert_eq!(plan, "uint32 id\nrex_msgs/Point2[] points\nuint32 first\n");
    let cmake = std::fs::read_to_string(package.join("CMakeLists.txt")).unwrap();
    assert!(cmake.contains("\"msg/Plan.msg\""), "{cmake}");
    let roots = own_roots();
    assert!(
        roots.iter().any(|r| r[0] == "rex_msgs/msg/Plan"),
        "the plan taken from ROS 2: {roots:?}"
    );

    let Some(python) = std::env::var_os("EMBODIED_INTEROP_PYTHON") else {
        eprintln!(
            "skipped the rosbags part: EMBODIED_INTEROP_PYTHON is not set (`scripts/test` installs rosbags and sets it)"
        );
        return;
    };
    let script = r#"
import json, pathlib, sys
from rosbags.typesys import Stores, get_typestore, get_types_from_msg
package, roots = pathlib.Path(sys.argv[1]), json.loads(sys.argv[2])
store = get_typestore(Stores.ROS2_KILTED)
types = {}
for msg in sorted((package / "msg").glob("*.msg")):
    types.update(get_types_from_msg(msg.read_text(), f"rex_msgs/msg/{msg.stem}"))
store.register(types)
print(json.dumps([[name, store.hash_rihs01(name)] for name, _ in roots]))
"#;
    let out = succeeded(
        Command::new(python)
            .args(["-c", script])
            .arg(&package)
            .arg(Value::Array(roots.clone()).to_string()),
    );
    let hashed: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(hashed, Value::Array(roots));
}
