//! Components, agents, names, periods and buffer groups.

use super::*;

impl<'a> Checker<'a> {
    /// The rules of a valid name (agent-core's, which the runtime and the code
    /// generators apply too); components have the rules of type names as well.
    pub(super) fn name_rules(&mut self, name: &str, path: &[Seg<'static>], what: &str) {
        let component = matches!(what, "subsystem" | "device" | "component");
        let problem = if component {
            crate::names::component_problem(name)
        } else {
            crate::names::check(name).err().map(|p| p.to_string())
        };
        if let Some(problem) = problem {
            let label = match crate::names::check(name) {
                Err(crate::names::NameProblem::Empty) => "empty",
                Err(crate::names::NameProblem::NotIdentifier) => "not an identifier",
                Err(crate::names::NameProblem::Unusable) => "not usable",
                Ok(()) => "not a type name",
            };
            self.push(
                Finding::new(
                    Code::InvalidName,
                    self.span(path),
                    label,
                    format!("{what} name `{}` {problem}", abbreviate(name, 60)),
                )
                .help("names are letters, digits and `_`, not starting with a digit (they become Rust identifiers; `self`, `Self`, `super`, `crate` and `_` cannot)"),
            );
        }
    }

    /// Report duplicates among `names` (each with its path).
    pub(super) fn unique<'n>(
        &mut self,
        what: &str,
        names: impl IntoIterator<Item = (&'n str, Path)>,
    ) {
        let mut seen: HashMap<&str, Path> = HashMap::new();
        for (name, path) in names {
            self.name_rules(name, &path, what);
            if let Some(first) = seen.get(name) {
                let first = self.span(first);
                self.push(
                    Finding::new(
                        Code::DuplicateName,
                        self.span(&path),
                        "defined again here",
                        format!("{what} `{name}` is defined twice"),
                    )
                    .label(first, "first defined here")
                    .help("give each one its own name"),
                );
            } else {
                seen.insert(name, path);
            }
        }
    }

    // -----------------------------------------------------------------------
    // Components and agents

    pub(super) fn components(&mut self) {
        let spec = self.spec;
        // The system's name becomes a crate name (`embodied new`) and a key of the
        // network transport: the same rule.
        self.name_rules(&spec.name, &[F("name")], "system");
        let agents = spec.agents.iter().map(|x| x.name.as_str());
        self.unique("agent", names_at(&[], "agents", agents));
        let mut all = Vec::new();
        for (a, agent) in spec.agents.iter().enumerate() {
            for (s, sub) in agent.subsystems.iter().enumerate() {
                let path = vec![F("agents"), I(a), F("subsystems"), I(s)];
                all.push(Comp {
                    name: &sub.name,
                    agent: a,
                    kind: sub.kind.into(),
                    path,
                    inputs: &sub.inputs,
                    outputs: &sub.outputs,
                });
            }
            for (d, dev) in agent.devices.iter().enumerate() {
                all.push(Comp {
                    name: &dev.name,
                    agent: a,
                    kind: dev.kind.into(),
                    path: vec![F("agents"), I(a), F("devices"), I(d)],
                    inputs: &dev.inputs,
                    outputs: &dev.outputs,
                });
                self.period(
                    dev.period_ms,
                    &[F("agents"), I(a), F("devices"), I(d), F("period_ms")],
                );
            }
        }
        self.unique(
            "component",
            all.iter()
                .map(|c| (c.name, join(&c.path, &[F("name")])))
                .collect::<Vec<_>>(),
        );
        for c in all {
            self.comps.entry(c.name).or_insert(c);
        }
        let names: Vec<&str> = {
            let mut v: Vec<&str> = self.comps.keys().copied().collect();
            v.sort_unstable();
            v
        };
        for name in names {
            self.groups(name);
        }
    }

    pub(super) fn agent(&mut self, a: usize) {
        let agent = &self.spec.agents[a];
        let controls: Vec<&str> = agent
            .subsystems
            .iter()
            .filter(|s| s.kind == SubsystemKind::Control)
            .map(|s| s.name.as_str())
            .collect();
        if controls.len() != 1 {
            let what = if controls.is_empty() {
                "no control subsystem".to_owned()
            } else {
                format!(
                    "{} control subsystems ({})",
                    controls.len(),
                    controls.join(", ")
                )
            };
            self.push(
                Finding::new(
                    Code::AgentControl,
                    self.span(&[F("agents"), I(a), F("name")]),
                    "this agent",
                    format!("agent `{}` has {what}", agent.name),
                )
                .help("an embodied agent has exactly one control subsystem; it coordinates the agent and talks to other agents"),
            );
        }
    }

    /// The runtime's rule ([`agent_core::Period::from_millis_f64`]): positive,
    /// finite, at least a nanosecond, at most 2^64 ns.
    pub(super) fn period(&mut self, ms: f64, path: &[Seg<'static>]) {
        if let Err(e) = agent_core::Period::from_millis_f64(ms) {
            self.push(
                Finding::new(
                    Code::Period,
                    self.span(path),
                    "not a period",
                    format!("period {ms} ms: {e}"),
                )
                .help("a subsystem or device runs every `period_ms` milliseconds: a positive number from 0.000001 (1 ns)"),
            );
        }
    }

    /// Groups of one component: peers exist, are allowed, appear once; buffer names
    /// are unique in each group.
    pub(super) fn groups(&mut self, name: &str) {
        let Some(c) = self.comps.get(name) else {
            return;
        };
        let (agent, kind, path, inputs, outputs) =
            (c.agent, c.kind, c.path.clone(), c.inputs, c.outputs);
        for (side, groups, outgoing) in [("inputs", inputs, false), ("outputs", outputs, true)] {
            self.unique(
                &format!("{side} group for peer"),
                groups
                    .iter()
                    .enumerate()
                    .map(|(g, x)| (x.peer.as_str(), join(&path, &[F(side), I(g), F("peer")])))
                    .collect::<Vec<_>>(),
            );
            for (g, group) in groups.iter().enumerate() {
                let gpath = join(&path, &[F(side), I(g)]);
                let buffers = group.buffers.iter().map(|x| x.name.as_str());
                self.unique("buffer", names_at(&gpath, "buffers", buffers));
                // A fan's peers, each checked as an ordinary group's peer is.
                let peers: Vec<(&str, Path)> = if group.peers.is_empty() {
                    vec![(group.peer.as_str(), join(&gpath, &[F("peer")]))]
                } else {
                    let peers = group.peers.iter().enumerate();
                    peers
                        .map(|(k, p)| (p.as_str(), join(&gpath, &[F("peers"), I(k)])))
                        .collect()
                };
                if !group.peers.is_empty() {
                    self.unique("peer of a fan", peers.clone());
                }
                for (peer, peer_path) in peers {
                    self.group_peer((name, kind, agent), side, outgoing, peer, &peer_path);
                }
            }
        }
    }

    /// The peer `peer` of a group of component `name` (its `kind`, its agent)
    /// on `side`, named at `peer_path`: a component the agent structure lets
    /// it talk to.
    fn group_peer(
        &mut self,
        (name, kind, agent): (&str, NodeKind, usize),
        side: &str,
        outgoing: bool,
        peer: &str,
        peer_path: &[Seg<'static>],
    ) {
        let peer_name = peer;
        match self.comps.get(peer_name) {
            None => {
                let known = self.known_components();
                let guess = self.guess_component(peer_name);
                self.push(
                    Finding::new(
                        Code::UnknownComponent,
                        self.span(peer_path),
                        "no such component",
                        format!("group peer `{peer_name}` of `{name}` is not a component of the system"),
                    )
                    .help(format!("{guess}a group names the component at the other end of its buffers; components: {known}")),
                );
            }
            Some(peer) => {
                let (src, dst) = if outgoing {
                    (kind, peer.kind)
                } else {
                    (peer.kind, kind)
                };
                if let Some(reason) = structure_violation(src, dst, agent == peer.agent) {
                    let peer_kind = peer.kind;
                    self.push(
                        Finding::new(
                            Code::Structure,
                            self.span(peer_path),
                            format!("a {peer_kind}"),
                            format!("`{name}` ({kind}) cannot have {side} from/to `{peer_name}`: {reason}"),
                        )
                        .help("see the agent structure of Fig. 2: c talks to its e, r and other agents' c; e to its E; r to its R"),
                    );
                }
            }
        }
    }

    pub(super) fn known_components(&mut self) -> std::rc::Rc<str> {
        if let Some(l) = &self.components_list {
            return std::rc::Rc::clone(l);
        }
        let mut v: Vec<&str> = self.comps.keys().copied().collect();
        v.sort_unstable();
        let l: std::rc::Rc<str> = list_or_none(&v).into();
        self.components_list = Some(std::rc::Rc::clone(&l));
        l
    }

    // -----------------------------------------------------------------------
    // Subsystems
}

/// Each of `names` (the items of list `field` under `base`, in order) with
/// the path of its `name` field: what [`Checker::unique`] takes.
pub(super) fn names_at<'n>(
    base: &[Seg<'static>],
    field: &'static str,
    names: impl IntoIterator<Item = &'n str>,
) -> Vec<(&'n str, Path)> {
    names
        .into_iter()
        .enumerate()
        .map(|(i, name)| (name, join(base, &[F(field), I(i), F("name")])))
        .collect()
}
