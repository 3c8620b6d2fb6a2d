//! Securing a deployment from its spec: who may publish and subscribe what,
//! as Zenoh's access control list, and the certificates that say who is who.
//!
//! In the formalism every input buffer has exactly one writer, and every output
//! buffer one owner: that is already an access-control policy. A process runs
//! some components; it may publish the keys of the output buffers of those
//! components that leave the process, and subscribe to the keys of their input
//! buffers fed from other processes; nothing else. [`AccessPolicy::of`] reads
//! that off a spec's deployment, and [`AccessPolicy::acl`] writes it as the
//! `access_control` section of a process's Zenoh configuration: every other
//! process is a subject, known by the common name of its certificate (mutual
//! TLS); what it may send this process (`put` on the keys it owns,
//! `declare_subscriber` on the keys it reads) and what this process may send it
//! are allowed, everything else denied. The runtime's own keys
//! (`<system>/_rt/**`: presence, instant zero, the stop signal, observations)
//! are open to every member of the deployment and to its launcher; so is
//! Zenoh's interest in who matches a publisher or subscriber on the link keys
//! (`declare_liveliness_subscriber`, no data), between members.

use std::collections::BTreeSet;

use agent_spec::model::Spec;
use serde_json::{Value, json};

/// The subject name of a deployment's launcher (or monitor), which takes part
/// in the runtime's keys only.
pub const LAUNCHER: &str = "launcher";

/// What one process of a deployment may do on the network.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ProcessAccess {
    /// The process's name.
    pub name: String,
    /// The common name of its certificate.
    pub common_name: String,
    /// The keys it publishes: the output buffers of its components that feed
    /// components of other processes.
    pub publishes: BTreeSet<String>,
    /// The keys it subscribes to: the output buffers of other processes'
    /// components that feed its components.
    pub subscribes: BTreeSet<String>,
}

/// Who may publish and subscribe what in a deployment (see the module's
/// documentation).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AccessPolicy {
    /// The system (the first part of every key).
    pub system: String,
    /// The deployment.
    pub deployment: String,
    /// Its processes, in the spec's order, then the launcher (no keys).
    pub processes: Vec<ProcessAccess>,
}

/// Why a policy could not be made.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum PolicyError {
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
    /// A link names a buffer of a component the spec does not have (a spec the
    /// checker refuses).
    #[error("link `{from} -> {to}`: no component `{component}` in the spec")]
    UnknownComponent {
        /// The link's output.
        from: String,
        /// The link's input.
        to: String,
        /// The component.
        component: String,
    },
    /// No process of that name.
    #[error("deployment `{deployment}` has no process `{name}` (it has: {known})")]
    UnknownProcess {
        /// The deployment.
        deployment: String,
        /// The name.
        name: String,
        /// Its processes.
        known: String,
    },
}

/// The common name of the certificate of `process` of `deployment` of
/// `system`.
pub fn common_name(system: &str, deployment: &str, process: &str) -> String {
    format!("{process}.{deployment}.{system}")
}

/// Every message kind of Zenoh's access control (1.x).
const ALL_MESSAGES: [&str; 9] = [
    "put",
    "delete",
    "declare_subscriber",
    "query",
    "declare_queryable",
    "reply",
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
];

