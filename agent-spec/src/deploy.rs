//! From a spec to a system: the components of one deployment, each in the agent,
//! with the kind and the period the spec gives it, linked as the spec's links say.
//!
//! The spec is the one place where the structure is written. Code supplies what a
//! spec cannot hold, the memory's initial values, the FSM's functions and the
//! drivers, and an [`Assembly`] puts them where the spec says:
//!
//! ```text
//! let spec = embodied::spec::load_checked("specs/rex.ron")?;
//! let mut rex = Assembly::new(&spec, "simulation")?;
//! let c1 = rex.subsystem::<C1>("c1", memory, c1_fsm()?)?;   // agent a1, 10 ms, as in the spec
//! let e1 = rex.driver("E1", platform)?;
//! if rex.runs("r11") { /* the deployment runs visual odometry */ }
//! let system = rex.build()?;                                 // every link of the spec
//! ```
//!
//! A component the spec does not declare, one of another kind, one the deployment
//! does not run, a deployed component that was not added, and a link whose buffer
//! the code does not have (or has with another type) are errors that name it: the
//! spec and the code cannot drift apart silently. [`wire`] links the components of
//! a [`SystemBuilder`] assembled by hand.

use std::collections::HashMap;

use agent_core::{
    AgentId, BuildError, Driver, DriverHandle, Fsm, Period, PeriodError, Subsystem,
    SubsystemHandle, System, SystemBuilder,
};

use crate::model::{Deployment, Spec};

/// Why a system could not be assembled from a spec.
#[derive(Debug, thiserror::Error)]
pub enum AssemblyError {
    /// The spec has no such deployment.
    #[error("spec `{spec}` has no deployment `{name}` (it has: {known})")]
    UnknownDeployment {
        /// The spec's name.
        spec: String,
        /// The deployment asked for.
        name: String,
        /// The deployments it has.
        known: String,
    },
    /// The spec declares no such component.
    #[error("spec `{spec}` declares no component `{name}`{hint}")]
    NotInSpec {
        /// The spec's name.
        spec: String,
        /// The component.
        name: String,
        /// `; did you mean ...?`, or empty.
        hint: String,
    },
    /// The deployment does not run the component.
    #[error(
        "deployment `{deployment}` does not run `{name}` (it runs: {runs}); ask `Assembly::runs` first"
    )]
    NotDeployed {
        /// The deployment.
        deployment: String,
        /// The component.
        name: String,
        /// What it runs.
        runs: String,
    },
    /// The code's component is not of the kind the spec declares.
    #[error("`{name}` is a {spec} in the spec, but `{ty}` is a {code}")]
    Kind {
        /// The component.
        name: String,
        /// The kind in the spec.
        spec: agent_core::NodeKind,
        /// The Rust type.
        ty: &'static str,
        /// Its kind.
        code: agent_core::NodeKind,
    },
    /// A component added twice.
    #[error("`{0}` is added twice")]
    Twice(String),
    /// The spec's FSM of a subsystem does not fit the code's behaviours and
    /// predicates.
    #[error("the FSM of `{name}` in the spec does not fit its code: {message}")]
    Fsm {
        /// The subsystem.
        name: String,
        /// Why.
        message: String,
    },
    /// The spec's period cannot run.
    #[error("the period of `{name}` in the spec: {source}")]
    Period {
        /// The component.
        name: String,
        /// Why.
        #[source]
        source: PeriodError,
    },
    /// Components missing, links that could not be made, or a malformed system.
    #[error("the system does not follow the spec:{}", list(.problems))]
    Build {
        /// Every problem, one per line.
        problems: Vec<String>,
    },
}

fn list(problems: &[String]) -> String {
    problems.iter().map(|p| format!("\n  - {p}")).collect()
}

/// `comp.group.buffer` of a spec link as `(comp, group.buffer)`.
fn split_end(end: &str) -> Option<(&str, &str)> {
    let (component, path) = end.split_once('.')?;
    Some((component, path))
}

/// Link the components of `builder` as the links of `spec` say: every link whose
/// two ends are components of `builder` is made (by name, checked against the
/// buffers' types); links to components `builder` does not have are left out.
/// Returns how many links were made; problems are [`SystemBuilder::build`]'s.
pub fn wire(builder: &mut SystemBuilder, spec: &Spec) -> usize {
    wire_aliased(builder, spec, &HashMap::new())
}

