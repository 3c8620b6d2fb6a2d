//! `embodied new`: a new agent crate from a spec.
//!
//! The crate compiles as generated and its tests run: the spec's types, buffers and
//! FSMs come from `embodied::agent!`; every transition function and predicate is a
//! stub that writes nothing (predicates are false) in `src/logic/<subsystem>.rs`;
//! every device is a stub driver in `src/devices.rs`; `src/system.rs` builds the
//! whole system with the spec's periods and links; `src/types.rs` holds a placeholder
//! for each type the spec names that is not a Rust standard type. The generated
//! tests check that the system has the spec's structure, that it runs, that no
//! elementary action panics whatever inputs are new, and (ignored until the
//! functions and an environment model are written) that each behaviour terminates.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::PathBuf;

use crate::Report;
use crate::model::{DeviceKind, Spec, Target};
use crate::names::{KEYWORDS, rust_ident as id, type_name as camel};

/// Where the new crate finds `embodied`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Dependency {
    /// A path to the `embodied` crate (its directory).
    Path(PathBuf),
    /// A version requirement from crates.io.
    Version(String),
}

/// What `embodied new` was asked for.
#[derive(Clone, Debug)]
pub struct Options {
    /// The crate's name (`[a-z][a-z0-9_-]*`).
    pub name: String,
    /// Where `embodied` comes from.
    pub embodied: Dependency,
}

/// One file of the new crate.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct File {
    /// Path relative to the crate's directory.
    pub path: PathBuf,
    /// Its text.
    pub contents: String,
}

/// Why no crate could be made.
#[derive(Debug, thiserror::Error)]
pub enum ScaffoldError {
    /// The crate name is not a valid package name.
    #[error(
        "`{0}` is not a valid crate name: use lowercase letters, digits, `_` and `-`, starting with a letter"
    )]
    Name(String),
    /// An agent's name is one of the crate's own modules.
    #[error(
        "agent `{0}` would share its name with the crate's module `{0}`; rename the agent in the spec"
    )]
    AgentName(String),
    /// The spec has errors (the report says which).
    #[error("the spec has {} error(s); `embodied check` shows them", .0.errors())]
    Spec(Box<Report>),
}

/// Names a new crate cannot take: its dependencies' and the standard library's.
const TAKEN_CRATE_NAMES: &[&str] = &[
    "embodied", "serde", "proptest", "std", "core", "alloc", "test",
];

/// The crate's own modules, which agents' modules stand beside.
const CRATE_MODULES: &[&str] = &["devices", "logic", "system", "types"];

/// Standard types a spec may name without a placeholder.
const KNOWN: &[&str] = &[
    "bool",
    "char",
    "str",
    "u8",
    "u16",
    "u32",
    "u64",
    "u128",
    "usize",
    "i8",
    "i16",
    "i32",
    "i64",
    "i128",
    "isize",
    "f32",
    "f64",
    "String",
    "Option",
    "Vec",
    "VecDeque",
    "HashMap",
    "HashSet",
    "BTreeMap",
    "BTreeSet",
    "BinaryHeap",
    "Box",
    "Result",
    "Arc",
    "Rc",
    "Cow",
    "Duration",
];

/// The number of type arguments in the `<...>` that starts `rest`, if it starts one.
fn arity(rest: &str) -> usize {
    if !rest.starts_with('<') {
        return 0;
    }
    let (mut depth, mut commas) = (0i32, 0usize);
    for c in rest.chars() {
        match c {
            '<' | '(' | '[' => depth += 1,
            '>' | ')' | ']' => {
                depth -= 1;
                if depth == 0 {
                    break;
                }
            }
            ',' if depth == 1 => commas += 1,
            _ => {}
        }
    }
    commas + 1
}

/// The type names in a spec type that need a placeholder, with their number of type
/// arguments: identifiers that are not standard, not part of a path
/// (`nalgebra::Vector3` is the user's to import) and not lifetimes.
fn unknown_types(ty: &str, out: &mut BTreeMap<String, usize>) {
    let bytes = ty.as_bytes();
    let mut i = 0;
    while i < bytes.len() {
        let c = bytes[i] as char;
        if c.is_ascii_alphabetic() || c == '_' {
            let start = i;
            while i < bytes.len()
                && ((bytes[i] as char).is_ascii_alphanumeric() || bytes[i] == b'_')
            {
                i += 1;
            }
            let word = &ty[start..i];
            let after_path = ty[..start].ends_with("::");
            let before_path = ty[i..].starts_with("::");
            let lifetime = ty[..start].ends_with('\'');
            if !(after_path
                || before_path
                || lifetime
                || KNOWN.contains(&word)
                || KEYWORDS.contains(&word))
            {
                let n = arity(ty[i..].trim_start());
                let known = out.entry(word.to_owned()).or_insert(n);
                *known = (*known).max(n);
            }
        } else {
            i += 1;
        }
    }
}

