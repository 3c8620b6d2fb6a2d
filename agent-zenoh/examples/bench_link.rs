//! One hop of a 64-byte buffer: in-process, between threads, and between two
//! processes over Zenoh on loopback, beside raw Zenoh publish/subscribe and
//! ROS 2 messages over rmw_zenoh between the same two processes in the same
//! run.
//!
//! `cargo run --release -p agent-zenoh --example bench_link`
//!
//! * `inproc_ns`: an instant of the deterministic executor in which one node
//!   writes the buffer and another reads it (two activations and the hop).
//! * `thread_us`, `zenoh_us`, `raw_zenoh_us`: half a round trip (ping, then
//!   pong sent back on receipt), each side polling its end (yielding between
//!   polls), so the figure is the link's and not a period's. `zenoh_us` goes
//!   through the framework's links between processes (header, fingerprint and
//!   sequence checks, postcard, the receiving inbox); `raw_zenoh_us` through
//!   bare Zenoh publishers and subscribers on the same sessions' settings.
//!
//! * `zenoh_secure_us`: `zenoh_us` between two other processes whose sessions
//!   use mutual TLS and the access control a secure deployment gets
//!   ([`agent_zenoh::security`]: each side may publish only its own keys and
//!   subscribe only to the other's).
//!
//! * `ros2_us`: the same half round trip as ROS 2 messages over rmw_zenoh,
//!   between the processes of `zenoh_us` on the same sessions ("publish to
//!   decode"). Each side sends through agent-ros2's bridge as it runs: the
//!   bridge's observer (postcard bytes into its wait-free ring, its
//!   publishing thread woken), that thread (CDR with the 4-byte header, the
//!   33-byte attachment, a put on the topic's data key); the other side takes
//!   the sample from a subscriber to that key and decodes the attachment, the
//!   CDR (`read_cdr`) and the postcard bytes into the value. `zenoh_us`
//!   includes the counterparts: our link's outbox ring and publishing thread
//!   (postcard and header, a put), and on receipt the inbox's checks and
//!   postcard. `ros2_over_zenoh` is the ratio of their p50s.
//!
//! The Zenoh figures alternate in rounds of 1000 so that the machine's drift
//! affects them alike. With two cores or more, this process (both pings) runs
//! on the first and the echo processes on the second: a round trip between
//! two processes on one core and one between two cores differ widely, and left
//! to the scheduler, the plain and the secure pair did not always get the same
//! placement (docs/measurements.md, "Pinning bench_link's processes").
//! The last line is the figures line.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a benchmark: a failure ends it"
)]

use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use agent_core::link::endpoint::{self, Receiver, Sender};
use agent_core::prelude::*;
use agent_core::trace::{Observer, TransferEvent};
use agent_ros2::bridge::{Adapters, Bridge, BridgeOptions, Plan};
use agent_ros2::wire::Attachment;
use agent_zenoh::security::{
    AccessPolicy, Credentials, LAUNCHER, ProcessAccess, Secured, common_name, create_dev_authority,
};
use agent_zenoh::zenoh::Wait;
use agent_zenoh::{ZenohTransport, open_secure_peer};

type Payload64 = [u64; 8];

const ROUNDS: usize = 20;
const PER_ROUND: usize = 1000;
const PORT: u16 = 17_600;
const SECURE_PORT: u16 = 17_601;

fn stamp(i: usize) -> Stamp {
    Stamp::new(i as u64, Time::ZERO)
}

