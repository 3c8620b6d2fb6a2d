//! A run of Rex's listen mission beside our stand-in for a ROS 2 node that
//! gives it one plan (rex-agent's ros2_plans and ros2_secure, each including
//! this file with `#[path]`).

use std::process::Output;
use std::time::Duration;

use serde_json::Value;

/// Say how long `command`'s run `out` took (`took`) and the node's timings in
/// its `answer`; check that the run exited 0 having acknowledged the one
/// plan it was given. Rex's stderr, and the context for failures (stdout,
/// stderr and the answer).
pub(crate) fn listened(
    command: &str,
    out: &Output,
    took: Duration,
    answer: &Value,
) -> (String, String) {
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);
    eprintln!(
        "{command} ran {:.1} s; the node put the plan {} s after it started, saw its final ack and outcome {} s later\n{stderr}",
        took.as_secs_f64(),
        answer["ready_to_put_s"],
        answer["plan_to_done_s"]
    );
    let context = format!("{stdout}\n{stderr}\n{answer}");
    assert!(out.status.success(), "{context}");
    let summary = stdout.lines().last().unwrap_or_default();
    assert!(
        summary.starts_with("mission=listen plans_acked=1/1 "),
        "{context}"
    );
    (stderr.into_owned(), context)
}
