//! What each node's read and step touch, asked of the cache a few nodes
//! ahead of the executor's walks ([`crate::cache`]).

use crate::cache::{prefetch, prefetch_addr};
use crate::node::InProcessNode;

/// The addresses each node's read and step touch beyond the node itself
/// (its ports and their channels, [`InProcessNode::reach`]), gathered once
/// when the executor is made: nodes, ports and channels never move.
#[derive(Debug, Default)]
pub(crate) struct Reach {
    read: Vec<usize>,
    step: Vec<usize>,
    /// Per node (in the nodes' order), where its addresses lie in `read`
    /// and in `step`: `[read from, read to, step from, step to]`. Gathered
    /// in stepping order, as each node is made ([`Reach::gather`]).
    at: Vec<[u32; 4]>,
}

impl Reach {
    /// Room for the reach of `nodes` nodes, to be gathered node by node.
    pub(crate) fn with_nodes(nodes: usize) -> Reach {
        Reach {
            at: vec![[0; 4]; nodes],
            ..Reach::default()
        }
    }

    /// Gather the addresses of `node`, the `i`-th of the nodes (just made:
    /// its ports and channels are still in the cache, where a pass over
    /// every node afterwards would miss them in a large system).
    pub(crate) fn gather(&mut self, i: usize, node: &dyn InProcessNode) {
        let (r0, s0) = (len32(&self.read), len32(&self.step));
        node.reach(&mut self.read, &mut self.step);
        if let Some(at) = self.at.get_mut(i) {
            *at = [r0, len32(&self.read), s0, len32(&self.step)];
        }
    }

    /// The addresses of `nodes`, in their order.
    #[cfg(test)]
    pub(crate) fn of(nodes: &[Box<dyn InProcessNode>]) -> Reach {
        let mut r = Reach::with_nodes(nodes.len());
        for (i, node) in nodes.iter().enumerate() {
            r.gather(i, &**node);
        }
        r
    }

    /// Every address of `nodes` (those the reach was gathered from) and of
    /// their reach: the memory an instant's walks touch.
    pub(crate) fn addresses<'a>(
        &'a self,
        nodes: &'a [Box<dyn InProcessNode>],
    ) -> impl Iterator<Item = usize> + 'a {
        let nodes = nodes.iter().map(|n| std::ptr::from_ref(&**n).addr());
        nodes.chain(self.read.iter().chain(&self.step).copied())
    }

    /// Ask the cache for what node `i` touches when it is read (`step`
    /// false) or stepped: its first lines and the addresses of its reach.
    #[inline(always)]
    pub(crate) fn prefetch(&self, node: &dyn InProcessNode, i: usize, step: bool) {
        prefetch(node, NODE_LINES);
        let Some(&[r0, r1, s0, s1]) = self.at.get(i) else {
            return;
        };
        let (list, from, to) = if step {
            (&self.step, s0, s1)
        } else {
            (&self.read, r0, r1)
        };
        for &at in list.get(from as usize..to as usize).unwrap_or_default() {
            prefetch_addr(at, REACH_LINES);
        }
    }
}

/// The lines asked of a node (its FSM state, buffers and port tables first).
const NODE_LINES: usize = 4;
/// The lines asked from each address of a node's reach: a port, a
/// channel, a queue's storage or a port table, each at most 128 bytes
/// for the values benchmarked (and the first two lines of a larger one
/// are those a transfer touches first). Measured against the exact lines
/// each value spans, which were slower (docs/scaling.md).
const REACH_LINES: usize = 2;

