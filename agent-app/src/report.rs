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
}