/// The spec's doc text as inner doc lines (`//!`), after an empty one.
fn inner_doc(out: &mut String, text: Option<&String>) {
    if let Some(t) = text {
        let _ = writeln!(out, "//!");
        for line in t.lines() {
            let _ = writeln!(out, "//! {line}");
        }
    }
}

/// The spec's doc text as doc comment lines, then an empty one before what follows.
fn doc_lines(out: &mut String, indent: &str, text: Option<&String>) {
    if let Some(t) = text {
        for line in t.lines() {
            let _ = writeln!(out, "{indent}/// {line}");
        }
        let _ = writeln!(out, "{indent}///");
    }
}

/// The files of a new crate for `source` (the spec's text, named `file`).
pub fn scaffold(file: &str, source: &str, options: &Options) -> Result<Vec<File>, ScaffoldError> {
    let name = &options.name;
    let valid_name = name.starts_with(|c: char| c.is_ascii_lowercase())
        && name
            .chars()
            .all(|c| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '_' || c == '-');
    let lib = name.replace('-', "_");
    if !valid_name || KEYWORDS.contains(&lib.as_str()) || TAKEN_CRATE_NAMES.contains(&lib.as_str())
    {
        return Err(ScaffoldError::Name(name.clone()));
    }
    let (spec, report) = crate::check_source(file, source);
    let spec = match spec {
        Some(s) if report.is_ok() => s,
        _ => return Err(ScaffoldError::Spec(Box::new(report))),
    };
    if let Some(a) = spec
        .agents
        .iter()
        .find(|a| CRATE_MODULES.contains(&a.name.as_str()))
    {
        return Err(ScaffoldError::AgentName(a.name.clone()));
    }
    let files = vec![
        File {
            path: "Cargo.toml".into(),
            contents: cargo_toml(name, &options.embodied),
        },
        File {
            path: "spec.ron".into(),
            contents: source.to_owned(),
        },
        File {
            path: "README.md".into(),
            contents: readme(name, file, &spec),
        },
        File {
            path: "src/lib.rs".into(),
            contents: lib_rs(file, &spec),
        },
        File {
            path: "src/types.rs".into(),
            contents: types_rs(&spec),
        },
        File {
            path: "src/logic.rs".into(),
            contents: logic_rs(&spec),
        },
        File {
            path: "src/devices.rs".into(),
            contents: devices_rs(&spec),
        },
        File {
            path: "src/system.rs".into(),
            contents: system_rs(&spec),
        },
        File {
            path: "tests/properties.rs".into(),
            contents: properties_rs(&lib, &spec),
        },
    ];
    let mut files = files;
    for (agent, sub) in spec.subsystems() {
        files.push(File {
            path: format!("src/logic/{}.rs", sub.name).into(),
            contents: logic_file(&agent.name, sub),
        });
    }
    Ok(files)
}

fn cargo_toml(name: &str, dep: &Dependency) -> String {
    let embodied = match dep {
        Dependency::Path(p) => format!("{{ path = {:?} }}", p.display().to_string()),
        Dependency::Version(v) => format!("{v:?}"),
    };
    format!(
        r#"[package]
name = "{name}"
version = "0.1.0"
edition = "2024"
publish = false

[dependencies]
embodied = {embodied}
serde = {{ version = "1", features = ["derive"] }}

[dev-dependencies]
proptest = "1"

# A crate of its own, even when created inside another workspace.
[workspace]
"#
    )
}

