//! One process of a run (`--child ...`): its Zenoh session, its links (pinged
//! or echoed) through agent-core's ends, and its measures (half round trips,
//! CPU time, messages), printed as one `result` line for the parent.

use std::io::{BufRead, Write};
use std::sync::{Arc, Mutex};
use std::thread::Thread;
use std::time::{Duration, Instant};

use agent_core::link::endpoint::{self, Receiver, Sender};
use agent_core::prelude::*;
use agent_zenoh::ZenohTransport;
use agent_zenoh::zenoh::Wait;

use crate::topology::{Connect, Topology};

type Payload64 = [u64; 8];

/// A value's slots: its number, its sending time (ns on the pinger's clock),
/// whether it was sent in the measuring window.
const SEQ: usize = 0;
const SENT: usize = 1;
const COUNTED: usize = 2;

fn stamp(i: u64) -> Stamp {
    Stamp::new(i, Time::ZERO)
}

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

pub(crate) fn child_main(args: &[String]) {
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
