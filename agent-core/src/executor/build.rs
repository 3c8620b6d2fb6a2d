//! The deterministic executor's nodes and channels, made in stepping order
//! (the cache layout of issue 57's knee: what an instant touches lies on the
//! heap in the order it is touched).

use crate::link::{ChannelPlan, Channels, InPlan, OutPlan};
use crate::node::{InProcessNode, NodeSeed};

/// The in-process nodes of `seeds` with their ports, and the links' channels
/// (`plans`), made node by node in stepping `order`: a node, the channels of
/// its links not made yet and its ports one after the other, so that what an
/// instant touches lies on the heap in the order it is touched (rather than
/// all nodes, then all channels, then all ports). Each node's ports keep their
/// order (that of the trace's events).
pub(super) fn in_process(
    seeds: Vec<Box<dyn NodeSeed>>,
    outs: Vec<(usize, Box<dyn OutPlan>)>,
    ins: Vec<(usize, Box<dyn InPlan>)>,
    plans: &[Box<dyn ChannelPlan>],
    order: &[usize],
    audit: bool,
) -> (Vec<Box<dyn InProcessNode>>, Channels) {
    let n = seeds.len();
    let mut outs_of: Vec<Vec<Box<dyn OutPlan>>> = (0..n).map(|_| Vec::new()).collect();
    for (node, plan) in outs {
        outs_of[node].push(plan);
    }
    let mut ins_of: Vec<Vec<Box<dyn InPlan>>> = (0..n).map(|_| Vec::new()).collect();
    for (node, plan) in ins {
        ins_of[node].push(plan);
    }
    let mut seeds: Vec<Option<Box<dyn NodeSeed>>> = seeds.into_iter().map(Some).collect();
    let mut made: Vec<Option<Box<dyn InProcessNode>>> = (0..n).map(|_| None).collect();
    let mut channels = Channels::unmade(plans.len());
    for &i in order {
        let Some(seed) = seeds[i].take() else {
            continue;
        };
        let mut node = seed.into_in_process(audit);
        // Handles were checked against the nodes' buffer types when the links
        // were declared, and every plan's channel was made from the same payload
        // type, so installation cannot fail.
        for plan in &outs_of[i] {
            for &l in plan.links() {
                channels.make(l, plans);
            }
            let installed = plan
                .local(&channels)
                .is_some_and(|port| node.install_out(port));
            debug_assert!(installed, "output port type checked at connect()");
        }
        for plan in &ins_of[i] {
            channels.make(plan.link(), plans);
            let installed = plan
                .local(&channels)
                .is_some_and(|port| node.install_in(port));
            debug_assert!(installed, "input port type checked at connect()");
        }
        made[i] = Some(node);
    }
    // Links no port of this system uses (none, unless a plan refused).
    for l in 0..plans.len() {
        channels.make(l, plans);
    }
    let nodes: Vec<Box<dyn InProcessNode>> = made.into_iter().flatten().collect();
    debug_assert_eq!(nodes.len(), n, "every node is in the stepping order");
    (nodes, channels)
}
