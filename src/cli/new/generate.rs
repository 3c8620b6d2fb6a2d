//! The files of a new crate: the spec's names and shapes put into the templates
//! of `templates/new/`.
//!
//! The code here decides only what depends on the spec: which pieces a file has
//! (a driver per device, a stub per function, a termination test per behaviour
//! that can end), the names and paths in them, and the `use` lines that those
//! make necessary. Everything else is in the templates.

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::path::PathBuf;

use embodied::spec::Report;
use embodied::spec::model::{Agent, Device, DeviceKind, Group, Spec, Subsystem, Target};
use embodied::spec::names::{KEYWORDS, rust_ident as ident, type_name};

use super::template::{self as files, TemplateError, parts};
use super::types::unknown_types;

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

/// The spec's doc text as doc comment lines (`prefix` is `///` or `//!`).
fn doc(indent: &str, prefix: &str, text: Option<&String>) -> String {
    let mut out = String::new();
    for line in text.map(|t| t.lines()).into_iter().flatten() {
        let line = line.trim_end();
        if line.is_empty() {
            out += &format!("{indent}{prefix}\n");
        } else {
            out += &format!("{indent}{prefix} {line}\n");
        }
    }
    out
}

/// `/// text` lines, then an empty `///` line if there were any: the spec's doc
/// above what the crate says of an item.
fn doc_then(indent: &str, text: Option<&String>) -> String {
    let mut out = doc(indent, "///", text);
    if !out.is_empty() {
        out += &format!("{indent}///\n");
    }
    out
}

/// An empty `//!` line, then the spec's doc as `//!` lines, if it has one.
fn inner_doc(text: Option<&String>) -> String {
    let lines = doc("", "//!", text);
    if lines.is_empty() {
        lines
    } else {
        format!("//!\n{lines}")
    }
}

/// The parameters of a function as rustfmt writes them: on the signature's line
/// if it fits in 100 columns, else one per line.
fn params(head: &str, params: &[String], tail: &str) -> String {
    let line = params.join(", ");
    if head.len() + line.len() + tail.len() <= 100 {
        line
    } else {
        let mut out = String::from("\n");
        for p in params {
            out += &format!("        {p},\n");
        }
        out + "    "
    }
}

/// `Ok(assembly.<method>(<args>)?)` in a function's body, as rustfmt writes it:
/// on one line if it fits in 100 columns, else one argument per line.
fn call(method: &str, args: &[String]) -> String {
    let line = format!("    Ok(assembly.{method}({})?)", args.join(", "));
    if line.len() <= 100 {
        return line;
    }
    let mut out = format!("    Ok(assembly.{method}(\n");
    for a in args {
        out += &format!("        {a},\n");
    }
    out + "    )?)"
}

/// A shell command of a doc comment and what it does, its `#` in the column of
/// the others (or one space after a longer command).
fn aligned(command: &str, comment: &str) -> String {
    format!("{command:<42} # {comment}")
}

/// A TOML basic string.
fn toml_string(text: &str) -> String {
    let mut out = String::from("\"");
    for c in text.chars() {
        match c {
            '"' => out += "\\\"",
            '\\' => out += "\\\\",
            c if c.is_control() => out += &format!("\\u{:04X}", u32::from(c)),
            c => out.push(c),
        }
    }
    out + "\""
}

/// `#[allow(non_snake_case)]` before an item named by a component with capitals.
fn allow_case<'a>(names: impl IntoIterator<Item = &'a str>) -> &'static str {
    if names
        .into_iter()
        .any(|n| n.chars().any(|c| c.is_ascii_uppercase()))
    {
        "#[allow(non_snake_case)]\n"
    } else {
        ""
    }
}

/// Whether a group list has a buffer.
fn any_buffer(groups: &[Group]) -> bool {
    groups.iter().any(|g| !g.buffers.is_empty())
}

