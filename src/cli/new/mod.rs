//! `embodied new`: a new agent crate from a spec.
//!
//! The crate compiles, runs and passes its tests as generated: the spec's types,
//! buffers and FSMs come from `embodied::agent!`; every transition function and
//! predicate is a stub in `src/logic/<subsystem>.rs` that writes nothing (a
//! predicate answers `false`) and marks itself as a placeholder; every device is a
//! stub driver in `src/devices.rs`, made with `Default`; `src/system.rs` assembles
//! the whole system from the spec (`embodied::spec::Assembly`); `src/main.rs` runs
//! it and prints every FSM transition; `src/types.rs` holds a placeholder for each
//! type the spec names that is not a standard one. The tests check that the system
//! has the spec's structure and runs, that no elementary action panics, and that
//! each behaviour that can end does, in a model of its world (`tests/properties/`).
//!
//! The crate depends on `embodied` by version; `--embodied-path` adds a
//! `.cargo/config.toml` that patches it with a local checkout. The files come from
//! the templates of `templates/new/` ([`template`]), filled by [`generate`].

mod generate;
mod template;
mod types;

#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use generate::{NewError, Options, generate};

/// What `embodied new` was given on the command line.
#[derive(Debug)]
pub(crate) struct Args {
    /// The crate's name.
    pub(crate) name: String,
    /// The spec file.
    pub(crate) spec: PathBuf,
    /// Where to create the crate (default: `./NAME`).
    pub(crate) path: Option<PathBuf>,
    /// A checkout of embodied-agents to build against.
    pub(crate) embodied_path: Option<PathBuf>,
}

/// The requirement on `embodied` that a new crate writes: this binary's version as
/// `major.minor` (`0.1`), so that any later compatible release satisfies it.
fn embodied_version() -> String {
    let version = env!("CARGO_PKG_VERSION");
    let mut parts = version.split('.');
    match (parts.next(), parts.next()) {
        (Some(major), Some(minor)) => format!("{major}.{minor}"),
        _ => version.to_owned(),
    }
}

/// Runs `embodied new`: prints what it made, or why it made nothing.
pub(crate) fn run(args: Args) -> ExitCode {
    match make(&args) {
        Ok((dir, files)) => {
            outln!(
                "created {} ({files} files) from {}",
                dir.display(),
                args.spec.display()
            );
            outln!(
                "next: cd {} && cargo run, then fill in src/logic/ (see its README.md)",
                dir.display()
            );
            if args.embodied_path.is_none() {
                outln!(
                    "it depends on embodied = \"{}\" from crates.io; to build against a checkout \
                     instead, see README.md (\"Building against a local embodied\") or pass \
                     --embodied-path",
                    embodied_version()
                );
            }
            ExitCode::SUCCESS
        }
        Err(message) => {
            err!("{message}");
            ExitCode::FAILURE
        }
    }
}

/// Makes the crate: its directory and the number of files written, or the whole
/// message of why not.
fn make(args: &Args) -> Result<(PathBuf, usize), String> {
    let file = args.spec.display().to_string();
    let bytes =
        std::fs::read(&args.spec).map_err(|e| format!("error: cannot read {file}: {e}\n"))?;
    let source = embodied::spec::decode(&file, bytes).map_err(|report| report.render(100))?;
    let embodied_path = match &args.embodied_path {
        None => None,
        Some(dir) => Some(checkout(dir)?),
    };
    let options = Options {
        name: args.name.clone(),
        embodied_version: embodied_version(),
        embodied_path,
    };
    let files = generate(&file, &source, &options).map_err(|e| match e {
        NewError::Spec(report) => format!(
            "{}error: {file} has errors; no crate was made\n",
            report.render(100)
        ),
        e => format!("error: {e}\n"),
    })?;
    let dir = args
        .path
        .clone()
        .unwrap_or_else(|| PathBuf::from(&args.name));
    if dir.exists() && !dir.is_dir() {
        return Err(format!(
            "error: {} exists and is not a directory; choose another --path\n",
            dir.display()
        ));
    }
    if dir.read_dir().is_ok_and(|mut d| d.next().is_some()) {
        return Err(format!(
            "error: {} exists and is not empty; choose another --path\n",
            dir.display()
        ));
    }
    for f in &files {
        let target = dir.join(&f.path);
        let written = target
            .parent()
            .map_or(Ok(()), std::fs::create_dir_all)
            .and_then(|()| std::fs::write(&target, &f.contents));
        if let Err(e) = written {
            return Err(format!("error: cannot write {}: {e}\n", target.display()));
        }
    }
    Ok((dir, files.len()))
}

/// The absolute path of a checkout of embodied-agents, if `dir` is one.
fn checkout(dir: &Path) -> Result<PathBuf, String> {
    let manifest = dir.join("Cargo.toml");
    let text = std::fs::read_to_string(&manifest).map_err(|e| {
        format!(
            "error: --embodied-path {}: cannot read {}: {e}\n",
            dir.display(),
            manifest.display()
        )
    })?;
    if !text.lines().any(|l| l.trim() == "name = \"embodied\"") {
        return Err(format!(
            "error: --embodied-path {}: {} is not the manifest of the `embodied` package\n",
            dir.display(),
            manifest.display()
        ));
    }
    std::path::absolute(dir).map_err(|e| format!("error: --embodied-path {}: {e}\n", dir.display()))
}