fn lib_rs(file: &str, spec: &Spec) -> String {
    let mut s = String::new();
    let _ = writeln!(
        s,
        "//! `{}`: generated by `embodied new` from `{file}` (copied to `spec.ron`).",
        spec.name
    );
    inner_doc(&mut s, spec.doc.as_ref());
    s.push_str(
        "//!\n//! The types, buffers and FSMs come from the spec through `embodied::agent!`: edit\n\
         //! `spec.ron` and the code follows (a function the spec adds is a compile error\n\
         //! until `src/logic/` implements it). See README.md for what to fill in.\n\n\
         pub mod devices;\npub mod logic;\npub mod system;\npub mod types;\n",
    );
    for a in &spec.agents {
        let _ = writeln!(s);
        doc_lines(&mut s, "", a.doc.as_ref());
        let _ = writeln!(
            s,
            "/// Agent `{0}` of the spec: one module per component.\npub mod {1} {{\n    #[allow(unused_imports)]\n    use crate::types::*;\n    embodied::agent!(spec = \"spec.ron\", agent = \"{0}\", memory_derive = [Default]);\n}}",
            a.name,
            id(&a.name)
        );
    }
    s
}

fn types_rs(spec: &Spec) -> String {
    let mut unknown = BTreeMap::new();
    for a in &spec.agents {
        for s in &a.subsystems {
            for m in &s.memory {
                unknown_types(&m.ty, &mut unknown);
            }
            for g in s.inputs.iter().chain(&s.outputs) {
                g.buffers
                    .iter()
                    .for_each(|b| unknown_types(&b.ty, &mut unknown));
            }
        }
        for d in &a.devices {
            for g in d.inputs.iter().chain(&d.outputs) {
                g.buffers
                    .iter()
                    .for_each(|b| unknown_types(&b.ty, &mut unknown));
            }
        }
    }
    let mut s = String::from(
        "//! The types the spec names. Each placeholder below stands for a type of yours:\n\
         //! replace it with the real definition (or a `pub use` of it). Buffer payloads\n\
         //! must be `Clone + Debug + Serialize + Deserialize + Send`; memory types\n\
         //! `Clone + Debug + Default` (the generated memory derives them).\n\n\
         #[allow(unused_imports)]\n\
         pub use std::{\n    borrow::Cow,\n    collections::{BTreeMap, BTreeSet, BinaryHeap, HashMap, HashSet, VecDeque},\n    rc::Rc,\n    sync::Arc,\n    time::Duration,\n};\n",
    );
    for (t, n) in &unknown {
        let derive = "#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize)]";
        let _ = write!(
            s,
            "\n/// Placeholder for the spec's type `{t}`: replace it with yours.\n{derive}\n"
        );
        if *n == 0 {
            let _ = writeln!(s, "pub struct {t};");
        } else {
            let params: Vec<String> = (0..*n).map(|k| format!("T{k}")).collect();
            let _ = writeln!(
                s,
                "pub struct {t}<{p}>(std::marker::PhantomData<({p},)>);",
                p = params.join(", ")
            );
        }
    }
    s
}

fn logic_rs(spec: &Spec) -> String {
    let mut s = String::from(
        "//! The transition functions and predicates of each subsystem, one file each.\n\n",
    );
    for (_, sub) in spec.subsystems() {
        let _ = writeln!(s, "pub mod {};", id(&sub.name));
    }
    s
}

fn logic_file(agent: &str, sub: &crate::model::Subsystem) -> String {
    let path = format!("crate::{}::{}", id(agent), id(&sub.name));
    let mut s = format!(
        "//! `{name}` of agent `{agent}`: the transition functions and predicates the spec\n\
         //! names. Each stub writes nothing (a predicate is false); replace the bodies.\n",
        name = sub.name
    );
    inner_doc(&mut s, sub.doc.as_ref());
    if !sub.functions.is_empty() {
        s.push_str("\nuse embodied::ActionError;\n");
    }
    let _ = write!(
        s,
        "\n#[allow(unused_imports)]\nuse {path}::*;\n\n\
         /// The behaviour of `{}`: the spec's functions over its memory and buffers.\n\
         #[derive(Debug)]\npub struct Logic;\n\nimpl Functions for Logic {{\n",
        sub.name
    );
    for f in &sub.functions {
        doc_lines(&mut s, "    ", f.doc.as_ref());
        let what = match &f.target {
            Target::Memory => "the next memory".to_owned(),
            Target::Common => "intermediate results in memory (runs first)".to_owned(),
            Target::Output(p) => format!("the outputs to `{p}`"),
        };
        let _ = writeln!(s, "    /// Computes {what}.");
        if !f.reads.is_empty() {
            let _ = writeln!(s, "    /// Reads: {}.", f.reads.join(", "));
        }
        if !f.writes.is_empty() {
            let _ = writeln!(s, "    /// Writes: {}.", f.writes.join(", "));
        }
        let sig = match &f.target {
            Target::Memory | Target::Common => {
                "memory: &mut Memory, input: &Input) -> Result<(), ActionError> {\n        let _ = (memory, input);".to_owned()
            }
            Target::Output(p) => format!(
                "memory: &Memory, input: &Input, output: &mut To{}) -> Result<(), ActionError> {{\n        let _ = (memory, input, output);",
                camel(p)
            ),
        };
        let _ = writeln!(s, "    fn {}({sig}\n        Ok(())\n    }}\n", id(&f.name));
    }
    for p in &sub.predicates {
        doc_lines(&mut s, "    ", p.doc.as_ref());
        if !p.reads.is_empty() {
            let _ = writeln!(s, "    /// Reads: {}.", p.reads.join(", "));
        }
        let _ = writeln!(
            s,
            "    fn {}(memory: &Memory, input: &Input) -> bool {{\n        let _ = (memory, input);\n        false\n    }}\n",
            id(&p.name)
        );
    }
    let trimmed = s.trim_end().len();
    s.truncate(trimmed);
    s.push_str("\n}\n");
    s
}

