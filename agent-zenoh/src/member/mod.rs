//! One process's membership in a running deployment: its session, presence,
//! the shared instant zero, the stop signal, probes; and [`Watch`], the view of a
//! launcher or monitor from outside.

use std::collections::HashMap;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use agent_core::Placement;
use agent_spec::model::Spec;
use zenoh::Wait;

use crate::outbox::Outbox;
use crate::transport::ZenohTransport;

mod layout;
mod presence;
mod session;
mod watch;

use layout::Layout;
use presence::{Presence, StoppedBy, watch_launcher, watch_stop};
pub use session::{SessionError, open_peer, open_secure_client, open_secure_peer};
use session::{close_within, poll_tokens, process_of};
pub use watch::{Observation, Watch};

/// Settings a command line may change.
#[derive(Clone, Debug, Default)]
pub struct Options {
    /// Replace the deployment's first port (so that tests or two runs of the
    /// same deployment do not share endpoints).
    pub port: Option<u16>,
    /// Replace the deployment's wait for the other processes.
    pub timeout: Option<Duration>,
    /// Where a secure deployment's credentials are (`ca.pem`,
    /// `<process>.pem`, `<process>.key`: [`crate::security::Credentials`]).
    pub credentials: Option<std::path::PathBuf>,
    /// The launch this process belongs to: the runtime's keys (presence,
    /// instant zero, the stop signal, observations) are under
    /// `<system>/_rt/<launch>/`, so that processes of two launches never take
    /// each other for their own. Default [`Options::DEFAULT_LAUNCH`] (processes
    /// started by hand agree on it).
    pub launch: Option<String>,
    /// Started by a launcher: the process stops when the launcher's presence
    /// (its liveliness token) is gone.
    pub launched: bool,
    /// Set from outside (a signal handler) to end the waits for the other
    /// processes early ([`MemberError::Cancelled`]).
    pub cancel: Option<Arc<AtomicBool>>,
}

impl Options {
    /// The launch of processes started without a launcher.
    pub const DEFAULT_LAUNCH: &'static str = "default";
}

/// Why a process could not join its deployment, or lost it.
#[derive(Debug, thiserror::Error)]
pub enum MemberError {
    /// The deployment's announced instant zero is too far in the future to be
    /// one this deployment set (a host's clock far off, or a foreign token):
    /// waiting for it would look like a hang.
    #[error(
        "process `{process}`: the deployment's instant zero is {ahead:.1} s in the future (at most {allowed:.1} s expected); are the hosts' clocks synchronised?"
    )]
    Origin {
        /// This process.
        process: String,
        /// How far ahead \[s\].
        ahead: f64,
        /// The most expected: the start lead and the deployment's timeout \[s\].
        allowed: f64,
    },
    /// The spec has no such deployment.
    #[error("spec `{spec}` has no deployment `{name}` (it has: {known})")]
    UnknownDeployment {
        /// The spec.
        spec: String,
        /// The deployment asked for.
        name: String,
        /// Those it has.
        known: String,
    },
    /// The deployment has no such process.
    #[error("deployment `{deployment}` has no process `{name}` (it has: {known})")]
    UnknownProcess {
        /// The deployment.
        deployment: String,
        /// The process asked for.
        name: String,
        /// Those it has.
        known: String,
    },
    /// Zenoh refused (a bad endpoint, a port taken, ...).
    #[error("zenoh, for process `{process}`: {error}")]
    Zenoh {
        /// This process.
        process: String,
        /// Zenoh's message.
        error: String,
    },
    /// Processes did not appear in time.
    #[error(
        "process `{process}` waited {waited:?} for {missing} of deployment `{deployment}` (on {endpoints}); is it started, and reachable?"
    )]
    Missing {
        /// This process.
        process: String,
        /// The deployment.
        deployment: String,
        /// The processes that did not appear, as a list.
        missing: String,
        /// Where they were expected.
        endpoints: String,
        /// How long.
        waited: Duration,
    },
    /// The transport was already handed to a placement.
    #[error("the placement of process `{0}` was already taken")]
    PlacementTaken(String),
    /// A secure deployment without the process's credentials.
    #[error("process `{process}` of secure deployment `{deployment}`: {error}")]
    Credentials {
        /// This process.
        process: String,
        /// The deployment.
        deployment: String,
        /// What is missing.
        error: crate::security::CredentialError,
    },
    /// The deployment's access policy could not be made.
    #[error(transparent)]
    Policy(#[from] crate::security::PolicyError),
    /// The wait for the other processes was cancelled (a signal).
    #[error("process `{process}`: stopped while waiting for {what}")]
    Cancelled {
        /// This process.
        process: String,
        /// What it waited for.
        what: String,
    },
    /// A launch identity that cannot be part of a key.
    #[error("launch identity `{0}`: use letters, digits, `-` and `_` only")]
    Launch(String),
    /// Messages the run put were not yet in Zenoh's hands when the session
    /// closed (a peer that does not take what a reliable link sends).
    #[error("process `{process}`: messages still waited to be published {waited:?} after the run")]
    Unsent {
        /// This process.
        process: String,
        /// How long the close waited.
        waited: Duration,
    },
}

