//! Starting every process of a deployment: children with their output
//! prefixed and collected, a crashed one restarted, all stopped together.

use std::io::{BufRead, BufReader, Read};
use std::path::PathBuf;
use std::process::{Command, ExitStatus, Stdio};
use std::sync::mpsc::{Sender, channel};
use std::time::{Duration, Instant};

/// One process to start.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Child {
    /// Its name in the deployment (the prefix of its lines).
    pub name: String,
    /// The program.
    pub program: PathBuf,
    /// Its arguments.
    pub args: Vec<String>,
    /// How many times it may be started again after a crash (`None`: the
    /// launcher's [`Launcher::max_restarts`]; `Some(0)`: never).
    pub restarts: Option<u32>,
    /// A flag the launcher adds with the start's number (0 for the first, `k`
    /// after the `k`-th restart), for example `--incarnation`.
    pub incarnation_flag: Option<String>,
}

impl Child {
    /// A child started as `program args`, restarted as the launcher's default
    /// says.
    pub fn new(name: impl Into<String>, program: impl Into<PathBuf>, args: Vec<String>) -> Child {
        Child {
            name: name.into(),
            program: program.into(),
            args,
            restarts: None,
            incarnation_flag: None,
        }
    }
}

/// What the launcher tells its caller.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Line {
    /// A line a child printed (on stdout or stderr).
    Output {
        /// The child.
        process: String,
        /// The line.
        text: String,
    },
    /// A child ended.
    Exited {
        /// The child.
        process: String,
        /// How (`None`: killed by a signal).
        code: Option<i32>,
        /// Whether it is started again.
        restarting: bool,
    },
    /// Nothing happened for a while (a chance to look elsewhere).
    Idle,
}

/// What the caller answers.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Control {
    /// Go on.
    Continue,
    /// Stop every child (SIGTERM, then SIGKILL after the grace period).
    Stop,
    /// Kill this child with SIGKILL, as a crash would end it (fault
    /// injection: it is restarted like any crashed child): now if it runs, as
    /// soon as it runs again if it waits to be restarted. An unknown name, or a
    /// child that ended for good, is ignored.
    Kill(String),
}

/// How a launch ended.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LaunchReport {
    /// Processes started (not counting restarts).
    pub processes: usize,
    /// Restarts of crashed processes.
    pub restarts: u32,
    /// How each process ended last (`None`: by a signal).
    pub exits: Vec<(String, Option<i32>)>,
    /// Whether the caller (or Ctrl-C) stopped the launch.
    pub stopped: bool,
    /// A child that crashed and could not be restarted, which ended the
    /// launch: its name, how it ended (`None`: by a signal), and the restarts
    /// it had.
    pub lost: Option<(String, Option<i32>, u32)>,
    /// A child that exited with a fatal code ([`Launcher::fatal_codes`]),
    /// which ended the launch: its name and code.
    pub fatal: Option<(String, i32)>,
}

impl LaunchReport {
    /// Whether every process ended successfully.
    pub fn all_succeeded(&self) -> bool {
        self.exits.iter().all(|(_, c)| *c == Some(0))
    }
}

/// Why a launch could not run.
#[derive(Debug, thiserror::Error)]
pub enum LaunchError {
    /// A child could not be started.
    #[error("cannot start process `{process}` ({program}): {source}")]
    Spawn {
        /// The child.
        process: String,
        /// Its program.
        program: String,
        /// The OS's reason.
        source: std::io::Error,
    },
}

/// Starts the processes of a deployment and watches them.
#[derive(Debug)]
pub struct Launcher {
    children: Vec<Child>,
    max_restarts: u32,
    grace: Duration,
    fatal: Vec<i32>,
    restart_delay: Duration,
}

struct Running {
    child: std::process::Child,
    restarts: u32,
}

impl Launcher {
    /// A launcher for `children`; a crashed child is restarted up to 3 times,
    /// half a second after it ended.
    pub fn new(children: Vec<Child>) -> Self {
        Launcher {
            children,
            max_restarts: 3,
            grace: Duration::from_secs(5),
            fatal: Vec::new(),
            restart_delay: Duration::from_millis(500),
        }
    }

    /// How long after a crash the child is started again (a crash that
    /// repeats at once does not become a busy loop, and what the child held,
    /// a port for example, is released meanwhile).
    pub fn restart_delay(mut self, delay: Duration) -> Self {
        self.restart_delay = delay;
        self
    }

