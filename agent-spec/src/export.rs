//! The other direction: the spec of a system built in Rust.
//!
//! A system assembled with `SystemBuilder` from described components (the derives
//! of the macros crate, or `Subsystem::shape`/`Driver::shape` by hand) knows
//! everything a spec says: agents, components with their kinds and periods, memory
//! fields and buffers with their types, predicates, relations, behaviours with their
//! parts and terminal conditions, arcs and finals, links with their policies.
//! [`spec_of`] writes it as a [`Spec`], [`to_ron`] as text, so the checker and the
//! diagrams work for agents written without a RON file:
//!
//! ```text
//! let spec = embodied::spec::export::spec_of("tank", system.info())?;
//! std::fs::write("specs/tank.ron", embodied::spec::export::to_ron(&spec)?)?;
//! ```
//!
//! What the types do not say is left out: which buffers a function or predicate
//! reads and which buffers of its target a function writes (`reads` and `writes`
//! are empty; the types let a part read all of the memory and inputs and write all
//! of its target). Add them by hand for the data-flow diagrams.
//! The peer a group is connected to is the component its links go to; a group linked
//! to nothing is named by its field (as `agent!` names fields after peers), and the
//! checker then says whether that is a component. A fan (agent-core's `Fan`, its
//! ports `c1[k].buffer`) is a group named by its field with `peers`: element `k`'s
//! peer is the component element `k`'s links go to, for every element up to the
//! last linked one (an element below it linked to nothing cannot be named, and is
//! an error); links name its elements `c2.c1[k].buffer`. A fan none of whose
//! elements is linked is written as an ordinary group named by its field.

use std::collections::HashMap;

use agent_core::{
    FsmShape, GroupShape, LinkInfo, NodeInfo, NodeKind, PartTarget, Shape, SystemInfo,
};

use crate::model::{
    self, Agent, Behaviour, Buffer, Device, DeviceKind, Fsm, Function, Group, Link, Predicate,
    Spec, Subsystem, SubsystemKind, Target,
};

/// Why a system cannot be written as a spec.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ExportError {
    /// A component's types do not describe its memory and buffers.
    #[error(
        "`{0}` does not describe its buffers: derive `Subsystem` (with `Memory`, `Buffers` and `Group` on its types); a driver is described by its `Input` and `Output` (do not override `Driver::shape` with `None`)"
    )]
    Undescribed(String),
    /// A driver's buffer has no link, so the peer of its group is unknown.
    #[error("buffer `{group}` of `{node}` is not linked to anything, so its peer cannot be named")]
    Unlinked {
        /// The component.
        node: String,
        /// The buffer.
        group: String,
    },
    /// The buffers of one group are linked to different components.
    #[error(
        "the buffers of group `{group}` of `{node}` are linked to several components ({peers})"
    )]
    SeveralPeers {
        /// The component.
        node: String,
        /// The group.
        group: String,
        /// The components, comma-separated.
        peers: String,
    },
    /// An output part whose group could not be identified.
    #[error(
        "behaviour `{behaviour}` of `{node}` writes group type `{group}`, which is not exactly one output group; name the field with the `fsm!` macro"
    )]
    UnknownTarget {
        /// The component.
        node: String,
        /// The behaviour.
        behaviour: String,
        /// The group's type name.
        group: String,
    },
    /// The text could not be written.
    #[error("cannot write the spec as RON: {0}")]
    Ron(String),
}

/// The peer of each group: the component at the other end of its links.
struct Peers<'a> {
    info: &'a SystemInfo,
}

