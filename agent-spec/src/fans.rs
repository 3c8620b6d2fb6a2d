//! A fan's elements named where the spec names buffers: `c2.c1[3].plan` is
//! buffer `plan` of element 3 of fan `c1` of `c2` (as links name it, and as
//! the runtime names the port, `c1[3].plan`), and in contracts and ROS 2
//! entries `c2.c1[*].plan` is that buffer of every element: the entry stands
//! for one entry per element, `[*]` replaced by `[0]`, `[1]`... in order.

use crate::model::{Group, Spec};

/// The text of a whole fan's index: `[*]`.
pub const EVERY: &str = "[*]";

/// The groups of component `name` (a subsystem or a device): inputs, outputs.
fn groups<'s>(spec: &'s Spec, name: &str) -> Option<(&'s [Group], &'s [Group])> {
    spec.agents.iter().find_map(|a| {
        a.subsystems
            .iter()
            .find(|s| s.name == name)
            .map(|s| (&s.inputs[..], &s.outputs[..]))
            .or_else(|| {
                a.devices
                    .iter()
                    .find(|d| d.name == name)
                    .map(|d| (&d.inputs[..], &d.outputs[..]))
            })
    })
}

/// The number of elements of fan `fan` of `component` (on either side; its
/// outputs first), or `None` when it has no fan of that name.
pub fn fan_len(spec: &Spec, component: &str, fan: &str) -> Option<usize> {
    let (inputs, outputs) = groups(spec, component)?;
    outputs
        .iter()
        .chain(inputs)
        .find(|g| g.peer == fan && !g.peers.is_empty())
        .map(|g| g.peers.len())
}

/// Whether `text` names every element of a fan (`c2.c1[*].plan`).
pub fn is_every(text: &str) -> bool {
    text.contains(EVERY)
}

/// `text` with its whole fan's index replaced by element `k`'s
/// (`c2.c1[*].plan` -> `c2.c1[3].plan`).
pub fn element(text: &str, k: usize) -> String {
    text.replacen(EVERY, &format!("[{k}]"), 1)
}

/// The elements a buffer reference stands for: `text` itself (`None`), or
/// for a whole fan (`component.fan[*].buffer`) each element's name with its
/// index, in order. Empty when `text` names a whole fan `spec` does not have.
pub fn elements(spec: &Spec, text: &str) -> Vec<(String, Option<usize>)> {
    if !is_every(text) {
        return vec![(text.to_owned(), None)];
    }
    let mut parts = text.splitn(3, '.');
    let (Some(component), Some(group)) = (parts.next(), parts.next()) else {
        return Vec::new();
    };
    let Some(fan) = group.strip_suffix(EVERY) else {
        return Vec::new();
    };
    let len = fan_len(spec, component, fan).unwrap_or(0);
    (0..len).map(|k| (element(text, k), Some(k))).collect()
}

/// `name` for element `k` of what it stands for: `name[k]`, or `name` itself
/// for no element.
pub fn named(name: &str, k: Option<usize>) -> String {
    k.map_or_else(|| name.to_owned(), |k| format!("{name}[{k}]"))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_whole_fan_stands_for_each_element_in_order() {
        let source = r#"(name: "f", agents: [(name: "a", subsystems: [(
            name: "c2", kind: Control, period_ms: 10.0,
            outputs: [(peer: "c1", peers: ["x", "y"], buffers: [(name: "plan", type: "u64")])],
            behaviours: [(name: "run", kind: While, terminal: "false")], fsm: (initial: "run"),
        )])])"#;
        let spec = crate::load("f.ron", source).expect("loads").spec;
        assert_eq!(fan_len(&spec, "c2", "c1"), Some(2));
        assert_eq!(fan_len(&spec, "c2", "x"), None);
        assert_eq!(
            elements(&spec, "c2.c1[*].plan"),
            [
                ("c2.c1[0].plan".to_owned(), Some(0)),
                ("c2.c1[1].plan".to_owned(), Some(1))
            ]
        );
        assert_eq!(
            elements(&spec, "c2.c1[1].plan"),
            [("c2.c1[1].plan".to_owned(), None)]
        );
        assert!(elements(&spec, "c2.nope[*].plan").is_empty());
        assert_eq!(named("torque", Some(3)), "torque[3]");
        assert_eq!(named("torque", None), "torque");
    }
}
