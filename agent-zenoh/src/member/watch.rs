//! [`Watch`]: a deployment seen from outside, by a launcher or a monitor.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

use agent_spec::model::Spec;
use zenoh::Wait;

use super::layout::Layout;
use super::session::{close_within, poll_tokens, process_of};
use super::{Member, MemberError, Options};

/// A deployment seen from outside (a launcher, a monitor): the observations its
/// processes publish, their presence, and the stop signal.
pub struct Watch {
    layout: Layout,
    session: zenoh::Session,
    _presence: zenoh::liveliness::LivelinessToken,
    observations:
        zenoh::pubsub::Subscriber<zenoh::handlers::FifoChannelHandler<zenoh::sample::Sample>>,
}

impl Drop for Watch {
    fn drop(&mut self) {
        close_within(self.session.clone(), Member::CLOSE);
    }
}

impl std::fmt::Debug for Watch {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Watch")
            .field("deployment", &self.layout.deployment)
            .finish()
    }
}

/// One observation: the process, its name, the bytes.
pub type Observation = (String, String, Vec<u8>);

impl Watch {
    /// Watch deployment `deployment` of `spec` (connecting to every process's
    /// endpoint; nothing listens).
    pub fn open(spec: &Spec, deployment: &str, options: &Options) -> Result<Watch, MemberError> {
        let layout = Layout::of(spec, deployment, options)?;
        let session = layout.open("launcher", None)?;
        let zerr = MemberError::zenoh("launcher");
        let observations = session
            .declare_subscriber(layout.rt_key("probe/**"))
            .with(zenoh::handlers::FifoChannel::new(1 << 16))
            .wait()
            .map_err(zerr)?;
        // The processes of the launch watch this: when it goes, they stop.
        let presence = session
            .liveliness()
            .declare_token(layout.rt_key("launcher"))
            .wait()
            .map_err(zerr)?;
        Ok(Watch {
            layout,
            session,
            _presence: presence,
            observations,
        })
    }

    /// The next observation, waiting at most `timeout`.
    pub fn next(&self, timeout: Duration) -> Option<Observation> {
        let sample = self.observations.recv_timeout(timeout).ok().flatten()?;
        let key = sample.key_expr().as_str();
        let rest = key.strip_prefix(&self.layout.rt_key("probe/"))?;
        let (process, name) = rest.split_once('/')?;
        Some((
            process.to_owned(),
            name.to_owned(),
            sample.payload().to_bytes().into_owned(),
        ))
    }

    /// The keys of the liveliness tokens under runtime key `key` now: one
    /// query, not repeated (its replies take up to 300 ms to gather).
    fn tokens_now(&self, key: &str) -> Vec<String> {
        let (_, seen) = poll_tokens(
            &self.session,
            &self.layout.rt_key(key),
            Duration::ZERO,
            None,
            |_| true,
        );
        seen
    }

    /// The processes present now.
    pub fn present(&self) -> Vec<String> {
        let prefix = self.layout.rt_key("process/");
        self.tokens_now("process/*/*")
            .iter()
            .filter_map(|k| process_of(k, &prefix).map(str::to_owned))
            .collect()
    }

    /// The deployment's instant zero, once a process has announced it (a
    /// query of up to 300 ms: ask until it is known, not in a hot loop).
    pub fn origin(&self) -> Option<SystemTime> {
        self.tokens_now("origin/*")
            .iter()
            .filter_map(|k| k.rsplit('/').next()?.parse::<u64>().ok())
            .max()
            .map(|ns| UNIX_EPOCH + Duration::from_nanos(ns))
    }

    /// Ask every process to stop (the signal names the launcher).
    pub fn stop(&self) {
        let _ = self
            .session
            .put(self.layout.rt_key("stop"), "launcher")
            .wait();
    }
}