fn devices_rs(spec: &Spec) -> String {
    let mut s = String::from(
        "//! The real effectors and receptors: stub drivers that read nothing and write\n\
         //! nothing. Replace each with the driver of your hardware or simulator.\n",
    );
    if spec.agents.iter().any(|a| !a.devices.is_empty()) {
        s.push_str("\nuse embodied::{DeviceKind, Driver, DriverContext, DriverError, Shape};\n");
    }
    for a in &spec.agents {
        for d in &a.devices {
            let _ = writeln!(s);
            doc_lines(&mut s, "", d.doc.as_ref());
            let kind = match d.kind {
                DeviceKind::Effector => "Effector",
                DeviceKind::Receptor => "Receptor",
            };
            let m = format!("crate::{}::{}", id(&a.name), id(&d.name));
            let _ = write!(
                s,
                "/// Device `{name}` of agent `{agent}` (a stub).\n#[derive(Debug, Default)]\npub struct {camel}Driver;\n\n\
                 impl Driver for {camel}Driver {{\n    const KIND: DeviceKind = DeviceKind::{kind};\n    type Input = {m}::Input;\n    type Output = {m}::Output;\n\n\
                 \x20   fn shape() -> Option<Shape> {{\n        Some(Shape::of_driver::<Self>())\n    }}\n\n\
                 \x20   fn step(\n        &mut self,\n        _: DriverContext,\n        _: &Self::Input,\n        _: &mut Self::Output,\n    ) -> Result<(), DriverError> {{\n        Ok(())\n    }}\n}}\n",
                name = d.name,
                agent = a.name,
                camel = camel(&d.name)
            );
        }
    }
    s
}

