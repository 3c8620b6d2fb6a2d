//! How Zenoh links scale with the number of processes: K processes (2, 8, 32),
//! each a Zenoh session in peer mode with explicit endpoints (no multicast),
//! links in a ring (process i pings i + 1, which echoes) and in a star (every
//! other process pings a hub, which echoes), on one host (loopback) and on four
//! "hosts" made of network namespaces joined by veth pairs to a bridge (in a
//! fifth namespace: no traffic leaves the namespaces the benchmark made).
//!
//! `cargo run --release -p agent-zenoh --example bench_zenoh_scale`
//! (`--quick`: K = 2 and 4, one host, ring, a short run; `--max-k N`;
//! `--connect needed`: each process connects only to the processes it has links
//! with, gossip off, instead of to every other one as a deployment's members do).
//!
//! * Each link runs at 100 Hz (a robot's rate), the pings of the processes
//!   spread over the period (process i starts i/K of a period in).
//! * The values go through the framework's links between processes as
//!   bench_link's `zenoh_us` does: agent-core's sending end over
//!   [`ZenohTransport`] (header and postcard, the outbox ring and its
//!   publishing thread, a reliable express publisher) and agent-core's inbox
//!   (header, fingerprint and sequence checks) with a reader taking the value.
//!   The receiving thread does not spin (32 spinning processes on 2 cores would
//!   measure the spinning): the subscriber's callback delivers into the inbox as
//!   [`ZenohTransport`]'s does and then wakes the process's thread
//!   (`Thread::unpark`), which takes the value from the link's reader.
//! * Latency: half a round trip (ping, echo sent back on receipt), as in
//!   bench_link, measured by the pinging process on its own clock (the ping
//!   carries its sending time; the echo returns it). Percentiles are over every
//!   link's samples of the measuring window (the same window, 10 s after 1 s of
//!   warm-up, at every K).
//! * CPU time per message: the on-CPU time of every thread of every process
//!   over the window (`/proc/self/task/*/schedstat`, read by each process at the
//!   window's ends), over the messages received in it (pings and echoes).
//!
//! One line per K, topology and host layout:
//! `zenoh k=.. topology=ring|star hosts=1|4 p50_us=.. p99_us=.. max_us=..
//! cpu_us_per_msg=.. msgs=..`, and last `zenoh_ratio_32=..` (p50 at K = 32 over
//! p50 at K = 2, ring, one host; `zenoh_ratio_<K>` with a smaller largest K).
//! Four hosts need root and `ip`; otherwise `zenoh hosts=4 skipped=<reason>`.
//!
//! Seen on the 2-core VM (shared with other work), three runs: p50 at K = 32 is
//! 0.55x to 1.5x of K = 2's in every topology and layout (one host, ring: 1.04x
//! and 1.19x; a lone link idles more between messages, and a CPU woken from
//! idle is slower to answer, so K = 2 is not always the fastest); p99 grows
//! from about 1 ms to 10-50 ms at K = 32. The tail follows the machine's total
//! message rate, not K or Zenoh's routing: K = 32 at 10 Hz had a p99 of 0.85
//! ms, K = 8 at 400 Hz (the message rate of K = 32 at 100 Hz) 12.8 ms;
//! `--connect needed` changed neither beyond the noise; running every process
//! `SCHED_FIFO` (`chrt -f 10`) halved it. Each message costs about 100 us of
//! CPU over all threads of both processes (several thread wake-ups: the
//! outbox's thread, Zenoh's, the callback's wake of the reader), so K = 32 at
//! 100 Hz keeps about three quarters of a core busy and the wake-ups queue on 2
//! cores; at low rates `cpu_us_per_msg` is dominated by each idle session's own
//! cost (about 4 ms of CPU a second a process).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a benchmark: a failure ends it"
)]

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc;
use std::sync::{Arc, Mutex};
use std::thread::Thread;
use std::time::{Duration, Instant};

use agent_core::link::endpoint::{self, Receiver, Sender};
use agent_core::prelude::*;
use agent_zenoh::ZenohTransport;
use agent_zenoh::zenoh::Wait;

type Payload64 = [u64; 8];

/// The rate of every link, unless `--rate-hz` says otherwise.
const RATE_HZ: u64 = 100;
/// A value's slots: its number, its sending time (ns on the pinger's clock),
/// whether it was sent in the measuring window.
const SEQ: usize = 0;
const SENT: usize = 1;
const COUNTED: usize = 2;

