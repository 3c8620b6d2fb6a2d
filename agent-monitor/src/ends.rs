//! Which link a contract's buffer is on: a link's ends (`node.port -> node.port`)
//! matched to the spec's `component.group.buffer` names, the same way over a
//! recording and inside a running executor.

/// The ends of a link: its nodes and ports.
#[derive(Clone, Debug)]
pub(crate) struct Ends {
    from: String,
    from_port: String,
    to: String,
    to_port: String,
}

impl Ends {
    /// A link's name, `node.port -> node.port`.
    pub(crate) fn parse(name: &str) -> Option<Ends> {
        let (from, to) = name.split_once(" -> ")?;
        let (from, from_port) = from.split_once('.')?;
        let (to, to_port) = to.split_once('.')?;
        Some(Ends {
            from: from.to_owned(),
            from_port: from_port.to_owned(),
            to: to.to_owned(),
            to_port: to_port.to_owned(),
        })
    }

    pub(crate) fn is_input(&self, spec: &str) -> bool {
        matches(spec, &self.to, &self.from, &self.to_port)
    }

    pub(crate) fn is_output(&self, spec: &str) -> bool {
        matches(spec, &self.from, &self.to, &self.from_port)
    }
}

/// Whether `spec` (`component.group.buffer`) names the end at `node`'s `port`
/// of a link to or from `peer`. A fan's element (`c2.c1[3].plan`) is named by
/// its port (`c1[3].plan`), whichever its peer.
fn matches(spec: &str, node: &str, peer: &str, port: &str) -> bool {
    let mut parts = spec.splitn(3, '.');
    let (Some(c), Some(g), Some(b)) = (parts.next(), parts.next(), parts.next()) else {
        return false;
    };
    let exact = port.strip_prefix(g).and_then(|p| p.strip_prefix('.')) == Some(b);
    if g.ends_with(']') || port.contains('[') {
        return c == node && exact;
    }
    c == node && g == peer && (exact || port.rsplit('.').next() == Some(b))
}

#[cfg(test)]
mod tests {
    use super::Ends;

    #[test]
    fn a_fan_element_is_matched_by_its_port_and_no_other_element() {
        let out = Ends::parse("c2.c1[3].plan -> c1_3.c2.plan").expect("a link");
        assert!(out.is_output("c2.c1[3].plan"));
        assert!(!out.is_output("c2.c1[2].plan"));
        assert!(!out.is_output("c2.c1_3.plan"));
        assert!(out.is_input("c1_3.c2.plan"));
        let back = Ends::parse("c1_3.c2.ack -> c2.c1[3].ack").expect("a link");
        assert!(back.is_input("c2.c1[3].ack"));
        assert!(!back.is_input("c2.c1[13].ack"));
        assert!(!back.is_input("c2.c1[3].plan"));
        // An ordinary group, as before: by its peer.
        let plain = Ends::parse("c1.e11.traj -> e11.c1.traj").expect("a link");
        assert!(plain.is_output("c1.e11.traj") && plain.is_input("e11.c1.traj"));
    }
}