impl MemberError {
    /// Zenoh's error in `process` as [`MemberError::Zenoh`], for `map_err`.
    fn zenoh(process: &str) -> impl Fn(zenoh::Error) -> MemberError + Copy {
        move |e| MemberError::Zenoh {
            process: process.to_owned(),
            error: e.to_string(),
        }
    }
}

/// This process in its running deployment.
pub struct Member {
    layout: Layout,
    process: String,
    session: zenoh::Session,
    transport: Option<ZenohTransport>,
    /// The transport's inboxes, by receiving component.
    senders: crate::transport::Senders,
    /// The epoch each other process announced, and who runs what.
    epochs: Arc<Mutex<HashMap<String, u64>>>,
    runs: HashMap<String, Vec<String>>,
    /// This process's epoch: on its values, and in its presence token.
    epoch: u64,
    /// The transport's publishing thread, flushed before the session closes.
    outbox: Arc<Outbox>,
    stop: Arc<AtomicBool>,
    /// Who asked the deployment to stop, as the stop signal says.
    stopped_by: StoppedBy,
    /// Whether the launcher's presence went away.
    launcher_gone: Arc<AtomicBool>,
    gone: Arc<Mutex<Vec<String>>>,
    _token: Option<zenoh::liveliness::LivelinessToken>,
    _launcher: Option<zenoh::pubsub::Subscriber<()>>,
    _origin_token: Option<zenoh::liveliness::LivelinessToken>,
    _watch: zenoh::pubsub::Subscriber<()>,
    _stop: zenoh::pubsub::Subscriber<()>,
}

impl std::fmt::Debug for Member {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Member")
            .field("system", &self.layout.system)
            .field("deployment", &self.layout.deployment)
            .field("process", &self.process)
            .finish()
    }
}

impl Member {
    /// How long [`Member::close`] waits for what the run put to be published.
    pub const FLUSH: Duration = Duration::from_secs(5);

    /// How long [`Member::close`] (and a [`Watch`] dropped) waits for Zenoh to
    /// close the session's links, once what it put is flushed: a process that
    /// ended after the others took 10 s more to go, Zenoh's default.
    pub const CLOSE: Duration = Duration::from_millis(500);

    /// How long after a process is seen to go it is reported lost, unless a
    /// stop of the deployment arrives meanwhile (the stop and the departure
    /// travel different ways, so the departure may come first).
    pub const STOP_SKEW: Duration = Duration::from_millis(300);