fn stamp(i: u64) -> Stamp {
    Stamp::new(i, Time::ZERO)
}

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

// ---------------------------------------------------------------------------
// What one run is.

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Topology {
    Ring,
    Star,
}

impl Topology {
    fn name(self) -> &'static str {
        match self {
            Topology::Ring => "ring",
            Topology::Star => "star",
        }
    }

    fn parse(s: &str) -> Topology {
        match s {
            "ring" => Topology::Ring,
            "star" => Topology::Star,
            _ => panic!("topology `{s}`: ring or star"),
        }
    }

    /// The links (pinger, echoer) of `k` processes; a link's index is its key.
    fn links(self, k: usize) -> Vec<(usize, usize)> {
        match self {
            Topology::Ring => (0..k).map(|i| (i, (i + 1) % k)).collect(),
            Topology::Star => (1..k).map(|i| (i, 0)).collect(),
        }
    }
}

/// Which processes a process connects to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Connect {
    /// Every other process (as a deployment's members do), with Zenoh's defaults.
    Mesh,
    /// Only those it has a link with (the lower index connects), gossip off.
    Needed,
}

impl Connect {
    fn name(self) -> &'static str {
        match self {
            Connect::Mesh => "mesh",
            Connect::Needed => "needed",
        }
    }

    fn parse(s: &str) -> Connect {
        match s {
            "mesh" => Connect::Mesh,
            "needed" => Connect::Needed,
            _ => panic!("connect `{s}`: mesh or needed"),
        }
    }
}

// ---------------------------------------------------------------------------
// One process.

/// The process's thread, woken by every value that arrives.
struct Wake(Thread);

/// A link's receiving end fed by a subscriber that wakes the process.
fn receiver(
    session: &agent_zenoh::zenoh::Session,
    key: &str,
    wake: &Arc<Wake>,
    keep: &mut Vec<agent_zenoh::zenoh::pubsub::Subscriber<()>>,
) -> Receiver<Payload64> {
    let (inbox, rx) = endpoint::fed::<Payload64>(key, Policy::queue(64));
    let wake = wake.clone();
    let subscriber = session
        .declare_subscriber(key.to_owned())
        .callback(move |sample| {
            inbox.deliver(&sample.payload().to_bytes());
            wake.0.unpark();
        })
        .wait()
        .unwrap();
    keep.push(subscriber);
    rx
}

/// A link this process pings on.
struct Ping {
    tx: Sender<Payload64>,
    rx: Receiver<Payload64>,
    seq: u64,
    answered: bool,
}

/// A link this process echoes.
struct Echo {
    rx: Receiver<Payload64>,
    tx: Sender<Payload64>,
    n: u64,
}

/// The arguments of a process: `--child INDEX K TOPOLOGY CONNECT PREFIX ENDPOINTS`
/// (the endpoints of all processes, comma-separated, its own at INDEX).
struct ChildArgs {
    index: usize,
    k: usize,
    topology: Topology,
    connect: Connect,
    prefix: String,
    endpoints: Vec<String>,
}

impl ChildArgs {
    fn parse(args: &[String]) -> ChildArgs {
        ChildArgs {
            index: args[0].parse().unwrap(),
            k: args[1].parse().unwrap(),
            topology: Topology::parse(&args[2]),
            connect: Connect::parse(&args[3]),
            prefix: args[4].clone(),
            endpoints: args[5].split(',').map(str::to_owned).collect(),
        }
    }

    /// The endpoints this process connects to.
    fn connect_to(&self) -> Vec<&str> {
        let me = self.index;
        let links = self.topology.links(self.k);
        (0..self.k)
            .filter(|&j| j != me)
            .filter(|&j| {
                self.connect == Connect::Mesh
                    || (me < j && links.iter().any(|&l| l == (me, j) || l == (j, me)))
            })
            .map(|j| self.endpoints[j].as_str())
            .collect()
    }
}