    /// Exit codes that mean "this will fail again" (a bad command line or
    /// configuration): a child that exits with one is not restarted, and the
    /// launch stops.
    pub fn fatal_codes(mut self, codes: impl IntoIterator<Item = i32>) -> Self {
        self.fatal = codes.into_iter().collect();
        self
    }

    /// How many times each child may be restarted after a crash (an exit with
    /// failure or by a signal that the launcher did not send).
    pub fn max_restarts(mut self, n: u32) -> Self {
        self.max_restarts = n;
        self
    }

    /// How long children have to end after SIGTERM before SIGKILL.
    pub fn grace(mut self, grace: Duration) -> Self {
        self.grace = grace;
        self
    }

    fn spawn(
        &self,
        k: usize,
        incarnation: u32,
        lines: &Sender<(usize, String)>,
    ) -> Result<std::process::Child, LaunchError> {
        use std::os::unix::process::CommandExt;
        let c = &self.children[k];
        let mut command = Command::new(&c.program);
        command.args(&c.args);
        if let Some(flag) = &c.incarnation_flag {
            command.arg(flag).arg(incarnation.to_string());
        }
        let mut child = command
            // A group of its own: stopping it stops what it started.
            .process_group(0)
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .map_err(|source| LaunchError::Spawn {
                process: c.name.clone(),
                program: c.program.display().to_string(),
                source,
            })?;
        if let Some(out) = child.stdout.take() {
            forward(k, out, lines.clone());
        }
        if let Some(err) = child.stderr.take() {
            forward(k, err, lines.clone());
        }
        Ok(child)
    }

    /// Start every child and watch them until all have ended. `on` sees every
    /// line and exit (and `Line::Idle` after each look, at least every 50 ms:
    /// the moment to watch something else); what it answers to a line or to
    /// `Idle` may stop the
    /// launch; so does `interrupted` (set it from a Ctrl-C handler).
    pub fn run(
        self,
        interrupted: &std::sync::atomic::AtomicBool,
        mut on: impl FnMut(&Line) -> Control,
    ) -> Result<LaunchReport, LaunchError> {
        let (tx, rx) = channel::<(usize, String)>();
        let mut running: Vec<Option<Running>> = Vec::new();
        let mut report = LaunchReport {
            processes: self.children.len(),
            ..LaunchReport::default()
        };
        let mut exits: Vec<Option<Option<i32>>> = vec![None; self.children.len()];
        for k in 0..self.children.len() {
            match self.spawn(k, 0, &tx) {
                Ok(child) => running.push(Some(Running { child, restarts: 0 })),
                Err(e) => {
                    for r in running.iter_mut().flatten() {
                        let _ = r.child.kill();
                        let _ = r.child.wait();
                    }
                    return Err(e);
                }
            }
        }
        let mut stopping: Option<Instant> = None;
        let mut killed = false;
        // Children to start again, when, and their restarts so far.
        let mut due: Vec<Option<(Instant, u32)>> = vec![None; self.children.len()];
        // The caller's answers not yet acted on, and the kills asked for.
        let mut answers: Vec<Control> = Vec::new();
        let mut kills: Vec<usize> = Vec::new();
        loop {
            if let Ok((k, text)) = rx.recv_timeout(Duration::from_millis(50)) {
                answers.push(on(&Line::Output {
                    process: self.children[k].name.clone(),
                    text,
                }));
                // Drain what else is waiting before looking at the children.
                while let Ok((k, text)) = rx.try_recv() {
                    answers.push(on(&Line::Output {
                        process: self.children[k].name.clone(),
                        text,
                    }));
                }
            }
            answers.push(on(&Line::Idle));
            let mut stop = false;
            for answer in answers.drain(..) {
                match answer {
                    Control::Continue => {}
                    Control::Stop => stop = true,
                    Control::Kill(name) => {
                        kills.extend(self.children.iter().position(|c| c.name == name));
                    }
                }
            }
            kills.retain(|&k| match running[k].as_mut() {
                Some(r) => {
                    let _ = r.child.kill();
                    false
                }
                // Waiting to be restarted: killed once it runs again.
                None => due[k].is_some() && stopping.is_none(),
            });
            if (stop || interrupted.load(std::sync::atomic::Ordering::Relaxed))
                && stopping.is_none()
            {
                stopping = Some(Instant::now());
                report.stopped = true;
                for r in running.iter().flatten() {
                    terminate(&r.child);
                }
                due.fill(None);
            }
            for k in 0..due.len() {
                let Some((at, restarts)) = due[k] else {
                    continue;
                };
                if Instant::now() < at {
                    continue;
                }
                due[k] = None;
                match self.spawn(k, restarts, &tx) {
                    Ok(child) => {
                        report.restarts += 1;
                        running[k] = Some(Running { child, restarts });
                    }
                    Err(e) => {
                        // Leave nothing running behind an error.
                        self.stop_all(&mut running);
                        return Err(e);
                    }
                }
            }
            if let Some(since) = stopping
                && !killed
                && since.elapsed() > self.grace
            {
                killed = true;
                for r in running.iter_mut().flatten() {
                    kill_group(&mut r.child);
                }
            }
            for k in 0..running.len() {
                let Some(r) = running[k].as_mut() else {
                    continue;
                };
                let status: ExitStatus = match r.child.try_wait() {
                    Ok(Some(s)) => s,
                    Ok(None) => continue,
                    Err(_) => continue,
                };
                let code = status.code();
                let fatal = code.is_some_and(|c| self.fatal.contains(&c));
                let crashed = !status.success() && stopping.is_none();
                let budget = self.children[k].restarts.unwrap_or(self.max_restarts);
                let restarting = crashed && !fatal && r.restarts < budget;
                if fatal && stopping.is_none() {
                    report.fatal = code.map(|c| (self.children[k].name.clone(), c));
                }
                // A crash that may not be restarted ends the launch.
                let lost = crashed && !fatal && !restarting;
                if lost {
                    report.lost = Some((self.children[k].name.clone(), code, r.restarts));
                }
                if (fatal || lost) && stopping.is_none() {
                    stopping = Some(Instant::now());
                    for (j, other) in running.iter().enumerate() {
                        if let (true, Some(o)) = (j != k, other) {
                            terminate(&o.child);
                        }
                    }
                    due.fill(None);
                }
                let Some(r) = running[k].as_mut() else {
                    continue;
                };
                let restarts = r.restarts;
                answers.push(on(&Line::Exited {
                    process: self.children[k].name.clone(),
                    code,
                    restarting,
                }));
                exits[k] = Some(code);
                running[k] = None;
                if restarting {
                    due[k] = Some((Instant::now() + self.restart_delay, restarts + 1));
                }
            }
            if running.iter().all(Option::is_none) && due.iter().all(Option::is_none) {
                // The last lines of the children that ended.
                while let Ok((k, text)) = rx.recv_timeout(Duration::from_millis(100)) {
                    on(&Line::Output {
                        process: self.children[k].name.clone(),
                        text,
                    });
                }
                break;
            }
        }
        report.exits = self
            .children
            .iter()
            .zip(exits)
            .map(|(c, e)| (c.name.clone(), e.flatten()))
            .collect();
        Ok(report)
    }
}

