//! Rex's secure deployment `split_secure` and its ROS 2 side, against a
//! router and ROS 2 nodes we did not write: Eclipse Zenoh's Python API (PyPI
//! `eclipse-zenoh` 1.10.2, tests/access_interop.py) opens the router with the
//! configuration `agent_ros2::access` generates (as rmw_zenohd would, by
//! `ZENOH_ROUTER_CONFIG_URI`) and the ROS 2 nodes with the generated session
//! configuration (the certificate `ros2.pem`), all from development
//! credentials of the deployment's authority.
//!
//! The processes connect as the bridge does in a secure deployment
//! (`SessionOptions::tls_client`, each with its process's certificate). What
//! the spec allows flows: a plan from ROS 2 on `/rex/plan` reaches
//! `locomotion` (c1 subscribes to it); `locomotion`'s estimate and the
//! world's pose reach ROS 2; discovery tokens of both sides are seen. What it
//! does not is refused: ROS 2 putting on `/rex/pose` (the spec only publishes
//! it) or on a link key of the deployment, ROS 2 reading its own plans,
//! `locomotion` putting the world's pose, `vision` (no topic) putting or
//! announcing anything, and a client without a certificate of the authority
//! connecting at all. The router's log (Zenoh's access-control trace)
//! shows the refusals.
//!
//! `scripts/test -p agent-ros2 --test access_interop` installs the Python
//! client and sets `EMBODIED_INTEROP_PYTHON`; plain `cargo test` skips,
//! saying so.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

#[path = "interop/python.rs"]
mod python;
#[path = "interop/router.rs"]
mod router;
#[path = "interop/script.rs"]
mod script;

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::{Arc, Mutex};
use std::time::Duration;

use agent_ros2::access::{create_dev_credentials, write_router_config, write_session_config};
use agent_ros2::bridge::SessionOptions;
use agent_zenoh::security::Credentials;
use python::python;
use router::{Router, refusals};
use script::{Script, free_port};
use zenoh::Wait;

fn rex() -> agent_spec::model::Spec {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../specs/rex.ron");
    agent_spec::load(path, std::fs::read_to_string(path).unwrap())
        .unwrap()
        .spec
}

const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/access_interop.py");
const DEPLOYMENT: &str = "split_secure";

// rmw_zenoh's data keys: domain, topic, DDS type, type hash.
const PLAN: &str = "0/rex/plan/rex_msgs::msg::dds_::Plan_/RIHS01_00ff";
const POSE: &str = "0/rex/pose/geometry_msgs::msg::dds_::PoseStamped_/RIHS01_00ff";
const ESTIMATE: &str = "0/rex/estimate/rex_msgs::msg::dds_::Estimate_/RIHS01_00ff";
/// A link of the deployment: a2's plans to c1.
const LINK: &str = "rex/a2/c2/c1/desired_plan";

/// Discovery tokens as rmw_zenoh lays them out (a subscription of
/// `locomotion`'s node; a node of `vision`).
const LOCOMOTION_TOKEN: &str = "@ros2_lv/0/1a/0/1/MS/%/%/locomotion/%rex%plan/rex_msgs::msg::dds_::Plan_/RIHS01_00ff/::,10:,:,:,,";
const VISION_TOKEN: &str = "@ros2_lv/0/2b/0/0/NN/%/%/vision";

/// A session of process `process`, as its bridge opens it.
fn process_session(dir: &Path, process: &str, connect: &str) -> zenoh::Session {
    let credentials = Credentials::in_dir(dir, process).unwrap();
    SessionOptions::tls_client(connect, &credentials)
        .unwrap()
        .open()
        .unwrap()
}

/// What a subscriber received: (key, text).
type Received = Arc<Mutex<Vec<(String, String)>>>;

fn subscribe(
    session: &zenoh::Session,
    key: &str,
    into: &Received,
) -> zenoh::pubsub::Subscriber<()> {
    let into = into.clone();
    session
        .declare_subscriber(key)
        .callback(move |sample| {
            let text = String::from_utf8_lossy(&sample.payload().to_bytes()).into_owned();
            into.lock()
                .unwrap()
                .push((sample.key_expr().as_str().to_owned(), text));
        })
        .wait()
        .unwrap()
}

fn texts(received: &[(String, String)]) -> Vec<&str> {
    received.iter().map(|(_, t)| t.as_str()).collect()
}