/// The session: the framework's peer session, or one connected only where needed.
fn child_session(a: &ChildArgs) -> agent_zenoh::zenoh::Session {
    let listen = a.endpoints[a.index].as_str();
    let connect = a.connect_to();
    if a.connect == Connect::Mesh {
        return agent_zenoh::open_peer(Some(listen), &connect).unwrap();
    }
    let mut config = agent_zenoh::zenoh::Config::default();
    let list = |v: &[&str]| format!("{v:?}");
    for (key, value) in [
        ("mode", "\"peer\"".to_owned()),
        ("listen/endpoints", list(&[listen])),
        ("connect/endpoints", list(&connect)),
        ("connect/exit_on_failure", "false".to_owned()),
        (
            "connect/retry",
            "{period_init_ms: 100, period_max_ms: 1000, period_increase_factor: 2}".to_owned(),
        ),
        ("scouting/multicast/enabled", "false".to_owned()),
        ("scouting/gossip/enabled", "false".to_owned()),
    ] {
        config.insert_json5(key, &value).unwrap();
    }
    agent_zenoh::zenoh::open(config).wait().unwrap()
}

/// On-CPU time of every thread of this process so far, in ns.
fn cpu_ns() -> u64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else {
        return 0;
    };
    tasks
        .filter_map(Result::ok)
        .filter_map(|t| std::fs::read_to_string(t.path().join("schedstat")).ok())
        .filter_map(|s| s.split_whitespace().next()?.parse::<u64>().ok())
        .sum()
}

/// When to go, as the parent says: warm-up and window in ms, the links' rate
/// in Hz.
type Go = Arc<Mutex<Option<(u64, u64, u64)>>>;

/// What the parent says on the process's standard input: go, or nothing more
/// (end of input: the process ends).
fn listen_stdin(wake: Arc<Wake>) -> Go {
    let go = Arc::new(Mutex::new(None));
    let go2 = go.clone();
    std::thread::spawn(move || {
        for line in std::io::stdin().lock().lines() {
            let Ok(line) = line else { break };
            let mut w = line.split_whitespace();
            if w.next() == Some("go") {
                let mut ms = || w.next().unwrap().parse::<u64>().unwrap();
                *go2.lock().unwrap() = Some((ms(), ms(), ms()));
                wake.0.unpark();
            }
        }
        std::process::exit(0);
    });
    go
}

fn child_main(args: &[String]) {
    let a = ChildArgs::parse(args);
    let session = child_session(&a);
    let mut transport = ZenohTransport::new(session.clone(), a.prefix.clone());
    let wake = Arc::new(Wake(std::thread::current()));
    let mut subscribers = Vec::new();
    let (mut pings, mut echoes) = (Vec::new(), Vec::new());
    for (l, &(from, to)) in a.topology.links(a.k).iter().enumerate() {
        let (ping, echo) = (
            format!("{}/ping/{l}", a.prefix),
            format!("{}/echo/{l}", a.prefix),
        );
        if from == a.index {
            pings.push(Ping {
                tx: endpoint::to_processes(&mut transport, &ping, Policy::queue(64)).unwrap(),
                rx: receiver(&session, &echo, &wake, &mut subscribers),
                seq: 0,
                answered: false,
            });
        }
        if to == a.index {
            echoes.push(Echo {
                rx: receiver(&session, &ping, &wake, &mut subscribers),
                tx: endpoint::to_processes(&mut transport, &echo, Policy::queue(64)).unwrap(),
                n: 0,
            });
        }
    }
    let go = listen_stdin(wake);
    let mut node = Node {
        pings,
        echoes,
        base: Instant::now(),
        counting: false,
        received: 0,
        samples: Vec::new(),
        problems: 0,
    };
    node.probe(&go);
    let (warmup, window, rate) = go.lock().unwrap().unwrap();
    let (cpu, msgs) = node.measure(
        a.index as f64 / a.k as f64,
        Duration::from_secs(1) / rate as u32,
        Duration::from_millis(warmup),
        Duration::from_millis(window),
    );
    let lat: Vec<String> = node.samples.iter().map(u64::to_string).collect();
    println!(
        "result cpu_ns={cpu} msgs={msgs} problems={} lat={}",
        node.problems,
        lat.join(",")
    );
    // Echo the others until the parent closes the input.
    loop {
        node.poll();
        std::thread::park_timeout(Duration::from_millis(100));
    }
}

/// One process's links and what it measured.
struct Node {
    pings: Vec<Ping>,
    echoes: Vec<Echo>,
    base: Instant,
    /// Whether the messages received are counted (in the window).
    counting: bool,
    received: u64,
    /// Half round trips of the pings sent in the window, ns.
    samples: Vec<u64>,
    /// Problems the links reported in the window (gaps, refused values).
    problems: u64,
}

impl Node {
    fn now_ns(&self) -> u64 {
        self.base.elapsed().as_nanos() as u64
    }