impl Peers<'_> {
    fn links_of(&self, node: usize, input: bool) -> impl Iterator<Item = &LinkInfo> + '_ {
        self.info
            .links
            .iter()
            .filter(move |l| if input { l.to == node } else { l.from == node })
    }

    /// The other end of link `l` seen from `node`.
    fn other(&self, l: &LinkInfo, input: bool) -> &str {
        let n = if input { l.from } else { l.to };
        self.info.nodes.get(n).map_or("?", |n| n.name.as_str())
    }

    /// The one peer of the links whose port satisfies `port`.
    fn peer_of(
        &self,
        node: usize,
        input: bool,
        group: &str,
        port: impl Fn(&str) -> bool,
    ) -> Result<String, ExportError> {
        let name = &self.info.nodes[node].name;
        let mut peers: Vec<&str> = self
            .links_of(node, input)
            .filter(|l| port(&unraw(if input { l.to_port } else { l.from_port })))
            .map(|l| self.other(l, input))
            .collect();
        peers.sort_unstable();
        peers.dedup();
        match peers[..] {
            [one] => Ok(one.to_owned()),
            [] => Err(ExportError::Unlinked {
                node: name.clone(),
                group: group.to_owned(),
            }),
            _ => Err(ExportError::SeveralPeers {
                node: name.clone(),
                group: group.to_owned(),
                peers: peers.join(", "),
            }),
        }
    }

    /// The spec groups of one direction of node `node`.
    fn groups(
        &self,
        node: usize,
        shapes: &[GroupShape],
        input: bool,
    ) -> Result<Vec<Group>, ExportError> {
        let mut out: Vec<Group> = Vec::new();
        for g in shapes {
            if g.name.is_empty() {
                // A driver's flat buffers: grouped by the peer each is linked to.
                for b in g.buffers {
                    let peer = self.peer_of(node, input, b.name, |p| p == b.name)?;
                    let buffer = Buffer {
                        name: b.name.to_owned(),
                        ty: b.ty.to_owned(),
                        doc: None,
                    };
                    match out.iter_mut().find(|x| x.peer == peer) {
                        Some(x) => x.buffers.push(buffer),
                        None => out.push(Group {
                            peer,
                            buffers: vec![buffer],
                            peers: Vec::new(),
                        }),
                    }
                }
            } else {
                let fan = self.fan_peers(node, input, g)?;
                let peer = if fan.is_empty() {
                    let prefix = format!("{}.", g.name);
                    // A group linked to nothing (an output nobody reads is only a warning of
                    // the checker) is named by its field: `agent!` names fields after peers.
                    match self.peer_of(node, input, g.name, |p| p.starts_with(&prefix)) {
                        Err(ExportError::Unlinked { .. }) => g.name.to_owned(),
                        other => other?,
                    }
                } else {
                    // A fan is named by its field; its elements' peers follow.
                    g.name.to_owned()
                };
                out.push(Group {
                    peer,
                    buffers: g
                        .buffers
                        .iter()
                        .map(|b| Buffer {
                            name: b.name.to_owned(),
                            ty: b.ty.to_owned(),
                            doc: None,
                        })
                        .collect(),
                    peers: fan,
                });
            }
        }
        Ok(out)
    }

    /// The peers of group `g` if it is a fan whose elements are linked
    /// (ports `name[k].buffer`): element `k`'s peer is the component its links
    /// go to. Empty for an ordinary group, and for a fan none of whose elements
    /// is linked (the system says nothing of its peers then).
    fn fan_peers(
        &self,
        node: usize,
        input: bool,
        g: &GroupShape,
    ) -> Result<Vec<String>, ExportError> {
        let prefix = format!("{}[", g.name);
        let mut elements: Vec<usize> = self
            .links_of(node, input)
            .filter_map(|l| {
                let port = unraw(if input { l.to_port } else { l.from_port });
                fan_element(port.strip_prefix(&prefix)?)
            })
            .collect();
        elements.sort_unstable();
        elements.dedup();
        let Some(&last) = elements.last() else {
            return Ok(Vec::new());
        };
        (0..=last)
            .map(|k| {
                let element = format!("{}[{k}]", g.name);
                let dotted = format!("{element}.");
                self.peer_of(node, input, &element, |p| p.starts_with(&dotted))
            })
            .collect()
    }
}

/// `3` in a fan element's port `c1[3].plan` (given `3].plan`): decimal
/// without leading zeros, as agent-core names the elements.
fn fan_element(rest: &str) -> Option<usize> {
    let (index, _) = rest.split_once("].")?;
    let canonical = !index.is_empty()
        && index.bytes().all(|b| b.is_ascii_digit())
        && (index == "0" || !index.starts_with('0'));
    canonical.then(|| index.parse().ok()).flatten()
}