fn spin<T>(mut f: impl FnMut() -> Option<T>) -> T {
    loop {
        if let Some(v) = f() {
            return v;
        }
        std::thread::yield_now();
    }
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

// ---------------------------------------------------------------------------
// In-process: a writer and a reader in the deterministic executor.

struct Writer;
#[derive(Debug, Default)]
struct ToReader {
    data: Out<Payload64>,
}
impl Group for ToReader {
    const PEER: NodeKind = NodeKind::VirtualEffector;
}
#[derive(Debug, Default)]
struct WriterOut {
    r: ToReader,
}
impl Subsystem for Writer {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = u64;
    type Input = ();
    type Output = WriterOut;
}

struct Reader;
#[derive(Debug, Default, Clone)]
struct FromWriter {
    data: In<Payload64>,
}
impl Group for FromWriter {
    const PEER: NodeKind = NodeKind::Control;
}
#[derive(Debug, Default, Clone)]
struct ReaderIn {
    w: FromWriter,
}
impl Subsystem for Reader {
    const KIND: SubsystemKind = SubsystemKind::VirtualEffector;
    type Memory = u64;
    type Input = ReaderIn;
    type Output = ();
}

fn inproc_ns() -> Vec<f64> {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let period = Period::from_millis(1).unwrap();
    let write = Action::<Writer>::new()
        .output(
            |y| &mut y.r,
            |m: &u64, _: &(), y: &mut ToReader| y.data.set([*m; 8]),
        )
        .memory(|m: &mut u64, _: &()| *m += 1);
    let read = Action::<Reader>::new().memory(|m: &mut u64, x: &ReaderIn| {
        if let Some(v) = x.w.data.fresh() {
            *m = m.wrapping_add(v[7]);
        }
    });
    let w = b.subsystem(
        a,
        "w",
        period,
        0,
        Fsm::single(Behaviour::while_loop("write", write, "false")).unwrap(),
    );
    let r = b.subsystem(
        a,
        "r",
        period,
        0,
        Fsm::single(Behaviour::while_loop("read", read, "false")).unwrap(),
    );
    b.connect(
        w.output(port!(WriterOut, r.data)),
        r.input(port!(ReaderIn, w.data)),
        Policy::Sample,
    );
    let mut exec = Executor::new(b.build().unwrap(), ExecConfig::default());
    let mut out = Vec::with_capacity(ROUNDS * PER_ROUND);
    for _ in 0..1000 {
        exec.step().unwrap();
    }
    for _ in 0..ROUNDS * PER_ROUND {
        let t = Instant::now();
        exec.step().unwrap();
        out.push(t.elapsed().as_nanos() as f64);
    }
    out
}

// ---------------------------------------------------------------------------
// Between threads.

fn thread_us() -> Vec<f64> {
    let (mut ping_tx, mut ping_rx) = endpoint::between_threads::<Payload64>(Policy::queue(4));
    let (mut pong_tx, mut pong_rx) = endpoint::between_threads::<Payload64>(Policy::queue(4));
    let n = ROUNDS * PER_ROUND;
    let echo = std::thread::spawn(move || {
        for i in 0..n {
            let v = spin(|| ping_rx.recv().unwrap().copied());
            pong_tx.send(v, stamp(i)).unwrap();
        }
    });
    let mut out = Vec::with_capacity(n);
    for i in 0..n {
        let t = Instant::now();
        ping_tx.send([i as u64; 8], stamp(i)).unwrap();
        let v = spin(|| pong_rx.recv().unwrap().copied());
        assert_eq!(v[0], i as u64);
        out.push(t.elapsed().as_secs_f64() * 1e6 / 2.0);
    }
    echo.join().unwrap();
    out
}

// ---------------------------------------------------------------------------
// Between processes.

struct Ours {
    tx: Sender<Payload64>,
    rx: Receiver<Payload64>,
}

struct Raw {
    publisher: agent_zenoh::zenoh::pubsub::Publisher<'static>,
    subscriber: agent_zenoh::zenoh::pubsub::Subscriber<
        agent_zenoh::zenoh::handlers::FifoChannelHandler<agent_zenoh::zenoh::sample::Sample>,
    >,
}

fn ends(session: &agent_zenoh::zenoh::Session, send: &str, recv: &str) -> (Ours, Raw) {
    let mut transport = ZenohTransport::new(session.clone(), "bench");
    let policy = Policy::queue(64);
    let ours = Ours {
        tx: endpoint::to_processes(&mut transport, &format!("bench/{send}"), policy).unwrap(),
        rx: endpoint::from_process(&mut transport, &format!("bench/{recv}"), policy).unwrap(),
    };
    let raw = Raw {
        publisher: session
            .declare_publisher(format!("raw/{send}"))
            .congestion_control(agent_zenoh::zenoh::qos::CongestionControl::Block)
            .express(true)
            .wait()
            .unwrap(),
        subscriber: session
            .declare_subscriber(format!("raw/{recv}"))
            .wait()
            .unwrap(),
    };
    (ours, raw)
}

fn raw_recv(raw: &Raw) -> Option<Vec<u8>> {
    raw.subscriber
        .try_recv()
        .ok()
        .flatten()
        .map(|s| s.payload().to_bytes().into_owned())
}

// ---------------------------------------------------------------------------
// ROS 2 over rmw_zenoh: the bridge's publishing path, a subscriber's decoding.

/// The value of the ROS 2 hop: `Payload64` (the same postcard bytes) in a
/// struct, so that its message has a name: `bench_msgs/msg/Ping64`.
#[derive(Clone, Debug, Default, serde::Serialize, serde::Deserialize)]
struct Ping64 {
    values: Payload64,
}

struct Pinger;
#[derive(Debug, Default)]
struct ToPonger {
    ping: Out<Ping64>,
}
impl Group for ToPonger {
    const PEER: NodeKind = NodeKind::VirtualEffector;
}
#[derive(Debug, Default)]
struct PingerOut {
    q: ToPonger,
}
impl Subsystem for Pinger {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = ();
    type Input = ();
    type Output = PingerOut;
}

struct Ponger;
#[derive(Debug, Default, Clone)]
struct FromPinger {
    ping: In<Ping64>,
}
impl Group for FromPinger {
    const PEER: NodeKind = NodeKind::Control;
}
#[derive(Debug, Default, Clone)]
struct PongerIn {
    p: FromPinger,
}
impl Subsystem for Ponger {
    const KIND: SubsystemKind = SubsystemKind::VirtualEffector;
    type Memory = ();
    type Input = PongerIn;
    type Output = ();
}

/// The system whose link `p.q.ping` the bridge publishes (it never runs:
/// the bridge takes its plan from it, and values through its observer).
fn ros_system() -> System {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let period = Period::from_millis(1).unwrap();
    let go = Fsm::single(Behaviour::while_loop(
        "go",
        Action::<Pinger>::new(),
        "false",
    ));
    let keep = Fsm::single(Behaviour::while_loop(
        "keep",
        Action::<Ponger>::new(),
        "false",
    ));
    let p = b.subsystem(a, "p", period, (), go.unwrap());
    let q = b.subsystem(a, "q", period, (), keep.unwrap());
    b.connect(
        p.output(port!(PingerOut, q.ping)),
        q.input(port!(PongerIn, p.ping)),
        Policy::queue(64),
    );
    b.build().unwrap()
}

/// The plan publishing `p.q.ping` on topic `/<topic>` from node `<topic>`.
fn ros_plan(system: &System, topic: &str) -> Plan {
    let text = format!(
        r#"(
    name: "bench",
    agents: [(name: "a", subsystems: [
        (name: "p", kind: Control, period_ms: 1.0,
         outputs: [(peer: "q", buffers: [(name: "ping", type: "Ping64")])],
         behaviours: [(name: "go", kind: While, terminal: "false")], fsm: (initial: "go")),
        (name: "q", kind: VirtualEffector, period_ms: 1.0,
         inputs: [(peer: "p", buffers: [(name: "ping", type: "Ping64")])],
         behaviours: [(name: "keep", kind: While, terminal: "false")], fsm: (initial: "keep")),
    ])],
    links: [(from: "p.q.ping", to: "q.p.ping", policy: Queue(64))],
    ros2: (node: "{topic}", publish: [(buffer: "p.q.ping", topic: "{topic}")]),
)"#
    );
    let spec = agent_spec::options().from_str(&text).unwrap();
    Plan::new(&spec, None, system, &Adapters::new()).unwrap()
}

