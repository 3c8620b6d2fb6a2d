//! Starting every process of a deployment: children with their output
//! prefixed and collected, a crashed one restarted, all stopped together.

use std::io::{BufRead, BufReader, Read};
use std::path::PathBuf;
use std::process::{Command, ExitStatus, Stdio};
use std::sync::mpsc::{Receiver, Sender, channel};
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
        let mut launch = Launch::start(&self)?;
        loop {
            launch.take_lines(&mut on);
            let stop = launch.take_answers();
            launch.kill_asked();
            if (stop || interrupted.load(std::sync::atomic::Ordering::Relaxed))
                && launch.stopping.is_none()
            {
                launch.stop();
            }
            launch.restart_due()?;
            launch.kill_after_grace();
            launch.reap(&mut on);
            if launch.all_ended() {
                launch.last_lines(&mut on);
                break;
            }
        }
        Ok(launch.report())
    }
}

/// A launch under way: its children running or waiting to be restarted, the
/// caller's answers, and how the launch is ending.
struct Launch<'l> {
    launcher: &'l Launcher,
    /// The children's lines, each with the child's index.
    tx: Sender<(usize, String)>,
    rx: Receiver<(usize, String)>,
    running: Vec<Option<Running>>,
    report: LaunchReport,
    /// How each child ended last, if it has (`Some(None)`: by a signal).
    exits: Vec<Option<Option<i32>>>,
    /// When the children were asked to stop, and whether the grace period
    /// is over (they were killed).
    stopping: Option<Instant>,
    killed: bool,
    /// Children to start again, when, and their restarts so far.
    due: Vec<Option<(Instant, u32)>>,
    /// The caller's answers not yet acted on, and the kills asked for.
    answers: Vec<Control>,
    kills: Vec<usize>,
}

