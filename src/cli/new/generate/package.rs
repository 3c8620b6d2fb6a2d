//! The crate's package files: `Cargo.toml`, `.cargo/config.toml`, the README,
//! `src/lib.rs`, `src/main.rs` and `tests/app.rs`.

use super::properties::ending;
use super::text::{aligned, doc_then, inner_doc, toml_string};
use super::{Crate, LOCAL, NewError, files, ident, parts};

impl Crate<'_> {
    pub(super) fn cargo_toml(&self) -> Result<String, NewError> {
        Ok(files::CARGO_TOML.fill(&[
            ("name", &self.options.name),
            ("embodied_version", &self.options.embodied_version),
            ("rust_version", env!("CARGO_PKG_RUST_VERSION")),
        ])?)
    }

    pub(super) fn cargo_config(&self, path: &std::path::Path) -> Result<String, NewError> {
        Ok(files::CARGO_CONFIG.fill(&[
            ("embodied_version", &self.options.embodied_version),
            ("embodied_path", &toml_string(&path.display().to_string())),
        ])?)
    }

    pub(super) fn readme(&self) -> Result<String, NewError> {
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

    pub(super) fn lib_rs(&self) -> Result<String, NewError> {
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

    pub(super) fn main_rs(&self) -> Result<String, NewError> {
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
        // A spec with contracts: they are watched in every run, and the stubs keep
        // none yet.
        let ends = if self.spec.contracts.is_some() {
            ends + "        // spec.ron states contracts, watched in every run (`contracts_violated=` after\n        \
                    // it). The stubs keep none yet: their violations are reported and the run\n        \
                    // goes on. Remove this line once your code keeps them (a run then stops at\n        \
                    // the first; `--on-error` chooses too).\n        \
                    .exec(embodied::ExecConfig::continue_on_error())\n"
        } else {
            ends
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
    pub(super) fn app_tests_rs(&self) -> Result<String, NewError> {
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
}