impl AccessPolicy {
    /// The policy of `deployment` of `spec`.
    pub fn of(spec: &Spec, deployment: &str) -> Result<AccessPolicy, PolicyError> {
        let dep = spec
            .deployment(deployment)
            .ok_or_else(|| PolicyError::UnknownDeployment {
                spec: spec.name.clone(),
                name: deployment.to_owned(),
                known: spec.deployment_names(),
            })?;
        let placed = dep.processes();
        let mut processes: Vec<ProcessAccess> = placed
            .iter()
            .map(|(_, p, _)| ProcessAccess {
                name: p.name.clone(),
                common_name: common_name(&spec.name, &dep.name, &p.name),
                publishes: BTreeSet::new(),
                subscribes: BTreeSet::new(),
            })
            .collect();
        let process_of = |component: &str| {
            placed
                .iter()
                .position(|(_, p, _)| p.runs.iter().any(|r| r == component))
        };
        let agent_of = |component: &str| {
            spec.agents
                .iter()
                .find(|a| {
                    a.subsystems.iter().any(|s| s.name == component)
                        || a.devices.iter().any(|d| d.name == component)
                })
                .map(|a| a.name.as_str())
        };
        for link in &spec.links {
            let (from, port) = link.from.split_once('.').unwrap_or((&link.from, ""));
            let to = link.to.split_once('.').map_or(link.to.as_str(), |(c, _)| c);
            let (Some(a), Some(b)) = (process_of(from), process_of(to)) else {
                // An end that is not deployed (omitted): no link to secure.
                continue;
            };
            if a == b {
                continue;
            }
            let agent = agent_of(from).ok_or_else(|| PolicyError::UnknownComponent {
                from: link.from.clone(),
                to: link.to.clone(),
                component: from.to_owned(),
            })?;
            // As `agent_core::link::remote::link_key` makes it.
            let key = format!("{}/{agent}/{from}/{}", spec.name, port.replace('.', "/"));
            processes[a].publishes.insert(key.clone());
            processes[b].subscribes.insert(key);
        }
        processes.push(ProcessAccess {
            name: LAUNCHER.to_owned(),
            common_name: common_name(&spec.name, &dep.name, LAUNCHER),
            publishes: BTreeSet::new(),
            subscribes: BTreeSet::new(),
        });
        Ok(AccessPolicy {
            system: spec.name.clone(),
            deployment: dep.name.clone(),
            processes,
        })
    }

    /// What process `name` may do.
    pub fn process(&self, name: &str) -> Option<&ProcessAccess> {
        self.processes.iter().find(|p| p.name == name)
    }

    /// The `access_control` section of the Zenoh configuration of process
    /// `process` (or of the launcher, [`LAUNCHER`]): default deny; for every
    /// other process, a subject by its certificate's common name with what it
    /// may send this one and what this one may send it; the runtime's keys open
    /// to all of them.
    pub fn acl(&self, process: &str) -> Result<Value, PolicyError> {
        if self.process(process).is_none() {
            return Err(PolicyError::UnknownProcess {
                deployment: self.deployment.clone(),
                name: process.to_owned(),
                known: self
                    .processes
                    .iter()
                    .map(|p| p.name.as_str())
                    .collect::<Vec<_>>()
                    .join(", "),
            });
        }
        let runtime = format!("{}/_rt/**", self.system);
        let mut rules = vec![json!({
            "id": "runtime",
            "permission": "allow",
            "flows": ["ingress", "egress"],
            "messages": ALL_MESSAGES,
            "key_exprs": [runtime],
        })];
        // Zenoh's own interest in who matches a publisher or subscriber (no
        // data): on the deployment's link keys, between its members.
        let links: BTreeSet<&String> = self.processes.iter().flat_map(|p| &p.publishes).collect();
        let interest = !links.is_empty();
        if interest {
            rules.push(json!({
                "id": "interest",
                "permission": "allow",
                "flows": ["ingress", "egress"],
                "messages": ["declare_liveliness_subscriber"],
                "key_exprs": links,
            }));
        }
        let mut subjects = Vec::new();
        let mut policies = Vec::new();
        for other in self.processes.iter().filter(|p| p.name != process) {
            let n = &other.name;
            let mut ids = vec!["runtime".to_owned()];
            if interest && other.name != LAUNCHER {
                ids.push("interest".to_owned());
            }
            // (id, flow, message, keys): what `other` may send here, what may
            // go to it.
            let grants = [
                (format!("{n} puts"), "ingress", "put", &other.publishes),
                (
                    format!("{n} subscribes"),
                    "ingress",
                    "declare_subscriber",
                    &other.subscribes,
                ),
                (format!("puts to {n}"), "egress", "put", &other.subscribes),
                (
                    format!("subscribes at {n}"),
                    "egress",
                    "declare_subscriber",
                    &other.publishes,
                ),
            ];
            for (id, flow, message, keys) in grants {
                // Zenoh refuses a rule without keys: none to grant.
                if keys.is_empty() {
                    continue;
                }
                rules.push(json!({
                    "id": id,
                    "permission": "allow",
                    "flows": [flow],
                    "messages": [message],
                    "key_exprs": keys,
                }));
                ids.push(id);
            }
            subjects.push(json!({"id": n, "cert_common_names": [other.common_name]}));
            policies.push(json!({"id": n, "rules": ids, "subjects": [n]}));
        }
        Ok(json!({
            "enabled": true,
            "default_permission": "deny",
            "rules": rules,
            "subjects": subjects,
            "policies": policies,
        }))
    }
}

