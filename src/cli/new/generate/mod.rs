//! The files of a new crate: the spec's names and shapes put into the templates
//! of `templates/new/`.
//!
//! The code here decides only what depends on the spec: which pieces a file has
//! (a driver per device, a stub per function, a termination test per behaviour
//! that can end), the names and paths in them, and the `use` lines that those
//! make necessary. Everything else is in the templates.

use std::fmt;
use std::path::PathBuf;

use embodied::spec::Report;
use embodied::spec::model::{Agent, Spec};
use embodied::spec::names::{KEYWORDS, rust_ident as ident, type_name};

use super::template::{self as files, TemplateError, parts};
use super::types::unknown_types;

mod package;
mod properties;
mod source;
mod text;

/// What `embodied new` was asked for.
#[derive(Clone, Debug)]
pub(crate) struct Options {
    /// The crate's name (`[a-z][a-z0-9_-]*`).
    pub(crate) name: String,
    /// The version requirement on `embodied` in the crate's `Cargo.toml` (`0.1`).
    pub(crate) embodied_version: String,
    /// A checkout of embodied-agents to build against instead of crates.io: the
    /// crate gets a `.cargo/config.toml` that patches `embodied` with this path.
    pub(crate) embodied_path: Option<PathBuf>,
}

/// One file of the new crate.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct File {
    /// Its path in the crate, with `/` between folders.
    pub(crate) path: String,
    /// Its text.
    pub(crate) contents: String,
}

impl File {
    fn new(path: impl Into<String>, contents: String) -> File {
        File {
            path: path.into(),
            contents,
        }
    }
}

/// Why no crate could be made.
#[derive(Debug)]
pub(crate) enum NewError {
    /// The crate name is not a valid package name, or one the crate cannot take.
    Name(String),
    /// A name of the spec would clash with a name of the crate.
    Taken {
        /// `agent` or `subsystem`.
        what: &'static str,
        /// Its name.
        name: String,
        /// What it would clash with.
        with: String,
    },
    /// The spec has errors (the report says which).
    Spec(Box<Report>),
    /// The templates and this code disagree.
    Template(TemplateError),
}

impl fmt::Display for NewError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            NewError::Name(name) => write!(
                f,
                "`{name}` is not a valid crate name: use lowercase letters, digits, `_` and `-`, \
                 starting with a letter, and not the name of a crate it uses (embodied, serde, \
                 proptest, std, core, alloc, test) or a Rust keyword"
            ),
            NewError::Taken { what, name, with } => write!(
                f,
                "{what} `{name}` would share its name with {with}; rename the {what} in the spec"
            ),
            NewError::Spec(report) => write!(
                f,
                "the spec has {} error(s); `embodied check` shows them",
                report.errors()
            ),
            NewError::Template(e) => e.fmt(f),
        }
    }
}

impl std::error::Error for NewError {}

impl From<TemplateError> for NewError {
    fn from(e: TemplateError) -> Self {
        NewError::Template(e)
    }
}

/// Names a new crate cannot take: its dependencies' and the standard library's.
const TAKEN_CRATE_NAMES: &[&str] = &[
    "embodied", "serde", "proptest", "std", "core", "alloc", "test",
];

/// The crates the generated code names in paths: a module of the same name beside
/// such a path makes it ambiguous.
const USED_CRATES: &[&str] = &["embodied", "serde", "proptest", "std", "core", "alloc"];

/// The crate's own modules, beside which each agent has a module.
const CRATE_MODULES: &[&str] = &["devices", "logic", "system", "types"];

/// The files of a new crate for `source` (the spec's text, named `file`).
pub(crate) fn generate(file: &str, source: &str, options: &Options) -> Result<Vec<File>, NewError> {
    let name = &options.name;
    let lib = name.replace('-', "_");
    let valid = name.starts_with(|c: char| c.is_ascii_lowercase())
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_' || c == '-');
    if !valid || KEYWORDS.contains(&lib.as_str()) || TAKEN_CRATE_NAMES.contains(&lib.as_str()) {
        return Err(NewError::Name(name.clone()));
    }
    let (spec, report) = embodied::spec::check_source(file, source);
    let spec = match spec {
        Some(spec) if report.is_ok() => spec,
        _ => return Err(NewError::Spec(Box::new(report))),
    };
    check_names(&spec, &lib)?;
    // A spec without a deployment gets one of two processes, so that the
    // crate launches one from the start.
    let (spec_text, spec) = match with_deployment(file, source, &spec) {
        Some((text, with)) => (text, with),
        None => (source.to_owned(), spec),
    };
    let crate_ = Crate {
        spec: &spec,
        lib: &lib,
        file,
        options,
    };
    let mut out = vec![
        File::new("Cargo.toml", crate_.cargo_toml()?),
        File::new(".gitignore", files::GITIGNORE.fill(&[])?),
        File::new("README.md", crate_.readme()?),
        File::new("spec.ron", spec_text),
        File::new("src/lib.rs", crate_.lib_rs()?),
        File::new("src/main.rs", crate_.main_rs()?),
        File::new("src/types.rs", crate_.types_rs()?),
        File::new("src/logic.rs", crate_.logic_rs()?),
        File::new("src/devices.rs", crate_.devices_rs()?),
        File::new("src/system.rs", crate_.system_rs()?),
        File::new("tests/properties/main.rs", crate_.tests_rs()?),
        File::new("tests/app.rs", crate_.app_tests_rs()?),
    ];
    if let Some(path) = &options.embodied_path {
        out.push(File::new(".cargo/config.toml", crate_.cargo_config(path)?));
    }
    for (agent, sub) in spec.subsystems() {
        out.push(File::new(
            format!("src/logic/{}.rs", sub.name),
            crate_.logic_file(agent, sub)?,
        ));
        out.push(File::new(
            format!("tests/properties/{}.rs", sub.name),
            crate_.test_file(agent, sub)?,
        ));
    }
    // A template's last slot may be empty or end a line itself: every file but the
    // spec ends with exactly one newline.
    for f in out.iter_mut().filter(|f| f.path != "spec.ron") {
        f.contents.truncate(f.contents.trim_end().len());
        f.contents.push('\n');
    }
    Ok(out)
}

