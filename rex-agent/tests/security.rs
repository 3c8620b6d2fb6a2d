//! A secure deployment of Rex (`split_secure`): mutual TLS between its
//! processes and an access control list generated from the spec. Real
//! processes, real Zenoh sessions: intruders without a certificate, with one
//! of another authority, and with a valid certificate of another process try
//! to connect, to publish c1's plan input and e1,1's torques, and to subscribe
//! to the torques; nothing reaches c1 or E1, the mission completes, and the
//! refusals are reported.

#![cfg(feature = "distributed")]
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use embodied::distributed::security::{
    AccessPolicy, Credentials, Secured, common_name, create_dev_authority,
};
use embodied::distributed::zenoh::Wait;
use embodied::distributed::{open_peer, open_secure_client, open_secure_peer};
use embodied::spec::model::Spec;
use rex_agent::mission::Mission;
use rex_agent::system::{RexConfig, build_deployment, load_spec};
use rex_agent::world::WorldConfig;

fn spec_path() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../specs/rex.ron")
}

fn spec() -> Spec {
    load_spec(&spec_path()).unwrap()
}

fn tmp(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR")).join(name);
    std::fs::create_dir_all(&d).unwrap();
    d
}

#[test]
fn the_generated_access_control_is_the_specs_wiring() {
    let spec = spec();
    let policy = AccessPolicy::of(&spec, "split_secure").unwrap();
    // Every link between two processes of the deployment, as the runtime
    // keys it: published by its sender's process, subscribed by its
    // receiver's, and no other key.
    let mut config = RexConfig::new(
        WorldConfig::shipped().unwrap(),
        Mission::shipped("figure_eight").unwrap(),
    );
    config.spec = spec_path();
    let (system, _) = build_deployment(&config, "split_secure").unwrap();
    let info = system.info();
    let process_of = |node: &str| {
        ["world", "locomotion", "vision"]
            .into_iter()
            .find(|p| {
                spec.deployments
                    .iter()
                    .find(|d| d.name == "split_secure")
                    .unwrap()
                    .processes()
                    .iter()
                    .any(|(_, q, _)| q.name == *p && q.runs.iter().any(|r| r == node))
            })
            .unwrap()
    };
    let mut expected: std::collections::BTreeMap<&str, (Vec<String>, Vec<String>)> =
        Default::default();
    for link in &info.links {
        let (a, b) = (
            process_of(&info.nodes[link.from].name),
            process_of(&info.nodes[link.to].name),
        );
        if a == b {
            continue;
        }
        let key = embodied::link::remote::link_key("rex", info, link);
        expected.entry(a).or_default().0.push(key.clone());
        expected.entry(b).or_default().1.push(key);
    }
    for p in ["world", "locomotion", "vision"] {
        let access = policy.process(p).unwrap();
        let (mut publishes, mut subscribes) = expected.remove(p).unwrap();
        publishes.sort();
        publishes.dedup();
        subscribes.sort();
        subscribes.dedup();
        assert_eq!(
            access.publishes.iter().cloned().collect::<Vec<_>>(),
            publishes,
            "{p}"
        );
        assert_eq!(
            access.subscribes.iter().cloned().collect::<Vec<_>>(),
            subscribes,
            "{p}"
        );
        assert_eq!(access.common_name, common_name("rex", "split_secure", p));
    }
    // The configuration locomotion's Zenoh gets, whole.
    insta::assert_json_snapshot!("acl_locomotion", policy.acl("locomotion").unwrap());
}