/// What a process of a secure deployment opens its session with.
#[derive(Clone, Debug, PartialEq)]
pub struct Secured {
    /// Its credentials.
    pub credentials: Credentials,
    /// Its access control ([`AccessPolicy::acl`]).
    pub acl: Value,
}

/// Where one process's credentials are: the deployment's authority (to check
/// the others), its certificate and its private key (PEM files).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Credentials {
    /// The authority's certificate.
    pub authority: std::path::PathBuf,
    /// The process's certificate (its common name says who it is:
    /// [`common_name`]).
    pub certificate: std::path::PathBuf,
    /// Its private key.
    pub key: std::path::PathBuf,
}

/// Why credentials could not be made or found.
#[derive(Debug, thiserror::Error)]
pub enum CredentialError {
    /// A certificate or key could not be made.
    #[error("making the certificate of `{what}`: {message}")]
    Make {
        /// Whose.
        what: String,
        /// rcgen's reason.
        message: String,
    },
    /// A file could not be written.
    #[error("writing {path}: {source}")]
    Write {
        /// The file.
        path: std::path::PathBuf,
        /// The OS's reason.
        source: std::io::Error,
    },
    /// No credentials were given to a process of a secure deployment.
    #[error(
        "a secure deployment needs credentials: a folder with the authority's `ca.pem` and, per process, `<process>.pem` and `<process>.key` (`rex launch` makes development ones; in code, `security::create_dev_authority`)"
    )]
    NotGiven,
    /// A file a secure process needs is not there.
    #[error(
        "{path} is missing: a secure deployment needs the authority's certificate `ca.pem` and, per process, `<process>.pem` and `<process>.key`"
    )]
    Missing {
        /// The file.
        path: std::path::PathBuf,
    },
}

impl Credentials {
    /// The credentials of `process` in `dir` (`ca.pem`, `<process>.pem`,
    /// `<process>.key`), each checked to be there.
    pub fn in_dir(dir: &std::path::Path, process: &str) -> Result<Credentials, CredentialError> {
        let c = Credentials {
            authority: dir.join("ca.pem"),
            certificate: dir.join(format!("{process}.pem")),
            key: dir.join(format!("{process}.key")),
        };
        for path in [&c.authority, &c.certificate, &c.key] {
            if !path.is_file() {
                return Err(CredentialError::Missing { path: path.clone() });
            }
        }
        Ok(c)
    }
}

/// A development certificate authority for `policy`'s deployment, written to
/// `dir`: `ca.pem` and `ca.key` (keep it; it issues no more than this), and for
/// every process and the launcher `<process>.pem` and `<process>.key`, with the
/// common name [`common_name`] and the names `hosts` (and `localhost`,
/// `127.0.0.1`) as subject alternative names. Keys are ECDSA P-256, written
/// readable by their owner only. For production, use certificates of your own
/// authority with the same common names and file names.
pub fn create_dev_authority(
    dir: &std::path::Path,
    policy: &AccessPolicy,
    hosts: &[String],
) -> Result<Vec<std::path::PathBuf>, CredentialError> {
    create_dev_authority_with(dir, policy, hosts, &[])
}