    /// Join deployment `deployment` of `spec` as process `process`: open the
    /// session on the process's endpoint, connect to the others, and follow
    /// their presence (processes that come and vanish), the stop signal and,
    /// if launched, the launcher. [`Member::ready`] announces this process.
    pub fn join(
        spec: &Spec,
        deployment: &str,
        process: &str,
        options: &Options,
    ) -> Result<Member, MemberError> {
        let layout = Layout::of(spec, deployment, options)?;
        let listen = listen_endpoint(&layout, process)?;
        let session = layout.open(process, Some(&listen))?;
        let zerr = MemberError::zenoh(process);
        let transport = ZenohTransport::new(session.clone(), layout.system.clone());
        // Followed for as long as the member lives (the subscribers are its own).
        let presence = Presence::new(&layout, transport.senders());
        let watch = presence.clone().watch(&session, &layout).map_err(zerr)?;
        let (stop_sub, stopped_by) = watch_stop(&session, &layout, &presence.stop).map_err(zerr)?;
        let (launcher, launcher_gone) =
            watch_launcher(&session, &layout, options.launched, &presence.stop).map_err(zerr)?;
        Ok(Member {
            layout,
            process: process.to_owned(),
            session,
            outbox: transport.outbox(),
            senders: transport.senders(),
            epochs: presence.epochs,
            runs: presence.runs,
            epoch: agent_core::link::remote::new_epoch(),
            transport: Some(transport),
            stop: presence.stop,
            stopped_by,
            launcher_gone,
            gone: presence.gone,
            _token: None,
            _launcher: launcher,
            _origin_token: None,
            _watch: watch,
            _stop: stop_sub,
        })
    }

    /// The components this process runs.
    pub fn runs(&self) -> &[String] {
        self.layout
            .processes
            .iter()
            .find(|(p, _, _)| *p == self.process)
            .map_or(&[][..], |(_, _, r)| r.as_slice())
    }

    /// This process's name.
    pub fn process(&self) -> &str {
        &self.process
    }

    /// The placement of this process for [`agent_core::RealTime::place`]: the
    /// components it runs, and the Zenoh transport for the others (once).
    pub fn placement(&mut self) -> Result<Placement, MemberError> {
        let transport = self
            .transport
            .take()
            .ok_or_else(|| MemberError::PlacementTaken(self.process.clone()))?;
        Ok(Placement {
            here: self.runs().to_vec(),
            prefix: self.layout.system.clone(),
            transport: Box::new(transport),
            epoch: self.epoch,
        })
    }

    /// Wait until every other process of the deployment is present; the error
    /// names those that did not appear within the deployment's timeout.
    pub fn wait_for_all(&self) -> Result<(), MemberError> {
        let others: Vec<&str> = self
            .layout
            .processes
            .iter()
            .map(|(p, _, _)| p.as_str())
            .filter(|p| *p != self.process)
            .collect();
        let prefix = self.layout.rt_key("process/");
        let missing_of = |seen: &[String]| -> Vec<&str> {
            others
                .iter()
                .copied()
                .filter(|o| !seen.iter().any(|k| process_of(k, &prefix) == Some(*o)))
                .collect()
        };
        let (ok, seen) = poll_tokens(
            &self.session,
            &self.layout.rt_key("process/*/*"),
            self.layout.timeout,
            self.layout.cancel.as_deref(),
            |seen| missing_of(seen).is_empty(),
        );
        if ok {
            return Ok(());
        }
        let missing = missing_of(&seen);
        if self.layout.cancelled() {
            return Err(MemberError::Cancelled {
                process: self.process.clone(),
                what: missing
                    .iter()
                    .map(|m| format!("`{m}`"))
                    .collect::<Vec<_>>()
                    .join(", "),
            });
        }
        Err(MemberError::Missing {
            process: self.process.clone(),
            deployment: self.layout.deployment.clone(),
            endpoints: self.layout.where_(
                missing
                    .iter()
                    .filter_map(|m| self.layout.endpoint(m))
                    .collect::<Vec<_>>()
                    .join(", "),
                &self.session,
            ),
            missing: missing
                .iter()
                .map(|m| format!("`{m}`"))
                .collect::<Vec<_>>()
                .join(", "),
            waited: self.layout.timeout,
        })
    }

