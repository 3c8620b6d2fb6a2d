//! The launcher with real child processes (`sh`): lines prefixed and collected,
//! a crashed child restarted, a fatal exit not restarted and the others stopped,
//! a stop ending every child (and what it started), a child that may not be
//! restarted or whose budget is spent ending the launch, each start told its
//! number.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::sync::atomic::AtomicBool;
use std::time::{Duration, Instant};

use agent_zenoh::{Child, Control, Launcher, Line};

fn sh(name: &str, script: &str) -> Child {
    Child::new(name, "sh", vec!["-c".into(), script.into()])
}

fn run(
    launcher: Launcher,
    mut stop_when: impl FnMut(&Line) -> bool,
) -> (agent_zenoh::LaunchReport, Vec<Line>) {
    let mut lines = Vec::new();
    let report = launcher
        .run(&AtomicBool::new(false), |l| {
            if *l != Line::Idle {
                lines.push(l.clone());
            }
            if stop_when(l) {
                Control::Stop
            } else {
                Control::Continue
            }
        })
        .unwrap();
    (report, lines)
}

#[test]
fn a_crashed_child_is_restarted_and_lines_are_collected() {
    let marker = std::env::temp_dir().join(format!("launcher-{}", std::process::id()));
    let _ = std::fs::remove_file(&marker);
    let script = format!(
        "if [ -e {m} ]; then echo second; exit 0; else touch {m}; echo first; exit 1; fi",
        m = marker.display()
    );
    let (report, lines) = run(
        Launcher::new(vec![sh("flaky", &script), sh("steady", "echo hello")]),
        |_| false,
    );
    assert_eq!(report.processes, 2);
    assert_eq!(report.restarts, 1, "{lines:?}");
    assert!(report.all_succeeded(), "{report:?}");
    let said = |p: &str, t: &str| {
        lines.contains(&Line::Output {
            process: p.into(),
            text: t.into(),
        })
    };
    assert!(said("flaky", "first") && said("flaky", "second") && said("steady", "hello"));
    assert!(lines.contains(&Line::Exited {
        process: "flaky".into(),
        code: Some(1),
        restarting: true
    }));
    let _ = std::fs::remove_file(&marker);
}

#[test]
fn a_fatal_exit_is_not_restarted_and_stops_the_others() {
    let started = Instant::now();
    let (report, lines) = run(
        Launcher::new(vec![
            sh("bad", "echo usage; exit 2"),
            sh("long", "sleep 30"),
        ])
        .fatal_codes([2])
        .grace(Duration::from_secs(2)),
        |_| false,
    );
    assert_eq!(report.restarts, 0, "{lines:?}");
    assert_eq!(report.exits[0], ("bad".into(), Some(2)));
    assert_ne!(report.exits[1].1, Some(0), "the other child was stopped");
    assert!(started.elapsed() < Duration::from_secs(20));
}

#[test]
fn a_stop_ends_every_child() {
    let started = Instant::now();
    let (report, _) = run(
        Launcher::new(vec![sh("a", "echo up; sleep 30"), sh("b", "sleep 30")])
            .grace(Duration::from_secs(2)),
        |l| matches!(l, Line::Output { text, .. } if text == "up"),
    );
    assert!(report.stopped);
    assert_eq!(report.restarts, 0, "stopped children are not restarted");
    assert!(started.elapsed() < Duration::from_secs(20));
}

#[test]
fn a_child_killed_on_request_is_restarted_as_a_crash() {
    // The child says `up`; the caller kills it (fault injection); the second
    // start finds the marker and ends cleanly.
    let marker = std::env::temp_dir().join(format!("launcher-kill-{}", std::process::id()));
    let _ = std::fs::remove_file(&marker);
    let script = format!(
        "if [ -e {m} ]; then echo again; exit 0; else touch {m}; echo up; sleep 30; fi",
        m = marker.display()
    );
    let started = Instant::now();
    let mut lines = Vec::new();
    let (mut exited, mut again) = (None, None);
    let report = Launcher::new(vec![sh("victim", &script), sh("other", "echo fine")])
        .restart_delay(Duration::from_millis(300))
        .run(&AtomicBool::new(false), |l| {
            if *l != Line::Idle {
                lines.push(l.clone());
            }
            match l {
                Line::Exited { process, .. } if process == "victim" && exited.is_none() => {
                    exited = Some(Instant::now());
                }
                Line::Output { text, .. } if text == "again" => again = Some(Instant::now()),
                _ => {}
            }
            match l {
                Line::Output { text, .. } if text == "up" => Control::Kill("victim".into()),
                // Unknown names are ignored.
                Line::Output { text, .. } if text == "fine" => Control::Kill("nobody".into()),
                _ => Control::Continue,
            }
        })
        .unwrap();
    assert_eq!(report.restarts, 1, "{lines:?}");
    assert!(lines.contains(&Line::Exited {
        process: "victim".into(),
        code: None,
        restarting: true
    }));
    assert!(lines.contains(&Line::Output {
        process: "victim".into(),
        text: "again".into()
    }));
    assert!(report.all_succeeded(), "{report:?}");
    let waited = again.unwrap() - exited.unwrap();
    assert!(
        waited >= Duration::from_millis(300),
        "restarted after {waited:?}"
    );
    assert!(started.elapsed() < Duration::from_secs(20));
    let _ = std::fs::remove_file(&marker);
}