fn system_rs(spec: &Spec) -> String {
    let devices = spec.agents.iter().any(|a| !a.devices.is_empty());
    let mut imports = vec![
        "Period",
        "PeriodError",
        "SubsystemHandle",
        "System",
        "SystemBuilder",
    ];
    if devices {
        imports.push("DriverHandle");
    }
    if !spec.links.is_empty() {
        imports.extend(["Policy", "port"]);
    }
    imports.sort_unstable();
    let mut s = format!(
        "//! The whole system of the spec: every component with its period and initial\n\
         //! memory (`Default`; set your own here), every link with its policy.\n\n\
         use embodied::{{{}}};\n\n\
         /// Handles to every component, for reading memories and statistics.\n\
         #[allow(non_snake_case)]\npub struct Handles {{\n",
        imports.join(", ")
    );
    let mut kinds = Vec::new();
    for a in &spec.agents {
        for sub in &a.subsystems {
            let ty = format!(
                "crate::{}::{}::{}",
                id(&a.name),
                id(&sub.name),
                camel(&sub.name)
            );
            let _ = writeln!(
                s,
                "    /// `{}`.\n    pub {}: SubsystemHandle<{ty}>,",
                sub.name,
                id(&sub.name)
            );
            kinds.push((a.name.clone(), sub.name.clone(), false));
        }
        for d in &a.devices {
            let _ = writeln!(
                s,
                "    /// `{}`.\n    pub {}: DriverHandle<crate::devices::{}Driver>,",
                d.name,
                id(&d.name),
                camel(&d.name)
            );
            kinds.push((a.name.clone(), d.name.clone(), true));
        }
    }
    s.push_str(
        "}\n\n/// A period in milliseconds, as the spec gives it (the checker's rule).\nfn period(ms: f64) -> Result<Period, PeriodError> {\n    Period::from_millis_f64(ms)\n}\n\n\
         /// Build the system of the spec.\n#[allow(non_snake_case)]\npub fn build() -> Result<(System, Handles), Box<dyn std::error::Error + Send + Sync>> {\n    let mut sys = SystemBuilder::new();\n",
    );
    for a in &spec.agents {
        let _ = writeln!(s, "    let agent_{} = sys.agent(\"{}\");", a.name, a.name);
    }
    for (agent, comp, device) in &kinds {
        let m = format!("crate::{}::{}", id(agent), id(comp));
        if *device {
            let _ = writeln!(
                s,
                "    let node_{comp} = sys.driver(agent_{agent}, \"{comp}\", period({m}::PERIOD_MS)?, crate::devices::{c}Driver);",
                c = camel(comp)
            );
        } else {
            let _ = writeln!(
                s,
                "    let node_{comp} = sys.subsystem(\n        agent_{agent},\n        \"{comp}\",\n        period({m}::PERIOD_MS)?,\n        {m}::Memory::default(),\n        {m}::fsm::<crate::logic::{v}::Logic>()?,\n    );",
                v = id(comp)
            );
        }
    }
    let module_of = |comp: &str| {
        kinds
            .iter()
            .find(|(_, c, _)| c == comp)
            .map(|(a, c, _)| format!("crate::{}::{}", id(a), id(c)))
            .unwrap_or_default()
    };
    for l in &spec.links {
        let (Some((fc, fg, fb)), Some((tc, tg, tb))) = (split3(&l.from), split3(&l.to)) else {
            continue;
        };
        let policy = match l.policy {
            crate::model::Policy::Sample => "Policy::Sample".to_owned(),
            crate::model::Policy::Queue { bound } => format!("Policy::queue({bound})"),
        };
        let _ = writeln!(
            s,
            "    sys.connect(\n        node_{fc}.output(port!({}::Output, {}.{})),\n        node_{tc}.input(port!({}::Input, {}.{})),\n        {policy},\n    );",
            module_of(fc),
            id(fg),
            id(fb),
            module_of(tc),
            id(tg),
            id(tb)
        );
    }
    let names: Vec<String> = kinds
        .iter()
        .map(|(_, c, _)| format!("{}: node_{c}", id(c)))
        .collect();
    let _ = writeln!(
        s,
        "    let handles = Handles {{ {} }};\n    Ok((sys.build()?, handles))\n}}",
        names.join(", ")
    );
    s
}

fn split3(endpoint: &str) -> Option<(&str, &str, &str)> {
    let mut it = endpoint.split('.');
    let r = (it.next()?, it.next()?, it.next()?);
    it.next().is_none().then_some(r)
}