/// The behaviours of a subsystem that can end (a terminal condition other than
/// `false`), with a unique snake-case name for the tests' functions.
fn ending(sub: &Subsystem) -> Vec<(&embodied::spec::model::Behaviour, String)> {
    let mut taken = BTreeSet::new();
    sub.behaviours
        .iter()
        .enumerate()
        .filter(|(_, b)| b.terminal.trim() != "false")
        .map(|(k, b)| {
            let mut name = b.name.to_lowercase();
            if !taken.insert(name.clone()) {
                name = format!("{name}_{k}");
                taken.insert(name.clone());
            }
            (b, name)
        })
        .collect()
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

impl Crate<'_> {
    fn cargo_toml(&self) -> Result<String, NewError> {
        Ok(files::CARGO_TOML.fill(&[
            ("name", &self.options.name),
            ("embodied_version", &self.options.embodied_version),
            ("rust_version", env!("CARGO_PKG_RUST_VERSION")),
        ])?)
    }

    fn cargo_config(&self, path: &std::path::Path) -> Result<String, NewError> {
        Ok(files::CARGO_CONFIG.fill(&[
            ("embodied_version", &self.options.embodied_version),
            ("embodied_path", &toml_string(&path.display().to_string())),
        ])?)
    }

    fn readme(&self) -> Result<String, NewError> {
        let mut logic_rows = String::new();
        let mut test_rows = String::new();
        for (agent, sub) in self.spec.subsystems() {
            logic_rows += &parts::README_LOGIC_ROW.fill(&[
                ("subsystem", &sub.name),
                ("agent", &agent.name),
                ("functions", &sub.functions.len().to_string()),
                ("predicates", &sub.predicates.len().to_string()),
            ])?;
            if !ending(sub).is_empty() {
                test_rows += &parts::README_TEST_ROW.fill(&[("subsystem", &sub.name)])?;
            }
        }
        Ok(files::README.fill(&[
            ("name", &self.options.name),
            ("spec_file", self.file),
            ("embodied_version", &self.options.embodied_version),
            ("logic_rows", &logic_rows),
            ("test_rows", &test_rows),
        ])?)
    }

    fn lib_rs(&self) -> Result<String, NewError> {
        let mut agents = String::new();
        for a in &self.spec.agents {
            // As rustfmt writes a call: the arguments on one line up to 60 columns.
            let arguments = [
                "spec = \"spec.ron\"".to_owned(),
                format!("agent = \"{}\"", a.name),
                "memory_derive = [Default]".to_owned(),
            ];
            let line = arguments.join(", ");
            let arguments = if line.len() <= 60 {
                line
            } else {
                format!("\n        {},\n    ", arguments.join(",\n        "))
            };
            agents += &parts::LIB_AGENT.fill(&[
                ("doc", &doc_then("", a.doc.as_ref())),
                ("arguments", &arguments),
                ("agent", &a.name),
                ("agent_ident", &ident(&a.name)),
            ])?;
        }
        Ok(files::LIB.fill(&[
            ("spec_name", &self.spec.name),
            ("spec_file", self.file),
            ("spec_doc", &inner_doc(self.spec.doc.as_ref())),
            ("agents", &agents),
        ])?)
    }

    fn main_rs(&self) -> Result<String, NewError> {
        let halting: Vec<String> = self
            .spec
            .subsystems()
            .filter(|(_, s)| !s.fsm.finals.is_empty())
            .map(|(_, s)| format!("{:?}", s.name))
            .collect();
        let ends = if halting.is_empty() {
            "        // A run ends at its time limit: no subsystem of spec.ron has a final\n        \
             // behaviour that could end it sooner (`.ends_when(...)` states such a rule).\n"
                .to_owned()
        } else {
            files::parts::ENDS.fill(&[("halting", &halting.join(", "))])?
        };
        Ok(files::MAIN.fill(&[
            ("lib", self.lib),
            (
                "replay",
                &aligned(
                    &format!(
                        "cargo run -- replay run.mcap --subsystem {}",
                        self.first_subsystem()
                    ),
                    "its subsystem replayed alone",
                ),
            ),
            (
                "launch",
                &aligned(
                    &format!(
                        "cargo run -- launch --deployment {}",
                        self.first_deployment()
                    ),
                    "its processes, over Zenoh",
                ),
            ),
            ("ends", &ends),
        ])?)
    }

    /// The first subsystem of the spec (the checker makes sure there is one).
    fn first_subsystem(&self) -> &str {
        self.spec
            .subsystems()
            .next()
            .map_or("c1", |(_, s)| s.name.as_str())
    }

    /// The deployment the crate's tests and docs launch: the spec's first
    /// with the most processes (every generated spec has one).
    fn deployment(&self) -> Option<&embodied::spec::model::Deployment> {
        let most = self
            .spec
            .deployments
            .iter()
            .map(|d| d.processes().len())
            .max()?;
        self.spec
            .deployments
            .iter()
            .find(|d| d.processes().len() == most)
    }

    fn first_deployment(&self) -> &str {
        self.deployment().map_or(LOCAL, |d| d.name.as_str())
    }

    /// `tests/app.rs`: the program run as a user runs it (real time, a launch
    /// of a deployment, a process killed and restarted, a recording replayed).
    fn app_tests_rs(&self) -> Result<String, NewError> {
        let deployment = self.deployment();
        let (processes, victim) = match deployment {
            Some(d) => {
                let ps = d.processes();
                let victim = ps
                    .iter()
                    .rev()
                    .find(|(_, p, _)| p.restart_budget() > 0)
                    .map_or_else(String::new, |(_, p, _)| p.name.clone());
                (ps.len(), victim)
            }
            None => (0, String::new()),
        };
        let subsystems: Vec<String> = self
            .spec
            .subsystems()
            .map(|(_, s)| format!("{:?}", s.name))
            .collect();
        let (mut kill, mut kill_summary) = (String::new(), String::new());
        if !victim.is_empty() {
            kill = files::parts::TEST_APP_KILL.fill(&[
                ("deployment", self.first_deployment()),
                ("processes", &processes.to_string()),
                ("victim", &victim),
            ])?;
            kill_summary = format!(",\n//! with `{victim}` killed and restarted");
        }
        let launch = match deployment {
            None => String::new(),
            Some(d) => {
                files::parts::TEST_APP_LAUNCH.fill(&[
                    ("deployment", &d.name),
                    ("processes", &processes.to_string()),
                ])? + &kill
            }
        };
        Ok(files::TESTS_APP.fill(&[
            ("summary", &match deployment {
                None => String::new(),
                Some(d) => format!(
                    ", and its deployment\n//! `{}` launched over Zenoh (each process a child of the launcher){kill_summary}",
                    d.name
                ),
            }),
            ("net", if deployment.is_some() { "use std::net::{TcpListener, UdpSocket};\n" } else { "" }),
            ("bin", &self.options.name),
            ("subsystems", &subsystems.join(", ")),
            ("launch", &launch),
        ])?)
    }

    fn types_rs(&self) -> Result<String, NewError> {
        let mut unknown = BTreeMap::new();
        let groups = |groups: &[Group], unknown: &mut BTreeMap<String, usize>| {
            for b in groups.iter().flat_map(|g| &g.buffers) {
                unknown_types(&b.ty, unknown);
            }
        };
        for a in &self.spec.agents {
            for s in &a.subsystems {
                for m in &s.memory {
                    unknown_types(&m.ty, &mut unknown);
                }
                groups(&s.inputs, &mut unknown);
                groups(&s.outputs, &mut unknown);
            }
            for d in &a.devices {
                groups(&d.inputs, &mut unknown);
                groups(&d.outputs, &mut unknown);
            }
        }
        let mut placeholders = String::new();
        for (ty, n) in &unknown {
            let generics = match n {
                0 => String::new(),
                1 => "<T0>(std::marker::PhantomData<T0>)".to_owned(),
                n => {
                    let list = (0..*n).map(|k| format!("T{k}")).collect::<Vec<_>>();
                    let list = list.join(", ");
                    format!("<{list}>(std::marker::PhantomData<({list})>)")
                }
            };
            placeholders += &parts::TYPE.fill(&[("type", ty), ("generics", &generics)])?;
        }
        let serde = if unknown.is_empty() {
            ""
        } else {
            "\nuse serde::{Deserialize, Serialize};\n"
        };
        Ok(files::TYPES.fill(&[("serde", serde), ("placeholders", &placeholders)])?)
    }

    fn logic_rs(&self) -> Result<String, NewError> {
        let mut modules = String::new();
        for name in self.subsystem_names() {
            modules += allow_case([name]);
            modules += &format!("pub mod {};\n", ident(name));
        }
        Ok(files::LOGIC.fill(&[("modules", &modules)])?)
    }

    fn logic_file(&self, agent: &Agent, sub: &Subsystem) -> Result<String, NewError> {
        let mut items = Vec::new();
        for f in &sub.functions {
            let mut lines = doc_then("    ", f.doc.as_ref());
            let (template, list) = match &f.target {
                Target::Memory | Target::Common => {
                    let what = match f.target {
                        Target::Common => "intermediate results in memory (runs first)",
                        _ => "the next memory",
                    };
                    lines += &format!("    /// Computes {what}.\n");
                    let list = vec!["memory: &mut Memory".to_owned(), "input: &Input".to_owned()];
                    (parts::MEMORY_FN, list)
                }
                Target::Output(peer) => {
                    lines += &format!("    /// Computes the outputs to `{peer}`.\n");
                    let list = vec![
                        "memory: &Memory".to_owned(),
                        "input: &Input".to_owned(),
                        format!("output: &mut To{}", type_name(peer)),
                    ];
                    (parts::OUTPUT_FN, list)
                }
            };
            if !f.reads.is_empty() {
                lines += &format!("    /// Reads: {}.\n", f.reads.join(", "));
            }
            if !f.writes.is_empty() {
                lines += &format!("    /// Writes: {}.\n", f.writes.join(", "));
            }
            let name = ident(&f.name);
            let head = format!("    fn {name}(");
            items.push(template.fill(&[
                ("doc", &lines),
                ("function_ident", &name),
                (
                    "params",
                    &params(&head, &list, ") -> Result<(), ActionError> {"),
                ),
                ("subsystem", &sub.name),
                ("function", &f.name),
            ])?);
        }
        for p in &sub.predicates {
            let mut lines = doc_then("    ", p.doc.as_ref());
            if !p.reads.is_empty() {
                lines += &format!("    /// Reads: {}.\n", p.reads.join(", "));
            }
            items.push(parts::PREDICATE.fill(&[
                ("doc", &lines),
                ("predicate_ident", &ident(&p.name)),
                ("subsystem", &sub.name),
                ("predicate", &p.name),
            ])?);
        }
        let mut imports = String::new();
        if !sub.functions.is_empty() {
            imports += "use embodied::ActionError;\n\n";
        }
        if !items.is_empty() {
            imports += "use super::placeholder;\n";
        }
        let impl_body = if items.is_empty() {
            "{}".to_owned()
        } else {
            format!("{{\n{}}}", items.join("\n"))
        };
        Ok(files::LOGIC_SUBSYSTEM.fill(&[
            ("subsystem", &sub.name),
            ("agent", &agent.name),
            ("doc", &inner_doc(sub.doc.as_ref())),
            ("imports", &imports),
            ("agent_ident", &ident(&agent.name)),
            ("subsystem_ident", &ident(&sub.name)),
            ("impl_body", &impl_body),
        ])?)
    }

    /// The subsystems' names, sorted (as rustfmt sorts `mod` lines).
    fn subsystem_names(&self) -> Vec<&str> {
        let mut names: Vec<&str> = self
            .spec
            .subsystems()
            .map(|(_, s)| s.name.as_str())
            .collect();
        names.sort_unstable();
        names
    }

    fn devices(&self) -> impl Iterator<Item = (&Agent, &Device)> {
        self.spec
            .agents
            .iter()
            .flat_map(|a| a.devices.iter().map(move |d| (a, d)))
    }

    fn devices_rs(&self) -> Result<String, NewError> {
        let mut drivers = String::new();
        for (agent, d) in self.devices() {
            let kind = match d.kind {
                DeviceKind::Effector => "Effector",
                DeviceKind::Receptor => "Receptor",
            };
            drivers += &parts::DRIVER.fill(&[
                ("doc", &doc_then("", d.doc.as_ref())),
                ("device", &d.name),
                ("agent", &agent.name),
                ("driver", &format!("{}Driver", type_name(&d.name))),
                ("kind", kind),
                ("agent_ident", &ident(&agent.name)),
                ("device_ident", &ident(&d.name)),
            ])?;
        }
        let imports = if drivers.is_empty() {
            ""
        } else {
            "\nuse embodied::{DeviceKind, Driver, DriverContext, DriverError, PortTable, Shape};\n"
        };
        Ok(files::DEVICES.fill(&[("imports", imports), ("drivers", &drivers)])?)
    }

    fn system_rs(&self) -> Result<String, NewError> {
        let (mut fields, mut values) = (String::new(), String::new());
        let (mut deployed, mut adders) = (String::new(), String::new());
        for a in &self.spec.agents {
            let agent_ident = ident(&a.name);
            for s in &a.subsystems {
                let id = ident(&s.name);
                let adder = format!("add_{id}");
                let ty = type_name(&s.name);
                fields += &parts::HANDLE_SUBSYSTEM.fill(&[
                    ("component", &s.name),
                    ("agent", &a.name),
                    ("agent_ident", &agent_ident),
                    ("ident", &id),
                    ("type", &ty),
                ])?;
                let ret = format!(
                    ") -> Result<SubsystemHandle<crate::{agent_ident}::{id}::{ty}>, Error> {{"
                );
                adders += &self.adder(
                    &parts::ADD_SUBSYSTEM,
                    &adder,
                    &ret,
                    &[
                        ("component", &s.name),
                        ("agent", &a.name),
                        ("agent_ident", &agent_ident),
                        ("ident", &id),
                        ("type", &ty),
                        (
                            "call",
                            &call(
                                "subsystem",
                                &[
                                    format!("{:?}", s.name),
                                    format!("crate::{agent_ident}::{id}::Memory::default()"),
                                    format!(
                                        "crate::{agent_ident}::{id}::fsm::<crate::logic::{id}::Logic>()?"
                                    ),
                                ],
                            ),
                        ),
                    ],
                )?;
                values += &format!("        {id}: {adder}(&mut assembly)?,\n");
                deployed += &parts::DEPLOYED.fill(&[("component", &s.name), ("adder", &adder)])?;
            }
            for d in &a.devices {
                let driver = format!("{}Driver", type_name(&d.name));
                let id = ident(&d.name);
                let adder = format!("add_{id}");
                fields += &parts::HANDLE_DRIVER.fill(&[
                    ("component", &d.name),
                    ("agent", &a.name),
                    ("ident", &id),
                    ("driver", &driver),
                ])?;
                let ret = format!(") -> Result<DriverHandle<crate::devices::{driver}>, Error> {{");
                adders += &self.adder(
                    &parts::ADD_DRIVER,
                    &adder,
                    &ret,
                    &[
                        ("component", &d.name),
                        ("agent", &a.name),
                        ("driver", &driver),
                        (
                            "call",
                            &call(
                                "driver",
                                &[
                                    format!("{:?}", d.name),
                                    format!("crate::devices::{driver}::default()"),
                                ],
                            ),
                        ),
                    ],
                )?;
                values += &format!("        {id}: {adder}(&mut assembly)?,\n");
                deployed += &parts::DEPLOYED.fill(&[("component", &d.name), ("adder", &adder)])?;
            }
        }
        let components = self.spec.agents.iter().flat_map(|a| {
            (a.subsystems.iter().map(|s| s.name.as_str()))
                .chain(a.devices.iter().map(|d| d.name.as_str()))
        });
        let mut names = Vec::new();
        if self.devices().next().is_some() {
            names.push("DriverHandle");
        }
        if self.spec.subsystems().next().is_some() {
            names.push("SubsystemHandle");
        }
        names.push("System");
        // In rustfmt's order: `embodied::spec` items, then `embodied::{...}`.
        let imports = format!(
            "use embodied::spec::{{Assembly, Spec}};\nuse embodied::{}{}{};\n",
            if names.len() > 1 { "{" } else { "" },
            names.join(", "),
            if names.len() > 1 { "}" } else { "" },
        );
        Ok(files::SYSTEM.fill(&[
            ("imports", &imports),
            ("allow", allow_case(components)),
            ("fields", &fields),
            ("values", &values),
            ("deployed", &deployed),
            ("adders", &adders),
        ])?)
    }

    /// The function that adds one component: `template` filled with its name
    /// `adder` and its parameter laid out as rustfmt would before `ret`.
    fn adder(
        &self,
        template: &files::Template,
        adder: &str,
        ret: &str,
        slots: &[(&str, &str)],
    ) -> Result<String, NewError> {
        let head = format!("fn {adder}(");
        let params = params(&head, &["assembly: &mut Assembly<'_>".to_owned()], ret);
        let mut all = vec![("adder", adder), ("params", params.as_str())];
        all.extend_from_slice(slots);
        let text = template.fill(&all)?;
        Ok(match allow_case([adder]) {
            "" => text,
            allow => text.replacen("\nfn ", &format!("\n{allow}fn "), 1),
        })
    }

    fn tests_rs(&self) -> Result<String, NewError> {
        let inputs = self.spec.subsystems().any(|(_, s)| any_buffer(&s.inputs));
        let termination = self.spec.subsystems().any(|(_, s)| !ending(s).is_empty());
        let mut imports = String::new();
        if termination {
            imports += "use std::collections::BTreeSet;\n";
        }
        imports += "use std::time::Duration;\n\n";
        if termination {
            imports += "use embodied::testing::TerminationFailure;\n";
        }
        imports += if inputs {
            "use embodied::{ExecConfig, Executor, Stamp, Time};\n"
        } else {
            "use embodied::{ExecConfig, Executor};\n"
        };
        let mut modules = String::new();
        for name in self.subsystem_names() {
            modules += allow_case([name]);
            modules += &format!("mod {};\n", ident(name));
        }
        let mut helpers = String::new();
        if inputs {
            helpers += &parts::TEST_STAMP.fill(&[])?;
        }
        if termination {
            helpers += &parts::TEST_VERDICT.fill(&[])?;
        }
        Ok(files::TESTS.fill(&[
            ("imports", &imports),
            ("modules", &modules),
            ("lib", self.lib),
            ("spec_name", &self.spec.name),
            ("helpers", &helpers),
        ])?)
    }

    fn test_file(&self, agent: &Agent, sub: &Subsystem) -> Result<String, NewError> {
        let ending = ending(sub);
        let module = format!("{}::{}::{}", self.lib, ident(&agent.name), ident(&sub.name));
        let ty = type_name(&sub.name);
        let name = sub.name.as_str();

        let mut uses = vec![
            format!("use {}::logic::{}::Logic;", self.lib, ident(name)),
            if ending.is_empty() {
                format!("use {module}::{{Input, Memory, Output, fsm}};")
            } else {
                format!("use {module}::{{{ty}, Input, Memory, Output, fsm}};")
            },
        ];
        let mut imports = String::new();
        if !ending.is_empty() {
            imports += "use embodied::testing::{Environment, Termination};\n";
            uses.push(format!("use {}::logic::placeholders_in;", self.lib));
        }
        uses.sort();
        imports += "use proptest::prelude::*;\n\n";
        imports += &uses.join("\n");
        imports += "\n";

        let inputs: Vec<(String, String)> = sub
            .inputs
            .iter()
            .flat_map(|g| {
                g.buffers
                    .iter()
                    .map(move |b| (ident(&g.peer), ident(&b.name)))
            })
            .collect();
        let input_fn = if inputs.is_empty() {
            parts::TEST_INPUT_NONE.fill(&[])?
        } else {
            let mut deliveries = String::new();
            for (bit, (peer, buffer)) in inputs.iter().take(128).enumerate() {
                deliveries += &parts::TEST_DELIVER.fill(&[
                    ("bit", &bit.to_string()),
                    ("peer", peer),
                    ("buffer", buffer),
                ])?;
            }
            parts::TEST_INPUT.fill(&[("deliveries", &deliveries)])?
        };

        let mut termination = String::new();
        if !ending.is_empty() {
            termination += &if inputs.is_empty() {
                parts::TEST_WORLD_NONE.fill(&[("subsystem", name), ("type", &ty)])?
            } else {
                let (mut deliver, mut age) = (String::new(), String::new());
                for (peer, buffer) in &inputs {
                    let slots = [("peer", peer.as_str()), ("buffer", buffer)];
                    deliver += &parts::TEST_WORLD_DELIVER.fill(&slots)?;
                    age += &parts::TEST_WORLD_AGE.fill(&slots)?;
                }
                let example = sub
                    .outputs
                    .iter()
                    .find_map(|g| {
                        let b = g.buffers.first()?;
                        Some(format!("y.{}.{}.written()", ident(&g.peer), ident(&b.name)))
                    })
                    .unwrap_or_else(|| "y.<peer>.<buffer>.written()".to_owned());
                parts::TEST_WORLD.fill(&[
                    ("subsystem", name),
                    ("type", &ty),
                    ("example", &example),
                    ("deliver", &deliver),
                    ("age", &age),
                ])?
            };
            for (b, f) in &ending {
                termination += &parts::TEST_TERMINATION.fill(&[
                    ("subsystem", name),
                    ("behaviour", &b.name),
                    ("fn", f),
                    ("kind", &b.kind.to_string()),
                    ("terminal", &b.terminal),
                ])?;
            }
        }

        let (summary, guide) = if ending.is_empty() {
            (".".to_owned(), String::new())
        } else {
            (
                ", and each behaviour that can end does, in a model of its world.".to_owned(),
                parts::TEST_GUIDE.fill(&[("subsystem", name)])?,
            )
        };
        Ok(files::TESTS_SUBSYSTEM.fill(&[
            ("subsystem", name),
            ("agent", &agent.name),
            ("summary", &summary),
            ("guide", &guide),
            ("imports", &imports),
            ("input_fn", &input_fn),
            ("behaviours", &sub.behaviours.len().max(1).to_string()),
            ("termination", &termination),
        ])?)
    }
}