    /// Echo every ping arrived, take every echo arrived.
    fn poll(&mut self) {
        for e in &mut self.echoes {
            loop {
                match e.rx.recv() {
                    Ok(Some(v)) => {
                        let v = *v;
                        e.n += 1;
                        e.tx.send(v, stamp(e.n)).unwrap();
                        self.received += u64::from(self.counting);
                    }
                    Ok(None) => break,
                    Err(_) => self.problems += u64::from(self.counting),
                }
            }
        }
        let now = self.now_ns();
        for p in &mut self.pings {
            loop {
                match p.rx.recv() {
                    Ok(Some(v)) => {
                        p.answered = true;
                        self.received += u64::from(self.counting);
                        if v[COUNTED] == 1 {
                            self.samples.push(now.saturating_sub(v[SENT]) / 2);
                        }
                    }
                    Ok(None) => break,
                    Err(_) => self.problems += u64::from(self.counting),
                }
            }
        }
    }

    /// Ping every link, marked counted or not.
    fn ping(&mut self, counted: bool) {
        let now = self.now_ns();
        for p in &mut self.pings {
            p.seq += 1;
            let mut v = [0; 8];
            (v[SEQ], v[SENT], v[COUNTED]) = (p.seq, now, u64::from(counted));
            p.tx.send(v, stamp(p.seq)).unwrap();
        }
    }

    /// Until told to go: ping every 20 ms, echo, and say `ready` once every
    /// link pinged from here was answered.
    fn probe(&mut self, go: &Mutex<Option<(u64, u64, u64)>>) {
        let mut said = false;
        let mut next = Instant::now();
        while go.lock().unwrap().is_none() {
            let now = Instant::now();
            self.poll();
            if !said && self.pings.iter().all(|p| p.answered) {
                println!("ready");
                std::io::stdout().flush().unwrap();
                said = true;
            }
            if now >= next {
                self.ping(false);
                next = now + Duration::from_millis(20);
            }
            std::thread::park_timeout(next.saturating_duration_since(Instant::now()));
        }
    }

    /// Warm up, then measure a window; the process's CPU time in it and the
    /// messages received in it. Pings start `phase` of a period in.
    fn measure(
        &mut self,
        phase: f64,
        period: Duration,
        warmup: Duration,
        window: Duration,
    ) -> (u64, u64) {
        let t0 = Instant::now();
        let (start, end) = (t0 + warmup, t0 + warmup + window);
        let mut next = t0 + period.mul_f64(phase);
        let mut cpu0 = None;
        // The last pings' echoes: a grace after the window.
        let grace = end + Duration::from_millis(300);
        let mut cpu = 0;
        let mut msgs = 0;
        loop {
            let now = Instant::now();
            if cpu0.is_none() && now >= start {
                cpu0 = Some(cpu_ns());
                self.counting = true;
            }
            if self.counting && now >= end {
                cpu = cpu_ns() - cpu0.unwrap();
                msgs = self.received;
                self.counting = false;
            }
            self.poll();
            if now >= grace {
                return (cpu, msgs);
            }
            if now >= next && next < end {
                self.ping(next >= start);
                next += period;
            }
            let until = if next < end { next } else { grace };
            std::thread::park_timeout(until.saturating_duration_since(Instant::now()));
        }
    }
}

// ---------------------------------------------------------------------------
// Four hosts: network namespaces.

/// Four network namespaces ("hosts") with addresses 10.57.0.1-4/24 on `eth0`,
/// joined by veth pairs to a bridge in a fifth; deleted when dropped (every
/// veth and the bridge go with them).
struct Hosts {
    names: Vec<String>,
}

const HOSTS: usize = 4;

fn ip(args: &[&str]) -> Result<(), String> {
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
}

impl Hosts {
    fn prefix(pid: u32) -> String {
        format!("zscale{pid}-")
    }

    fn host(&self, h: usize) -> &str {
        &self.names[h]
    }

    fn address(h: usize) -> String {
        format!("10.57.0.{}", h + 1)
    }