/// One end of link `l` as a spec names it: `component.group.buffer`, the
/// group being the component at the other end, or a fan's element
/// (`c2.c1[3].plan`) as the port names it.
fn link_end(component: &str, other: &str, port: &str) -> String {
    let port = unraw(port);
    let (group, buffer) = port.rsplit_once('.').unwrap_or(("", &port));
    if group.ends_with(']') {
        format!("{component}.{group}.{buffer}")
    } else {
        format!("{component}.{other}.{buffer}")
    }
}

/// A period in milliseconds as a spec writes it: `9 ms` is `9.0`, exactly.
fn millis(p: agent_core::Period) -> f64 {
    p.as_nanos() as f64 / 1e6
}

/// A port path as the field names are: `r#type.x` -> `type.x` (`port!` keeps the
/// raw identifiers it is given; descriptions and specs do not).
fn unraw(port: &str) -> String {
    port.split('.')
        .map(|s| s.strip_prefix("r#").unwrap_or(s))
        .collect::<Vec<_>>()
        .join(".")
}

/// A type without its paths or spaces: `a::b::Name` -> `Name`,
/// `agent_core::buffer::Fan<x::ToRobot>` -> `Fan<ToRobot>` (the type of a part's
/// target as the compiler names it, against a group's type as its field writes
/// it).
fn bare_type(ty: &str) -> String {
    let mut out = String::with_capacity(ty.len());
    // Where the identifier being written starts in `out`.
    let mut start = 0;
    let mut chars = ty.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            ':' if chars.peek() == Some(&':') => {
                chars.next();
                out.truncate(start);
            }
            c if c.is_whitespace() => {}
            c if c.is_alphanumeric() || c == '_' => out.push(c),
            c => {
                out.push(c);
                start = out.len();
            }
        }
    }
    out
}

fn subsystem(
    peers: &Peers<'_>,
    index: usize,
    node: &NodeInfo,
    shape: &Shape,
) -> Result<Subsystem, ExportError> {
    let kind = match node.kind {
        NodeKind::Control => SubsystemKind::Control,
        NodeKind::VirtualEffector => SubsystemKind::VirtualEffector,
        _ => SubsystemKind::VirtualReceptor,
    };
    let memory: Vec<Buffer> = shape
        .memory
        .unwrap_or(&[])
        .iter()
        .map(|f| Buffer {
            name: f.name.to_owned(),
            ty: f.ty.to_owned(),
            doc: None,
        })
        .collect();
    let inputs = peers.groups(index, shape.inputs, true)?;
    let outputs = peers.groups(index, shape.outputs, false)?;
    let Some(fsm) = &node.fsm else {
        return Err(ExportError::Undescribed(node.name.clone()));
    };
    let (functions, behaviours) = functions_and_behaviours(node, shape, fsm, &outputs)?;
    Ok(Subsystem {
        name: node.name.clone(),
        kind,
        period_ms: millis(node.period),
        doc: None,
        memory,
        inputs,
        outputs,
        predicates: fsm
            .predicates
            .iter()
            .map(|p| Predicate {
                name: p.clone(),
                reads: Vec::new(),
                doc: None,
            })
            .collect(),
        relations: fsm.relations.clone(),
        functions,
        behaviours,
        fsm: spec_fsm(fsm),
    })
}

/// The functions, one per part name and target, and the behaviours that name
/// them (a part without a name is `<behaviour>_<target>`).
fn functions_and_behaviours(
    node: &NodeInfo,
    shape: &Shape,
    fsm: &FsmShape,
    outputs: &[Group],
) -> Result<(Vec<Function>, Vec<Behaviour>), ExportError> {
    let mut functions: Vec<Function> = Vec::new();
    let mut behaviours = Vec::new();
    for b in &fsm.behaviours {
        let mut names = Vec::new();
        for part in &b.parts {
            let (target, suffix) = part_target(node, &b.name, &part.target, shape, outputs)?;
            let name = part
                .name
                .as_ref()
                .map_or_else(|| format!("{}_{suffix}", b.name), |n| n.to_string());
            names.push(add_function(&mut functions, name, target, &suffix));
        }
        behaviours.push(Behaviour {
            name: b.name.clone(),
            kind: b.kind,
            functions: names,
            terminal: b.terminal.clone(),
            doc: None,
        });
    }
    Ok((functions, behaviours))
}

