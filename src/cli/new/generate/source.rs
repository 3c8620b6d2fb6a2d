//! The crate's sources: `src/types.rs`, `src/logic.rs` and a module per
//! subsystem, `src/devices.rs` and `src/system.rs`.

use std::collections::BTreeMap;

use embodied::spec::model::{Agent, Device, DeviceKind, Group, Subsystem, Target};

use super::text::{allow_case, call, doc_then, inner_doc, params};
use super::{Crate, NewError, files, ident, parts, type_name, unknown_types};

/// The pieces of `src/system.rs` made for each component, in the spec's
/// order.
#[derive(Default)]
struct SystemPieces {
    /// The handles' fields.
    fields: String,
    /// The constructor's values (each component added).
    values: String,
    /// The deployed constructor's lines (each component added if it runs
    /// here).
    deployed: String,
    /// The functions that add each component.
    adders: String,
}

impl SystemPieces {
    /// Component `name` (identifier `id`) added by `adder` in the
    /// constructors.
    fn constructed(&mut self, name: &str, id: &str, adder: &str) -> Result<(), NewError> {
        self.values += &format!("        {id}: {adder}(&mut assembly)?,\n");
        self.deployed += &parts::DEPLOYED.fill(&[("component", name), ("adder", adder)])?;
        Ok(())
    }
}

impl Crate<'_> {
    pub(super) fn types_rs(&self) -> Result<String, NewError> {
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

    pub(super) fn logic_rs(&self) -> Result<String, NewError> {
        let mut modules = String::new();
        for name in self.subsystem_names() {
            modules += allow_case([name]);
            modules += &format!("pub mod {};\n", ident(name));
        }
        Ok(files::LOGIC.fill(&[("modules", &modules)])?)
    }

    pub(super) fn logic_file(&self, agent: &Agent, sub: &Subsystem) -> Result<String, NewError> {
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
    pub(super) fn subsystem_names(&self) -> Vec<&str> {
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

    pub(super) fn devices_rs(&self) -> Result<String, NewError> {
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
            "\nuse embodied::{DeviceKind, Driver, DriverContext, DriverError};\n"
        };
        Ok(files::DEVICES.fill(&[("imports", imports), ("drivers", &drivers)])?)
    }

    pub(super) fn system_rs(&self) -> Result<String, NewError> {
        let mut pieces = SystemPieces::default();
        for a in &self.spec.agents {
            for s in &a.subsystems {
                self.add_subsystem(&mut pieces, a, s)?;
            }
            for d in &a.devices {
                self.add_driver(&mut pieces, a, d)?;
            }
        }
        let components = self.spec.agents.iter().flat_map(|a| {
            (a.subsystems.iter().map(|s| s.name.as_str()))
                .chain(a.devices.iter().map(|d| d.name.as_str()))
        });
        Ok(files::SYSTEM.fill(&[
            ("imports", &self.system_imports()),
            ("allow", allow_case(components)),
            ("fields", &pieces.fields),
            ("values", &pieces.values),
            ("deployed", &pieces.deployed),
            ("adders", &pieces.adders),
        ])?)
    }

    /// Subsystem `s` of agent `a` in `src/system.rs`: its handle, the function
    /// that adds it, and its lines in the constructors.
    fn add_subsystem(
        &self,
        pieces: &mut SystemPieces,
        a: &Agent,
        s: &Subsystem,
    ) -> Result<(), NewError> {
        let agent_ident = ident(&a.name);
        let id = ident(&s.name);
        let adder = format!("add_{id}");
        let ty = type_name(&s.name);
        pieces.fields += &parts::HANDLE_SUBSYSTEM.fill(&[
            ("component", &s.name),
            ("agent", &a.name),
            ("agent_ident", &agent_ident),
            ("ident", &id),
            ("type", &ty),
        ])?;
        let ret =
            format!(") -> Result<SubsystemHandle<crate::{agent_ident}::{id}::{ty}>, Error> {{");
        pieces.adders += &self.adder(
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
        pieces.constructed(&s.name, &id, &adder)
    }

    /// Device `d` of agent `a` in `src/system.rs`: its handle, the function
    /// that adds its driver, and its lines in the constructors.
    fn add_driver(&self, pieces: &mut SystemPieces, a: &Agent, d: &Device) -> Result<(), NewError> {
        let driver = format!("{}Driver", type_name(&d.name));
        let id = ident(&d.name);
        let adder = format!("add_{id}");
        pieces.fields += &parts::HANDLE_DRIVER.fill(&[
            ("component", &d.name),
            ("agent", &a.name),
            ("ident", &id),
            ("driver", &driver),
        ])?;
        let ret = format!(") -> Result<DriverHandle<crate::devices::{driver}>, Error> {{");
        pieces.adders += &self.adder(
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
        pieces.constructed(&d.name, &id, &adder)
    }

    /// The `use` lines of `src/system.rs`: the handles' types only where the
    /// spec has such components.
    fn system_imports(&self) -> String {
        let mut names = Vec::new();
        if self.devices().next().is_some() {
            names.push("DriverHandle");
        }
        if self.spec.subsystems().next().is_some() {
            names.push("SubsystemHandle");
        }
        names.push("System");
        // In rustfmt's order: `embodied::spec` items, then `embodied::{...}`.
        format!(
            "use embodied::spec::{{Assembly, Spec}};\nuse embodied::{}{}{};\n",
            if names.len() > 1 { "{" } else { "" },
            names.join(", "),
            if names.len() > 1 { "}" } else { "" },
        )
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
}
