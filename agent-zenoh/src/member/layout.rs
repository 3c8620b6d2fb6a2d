//! The deployment as one process (or a launcher) sees it: its processes and
//! their endpoints, the runtime's keys, the waits, and its security.

use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

use agent_spec::model::{Deployment, Spec};
use zenoh::Wait;

use super::session::open_secure_peer;
use super::{MemberError, Options};

/// The deployment as one process sees it.
pub(super) struct Layout {
    pub(super) system: String,
    pub(super) deployment: String,
    /// The launch's identity (the runtime keys' third part).
    pub(super) launch: String,
    /// Every process: name, endpoint, components.
    pub(super) processes: Vec<(String, String, Vec<String>)>,
    pub(super) router: Option<String>,
    pub(super) timeout: Duration,
    /// A secure deployment's policy and where its credentials are.
    pub(super) secure: Option<(crate::security::AccessPolicy, Option<std::path::PathBuf>)>,
    /// Ends the waits early.
    pub(super) cancel: Option<Arc<AtomicBool>>,
}

impl Layout {
    pub(super) fn of(
        spec: &Spec,
        deployment: &str,
        options: &Options,
    ) -> Result<Layout, MemberError> {
        let dep: &Deployment =
            spec.deployment(deployment)
                .ok_or_else(|| MemberError::UnknownDeployment {
                    spec: spec.name.clone(),
                    name: deployment.to_owned(),
                    known: spec.deployment_names(),
                })?;
        let mut dep = dep.clone();
        if let Some(port) = options.port {
            dep.port = Some(port);
        }
        let secure = if dep.is_secure() {
            Some((
                crate::security::AccessPolicy::of(spec, &dep.name)?,
                options.credentials.clone(),
            ))
        } else {
            None
        };
        // A secure deployment's links are QUIC (TLS 1.3 with mutual
        // authentication, on UDP): Zenoh's TLS link over TCP has a data race
        // between its reader and writer (eclipse-zenoh/zenoh#2557), QUIC's
        // streams do not share state that way. `tls/` says the same.
        let endpoint = |e: String| match (&secure, e.split_once('/')) {
            (Some(_), Some(("tcp" | "tls", rest))) => format!("quic/{rest}"),
            _ => e,
        };
        let launch = options
            .launch
            .clone()
            .unwrap_or_else(|| Options::DEFAULT_LAUNCH.to_owned());
        if launch.is_empty()
            || !launch
                .chars()
                .all(|c| c.is_ascii_alphanumeric() || c == '-' || c == '_')
        {
            return Err(MemberError::Launch(launch));
        }
        Ok(Layout {
            system: spec.name.clone(),
            deployment: dep.name.clone(),
            launch,
            processes: dep
                .processes()
                .into_iter()
                .map(|(_, p, e)| (p.name.clone(), endpoint(e), p.runs.clone()))
                .collect(),
            router: dep.router.clone(),
            timeout: options.timeout.unwrap_or_else(|| dep.timeout()),
            secure,
            cancel: options.cancel.clone(),
        })
    }

    pub(super) fn rt_key(&self, rest: &str) -> String {
        format!("{}/_rt/{}/{rest}", self.system, self.launch)
    }

    /// `endpoints`, and the router when the deployment has one (a router that
    /// is down is a reason why nobody appears): whether `session` reaches it.
    pub(super) fn where_(&self, endpoints: String, session: &zenoh::Session) -> String {
        match &self.router {
            Some(r) if session.info().routers_zid().wait().next().is_none() => {
                format!("{endpoints}, or through the router at {r}, which is not reachable")
            }
            Some(r) => format!("{endpoints}, or through the router at {r}"),
            None => endpoints,
        }
    }

    pub(super) fn cancelled(&self) -> bool {
        self.cancel
            .as_deref()
            .is_some_and(|c| c.load(Ordering::Relaxed))
    }

    pub(super) fn endpoint(&self, process: &str) -> Option<&str> {
        self.processes
            .iter()
            .find(|(p, _, _)| p == process)
            .map(|(_, e, _)| e.as_str())
    }

    /// A peer session listening on `listen` (if any) and connected to every other
    /// process and the router.
    pub(super) fn open(
        &self,
        me: &str,
        listen: Option<&str>,
    ) -> Result<zenoh::Session, MemberError> {
        let connect: Vec<&str> = self
            .processes
            .iter()
            .filter(|(p, _, _)| p != me)
            .map(|(_, e, _)| e.as_str())
            .chain(self.router.as_deref())
            .collect();
        let secured = match &self.secure {
            None => None,
            Some((policy, dir)) => {
                let credentials = |error| MemberError::Credentials {
                    process: me.to_owned(),
                    deployment: self.deployment.clone(),
                    error,
                };
                let dir = dir
                    .as_deref()
                    .ok_or_else(|| credentials(crate::security::CredentialError::NotGiven))?;
                Some(crate::security::Secured {
                    credentials: crate::security::Credentials::in_dir(dir, me)
                        .map_err(credentials)?,
                    acl: policy.acl(me)?,
                })
            }
        };
        open_secure_peer(listen, &connect, secured.as_ref()).map_err(|error| MemberError::Zenoh {
            process: me.to_owned(),
            error: error.to_string(),
        })
    }
}
