//! `--transitions`: every FSM transition printed as it happens, in either
//! executor:
//!
//! ```text
//! t=0.100000 s c2: ask -> wait (arc 0, when true)
//! ```

use std::sync::Arc;

use agent_core::{NoObserver, NodeInfo, Observer, RealTime, Step, SystemInfo, TransitionEvent};
use agent_mcap::McapRecorder;
use agent_monitor::live::Live;

use crate::output;
use crate::ros2::Threads;

/// An observer that prints each FSM transition (when enabled).
#[derive(Debug, Default)]
pub(crate) struct Transitions {
    on: bool,
    /// The subsystems and drivers, by node index.
    nodes: Vec<Node>,
}

/// What a transition line names of one node.
#[derive(Debug, Default)]
struct Node {
    name: String,
    behaviours: Arc<[String]>,
    /// The conditions of the arcs out of each behaviour, by behaviour and arc.
    arcs: Vec<Vec<String>>,
}

impl Node {
    fn of(n: &NodeInfo) -> Node {
        Node {
            name: n.name.clone(),
            behaviours: n.behaviours.clone(),
            arcs: n
                .behaviours
                .iter()
                .map(|b| {
                    n.fsm
                        .iter()
                        .flat_map(|fsm| &fsm.arcs)
                        .filter(|(from, _, _)| from == b)
                        .map(|(_, _, when)| when.clone())
                        .collect()
                })
                .collect(),
        }
    }
}

impl Transitions {
    /// A printer that prints (`on`) or observes nothing.
    pub(crate) fn new(on: bool) -> Transitions {
        Transitions {
            on,
            nodes: Vec::new(),
        }
    }
}

impl Observer for Transitions {
    fn enabled(&self) -> bool {
        self.on
    }

    fn start(&mut self, system: &SystemInfo) {
        self.nodes = system.nodes.iter().map(Node::of).collect();
    }

    fn transition(&mut self, event: &TransitionEvent) {
        let Some(node) = self.nodes.get(event.node) else {
            return;
        };
        let behaviour = |b: usize| node.behaviours.get(b).map_or("?", String::as_str);
        let t = event.time;
        match event.step {
            Step::Entered { from, arc, to, .. } => {
                let when = node.arcs.get(from).and_then(|arcs| arcs.get(arc));
                output::out(format_args!(
                    "t={t} {}: {} -> {} (arc {arc}, when {})\n",
                    node.name,
                    behaviour(from),
                    behaviour(to),
                    when.map_or("?", String::as_str)
                ));
            }
            Step::Finished => output::out(format_args!("t={t} {}: finished\n", node.name)),
            Step::Run => {}
        }
    }
}

/// What observes each thread of a real-time run.
pub(crate) struct Observers<'a> {
    /// The recording, whose part each thread gets.
    pub(crate) recorder: Option<&'a McapRecorder>,
    /// Whether transitions are printed.
    pub(crate) print: bool,
    /// The ROS 2 bridge's parts.
    pub(crate) ros2: Option<Threads>,
    /// The spec's contracts, whose watch of its subsystems each thread gets.
    pub(crate) contracts: Option<&'a Live>,
}

/// Give a real-time run its observers: on each thread its part of the
/// recording and of the ROS 2 bridge, a transition printer (printing if
/// asked) and the watch of the contracts of the thread's subsystems; none if
/// there is nothing to observe.
pub(crate) fn observe(rt: &mut RealTime, o: Observers<'_>) {
    if o.recorder.is_none() && o.ros2.is_none() && !o.print && o.contracts.is_none() {
        return;
    }
    let mut parts = o.recorder.map(McapRecorder::threads);
    let mut bridge = o.ros2;
    let contracts = o.contracts.cloned();
    let print = o.print;
    rt.observe(move |thread, nodes| {
        let part: Box<dyn Observer> = match &mut parts {
            Some(parts) => Box::new(parts(thread, nodes)),
            None => Box::new(NoObserver),
        };
        let bridged: Box<dyn Observer> = match &mut bridge {
            Some(bridge) => Box::new(bridge(thread, nodes)),
            None => Box::new(NoObserver),
        };
        let watch = contracts.as_ref().map(|c| c.watch_nodes(nodes));
        Box::new(((part, bridged), (Transitions::new(print), watch)))
    });
}