#[test]
fn ros_2_feeds_and_reads_only_what_the_spec_says() {
    let Some(python) = python() else { return };
    let spec = rex();
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("access-interop");
    let _ = std::fs::remove_dir_all(&dir);
    create_dev_credentials(&dir, &spec, DEPLOYMENT, &[]).unwrap();
    let endpoint = format!("tls/127.0.0.1:{}", free_port());
    let router_config = write_router_config(&dir, &spec, DEPLOYMENT, &endpoint).unwrap();
    let session_config = write_session_config(&dir, &endpoint).unwrap();
    let router = Router::start(&python, SCRIPT, &router_config);

    // The processes, as their bridges connect.
    let locomotion = process_session(&dir, "locomotion", &endpoint);
    let world = process_session(&dir, "world", &endpoint);
    let vision = process_session(&dir, "vision", &endpoint);
    let plans: Received = Arc::default();
    // c1's input: the topic's keys, every type (as the inbound bridge
    // subscribes); and the link key, which is not the router's.
    let _plans = subscribe(&locomotion, "0/rex/plan/*/*", &plans);
    let _link = subscribe(&locomotion, LINK, &plans);
    let _token = locomotion
        .liveliness()
        .declare_token(LOCOMOTION_TOKEN)
        .wait()
        .unwrap();
    let _vision_token = vision
        .liveliness()
        .declare_token(VISION_TOKEN)
        .wait()
        .unwrap();

    // The ROS 2 nodes.
    let ca = dir.join("ca.pem").display().to_string();
    let puts = [
        format!("{PLAN}=plan from ros2"),
        format!("{POSE}=pose from ros2"),
        format!("{LINK}=link from ros2"),
    ];
    let mut nodes = Script::start(
        Command::new(&python)
            .args([SCRIPT, "ros2", "--config"])
            .arg(&session_config)
            .args(["--connect", &endpoint, "--anonymous-ca", &ca])
            .args(["--subscribe", "0/rex/pose/*/*"])
            .args(["--subscribe", "0/rex/estimate/*/*"])
            // Its own plans: not for it to read.
            .args(["--subscribe", "0/rex/plan/*/*"])
            .args(puts.iter().flat_map(|p| ["--put", p.as_str()]))
            .args(["--tokens", "@ros2_lv/0/**"]),
        "the ROS 2 nodes",
    );
    nodes.ready();
    // Let every declaration reach the router and the other sessions.
    std::thread::sleep(Duration::from_millis(1500));

    for _ in 0..3 {
        for (session, key, text) in [
            (&locomotion, ESTIMATE, "estimate from locomotion"),
            (&locomotion, POSE, "pose from locomotion"),
            (&world, POSE, "pose from world"),
            (&vision, PLAN, "plan from vision"),
            (&vision, POSE, "pose from vision"),
        ] {
            session.put(key, text).wait().unwrap();
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    let answer = nodes.end("go");
    // Let the last plans arrive.
    std::thread::sleep(Duration::from_millis(500));
    for s in [locomotion, world, vision] {
        s.close().wait().unwrap();
    }
    let log = router.stop();
    // Kept for a look: the router's access-control trace.
    std::fs::write(dir.join("router.log"), log.join("\n")).unwrap();

    // ROS 2 fed c1's plans: only its own, on the topic, not the link.
    let plans = plans.lock().unwrap().clone();
    let seen = texts(&plans);
    assert!(seen.contains(&"plan from ros2"), "{plans:?}");
    assert!(
        seen.iter().all(|t| *t == "plan from ros2"),
        "locomotion received what it must not: {plans:?}"
    );
    assert!(plans.iter().all(|(k, _)| k == PLAN), "{plans:?}");

    // ROS 2 read the estimate and the world's pose, nothing else.
    let received: Vec<(String, String)> =
        serde_json::from_value(answer["received"].clone()).unwrap();
    let seen = texts(&received);
    for expected in ["estimate from locomotion", "pose from world"] {
        assert!(seen.contains(&expected), "{expected}: {received:?}");
    }
    for refused in [
        "pose from ros2",
        "plan from ros2",
        "pose from locomotion",
        "pose from vision",
        "plan from vision",
    ] {
        assert!(!seen.contains(&refused), "{refused}: {received:?}");
    }

    // Discovery: locomotion's token seen, vision's refused.
    let tokens: Vec<String> = serde_json::from_value(answer["tokens"].clone()).unwrap();
    assert!(tokens.iter().any(|t| t == LOCOMOTION_TOKEN), "{tokens:?}");
    assert!(!tokens.iter().any(|t| t == VISION_TOKEN), "{tokens:?}");

    // No certificate of the authority, no session.
    let anonymous = answer["anonymous"].as_str().unwrap();
    assert!(anonymous.starts_with("refused"), "{anonymous}");

    // The router refused them, saying to whom: ROS 2's values of the pose
    // and of the link, and its subscription to its own plans; locomotion's
    // pose and its subscription to the link; vision, no subject, everything.
    let refusals = refusals(&log);
    let refused = |cn: &str, what: &str, key: &str| {
        refusals
            .iter()
            .any(|r| r.0.as_deref() == Some(cn) && r.1 == what && r.2 == key)
    };
    let (ros2, locomotion, world) = (
        common_name("ros2"),
        common_name("locomotion"),
        common_name("world"),
    );
    for (cn, what, key) in [
        (&ros2, "Put (ingress)", POSE),
        (&ros2, "Put (ingress)", LINK),
        (&ros2, "Declare Subscriber (ingress)", "0/rex/plan/*/*"),
        (&locomotion, "Put (ingress)", POSE),
        (&locomotion, "Declare Subscriber (ingress)", LINK),
    ] {
        assert!(refused(cn, what, key), "{cn} {what} {key}: {refusals:#?}");
    }
    assert!(
        refusals
            .iter()
            .any(|r| r.0.is_none() && r.1 == "Liveliness Token (ingress)" && r.2 == VISION_TOKEN),
        "{refusals:#?}"
    );
    // Never what the spec allows.
    for (cn, key) in [(&ros2, PLAN), (&locomotion, ESTIMATE), (&world, POSE)] {
        assert!(!refused(cn, "Put (ingress)", key), "{cn} {key}");
    }
}

fn common_name(process: &str) -> String {
    agent_zenoh::security::common_name("rex", DEPLOYMENT, process)
}
