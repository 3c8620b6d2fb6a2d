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

#[cfg(feature = "ros2")]
/// A plan the spec cannot make, as invalid input (`--ros2 ENDPOINT: ...`); a
/// buffer whose Rust type cannot be its topic's message is said at the
/// spec's entry, in the checker's format (`spec::ros2_type`): the spec alone
/// does not know the types, the program does.
fn refused(
    file: &SpecFile,
    deployment: Option<&str>,
    endpoint: &str,
    e: &agent_ros2::bridge::PlanError,
) -> AppError {
    use agent_spec::{Code, Finding, Report};
    let at = e.mistyped_buffer().and_then(|buffer| {
        agent_spec::ros2::entry_span(&file.spec, &file.text, deployment, buffer)
    });
    let Some(span) = at else {
        return AppError::invalid(format!("--ros2 {endpoint}: {e}"));
    };
    let finding = Finding::new(Code::Ros2Type, span, "this buffer's type", e.to_string()).help(
        "publish a buffer whose type a ROS 2 message can carry, name a message an adapter makes of it, or give the program that adapter (Application::ros2_adapters)",
    );
    let report = Report::new(file.path.clone(), file.text.clone(), vec![finding]);
    AppError::invalid(format!(
        "--ros2 {endpoint}: specification {}:\n{}",
        file.path,
        report.short().trim_end()
    ))
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

    /// No inputs to feed.
    #[allow(
        clippy::unused_self,
        clippy::unnecessary_wraps,
        reason = "the bridge's signature, without the bridge"
    )]
    pub(crate) fn feed(&mut self, _rt: &mut agent_core::RealTime) -> Result<(), AppError> {
        Ok(())
    }

    /// Nothing to stamp.
    pub(crate) fn started(&self, _running: &agent_core::Running) {}

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
        let file = spec;
        let (spec, absent) = in_the_system(&spec.spec, part.map(|p| p.deployment), system);
        if !absent.is_empty() {
            crate::output::warn(format_args!(
                "--ros2: not shown to ROS 2, their components are not in this run: {}",
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
        let mut plan = Plan::new(&spec, deployment, system, &adapters)
            .map_err(|e| refused(file, part.map(|p| p.deployment), endpoint, &e))?;
        if let Some(p) = part {
            let node = format!("{}_{}", plan.node, node_name_part(p.process));
            plan = plan
                .only_components(p.runs)
                .named(&node)
                .map_err(|e| invalid(&e))?;
        }
        // A deterministic run is not on the wall clock: a value from ROS 2
        // has no instant in it.
        if part.is_none() && !common.realtime {
            plan = plan.unserve_subscriptions(DETERMINISTIC);
        }
        for topic in plan.unserved() {
            crate::output::warn(format_args!("--ros2: {topic}"));
        }
        let session = match part {
            Some(p) if secure(&spec, p.deployment) => secure_session(common, endpoint, p)?,
            _ => SessionOptions::client(endpoint),
        };
        let mut options = BridgeOptions {
            session,
            ..BridgeOptions::default()
        };
        if part.is_none() && !common.realtime {
            options.slots = DETERMINISTIC_SLOTS;
            options.wait_when_full = Some(DETERMINISTIC_WAIT);
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

    /// Feed the inputs of the topics the bridge subscribes to, in the
    /// real-time run `rt` (before it starts).
    pub(crate) fn feed(&mut self, rt: &mut agent_core::RealTime) -> Result<(), AppError> {
        let Some(bridge) = self.bridge.as_mut() else {
            return Ok(());
        };
        let wanted: Vec<(usize, usize, String)> = bridge
            .plan()
            .subscriptions
            .iter()
            .enumerate()
            .map(|(i, t)| (i, t.link, t.key.topic().to_owned()))
            .collect();
        for (index, link, topic) in wanted {
            let refused = |e: &dyn std::fmt::Display| {
                AppError::Run(format!(
                    "--ros2: topic `{topic}` cannot feed its input: {e}"
                ))
            };
            let id = agent_core::LinkId::of(rt.info(), link)
                .ok_or_else(|| refused(&format_args!("the system has no link #{link}")))?;
            let inbox = rt
                .feed(id, &format!("ros2:{topic}"))
                .map_err(|e| refused(&e))?;
            bridge.subscribe(index, inbox).map_err(|e| refused(&e))?;
        }
        Ok(())
    }

    /// The run started: the values taken from ROS 2 count their instants
    /// from its instant zero.
    pub(crate) fn started(&self, running: &agent_core::Running) {
        if let Some(bridge) = &self.bridge {
            bridge.set_inbound_zero(running.zero());
        }
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
                    "ros2: published={} dropped={} encode_failures={} put_failures={} received={} delivered={} refused={} lost={}",
                    report.published(),
                    report.dropped(),
                    report.encode_failures(),
                    report.put_failures(),
                    report.received(),
                    report.delivered(),
                    report.refused(),
                    report.lost()
                ));
                for t in &report.subscriptions {
                    if t.refused() + t.dropped + t.inbox_problems > 0 {
                        crate::output::warn(format_args!(
                            "ros2: {} (into {}): refused {} of {} received (wrong_type={} bad_attachment={} duplicate={} undecodable={} rejected={}), dropped={}, inbox_problems={}{}",
                            t.topic,
                            t.buffer,
                            t.refused(),
                            t.received,
                            t.wrong_type,
                            t.bad_attachment,
                            t.duplicate,
                            t.undecodable,
                            t.rejected,
                            t.dropped,
                            t.inbox_problems,
                            t.last_refusal
                                .as_deref()
                                .map(|why| format!("; the last refused: {why}"))
                                .unwrap_or_default()
                        ));
                    }
                }
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

/// `spec` without the `publish` and `subscribe` entries whose component
/// `system` does not have (a run built without some of the spec's
/// components, as Rex's `--no-vo`), and the buffers of those that
/// `deployment`'s section (or the system's) names.
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
        .map(|s| {
            s.publish
                .iter()
                .chain(&s.subscribe)
                .filter(|t| !has(&t.buffer))
        })
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
        section.subscribe.retain(|t| has(&t.buffer));
    }
    (spec, absent)
}

/// `ros2-package DIR`: the ROS 2 interface package of the messages the
/// bridge makes from the buffer types, written into `DIR/<package>/`.
#[cfg(feature = "ros2")]
pub(crate) fn package<A: Application>(
    app: &mut A,
    config: &A::Config,
    common: &Common,
    dir: &std::path::Path,
) -> Result<crate::Status, AppError> {
    use agent_ros2::bridge::Plan;
    use agent_ros2::package::Package;
    let spec = app.spec(config)?;
    let system = app.build(config, &crate::Target::Whole)?;
    let deployment = common.deployment.as_deref();
    let (section, _) = in_the_system(&spec.spec, deployment, &system);
    let invalid = |e: &dyn std::fmt::Display| AppError::invalid(format!("ros2-package: {e}"));
    let chosen = match deployment {
        Some(d) => Some(
            section
                .deployment(d)
                .ok_or_else(|| invalid(&format_args!("the spec has no deployment `{d}`")))?,
        ),
        None => None,
    };
    let plan =
        Plan::new(&section, chosen, &system, &app.ros2_adapters()).map_err(|e| invalid(&e))?;
    let messages = plan
        .topics
        .iter()
        .map(|t| &t.messages)
        .chain(plan.subscriptions.iter().map(|t| &t.messages));
    let package = Package::of(&plan.package, messages).map_err(|e| invalid(&e))?;
    let written = package
        .write(&dir.join(package.name()))
        .map_err(|e| invalid(&e))?;
    for path in written {
        crate::output::out(format_args!("{}\n", path.display()));
    }
    Ok(crate::Status::Success)
}

/// Without the feature, no package.
#[cfg(not(feature = "ros2"))]
pub(crate) fn package<A: Application>(
    _app: &mut A,
    _config: &A::Config,
    _common: &Common,
    dir: &std::path::Path,
) -> Result<crate::Status, AppError> {
    Err(AppError::invalid(format!(
        "ros2-package {}: built without the feature `ros2`",
        dir.display()
    )))
}

/// Why a deterministic run takes nothing from ROS 2.
#[cfg(feature = "ros2")]
const DETERMINISTIC: &str = "a deterministic run is not on the wall clock: run with --realtime (or a deployment) to take values from ROS 2";

/// Whether `deployment` of `spec` is secure.
#[cfg(feature = "ros2")]
fn secure(spec: &agent_spec::Spec, deployment: &str) -> bool {
    spec.deployment(deployment).is_some_and(|d| d.is_secure())
}

/// The bridge's session in a process of a secure deployment: over TLS, with
/// the process's certificate (the ROS 2 router's access control, generated by
/// `credentials`, knows it by its common name).
#[cfg(all(feature = "ros2", feature = "distributed"))]
fn secure_session(
    common: &Common,
    endpoint: &str,
    part: Part<'_>,
) -> Result<agent_ros2::bridge::SessionOptions, AppError> {
    use agent_zenoh::security::Credentials;
    let invalid = |why: &dyn std::fmt::Display| {
        AppError::invalid(format!(
            "--ros2={endpoint}: deployment `{}` is secure: {why}",
            part.deployment
        ))
    };
    if !endpoint.starts_with("tls/") {
        return Err(invalid(
            &"its bridges reach the ROS 2 router over mutual TLS: give a tls/HOST:PORT endpoint",
        ));
    }
    let dir = common.credentials.as_deref().ok_or_else(|| {
        invalid(&format_args!(
            "the ROS 2 router must know its certificates: make them with `{} credentials --deployment {} DIR`, start the router with DIR/{}, and launch with --credentials DIR",
            crate::output::program(),
            part.deployment,
            agent_ros2::access::ROUTER_CONFIG
        ))
    })?;
    let credentials = Credentials::in_dir(dir, part.process).map_err(|e| invalid(&e))?;
    agent_ros2::bridge::SessionOptions::tls_client(endpoint, &credentials).map_err(|e| invalid(&e))
}

/// Without deployments, no secure session.
#[cfg(all(feature = "ros2", not(feature = "distributed")))]
fn secure_session(
    _common: &Common,
    endpoint: &str,
    part: Part<'_>,
) -> Result<agent_ros2::bridge::SessionOptions, AppError> {
    Err(AppError::invalid(format!(
        "--ros2={endpoint}: deployment `{}` is secure, and this program is built without the feature `distributed`",
        part.deployment
    )))
}

/// The values the bridge's publishing thread may fall behind by in a
/// deterministic run, which goes as fast as it can (Rex's square mission,
/// some 50 times faster than real time, sends some 36,000 published values
/// in 0.7 s of wall-clock time): beyond, the run waits for the publishing
/// thread ([`DETERMINISTIC_WAIT`]) instead of dropping values, since its time
/// is not the wall clock's.
#[cfg(feature = "ros2")]
const DETERMINISTIC_SLOTS: usize = 4096;

/// How long a deterministic run waits for the bridge's publishing thread to
/// take a value before it drops it (and counts it): a stalled router, not a
/// busy one.
#[cfg(feature = "ros2")]
const DETERMINISTIC_WAIT: std::time::Duration = std::time::Duration::from_secs(5);

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