/// The spec target of a part of behaviour `behaviour`, and the suffix that
/// names it (`common`, `memory`, or the output group's field): an output
/// group is found by its field, else by its type.
fn part_target(
    node: &NodeInfo,
    behaviour: &str,
    target: &PartTarget,
    shape: &Shape,
    outputs: &[Group],
) -> Result<(Target, String), ExportError> {
    Ok(match target {
        PartTarget::Common => (Target::Common, "common".to_owned()),
        PartTarget::Memory => (Target::Memory, "memory".to_owned()),
        PartTarget::Output { group, field, .. } => {
            let candidates: Vec<(usize, &GroupShape)> = shape
                .outputs
                .iter()
                .enumerate()
                .filter(|(_, g)| match field {
                    Some(f) => g.name == *f,
                    None => bare_type(g.ty) == bare_type(group),
                })
                .collect();
            let [(k, g)] = candidates[..] else {
                return Err(ExportError::UnknownTarget {
                    node: node.name.clone(),
                    behaviour: behaviour.to_owned(),
                    group: (*group).to_owned(),
                });
            };
            let peer = outputs.get(k).map(|o| o.peer.clone()).unwrap_or_default();
            (Target::Output(peer), g.name.to_owned())
        }
    })
}

/// The name under which a behaviour uses function `name` writing `target`,
/// adding the function unless it is there: one name with two targets gets
/// `_<suffix>` for the second (a spec function has one target).
fn add_function(
    functions: &mut Vec<Function>,
    name: String,
    target: Target,
    suffix: &str,
) -> String {
    let function = |name: String, target: Target| Function {
        name,
        target,
        reads: Vec::new(),
        writes: Vec::new(),
        doc: None,
    };
    match functions.iter().find(|f| f.name == name) {
        Some(f) if f.target == target => name,
        Some(_) => {
            let renamed = format!("{name}_{suffix}");
            if !functions.iter().any(|f| f.name == renamed) {
                functions.push(function(renamed.clone(), target));
            }
            renamed
        }
        None => {
            functions.push(function(name.clone(), target));
            name
        }
    }
}

/// The FSM's graph as a spec writes it.
fn spec_fsm(fsm: &FsmShape) -> Fsm {
    Fsm {
        initial: Some(fsm.initial.clone()),
        arcs: fsm
            .arcs
            .iter()
            .map(|(from, to, when)| model::FsmArc {
                from: from.clone(),
                to: to.clone(),
                when: when.clone(),
            })
            .collect(),
        finals: fsm.finals.clone(),
    }
}

/// The spec of a built system, named `name`.
pub fn spec_of(name: &str, info: &SystemInfo) -> Result<Spec, ExportError> {
    let peers = Peers { info };
    let mut agents: Vec<Agent> = info
        .agents
        .iter()
        .map(|a| Agent {
            name: a.clone(),
            doc: None,
            subsystems: Vec::new(),
            devices: Vec::new(),
        })
        .collect();
    let agent_index: HashMap<&str, usize> = info
        .agents
        .iter()
        .enumerate()
        .map(|(i, a)| (a.as_str(), i))
        .collect();
    for (i, node) in info.nodes.iter().enumerate() {
        let Some(shape) = &node.shape else {
            return Err(ExportError::Undescribed(node.name.clone()));
        };
        let Some(&a) = agent_index.get(node.agent.as_str()) else {
            continue;
        };
        match node.kind {
            NodeKind::RealEffector | NodeKind::RealReceptor => agents[a].devices.push(Device {
                name: node.name.clone(),
                kind: if node.kind == NodeKind::RealEffector {
                    DeviceKind::Effector
                } else {
                    DeviceKind::Receptor
                },
                period_ms: millis(node.period),
                doc: None,
                inputs: peers.groups(i, shape.inputs, true)?,
                outputs: peers.groups(i, shape.outputs, false)?,
            }),
            _ => agents[a]
                .subsystems
                .push(subsystem(&peers, i, node, shape)?),
        }
    }
    let node = |n: usize| info.nodes.get(n).map_or("?", |x| x.name.as_str());
    let links = info
        .links
        .iter()
        .map(|l| Link {
            from: link_end(node(l.from), node(l.to), l.from_port),
            to: link_end(node(l.to), node(l.from), l.to_port),
            policy: l.policy,
        })
        .collect();
    Ok(Spec {
        name: name.to_owned(),
        doc: None,
        agents,
        links,
        deployments: Vec::new(),
        ros2: None,
        contracts: None,
        timing: None,
    })
}