/// `group.buffer` of a link end with the group named as the code names it:
/// `aliases` maps a spec peer to the code's group (see [`Assembly::alias`]).
fn code_path(path: &str, aliases: &HashMap<String, String>) -> String {
    match path.split_once('.') {
        Some((group, buffer)) => match aliases.get(group) {
            Some(code) => format!("{code}.{buffer}"),
            None => path.to_owned(),
        },
        None => path.to_owned(),
    }
}

/// [`wire`], with the groups named by `aliases` (spec peer to the code's
/// group name) where they differ.
fn wire_aliased(
    builder: &mut SystemBuilder,
    spec: &Spec,
    aliases: &HashMap<String, String>,
) -> usize {
    let mut made = 0;
    for link in &spec.links {
        let (Some((src, out)), Some((dst, inp))) = (split_end(&link.from), split_end(&link.to))
        else {
            continue; // the checker refuses such a spec
        };
        if builder.node(src).is_none() || builder.node(dst).is_none() {
            continue;
        }
        let (out, inp) = if aliases.is_empty() {
            (out.to_owned(), inp.to_owned())
        } else {
            (code_path(out, aliases), code_path(inp, aliases))
        };
        if builder
            .connect_named(src, &out, dst, &inp, link.policy)
            .is_some()
        {
            made += 1;
        }
    }
    made
}

/// What a component of the spec is.
#[derive(Clone, Copy)]
struct Declared<'s> {
    agent: &'s str,
    kind: agent_core::NodeKind,
    period_ms: f64,
}

/// A system being assembled as a spec's deployment says. See the [module](self).
pub struct Assembly<'s> {
    spec: &'s Spec,
    deployment: Option<&'s Deployment>,
    declared: HashMap<&'s str, Declared<'s>>,
    runs: Vec<&'s str>,
    builder: SystemBuilder,
    agents: HashMap<&'s str, AgentId>,
    periods: HashMap<String, Period>,
    aliases: HashMap<String, String>,
}

impl std::fmt::Debug for Assembly<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Assembly")
            .field("spec", &self.spec.name)
            .field("deployment", &self.deployment.map(|d| &d.name))
            .field("runs", &self.runs)
            .finish()
    }
}

impl<'s> Assembly<'s> {
    /// The components that deployment `name` of `spec` runs (on any host and in any
    /// process).
    pub fn new(spec: &'s Spec, name: &str) -> Result<Assembly<'s>, AssemblyError> {
        let Some(deployment) = spec.deployment(name) else {
            return Err(AssemblyError::UnknownDeployment {
                spec: spec.name.clone(),
                name: name.to_owned(),
                known: spec.deployment_names(),
            });
        };
        let runs = deployment.runs().collect();
        Ok(Assembly::with(spec, Some(deployment), runs))
    }

    /// Every component of `spec` (a spec without deployments).
    pub fn all(spec: &'s Spec) -> Assembly<'s> {
        let runs = spec
            .agents
            .iter()
            .flat_map(|a| {
                a.subsystems
                    .iter()
                    .map(|s| s.name.as_str())
                    .chain(a.devices.iter().map(|d| d.name.as_str()))
            })
            .collect();
        Assembly::with(spec, None, runs)
    }

    fn with(spec: &'s Spec, deployment: Option<&'s Deployment>, runs: Vec<&'s str>) -> Self {
        let mut declared = HashMap::new();
        for a in &spec.agents {
            for s in &a.subsystems {
                let kind = s.kind.into();
                declared.insert(
                    s.name.as_str(),
                    Declared {
                        agent: &a.name,
                        kind,
                        period_ms: s.period_ms,
                    },
                );
            }
            for d in &a.devices {
                let kind = d.kind.into();
                declared.insert(
                    d.name.as_str(),
                    Declared {
                        agent: &a.name,
                        kind,
                        period_ms: d.period_ms,
                    },
                );
            }
        }
        Assembly {
            spec,
            deployment,
            declared,
            runs,
            builder: SystemBuilder::new(),
            agents: HashMap::new(),
            periods: HashMap::new(),
            aliases: HashMap::new(),
        }
    }

    /// Name the groups towards spec component `peer` as `group` in the code:
    /// the buffers of a component's group are named by the peer in the spec
    /// (`e11_3.traj` in `c1_3`, a robot of a fleet) and by a field in the code
    /// (`e11.traj` in `C1`'s outputs). Copies of a component made from one
    /// type (a fleet's robots) are linked with their type's group names.
    pub fn alias(&mut self, peer: &str, group: &str) -> &mut Self {
        self.aliases.insert(peer.to_owned(), group.to_owned());
        self
    }

    /// Whether the deployment runs component `name`.
    pub fn runs(&self, name: &str) -> bool {
        self.runs.contains(&name)
    }

    /// The components the deployment runs, in the order the spec's deployment
    /// lists them.
    pub fn components(&self) -> &[&'s str] {
        &self.runs
    }

    /// The spec.
    pub fn spec(&self) -> &'s Spec {
        self.spec
    }

    /// Give the system its environment, the world its devices act on and sense
    /// ([`SystemBuilder::environment`]).
    pub fn environment<W: std::any::Any + Send>(&mut self, world: W) -> &mut Self {
        self.builder.environment(world);
        self
    }

    /// Run component `name` every `period` instead of the spec's period: for test
    /// harnesses that vary a rate. The built system then differs from the spec in
    /// that period (its exported structure says so).
    pub fn set_period(&mut self, name: &str, period: Period) -> Result<(), AssemblyError> {
        self.declared(name)?;
        self.periods.insert(name.to_owned(), period);
        Ok(())
    }

    /// The period component `name` runs at: the spec's, unless
    /// [`Assembly::set_period`] changed it.
    pub fn period(&self, name: &str) -> Result<Period, AssemblyError> {
        let declared = self.declared(name)?;
        if let Some(&period) = self.periods.get(name) {
            return Ok(period);
        }
        Period::from_millis_f64(declared.period_ms).map_err(|source| AssemblyError::Period {
            name: name.to_owned(),
            source,
        })
    }

    fn declared(&self, name: &str) -> Result<Declared<'s>, AssemblyError> {
        self.declared
            .get(name)
            .copied()
            .ok_or_else(|| AssemblyError::NotInSpec {
                spec: self.spec.name.clone(),
                name: name.to_owned(),
                hint: crate::names::did_you_mean(name, self.declared.keys().copied())
                    .map_or_else(String::new, |m| format!("; did you mean `{m}`?")),
            })
    }

