//! `--transitions`: every FSM transition printed as it happens, in either
//! executor:
//!
//! ```text
//! t=0.100000 s c2: ask -> wait (arc 0, when true)
//! ```

use agent_core::{NoObserver, NodeInfo, Observer, RealTime, Step, SystemInfo, TransitionEvent};
use agent_mcap::McapRecorder;

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
    behaviours: Vec<String>,
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

/// Give a real-time run its observers: on each thread its part of
/// `recorder`'s recording and of the ROS 2 bridge's (`ros2`) beside a
/// transition printer (printing if `print`); with neither, a printer only if
/// it prints.
pub(crate) fn observe(
    rt: &mut RealTime,
    recorder: Option<&McapRecorder>,
    print: bool,
    ros2: Option<Threads>,
) {
    match (recorder, ros2) {
        (Some(r), None) => {
            let mut parts = r.threads();
            rt.observe(move |thread, nodes| {
                Box::new((parts(thread, nodes), Transitions::new(print)))
            });
        }
        (recorder, Some(mut bridge)) => {
            let mut parts = recorder.map(McapRecorder::threads);
            rt.observe(move |thread, nodes| {
                let part: Box<dyn Observer> = match &mut parts {
                    Some(parts) => parts(thread, nodes),
                    None => Box::new(NoObserver),
                };
                Box::new(((part, bridge(thread, nodes)), Transitions::new(print)))
            });
        }
        (None, None) if print => {
            rt.observe(|_, _| Box::new(Transitions::new(true)));
        }
        (None, None) => {}
    }
}