/// [`create_dev_authority`], and a certificate and key for each of `others`
/// too (`<name>.pem`, `<name>.key`, common name [`common_name`] of the
/// deployment): parties beside the deployment's processes that the same
/// authority vouches for, such as the ROS 2 side of a deployment and its
/// router (`agent_ros2::access`). A name that is also a process's (or the
/// launcher's), or given twice, is issued once.
pub fn create_dev_authority_with(
    dir: &std::path::Path,
    policy: &AccessPolicy,
    hosts: &[String],
    others: &[&str],
) -> Result<Vec<std::path::PathBuf>, CredentialError> {
    use rcgen::{
        BasicConstraints, CertificateParams, CertifiedIssuer, DnType, ExtendedKeyUsagePurpose,
        IsCa, KeyPair, KeyUsagePurpose,
    };
    let make = |what: &str| {
        let what = what.to_owned();
        move |e: rcgen::Error| CredentialError::Make {
            what: what.clone(),
            message: e.to_string(),
        }
    };
    std::fs::create_dir_all(dir).map_err(|source| CredentialError::Write {
        path: dir.to_owned(),
        source,
    })?;
    let mut written = Vec::new();
    let mut write = |name: &str, text: &str, secret: bool| -> Result<(), CredentialError> {
        let path = dir.join(name);
        write_file(&path, text, secret).map_err(|source| CredentialError::Write {
            path: path.clone(),
            source,
        })?;
        written.push(path);
        Ok(())
    };
    let ca_name = format!("{}.{} authority", policy.deployment, policy.system);
    let ca_key = KeyPair::generate().map_err(make(&ca_name))?;
    let mut ca = CertificateParams::new(Vec::<String>::new()).map_err(make(&ca_name))?;
    ca.is_ca = IsCa::Ca(BasicConstraints::Unconstrained);
    ca.distinguished_name
        .push(DnType::CommonName, ca_name.clone());
    ca.key_usages = vec![KeyUsagePurpose::KeyCertSign, KeyUsagePurpose::CrlSign];
    write("ca.key", &ca_key.serialize_pem(), true)?;
    let issuer = CertifiedIssuer::self_signed(ca, ca_key).map_err(make(&ca_name))?;
    write("ca.pem", &issuer.pem(), false)?;
    let mut names: Vec<String> = vec!["localhost".into(), "127.0.0.1".into()];
    for h in hosts {
        if !names.contains(h) {
            names.push(h.clone());
        }
    }
    // (file name, common name): the processes and the launcher, then the
    // others not among them.
    let mut subjects: Vec<(String, String)> = policy
        .processes
        .iter()
        .map(|p| (p.name.clone(), p.common_name.clone()))
        .collect();
    for name in others {
        if !subjects.iter().any(|(n, _)| n == name) {
            let cn = common_name(&policy.system, &policy.deployment, name);
            subjects.push(((*name).to_owned(), cn));
        }
    }
    for (name, cn) in &subjects {
        let key = KeyPair::generate().map_err(make(name))?;
        let mut params = CertificateParams::new(names.clone()).map_err(make(name))?;
        params
            .distinguished_name
            .push(DnType::CommonName, cn.clone());
        params.key_usages = vec![KeyUsagePurpose::DigitalSignature];
        params.extended_key_usages = vec![
            ExtendedKeyUsagePurpose::ServerAuth,
            ExtendedKeyUsagePurpose::ClientAuth,
        ];
        let cert = params.signed_by(&key, &issuer).map_err(make(name))?;
        write(&format!("{name}.pem"), &cert.pem(), false)?;
        write(&format!("{name}.key"), &key.serialize_pem(), true)?;
    }
    Ok(written)
}

/// Write `text` to `path`, readable by its owner only if `secret`.
fn write_file(path: &std::path::Path, text: &str, secret: bool) -> std::io::Result<()> {
    use std::io::Write as _;
    let mut options = std::fs::OpenOptions::new();
    options.write(true).create(true).truncate(true);
    #[cfg(unix)]
    if secret {
        use std::os::unix::fs::OpenOptionsExt as _;
        options.mode(0o600);
    }
    let _ = secret;
    options.open(path)?.write_all(text.as_bytes())
}

