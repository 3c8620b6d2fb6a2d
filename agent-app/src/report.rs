//! A run's report folder: the files a program writes at the end of a run
//! (its plots from [`plot`](crate::plot), tables, a summary), and what every
//! report can hold of the spec the run followed: its diagrams and its timing
//! certificate.
//!
//! ```
//! # fn main() -> std::io::Result<()> {
//! let dir = std::env::temp_dir().join(format!("agent-app-report-doc-{}", std::process::id()));
//! let mut report = agent_app::report::Report::create(&dir)?;
//! report.put("summary.txt", "passed\n")?;
//! assert_eq!(report.files(), [dir.join("summary.txt")]);
//! # std::fs::remove_dir_all(&dir)
//! # }
//! ```

use std::io;
use std::path::{Path, PathBuf};

use agent_spec::Spec;

use crate::AppError;

/// A report folder being written: the files put in it, in order.
#[derive(Debug)]
pub struct Report {
    dir: PathBuf,
    files: Vec<PathBuf>,
}

impl Report {
    /// The report folder `dir`, created if needed.
    pub fn create(dir: &Path) -> io::Result<Report> {
        std::fs::create_dir_all(dir)?;
        Ok(Report {
            dir: dir.to_owned(),
            files: Vec::new(),
        })
    }

    /// Write `text` into the file `name` of the folder (a path relative to
    /// it: its folders are created).
    pub fn put(&mut self, name: &str, text: impl AsRef<[u8]>) -> io::Result<()> {
        let path = self.dir.join(name);
        if let Some(parent) = path.parent() {
            std::fs::create_dir_all(parent)?;
        }
        std::fs::write(&path, text)?;
        self.files.push(path);
        Ok(())
    }

    /// What the report holds of `spec`: its timing certificate
    /// (`timing.txt`, see [`timing`]) and every diagram of it in `diagrams/`
    /// (each subsystem's FSM as SVG and Mermaid, its data flow, the agents'
    /// structure: `embodied diagram`'s).
    pub fn spec(&mut self, spec: &Spec) -> io::Result<()> {
        self.put("timing.txt", timing(spec))?;
        for (name, text) in agent_spec::diagram::render_all(spec) {
            self.put(&format!("diagrams/{name}"), text)?;
        }
        Ok(())
    }

    /// The files written so far, in order.
    pub fn files(&self) -> &[PathBuf] {
        &self.files
    }
}

/// The flags of a program that writes a report folder at the end of each run
/// (`--out DIR`, `--no-report`, `--no-record`): flatten them into the
/// application's flags (`#[command(flatten)] report: ReportFlags`). Each run
/// (a mission, say) writes into a sub-folder of its own, which also holds
/// the run's recording (`run.mcap`) unless `--no-record` or `--record FILE`.
#[derive(clap::Args, Clone, Debug, Default)]
pub struct ReportFlags {
    /// Report folder (default: `target/<program>-report`, for example
    /// `target/rex-report`); one sub-folder per run.
    #[arg(long, global = true, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Do not write the report folder (nor the recording it holds).
    #[arg(long, global = true)]
    pub no_report: bool,
    /// Do not record the run into its report folder (`<out>/<run>/run.mcap`,
    /// made by default; see `--record`).
    #[arg(long, global = true)]
    pub no_record: bool,
}

impl ReportFlags {
    /// The report folder's root, unless `--no-report`.
    pub fn root(&self) -> Option<PathBuf> {
        if self.no_report {
            return None;
        }
        Some(self.out.clone().unwrap_or_else(|| {
            let program = crate::output::program();
            let stem = program.strip_suffix(".exe").unwrap_or(&program);
            PathBuf::from(format!("target/{stem}-report"))
        }))
    }

    /// Check, before anything runs, that the report folder can be written
    /// ([`writable_folder`](crate::writable_folder); nothing to check with
    /// `--no-report`). Call it from
    /// [`Application::configure`](crate::Application::configure).
    pub fn check(&self) -> Result<(), AppError> {
        self.root()
            .map_or(Ok(()), |root| crate::writable_folder("--out", &root))
    }

    /// The folder of the run `run`, unless `--no-report`.
    pub fn folder(&self, run: &str) -> Option<PathBuf> {
        self.root().map(|root| root.join(run))
    }

    /// Where the run `run` is recorded by default (`<out>/<run>/run.mcap`,
    /// its folder made), unless `--no-report` or `--no-record`: what
    /// [`Application::default_record`](crate::Application::default_record)
    /// returns.
    pub fn recording(&self, run: &str) -> Option<PathBuf> {
        let dir = self.folder(run).filter(|_| !self.no_record)?;
        std::fs::create_dir_all(&dir).ok()?;
        Some(dir.join("run.mcap"))
    }

    /// Write the report of the run `run` with `write` (given the folder,
    /// it returns the files it wrote), unless `--no-report`. Returns the
    /// summary's line for it (`report: DIR (N files)`); a folder that could
    /// not be written is said on standard error, and the run's verdict is
    /// left to its judgement.
    pub fn write(
        &self,
        run: &str,
        write: impl FnOnce(&Path) -> io::Result<Vec<PathBuf>>,
    ) -> Option<String> {
        let dir = self.folder(run)?;
        match write(&dir) {
            Ok(files) => Some(format!(
                "report: {} ({} files)\n",
                dir.display(),
                files.len()
            )),
            Err(e) => {
                crate::output::error(&format_args!("report {}: {e}", dir.display()));
                None
            }
        }
    }
}

