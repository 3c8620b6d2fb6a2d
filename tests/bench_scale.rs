//! `cargo run --example bench_scale -- --quick`, run here: the example's code
//! (`examples/bench_scale/`) is a module of this test, so that it runs without
//! a second build. Checks the shape of its lines and that the deterministic
//! executor's figures are finite and positive. `embodied new` is timed when the
//! `embodied` binary is built with the tests (feature `cli`).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

#[path = "../examples/bench_scale/main.rs"]
#[expect(dead_code, reason = "the example's `main` is not called here")]
mod program;

/// The value of `key=` in `line`.
fn field<'a>(line: &'a str, key: &str) -> &'a str {
    line.split_whitespace()
        .find_map(|kv| kv.strip_prefix(key)?.strip_prefix('='))
        .unwrap_or_else(|| panic!("no `{key}=` in `{line}`"))
}

fn positive(line: &str, key: &str) -> f64 {
    let v: f64 = field(line, key)
        .parse()
        .unwrap_or_else(|e| panic!("`{key}` in `{line}`: {e}"));
    assert!(v.is_finite() && v > 0.0, "`{key}` in `{line}`");
    v
}

/// The example's binary, which `cargo test` builds beside this test's
/// (`target/<profile>/examples/` next to `target/<profile>/deps/`): the run
/// starts it again for each first build in a fresh process.
fn example() -> std::path::PathBuf {
    let exe = std::env::current_exe().unwrap();
    let profile = exe.parent().and_then(std::path::Path::parent).unwrap();
    let example = profile
        .join("examples")
        .join(format!("bench_scale{}", std::env::consts::EXE_SUFFIX));
    assert!(example.is_file(), "{} is not built", example.display());
    example
}

#[test]
fn quick_run_prints_its_figures_and_the_scale_line() {
    let options = program::Options {
        quick: true,
        embodied_bin: option_env!("CARGO_BIN_EXE_embodied").map(Into::into),
        skip_external: true,
        program: Some(example()),
    };
    let mut out = Vec::new();
    let scale = program::run(&options, &mut out).unwrap();
    let text = String::from_utf8(out).unwrap();
    let lines: Vec<&str> = text.lines().collect();

    let det: Vec<&str> = lines
        .iter()
        .copied()
        .filter(|l| l.starts_with("det n="))
        .collect();
    assert!(det.len() >= 2, "{text}");
    assert_eq!(field(det[0], "n"), "3", "{text}");
    for l in &det {
        for key in [
            "action_ns_p50",
            "action_ns_p99",
            "bytes_per_subsystem",
            "build_ms",
            "first_build_us_per_subsystem",
        ] {
            positive(l, key);
        }
        assert!(positive(l, "action_ns_p99") >= positive(l, "action_ns_p50"));
        // The kernel's copy into huge pages, waited for before the actions
        // are timed: none, or a time (zero for a small system asked in place).
        let huge: f64 = field(l, "huge_pages_ms").parse().unwrap();
        assert!(huge.is_finite() && huge >= 0.0, "{l}");
        assert_eq!(field(l, "allocs_per_action"), "0", "steady state: {l}");
    }

    let tools: Vec<&str> = lines
        .iter()
        .copied()
        .filter(|l| l.starts_with("tools n_behaviours="))
        .collect();
    assert!(!tools.is_empty(), "{text}");
    for l in &tools {
        positive(l, "check_ms");
        positive(l, "diagram_ms");
        positive(l, "diagram_fsm_ms");
        let new = field(l, "new_ms");
        assert!(
            new == "na" || new.parse::<f64>().is_ok_and(|v| v > 0.0),
            "{l}"
        );
    }

    real_time_lines(&lines, &text, scale.rt_subsystems);

    // Exactly one final line, with the six figures in order, `na` where not measured.
    let last = lines.last().unwrap();
    assert_eq!(lines.iter().filter(|l| l.starts_with("scale ")).count(), 1);
    let keys: Vec<&str> = last
        .strip_prefix("scale ")
        .unwrap()
        .split(' ')
        .map(|kv| kv.split_once('=').unwrap().0)
        .collect();
    assert_eq!(
        keys,
        [
            "action_ratio_10000",
            "rt_subsystems",
            "rt_jitter_us_p99",
            "zenoh_ratio_32",
            "fleet_robots",
            "fleet_cost_ratio"
        ],
        "{last}"
    );
    for key in &keys[1..] {
        let v = field(last, key);
        assert!(
            v == "na" || v.parse::<f64>().is_ok_and(f64::is_finite),
            "{last}"
        );
    }
    let ratio = positive(last, "action_ratio_10000");
    assert_eq!(
        Some(ratio),
        scale.action_ratio_10000.map(|r| (r * 1e3).round() / 1e3)
    );
}

/// The real-time executor's lines: the pool at every size, a thread per
/// subsystem at the small ones; every figure present, and the pool's threads
/// bounded by the cores (at most one worker a core at one period); a size
/// the pool missed the aim at run twice. The final line's `rt_subsystems` is
/// a size the pool's last run of kept the aim.
fn real_time_lines(lines: &[&str], text: &str, rt_subsystems: Option<f64>) {
    let rt: Vec<&str> = lines
        .iter()
        .copied()
        .filter(|l| l.starts_with("rt n="))
        .collect();
    assert!(rt.iter().any(|l| field(l, "mode") == "pool"), "{text}");
    assert!(
        rt.iter().any(|l| field(l, "mode") == "per_subsystem"),
        "{text}"
    );
    let cores = std::thread::available_parallelism().map_or(1, std::num::NonZero::get);
    for l in &rt {
        positive(l, "jitter_us_p99");
        positive(l, "response_us_p99");
        positive(l, "bytes_per_subsystem");
        let n: usize = field(l, "n").parse().unwrap();
        let threads: usize = field(l, "threads").parse().unwrap();
        match field(l, "mode") {
            "pool" => assert!(threads <= cores.min(n), "{l}"),
            _ => assert_eq!(threads, n, "{l}"),
        }
        let schedulable = field(l, "schedulable");
        assert!(schedulable == "0" || schedulable == "1", "{l}");
    }
    // A size whose pool run missed the aim was run a second time, and only
    // a second miss counts: the final figure is a size whose last run kept it.
    let pool_runs = |n: &str| -> Vec<&str> {
        (rt.iter().copied())
            .filter(|l| field(l, "mode") == "pool" && field(l, "n") == n)
            .collect()
    };
    for l in rt.iter().filter(|l| field(l, "mode") == "pool") {
        let runs = pool_runs(field(l, "n"));
        let expected = if field(runs[0], "schedulable") == "0" {
            2
        } else {
            1
        };
        assert_eq!(runs.len(), expected, "{text}");
        for (k, run) in runs.iter().enumerate() {
            assert_eq!(field(run, "run"), format!("{}", k + 1), "{run}");
        }
    }
    if let Some(n) = rt_subsystems {
        let runs = pool_runs(&format!("{n}"));
        assert!(
            runs.last().is_some_and(|l| field(l, "schedulable") == "1"),
            "{text}"
        );
    }
}

/// `--agents` and `--first-build` take positive numbers of agents; anything
/// else is refused with the flag named (an empty system has no time an
/// action to divide by).
#[test]
fn a_number_of_agents_is_positive() {
    assert_eq!(program::count("--agents", "3333"), Ok(3333));
    for bad in ["0", "-1", "x", ""] {
        let err = program::count("--agents", bad).unwrap_err();
        assert!(err.starts_with("--agents: "), "{err}");
    }
}