    /// Announce this process ready (its links made), and return the deployment's
    /// instant zero: the first process of the deployment sets it, `lead` after
    /// every process is ready, and announces it; the others wait for it (a
    /// process restarted later finds it at once, in the past). Give it to
    /// [`agent_core::RealTime::start_when`], which calls it once the links exist.
    pub fn ready(&mut self, lead: Duration) -> Result<SystemTime, MemberError> {
        if self._token.is_none() {
            let token = self
                .session
                .liveliness()
                .declare_token(
                    self.layout
                        .rt_key(&format!("process/{}/{}", self.process, self.epoch)),
                )
                .wait()
                .map_err(MemberError::zenoh(&self.process))?;
            self._token = Some(token);
            // The inboxes exist now: each takes the epoch its sender announced.
            let epochs = self
                .epochs
                .lock()
                .unwrap_or_else(PoisonError::into_inner)
                .clone();
            let senders = self.senders.lock().unwrap_or_else(PoisonError::into_inner);
            for (process, epoch) in epochs {
                for component in self.runs.get(&process).into_iter().flatten() {
                    for inbox in senders.get(component).into_iter().flatten() {
                        inbox.expect(epoch);
                    }
                }
            }
        }
        let leader = self
            .layout
            .processes
            .first()
            .map(|(p, _, _)| p.clone())
            .unwrap_or_default();
        let key = self.layout.rt_key("origin/*");
        let parse = |seen: &[String]| -> Option<u64> {
            seen.iter()
                .filter_map(|k| k.rsplit('/').next()?.parse::<u64>().ok())
                .max()
        };
        if leader == self.process {
            // Once the others are seen, their tokens are: a deployment already
            // running (this leader restarted) keeps its instant zero, which
            // every process announces.
            self.wait_for_all()?;
            let (_, seen) = poll_tokens(&self.session, &key, Duration::ZERO, None, |_| true);
            if let Some(ns) = parse(&seen) {
                let origin = self.plausible(ns, lead)?;
                self.announce_origin(ns)?;
                return Ok(origin);
            }
            let origin = SystemTime::now() + lead;
            let ns = origin
                .duration_since(UNIX_EPOCH)
                .map_or(0, |d| u64::try_from(d.as_nanos()).unwrap_or(u64::MAX));
            self.announce_origin(ns)?;
            return Ok(origin);
        }
        let (ok, seen) = poll_tokens(
            &self.session,
            &key,
            self.layout.timeout,
            self.layout.cancel.as_deref(),
            |seen| parse(seen).is_some(),
        );
        if !ok && self.layout.cancelled() {
            return Err(MemberError::Cancelled {
                process: self.process.clone(),
                what: format!("the start signal of `{leader}`"),
            });
        }
        match parse(&seen) {
            Some(ns) if ok => {
                let origin = self.plausible(ns, lead)?;
                self.announce_origin(ns)?;
                Ok(origin)
            }
            _ => Err(MemberError::Missing {
                process: self.process.clone(),
                deployment: self.layout.deployment.clone(),
                missing: format!("the start signal of `{leader}`"),
                endpoints: self.layout.where_(
                    self.layout.endpoint(&leader).unwrap_or("?").to_owned(),
                    &self.session,
                ),
                waited: self.layout.timeout,
            }),
        }
    }

    /// Instant zero announced as `ns` since the Unix epoch, if it is no later
    /// than a leader could have set it (`lead` after all were ready, and the
    /// deployment's timeout for clocks and stragglers).
    fn plausible(&self, ns: u64, lead: Duration) -> Result<SystemTime, MemberError> {
        let origin = UNIX_EPOCH + Duration::from_nanos(ns);
        let allowed = lead + self.layout.timeout;
        match origin.duration_since(SystemTime::now()) {
            Ok(ahead) if ahead > allowed => Err(MemberError::Origin {
                process: self.process.clone(),
                ahead: ahead.as_secs_f64(),
                allowed: allowed.as_secs_f64(),
            }),
            _ => Ok(origin),
        }
    }

