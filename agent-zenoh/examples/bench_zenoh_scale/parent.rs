//! The parent: starts a run's processes (on one host or four), tells them
//! when to go, gathers their `result` lines and prints the run's figures
//! (percentiles of the half round trips, CPU time per message).

use std::io::{BufRead, BufReader, Write};
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use crate::RATE_HZ;
use crate::hosts::{HOSTS, Hosts};
use crate::topology::{Connect, Topology};

fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    v[((v.len() - 1) as f64 * q).round() as usize]
}

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
pub(crate) struct Run {
    pub(crate) k: usize,
    pub(crate) topology: Topology,
    /// Four hosts (namespaces) or one.
    pub(crate) four: bool,
    pub(crate) connect: Connect,
    pub(crate) warmup: Duration,
    pub(crate) window: Duration,
    pub(crate) rate_hz: u64,
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
pub(crate) fn report(run: &Run, hosts: Option<&Hosts>) -> Result<f64, String> {
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
