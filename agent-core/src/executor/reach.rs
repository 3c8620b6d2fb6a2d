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
    /// Per node, where its addresses start in `read` and `step` (one more
    /// entry: the end).
    at: Vec<(u32, u32)>,
}

impl Reach {
    /// The addresses of `nodes`, in their order.
    pub(crate) fn of(nodes: &[Box<dyn InProcessNode>]) -> Reach {
        let mut r = Reach::default();
        for node in nodes {
            r.at.push((len32(&r.read), len32(&r.step)));
            node.reach(&mut r.read, &mut r.step);
        }
        r.at.push((len32(&r.read), len32(&r.step)));
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
        let (Some(&(r0, s0)), Some(&(r1, s1))) = (self.at.get(i), self.at.get(i + 1)) else {
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
        let fsm = || {
            Fsm::single(Behaviour::while_loop(
                "run",
                Action::<C>::new()
                    .output(|y| &mut y.p, |m: &u64, _: &CIn, y: &mut ToPeer| y.v.set(*m)),
                "false",
            ))
            .unwrap()
        };
        let (a1, a2, a3) = (b.agent("a1"), b.agent("a2"), b.agent("a3"));
        let c1 = b.subsystem(a1, "c1", period, 0, fsm());
        let c2 = b.subsystem(a2, "c2", period, 0, fsm());
        let (out, into) = (port!(COut, p.v), port!(CIn, p.v));
        b.connect(c1.output(out), c2.input(into), Policy::queue(4));
        b.connect(c2.output(out), c1.input(into), Policy::Sample);
        // c2's output fanned out to c3 too.
        let c3 = b.subsystem(a3, "c3", period, 0, fsm());
        b.connect(c2.output(out), c3.input(into), Policy::Sample);
        let x = Executor::new(b.build().unwrap(), ExecConfig::default());
        let r = &x.reach;
        let list = |node: usize, step: bool| {
            let (from, to) = (r.at[node], r.at[node + 1]);
            if step {
                r.step[from.1 as usize..to.1 as usize].to_vec()
            } else {
                r.read[from.0 as usize..to.0 as usize].to_vec()
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