impl<'l> Launch<'l> {
    /// Start every child of `launcher`; if one cannot start, those started
    /// are killed.
    fn start(launcher: &'l Launcher) -> Result<Launch<'l>, LaunchError> {
        let (tx, rx) = channel::<(usize, String)>();
        let n = launcher.children.len();
        let mut running: Vec<Option<Running>> = Vec::new();
        for k in 0..n {
            match launcher.spawn(k, 0, &tx) {
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
        Ok(Launch {
            launcher,
            tx,
            rx,
            running,
            report: LaunchReport {
                processes: n,
                ..LaunchReport::default()
            },
            exits: vec![None; n],
            stopping: None,
            killed: false,
            due: vec![None; n],
            answers: Vec::new(),
            kills: Vec::new(),
        })
    }

    fn name(&self, k: usize) -> String {
        self.launcher.children[k].name.clone()
    }

    /// The children's lines (waiting at most 50 ms for the first), then
    /// `Idle`, each shown to `on`.
    fn take_lines(&mut self, on: &mut impl FnMut(&Line) -> Control) {
        if let Ok((k, text)) = self.rx.recv_timeout(Duration::from_millis(50)) {
            self.answers.push(on(&Line::Output {
                process: self.name(k),
                text,
            }));
            // Drain what else is waiting before looking at the children.
            while let Ok((k, text)) = self.rx.try_recv() {
                self.answers.push(on(&Line::Output {
                    process: self.name(k),
                    text,
                }));
            }
        }
        self.answers.push(on(&Line::Idle));
    }

    /// The caller's answers taken: the kills asked for noted; whether one
    /// asked to stop.
    fn take_answers(&mut self) -> bool {
        let mut stop = false;
        for answer in self.answers.drain(..) {
            match answer {
                Control::Continue => {}
                Control::Stop => stop = true,
                Control::Kill(name) => {
                    self.kills
                        .extend(self.launcher.children.iter().position(|c| c.name == name));
                }
            }
        }
        stop
    }

    /// Kill the children asked for that run; one waiting to be restarted
    /// is killed once it runs again.
    fn kill_asked(&mut self) {
        let (running, due, stopping) = (&mut self.running, &self.due, self.stopping);
        self.kills.retain(|&k| match running[k].as_mut() {
            Some(r) => {
                let _ = r.child.kill();
                false
            }
            // Waiting to be restarted: killed once it runs again.
            None => due[k].is_some() && stopping.is_none(),
        });
    }

    /// Ask every child to stop (SIGTERM), and restart none.
    fn stop(&mut self) {
        self.stopping = Some(Instant::now());
        self.report.stopped = true;
        for r in self.running.iter().flatten() {
            terminate(&r.child);
        }
        self.due.fill(None);
    }

    /// Start again the children whose restart is due; if one cannot start,
    /// every child is stopped.
    fn restart_due(&mut self) -> Result<(), LaunchError> {
        for k in 0..self.due.len() {
            let Some((at, restarts)) = self.due[k] else {
                continue;
            };
            if Instant::now() < at {
                continue;
            }
            self.due[k] = None;
            match self.launcher.spawn(k, restarts, &self.tx) {
                Ok(child) => {
                    self.report.restarts += 1;
                    self.running[k] = Some(Running { child, restarts });
                }
                Err(e) => {
                    // Leave nothing running behind an error.
                    self.launcher.stop_all(&mut self.running);
                    return Err(e);
                }
            }
        }
        Ok(())
    }

    /// SIGKILL to every child once the grace period after the stop is over.
    fn kill_after_grace(&mut self) {
        if let Some(since) = self.stopping
            && !self.killed
            && since.elapsed() > self.launcher.grace
        {
            self.killed = true;
            for r in self.running.iter_mut().flatten() {
                kill_group(&mut r.child);
            }
        }
    }

    /// The children that ended, each shown to `on`: restarted if it crashed
    /// and may be; a fatal exit or a crash that may not be restarted stops
    /// the others.
    fn reap(&mut self, on: &mut impl FnMut(&Line) -> Control) {
        for k in 0..self.running.len() {
            let Some(r) = self.running[k].as_mut() else {
                continue;
            };
            let status: ExitStatus = match r.child.try_wait() {
                Ok(Some(s)) => s,
                Ok(None) => continue,
                Err(_) => continue,
            };
            let restarts = r.restarts;
            let code = status.code();
            let child = &self.launcher.children[k];
            let fatal = code.is_some_and(|c| self.launcher.fatal.contains(&c));
            let crashed = !status.success() && self.stopping.is_none();
            let budget = child.restarts.unwrap_or(self.launcher.max_restarts);
            let restarting = crashed && !fatal && restarts < budget;
            if fatal && self.stopping.is_none() {
                self.report.fatal = code.map(|c| (child.name.clone(), c));
            }
            // A crash that may not be restarted ends the launch.
            let lost = crashed && !fatal && !restarting;
            if lost {
                self.report.lost = Some((child.name.clone(), code, restarts));
            }
            if (fatal || lost) && self.stopping.is_none() {
                self.stop_others(k);
            }
            self.answers.push(on(&Line::Exited {
                process: self.name(k),
                code,
                restarting,
            }));
            self.exits[k] = Some(code);
            self.running[k] = None;
            if restarting {
                self.due[k] = Some((Instant::now() + self.launcher.restart_delay, restarts + 1));
            }
        }
    }

    /// Ask every child but `k` to stop (SIGTERM), and restart none.
    fn stop_others(&mut self, k: usize) {
        self.stopping = Some(Instant::now());
        for (j, other) in self.running.iter().enumerate() {
            if let (true, Some(o)) = (j != k, other) {
                terminate(&o.child);
            }
        }
        self.due.fill(None);
    }

    /// Whether every child has ended and none is to be restarted.
    fn all_ended(&self) -> bool {
        self.running.iter().all(Option::is_none) && self.due.iter().all(Option::is_none)
    }

    /// The last lines of the children that ended, shown to `on`.
    fn last_lines(&mut self, on: &mut impl FnMut(&Line) -> Control) {
        while let Ok((k, text)) = self.rx.recv_timeout(Duration::from_millis(100)) {
            on(&Line::Output {
                process: self.name(k),
                text,
            });
        }
    }

    /// The report, with how each child ended last.
    fn report(self) -> LaunchReport {
        let mut report = self.report;
        report.exits = self
            .launcher
            .children
            .iter()
            .zip(self.exits)
            .map(|(c, e)| (c.name.clone(), e.flatten()))
            .collect();
        report
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
