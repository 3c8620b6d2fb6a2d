//! `App::from_code`: a system built in code gets its spec exported from it, and
//! the deployments given to it are checked with that spec; a deployment that
//! does not parse, that omits components (each process runs the whole system
//! built in code), or that does not place every component is refused with
//! status 2 before anything runs.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use clap::Parser as _;
use embodied::app::{App, Cli, NoFlags, Status};

#[path = "../examples/lamp/lamp.rs"]
#[allow(dead_code, reason = "the example's module, whole")]
mod lamp;

fn check(app: App) -> Status {
    let mut app = app;
    let cli = Cli::<NoFlags>::try_parse_from(["lamp", "check", "--quiet"]).unwrap();
    embodied::app::run(&mut app, &cli)
}

#[test]
fn the_spec_of_a_system_built_in_code_is_exported_and_checked() {
    assert_eq!(check(App::from_code("lamp", lamp::system)), Status::Success);
    assert_eq!(
        check(App::from_code("lamp", lamp::system).deployment(lamp::SPLIT)),
        Status::Success
    );
    // Written as in a spec file: `secure: false`, not `secure: Some(false)`.
    assert_eq!(
        check(
            App::from_code("lamp", lamp::system)
                .deployment(lamp::SPLIT)
                .deployment(lamp::OPEN)
        ),
        Status::Success
    );
}

#[test]
fn bad_deployments_of_a_system_built_in_code_are_refused() {
    for bad in [
        // Not RON of a deployment.
        "(name: \"split\", hosts: [",
        "(name: \"split\", processes: [])",
        // Omits a component: every process runs the whole system.
        r#"(name: "part", hosts: [(name: "h", processes: [(name: "p", runs: ["c1", "e1"])])], omit: ["E1"])"#,
        // Places no process for E1.
        r#"(name: "some", hosts: [(name: "h", processes: [(name: "p", runs: ["c1", "e1"])])])"#,
        // A component that does not exist.
        r#"(name: "ghost", hosts: [(name: "h", processes: [(name: "p", runs: ["c1", "e1", "E1", "c9"])])])"#,
    ] {
        assert_eq!(
            check(App::from_code("lamp", lamp::system).deployment(bad)),
            Status::Invalid,
            "{bad}"
        );
    }
}

#[test]
fn a_system_that_does_not_build_is_a_failure_named_before_anything_runs() {
    let app = App::from_code("broken", || Err("no lamp attached".into()));
    assert_ne!(check(app), Status::Success);
}
