//! The Zenoh scaling benchmark (`examples/bench_zenoh_scale/`) runs in its
//! quick form (K = 2 and 4 processes, one host, a ring, a second's window) and
//! prints its lines in their shape, with finite positive latencies.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::path::PathBuf;
use std::process::Command;

/// The example's binary: the one `cargo test` built beside this test (it
/// builds the examples, with the same features), or, if there is none or it is
/// older than one of its sources (`cargo test --test bench_zenoh_scale` builds
/// no example), one built now by this test's cargo.
fn example() -> PathBuf {
    let built = std::env::current_exe()
        .unwrap()
        .parent()
        .and_then(|deps| deps.parent())
        .map(|profile| profile.join("examples/bench_zenoh_scale"));
    let sources = concat!(env!("CARGO_MANIFEST_DIR"), "/examples/bench_zenoh_scale");
    let modified = |p: &std::path::Path| std::fs::metadata(p).and_then(|m| m.modified()).ok();
    let newest_source = std::fs::read_dir(sources)
        .ok()
        .and_then(|files| files.filter_map(|f| modified(&f.ok()?.path())).max());
    if let Some(exe) = built
        && let (Some(e), Some(s)) = (modified(&exe), newest_source)
        && e >= s
    {
        return exe;
    }
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .args([
            "build",
            "--quiet",
            "-p",
            "agent-zenoh",
            "--example",
            "bench_zenoh_scale",
            "--message-format=json",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .expect("cargo runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    // The executable of the example, from cargo's messages.
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter(|l| l.contains("\"bench_zenoh_scale\""))
        .find_map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).ok()?;
            Some(PathBuf::from(v.get("executable")?.as_str()?))
        })
        .expect("cargo names the example's executable")
}

fn value<'a>(line: &'a str, name: &str) -> &'a str {
    line.split_whitespace()
        .find_map(|w| w.strip_prefix(name)?.strip_prefix('='))
        .unwrap_or_else(|| panic!("no `{name}=` in `{line}`"))
}

#[test]
fn the_quick_scaling_benchmark_prints_a_line_per_k_and_the_ratio() {
    let out = Command::new(example())
        .arg("--quick")
        .output()
        .expect("the example runs");
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert!(
        out.status.success(),
        "{text}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines.len(), 3, "{text}");
    for (line, k) in lines[..2].iter().zip(["2", "4"]) {
        let words: Vec<&str> = line.split_whitespace().collect();
        let names: Vec<&str> = words[1..]
            .iter()
            .map(|w| w.split_once('=').unwrap().0)
            .collect();
        assert_eq!(words[0], "zenoh", "{line}");
        assert_eq!(
            names,
            [
                "k",
                "topology",
                "hosts",
                "p50_us",
                "p99_us",
                "max_us",
                "cpu_us_per_msg",
                "msgs"
            ],
            "{line}"
        );
        assert_eq!(
            (
                value(line, "k"),
                value(line, "topology"),
                value(line, "hosts")
            ),
            (k, "ring", "1"),
            "{line}"
        );
        let number = |name| value(line, name).parse::<f64>().unwrap();
        let (p50, p99, max) = (number("p50_us"), number("p99_us"), number("max_us"));
        assert!(p50.is_finite() && p50 > 0.0, "{line}");
        assert!(p50 <= p99 && p99 <= max && max.is_finite(), "{line}");
        assert!(number("cpu_us_per_msg") > 0.0, "{line}");
        // 100 Hz a link, K links, pings and echoes, over a second's window.
        assert!(number("msgs") >= 100.0, "{line}");
    }
    let ratio = lines[2]
        .strip_prefix("zenoh_ratio_4=")
        .unwrap_or_else(|| panic!("{}", lines[2]));
    let ratio: f64 = ratio.parse().unwrap();
    assert!(ratio.is_finite() && ratio > 0.0, "{ratio}");
}