    /// Where component `name` goes: its agent and period, after checking that the
    /// spec declares it with `kind` and the deployment runs it.
    fn place(
        &mut self,
        name: &str,
        kind: agent_core::NodeKind,
        ty: &'static str,
    ) -> Result<(AgentId, Period), AssemblyError> {
        let declared = self.declared(name)?;
        if declared.kind != kind {
            return Err(AssemblyError::Kind {
                name: name.to_owned(),
                spec: declared.kind,
                ty,
                code: kind,
            });
        }
        if !self.runs(name) {
            return Err(AssemblyError::NotDeployed {
                deployment: self.deployment.map_or_else(String::new, |d| d.name.clone()),
                name: name.to_owned(),
                runs: self.runs.join(", "),
            });
        }
        if self.builder.node(name).is_some() {
            return Err(AssemblyError::Twice(name.to_owned()));
        }
        let period = self.period(name)?;
        let builder = &mut self.builder;
        let agent = *self
            .agents
            .entry(declared.agent)
            .or_insert_with(|| builder.agent(declared.agent));
        Ok((agent, period))
    }

    /// Add subsystem `name` with its initial memory and FSM, in the agent and with
    /// the period of the spec. The code gives the behaviours (their actions)
    /// and the predicates; the spec gives the graph: the initial behaviour, the
    /// arcs with their initial conditions, the terminal conditions and the
    /// final behaviours ([`Fsm::regraph`]), so that what the spec says (and
    /// the checker proved) is what runs. The two must name the same
    /// behaviours.
    pub fn subsystem<S: Subsystem>(
        &mut self,
        name: &str,
        memory: S::Memory,
        fsm: Fsm<S>,
    ) -> Result<SubsystemHandle<S>, AssemblyError> {
        let fsm = self.spec_graph(name, fsm)?;
        self.stand_in(name, memory, fsm)
    }

    /// As [`Assembly::subsystem`], with the subsystem's first input and output
    /// buffers given rather than their defaults: how the length of a fan (a
    /// group with `peers` in the spec, agent-core's `Fan` in the code) is
    /// fixed when the system is built
    /// ([`SystemBuilder::subsystem_with_buffers`]). The spec's links to the
    /// fan's elements (`c2.c1[3].plan`) are made by [`Assembly::build`]; one
    /// to an element the fan lacks is a build problem.
    pub fn subsystem_with_buffers<S: Subsystem>(
        &mut self,
        name: &str,
        memory: S::Memory,
        fsm: Fsm<S>,
        input: S::Input,
        output: S::Output,
    ) -> Result<SubsystemHandle<S>, AssemblyError> {
        let fsm = self.spec_graph(name, fsm)?;
        let (agent, period) = self.place(name, S::KIND.into(), std::any::type_name::<S>())?;
        Ok(self
            .builder
            .subsystem_with_buffers(agent, name, period, memory, fsm, input, output))
    }

