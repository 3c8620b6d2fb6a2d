//! The deterministic executor's nodes and channels, made in stepping order
//! (the cache layout of issue 57's knee: what an instant touches lies on the
//! heap in the order it is touched).

use super::reach::Reach;
use crate::cache::prefetch;
use crate::link::{ChannelPlan, Channels, InPlan, OutPlan};
use crate::node::{InProcessNode, NodeSeed};

/// The in-process nodes of `seeds` with their ports, and the links' channels
/// (`plans`), made node by node in stepping `order`: a node, the channels of
/// its links not made yet and its ports one after the other, so that what an
/// instant touches lies on the heap in the order it is touched (rather than
/// all nodes, then all channels, then all ports). Each node's ports keep their
/// order (that of the trace's events).
///
/// What is made is used while it is in the cache (issue 57's build of
/// thousands of subsystems, whose memory exceeds the last-level cache): each
/// node's reach is gathered as soon as it is made, and each node's plans are
/// dropped once its ports are installed, rather than in passes over every
/// node afterwards; what the builder made long before (the seeds, the plans,
/// the channels' plans) is asked of the cache a few nodes ahead of its use;
/// the plans are sorted by node into one vector (not a vector a node).
pub(super) fn in_process(
    seeds: Vec<Box<dyn NodeSeed>>,
    outs: Vec<(usize, Box<dyn OutPlan>)>,
    ins: Vec<(usize, Box<dyn InPlan>)>,
    plans: &[Box<dyn ChannelPlan>],
    order: &[usize],
    audit: bool,
) -> (Vec<Box<dyn InProcessNode>>, Channels, Reach) {
    let n = seeds.len();
    let mut outs_of = ByNode::new(n, outs);
    let mut ins_of = ByNode::new(n, ins);
    let mut seeds: Vec<Option<Box<dyn NodeSeed>>> = seeds.into_iter().map(Some).collect();
    let mut made: Vec<Option<Box<dyn InProcessNode>>> = (0..n).map(|_| None).collect();
    let mut channels = Channels::unmade(plans.len());
    let mut reach = Reach::with_nodes(n);
    for (k, &i) in order.iter().enumerate() {
        // What the node a few ahead is made from: its seed and plans, made
        // by the builder before and out of the cache in a large system.
        if let Some(&j) = order.get(k + AHEAD) {
            if let Some(Some(seed)) = seeds.get(j) {
                prefetch(&**seed, SEED_LINES);
            }
            outs_of.prefetch(j);
            ins_of.prefetch(j);
        }
        // Half as far ahead, that node's plans are in the cache: the plans
        // of the channels of its links, asked for now.
        if let Some(&j) = order.get(k + AHEAD / 2) {
            let channel = |l: usize| {
                if let Some(plan) = plans.get(l) {
                    prefetch(&**plan, 1);
                }
            };
            for plan in outs_of.peek(j) {
                plan.links().iter().copied().for_each(channel);
            }
            for plan in ins_of.peek(j) {
                channel(plan.link());
            }
        }
        let Some(seed) = seeds.get_mut(i).and_then(Option::take) else {
            continue;
        };
        let mut node = seed.into_in_process(audit);
        // Handles were checked against the nodes' buffer types when the links
        // were declared, and every plan's channel was made from the same payload
        // type, so installation cannot fail.
        for plan in outs_of.take(i) {
            for &l in plan.links() {
                channels.make(l, plans);
            }
            let installed = plan
                .local(&channels)
                .is_some_and(|port| node.install_out(port));
            debug_assert!(installed, "output port type checked at connect()");
        }
        for plan in ins_of.take(i) {
            channels.make(plan.link(), plans);
            let installed = plan
                .local(&channels)
                .is_some_and(|port| node.install_in(port));
            debug_assert!(installed, "input port type checked at connect()");
        }
        reach.gather(i, &*node);
        if let Some(slot) = made.get_mut(i) {
            *slot = Some(node);
        }
    }
    // Links no port of this system uses (none, unless a plan refused).
    for l in 0..plans.len() {
        channels.make(l, plans);
    }
    let nodes: Vec<Box<dyn InProcessNode>> = made.into_iter().flatten().collect();
    debug_assert_eq!(nodes.len(), n, "every node is in the stepping order");
    (nodes, channels, reach)
}