/// One end of the ROS 2 hop: a bridge publishing on `/<send>` (its observer,
/// ring and publishing thread) and a subscriber to `/<recv>`'s data key.
struct Ros {
    bridge: Bridge,
    link: usize,
    shape: agent_core::TypeShape,
    subscriber: agent_zenoh::zenoh::pubsub::Subscriber<
        agent_zenoh::zenoh::handlers::FifoChannelHandler<agent_zenoh::zenoh::sample::Sample>,
    >,
    /// The postcard bytes of the value being decoded.
    bytes: Vec<u8>,
}

fn ros_ends(session: &agent_zenoh::zenoh::Session, send: &str, recv: &str) -> Ros {
    let system = ros_system();
    let plan = ros_plan(&system, send);
    let link = plan.topics[0].link;
    let key = ros_plan(&system, recv).topics[0].key.to_string();
    let subscriber = session.declare_subscriber(key).wait().unwrap();
    let options = BridgeOptions::default();
    Ros {
        bridge: Bridge::on_session(plan, session.clone(), &options).unwrap(),
        link,
        shape: system.payload_shape(link).unwrap(),
        subscriber,
        bytes: Vec::new(),
    }
}

impl Ros {
    /// Publish `v` as the bridge publishes a value sent into its link.
    fn send(&mut self, v: Payload64, i: usize) {
        let event = TransferEvent {
            link: self.link,
            stamp: stamp(i),
        };
        self.bridge.transfer(&event, &Ping64 { values: v });
    }

