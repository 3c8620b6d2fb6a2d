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
use std::process::{Child, Command, Output, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::{Duration, Instant};

use embodied::distributed::security::{
    AccessPolicy, Credentials, Secured, common_name, create_dev_authority,
};
use embodied::distributed::zenoh::Session;
use embodied::distributed::zenoh::Wait;
use embodied::distributed::zenoh::pubsub::Subscriber;
use embodied::distributed::zenoh::sample::Sample;
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
fn tokens(session: &Session, enough: usize, wait: Duration) -> Vec<String> {
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

/// c1's plan input (c2's, in partners) and E1's torques (e11's, in
/// locomotion): what the intruders put on.
const PLAN_KEY: &str = "rex/a2/c2/c1/desired_plan";
const TORQUE_KEY: &str = "rex/a1/e11/E1/tau";

/// `who`'s certificate in `dir` and its access control.
fn secured(policy: &AccessPolicy, dir: &Path, who: &str) -> Secured {
    Secured {
        credentials: Credentials::in_dir(dir, who).unwrap(),
        acl: policy.acl(who).unwrap(),
    }
}

/// `rex launch` of `deployment` without the camera, on the ports from `port`,
/// with the processes' certificates in `certs`.
fn launch(deployment: &str, port: u16, mission: &Path, certs: &Path) -> Child {
    Command::new(env!("CARGO_BIN_EXE_rex"))
        .args(["launch", "--deployment", deployment, "--no-vo"])
        .args(["--quiet", "--no-report"])
        .args(["--port", &port.to_string(), "--limit", "90", "--mission"])
        .arg(mission)
        .arg("--credentials")
        .arg(certs)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Wait until `monitor` sees the three processes; if they are not up in 30 s,
/// stop the launch and fail with its output.
fn wait_until_up(launch: Child, monitor: &Session) -> Child {
    let seen = tokens(monitor, 3, Duration::from_secs(30));
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
    launch
}

/// Without a certificate (plain TCP to the TLS endpoints) and with one of
/// another authority (`stranger`, refused by mutual TLS), nothing of the
/// deployment is seen.
fn outsiders_see_nothing(port: u16, endpoints: &[&str], stranger: &Secured) {
    let plain: Vec<String> = (0..3)
        .map(|k| format!("tcp/127.0.0.1:{}", port + k))
        .collect();
    let plain: Vec<&str> = plain.iter().map(String::as_str).collect();
    let nobody = open_peer(None, &plain).unwrap();
    assert!(tokens(&nobody, 1, Duration::from_secs(2)).is_empty());
    drop(nobody);
    let stranger = open_secure_peer(None, endpoints, Some(stranger)).unwrap();
    assert!(tokens(&stranger, 1, Duration::from_secs(2)).is_empty());
    drop(stranger);
}

/// Intruders with valid certificates of other processes (clients: they take
/// no part in routing): world's at c1's process puts on c1's plan input,
/// partners' at the world's puts on E1's torques, and a spy with partners'
/// certificate subscribes to the torques at locomotion. A witness with
/// world's certificate (world reads the torques) hears them there: the spy's
/// silence is the access control's doing. Connected until dropped.
struct Intruders {
    at_c1: Session,
    at_e1: Session,
    /// The torques the spy and the witness heard.
    spied: Arc<AtomicU64>,
    heard: Arc<AtomicU64>,
    /// The spy's and the witness's subscriptions and sessions (a subscription is
    /// dropped before its session).
    _listening: [(Subscriber<()>, Session); 2],
}

impl Intruders {
    /// The intruders and the witness, with certificates from `certs`, at the
    /// world's and locomotion's endpoints.
    fn connect(policy: &AccessPolicy, certs: &Path, world: &str, locomotion: &str) -> Intruders {
        // The keys are the processes' own.
        let publishes = |p: &str, key: &str| policy.process(p).unwrap().publishes.contains(key);
        assert!(publishes("partners", PLAN_KEY));
        assert!(publishes("locomotion", TORQUE_KEY));
        let client = |at: &str, who: &str| {
            open_secure_client(&[at], Some(&secured(policy, certs, who))).unwrap()
        };
        let listen = |session: Session, n: &Arc<AtomicU64>| {
            let n = n.clone();
            let subscriber = session
                .declare_subscriber(TORQUE_KEY)
                .callback(move |_: Sample| {
                    n.fetch_add(1, Ordering::Relaxed);
                })
                .wait()
                .unwrap();
            (subscriber, session)
        };
        let (at_c1, at_e1) = (client(locomotion, "world"), client(world, "partners"));
        let (spy, witness) = (client(locomotion, "partners"), client(locomotion, "world"));
        let spied = Arc::new(AtomicU64::new(0));
        let heard = Arc::new(AtomicU64::new(0));
        let spying = listen(spy, &spied);
        let witnessing = listen(witness, &heard);
        Intruders {
            at_c1,
            at_e1,
            spied,
            heard,
            _listening: [spying, witnessing],
        }
    }

    /// 100 puts on each key, every 20 ms.
    fn put(&self) {
        for _ in 0..100 {
            self.at_c1.put(PLAN_KEY, vec![0xffu8; 64]).wait().unwrap();
            self.at_e1.put(TORQUE_KEY, vec![0xffu8; 64]).wait().unwrap();
            std::thread::sleep(Duration::from_millis(20));
        }
    }
}

/// Nothing reached c1 or E1: every plan achieved, and no link reported a
/// message it could not read (the intruders' bytes are no value of any type);
/// the only link errors are of the processes ending one after the other.
fn assert_untouched(out: &Output, stdout: &str, stderr: &str) {
    let last = stdout.lines().last().unwrap_or_default();
    assert!(out.status.success(), "{stdout}\n{stderr}");
    assert!(last.starts_with("mission=short plans_acked=2/2"), "{last}");
    let link_errors: Vec<&str> = stderr
        .lines()
        .filter(|l| l.contains("] rex: link `"))
        .collect();
    assert!(
        link_errors.iter().all(|l| l.ends_with(" is gone")),
        "{link_errors:#?}"
    );
}

/// The refusals are reported: by the processes that refused them, and in the
/// launcher's summary.
fn assert_refusals_reported(stdout: &str, stderr: &str) {
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
    for (process, key) in [("locomotion", PLAN_KEY), ("world", TORQUE_KEY)] {
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

    let launch = launch(deployment, port, &mission, &certs);
    // The launcher's credentials see the three processes (waiting for them
    // to be up).
    let launcher = secured(&policy, &certs, "launcher");
    let monitor = open_secure_peer(None, &endpoints, Some(&launcher)).unwrap();
    let launch = wait_until_up(launch, &monitor);
    outsiders_see_nothing(port, &endpoints, &secured(&policy, &foreign, "launcher"));
    let intruders = Intruders::connect(&policy, &certs, &world, &locomotion);
    intruders.put();

    let out = launch.wait_with_output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_untouched(&out, &stdout, &stderr);
    assert!(intruders.heard.load(Ordering::Relaxed) > 20);
    assert_eq!(intruders.spied.load(Ordering::Relaxed), 0);
    assert_refusals_reported(&stdout, &stderr);
}
