//! `embodied export --ros2`: a recording of the tank example exported for
//! ROS 2 tools. The command writes an MCAP file of profile `ros2` with the
//! recording's CDR channels, says what it wrote and names every channel it
//! left out with the reason; exit 1 when it cannot export (no ROS 2 channel,
//! an output it cannot write), 2 for invalid input (a missing file, another
//! kind of file, no `--ros2`).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

#[path = "common/tank_run.rs"]
#[allow(dead_code, reason = "the other recording tests use the rest")]
mod tank_run;

use std::path::Path;
use std::process::Command;
use std::time::Duration;

use embodied::record::{McapRecorder, RecordOptions, Recording, Values, mcap};
use embodied::*;

use tank_run::{system, tmp};

fn embodied(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_embodied"))
        .args(args)
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

/// Record 5 s of the tank example to `name`, its values as `values`.
fn record(name: &str, values: Values) -> String {
    let path = tmp(name);
    let options = RecordOptions {
        values,
        ..RecordOptions::default()
    };
    let recorder = McapRecorder::create(&path, &system(), options).unwrap();
    let mut exec = Executor::with_observer(system(), ExecConfig::default(), recorder);
    exec.run_for(Duration::from_secs(5)).unwrap();
    exec.into_observer().finish().unwrap();
    path.to_str().unwrap().to_owned()
}

#[test]
fn a_recording_exports_for_ros_2_and_the_command_names_what_it_left_out() {
    let source = record("tank_export.mcap", Values::Cdr);
    let out = tmp("tank_ros2.mcap");
    let (code, stdout, stderr) =
        embodied(&["export", &source, "-o", out.to_str().unwrap(), "--ros2"]);
    assert_eq!(code, 0, "{stdout}{stderr}");

    let recording = Recording::open(Path::new(&source)).unwrap();
    let cdr: Vec<&str> = recording
        .channels
        .values()
        .filter(|c| c.message_encoding == "cdr")
        .map(|c| c.topic.as_str())
        .collect();
    assert!(!cdr.is_empty());
    let exported = Recording::open(&out).unwrap();
    let topics: Vec<&str> = exported
        .channels
        .values()
        .map(|c| c.topic.as_str())
        .collect();
    assert_eq!(topics.len(), cdr.len(), "{topics:?} {cdr:?}");
    assert!(cdr.iter().all(|t| topics.contains(t)), "{topics:?} {cdr:?}");
    let bytes = std::fs::read(&out).unwrap();
    let header = mcap::read::LinearReader::new(&bytes)
        .unwrap()
        .find_map(|r| match r.unwrap() {
            mcap::records::Record::Header(h) => Some(h),
            _ => None,
        })
        .unwrap();
    assert_eq!(header.profile, "ros2");

    // What it wrote, and every channel left out, by name, with the reason.
    assert!(
        stdout.starts_with(&format!(
            "{}: profile ros2, {} ROS 2 channels, {} messages,",
            out.display(),
            cdr.len(),
            exported.messages.len()
        )),
        "{stdout}"
    );
    let left_out = recording.channels.len() - cdr.len();
    assert!(
        stdout.contains(&format!("left out {left_out} channels that are not ROS 2")),
        "{stdout}"
    );
    assert!(
        stdout.contains("its messages are `json`, not CDR"),
        "{stdout}"
    );
    assert!(
        stdout.contains("its messages are `embodied-wire-frames/1`, not CDR"),
        "{stdout}"
    );
    for c in recording
        .channels
        .values()
        .filter(|c| c.message_encoding != "cdr")
    {
        assert!(
            stdout.contains(&format!("    {}\n", c.topic)),
            "{}: {stdout}",
            c.topic
        );
    }
}

#[test]
fn what_cannot_be_exported_exits_1_and_invalid_input_2() {
    let out = tmp("tank_refused.mcap");
    let out = out.to_str().unwrap();

    let (code, _, stderr) = embodied(&["export", "/no/such/run.mcap", "-o", out, "--ros2"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("/no/such/run.mcap"), "{stderr}");
    let text = tmp("tank_not_mcap.txt");
    std::fs::write(&text, "not a recording").unwrap();
    let (code, _, stderr) = embodied(&["export", text.to_str().unwrap(), "-o", out, "--ros2"]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("is not an MCAP file"), "{stderr}");

    let source = record("tank_export_json.mcap", Values::Json);
    let (code, _, stderr) = embodied(&["export", &source, "-o", out]);
    assert_eq!(code, 2, "{stderr}");
    assert!(stderr.contains("--ros2"), "{stderr}");
    let (code, _, stderr) = embodied(&["export", &source, "-o", out, "--ros2"]);
    assert_eq!(code, 1, "{stderr}");
    assert!(stderr.contains("no ROS 2 channel"), "{stderr}");
    assert!(!Path::new(out).exists());

    let cdr = record("tank_export_cdr.mcap", Values::Cdr);
    let (code, _, stderr) = embodied(&["export", &cdr, "-o", "/no/such/folder/x.mcap", "--ros2"]);
    assert_eq!(code, 1, "{stderr}");
    assert!(
        stderr.contains("writing /no/such/folder/x.mcap"),
        "{stderr}"
    );
}