#[test]
fn a_kill_asked_while_the_child_waits_to_restart_reaches_it_when_it_runs() {
    let marker = std::env::temp_dir().join(format!("launcher-late-kill-{}", std::process::id()));
    let _ = std::fs::remove_file(&marker);
    // Run 1 crashes; run 2 would sleep (it is killed as it starts); run 3 ends well.
    let script = format!(
        "n=$(cat {m} 2>/dev/null || echo 0); n=$((n+1)); echo $n > {m}; echo run$n; \
         if [ $n -eq 1 ]; then exit 1; fi; if [ $n -eq 2 ]; then sleep 30; fi; exit 0",
        m = marker.display()
    );
    let started = Instant::now();
    let mut lines = Vec::new();
    let report = Launcher::new(vec![sh("victim", &script)])
        .restart_delay(Duration::from_millis(200))
        .run(&AtomicBool::new(false), |l| {
            if *l != Line::Idle {
                lines.push(l.clone());
            }
            match l {
                // Asked while the child waits out its restart delay.
                Line::Exited {
                    code: Some(1),
                    restarting: true,
                    ..
                } => Control::Kill("victim".into()),
                _ => Control::Continue,
            }
        })
        .unwrap();
    assert_eq!(report.restarts, 2, "{lines:?}");
    assert!(lines.contains(&Line::Exited {
        process: "victim".into(),
        code: None,
        restarting: true
    }));
    assert!(lines.contains(&Line::Output {
        process: "victim".into(),
        text: "run3".into()
    }));
    assert!(report.all_succeeded(), "{report:?}");
    assert!(
        started.elapsed() < Duration::from_secs(20),
        "run 2 was killed"
    );
    let _ = std::fs::remove_file(&marker);
}

#[test]
fn a_crash_that_may_not_be_restarted_ends_the_launch_naming_the_child() {
    let started = Instant::now();
    let world = Child {
        restarts: Some(0),
        ..sh("world", "echo up; exit 1")
    };
    let (report, lines) = run(
        Launcher::new(vec![world, sh("long", "sleep 30")]).grace(Duration::from_secs(2)),
        |_| false,
    );
    assert_eq!(report.restarts, 0, "{lines:?}");
    assert_eq!(report.lost, Some(("world".into(), Some(1), 0)));
    assert!(lines.contains(&Line::Exited {
        process: "world".into(),
        code: Some(1),
        restarting: false
    }));
    assert_ne!(report.exits[1].1, Some(0), "the other child was stopped");
    assert!(started.elapsed() < Duration::from_secs(20));
}

#[test]
fn a_spent_restart_budget_ends_the_launch_and_each_start_knows_its_number() {
    let started = Instant::now();
    let crashing = Child {
        restarts: Some(2),
        incarnation_flag: Some("start".into()),
        // `sh -c SCRIPT start K`: $0 is `start`, $1 the start's number.
        ..Child::new(
            "crashing",
            "sh",
            vec!["-c".into(), "echo start=$1; exit 1".into()],
        )
    };
    let (report, lines) = run(
        Launcher::new(vec![crashing, sh("long", "sleep 30")])
            .restart_delay(Duration::from_millis(50))
            .grace(Duration::from_secs(2)),
        |_| false,
    );
    assert_eq!(report.restarts, 2, "{lines:?}");
    assert_eq!(report.lost, Some(("crashing".into(), Some(1), 2)));
    for k in 0..=2 {
        assert!(
            lines.contains(&Line::Output {
                process: "crashing".into(),
                text: format!("start={k}")
            }),
            "start {k}: {lines:?}"
        );
    }
    assert!(started.elapsed() < Duration::from_secs(20));
}

#[test]
fn stopping_a_child_stops_what_it_started() {
    let pidfile = std::env::temp_dir().join(format!("launcher-grandchild-{}", std::process::id()));
    let _ = std::fs::remove_file(&pidfile);
    // The child starts a grandchild that ignores nothing, and waits.
    let script = format!(
        "sleep 60 & echo $! > {p}; echo up; wait",
        p = pidfile.display()
    );
    let (report, _) = run(
        Launcher::new(vec![sh("parent", &script)]).grace(Duration::from_secs(2)),
        |l| matches!(l, Line::Output { text, .. } if text == "up"),
    );
    assert!(report.stopped);
    let pid: i32 = std::fs::read_to_string(&pidfile)
        .unwrap()
        .trim()
        .parse()
        .unwrap();
    // Reaped by init, or at least dead: no process of that pid runs `sleep`.
    let deadline = Instant::now() + Duration::from_secs(5);
    let alive =
        || std::fs::read_to_string(format!("/proc/{pid}/stat")).is_ok_and(|s| !s.contains(") Z "));
    while alive() && Instant::now() < deadline {
        std::thread::sleep(Duration::from_millis(50));
    }
    assert!(!alive(), "the grandchild {pid} outlived the stop");
    let _ = std::fs::remove_file(&pidfile);
}
