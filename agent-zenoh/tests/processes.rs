//! Links between real processes over real Zenoh sessions on loopback.
//!
//! Each test starts this test binary again as the deployment's processes (the
//! environment variable `AGENT_ZENOH_ROLE` tells a child which process it is and
//! the test `child` runs it), so both sides are the code under test, in separate
//! address spaces, talking through Zenoh.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

mod common;

use std::process::{Command, Stdio};
use std::time::Duration;

use agent_core::*;
use agent_spec::model::Spec;
use agent_zenoh::{Member, Options};
use common::*;

const ROLE: &str = "AGENT_ZENOH_ROLE";

/// The counter `c` in process `p1`, the recorder `e` in process `p2`: on one
/// host (`two`), or on two hosts at the addresses of the network namespaces the
/// test makes (`hosts`).
fn spec(timeout_ms: u64) -> Spec {
    agent_spec::options()
        .from_str(&format!(
            r#"(name: "relay", agents: [], deployments: [
            (
                name: "two", timeout_ms: {timeout_ms}, secure: false,
                hosts: [(name: "local", processes: [(name: "p1", runs: ["c"]), (name: "p2", runs: ["e"])])],
            ),
            (
                name: "routed", timeout_ms: {timeout_ms}, router: "{ROUTER}", secure: false,
                hosts: [(name: "local", processes: [(name: "p1", runs: ["c"]), (name: "p2", runs: ["e"])])],
            ),
            (
                name: "hosts", timeout_ms: {timeout_ms}, secure: false,
                hosts: [
                    (name: "h1", address: "{A1}", processes: [(name: "p1", runs: ["c"])]),
                    (name: "h2", address: "{A2}", processes: [(name: "p2", runs: ["e"])]),
                ],
            ),
        ])"#
        ))
        .unwrap()
}

/// Where the deployment `routed` expects a router; none runs there.
const ROUTER: &str = "tcp/127.0.0.1:17559";
const A1: &str = "10.231.0.1";
const A2: &str = "10.231.0.2";

/// What a child prints on its last line: `e`'s values, or `c`'s echo count,
/// and the errors its executor met.
fn child_main(
    deployment: &str,
    process: &str,
    port: u16,
    limit_ms: u64,
    timeout_ms: u64,
    fingerprint_twist: bool,
) {
    let p = pair(2, 2, 1, Policy::queue(512), false);
    let system = if fingerprint_twist && process == "p2" {
        twisted_pair().system
    } else {
        p.system
    };
    let options = Options {
        port: Some(port),
        timeout: Some(Duration::from_millis(timeout_ms)),
        ..Options::default()
    };
    let mut member = match Member::join(&spec(timeout_ms), deployment, process, &options) {
        Ok(m) => m,
        Err(e) => {
            println!("error: {e}");
            std::process::exit(3);
        }
    };
    let rt = placed(system, &mut member);
    let mut origin = None;
    let running = match rt.start_when(Duration::from_millis(limit_ms), || {
        let zero = member.ready(Duration::from_millis(300));
        origin = zero.as_ref().ok().copied();
        zero
    }) {
        Ok(r) => r,
        Err(e) => {
            println!("error: {e}");
            std::process::exit(4);
        }
    };
    if let Some(t) = origin.and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok()) {
        use std::io::Write;
        println!("origin: {}", t.as_nanos());
        let _ = std::io::stdout().flush();
    }
    let f = running.join().unwrap();
    for e in &f.report().errors {
        println!("exec-error: {e}");
    }
    match process {
        "p2" if !fingerprint_twist => {
            let got: Vec<String> = f
                .memory(&p.e)
                .unwrap()
                .got
                .iter()
                .map(|g| g.1.to_string())
                .collect();
            println!("got: {}", got.join(","));
        }
        _ => println!("done"),
    }
}