fn properties_rs(lib: &str, spec: &Spec) -> String {
    let terminating = spec
        .subsystems()
        .any(|(_, s)| s.behaviours.iter().any(|b| b.terminal.trim() != "false"));
    let inputs = spec
        .subsystems()
        .any(|(_, s)| s.inputs.iter().any(|g| !g.buffers.is_empty()));
    let testing = if terminating {
        "use embodied::testing::{Script, Termination};\n"
    } else {
        ""
    };
    let stamp = if inputs {
        "\n/// The stamp of every value the tests deliver.\nfn stamp() -> Stamp {\n    Stamp::new(0, Time::ZERO)\n}\n"
    } else {
        ""
    };
    let mut s = format!(
        r#"//! Tests generated by `embodied new` from the spec: the structure, a run, and one
//! property per subsystem (no elementary action panics) run as generated; the
//! termination properties wait (`#[ignore]`) until the functions and a model of each
//! subsystem's environment are written.

use std::time::Duration;

{testing}use embodied::*;
use proptest::prelude::*;

/// The system built from the code has the structure of `spec.ron`: components,
/// kinds, periods, buffers and their types, predicates, functions, behaviours, arcs
/// and links. The code cannot drift from the spec.
#[test]
fn the_system_is_the_spec() {{
    let (system, _) = {lib}::system::build().expect("the system builds");
    let exported = embodied::spec::export::spec_of({name:?}, system.info())
        .expect("every component is described");
    let (spec, report) = embodied::spec::check_source("spec.ron", include_str!("../spec.ron"));
    assert!(report.is_ok(), "{{}}", report.short());
    let spec = spec.expect("the spec parses");
    if let Some(d) = embodied::spec::export::difference(&spec.structure(), &exported.structure()) {{
        panic!("the system built differs from spec.ron: {{d}}");
    }}
}}

/// The system runs for a second of virtual time without an error.
#[test]
fn the_system_runs() {{
    let (system, _) = {lib}::system::build().expect("the system builds");
    let mut exec = Executor::new(system, ExecConfig::default());
    exec.run_for(Duration::from_secs(1)).expect("no error");
}}
{stamp}"#,
        name = spec.name
    );
    for (agent, sub) in spec.subsystems() {
        let m = format!("{lib}::{}::{}", id(&agent.name), id(&sub.name));
        let v = &sub.name;
        let _ = write!(
            s,
            "\n// ---------------------------------------------------------------------------\n// `{v}`\n\n\
             /// Inputs of `{v}` in which the buffers whose bit is set in `fresh` are new\n\
             /// (holding `Default` values; the others never received anything).\n\
             fn {v}_input(fresh: u128) -> {m}::Input {{\n    #[allow(unused_mut)]\n    let mut x = {m}::Input::default();\n"
        );
        let mut k = 0u32;
        for g in &sub.inputs {
            for b in &g.buffers {
                if k < 128 {
                    let _ = writeln!(
                        s,
                        "    if fresh >> {k} & 1 == 1 {{\n        x.{}.{}.deliver(Default::default(), stamp());\n    }}",
                        id(&g.peer),
                        id(&b.name)
                    );
                }
                k += 1;
            }
        }
        let _ = write!(
            s,
            "    let _ = fresh;\n    x\n}}\n\n\
             proptest! {{\n    /// Every elementary action of `{v}` completes or returns an error, whichever\n    /// inputs are new: it never panics.\n\
             \x20   #[test]\n    fn {v}_actions_never_panic(fresh in any::<u128>(), behaviour in 0..{n}usize) {{\n\
             \x20       let fsm = {m}::fsm::<{lib}::logic::{id}::Logic>().expect(\"the spec's FSM\");\n\
             \x20       let mut state = fsm.start_at(behaviour).expect(\"a behaviour\");\n\
             \x20       let mut memory = {m}::Memory::default();\n\
             \x20       let mut output = {m}::Output::default();\n\
             \x20       let _ = fsm.act(&mut state, &mut memory, &{v}_input(fresh), &mut output);\n    }}\n}}\n",
            n = sub.behaviours.len().max(1),
            id = id(v),
        );
        let ending: Vec<_> = sub
            .behaviours
            .iter()
            .filter(|b| b.terminal.trim() != "false")
            .collect();
        if ending.is_empty() {
            continue;
        }
        let _ = write!(
            s,
            "\n/// Fill in: initial memories of `{v}` worth testing.\n\
             fn {v}_memory() -> impl Strategy<Value = {m}::Memory> {{\n    Just({m}::Memory::default())\n}}\n\n\
             /// Fill in: a model of what the rest of the world sends `{v}` (here: random\n\
             /// freshness of default values; a reactive model implements `testing::Environment`).\n\
             fn {v}_environment() -> impl Strategy<Value = Script<{m}::{marker}>> {{\n\
             \x20   prop::collection::vec(any::<u128>(), 1..50)\n        .prop_map(|v| Script::new(v.into_iter().map({v}_input).collect()))\n}}\n",
            marker = camel(v)
        );
        for b in ending {
            let _ = write!(
                s,
                "\n/// Behaviour `{bn}` of `{v}` ends within 1000 iterations.\n#[test]\n\
                 #[ignore = \"write {v}'s functions and its environment model first, then remove this line\"]\n\
                 fn {v}_{lower}_terminates() {{\n    let fsm = {m}::fsm::<{lib}::logic::{id}::Logic>().expect(\"the spec's FSM\");\n\
                 \x20   let result = Termination::within(1000).behaviour(&fsm, {bn:?}, {v}_memory(), {v}_environment());\n\
                 \x20   if let Err(e) = result {{\n        panic!(\"{{e}}\");\n    }}\n}}\n",
                bn = b.name,
                lower = b.name.to_lowercase(),
                id = id(v)
            );
        }
    }
    s
}