#[test]
fn moving_a_component_to_another_process_moves_its_rights() {
    let mut spec = spec();
    let before = AccessPolicy::of(&spec, "split_secure").unwrap();
    // r11 from `vision` to `locomotion`.
    let dep = spec
        .deployments
        .iter_mut()
        .find(|d| d.name == "split_secure")
        .unwrap();
    for p in dep.hosts.iter_mut().flat_map(|h| &mut h.processes) {
        p.runs.retain(|r| r != "r11");
        if p.name == "locomotion" {
            p.runs.push("r11".into());
        }
    }
    let after = AccessPolicy::of(&spec, "split_secure").unwrap();
    let vo_motion = "rex/a1/r11/c1/A4x4";
    let camera = before
        .process("vision")
        .unwrap()
        .subscribes
        .iter()
        .find(|k| k.starts_with("rex/a1/R1/"))
        .cloned()
        .expect("vision reads the camera");
    // r11's output to c1 is now inside locomotion: nobody publishes it.
    assert!(
        before
            .process("vision")
            .unwrap()
            .publishes
            .contains(vo_motion)
    );
    assert!(
        before
            .process("locomotion")
            .unwrap()
            .subscribes
            .contains(vo_motion)
    );
    for p in &after.processes {
        assert!(!p.publishes.contains(vo_motion), "{}", p.name);
        assert!(!p.subscribes.contains(vo_motion), "{}", p.name);
    }
    // The camera's images now go to locomotion, and vision has nothing left.
    assert!(
        after
            .process("locomotion")
            .unwrap()
            .subscribes
            .contains(&camera)
    );
    let vision = after.process("vision").unwrap();
    assert!(vision.publishes.is_empty() && vision.subscribes.is_empty());
    insta::assert_json_snapshot!("acl_locomotion_with_r11", after.acl("locomotion").unwrap());
}

