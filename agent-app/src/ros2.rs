//! `--ros2[=ENDPOINT]`: while a run goes, the buffers the spec's `ros2`
//! section publishes are ROS 2 topics over rmw_zenoh (agent-ros2's outbound
//! bridge, a client of the Zenoh router at ENDPOINT, such as rmw_zenohd); at
//! the end, what it published is said on standard error:
//!
//! ```text
//! ros2: published=1203 dropped=0 encode_failures=0 put_failures=0
//! ```

use agent_core::trace::{
    ActionEvent, AuditEvent, ErasedPayload, ReadEvent, TransferEvent, TransitionEvent,
};
use agent_core::{ExecError, Observer, System, SystemInfo, Time};

use crate::error::AppError;
use crate::{Application, Common, SpecFile};

/// The observers of a real-time run's threads, one made per thread.
pub(crate) type Threads = Box<dyn FnMut(&str, &[usize]) -> Box<dyn Observer> + Send>;

/// The part of a deployment this process runs: its bridge publishes only
/// the buffers of the components it runs, as node `<node>_<process>`.
#[derive(Clone, Copy, Debug)]
#[cfg_attr(
    not(all(feature = "ros2", feature = "distributed")),
    allow(
        dead_code,
        reason = "made by a process of a deployment, read by the bridge"
    )
)]
pub(crate) struct Part<'a> {
    /// The deployment.
    pub(crate) deployment: &'a str,
    /// This process.
    pub(crate) process: &'a str,
    /// The components it runs.
    pub(crate) runs: &'a [String],
}

/// The bridge of a run, when `--ros2` is given: an observer of the
/// deterministic executor (observing nothing without a bridge).
#[derive(Debug, Default)]
pub(crate) struct Ros2Out {
    #[cfg(feature = "ros2")]
    bridge: Option<agent_ros2::bridge::Bridge>,
}

#[cfg(not(feature = "ros2"))]
impl Ros2Out {
    /// No bridge: `--ros2` is refused (built without the feature).
    pub(crate) fn start<A: Application>(
        _app: &A,
        common: &Common,
        _spec: &SpecFile,
        _system: &System,
        _part: Option<Part<'_>>,
    ) -> Result<Ros2Out, AppError> {
        match &common.ros2 {
            Some(endpoint) => Err(AppError::invalid(format!(
                "--ros2 {endpoint}: built without the feature `ros2`: no ROS 2 bridge"
            ))),
            None => Ok(Ros2Out::default()),
        }
    }

    /// No observers.
    pub(crate) fn threads(&self) -> Option<Threads> {
        None
    }

    /// Nothing to finish: whether it finished cleanly (yes).
    pub(crate) fn finish(self) -> bool {
        true
    }

    fn observer(&mut self) -> Option<&mut dyn Observer> {
        None
    }
}

#[cfg(feature = "ros2")]
impl Ros2Out {
    /// The bridge of `system` (built from `spec`) if `--ros2` is given,
    /// started (a client of the router at its endpoint); for `part` of a
    /// deployment, that part's. A plan the spec cannot make or a router that
    /// cannot be reached is invalid input.
    pub(crate) fn start<A: Application>(
        app: &A,
        common: &Common,
        spec: &SpecFile,
        system: &System,
        part: Option<Part<'_>>,
    ) -> Result<Ros2Out, AppError> {
        use agent_ros2::bridge::{Bridge, BridgeOptions, Plan, SessionOptions};
        let Some(endpoint) = &common.ros2 else {
            return Ok(Ros2Out::default());
        };
        let invalid =
            |e: &dyn std::fmt::Display| AppError::invalid(format!("--ros2 {endpoint}: {e}"));
        let (spec, absent) = in_the_system(&spec.spec, part.map(|p| p.deployment), system);
        if !absent.is_empty() {
            crate::output::warn(format_args!(
                "--ros2: not published, their components are not in this run: {}",
                absent.join(", ")
            ));
        }
        let deployment = match part {
            Some(p) => Some(spec.deployment(p.deployment).ok_or_else(|| {
                invalid(&format_args!("spec has no deployment `{}`", p.deployment))
            })?),
            None => None,
        };
        let adapters = app.ros2_adapters();
        let mut plan = Plan::new(&spec, deployment, system, &adapters).map_err(|e| invalid(&e))?;
        if let Some(p) = part {
            let node = format!("{}_{}", plan.node, node_name_part(p.process));
            plan = plan
                .only_components(p.runs)
                .named(&node)
                .map_err(|e| invalid(&e))?;
        }
        if !plan.unserved().is_empty() {
            let topics: Vec<&str> = plan.unserved().iter().map(|t| t.topic.as_str()).collect();
            crate::output::warn(format_args!(
                "--ros2: the spec's subscribe topics are not served yet (nothing is taken from ROS 2): {}",
                topics.join(", ")
            ));
        }
        let mut options = BridgeOptions {
            session: SessionOptions::client(endpoint),
            ..BridgeOptions::default()
        };
        if part.is_none() && !common.realtime {
            options.slots = DETERMINISTIC_SLOTS;
        }
        let bridge = Bridge::start(plan, options).map_err(|e| invalid(&e))?;
        Ok(Ros2Out {
            bridge: Some(bridge),
        })
    }

