//! A real-time run that ended: every node, the environment, the links' counters
//! and the report, for the program to inspect.

use std::any::Any;
use std::collections::BTreeMap;
use std::fmt;

use crate::executor::Executor;
use crate::link::{LinkId, LinkStats};
use crate::node::{DriverCore, subsystem_core};
use crate::subsystem::{Driver, Subsystem};
use crate::system::{DriverHandle, SubsystemHandle};
use crate::trace::Observer;
use crate::trace::SystemInfo;

use super::RtReport;

/// A real-time run that ended: its nodes, environment, links and report.
pub struct Finished {
    pub(super) info: SystemInfo,
    pub(super) cores: BTreeMap<usize, Box<dyn Any + Send>>,
    pub(super) environment: Option<Box<dyn Any + Send>>,
    pub(super) links: Vec<LinkStats>,
    pub(super) report: RtReport,
}

impl fmt::Debug for Finished {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Finished")
            .field("report", &self.report)
            .finish()
    }
}

impl Finished {
    pub(crate) fn new(
        info: SystemInfo,
        cores: BTreeMap<usize, Box<dyn Any + Send>>,
        environment: Option<Box<dyn Any + Send>>,
        links: Vec<LinkStats>,
        report: RtReport,
    ) -> Finished {
        Finished {
            info,
            cores,
            environment,
            links,
            report,
        }
    }

    /// What the run measured.
    pub fn report(&self) -> &RtReport {
        &self.report
    }

    /// Names, kinds, periods and links.
    pub fn info(&self) -> &SystemInfo {
        &self.info
    }

    /// The report, keeping nothing else.
    pub fn into_report(self) -> RtReport {
        self.report
    }

    fn core(&self, node: usize) -> Option<&dyn Any> {
        self.cores.get(&node).map(|c| &**c as &dyn Any)
    }

    /// The memory of a subsystem at the end.
    pub fn memory<S: Subsystem>(&self, h: &SubsystemHandle<S>) -> Option<&S::Memory> {
        subsystem_core::<S>(self.core(h.id().index())?).map(|c| &c.memory)
    }

    /// The name of the behaviour a subsystem ended in.
    pub fn behaviour<S: Subsystem>(&self, h: &SubsystemHandle<S>) -> Option<&str> {
        subsystem_core::<S>(self.core(h.id().index())?)
            .map(|c| c.fsm.behaviour_name(c.state.behaviour()))
    }

    /// Whether a subsystem ended halted (final behaviour, or an FSM error).
    pub fn is_halted<S: Subsystem>(&self, h: &SubsystemHandle<S>) -> bool {
        self.core(h.id().index())
            .and_then(subsystem_core::<S>)
            .is_some_and(|c| c.state.is_halted())
    }

    /// A driver's device at the end.
    pub fn driver<D: Driver>(&self, h: &DriverHandle<D>) -> Option<&D> {
        self.core(h.id().index())?
            .downcast_ref::<DriverCore<D>>()
            .map(|c| &c.driver)
    }

    /// The system's environment at the end.
    pub fn environment<W: Any>(&self) -> Option<&W> {
        self.environment.as_deref()?.downcast_ref()
    }

    /// The number of activations a node executed.
    pub fn activations(&self, node: crate::NodeId) -> Option<u64> {
        let name = &self.info.nodes.get(node.index())?.name;
        self.report.node(name).map(|t| t.activations)
    }

    /// Counters of a link.
    pub fn link_stats(&self, link: LinkId) -> Option<LinkStats> {
        self.links.get(link.index()).copied()
    }

    /// Counters of every link, in the order of [`SystemInfo::links`].
    pub fn links(&self) -> &[LinkStats] {
        &self.links
    }
}

impl<O: Observer> Executor<O> {
    /// End the run: every node, the environment and the links' counters, as
    /// the real-time executor returns them ([`Finished`]), with this run's
    /// errors and last instant in its report; and the observer.
    pub fn finish(self) -> (Finished, O) {
        let Executor {
            info,
            nodes,
            environment,
            channels,
            now,
            observer,
            report,
            probes_dropped,
            ..
        } = self;
        let links: Vec<LinkStats> = channels.all_stats();
        let cores = nodes
            .into_iter()
            .enumerate()
            .map(|(i, n)| (i, n.into_core()))
            .collect();
        let report = RtReport {
            errors: report.errors,
            error_count: report.error_count,
            last_instant: now,
            safe_stopped: report.safe_stopped,
            probe_dropped: probes_dropped
                .iter()
                .map(|d| d.load(std::sync::atomic::Ordering::Relaxed))
                .sum(),
            ..RtReport::default()
        };
        (
            Finished::new(info, cores, environment, links, report),
            observer,
        )
    }
}