    /// Announce instant zero (`ns` since the Unix epoch) as long as this process
    /// lives: every process does, so that one restarted, the first included,
    /// finds it.
    fn announce_origin(&mut self, ns: u64) -> Result<(), MemberError> {
        if self._origin_token.is_none() {
            let token = self
                .session
                .liveliness()
                .declare_token(self.layout.rt_key(&format!("origin/{ns}")))
                .wait()
                .map_err(MemberError::zenoh(&self.process))?;
            self._origin_token = Some(token);
        }
        Ok(())
    }

    /// Whether a stop was asked (by [`Member::request_stop`] or [`Watch::stop`]
    /// of any participant).
    pub fn stop_requested(&self) -> bool {
        self.stop.load(Ordering::Relaxed)
    }

    /// Ask every process of the deployment to stop (the signal names this
    /// process).
    pub fn request_stop(&self) {
        let _ = self
            .session
            .put(
                self.layout.rt_key("stop"),
                format!("process `{}`", self.process),
            )
            .wait();
        self.stop.store(true, Ordering::Relaxed);
    }

    /// Who asked the deployment to stop, as its stop signal names itself
    /// (`launcher`, `process \`world\``), if a stop came over the network.
    pub fn stopped_by(&self) -> Option<String> {
        self.stopped_by
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// Whether the launcher that started this process is gone (its presence
    /// ended): the run stops.
    pub fn launcher_gone(&self) -> bool {
        self.launcher_gone.load(Ordering::Relaxed)
    }

    /// This process's launch (the runtime keys' part).
    pub fn launch(&self) -> &str {
        &self.layout.launch
    }

    /// Leave the deployment: what was published is sent before the session
    /// closes (waiting at most [`Member::FLUSH`] for the publishing thread),
    /// and the others see this process go.
    pub fn close(self) -> Result<(), MemberError> {
        let Member {
            session,
            outbox,
            process,
            ..
        } = self;
        let flushed = outbox.flush(Member::FLUSH);
        close_within(session, Member::CLOSE);
        if flushed {
            Ok(())
        } else {
            Err(MemberError::Unsent {
                process,
                waited: Member::FLUSH,
            })
        }
    }

    /// Values of sample links dropped so far because the publishing thread
    /// was behind ([`ZenohTransport::dropped`]).
    pub fn sample_dropped(&self) -> u64 {
        self.outbox.dropped()
    }

    /// The processes seen to vanish so far.
    pub fn gone(&self) -> Vec<String> {
        self.gone
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .clone()
    }

    /// Publish `bytes` as observation `name` of this process, for a [`Watch`]
    /// (reliably: observations are not dropped under congestion).
    pub fn observe(&self, name: &str, bytes: Vec<u8>) -> Result<(), MemberError> {
        self.session
            .put(
                self.layout
                    .rt_key(&format!("probe/{}/{name}", self.process)),
                bytes,
            )
            .congestion_control(zenoh::qos::CongestionControl::Block)
            .wait()
            .map_err(MemberError::zenoh(&self.process))
    }
}

/// The endpoint `process` listens on, as the deployment says.
fn listen_endpoint(layout: &Layout, process: &str) -> Result<String, MemberError> {
    layout
        .endpoint(process)
        .map(str::to_owned)
        .ok_or_else(|| MemberError::UnknownProcess {
            deployment: layout.deployment.clone(),
            name: process.to_owned(),
            known: layout
                .processes
                .iter()
                .map(|(p, _, _)| p.as_str())
                .collect::<Vec<_>>()
                .join(", "),
        })
}