    /// The next value received, if any: its attachment and CDR decoded.
    fn recv(&mut self) -> Option<Payload64> {
        let sample = self.subscriber.try_recv().ok().flatten()?;
        let attachment = sample.attachment().expect("rmw_zenoh's attachment");
        let attachment = Attachment::decode(&attachment.to_bytes()).unwrap();
        assert!(attachment.sequence_number > 0);
        self.bytes.clear();
        agent_mcap::cdr::read_cdr(&self.shape, &sample.payload().to_bytes(), &mut self.bytes)
            .unwrap();
        Some(postcard::from_bytes::<Ping64>(&self.bytes).unwrap().values)
    }
}

/// The policy of the two benchmark processes: `main` pings, `echo` pongs.
fn policy() -> AccessPolicy {
    let keys = |a: &str| {
        [format!("bench/{a}"), format!("raw/{a}")]
            .into_iter()
            .collect::<std::collections::BTreeSet<_>>()
    };
    let process = |name: &str, publishes, subscribes| ProcessAccess {
        name: name.to_owned(),
        common_name: common_name("bench", "link", name),
        publishes,
        subscribes,
    };
    AccessPolicy {
        system: "bench".into(),
        deployment: "link".into(),
        processes: vec![
            process("main", keys("ping"), keys("pong")),
            process("echo", keys("pong"), keys("ping")),
            process(LAUNCHER, Default::default(), Default::default()),
        ],
    }
}

/// A session of `who`: plain TCP, or (with `certs`) QUIC (TLS 1.3) and the policy.
fn session(who: &str, certs: Option<&std::path::Path>) -> agent_zenoh::zenoh::Session {
    let secured = certs.map(|dir| Secured {
        credentials: Credentials::in_dir(dir, who).unwrap(),
        acl: policy().acl(who).unwrap(),
    });
    let endpoint = match certs {
        None => format!("tcp/127.0.0.1:{PORT}"),
        Some(_) => format!("quic/127.0.0.1:{SECURE_PORT}"),
    };
    if who == "echo" {
        open_secure_peer(Some(&endpoint), &[], secured.as_ref()).unwrap()
    } else {
        open_secure_peer(None, &[&endpoint], secured.as_ref()).unwrap()
    }
}

/// The echoing process: sends back every ping, ours and raw, until told to end.
/// Run this process (every thread it has and will have) on core `cpu`, when
/// the machine has two cores or more; say where.
fn pin(cpu: usize) -> Option<usize> {
    let cores = std::thread::available_parallelism().map_or(1, usize::from);
    if cores < 2 {
        return None;
    }
    let mut set = nix::sched::CpuSet::new();
    set.set(cpu).ok()?;
    nix::sched::sched_setaffinity(nix::unistd::Pid::from_raw(0), &set).ok()?;
    Some(cpu)
}