/// The pair as another build would have it: `c.e.count` carries a `u32` (p1's
/// carries a `u64`). Only `e` runs in p2; `c` is there for the structure.
fn twisted_pair() -> Pair32 {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let idle = |name| Behaviour::while_loop(name, Action::<C32>::new(), "false");
    let c = b.subsystem(a, "c", ms(2), (), Fsm::single(idle("count")).unwrap());
    let e = b.subsystem(
        a,
        "e",
        ms(2),
        (),
        Fsm::single(Behaviour::while_loop(
            "record",
            Action::<E32>::new(),
            "false",
        ))
        .unwrap(),
    );
    b.connect(
        c.output(port!(C32Out, e.count)),
        e.input(port!(E32In, c.count)),
        Policy::queue(512),
    );
    b.connect(
        e.output(port!(E32Out, c.echo)),
        c.input(port!(CounterIn, e.echo)),
        Policy::Sample,
    );
    Pair32 {
        system: b.build().unwrap(),
    }
}

struct Pair32 {
    system: System,
}

struct C32;
#[derive(Debug, Default)]
struct C32ToE {
    count: Out<u32>,
}
impl Group for C32ToE {
    const PEER: NodeKind = NodeKind::VirtualEffector;
}
#[derive(Debug, Default)]
struct C32Out {
    e: C32ToE,
}
impl Subsystem for C32 {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = ();
    type Input = CounterIn;
    type Output = C32Out;
}

struct E32;
#[derive(Debug, Default, Clone)]
struct From32 {
    count: In<u32>,
}
impl Group for From32 {
    const PEER: NodeKind = NodeKind::Control;
}
#[derive(Debug, Default, Clone)]
struct E32In {
    c: From32,
}
#[derive(Debug, Default)]
struct E32Out {
    c: EchoToC,
}
impl Subsystem for E32 {
    const KIND: SubsystemKind = SubsystemKind::VirtualEffector;
    type Memory = ();
    type Input = E32In;
    type Output = E32Out;
}

#[test]
fn child() {
    let Ok(role) = std::env::var(ROLE) else {
        return; // not a child: nothing to do
    };
    let parts: Vec<&str> = role.split(',').collect();
    let [deployment, process, port, limit, timeout, twist] = parts[..] else {
        panic!("bad role {role}");
    };
    child_main(
        deployment,
        process,
        port.parse().unwrap(),
        limit.parse().unwrap(),
        timeout.parse().unwrap(),
        twist == "twist",
    );
    std::process::exit(0);
}

/// Start this binary as process `process` of the deployment `two`.
fn spawn(
    process: &str,
    port: u16,
    limit_ms: u64,
    timeout_ms: u64,
    twist: bool,
) -> std::process::Child {
    spawn_in(None, "two", process, port, limit_ms, timeout_ms, twist)
}

/// Start this binary as process `process` of `deployment`, in network
/// namespace `netns` if given.
fn spawn_in(
    netns: Option<&str>,
    deployment: &str,
    process: &str,
    port: u16,
    limit_ms: u64,
    timeout_ms: u64,
    twist: bool,
) -> std::process::Child {
    let exe = std::env::current_exe().unwrap();
    let mut command = match netns {
        Some(ns) => {
            let mut c = Command::new("ip");
            c.args(["netns", "exec", ns]).arg(&exe);
            c
        }
        None => Command::new(&exe),
    };
    command
        .args(["--exact", "child", "--nocapture", "--test-threads=1"])
        .env(
            ROLE,
            format!(
                "{deployment},{process},{port},{limit_ms},{timeout_ms},{}",
                if twist { "twist" } else { "plain" }
            ),
        )
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap()
}

fn output(child: std::process::Child) -> (i32, String) {
    let out = child.wait_with_output().unwrap();
    let text =
        String::from_utf8_lossy(&out.stdout).into_owned() + &String::from_utf8_lossy(&out.stderr);
    (out.status.code().unwrap_or(-1), text)
}

#[test]
fn a_queue_link_between_two_processes_carries_every_value_in_order() {
    let port = 17_450;
    let p1 = spawn("p1", port, 1_000, 10_000, false);
    let p2 = spawn("p2", port, 1_000, 10_000, false);
    assert_lossless(p1, p2);
}

