//! The checker and the tools as the spec grows.
//!
//! Generates valid specs, without findings, of `agents` agents: each a control
//! subsystem `c` and a virtual effector `e` of [`BEHAVIOURS`] behaviours each,
//! [`BEHAVIOURS`] buffers each way between them (and `c`'s memory), `c` linked
//! to the next agent's `c` (a ring of transmission buffers), and one deployment
//! that runs [`AGENTS_PER_PROCESS`] agents per process, [`PROCESSES_PER_HOST`]
//! processes per host. 500 agents make 10,000 behaviours, 1,000 subsystems and
//! 100 processes. The spec is written to a temporary folder and, as the
//! commands do:
//!
//! * `check_ms`: read, load and check it with the arc proofs
//!   (`embodied check FILE`), median of [`RUNS`] runs;
//! * `diagram_ms`: read, load and check the structure, then draw the structure
//!   of the whole system as SVG (`embodied diagram FILE --kind structure`);
//!   `diagram_fsm_ms` every subsystem's FSM (`--kind fsm`); medians of [`RUNS`].
//!   Above 60 subsystems the structure is the overview (an agent a box, one
//!   edge per pair of linked agents), as `embodied diagram` draws it; the
//!   detailed drawing grows with the square of the agents and is not bounded
//!   in size;
//! * `new_ms`: run `embodied new` on it (the binary, from its own process: the
//!   generator is the command's), median of [`RUNS`] runs into fresh folders;
//!   `na` when the binary is not built (`cargo build --release --features cli
//!   --bin embodied`; `EMBODIED_BIN` names another).
//!
//! The line also gives the structure diagram's size (`structure_svg_kib`, its
//! width and height in pixels), to judge whether it can be read.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use embodied::spec::diagram::{self, Format, Kind};

use super::det::quantile;

/// Behaviours per subsystem.
pub(crate) const BEHAVIOURS: usize = 10;
/// Agents run by one process of the deployment.
pub(crate) const AGENTS_PER_PROCESS: usize = 5;
/// Processes per host of the deployment.
pub(crate) const PROCESSES_PER_HOST: usize = 10;
/// Timed runs per command and size (the median is reported).
pub(crate) const RUNS: usize = 5;

