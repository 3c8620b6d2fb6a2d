//! The runtime under faults, tried as a careless or hostile user would, with
//! real processes and real Zenoh sessions: two launches on the same ports
//! never mix (the second is refused, naming the endpoint and who holds it);
//! nothing outlives its launcher; the spec says what may be restarted, and a
//! crash beyond that ends the launch naming the process; a recording survives a
//! restart and each start replays; every stop (SIGINT, SIGTERM) ends with the
//! summary, the timing table and a finished recording; a full disk is named;
//! a process waiting for its peers stops on a signal, and one stopped by a
//! signal mid-run exits 1; bad command lines are refused with status 2.
//!
//! The launches run one at a time (each is several real-time processes).

#![cfg(feature = "distributed")]
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::path::PathBuf;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

const MISSION: &str = r#"(
    name: "short",
    plans: [[(x: 1.0, y: 0.0), (x: 1.5, y: 0.5)], [(x: 1.0, y: 1.0), (x: 0.0, y: 1.0)]],
)"#;

/// A folder of this test's own.
fn scratch(name: &str) -> PathBuf {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join(format!("faults-{name}"));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn mission(dir: &std::path::Path) -> String {
    let path = dir.join("short.ron");
    std::fs::write(&path, MISSION).unwrap();
    path.display().to_string()
}

/// One launch at a time: each runs real-time processes on every core.
static ONE_AT_A_TIME: std::sync::Mutex<()> = std::sync::Mutex::new(());

fn one_at_a_time() -> std::sync::MutexGuard<'static, ()> {
    ONE_AT_A_TIME
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

fn rex(args: &[&str]) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_rex"));
    c.args(args).stdout(Stdio::piped()).stderr(Stdio::piped());
    c
}

fn said(out: &Output) -> (Option<i32>, String, String) {
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Send `signal` (`INT`, `TERM`, `KILL`) to `pid`.
fn signal(pid: u32, signal: &str) {
    let ok = Command::new("kill")
        .args([&format!("-{signal}"), &pid.to_string()])
        .status()
        .unwrap()
        .success();
    assert!(ok, "kill -{signal} {pid}");
}

/// Whether process `pid` runs (a zombie does not).
fn alive(pid: u32) -> bool {
    std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|s| {
        s.rsplit_once(") ")
            .is_some_and(|(_, rest)| !rest.starts_with('Z'))
    })
}

/// The processes whose parent is `pid`.
fn children_of(pid: u32) -> Vec<u32> {
    let mut out = Vec::new();
    for entry in std::fs::read_dir("/proc").unwrap().flatten() {
        let Some(child) = entry
            .file_name()
            .to_str()
            .and_then(|n| n.parse::<u32>().ok())
        else {
            continue;
        };
        let Ok(stat) = std::fs::read_to_string(format!("/proc/{child}/stat")) else {
            continue;
        };
        // `pid (comm) state ppid ...`: the fields after the command's `)`.
        let ppid = stat
            .rsplit_once(") ")
            .and_then(|(_, rest)| rest.split_whitespace().nth(1)?.parse::<u32>().ok());
        if ppid == Some(pid) {
            out.push(child);
        }
    }
    out
}