    fn make() -> Result<Hosts, String> {
        Self::remove_stale();
        let p = Self::prefix(std::process::id());
        let mut names: Vec<String> = (0..HOSTS).map(|h| format!("{p}h{h}")).collect();
        let switch = format!("{p}sw");
        names.push(switch.clone());
        // From here on, dropping `hosts` deletes what was made.
        let hosts = Hosts { names };
        for ns in &hosts.names {
            ip(&["netns", "add", ns])?;
        }
        let sw = switch.as_str();
        ip(&["-n", sw, "link", "add", "br0", "type", "bridge"])?;
        ip(&["-n", sw, "link", "set", "br0", "up"])?;
        for h in 0..HOSTS {
            let (ns, port) = (hosts.host(h), format!("p{h}"));
            ip(&[
                "-n", sw, "link", "add", &port, "type", "veth", "peer", "name", "eth0", "netns", ns,
            ])?;
            ip(&["-n", sw, "link", "set", &port, "master", "br0"])?;
            ip(&["-n", sw, "link", "set", &port, "up"])?;
            let addr = format!("{}/24", Self::address(h));
            ip(&["-n", ns, "addr", "add", &addr, "dev", "eth0"])?;
            ip(&["-n", ns, "link", "set", "eth0", "up"])?;
            ip(&["-n", ns, "link", "set", "lo", "up"])?;
        }
        Ok(hosts)
    }

    /// Namespaces of earlier runs whose process is gone (killed before its
    /// guard could delete them).
    fn remove_stale() {
        let Ok(out) = Command::new("ip").args(["netns", "list"]).output() else {
            return;
        };
        for line in String::from_utf8_lossy(&out.stdout).lines() {
            let name = line.split_whitespace().next().unwrap_or("");
            let Some(rest) = name.strip_prefix("zscale") else {
                continue;
            };
            let pid = rest.split('-').next().unwrap_or("");
            if pid.parse::<u32>().is_ok() && !std::path::Path::new(&format!("/proc/{pid}")).exists()
            {
                let _ = ip(&["netns", "del", name]);
            }
        }
    }
}

impl Drop for Hosts {
    fn drop(&mut self) {
        for ns in &self.names {
            let _ = ip(&["netns", "del", ns]);
        }
    }
}

/// Why four hosts cannot be made here, if they cannot.
fn hosts_unavailable() -> Option<String> {
    let root = std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("Uid:"))
                .map(|l| l.split_whitespace().nth(1) == Some("0"))
        })
        .unwrap_or(false);
    if !root {
        return Some("not_root".into());
    }
    match Command::new("ip").arg("-V").output() {
        Ok(o) if o.status.success() => None,
        _ => Some("no_ip_command".into()),
    }
}

// ---------------------------------------------------------------------------
// The parent: start the processes, collect their figures.

/// The processes of one run; ended when dropped (input closed, then killed if
/// they linger).
struct Procs {
    children: Vec<(Child, Option<ChildStdin>)>,
}

impl Drop for Procs {
    fn drop(&mut self) {
        for (_, stdin) in &mut self.children {
            stdin.take();
        }
        let deadline = Instant::now() + Duration::from_secs(5);
        for (child, _) in &mut self.children {
            while Instant::now() < deadline && matches!(child.try_wait(), Ok(None)) {
                std::thread::sleep(Duration::from_millis(20));
            }
            let _ = child.kill();
            let _ = child.wait();
        }
    }
}

/// One run's settings.
#[derive(Clone, Copy, Debug)]
struct Run {
    k: usize,
    topology: Topology,
    /// Four hosts (namespaces) or one.
    four: bool,
    connect: Connect,
    warmup: Duration,
    window: Duration,
    rate_hz: u64,
}

/// What one run measured.
struct Figures {
    samples_us: Vec<f64>,
    cpu_ns: u64,
    msgs: u64,
    problems: u64,
}

/// Free TCP ports on loopback (the OS's choice; released before the processes
/// bind them).
fn free_ports(n: usize) -> Vec<u16> {
    let listeners: Vec<_> = (0..n)
        .map(|_| std::net::TcpListener::bind("127.0.0.1:0").unwrap())
        .collect();
    listeners
        .iter()
        .map(|l| l.local_addr().unwrap().port())
        .collect()
}

fn spawn(run: &Run, hosts: Option<&Hosts>, index: usize, endpoints: &str) -> Child {
    let exe = std::env::current_exe().unwrap();
    let mut command = match hosts {
        Some(h) => {
            let mut c = Command::new("ip");
            c.args(["netns", "exec", h.host(index % HOSTS)]).arg(&exe);
            c
        }
        None => Command::new(&exe),
    };
    command
        .arg("--child")
        .args([
            index.to_string(),
            run.k.to_string(),
            run.topology.name().into(),
            run.connect.name().into(),
            format!("zscale{}", std::process::id()),
            endpoints.to_owned(),
        ])
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .spawn()
        .unwrap()
}