fn echo_main(certs: Option<&std::path::Path>) {
    pin(1);
    let session = session("echo", certs);
    let (mut ours, raw) = ends(&session, "pong", "ping");
    // ROS 2 keys are not in the secure pair's access control.
    let mut ros = certs.is_none().then(|| ros_ends(&session, "pong", "ping"));
    let ready = session.declare_publisher("bench/_rt/ready").wait().unwrap();
    let end = Instant::now() + Duration::from_secs(300);
    let mut i = 0;
    let mut last_ready = Instant::now() - Duration::from_secs(1);
    while Instant::now() < end {
        let mut idle = true;
        if let Some(v) = ours.rx.recv().unwrap().copied() {
            if v[1] == u64::MAX {
                return;
            }
            ours.tx.send(v, stamp(i)).unwrap();
            i += 1;
            idle = false;
        }
        if let Some(bytes) = raw_recv(&raw) {
            raw.publisher.put(bytes).wait().unwrap();
            idle = false;
        }
        if let Some(ros) = ros.as_mut()
            && let Some(v) = ros.recv()
        {
            ros.send(v, i);
            idle = false;
        }
        if idle {
            // Ready once the pongs of ROS 2 have their subscriber too (asked
            // only when it is time to say so: asking is not free).
            let due = last_ready.elapsed() > Duration::from_millis(100);
            let matched = || {
                ros.as_ref()
                    .is_none_or(|r| r.bridge.wait_for_subscribers(Duration::ZERO))
            };
            if due && matched() {
                ready.put("ready").wait().unwrap();
                last_ready = Instant::now();
            }
            std::thread::yield_now();
        }
    }
}

/// One side of the Zenoh figures: the echo process and our ends.
struct Pair {
    child: std::process::Child,
    ours: Ours,
    raw: Raw,
    /// The ROS 2 ends (the plain pair only).
    ros: Option<Ros>,
    _session: agent_zenoh::zenoh::Session,
}

fn pair(certs: Option<&std::path::Path>) -> Pair {
    let mut cmd = Command::new(std::env::current_exe().unwrap());
    cmd.arg("--echo");
    if let Some(dir) = certs {
        cmd.arg(dir);
    }
    let child = cmd.stdout(Stdio::null()).spawn().unwrap();
    let session = session("main", certs);
    let (ours, raw) = ends(&session, "ping", "pong");
    let ros = certs.is_none().then(|| ros_ends(&session, "ping", "pong"));
    // The echo process is up and its subscriptions reach us.
    let ready = session
        .declare_subscriber("bench/_rt/ready")
        .wait()
        .unwrap();
    ready
        .recv_timeout(Duration::from_secs(30))
        .unwrap()
        .expect("the echo process is ready");
    if let Some(ros) = &ros {
        assert!(ros.bridge.wait_for_subscribers(Duration::from_secs(30)));
    }
    Pair {
        child,
        ours,
        raw,
        ros,
        _session: session,
    }
}

/// Half round trips of `n` values through the ROS 2 ends, numbered from
/// `*seq + 1`, pushed to `out` if `count`.
fn ros_round(ros: &mut Ros, seq: &mut u64, n: usize, count: bool, out: &mut Vec<f64>) {
    for _ in 0..n {
        *seq += 1;
        let t = Instant::now();
        ros.send([*seq, 0, 0, 0, 0, 0, 0, 0], *seq as usize);
        let v = spin(|| ros.recv());
        assert_eq!(v[0], *seq);
        if count {
            out.push(t.elapsed().as_secs_f64() * 1e6 / 2.0);
        }
    }
}