/// Wait until `cond` holds, at most `limit`.
fn wait_for(limit: Duration, mut cond: impl FnMut() -> bool) -> bool {
    let start = Instant::now();
    while start.elapsed() < limit {
        if cond() {
            return true;
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    cond()
}

fn launch_args<'a>(port: &'a str, mission: &'a str) -> Vec<&'a str> {
    vec![
        "launch",
        "--deployment",
        "split_without_vo",
        "--no-vo",
        "--no-report",
        "--quiet",
        "--port",
        port,
        "--limit",
        "60",
        "--mission",
        mission,
    ]
}

#[test]
fn a_second_launch_on_the_same_ports_is_refused_and_the_first_goes_on() {
    let _one = one_at_a_time();
    let dir = scratch("two-launches");
    let mission = mission(&dir);
    let first: Child = rex(&launch_args("17700", &mission)).spawn().unwrap();
    // The first launch's world listens on 17700 once it is up.
    assert!(
        wait_for(Duration::from_secs(30), || {
            std::net::TcpListener::bind("127.0.0.1:17700").is_err()
        }),
        "the first launch came up"
    );
    let (code, stdout, stderr) = said(&rex(&launch_args("17700", &mission)).output().unwrap());
    assert_eq!(code, Some(2), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("cannot listen on tcp/127.0.0.1:1770")
            && stderr.contains("the address is in use (by pid")
            && stderr.contains("the launch ended"),
        "the endpoint and who holds it:\n{stderr}"
    );
    assert!(!stdout.contains("plans_acked"), "nothing judged: {stdout}");
    let (code, stdout, stderr) = said(&first.wait_with_output().unwrap());
    assert_eq!(
        code,
        Some(0),
        "the first launch is its own:\n{stdout}\n{stderr}"
    );
    assert!(
        stdout
            .lines()
            .last()
            .is_some_and(|l| l.starts_with("mission=short plans_acked=2/2")),
        "{stdout}"
    );
}

#[test]
fn killing_the_launcher_ends_every_process_it_started() {
    let _one = one_at_a_time();
    let dir = scratch("orphans");
    let mission = mission(&dir);
    let launcher = rex(&launch_args("17720", &mission)).spawn().unwrap();
    let pid = launcher.id();
    let mut children = Vec::new();
    assert!(
        wait_for(Duration::from_secs(30), || {
            children = children_of(pid);
            children.len() == 2
        }),
        "the launcher started its two processes: {children:?}"
    );
    std::thread::sleep(Duration::from_secs(3));
    signal(pid, "KILL");
    let _ = launcher.wait_with_output();
    assert!(
        wait_for(Duration::from_secs(10), || children
            .iter()
            .all(|c| !alive(*c))),
        "children outlived their launcher: {:?}",
        children.iter().filter(|c| alive(**c)).collect::<Vec<_>>()
    );
    // Their ports are free again.
    assert!(wait_for(Duration::from_secs(5), || {
        std::net::TcpListener::bind("127.0.0.1:17720").is_ok()
    }));
}

#[test]
fn the_world_is_never_restarted_its_crash_ends_the_launch() {
    let _one = one_at_a_time();
    let dir = scratch("world");
    let mission = mission(&dir);
    let mut args = launch_args("17740", &mission);
    args.extend(["--kill", "world@3"]);
    let (code, stdout, stderr) = said(&rex(&args).output().unwrap());
    assert_eq!(code, Some(1), "{stdout}\n{stderr}");
    assert!(
        stdout.contains(
            "process `world` ended (killed by a signal) and may not be restarted (`restarts: 0` in the spec)"
        ),
        "{stdout}"
    );
    assert!(
        stderr.contains("[world] exited (killed by a signal)\n"),
        "{stderr}"
    );
    assert!(!stderr.contains("[world] exited (killed by a signal); restarting it"));
    assert!(
        stdout
            .lines()
            .last()
            .unwrap_or_default()
            .ends_with("restarts=0")
    );
}

#[test]
fn a_spent_restart_budget_ends_the_launch_naming_the_process() {
    let _one = one_at_a_time();
    let dir = scratch("budget");
    let mission = mission(&dir);
    let mut args = launch_args("17760", &mission);
    // The spec gives locomotion the default budget of 3 restarts.
    let kills = [
        "locomotion@3",
        "locomotion@7",
        "locomotion@11",
        "locomotion@15",
    ];
    for kill in kills {
        args.extend(["--kill", kill]);
    }
    let started = Instant::now();
    let (code, stdout, stderr) = said(&rex(&args).output().unwrap());
    assert_eq!(code, Some(1), "{stdout}\n{stderr}");
    assert!(
        stdout.contains(
            "process `locomotion` ended (killed by a signal) after 3 restarts, all the spec allows (`restarts: 3`)"
        ),
        "{stdout}\n{stderr}"
    );
    assert!(
        stdout
            .lines()
            .last()
            .unwrap_or_default()
            .ends_with("restarts=3")
    );
    assert!(
        started.elapsed() < Duration::from_secs(50),
        "the launch ended then"
    );
}

#[test]
fn a_recording_survives_a_restart_and_each_start_replays() {
    let _one = one_at_a_time();
    let dir = scratch("restart-record");
    let mission = mission(&dir);
    let record = dir.join("run.mcap");
    let record = record.to_str().unwrap();
    let mut args = launch_args("17780", &mission);
    args.extend(["--record", record, "--kill", "locomotion@4"]);
    let (code, stdout, stderr) = said(&rex(&args).output().unwrap());
    assert_eq!(code, Some(0), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("(merged from 2 processes and 1 restarts:"),
        "{stdout}"
    );
    assert!(
        stdout.contains("record: a part cut short, kept up to there:")
            && stdout.contains("run.locomotion.mcap is truncated"),
        "the killed start's part is kept and said: {stdout}"
    );
    for part in [
        "run.world.mcap",
        "run.locomotion.mcap",
        "run.locomotion.1.mcap",
    ] {
        assert!(dir.join(part).is_file(), "{part}");
    }
    let merged = embodied::record::Recording::open(std::path::Path::new(record)).unwrap();
    assert!(
        merged.metadata["restarts"]["starts"].contains("locomotion#1"),
        "{:?}",
        merged.metadata.keys()
    );
    // c1 ran in locomotion: its second start replays from the instant it
    // joined; the first was killed before its recorder finished.
    let (code, stdout, stderr) = said(
        &rex(&["replay", record, "--subsystem", "c1"])
            .output()
            .unwrap(),
    );
    assert_eq!(code, Some(0), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("replay c1 (start 0 of process `locomotion`): not replayed")
            && stdout.contains("replay c1 (start 1 of process `locomotion`): equivalent"),
        "{stdout}\n{stderr}"
    );
    // c2 ran in the world, which was not restarted.
    let (code, stdout, stderr) = said(
        &rex(&["replay", record, "--subsystem", "c2"])
            .output()
            .unwrap(),
    );
    assert_eq!(code, Some(0), "{stdout}\n{stderr}");
    assert!(
        stdout.contains("replay c2: equivalent"),
        "{stdout}\n{stderr}"
    );
}

#[test]
fn sigint_or_sigterm_end_a_real_time_run_with_its_summary_and_recording() {
    let _one = one_at_a_time();
    for sig in ["INT", "TERM"] {
        let dir = scratch(&format!("signal-{sig}"));
        let record = dir.join("run.mcap");
        let child = rex(&["--realtime", "--no-vo", "--no-report", "--limit", "120"])
            .args(["--mission", "square", "--record"])
            .arg(&record)
            .spawn()
            .unwrap();
        std::thread::sleep(Duration::from_secs(5));
        signal(child.id(), sig);
        let started = Instant::now();
        let (code, stdout, stderr) = said(&child.wait_with_output().unwrap());
        assert!(
            started.elapsed() < Duration::from_secs(20),
            "SIG{sig}: it stopped"
        );
        assert_eq!(
            code,
            Some(1),
            "SIG{sig}: stopped before its end\n{stdout}\n{stderr}"
        );
        assert!(
            stdout.contains(&format!(
                "the run was stopped before its end: SIG{sig} received"
            )),
            "{stdout}"
        );
        assert!(stdout.contains("rt_priority="), "{stdout}");
        assert!(stderr.contains("jit_p99"), "the timing table: {stderr}");
        assert!(
            stdout
                .lines()
                .last()
                .is_some_and(|l| l.starts_with("mission=square plans_acked=")),
            "the summary: {stdout}"
        );
        let r = embodied::record::Recording::open(&record).unwrap();
        assert!(r.finished(), "SIG{sig}: the recording is finished");
    }
}

#[test]
fn a_process_waiting_for_its_peers_stops_on_sigint() {
    let _one = one_at_a_time();
    let dir = scratch("waiting");
    let mission = mission(&dir);
    let child = rex(&[
        "--deployment",
        "split_without_vo",
        "--process",
        "locomotion",
        "--no-vo",
        "--port",
        "17800",
        "--wait",
        "1000",
        "--mission",
        &mission,
    ])
    .spawn()
    .unwrap();
    std::thread::sleep(Duration::from_secs(3));
    signal(child.id(), "INT");
    let started = Instant::now();
    let (code, stdout, stderr) = said(&child.wait_with_output().unwrap());
    assert!(
        started.elapsed() < Duration::from_secs(5),
        "it stopped waiting"
    );
    assert_eq!(code, Some(1), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("stopped while waiting for") && stderr.contains("`world`"),
        "{stderr}"
    );
}

/// A process of a deployment stopped by a signal in the middle of its run
/// (not by the deployment's end) exits 1, as a run in one process does, and
/// finishes its recording: a launcher would take it for a crash.
#[test]
fn a_process_stopped_by_a_signal_mid_run_exits_1_with_its_recording() {
    let _one = one_at_a_time();
    let dir = scratch("process-signal");
    let mission = mission(&dir);
    let record = dir.join("locomotion.mcap");
    let process = |name: &str| {
        let mut c = rex(&["--deployment", "split_without_vo", "--process", name]);
        c.args([
            "--no-vo",
            "--no-report",
            "--port",
            "17960",
            "--limit",
            "120",
        ])
        .args(["--mission", &mission]);
        c
    };
    let world = process("world").spawn().unwrap();
    let locomotion = process("locomotion")
        .arg("--record")
        .arg(&record)
        .spawn()
        .unwrap();
    // Both come up, agree on instant zero and run for a while.
    std::thread::sleep(Duration::from_secs(10));
    for (name, child) in [("locomotion", locomotion), ("world", world)] {
        signal(child.id(), "TERM");
        let (code, stdout, stderr) = said(&child.wait_with_output().unwrap());
        assert_eq!(
            code,
            Some(1),
            "{name}: stopped before its end\n{stdout}\n{stderr}"
        );
        assert!(
            stderr.contains(&format!("process `{name}` stopped: SIGTERM received")),
            "{name}: {stderr}"
        );
    }
    let r = embodied::record::Recording::open(&record).unwrap();
    assert!(r.finished(), "the recording is finished");
    assert!(!r.messages.is_empty(), "it recorded the run");
}

#[test]
fn a_full_disk_is_named_and_the_summary_still_printed() {
    // `/dev/full` fails every write as a full disk does.
    if !std::path::Path::new("/dev/full").exists() {
        eprintln!("no /dev/full here: skipped");
        return;
    }
    let (code, stdout, stderr) = said(
        &rex(&["--no-vo", "--no-report", "--quiet", "--limit", "3"])
            .args(["--mission", "square", "--record", "/dev/full"])
            .output()
            .unwrap(),
    );
    assert_eq!(code, Some(1), "{stdout}\n{stderr}");
    assert!(
        stderr.contains("recording /dev/full") && stderr.contains("reached 0 bytes"),
        "the file and what it reached: {stderr}"
    );
    assert!(
        stderr.contains("is not a regular file: left as it is"),
        "a device is never removed: {stderr}"
    );
    assert!(
        stdout
            .lines()
            .last()
            .is_some_and(|l| l.starts_with("mission=square plans_acked=")),
        "the summary: {stdout}"
    );
    assert!(std::path::Path::new("/dev/full").exists());
}

#[test]
fn bad_command_lines_are_refused_with_status_2() {
    let dir = scratch("refused");
    let mission = mission(&dir);
    let record_dir = dir.display().to_string();
    let cases: Vec<(Vec<&str>, &str)> = vec![
        (
            vec![
                "launch",
                "--deployment",
                "split_without_vo",
                "--no-vo",
                "--record",
                &record_dir,
            ],
            "is a folder",
        ),
        (
            vec![
                "launch",
                "--deployment",
                "split_without_vo",
                "--no-vo",
                "--port",
                "65535",
            ],
            "must lie within 1024-65535",
        ),
        (
            vec![
                "launch",
                "--deployment",
                "split_without_vo",
                "--no-vo",
                "--port",
                "1",
            ],
            "must lie within 1024-65535",
        ),
        (
            vec!["--deployment", "split_without_vo", "--no-vo"],
            "with `launch` (every process) or with `--process NAME`",
        ),
        (
            vec!["launch", "--deployment", "split", "--no-vo"],
            "deployment `split` runs the visual odometry",
        ),
        (
            vec!["replay", "x.mcap", "--subsystem", "c1", "--limit", "3"],
            "--for/--limit is not for a replay",
        ),
        (
            vec!["--no-vo", "--out", "/"],
            "--out /: is the file system's root",
        ),
        (
            vec![
                "launch",
                "--deployment",
                "split_without_vo",
                "--no-vo",
                "--kill",
                "nobody@1",
            ],
            "has no process `nobody`",
        ),
    ];
    for (args, expected) in cases {
        let mut all = args.clone();
        all.extend(["--mission", &mission]);
        let (code, stdout, stderr) = said(&rex(&all).output().unwrap());
        assert_eq!(code, Some(2), "{args:?}:\n{stdout}\n{stderr}");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
    }
}