/// Start the processes of `run`; their output lines arrive on the receiver.
fn start(run: &Run, hosts: Option<&Hosts>) -> (Procs, mpsc::Receiver<(usize, String)>) {
    let endpoints: Vec<String> = match hosts {
        Some(_) => (0..run.k)
            .map(|i| format!("tcp/{}:{}", Hosts::address(i % HOSTS), 17_700 + i))
            .collect(),
        None => free_ports(run.k)
            .into_iter()
            .map(|p| format!("tcp/127.0.0.1:{p}"))
            .collect(),
    };
    let endpoints = endpoints.join(",");
    let (lines_tx, lines) = mpsc::channel();
    let mut procs = Procs {
        children: Vec::new(),
    };
    for i in 0..run.k {
        let mut child = spawn(run, hosts, i, &endpoints);
        let stdout = child.stdout.take().unwrap();
        let stdin = child.stdin.take();
        let tx = lines_tx.clone();
        std::thread::spawn(move || {
            for line in BufReader::new(stdout).lines().map_while(Result::ok) {
                if tx.send((i, line)).is_err() {
                    break;
                }
            }
        });
        procs.children.push((child, stdin));
    }
    (procs, lines)
}

/// Wait for a line starting with `word` from every process, within `timeout`.
fn gather(
    lines: &mpsc::Receiver<(usize, String)>,
    k: usize,
    word: &str,
    timeout: Duration,
) -> Result<Vec<String>, String> {
    let deadline = Instant::now() + timeout;
    let mut got: Vec<Option<String>> = vec![None; k];
    while got.iter().any(Option::is_none) {
        let left = deadline.saturating_duration_since(Instant::now());
        match lines.recv_timeout(left) {
            Ok((i, line)) if line.starts_with(word) => got[i] = Some(line),
            Ok(_) => {}
            Err(_) => {
                let missing: Vec<usize> = (0..k).filter(|&i| got[i].is_none()).collect();
                return Err(format!("no `{word}` from processes {missing:?}"));
            }
        }
    }
    Ok(got.into_iter().map(Option::unwrap).collect())
}

fn field<'a>(line: &'a str, name: &str) -> &'a str {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(name)?.strip_prefix('='))
        .unwrap_or("")
}

fn measure(run: &Run, hosts: Option<&Hosts>) -> Result<Figures, String> {
    let (mut procs, lines) = start(run, hosts);
    gather(&lines, run.k, "ready", Duration::from_secs(120))?;
    let go = format!(
        "go {} {} {}\n",
        run.warmup.as_millis(),
        run.window.as_millis(),
        run.rate_hz
    );
    for (_, stdin) in &mut procs.children {
        let stdin = stdin.as_mut().unwrap();
        stdin.write_all(go.as_bytes()).map_err(|e| e.to_string())?;
        stdin.flush().map_err(|e| e.to_string())?;
    }
    let limit = run.warmup + run.window + Duration::from_secs(30);
    let results = gather(&lines, run.k, "result", limit)?;
    drop(procs);
    let mut f = Figures {
        samples_us: Vec::new(),
        cpu_ns: 0,
        msgs: 0,
        problems: 0,
    };
    for r in &results {
        f.cpu_ns += field(r, "cpu_ns").parse::<u64>().unwrap();
        f.msgs += field(r, "msgs").parse::<u64>().unwrap();
        f.problems += field(r, "problems").parse::<u64>().unwrap();
        let lat = field(r, "lat");
        f.samples_us.extend(
            lat.split(',')
                .filter(|s| !s.is_empty())
                .map(|s| s.parse::<f64>().unwrap() / 1e3),
        );
    }
    Ok(f)
}

