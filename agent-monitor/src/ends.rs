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
/// of a link to or from `peer`.
fn matches(spec: &str, node: &str, peer: &str, port: &str) -> bool {
    let mut parts = spec.splitn(3, '.');
    let (Some(c), Some(g), Some(b)) = (parts.next(), parts.next(), parts.next()) else {
        return false;
    };
    c == node
        && g == peer
        && (port.strip_prefix(g).and_then(|p| p.strip_prefix('.')) == Some(b)
            || port.rsplit('.').next() == Some(b))
}