/// Messages the access control refused, as this process's Zenoh saw them:
/// what (`Put (ingress)`, `Declare Subscriber (ingress)`, `Put (egress)`...),
/// on which key, and how often: everything another process sent that the spec
/// forbids, and data this process sent where it must not (not the
/// declarations Zenoh offers every peer and the policy withholds). Zenoh says each refusal in a trace event of its access-control
/// module; [`Refusals::watch`] installs the process's `tracing` subscriber with
/// a layer that counts them (and nothing else: no other event is enabled).
#[derive(Clone, Debug)]
pub struct Refusals {
    counts: std::sync::Arc<std::sync::Mutex<std::collections::BTreeMap<(String, String), u64>>>,
    installed: bool,
}

/// Zenoh's module that logs access-control decisions.
const ACL_TARGET: &str = "zenoh::net::routing::interceptor::access_control";

impl Refusals {
    /// Count this process's refusals from now on. Installs the global
    /// `tracing` subscriber once per process (later calls share the count);
    /// if the program installed its own, refusals cannot be counted and
    /// [`Refusals::counting`] says so.
    pub fn watch() -> Refusals {
        use tracing_subscriber::layer::SubscriberExt as _;
        use tracing_subscriber::{Layer as _, filter};
        static SHARED: std::sync::OnceLock<Refusals> = std::sync::OnceLock::new();
        SHARED
            .get_or_init(|| {
                let counts = std::sync::Arc::new(std::sync::Mutex::new(Default::default()));
                let layer = Counter(counts.clone()).with_filter(
                    filter::Targets::new().with_target(ACL_TARGET, tracing::Level::TRACE),
                );
                let installed = tracing::subscriber::set_global_default(
                    tracing_subscriber::registry().with(layer),
                )
                .is_ok();
                Refusals { counts, installed }
            })
            .clone()
    }

    /// Whether refusals are being counted.
    pub fn counting(&self) -> bool {
        self.installed
    }

    /// The refusals so far: (what, key) and how many.
    pub fn counts(&self) -> Vec<(String, String, u64)> {
        self.counts
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .iter()
            .map(|((what, key), n)| (what.clone(), key.clone(), *n))
            .collect()
    }

    /// How many refusals so far.
    pub fn total(&self) -> u64 {
        self.counts().iter().map(|(_, _, n)| n).sum()
    }
}

thread_local! {
    /// The key whose permissions Zenoh is caching on this thread, if it is:
    /// the decisions that follow (every message kind, for every subject of
    /// the link) are not messages.
    static PRIMING: std::cell::RefCell<Option<String>> = const { std::cell::RefCell::new(None) };
}

/// The layer that counts Zenoh's refusals.
struct Counter(std::sync::Arc<std::sync::Mutex<std::collections::BTreeMap<(String, String), u64>>>);