/// How many nodes ahead in the stepping order the build asks the cache for
/// what a node is made from.
const AHEAD: usize = 8;
/// The lines asked of a node's seed (its core: FSM, buffers, memory).
const SEED_LINES: usize = 4;

/// Plans sorted by the node they belong to (a counting sort: one vector for
/// all, each node's in the order given), taken node by node.
struct ByNode<P> {
    plans: Vec<Option<P>>,
    /// Where each node's plans start in `plans` (one more entry: the end).
    from: Vec<usize>,
}

impl<P> ByNode<P> {
    fn new(nodes: usize, given: Vec<(usize, P)>) -> ByNode<P> {
        let mut from = vec![0; nodes + 1];
        for &(node, _) in &given {
            if let Some(count) = from.get_mut(node + 1) {
                *count += 1;
            }
        }
        for k in 1..from.len() {
            from[k] += from[k - 1];
        }
        let mut next = from.clone();
        let mut plans: Vec<Option<P>> = (0..given.len()).map(|_| None).collect();
        for (node, plan) in given {
            // A plan of no node of this system (none: the builder made
            // them for its nodes) is dropped.
            if let Some(at) = next.get_mut(node) {
                if let Some(slot) = plans.get_mut(*at) {
                    *slot = Some(plan);
                }
                *at += 1;
            }
        }
        ByNode { plans, from }
    }

    /// Ask the cache for node `node`'s plans.
    fn prefetch(&self, node: usize)
    where
        P: std::ops::Deref,
    {
        for plan in self.peek(node) {
            prefetch(&**plan, 1);
        }
    }

    /// Where node `node`'s plans lie in `plans` (empty for no such node).
    fn of(&self, node: usize) -> std::ops::Range<usize> {
        let at = |k: usize| self.from.get(k).copied().unwrap_or(0);
        at(node)..at(node + 1)
    }

    /// Node `node`'s plans, left in place.
    fn peek(&self, node: usize) -> impl Iterator<Item = &P> + '_ {
        let plans = self.plans.get(self.of(node)).unwrap_or_default();
        plans.iter().flatten()
    }

    /// Node `node`'s plans, taken out (dropped by the caller once used).
    fn take(&mut self, node: usize) -> impl Iterator<Item = P> + '_ {
        let range = self.of(node);
        let plans = self.plans.get_mut(range).unwrap_or_default();
        plans.iter_mut().filter_map(Option::take)
    }
}

#[cfg(test)]
mod tests {
    use super::ByNode;

    /// Each node's plans come out in the order they were given (the order of
    /// its ports, and of the trace's events), once; a plan of no node is
    /// never given to one.
    #[test]
    fn plans_by_node_keep_their_order_and_are_taken_once() {
        let given = vec![
            (2, "c0"),
            (0, "a0"),
            (3, "past"),
            (2, "c1"),
            (7, "none"),
            (0, "a1"),
            (2, "c2"),
        ];
        let mut by = ByNode::new(3, given);
        assert_eq!(by.peek(2).copied().collect::<Vec<_>>(), ["c0", "c1", "c2"]);
        assert_eq!(by.peek(1).count(), 0);
        assert_eq!(by.take(0).collect::<Vec<_>>(), ["a0", "a1"]);
        assert_eq!(by.take(0).count(), 0, "taken once");
        assert_eq!(by.take(2).collect::<Vec<_>>(), ["c0", "c1", "c2"]);
        assert_eq!(by.peek(7).count(), 0, "no such node");
        assert_eq!(by.take(3).count(), 0, "no such node: the one past the last");
    }
}