impl Launcher {
    /// SIGTERM to every child still running, SIGKILL after the grace period,
    /// and wait for them.
    fn stop_all(&self, running: &mut [Option<Running>]) {
        for r in running.iter().flatten() {
            terminate(&r.child);
        }
        let until = Instant::now() + self.grace;
        for r in running.iter_mut().flatten() {
            while Instant::now() < until {
                if let Ok(Some(_)) = r.child.try_wait() {
                    break;
                }
                std::thread::sleep(Duration::from_millis(20));
            }
            kill_group(&mut r.child);
            let _ = r.child.wait();
        }
    }
}

/// SIGTERM to the child's process group: the child stops cleanly (ends its
/// run, prints its report, finishes its recording), and so does what it
/// started.
fn terminate(child: &std::process::Child) {
    use nix::sys::signal::{Signal, killpg};
    use nix::unistd::Pid;
    if let Ok(pid) = i32::try_from(child.id()) {
        let _ = killpg(Pid::from_raw(pid), Signal::SIGTERM);
    }
}

/// SIGKILL to the child's process group (the grace period is over).
fn kill_group(child: &mut std::process::Child) {
    use nix::sys::signal::{Signal, killpg};
    use nix::unistd::Pid;
    if let Ok(pid) = i32::try_from(child.id()) {
        let _ = killpg(Pid::from_raw(pid), Signal::SIGKILL);
    }
    let _ = child.kill();
}

fn forward(k: usize, stream: impl Read + Send + 'static, lines: Sender<(usize, String)>) {
    std::thread::spawn(move || {
        for line in BufReader::new(stream).lines() {
            let Ok(line) = line else { break };
            if lines.send((k, line)).is_err() {
                break;
            }
        }
    });
}