fn readme(name: &str, file: &str, spec: &Spec) -> String {
    let mut subs = String::new();
    for (a, sub) in spec.subsystems() {
        let _ = writeln!(
            subs,
            "| `src/logic/{}.rs` | `{}` of agent `{}`: {} functions, {} predicates |",
            sub.name,
            sub.name,
            a.name,
            sub.functions.len(),
            sub.predicates.len()
        );
    }
    format!(
        r#"# {name}

An embodied-agent system generated by `embodied new` from `{file}` (copied to
`spec.ron`). It compiles and its tests run as generated; the behaviour is yours to
write.

```sh
cargo test                  # structure, a run, actions that never panic
cargo test -- --ignored     # termination of every behaviour, once filled in
embodied check spec.ron     # the checker; `embodied diagram spec.ron --kind fsm`
```

## What to fill in

| file | what |
|---|---|
| `src/types.rs` | a placeholder for each type the spec names: replace with your types |
{subs}| `src/devices.rs` | a stub driver per device: your hardware or simulator |
| `src/system.rs` | initial memories (`Default` now) |
| `tests/properties.rs` | `<subsystem>_memory` and `<subsystem>_environment`: the cases for the termination properties; then remove their `#[ignore]` |

Each function in `src/logic/` computes one part of a behaviour's transition
function: `memory` and `common` parts get `&mut Memory`, an output part gets `&mut`
to the one group of buffers it writes. Each predicate is an atom of the spec's
terminal and initial conditions. The stubs write nothing and answer `false`.

## What cannot drift

`src/lib.rs` generates the memory, buffers, markers and FSMs from `spec.ron` with
`embodied::agent!`, checking the spec at compile time (a checker error is a compile
error `spec.ron:line:col`). Add a function to the spec and the crate stops compiling
until `src/logic/` implements it; rename one and the compiler names it.
`tests/properties.rs::the_system_is_the_spec` exports the spec of the built system
and compares it with `spec.ron`.
"#
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn unknown_types_skip_standard_paths_and_lifetimes() {
        let mut out = BTreeMap::new();
        for t in [
            "Option<MapPose>",
            "Vec<(u8, Plan)>",
            "[f64; 4]",
            "nalgebra::Vector3<f64>",
            "HashMap<String, Ack>",
            "&'static str",
            "Grid<(u8, u8), Cell<f64>>",
            "Arc<Duration>",
        ] {
            unknown_types(t, &mut out);
        }
        assert_eq!(out.get("Grid"), Some(&2));
        assert_eq!(out.get("Cell"), Some(&1));
        out.retain(|_, n| *n == 0);
        assert_eq!(
            out.into_keys().collect::<Vec<_>>(),
            ["Ack", "MapPose", "Plan"]
        );
    }

    #[test]
    fn a_crate_is_made_only_from_a_valid_spec_and_name() {
        let opts = |name: &str| Options {
            name: name.into(),
            embodied: Dependency::Version("0.1".into()),
        };
        let source = include_str!("../../specs/tank.ron");
        let files = scaffold("tank.ron", source, &opts("my-tank")).expect("a crate");
        let paths: Vec<String> = files.iter().map(|f| f.path.display().to_string()).collect();
        for p in [
            "Cargo.toml",
            "src/lib.rs",
            "src/logic/c1.rs",
            "src/logic/c2.rs",
            "tests/properties.rs",
        ] {
            assert!(paths.contains(&p.to_owned()), "{p} in {paths:?}");
        }
        let types = &files
            .iter()
            .find(|f| f.path.ends_with("types.rs"))
            .expect("types")
            .contents;
        assert!(types.contains("pub struct Order;") && types.contains("pub struct StationParams;"));
        let system = &files
            .iter()
            .find(|f| f.path.ends_with("system.rs"))
            .expect("system")
            .contents;
        assert!(
            system.contains("c2.output(port!(crate::operator::c2::Output, c1.order))"),
            "{system}"
        );
        assert!(matches!(
            scaffold("t.ron", source, &opts("My Tank")),
            Err(ScaffoldError::Name(_))
        ));
        let broken = source.replace("terminal: \"settled\"", "terminal: \"setled\"");
        assert!(matches!(
            scaffold("t.ron", &broken, &opts("t")),
            Err(ScaffoldError::Spec(_))
        ));
    }
}