impl<S: tracing::Subscriber> tracing_subscriber::Layer<S> for Counter {
    fn on_event(&self, event: &tracing::Event<'_>, _: tracing_subscriber::layer::Context<'_, S>) {
        struct Message(String);
        impl tracing::field::Visit for Message {
            fn record_debug(&mut self, field: &tracing::field::Field, value: &dyn std::fmt::Debug) {
                if field.name() == "message" {
                    self.0 = format!("{value:?}");
                }
            }
        }
        let mut m = Message(String::new());
        event.record(&mut m);
        // Zenoh decides every kind of message at once when a key is first
        // seen on a link (`caching permissions for `<key>` ...`, then a
        // decision per kind and per subject of the link, on this thread, in
        // the uncached form `<zid> on <subject> is (un)authorized to <what>
        // on <key>`): those are not messages. A message is decided by `Using
        // cached result: <zid> is unauthorized to <what> on <key>`, or,
        // without a cache, in the uncached form.
        if let Some(rest) = m.0.split_once("caching permissions for `").map(|(_, r)| r) {
            let key = rest.split('`').next().unwrap_or_default().to_owned();
            PRIMING.with(|p| *p.borrow_mut() = Some(key));
            return;
        }
        let cached = m.0.starts_with("Using cached result");
        let decision =
            m.0.split_once(" is unauthorized to ")
                .map(|(_, rest)| (rest, false))
                .or_else(|| {
                    m.0.split_once(" is authorized to ")
                        .map(|(_, rest)| (rest, true))
                });
        let Some((rest, allowed)) = decision else {
            return;
        };
        let Some((what, key)) = rest.rsplit_once(" on ") else {
            return;
        };
        let key = key.trim_start_matches("Some(").trim_end_matches(')');
        let priming = !cached && PRIMING.with(|p| p.borrow().as_deref() == Some(key));
        if !priming {
            PRIMING.with(|p| *p.borrow_mut() = None);
        }
        if priming || allowed {
            return;
        }
        // Zenoh offers every declaration to every peer, and the policy
        // withholds those a peer has no right to (`Declare Subscriber
        // (egress)`): that is the policy at work, not an attempt. Counted: what
        // another process sent that the spec forbids (ingress), and data this
        // process sent where it must not (egress).
        let data = ["Put ", "Delete ", "Query ", "Reply "]
            .iter()
            .any(|d| what.starts_with(d));
        if !(what.ends_with("(ingress)") || data) {
            return;
        }
        *self
            .0
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .entry((what.to_owned(), key.to_owned()))
            .or_default() += 1;
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

    use super::*;

    fn rex() -> Spec {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../specs/rex.ron");
        agent_spec::load(path, std::fs::read_to_string(path).unwrap())
            .unwrap()
            .spec
    }

    #[test]
    fn unknown_deployments_and_processes_are_named() {
        let spec = rex();
        let e = AccessPolicy::of(&spec, "nowhere").unwrap_err();
        assert!(e.to_string().contains("split_secure"), "{e}");
        let p = AccessPolicy::of(&spec, "split_secure").unwrap();
        let e = p.acl("intruder").unwrap_err();
        assert!(
            e.to_string()
                .contains("world, locomotion, vision, launcher"),
            "{e}"
        );
    }

    #[test]
    fn a_process_in_one_process_deployment_has_no_keys_and_denies_the_rest() {
        let p = AccessPolicy::of(&rex(), "simulation").unwrap();
        let rex = p.process("rex").unwrap();
        assert!(rex.publishes.is_empty() && rex.subscribes.is_empty());
        let acl = p.acl("rex").unwrap();
        assert_eq!(acl["default_permission"], "deny");
        // Only the runtime's keys, with the launcher.
        assert_eq!(acl["rules"].as_array().unwrap().len(), 1);
        assert_eq!(acl["subjects"][0]["id"], "launcher");
    }

    #[test]
    fn credentials_are_made_checked_and_their_keys_kept_secret() {
        let dir = std::env::temp_dir().join(format!("agent-zenoh-certs-{}", std::process::id()));
        let p = AccessPolicy::of(&rex(), "split_secure").unwrap();
        let files = create_dev_authority(&dir, &p, &["10.0.0.2".into()]).unwrap();
        // The authority, and a certificate and key per process and launcher.
        assert_eq!(files.len(), 2 + 2 * 4);
        let c = Credentials::in_dir(&dir, "locomotion").unwrap();
        let pem = std::fs::read_to_string(&c.certificate).unwrap();
        assert!(pem.starts_with("-----BEGIN CERTIFICATE-----"));
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt as _;
            let mode = std::fs::metadata(&c.key).unwrap().permissions().mode();
            assert_eq!(mode & 0o077, 0, "{mode:o}");
        }
        std::fs::remove_file(&c.key).unwrap();
        let e = Credentials::in_dir(&dir, "locomotion").unwrap_err();
        assert!(e.to_string().contains("locomotion.key is missing"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn others_beside_the_processes_get_certificates_of_the_same_authority() {
        let dir = std::env::temp_dir().join(format!("agent-zenoh-others-{}", std::process::id()));
        let p = AccessPolicy::of(&rex(), "split_secure").unwrap();
        // `world` is a process already: issued once.
        let files =
            create_dev_authority_with(&dir, &p, &[], &["ros2", "ros2_router", "world", "ros2"])
                .unwrap();
        assert_eq!(files.len(), 2 + 2 * 4 + 2 * 2);
        for name in ["ros2", "ros2_router", "world"] {
            let c = Credentials::in_dir(&dir, name).unwrap();
            let pem = std::fs::read_to_string(&c.certificate).unwrap();
            assert!(pem.starts_with("-----BEGIN CERTIFICATE-----"), "{name}");
        }
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
