//! A Python script of the interoperability tests (our stand-in for a ROS 2
//! node), running as a child process that the test speaks to in lines: it
//! reads requests on stdin (JSON, or a word), says `ready` once it listens
//! and answers each request with one JSON line on stdout; its stderr is the
//! test's. It is killed if the test fails before its end.
//!
//! Shared by the ROS 2 interoperability tests of agent-ros2 and rex-agent,
//! each including it with `#[path]`.

#![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

use std::fmt::Display;
use std::io::{BufRead, BufReader, Write as _};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};

use serde_json::Value;

/// A localhost TCP port free a moment ago.
pub(crate) fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port()
}

/// The script, running.
pub(crate) struct Script {
    name: &'static str,
    child: Child,
    to: ChildStdin,
    from: BufReader<ChildStdout>,
}

impl Script {
    /// Start `command` (the interpreter, the script and its arguments) with
    /// its stdin and stdout piped; `name` says what it is in failures ("the
    /// listener").
    pub(crate) fn start(command: &mut Command, name: &'static str) -> Self {
        let mut child = command
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::inherit())
            .spawn()
            .unwrap();
        let to = child.stdin.take().unwrap();
        let from = BufReader::new(child.stdout.take().unwrap());
        Self {
            name,
            child,
            to,
            from,
        }
    }

    /// Send it `line`: a request (JSON) or a word.
    pub(crate) fn send(&mut self, line: impl Display) {
        writeln!(self.to, "{line}").unwrap();
    }

    /// Wait until it says `ready`.
    pub(crate) fn ready(&mut self) {
        let line = self.read();
        assert_eq!(line.trim(), "ready", "{} did not start", self.name);
    }

    /// Send it `request`; its answer.
    pub(crate) fn ask(&mut self, request: impl Display) -> Value {
        self.send(request);
        let line = self.read();
        serde_json::from_str(&line).unwrap_or_else(|e| panic!("{}: {e}: {line:?}", self.name))
    }

    /// Send it `request`, its last; its answer, once it has exited
    /// successfully.
    pub(crate) fn end(&mut self, request: impl Display) -> Value {
        let answer = self.ask(request);
        assert!(self.child.wait().unwrap().success(), "{}", self.name);
        answer
    }

    /// Its next line.
    fn read(&mut self) -> String {
        let mut line = String::new();
        self.from.read_line(&mut line).unwrap();
        line
    }
}

impl Drop for Script {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
