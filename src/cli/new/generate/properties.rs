//! The crate's property tests: `tests/properties/main.rs` and a file per
//! subsystem (no elementary action panics; each behaviour that can end does,
//! in a model of its world).

use std::collections::BTreeSet;

use embodied::spec::model::{Agent, Group, Subsystem};

use super::text::allow_case;
use super::{Crate, NewError, files, ident, parts, type_name};

/// Whether a group list has a buffer.
pub(super) fn any_buffer(groups: &[Group]) -> bool {
    groups.iter().any(|g| !g.buffers.is_empty())
}

/// The behaviours of a subsystem that can end (a terminal condition other than
/// `false`), with a unique snake-case name for the tests' functions.
pub(super) fn ending(sub: &Subsystem) -> Vec<(&embodied::spec::model::Behaviour, String)> {
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

impl Crate<'_> {
    pub(super) fn tests_rs(&self) -> Result<String, NewError> {
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

    pub(super) fn test_file(&self, agent: &Agent, sub: &Subsystem) -> Result<String, NewError> {
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