    /// The observers of a real-time run's threads, if a bridge runs.
    pub(crate) fn threads(&self) -> Option<Threads> {
        self.bridge
            .as_ref()
            .map(|b| Box::new(b.threads()) as Threads)
    }

    /// Finish the bridge (after the run) and say what it published; whether
    /// it finished cleanly (an error is said).
    pub(crate) fn finish(self) -> bool {
        let Some(bridge) = self.bridge else {
            return true;
        };
        match bridge.finish() {
            Ok(report) => {
                crate::output::err(format_args!(
                    "ros2: published={} dropped={} encode_failures={} put_failures={}",
                    report.published(),
                    report.dropped(),
                    report.encode_failures(),
                    report.put_failures()
                ));
                for e in &report.close_errors {
                    crate::output::warn(format_args!("ros2: {e}"));
                }
                true
            }
            Err(e) => {
                crate::output::error(&format_args!("ros2: {e}"));
                false
            }
        }
    }

    fn observer(&mut self) -> Option<&mut dyn Observer> {
        self.bridge.as_mut().map(|b| b as &mut dyn Observer)
    }
}

/// `spec` without the `publish` entries whose component `system` does not
/// have (a run built without some of the spec's components, as Rex's
/// `--no-vo`), and the buffers of those that `deployment`'s section (or the
/// system's) names.
#[cfg(feature = "ros2")]
fn in_the_system(
    spec: &agent_spec::Spec,
    deployment: Option<&str>,
    system: &System,
) -> (agent_spec::Spec, Vec<String>) {
    let info = system.info();
    let has = |buffer: &str| {
        let component = buffer.split('.').next().unwrap_or_default();
        info.nodes.iter().any(|n| n.name == component)
    };
    let section = agent_spec::ros2::section(spec, deployment.and_then(|d| spec.deployment(d)));
    let absent = section
        .map(|s| s.publish.iter().filter(|t| !has(&t.buffer)))
        .into_iter()
        .flatten()
        .map(|t| t.buffer.clone())
        .collect();
    let mut spec = spec.clone();
    let sections = spec
        .ros2
        .iter_mut()
        .chain(spec.deployments.iter_mut().filter_map(|d| d.ros2.as_mut()));
    for section in sections {
        section.publish.retain(|t| has(&t.buffer));
    }
    (spec, absent)
}

/// The values the bridge's publishing thread may fall behind by in a
/// deterministic run, which goes as fast as it can (Rex's square mission,
/// some 50 times faster than real time, sends some 36,000 published values
/// in 0.7 s of wall-clock time; a ring of 256 dropped a third of them):
/// beyond, values are dropped and counted.
#[cfg(feature = "ros2")]
const DETERMINISTIC_SLOTS: usize = 1 << 15;

/// `process` as part of a ROS 2 node name: what is not a letter, digit or
/// `_` becomes `_`.
#[cfg_attr(
    not(feature = "ros2"),
    allow(dead_code, reason = "used by the bridge only (and its test)")
)]
fn node_name_part(process: &str) -> String {
    process
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect()
}

impl Observer for Ros2Out {
    fn enabled(&self) -> bool {
        #[cfg(feature = "ros2")]
        return self.bridge.as_ref().is_some_and(Observer::enabled);
        #[cfg(not(feature = "ros2"))]
        false
    }
    fn start(&mut self, system: &SystemInfo) {
        if let Some(o) = self.observer() {
            o.start(system);
        }
    }
    fn transition(&mut self, event: &TransitionEvent) {
        if let Some(o) = self.observer() {
            o.transition(event);
        }
    }
    fn action(&mut self, event: &ActionEvent) {
        if let Some(o) = self.observer() {
            o.action(event);
        }
    }
    fn audit(&mut self, event: &AuditEvent) {
        if let Some(o) = self.observer() {
            o.audit(event);
        }
    }
    fn transfer(&mut self, event: &TransferEvent, value: &dyn ErasedPayload) {
        if let Some(o) = self.observer() {
            o.transfer(event, value);
        }
    }
    fn read(&mut self, event: &ReadEvent) {
        if let Some(o) = self.observer() {
            o.read(event);
        }
    }
    fn received(&mut self, event: &ReadEvent, value: &dyn ErasedPayload) {
        if let Some(o) = self.observer() {
            o.received(event, value);
        }
    }
    fn error(&mut self, time: Time, error: &ExecError) {
        if let Some(o) = self.observer() {
            o.error(time, error);
        }
    }
}

#[cfg(test)]
mod tests;