/// One subsystem: `B` behaviours `b{k}`, each ended by `p{k}`, out of which
/// `q{k}` picks the next one or the first (the last goes back to `b0`).
fn subsystem(out: &mut String, name: &str, kind: &str, peer: &str, next: Option<(&str, &str)>) {
    let buffers = |prefix: &str| {
        (0..BEHAVIOURS)
            .map(|k| format!("(name: \"{prefix}{k}\", type: \"f64\")"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let memory = next.is_some();
    let _ = write!(out, "(name: \"{name}\", kind: {kind}, period_ms: 10.0, ");
    if memory {
        let _ = write!(out, "memory: [{}], ", buffers("m"));
    }
    let _ = write!(
        out,
        "inputs: [(peer: \"{peer}\", buffers: [{}])",
        buffers("x")
    );
    if let Some((prev, _)) = next {
        let _ = write!(
            out,
            ", (peer: \"{prev}\", buffers: [(name: \"t\", type: \"f64\")])"
        );
    }
    let _ = write!(
        out,
        "], outputs: [(peer: \"{peer}\", buffers: [{}])",
        buffers("y")
    );
    if let Some((_, following)) = next {
        let _ = write!(
            out,
            ", (peer: \"{following}\", buffers: [(name: \"t\", type: \"f64\")])"
        );
    }
    out.push_str("], predicates: [");
    for k in 0..BEHAVIOURS {
        let _ = write!(out, "(name: \"p{k}\", reads: [\"x{k}\"]), ");
        if k < BEHAVIOURS - 1 {
            let _ = write!(out, "(name: \"q{k}\", reads: [\"x{k}\"]), ");
        }
    }
    out.push_str("], functions: [");
    for k in 0..BEHAVIOURS {
        let j = (k + 1) % BEHAVIOURS;
        let _ = write!(
            out,
            "(name: \"out{k}\", target: Output(\"{peer}\"), reads: [\"x{k}\", \"x{j}\"], writes: [\"y{k}\"]), "
        );
        if memory {
            let _ = write!(
                out,
                "(name: \"mem{k}\", target: Memory, reads: [\"m{k}\", \"x{k}\"], writes: [\"m{k}\"]), "
            );
        }
    }
    if let Some((prev, following)) = next {
        let _ = write!(
            out,
            "(name: \"pass\", target: Output(\"{following}\"), reads: [\"{prev}.t\", \"m0\"], writes: [\"t\"]), "
        );
    }
    out.push_str("], behaviours: [");
    for k in 0..BEHAVIOURS {
        let mut functions = format!("\"out{k}\"");
        if memory {
            let _ = write!(functions, ", \"mem{k}\"");
        }
        if next.is_some() && k == 0 {
            functions.push_str(", \"pass\"");
        }
        let _ = write!(
            out,
            "(name: \"b{k}\", kind: Repeat, functions: [{functions}], terminal: \"p{k}\"), "
        );
    }
    out.push_str("], fsm: (initial: \"b0\", arcs: [");
    for k in 0..BEHAVIOURS - 1 {
        let _ = write!(
            out,
            "(from: \"b{k}\", to: \"b{}\", when: \"q{k}\"), (from: \"b{k}\", to: \"b0\", when: \"!q{k}\"), ",
            k + 1
        );
    }
    let _ = write!(
        out,
        "(from: \"b{}\", to: \"b0\", when: \"true\")])),",
        BEHAVIOURS - 1
    );
}

/// A valid spec of `agents` agents (at least 2, for the ring): `2 * agents`
/// subsystems, `2 * BEHAVIOURS * agents` behaviours, a deployment of
/// `agents / AGENTS_PER_PROCESS` processes (rounded up).
pub(crate) fn spec(agents: usize) -> String {
    let mut out = String::from("(name: \"scale\", agents: [");
    for a in 0..agents {
        let prev = format!("c{}", (a + agents - 1) % agents);
        let following = format!("c{}", (a + 1) % agents);
        let _ = write!(out, "(name: \"a{a}\", subsystems: [");
        subsystem(
            &mut out,
            &format!("c{a}"),
            "Control",
            &format!("e{a}"),
            Some((&prev, &following)),
        );
        subsystem(
            &mut out,
            &format!("e{a}"),
            "VirtualEffector",
            &format!("c{a}"),
            None,
        );
        out.push_str("]),");
    }
    out.push_str("], links: [");
    for a in 0..agents {
        for k in 0..BEHAVIOURS {
            let _ = write!(out, "(from: \"c{a}.e{a}.y{k}\", to: \"e{a}.c{a}.x{k}\"), ");
            let _ = write!(out, "(from: \"e{a}.c{a}.y{k}\", to: \"c{a}.e{a}.x{k}\"), ");
        }
        let b = (a + 1) % agents;
        let _ = write!(
            out,
            "(from: \"c{a}.c{b}.t\", to: \"c{b}.c{a}.t\", policy: Queue(2)), "
        );
    }
    out.push_str("], deployments: [(name: \"spread\", hosts: [");
    let processes = agents.div_ceil(AGENTS_PER_PROCESS);
    for p in 0..processes {
        if p % PROCESSES_PER_HOST == 0 {
            if p > 0 {
                out.push_str("]), ");
            }
            let _ = write!(out, "(name: \"h{}\", processes: [", p / PROCESSES_PER_HOST);
        }
        let runs: Vec<String> = (p * AGENTS_PER_PROCESS
            ..((p + 1) * AGENTS_PER_PROCESS).min(agents))
            .flat_map(|a| [format!("\"c{a}\""), format!("\"e{a}\"")])
            .collect();
        let _ = write!(out, "(name: \"p{p}\", runs: [{}]), ", runs.join(", "));
    }
    out.push_str("])])])");
    out
}

/// What one size measured.
#[derive(Clone, Debug)]
pub(crate) struct Figures {
    /// Agents.
    pub(crate) agents: usize,
    /// Size of the spec's text \[KiB\].
    pub(crate) kib: usize,
    /// `embodied check` \[ms\].
    pub(crate) check_ms: f64,
    /// `embodied diagram --kind structure` \[ms\]: `Ok(ms)`, `Err(budget \[ms\])`
    /// when it did not end within it, `None` when not measured.
    pub(crate) diagram_ms: Option<Result<f64, u64>>,
    /// `embodied diagram --kind fsm` \[ms\].
    pub(crate) diagram_fsm_ms: f64,
    /// The structure SVG, when drawn: size \[KiB\], width and height \[px\].
    pub(crate) structure_svg: Option<(usize, f64, f64)>,
    /// `embodied new`, when the binary was found \[ms\].
    pub(crate) new_ms: Option<f64>,
}

impl Figures {
    /// The `tools ...` line.
    pub(crate) fn line(&self) -> String {
        let a = self.agents;
        let diagram = match self.diagram_ms {
            None => "na".to_owned(),
            Some(Ok(ms)) => format!("{ms:.2}"),
            Some(Err(budget)) => format!(">{budget}"),
        };
        let svg = match self.structure_svg {
            None => String::new(),
            Some((kib, w, h)) => format!(" structure_svg_kib={kib} structure_svg_px={w:.0}x{h:.0}"),
        };
        format!(
            "tools n_behaviours={} n_subsystems={} n_processes={} spec_kib={} check_ms={:.2} \
             diagram_ms={diagram} diagram_fsm_ms={:.2} new_ms={}{svg}",
            2 * BEHAVIOURS * a,
            2 * a,
            a.div_ceil(AGENTS_PER_PROCESS),
            self.kib,
            self.check_ms,
            self.diagram_fsm_ms,
            self.new_ms.map_or("na".to_owned(), |ms| format!("{ms:.1}")),
        )
    }
}

/// The median time of `runs` calls of `f` \[ms\], and what the last returned.
fn median_ms<T>(
    runs: usize,
    mut f: impl FnMut(usize) -> Result<T, String>,
) -> Result<(f64, T), String> {
    let mut times = Vec::with_capacity(runs);
    let mut last = None;
    for run in 0..runs {
        let start = Instant::now();
        let out = f(run)?;
        times.push(start.elapsed().as_secs_f64() * 1e3);
        last = Some(out);
    }
    let last = last.ok_or("no run")?;
    Ok((quantile(&mut times, 0.5), last))
}

/// `width` and `height` of an SVG's root element.
fn svg_size(svg: &str) -> (f64, f64) {
    let head = &svg[..svg.find('>').unwrap_or(svg.len())];
    let attr = |name: &str| {
        head.split(&format!(" {name}=\""))
            .nth(1)
            .and_then(|rest| rest.split('"').next())
            .and_then(|v| v.trim_end_matches("px").parse().ok())
            .unwrap_or(f64::NAN)
    };
    (attr("width"), attr("height"))
}

/// Draws `kind` of the spec at `path` as `embodied diagram` does.
fn draw(path: &Path, kind: Kind) -> Result<String, String> {
    let (spec, report) = embodied::spec::check_file_structure(path).map_err(|e| e.to_string())?;
    let spec = spec
        .filter(|_| report.is_ok())
        .ok_or_else(|| report.short())?;
    diagram::render(&spec, kind, None, Format::Svg).map_err(|e| e.to_string())
}

/// The `embodied` binary: `EMBODIED_BIN`, or the one beside this program's
/// folder (`target/<profile>/embodied` for `target/<profile>/examples/..`).
pub(crate) fn embodied_bin() -> Option<PathBuf> {
    if let Some(path) = std::env::var_os("EMBODIED_BIN") {
        return Some(PathBuf::from(path));
    }
    let exe = std::env::current_exe().ok()?;
    let bin = exe.parent()?.parent()?.join("embodied");
    bin.is_file().then_some(bin)
}

/// Build the `embodied` binary in release with the cargo that runs this
/// benchmark: its path, or `None` if that fails.
pub(crate) fn build_embodied() -> Option<PathBuf> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".to_owned());
    let built = Command::new(cargo)
        .args([
            "build",
            "--release",
            "--quiet",
            "--features",
            "cli",
            "--bin",
            "embodied",
        ])
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .status()
        .ok()?;
    // Beside this program's folder, as `embodied_bin` looks for it (a run
    // from a debug build finds no release binary there: not measured).
    built.success().then(embodied_bin).flatten()
}

/// Runs `embodied new` on the spec at `path` into `dir` (which does not exist).
fn scaffold(bin: &Path, path: &Path, dir: &Path) -> Result<(), String> {
    let out = Command::new(bin)
        .args(["new", "scale_agent", "--spec"])
        .arg(path)
        .arg("--path")
        .arg(dir)
        .output()
        .map_err(|e| format!("cannot run {}: {e}", bin.display()))?;
    if !out.status.success() {
        return Err(format!(
            "embodied new failed: {}",
            String::from_utf8_lossy(&out.stderr)
        ));
    }
    Ok(())
}

/// Measures a spec of `agents` agents, written under `dir`.
/// `bin`: the `embodied` binary, if built.
pub(crate) fn measure(agents: usize, dir: &Path, bin: Option<&Path>) -> Result<Figures, String> {
    let text = spec(agents);
    let path = dir.join(format!("scale_{agents}.ron"));
    std::fs::write(&path, &text).map_err(|e| format!("cannot write {}: {e}", path.display()))?;

    let (check_ms, ()) = median_ms(RUNS, |_| {
        let (spec, report) =
            embodied::spec::check_file(&path).map_err(|e| format!("{}: {e}", path.display()))?;
        // A finding (even a warning) would mean the generator is wrong and the
        // times measure something else.
        if spec.is_none() || !report.findings.is_empty() {
            return Err(format!(
                "the generated spec must check with 0 findings:\n{}",
                report.short()
            ));
        }
        Ok(())
    })?;
    let (diagram_ms, structure_svg) = {
        let (ms, svg) = median_ms(RUNS, |_| draw(&path, Kind::Structure))?;
        let (w, h) = svg_size(&svg);
        (Some(Ok(ms)), Some((svg.len() / 1024, w, h)))
    };
    let (diagram_fsm_ms, _) = median_ms(RUNS, |_| draw(&path, Kind::Fsm))?;
    let new_ms = match bin {
        None => None,
        Some(bin) => {
            // Each run into a folder of its own, removed after the runs: the
            // time is the command's, not the removal of the last run's crate.
            let made = |run: usize| dir.join(format!("new_{agents}_{run}"));
            let timed = median_ms(RUNS, |run| scaffold(bin, &path, &made(run)));
            for run in 0..RUNS {
                let _ = std::fs::remove_dir_all(made(run));
            }
            Some(timed?.0)
        }
    };
    Ok(Figures {
        agents,
        kib: text.len() / 1024,
        check_ms,
        diagram_ms,
        diagram_fsm_ms,
        structure_svg,
        new_ms,
    })
}