/// What went wrong in a run, whether or not its judgement failed of it (a
/// command clamped, a sample dropped, a component restarted), said as one
/// line of the summary: `none`, or the findings joined by `; `.
///
/// ```
/// use agent_app::report::Findings;
///
/// let mut faults = Findings::default();
/// assert_eq!(faults.to_string(), "none");
/// faults.count(0u32, "planner failures");
/// faults.push("the platform stopped at 3.20 s");
/// faults.count(2u64, "torque commands clamped");
/// assert_eq!(faults.to_string(), "the platform stopped at 3.20 s; 2 torque commands clamped");
/// ```
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Findings(Vec<String>);

impl Findings {
    /// One finding.
    pub fn push(&mut self, finding: impl Into<String>) {
        self.0.push(finding.into());
    }

    /// `"{n} {what}"` when `n` is not zero: a count of something that went
    /// wrong (nothing when it never did).
    pub fn count(&mut self, n: impl Into<u64>, what: &str) {
        let n = n.into();
        if n > 0 {
            self.push(format!("{n} {what}"));
        }
    }

    /// Whether nothing went wrong.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }
}

impl std::fmt::Display for Findings {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if self.0.is_empty() {
            f.write_str("none")
        } else {
            f.write_str(&self.0.join("; "))
        }
    }
}

/// The timing certificate of `spec` run as one process on one host
/// (`embodied check --timing`'s analysis), or why there is none, as text.
pub fn timing(spec: &Spec) -> String {
    match agent_spec::timing::analyse(spec, None, None) {
        Ok(analysis) => format!(
            "# The timing analysis of `{}` as one process on one host (embodied check --timing)\n{analysis}",
            spec.name
        ),
        Err(why) => format!("no timing analysis: {why}\n"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_report_holds_its_files_and_the_specs_diagrams_and_timing() {
        let dir = std::env::temp_dir().join(format!("agent-app-report-{}", std::process::id()));
        let spec = crate::SpecFile::parse("tank.ron", include_str!("../../specs/tank.ron"))
            .map(|s| s.spec);
        let Ok(spec) = spec else {
            panic!("the tank's spec is valid");
        };
        let mut report = Report::create(&dir).unwrap_or_else(|e| panic!("{e}"));
        report
            .put("summary.txt", "passed\n")
            .and_then(|()| report.spec(&spec))
            .unwrap_or_else(|e| panic!("{e}"));
        let files = report.files();
        assert_eq!(files[0], dir.join("summary.txt"));
        assert_eq!(files[1], dir.join("timing.txt"));
        assert!(files.len() > 3, "diagrams: {files:?}");
        assert!(files.iter().all(|f| f.is_file()));
        let timing = std::fs::read_to_string(dir.join("timing.txt")).unwrap_or_default();
        assert_eq!(timing, super::timing(&spec));
        // The tank's spec states no execution times; Rex's does.
        assert!(timing.starts_with("no timing analysis: "), "{timing}");
        let rex = crate::SpecFile::parse("rex.ron", include_str!("../../specs/rex.ron"));
        let timed = rex.map(|s| super::timing(&s.spec)).unwrap_or_default();
        assert!(
            timed.starts_with("# The timing analysis of `rex` as one process"),
            "{timed}"
        );
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn findings_list_what_went_wrong_in_order() {
        let mut f = Findings::default();
        assert!(f.is_empty());
        assert_eq!(f.to_string(), "none");
        f.count(3u32, "fragments refused");
        f.count(0u64, "executor errors");
        f.push(String::from("c1 restarted 1 times"));
        assert!(!f.is_empty());
        assert_eq!(f.to_string(), "3 fragments refused; c1 restarted 1 times");
    }

    #[test]
    fn the_report_flags_name_the_folders_and_the_recording() {
        let root = std::env::temp_dir().join(format!("agent-app-flags-{}", std::process::id()));
        let flags = ReportFlags {
            out: Some(root.clone()),
            ..ReportFlags::default()
        };
        assert_eq!(flags.check().map_err(|e| e.to_string()), Ok(()));
        assert_eq!(flags.folder("square"), Some(root.join("square")));
        let recording = flags.recording("square");
        assert_eq!(recording, Some(root.join("square/run.mcap")));
        assert!(root.join("square").is_dir(), "the run's folder is made");
        let line = flags.write("square", |dir| {
            let mut report = Report::create(dir)?;
            report.put("summary.txt", "passed\n")?;
            Ok(report.files().to_vec())
        });
        let expected = format!("report: {} (1 files)\n", root.join("square").display());
        assert_eq!(line, Some(expected));
        // A report that cannot be written is said, and gives no line.
        let failed = flags.write("square", |_| Err(io::Error::other("disk full")));
        assert_eq!(failed, None);

        let unrecorded = ReportFlags {
            no_record: true,
            ..flags.clone()
        };
        assert_eq!(unrecorded.recording("square"), None);
        assert_eq!(unrecorded.folder("square"), Some(root.join("square")));
        let none = ReportFlags {
            no_report: true,
            ..flags
        };
        assert_eq!(none.root(), None);
        assert_eq!(none.recording("square"), None);
        assert_eq!(none.write("square", |_| panic!("not called")), None);
        assert!(none.check().is_ok());
        // The default root is named after the program.
        let default = ReportFlags::default().root().unwrap_or_default();
        let name = default
            .file_name()
            .map(|n| n.to_string_lossy().into_owned());
        assert!(name.is_some_and(|n| n.ends_with("-report")), "{default:?}");
        assert!(default.starts_with("target"), "{default:?}");
        // A file where the folder should be is invalid input, named.
        let file = root.join("a-file");
        std::fs::write(&file, b"").ok();
        let blocked = ReportFlags {
            out: Some(file),
            ..ReportFlags::default()
        };
        let why = blocked.check().map_err(|e| e.to_string());
        assert!(why.as_ref().is_err_and(|w| w.contains("--out")), "{why:?}");
        std::fs::remove_dir_all(&root).ok();
    }
}