/// Measure `run` and print its line; its p50.
fn report(run: &Run, hosts: Option<&Hosts>) -> Result<f64, String> {
    let mut f = measure(run, hosts)?;
    if f.samples_us.is_empty() {
        return Err(format!("k={} {}: no sample", run.k, run.topology.name()));
    }
    let p50 = percentile(&mut f.samples_us, 0.5);
    let p99 = percentile(&mut f.samples_us, 0.99);
    let max = f.samples_us.iter().copied().fold(0.0, f64::max);
    let cpu = f.cpu_ns as f64 / 1e3 / f.msgs.max(1) as f64;
    let mut extra = match run.connect {
        Connect::Mesh => String::new(),
        Connect::Needed => " connect=needed".into(),
    };
    if run.rate_hz != RATE_HZ {
        extra += &format!(" rate_hz={}", run.rate_hz);
    }
    let problems = if f.problems > 0 {
        format!(" problems={}", f.problems)
    } else {
        String::new()
    };
    println!(
        "zenoh k={} topology={} hosts={} p50_us={p50:.1} p99_us={p99:.1} max_us={max:.1} cpu_us_per_msg={cpu:.2} msgs={}{extra}{problems}",
        run.k,
        run.topology.name(),
        if run.four { HOSTS } else { 1 },
        f.msgs,
    );
    std::io::stdout().flush().unwrap();
    Ok(p50)
}

/// The command line: `--quick`, `--max-k N`, `--connect mesh|needed`, and
/// for experiments `--rate-hz N`, `--topology ring|star`, `--hosts 1|4`
/// (only those runs).
struct Options {
    quick: bool,
    max_k: usize,
    connect: Connect,
    rate_hz: u64,
    topology: Option<Topology>,
    hosts: Option<usize>,
}

fn options(args: &[String]) -> Options {
    let mut o = Options {
        quick: false,
        max_k: 32,
        connect: Connect::Mesh,
        rate_hz: RATE_HZ,
        topology: None,
        hosts: None,
    };
    let mut i = 0;
    while i < args.len() {
        match args[i].as_str() {
            "--quick" => o.quick = true,
            "--max-k" => {
                i += 1;
                o.max_k = args[i].parse().expect("--max-k N");
            }
            "--connect" => {
                i += 1;
                o.connect = Connect::parse(&args[i]);
            }
            "--rate-hz" => {
                i += 1;
                o.rate_hz = args[i].parse().expect("--rate-hz N");
            }
            "--topology" => {
                i += 1;
                o.topology = Some(Topology::parse(&args[i]));
            }
            "--hosts" => {
                i += 1;
                o.hosts = Some(args[i].parse().expect("--hosts 1|4"));
            }
            other => {
                panic!(
                    "unknown argument `{other}`: --quick, --max-k N, --connect mesh|needed, --rate-hz N, --topology ring|star, --hosts 1|4"
                )
            }
        }
        i += 1;
    }
    o
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    if args.first().map(String::as_str) == Some("--child") {
        return child_main(&args[1..]);
    }
    let o = options(&args);
    let (ks, topologies, layouts, warmup, window): (Vec<usize>, _, _, _, _) = if o.quick {
        (vec![2, 4], vec![Topology::Ring], vec![false], 300, 1_000)
    } else {
        (
            vec![2, 8, 32],
            vec![Topology::Ring, Topology::Star],
            vec![false, true],
            1_000,
            10_000,
        )
    };
    let ks: Vec<usize> = ks.into_iter().filter(|&k| k <= o.max_k).collect();
    let topologies: Vec<Topology> = topologies
        .into_iter()
        .filter(|t| o.topology.is_none_or(|o| o == *t))
        .collect();
    let layouts = layouts
        .into_iter()
        .filter(|&four| o.hosts.is_none_or(|h| (h == HOSTS) == four));
    let mut ratio = (None, None);
    for four in layouts {
        let hosts = if four {
            match hosts_unavailable().map_or_else(Hosts::make, Err) {
                Ok(h) => Some(h),
                Err(why) => {
                    println!("zenoh hosts=4 skipped={}", why.replace(' ', "_"));
                    continue;
                }
            }
        } else {
            None
        };
        for &topology in &topologies {
            for &k in &ks {
                let run = Run {
                    k,
                    topology,
                    four,
                    connect: o.connect,
                    warmup: Duration::from_millis(warmup),
                    window: Duration::from_millis(window),
                    rate_hz: o.rate_hz,
                };
                let p50 = report(&run, hosts.as_ref()).unwrap_or_else(|e| panic!("{e}"));
                if !four && topology == Topology::Ring {
                    if k == ks[0] {
                        ratio.0 = Some(p50);
                    }
                    if Some(&k) == ks.last() {
                        ratio.1 = Some(p50);
                    }
                }
            }
        }
    }
    if let (Some(first), Some(last)) = ratio {
        println!("zenoh_ratio_{}={:.2}", ks.last().unwrap(), last / first);
    }
}