/// p2 got every value p1 sent, in order, but those in flight at the end.
fn assert_lossless(p1: std::process::Child, p2: std::process::Child) {
    let (c1, out1) = output(p1);
    let (c2, out2) = output(p2);
    assert_eq!((c1, c2), (0, 0), "p1:\n{out1}\np2:\n{out2}");
    assert!(!out2.contains("exec-error"), "{out2}");
    let got: Vec<u64> = out2
        .lines()
        .find_map(|l| l.split_once("got: ").map(|(_, v)| v))
        .expect(&out2)
        .split(',')
        .filter(|s| !s.is_empty())
        .map(|s| s.parse().unwrap())
        .collect();
    // c counts every 2 ms for 1 s; the values still in flight at the end are
    // the only ones missing, and none is lost or reordered before them.
    assert!(got.len() > 400, "{} values: {got:?}", got.len());
    assert_eq!(got, (0..got.len() as u64).collect::<Vec<_>>());
}

#[test]
fn a_process_that_never_appears_is_named_in_a_timely_error() {
    let p1 = spawn("p1", 17_470, 1_000, 1_500, false);
    let (code, out) = output(p1);
    assert_ne!(code, 0, "{out}");
    assert!(
        out.contains("`p2`") && out.contains("tcp/127.0.0.1:17471"),
        "the error names the missing process and where it was expected:\n{out}"
    );
}

#[test]
fn a_router_that_is_down_is_named_and_the_processes_reach_each_other_without_it() {
    // Alone, a process says that neither its peer nor the router answers.
    let started = std::time::Instant::now();
    let p1 = spawn_in(None, "routed", "p1", 17_550, 1_000, 1_500, false);
    let (code, out) = output(p1);
    assert_ne!(code, 0, "{out}");
    assert!(
        out.contains("`p2`")
            && out.contains("tcp/127.0.0.1:17551")
            && out.contains(&format!("router at {ROUTER}, which is not reachable")),
        "the error names the missing process, its endpoint and the router:\n{out}"
    );
    assert!(started.elapsed() < Duration::from_secs(30), "no hang");
    // Together, they connect directly, as the spec's endpoints allow.
    let p1 = spawn_in(None, "routed", "p1", 17_560, 1_500, 10_000, false);
    let p2 = spawn_in(None, "routed", "p2", 17_560, 1_500, 10_000, false);
    assert_lossless(p1, p2);
}

#[test]
fn a_process_built_from_other_code_is_refused_with_a_message_that_says_so() {
    let port = 17_490;
    let p1 = spawn("p1", port, 800, 10_000, false);
    let p2 = spawn("p2", port, 800, 10_000, true);
    let (_, out1) = output(p1);
    let (_, out2) = output(p2);
    assert!(
        out2.contains("fingerprint") && out2.contains("built from different specs or code"),
        "p2:\n{out2}\np1:\n{out1}"
    );
    assert!(
        out2.contains("relay/a/c/e/count"),
        "the error names the key:\n{out2}"
    );
}

#[test]
fn a_process_that_vanishes_is_reported_on_the_links_it_fed() {
    let port = 17_510;
    let mut p1 = spawn("p1", port, 20_000, 10_000, false);
    let p2 = spawn("p2", port, 8_000, 10_000, false);
    // Both are up and running well before this; then p1 dies without a word.
    std::thread::sleep(Duration::from_millis(3_000));
    p1.kill().unwrap();
    let _ = p1.wait();
    let (_, out1) = output(p1);
    // p1 (the first process, which set instant zero) starts again: it joins the
    // running deployment at the instant zero p2 keeps announcing.
    let p1 = spawn("p1", port, 6_000, 10_000, false);
    let (code, again) = output(p1);
    assert_eq!(code, 0, "{again}");
    let (code, out) = output(p2);
    assert_eq!(code, 0, "{out}");
    assert!(
        out.contains("the sending process `p1` is gone") && out.contains("relay/a/c/e/count"),
        "p2 names the process and the key of the link it lost:\n{out}"
    );
    let origin = |text: &str| {
        text.lines()
            .find_map(|l| l.split("origin: ").nth(1))
            .map(str::to_owned)
            .unwrap_or_else(|| panic!("no origin in\n{text}"))
    };
    assert_eq!(origin(&out1), origin(&out), "p1 and p2 started together");
    assert_eq!(
        origin(&again),
        origin(&out),
        "the restarted p1 kept instant zero"
    );
    // And its values reached p2 again, a new count from its restart.
    let got = out
        .lines()
        .find_map(|l| l.strip_prefix("got: "))
        .unwrap_or_default();
    assert!(
        got.split(',').filter(|v| *v == "1").count() >= 2,
        "p2 got the restarted p1's values: {got}"
    );
}