/// The spec as RON text in the layout of hand-written specs.
pub fn to_ron(spec: &Spec) -> Result<String, ExportError> {
    let config = ron::ser::PrettyConfig::new()
        .struct_names(false)
        .indentor("    ".to_owned())
        .separate_tuple_members(false)
        .compact_arrays(false)
        .depth_limit(6);
    ron::Options::default()
        .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
        .to_string_pretty(spec, config)
        .map_err(|e| ExportError::Ron(e.to_string()))
}

/// Where two specs differ, for a person: the first line of their RON texts that
/// differs, with the lines before it, or `None` if they are equal. Compare
/// [`Spec::structure`]s to ignore docs, reads, writes and deployments.
pub fn difference(expected: &Spec, actual: &Spec) -> Option<String> {
    if expected == actual {
        return None;
    }
    let text = |s: &Spec| to_ron(s).unwrap_or_else(|_| format!("{s:#?}"));
    let (a, b) = (text(expected), text(actual));
    let (la, lb): (Vec<&str>, Vec<&str>) = (a.lines().collect(), b.lines().collect());
    let i = (0..la.len().max(lb.len()))
        .find(|&i| la.get(i) != lb.get(i))
        .unwrap_or(0);
    let context = la[i.saturating_sub(4)..i.min(la.len())].join("\n");
    Some(format!(
        "the specs differ at line {}:\n{context}\n- expected: {}\n+ actual:   {}",
        i + 1,
        la.get(i).map_or("(end)", |l| l.trim()),
        lb.get(i).map_or("(end)", |l| l.trim()),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_difference_is_shown_at_its_line() {
        let source = include_str!("../../specs/tank.ron");
        let (spec, report) = crate::check_source("tank.ron", source);
        assert!(report.is_ok(), "{}", report.short());
        let spec = spec.expect("parses").structure();
        assert_eq!(difference(&spec, &spec), None);
        let mut other = spec.clone();
        other.agents[0].subsystems[1].period_ms = 9.0;
        let d = difference(&spec, &other).expect("they differ");
        assert!(d.contains("- expected: period_ms: 10.0,"), "{d}");
        assert!(d.contains("+ actual:   period_ms: 9.0,"), "{d}");
        assert!(
            d.contains("name: \"e1\""),
            "the lines before it show where: {d}"
        );
    }

    #[test]
    fn ports_and_periods_are_written_as_specs_write_them() {
        assert_eq!(unraw("r#type.r#in"), "type.in");
        assert_eq!(unraw("pump.flow"), "pump.flow");
        assert_eq!(bare_type("tank::Command"), "Command");
        assert_eq!(
            bare_type("agent_core::buffer::Fan<fleet::ToRobot>"),
            "Fan<ToRobot>"
        );
        assert_eq!(bare_type("Fan < ToRobot >"), "Fan<ToRobot>");
        assert_eq!(bare_type("[f64; 4]"), "[f64;4]");
        assert_eq!(link_end("c2", "c1_3", "r#c1[3].plan"), "c2.c1[3].plan");
        assert_eq!(link_end("c1_3", "c2", "c2.plan"), "c1_3.c2.plan");
        assert_eq!(link_end("E1", "e11", "speed"), "E1.e11.speed");
        for ms in [1, 9, 11, 13, 45, 1000] {
            let p = agent_core::Period::from_millis(ms).expect("a period");
            assert_eq!(millis(p), ms as f64);
        }
    }
}