fn len32(v: &[usize]) -> u32 {
    u32::try_from(v.len()).unwrap_or(u32::MAX)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

    use crate::*;

    /// A control subsystem that sends its count to another agent's and
    /// reads the other's.
    struct C;
    #[derive(Debug, Default)]
    struct ToPeer {
        v: Out<u64>,
    }
    impl Group for ToPeer {
        const PEER: NodeKind = NodeKind::Control;
    }
    #[derive(Debug, Default)]
    struct FromPeer {
        v: In<u64>,
    }
    impl Group for FromPeer {
        const PEER: NodeKind = NodeKind::Control;
    }
    #[derive(Debug, Default)]
    struct COut {
        p: ToPeer,
    }
    #[derive(Debug, Default)]
    struct CIn {
        p: FromPeer,
    }
    impl Subsystem for C {
        const KIND: SubsystemKind = SubsystemKind::Control;
        type Memory = u64;
        type Input = CIn;
        type Output = COut;
    }

    /// A subsystem that sends its count to its peer, forever.
    fn sends() -> Fsm<C> {
        Fsm::single(Behaviour::while_loop(
            "run",
            Action::<C>::new().output(|y| &mut y.p, |m: &u64, _: &CIn, y: &mut ToPeer| y.v.set(*m)),
            "false",
        ))
        .unwrap()
    }

    /// A receptor that senses nothing: stepped after every other node.
    struct Clock;
    impl Driver for Clock {
        const KIND: DeviceKind = DeviceKind::Receptor;
        type Input = ();
        type Output = ();
        fn step(&mut self, _: DriverContext<'_>, _: &(), _: &mut ()) -> Result<(), DriverError> {
            Ok(())
        }
    }

    /// The reach the build gathers as it makes each node (in stepping
    /// order: here the receptor, declared first, is made last) is, node by
    /// node, what a pass over the made nodes gathers.
    #[test]
    fn the_reach_gathered_while_building_is_that_of_the_made_nodes() {
        let mut b = SystemBuilder::new();
        let period = Period::from_millis(1).unwrap();
        let agents: Vec<_> = (1..4).map(|i| b.agent(format!("a{i}"))).collect();
        b.driver(agents[0], "clock", period, Clock);
        let cs: Vec<_> = (0..3)
            .map(|i| b.subsystem(agents[i], format!("c{}", i + 1), period, 0, sends()))
            .collect();
        let (out, into) = (port!(COut, p.v), port!(CIn, p.v));
        for (i, c) in cs.iter().enumerate() {
            let next = cs[(i + 1) % cs.len()];
            let policy = if i == 0 {
                Policy::queue(4)
            } else {
                Policy::Sample
            };
            b.connect(c.output(out), next.input(into), policy);
        }
        let x = Executor::new(b.build().unwrap(), ExecConfig::default());
        assert_eq!(x.order, [1, 2, 3, 0], "the receptor is made last");
        let after = super::Reach::of(&x.nodes);
        let slices = |r: &super::Reach, i: usize| {
            let [r0, r1, s0, s1] = r.at[i];
            (
                r.read[r0 as usize..r1 as usize].to_vec(),
                r.step[s0 as usize..s1 as usize].to_vec(),
            )
        };
        for i in 0..x.nodes.len() {
            assert_eq!(slices(&x.reach, i), slices(&after, i), "node {i}");
        }
        assert!(slices(&x.reach, 0).0.is_empty(), "the clock has no ports");
        assert!(!slices(&x.reach, 1).1.is_empty(), "c1 sends");
    }

    fn shared(a: &[usize], b: &[usize]) -> usize {
        a.iter().filter(|x| b.contains(x)).count()
    }

    /// The reach of a link's two ends names the same channel (and a queue's
    /// storage): what the writer's step touches is what the reader's read
    /// touches, and the ports (one per end) are their own.
    #[test]
    fn each_end_of_a_link_reaches_its_channel() {
        let mut b = SystemBuilder::new();
        let period = Period::from_millis(1).unwrap();
        let (a1, a2, a3) = (b.agent("a1"), b.agent("a2"), b.agent("a3"));
        let c1 = b.subsystem(a1, "c1", period, 0, sends());
        let c2 = b.subsystem(a2, "c2", period, 0, sends());
        let (out, into) = (port!(COut, p.v), port!(CIn, p.v));
        b.connect(c1.output(out), c2.input(into), Policy::queue(4));
        b.connect(c2.output(out), c1.input(into), Policy::Sample);
        // c2's output fanned out to c3 too.
        let c3 = b.subsystem(a3, "c3", period, 0, sends());
        b.connect(c2.output(out), c3.input(into), Policy::Sample);
        let x = Executor::new(b.build().unwrap(), ExecConfig::default());
        let r = &x.reach;
        let list = |node: usize, step: bool| {
            let [r0, r1, s0, s1] = r.at[node];
            if step {
                r.step[s0 as usize..s1 as usize].to_vec()
            } else {
                r.read[r0 as usize..r1 as usize].to_vec()
            }
        };
        let (i, j, k) = (c1.id().index(), c2.id().index(), c3.id().index());
        // The port table, the port, then the channel (and a queue's storage;
        // a fanned-out port's further destinations' header, list and
        // channels).
        assert_eq!(list(i, true).len(), 4);
        assert_eq!(list(j, false).len(), 4);
        assert_eq!(list(j, true).len(), 6);
        assert_eq!(list(i, false).len(), 3);
        assert_eq!(list(k, false).len(), 3);
        let queue = shared(&list(i, true), &list(j, false));
        assert_eq!(queue, 2, "queue: channel and storage");
        let sample = shared(&list(j, true), &list(i, false));
        assert_eq!(sample, 1, "sample: channel");
        let fanned = shared(&list(j, true), &list(k, false));
        assert_eq!(fanned, 1, "the fanned-out port's second channel");
        assert_eq!(shared(&list(i, true), &list(i, false)), 0);
        assert!(r.read.iter().chain(&r.step).all(|&a| a != 0));
    }
}