/// The name of the deployment `embodied new` adds to a spec without one.
const LOCAL: &str = "local";

/// `source` with a deployment of two processes on this machine (by agent, or
/// the control subsystems apart from the rest), if `spec` has none: the text
/// and the spec it reads as. `None` when it has one, or the text could not be
/// extended (the crate is made with the spec as given).
fn with_deployment(file: &str, source: &str, spec: &Spec) -> Option<(String, Spec)> {
    if !spec.deployments.is_empty() {
        return None;
    }
    let names = |a: &Agent| -> Vec<String> {
        a.subsystems
            .iter()
            .map(|s| s.name.clone())
            .chain(a.devices.iter().map(|d| d.name.clone()))
            .collect()
    };
    let processes: Vec<(String, Vec<String>)> = match spec.agents.as_slice() {
        [] => return None,
        [one] => {
            let (control, rest): (Vec<String>, Vec<String>) =
                names(one).into_iter().partition(|n| {
                    spec.subsystem(n)
                        .is_some_and(|s| s.kind == embodied::SubsystemKind::Control)
                });
            if control.is_empty() || rest.is_empty() {
                vec![(one.name.clone(), names(one))]
            } else {
                vec![("control".into(), control), ("devices".into(), rest)]
            }
        }
        [first, rest @ ..] => {
            let name = match rest {
                [second] => second.name.clone(),
                _ => "others".into(),
            };
            vec![
                (first.name.clone(), names(first)),
                (name, rest.iter().flat_map(names).collect()),
            ]
        }
    };
    let mut lines = String::new();
    for (name, runs) in &processes {
        let runs: Vec<String> = runs.iter().map(|r| format!("{r:?}")).collect();
        lines += &format!(
            "                (name: {name:?}, runs: [{}]),\n",
            runs.join(", ")
        );
    }
    let block = format!(
        "    // Added by `embodied new` (the spec had no deployment): {} on this\n    \
         // machine, each a process of this program, linked over Zenoh:\n    \
         //   cargo run -- launch --deployment {LOCAL}\n    \
         // Write your own here (hosts and their addresses, `restarts`, `secure`).\n    \
         deployments: [\n        (\n            name: {LOCAL:?},\n            \
         hosts: [(name: \"localhost\", processes: [\n{lines}            ])],\n        ),\n    ],\n",
        if processes.len() == 1 {
            "one process"
        } else {
            "two processes"
        }
    );
    let end = source.rfind(')')?;
    let before = source[..end].trim_end();
    let comma = if before.ends_with(',') || before.ends_with('(') {
        ""
    } else {
        ","
    };
    let text = format!("{before}{comma}\n{block}{}", &source[end..]);
    let (with, report) = embodied::spec::check_source(file, text.clone());
    match with {
        Some(with) if report.is_ok() && with.deployments.len() == 1 => Some((text, with)),
        _ => None,
    }
}

/// Refuses names of the spec that would clash in the crate: an agent's module
/// beside the crate's own, a subsystem's module (in `src/logic.rs` and in the
/// tests) beside the crates the code uses.
fn check_names(spec: &Spec, lib: &str) -> Result<(), NewError> {
    let crate_name = |name: &str| {
        (USED_CRATES.contains(&name) || name == lib).then(|| format!("the crate `{name}`"))
    };
    for a in &spec.agents {
        let module = CRATE_MODULES
            .contains(&a.name.as_str())
            .then(|| format!("the crate's module `{}`", a.name));
        if let Some(with) = module.or_else(|| crate_name(&a.name)) {
            return Err(NewError::Taken {
                what: "agent",
                name: a.name.clone(),
                with,
            });
        }
    }
    for (_, s) in spec.subsystems() {
        let main = (s.name == "main")
            .then(|| "the root of the tests, `tests/properties/main.rs`".to_owned());
        if let Some(with) = main.or_else(|| crate_name(&s.name)) {
            return Err(NewError::Taken {
                what: "subsystem",
                name: s.name.clone(),
                with,
            });
        }
    }
    Ok(())
}

/// One crate being generated.
struct Crate<'a> {
    spec: &'a Spec,
    /// The library's name (the crate's name with `_` for `-`).
    lib: &'a str,
    /// The spec's file, as given.
    file: &'a str,
    options: &'a Options,
}
