//! When the deterministic executor's nodes are due: the nodes grouped by
//! period and next instant, the groups in a heap, so that an instant costs the
//! nodes due at it, not all the system's nodes.

use std::cmp::Reverse;
use std::collections::BinaryHeap;

/// The nodes of one period due at one instant.
#[derive(Debug)]
struct Group {
    period: u64,
    /// The instant its nodes are due at.
    next: u64,
    /// The nodes, in the executor's `order`.
    members: Vec<usize>,
}

/// The executor's nodes grouped by (period, next instant), the groups in a
/// heap by next instant: an instant pops the groups due (one per period at
/// most), steps their nodes in order and puts each group back at its next
/// instant, so that its cost is the nodes due (and the logarithm of the
/// groups), not all nodes. Nodes of one period started together stay
/// together: nodes are parted only by [`Executor::start_at`](super::Executor::start_at) (groups of the
/// same period at different instants).
///
/// Invariant unless `stale`: every group in the heap is not empty and every
/// member's `next` is the group's; a node whose `next` is `u64::MAX` is in
/// none; `groups` outside the heap (and not popped) are empty.
#[derive(Debug)]
pub(super) struct Schedule {
    groups: Vec<Group>,
    /// `(next, group)`, earliest first.
    heap: BinaryHeap<Reverse<(u64, usize)>>,
    /// Each node's rank: its position in the executor's `order`.
    pub(super) rank: Vec<usize>,
    /// The groups due at the instant being executed.
    popped: Vec<usize>,
    /// The nodes due at the instant being executed, in the executor's
    /// `order`.
    pub(super) due: Vec<usize>,
    /// Some node halted during the instant being executed (its group must
    /// drop it).
    pub(super) halted: bool,
    /// `next` was changed outside an instant ([`Executor::isolate`](super::Executor::isolate),
    /// [`Executor::start_at`](super::Executor::start_at)) or an instant was left half done (a stopping
    /// error): the groups are rebuilt before the next instant, and until then
    /// `next` alone says when that is.
    pub(super) stale: bool,
}

impl Schedule {
    /// The schedule of nodes due at `next`, of periods `periods`, stepped
    /// in `order`.
    pub(super) fn new(next: &[u64], periods: &[u64], order: &[usize]) -> Schedule {
        let mut rank = vec![0; order.len()];
        for (r, &i) in order.iter().enumerate() {
            rank[i] = r;
        }
        let mut nodes: Vec<usize> = order
            .iter()
            .copied()
            .filter(|&i| next[i] != u64::MAX)
            .collect();
        // Stable: each group's nodes stay in `order`.
        nodes.sort_by_key(|&i| (periods[i], next[i]));
        let mut groups: Vec<Group> = Vec::new();
        for i in nodes {
            let (period, at) = (periods[i], next[i]);
            match groups.last_mut() {
                Some(g) if g.period == period && g.next == at => g.members.push(i),
                _ => groups.push(Group {
                    period,
                    next: at,
                    members: vec![i],
                }),
            }
        }
        let heap = groups
            .iter()
            .enumerate()
            .map(|(k, g)| Reverse((g.next, k)))
            .collect();
        Schedule {
            rank,
            popped: Vec::with_capacity(groups.len()),
            due: Vec::with_capacity(order.len()),
            groups,
            heap,
            halted: false,
            stale: false,
        }
    }

    /// The earliest instant a node is due at.
    pub(super) fn next_instant(&self) -> Option<u64> {
        self.heap.peek().map(|Reverse((t, _))| *t)
    }

    /// Take the groups due at `tn` out of the heap; their nodes into `due`.
    pub(super) fn take_due(&mut self, tn: u64) {
        self.popped.clear();
        self.due.clear();
        while let Some(&Reverse((t, g))) = self.heap.peek() {
            if t != tn {
                break;
            }
            self.heap.pop();
            self.popped.push(g);
            self.due.extend_from_slice(&self.groups[g].members);
        }
        if self.popped.len() > 1 {
            // Several periods due together: their nodes interleaved (in
            // place, no allocation).
            let rank = &self.rank;
            self.due.sort_unstable_by_key(|&i| rank[i]);
        }
    }

    /// After a whole instant `tn`: put the groups due back at their next
    /// instant, without the nodes that halted.
    pub(super) fn reschedule(&mut self, tn: u64, next: &[u64]) {
        let halted = std::mem::take(&mut self.halted);
        for &g in &self.popped {
            let group = &mut self.groups[g];
            group.next = tn.saturating_add(group.period);
            if group.next == u64::MAX {
                group.members.clear();
            } else if halted {
                let at = group.next;
                group.members.retain(|&i| next[i] == at);
            }
            if !group.members.is_empty() {
                self.heap.push(Reverse((group.next, g)));
            }
        }
        self.popped.clear();
    }

    /// Drop from the groups waiting in the heap the nodes that halted (a
    /// safe-stop), and the groups left empty.
    pub(super) fn prune(&mut self, next: &[u64]) {
        for &Reverse((at, g)) in self.heap.iter() {
            self.groups[g].members.retain(|&i| next[i] == at);
        }
        let groups = &self.groups;
        self.heap
            .retain(|&Reverse((_, g))| !groups[g].members.is_empty());
    }
}
