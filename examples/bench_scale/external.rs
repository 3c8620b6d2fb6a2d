//! The parts measured by other crates' benchmarks, run as programs of their
//! own: Zenoh between K processes (`agent-zenoh`'s `bench_zenoh_scale`, which
//! starts the processes and the network namespaces itself) and the fleet of
//! Rex robots (`rex-agent`'s `fleet`). Each is built and run by the cargo that
//! runs this benchmark (`$CARGO`, else `cargo` on the path), in release; its
//! figure lines are copied here, and the figures of the final line read from
//! them.

use std::io::Write;
use std::process::Command;

/// Run `cargo run --release -p <package> --example <example> -- <args>`:
/// its figure lines (`key=value ...`, or a word and then `key=value ...`),
/// each also written to `out`. A program that fails is said on `out`, and
/// gives no line.
pub(crate) fn run(
    package: &str,
    example: &str,
    args: &[&str],
    out: &mut dyn Write,
) -> std::io::Result<Vec<String>> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned());
    let ran = Command::new(cargo)
        .args([
            "run",
            "--release",
            "--quiet",
            "-p",
            package,
            "--example",
            example,
            "--",
        ])
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output();
    let ran = match ran {
        Ok(ran) => ran,
        Err(e) => {
            writeln!(out, "{example}: not run: {e}")?;
            return Ok(Vec::new());
        }
    };
    let stdout = String::from_utf8_lossy(&ran.stdout);
    let lines: Vec<String> = stdout
        .lines()
        .filter(|l| is_figure(l))
        .map(str::to_owned)
        .collect();
    for l in &lines {
        writeln!(out, "{l}")?;
    }
    if !ran.status.success() {
        let stderr = String::from_utf8_lossy(&ran.stderr);
        let tail: Vec<&str> = stderr.lines().rev().take(5).collect();
        writeln!(
            out,
            "{example}: ended with {} ({})",
            ran.status,
            tail.into_iter().rev().collect::<Vec<_>>().join(" | ")
        )?;
    }
    Ok(lines)
}

/// Whether `line` is a figure line: `key=value`, or one word then
/// `key=value`.
pub(crate) fn is_figure(line: &str) -> bool {
    let key = |w: &str| {
        w.split_once('=').is_some_and(|(k, v)| {
            !v.is_empty()
                && k.starts_with(|c: char| c.is_ascii_lowercase())
                && k.chars()
                    .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_')
        })
    };
    let mut words = line.split_whitespace();
    match (words.next(), words.next()) {
        (Some(first), _) if key(first) => true,
        (Some(first), Some(second)) => first.chars().all(|c| c.is_ascii_lowercase()) && key(second),
        _ => false,
    }
}

/// The number after `key=` in any of `lines` (the last one that has it).
pub(crate) fn figure(lines: &[String], key: &str) -> Option<f64> {
    lines
        .iter()
        .rev()
        .flat_map(|l| l.split_whitespace())
        .find_map(|kv| kv.strip_prefix(key)?.strip_prefix('=')?.parse().ok())
        .filter(|v: &f64| v.is_finite())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figure_lines_and_figures() {
        assert!(is_figure("zenoh k=2 topology=ring p50_us=80.1"));
        assert!(is_figure("fleet_robots=64 fleet_cost_ratio=1.21"));
        assert!(!is_figure("rt machine: cores=2"));
        assert!(!is_figure("  robot 3: achieved"));
        let lines = vec!["zenoh_ratio_32=1.31".to_owned(), "x a=1".to_owned()];
        assert_eq!(figure(&lines, "zenoh_ratio_32"), Some(1.31));
        assert_eq!(figure(&lines, "zenoh_ratio_8"), None);
    }
}