/// Liveliness tokens of the deployment's processes that `session` sees
/// within `wait` (once it sees `enough`).
fn tokens(
    session: &embodied::distributed::zenoh::Session,
    enough: usize,
    wait: Duration,
) -> Vec<String> {
    let start = Instant::now();
    loop {
        let mut seen = Vec::new();
        if let Ok(replies) = session
            .liveliness()
            .get("rex/_rt/*/process/**")
            .timeout(Duration::from_millis(300))
            .wait()
        {
            while let Ok(r) = replies.recv() {
                if let Ok(s) = r.result() {
                    seen.push(s.key_expr().as_str().to_owned());
                }
            }
        }
        if seen.len() >= enough || start.elapsed() >= wait {
            return seen;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

const MISSION: &str = r#"(
    name: "short",
    plans: [[(x: 1.0, y: 0.0), (x: 1.5, y: 0.5)], [(x: 1.0, y: 1.0), (x: 0.0, y: 1.0)]],
)"#;

#[test]
fn intruders_reach_nothing_and_the_secure_mission_completes() {
    // Without the camera (its images through TLS in a debug build load the
    // machine more than this test needs), the partner agents in a process of
    // their own: world (E1, R3), partners (c2, c3, r31), locomotion (c1, e11).
    let deployment = "split_secure_without_vo";
    let dir = tmp("secure");
    let spec = spec();
    let policy = AccessPolicy::of(&spec, deployment).unwrap();
    let certs = dir.join("certs");
    create_dev_authority(&certs, &policy, &[]).unwrap();
    // Another authority's certificates, with the same names.
    let foreign = dir.join("foreign");
    create_dev_authority(&foreign, &policy, &[]).unwrap();
    let mission = dir.join("short.ron");
    std::fs::write(&mission, MISSION).unwrap();
    let port: u16 = 17930;
    // world, partners, locomotion.
    let endpoint = |k: u16| format!("quic/127.0.0.1:{}", port + k);
    let (world, locomotion) = (endpoint(0), endpoint(2));
    let endpoints = [endpoint(0), endpoint(1), endpoint(2)];
    let endpoints: Vec<&str> = endpoints.iter().map(String::as_str).collect();

    let launch = Command::new(env!("CARGO_BIN_EXE_rex"))
        .args(["launch", "--deployment", deployment, "--no-vo"])
        .args(["--quiet", "--no-report"])
        .args(["--port", &port.to_string(), "--limit", "90", "--mission"])
        .arg(&mission)
        .arg("--credentials")
        .arg(&certs)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();

    let secured = |dir: &Path, who: &str| Secured {
        credentials: Credentials::in_dir(dir, who).unwrap(),
        acl: policy.acl(who).unwrap(),
    };
    // The launcher's credentials see the three processes (waiting for them
    // to be up).
    let monitor = open_secure_peer(None, &endpoints, Some(&secured(&certs, "launcher"))).unwrap();
    let seen = tokens(&monitor, 3, Duration::from_secs(30));
    if seen.len() != 3 {
        let mut launch = launch;
        let _ = launch.kill();
        let out = launch.wait_with_output().unwrap();
        panic!(
            "the deployment is not up: {seen:?}\n{}\n{}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }

    // No certificate: plain TCP to the TLS endpoints reaches nobody.
    let plain: Vec<String> = (0..3)
        .map(|k| format!("tcp/127.0.0.1:{}", port + k))
        .collect();
    let plain: Vec<&str> = plain.iter().map(String::as_str).collect();
    let nobody = open_peer(None, &plain).unwrap();
    assert!(tokens(&nobody, 1, Duration::from_secs(2)).is_empty());
    drop(nobody);
    // A certificate of another authority: refused by mutual TLS.
    let stranger =
        open_secure_peer(None, &endpoints, Some(&secured(&foreign, "launcher"))).unwrap();
    assert!(tokens(&stranger, 1, Duration::from_secs(2)).is_empty());
    drop(stranger);

    // Intruders with valid certificates of other processes (clients: they take
    // no part in routing): world's at c1's process puts on c1's plan input
    // (c2's, in partners), partners' at the world's puts on E1's torques (e11's,
    // in locomotion), and a spy with partners' certificate subscribes to the
    // torques at locomotion. A witness with world's certificate (world reads
    // the torques) hears them there: the spy's silence is the access control's
    // doing.
    let plan_key = "rex/a2/c2/c1/desired_plan";
    let torque_key = "rex/a1/e11/E1/tau";
    assert!(
        policy
            .process("partners")
            .unwrap()
            .publishes
            .contains(plan_key)
    );
    assert!(
        policy
            .process("locomotion")
            .unwrap()
            .publishes
            .contains(torque_key)
    );
    let client =
        |at: &str, who: &str| open_secure_client(&[at], Some(&secured(&certs, who))).unwrap();
    let at_c1 = client(&locomotion, "world");
    let at_e1 = client(&world, "partners");
    let spy = client(&locomotion, "partners");
    let witness = client(&locomotion, "world");
    let counter = |n: &std::sync::Arc<std::sync::atomic::AtomicU64>| {
        let n = n.clone();
        move |_: embodied::distributed::zenoh::sample::Sample| {
            n.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        }
    };
    let spied = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let _spy = spy
        .declare_subscriber(torque_key)
        .callback(counter(&spied))
        .wait()
        .unwrap();
    let heard = std::sync::Arc::new(std::sync::atomic::AtomicU64::new(0));
    let _witness = witness
        .declare_subscriber(torque_key)
        .callback(counter(&heard))
        .wait()
        .unwrap();
    for _ in 0..100 {
        at_c1.put(plan_key, vec![0xffu8; 64]).wait().unwrap();
        at_e1.put(torque_key, vec![0xffu8; 64]).wait().unwrap();
        std::thread::sleep(Duration::from_millis(20));
    }

    let out = launch.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    let last = stdout.lines().last().unwrap_or_default();
    assert!(out.status.success(), "{stdout}\n{stderr}");
    // Nothing reached c1 or E1: every plan achieved, and no link reported a
    // message it could not read (the intruders' bytes are no value of any
    // type); the only link errors are of the processes ending one after the
    // other.
    assert!(last.starts_with("mission=short plans_acked=2/2"), "{last}");
    let link_errors: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("] rex: link `"))
        .collect();
    assert!(
        link_errors.iter().all(|l| l.ends_with(" is gone")),
        "{link_errors:#?}"
    );
    assert!(heard.load(std::sync::atomic::Ordering::Relaxed) > 20);
    assert_eq!(spied.load(std::sync::atomic::Ordering::Relaxed), 0);
    // The refusals are reported: by the processes that refused them, and in
    // the launcher's summary.
    let refused = stdout
        .lines()
        .find(|l| l.starts_with("security acl_refused="))
        .unwrap_or_else(|| panic!("no refusals reported:\n{stdout}\n{stderr}"));
    let n: u64 = refused["security acl_refused=".len()..]
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(n > 0, "{refused}");
    // Each intruder put once (the first decides the key's permissions as Zenoh
    // caches them, which is not counted); a process names every refused one.
    for (process, key) in [("locomotion", plan_key), ("world", torque_key)] {
        let prefix = format!("[{process}] rex: the access control refused ");
        let named: u64 = stderr
            .lines()
            .filter(|l| l.contains("Put (ingress)") && l.contains(key))
            .filter_map(|l| {
                l.strip_prefix(&prefix)?
                    .split(" x ")
                    .next()?
                    .parse::<u64>()
                    .ok()
            })
            .sum();
        assert!(
            (99..=100).contains(&named),
            "{process} names {named} refused puts on {key}:\n{stderr}"
        );
    }
}
