//! The router of a secure deployment's ROS 2 side (what rmw_zenohd is), run
//! by a Python script of the interoperability tests (`SCRIPT router CONFIG`,
//! tests/interop/ros2_side.py's `serve_router`): opened from the generated
//! configuration file, it says `ready` once it listens, then writes Zenoh's
//! access-control trace until its stdin closes. Its output is collected.
//!
//! Shared by agent-ros2's access_interop and rex-agent's ros2_secure, each
//! including it with `#[path]`.

#![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The router, running; its output collected. Killed if the test fails
/// before its end.
pub(crate) struct Router {
    child: Child,
    log: Arc<Mutex<Vec<String>>>,
}

impl Router {
    /// Start `script router config` and wait until it listens.
    pub(crate) fn start(python: &Path, script: &str, config: &Path) -> Router {
        let mut child = Command::new(python)
            .args([script, "router"])
            .arg(config)
            .env(
                "RUST_LOG",
                "error,zenoh::net::routing::interceptor::access_control=trace",
            )
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let out = BufReader::new(child.stdout.take().unwrap());
        let log = Arc::new(Mutex::new(Vec::new()));
        let (ready, started) = std::sync::mpsc::channel();
        let lines = log.clone();
        std::thread::spawn(move || {
            for line in out.lines().map_while(Result::ok) {
                if line.trim() == "ready" {
                    let _ = ready.send(());
                }
                lines.lock().unwrap().push(line);
            }
        });
        assert!(
            started.recv_timeout(Duration::from_secs(20)).is_ok(),
            "the router did not start: {:?}",
            log.lock().unwrap()
        );
        Router { child, log }
    }

    /// Stop it (its stdin closed, 10 s at most); its log.
    pub(crate) fn stop(mut self) -> Vec<String> {
        drop(self.child.stdin.take());
        let deadline = Instant::now() + Duration::from_secs(10);
        while self.child.try_wait().unwrap().is_none() && Instant::now() < deadline {
            std::thread::sleep(Duration::from_millis(50));
        }
        self.log.lock().unwrap().clone()
    }
}

impl Drop for Router {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// The refusals in the router's log: (the common name of the certificate of
/// the session refused, if it has a subject; what; key). Zenoh says
/// `<zid> on ...+CertCommonName(<cn>)+... is unauthorized to <what> on
/// <key>`, or `Using cached result: <zid> is unauthorized to ...`, and
/// `<zid> did not match any configured ACL subject` for a certificate it
/// does not know.
pub(crate) fn refusals(log: &[String]) -> Vec<(Option<String>, String, String)> {
    let plain: Vec<String> = log.iter().map(|l| strip_ansi(l)).collect();
    let mut names = std::collections::HashMap::new();
    let messages: Vec<&str> = plain
        .iter()
        .filter_map(|l| l.split_once("access_control: ").map(|(_, m)| m))
        .collect();
    for m in &messages {
        if let (Some((zid, _)), Some((_, cn))) =
            (m.split_once(" on "), m.split_once("CertCommonName("))
        {
            let cn = cn.split(')').next().unwrap_or_default();
            names.insert(zid.to_owned(), cn.to_owned());
        }
    }
    messages
        .iter()
        .filter_map(|m| {
            let (who, rest) = m.split_once(" is unauthorized to ")?;
            let (what, key) = rest.rsplit_once(" on ")?;
            let zid = who.trim_start_matches("Using cached result: ");
            let zid = zid.split(' ').next().unwrap_or_default();
            Some((names.get(zid).cloned(), what.to_owned(), key.to_owned()))
        })
        .collect()
}

/// `line` without its terminal colours.
fn strip_ansi(line: &str) -> String {
    let mut out = String::new();
    let mut chars = line.chars();
    while let Some(c) = chars.next() {
        if c == '\u{1b}' {
            for c in chars.by_ref() {
                if c.is_ascii_alphabetic() {
                    break;
                }
            }
        } else {
            out.push(c);
        }
    }
    out
}