/// Half round trips through our links, raw Zenoh and ROS 2 (plain), and our
/// links secure, alternating in rounds: ours, secure, raw, ROS 2.
fn zenoh_us(certs: &std::path::Path) -> [Vec<f64>; 4] {
    let mut plain = pair(None);
    let mut secure = pair(Some(certs));
    std::thread::sleep(Duration::from_millis(300));
    let mut out: [Vec<f64>; 4] = Default::default();
    let mut seq = 0u64;
    for round in 0..ROUNDS + 1 {
        // The first round warms every path up and is not counted.
        let count = round > 0;
        for (k, p) in [&mut plain, &mut secure].into_iter().enumerate() {
            for _ in 0..PER_ROUND {
                seq += 1;
                let t = Instant::now();
                p.ours
                    .tx
                    .send([seq, 0, 0, 0, 0, 0, 0, 0], stamp(seq as usize))
                    .unwrap();
                let v = spin(|| p.ours.rx.recv().unwrap().copied());
                assert_eq!(v[0], seq);
                if count {
                    out[k * 2].push(t.elapsed().as_secs_f64() * 1e6 / 2.0);
                }
            }
        }
        for _ in 0..PER_ROUND {
            seq += 1;
            let bytes = [seq; 8].map(u64::to_le_bytes).concat();
            let t = Instant::now();
            plain.raw.publisher.put(bytes).wait().unwrap();
            let back = spin(|| raw_recv(&plain.raw));
            assert_eq!(back.get(..8), Some(&seq.to_le_bytes()[..]));
            if count {
                out[1].push(t.elapsed().as_secs_f64() * 1e6 / 2.0);
            }
        }
        let ros = plain.ros.as_mut().unwrap();
        ros_round(ros, &mut seq, PER_ROUND, count, &mut out[3]);
    }
    let report = plain.ros.take().unwrap().bridge.finish().unwrap();
    assert_eq!(
        (
            report.dropped(),
            report.encode_failures(),
            report.put_failures()
        ),
        (0, 0, 0)
    );
    for p in [&mut plain, &mut secure] {
        p.ours
            .tx
            .send([0, u64::MAX, 0, 0, 0, 0, 0, 0], stamp(0))
            .unwrap();
        let _ = p.child.wait();
    }
    out
}

fn report(name: &str, unit: &str, v: &mut [f64]) -> (f64, f64) {
    let (p50, p99) = (percentile(v, 0.5), percentile(v, 0.99));
    let max = v.iter().copied().fold(0.0, f64::max);
    println!(
        "{name:<10} n={:<6} p50={p50:.2} {unit}  p99={p99:.2} {unit}  max={max:.2} {unit}",
        v.len()
    );
    (p50, p99)
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.get(1).map(String::as_str) == Some("--echo") {
        return echo_main(args.get(2).map(std::path::Path::new));
    }
    match pin(0) {
        Some(_) => println!("pings on core 0, echo processes on core 1"),
        None => println!("not pinned (one core, or the OS refused the affinity)"),
    }
    let certs = std::env::temp_dir().join(format!("bench-link-certs-{}", std::process::id()));
    create_dev_authority(&certs, &policy(), &[]).unwrap();
    let (inproc, _) = report("inproc", "ns", &mut inproc_ns());
    let (thread, _) = report("thread", "us", &mut thread_us());
    let [mut ours, mut raw, mut secure, mut ros2] = zenoh_us(&certs);
    let _ = std::fs::remove_dir_all(&certs);
    let (zenoh_p50, zenoh_p99) = report("zenoh", "us", &mut ours);
    let (raw_p50, _) = report("raw_zenoh", "us", &mut raw);
    let (secure_p50, secure_p99) = report("secure", "us", &mut secure);
    let (ros2_p50, ros2_p99) = report("ros2", "us", &mut ros2);
    println!(
        "zenoh_p50 / raw_zenoh_p50 = {:.2} (aim <= 1.2)",
        zenoh_p50 / raw_p50
    );
    println!(
        "zenoh_secure_p50 / zenoh_p50 = {:.2} (TLS and access control; aim <= 1.3)",
        secure_p50 / zenoh_p50
    );
    let ros2_over_zenoh = ros2_p50 / zenoh_p50;
    println!("ros2_p50 / zenoh_p50 = {ros2_over_zenoh:.2} (ROS 2 over rmw_zenoh; aim <= 1.2)");
    println!(
        "inproc_ns_p50={inproc:.0} thread_us_p50={thread:.2} zenoh_us_p50={zenoh_p50:.1} zenoh_us_p99={zenoh_p99:.1} raw_zenoh_us_p50={raw_p50:.1} zenoh_secure_us_p50={secure_p50:.1} zenoh_secure_us_p99={secure_p99:.1} ros2_us_p50={ros2_p50:.1} ros2_us_p99={ros2_p99:.1} ros2_over_zenoh={ros2_over_zenoh:.2}"
    );
}