/// Two network namespaces joined by a veth pair: two hosts on one machine.
/// Removed (with the pair) when dropped.
struct Hosts {
    names: [String; 2],
}

impl Hosts {
    fn make() -> Result<Hosts, String> {
        let tag = std::process::id() % 100_000;
        let names = [format!("ea-h1-{tag}"), format!("ea-h2-{tag}")];
        let (v1, v2) = (format!("ea1-{tag}"), format!("ea2-{tag}"));
        let hosts = Hosts {
            names: names.clone(),
        };
        let ip = |args: &[&str]| -> Result<(), String> {
            let out = Command::new("ip")
                .args(args)
                .output()
                .map_err(|e| format!("ip: {e}"))?;
            if out.status.success() {
                Ok(())
            } else {
                Err(format!(
                    "`ip {}`: {}",
                    args.join(" "),
                    String::from_utf8_lossy(&out.stderr).trim()
                ))
            }
        };
        ip(&["netns", "add", &names[0]])?;
        ip(&["netns", "add", &names[1]])?;
        ip(&["link", "add", &v1, "type", "veth", "peer", "name", &v2])?;
        for (ns, dev, addr) in [(&names[0], &v1, A1), (&names[1], &v2, A2)] {
            ip(&["link", "set", dev, "netns", ns])?;
            ip(&["-n", ns, "addr", "add", &format!("{addr}/24"), "dev", dev])?;
            ip(&["-n", ns, "link", "set", dev, "up"])?;
            ip(&["-n", ns, "link", "set", "lo", "up"])?;
        }
        Ok(hosts)
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        for ns in &self.names {
            let _ = Command::new("ip").args(["netns", "del", ns]).output();
        }
    }
}

#[test]
fn a_queue_link_between_two_hosts_carries_every_value_in_order() {
    let hosts = match Hosts::make() {
        Ok(h) => h,
        Err(why) => {
            println!("skipped: cannot make two hosts in network namespaces ({why}); run as root");
            return;
        }
    };
    let port = 17_530;
    let p1 = spawn_in(
        Some(&hosts.names[0]),
        "hosts",
        "p1",
        port,
        1_000,
        10_000,
        false,
    );
    let p2 = spawn_in(
        Some(&hosts.names[1]),
        "hosts",
        "p2",
        port,
        1_000,
        10_000,
        false,
    );
    assert_lossless(p1, p2);
}

#[test]
fn an_instant_zero_far_in_the_future_is_refused_not_waited_for() {
    use agent_zenoh::zenoh::Wait;
    // Something on p1's endpoint announces an instant zero an hour ahead (a
    // clock far off): p2 says so instead of sleeping an hour.
    let port = 17_580;
    let fake = agent_zenoh::open_peer(Some(&format!("tcp/127.0.0.1:{port}")), &[]).unwrap();
    let far = std::time::SystemTime::now() + Duration::from_secs(3600);
    let ns = far
        .duration_since(std::time::UNIX_EPOCH)
        .unwrap()
        .as_nanos();
    let _token = fake
        .liveliness()
        .declare_token(format!("relay/_rt/default/origin/{ns}"))
        .wait()
        .unwrap();
    let started = std::time::Instant::now();
    let (code, out) = output(spawn("p2", port, 1_000, 5_000, false));
    assert_ne!(code, 0, "{out}");
    assert!(
        out.contains("s in the future") && out.contains("clocks synchronised"),
        "{out}"
    );
    assert!(started.elapsed() < Duration::from_secs(60), "no hang");
}
