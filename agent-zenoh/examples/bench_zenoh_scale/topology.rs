//! What one run is: its links' topology (a ring or a star of K processes) and
//! whom each process connects to.

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Topology {
    Ring,
    Star,
}

impl Topology {
    pub(crate) fn name(self) -> &'static str {
        match self {
            Topology::Ring => "ring",
            Topology::Star => "star",
        }
    }

    pub(crate) fn parse(s: &str) -> Topology {
        match s {
            "ring" => Topology::Ring,
            "star" => Topology::Star,
            _ => panic!("topology `{s}`: ring or star"),
        }
    }

    /// The links (pinger, echoer) of `k` processes; a link's index is its key.
    pub(crate) fn links(self, k: usize) -> Vec<(usize, usize)> {
        match self {
            Topology::Ring => (0..k).map(|i| (i, (i + 1) % k)).collect(),
            Topology::Star => (1..k).map(|i| (i, 0)).collect(),
        }
    }
}

/// Which processes a process connects to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Connect {
    /// Every other process (as a deployment's members do), with Zenoh's defaults.
    Mesh,
    /// Only those it has a link with (the lower index connects), gossip off.
    Needed,
}

impl Connect {
    pub(crate) fn name(self) -> &'static str {
        match self {
            Connect::Mesh => "mesh",
            Connect::Needed => "needed",
        }
    }

    pub(crate) fn parse(s: &str) -> Connect {
        match s {
            "mesh" => Connect::Mesh,
            "needed" => Connect::Needed,
            _ => panic!("connect `{s}`: mesh or needed"),
        }
    }
}
