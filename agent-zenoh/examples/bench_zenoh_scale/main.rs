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
//!
//! [`ZenohTransport`]: agent_zenoh::ZenohTransport

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a benchmark: a failure ends it"
)]

mod child;
mod hosts;
mod parent;
mod topology;

use std::time::Duration;

use hosts::{HOSTS, Hosts, hosts_unavailable};
use parent::{Run, report};
use topology::{Connect, Topology};

/// The rate of every link, unless `--rate-hz` says otherwise.
const RATE_HZ: u64 = 100;

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
        return child::child_main(&args[1..]);
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