    /// Add a stand-in for subsystem `name` (a test double: a stub in place of
    /// the real component), in the agent and with the period of the spec, with
    /// its own FSM: the spec's graph is not applied, since the stand-in does
    /// not have the component's behaviours. Its buffers are still linked by
    /// the spec's links.
    pub fn stand_in<S: Subsystem>(
        &mut self,
        name: &str,
        memory: S::Memory,
        fsm: Fsm<S>,
    ) -> Result<SubsystemHandle<S>, AssemblyError> {
        let (agent, period) = self.place(name, S::KIND.into(), std::any::type_name::<S>())?;
        Ok(self.builder.subsystem(agent, name, period, memory, fsm))
    }

    /// `fsm` with the spec's graph for subsystem `name` ([`Fsm::regraph`]),
    /// not added: several subsystems of one kind and one graph (a fleet's
    /// robots) can then be given clones of it, which share one definition
    /// ([`Assembly::subsystem`] passes an FSM that has its graph through).
    pub fn graphed<S: Subsystem>(&self, name: &str, fsm: Fsm<S>) -> Result<Fsm<S>, AssemblyError> {
        self.spec_graph(name, fsm)
    }

    /// `fsm` with the spec's graph for subsystem `name`.
    fn spec_graph<S: Subsystem>(&self, name: &str, fsm: Fsm<S>) -> Result<Fsm<S>, AssemblyError> {
        let Some(declared) = self
            .spec
            .agents
            .iter()
            .flat_map(|a| &a.subsystems)
            .find(|s| s.name == name)
        else {
            return Ok(fsm);
        };
        let fail = |message: String| AssemblyError::Fsm {
            name: name.to_owned(),
            message,
        };
        let mut code: Vec<&str> = (0..fsm.len()).map(|b| fsm.behaviour_name(b)).collect();
        let mut spec: Vec<&str> = declared
            .behaviours
            .iter()
            .map(|b| b.name.as_str())
            .collect();
        code.sort_unstable();
        spec.sort_unstable();
        if code != spec {
            return Err(fail(format!(
                "the spec's behaviours are [{}], the code's [{}]",
                spec.join(", "),
                code.join(", ")
            )));
        }
        let initial = match (&declared.fsm.initial, declared.behaviours.as_slice()) {
            (Some(i), _) => i.clone(),
            (None, [only]) => only.name.clone(),
            (None, _) => return Err(fail("the spec names no initial behaviour".into())),
        };
        let graph = agent_core::FsmGraph {
            initial,
            arcs: declared
                .fsm
                .arcs
                .iter()
                .map(|a| (a.from.clone(), a.to.clone(), a.when.clone()))
                .collect(),
            terminals: declared
                .behaviours
                .iter()
                .map(|b| (b.name.clone(), b.terminal.clone()))
                .collect(),
            finals: declared.fsm.finals.clone(),
        };
        fsm.regraph(&graph).map_err(|e| fail(e.to_string()))
    }

    /// Add driver `name` (a real effector or receptor), in the agent and with the
    /// period of the spec.
    pub fn driver<D: Driver>(
        &mut self,
        name: &str,
        driver: D,
    ) -> Result<DriverHandle<D>, AssemblyError> {
        let (agent, period) = self.place(name, D::KIND.into(), std::any::type_name::<D>())?;
        Ok(self.builder.driver(agent, name, period, driver))
    }

    /// Link the components as the spec says and build the system: every component
    /// the deployment runs must have been added, and every link between them is made.
    pub fn build(mut self) -> Result<System, AssemblyError> {
        let mut problems: Vec<String> = self
            .runs
            .iter()
            .filter(|name| self.builder.node(name).is_none())
            .map(|name| {
                format!(
                    "`{name}` is run by the deployment{} but was not added",
                    self.deployment
                        .map_or_else(String::new, |d| format!(" `{}`", d.name))
                )
            })
            .collect();
        wire_aliased(&mut self.builder, self.spec, &self.aliases);
        match self.builder.build() {
            Ok(system) if problems.is_empty() => Ok(system),
            Ok(_) => Err(AssemblyError::Build { problems }),
            Err(BuildError { problems: more }) => {
                problems.extend(more.iter().map(ToString::to_string));
                Err(AssemblyError::Build { problems })
            }
        }
    }
}
