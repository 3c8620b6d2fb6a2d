//! A secure deployment's ROS 2 side: the Zenoh router ROS 2 nodes meet at
//! (rmw_zenohd), configured from the spec with mutual TLS and an access
//! control list, so that a ROS 2 topic feeds an input buffer only where the
//! spec's `ros2` section says so, and a buffer is shown to ROS 2 only where it
//! says so.
//!
//! rmw_zenoh reads its router's Zenoh configuration from
//! `ZENOH_ROUTER_CONFIG_URI` and its nodes' from `ZENOH_SESSION_CONFIG_URI`.
//! [`router_config`] makes the router's: it listens on a TLS endpoint
//! (`tls/...`), proves itself with the certificate [`ROUTER`] of the
//! deployment's authority, asks every client for a certificate of that
//! authority (`enable_mtls`), and denies by default. Its subjects, by the
//! common name of their certificates
//! ([`agent_zenoh::security::common_name`]):
//!
//! - each process of the deployment that runs a component with a buffer on a
//!   topic (its bridge connects with the process's own certificate,
//!   [`crate::bridge::SessionOptions::tls_client`]): it may put on the topics
//!   its components publish and subscribe to the topics that feed its
//!   components;
//! - [`ROS2`], the ROS 2 side (`ros2.<deployment>.<system>`): it may put only
//!   on the topics the spec subscribes to, and subscribe only to the topics it
//!   publishes.
//!
//! What flows to a subject mirrors that (the values of the topics it
//! subscribes to, the subscriptions to the topics it puts on). Each may also
//! take part in discovery, rmw_zenoh's liveliness tokens under
//! `@ros2_lv/<domain>/**`, and, on its own topics, in what rmw_zenoh's
//! publishers and subscriptions exchange besides values (Zenoh's interest in
//! matching subscribers, and the `@adv` keys of zenoh-ext's advanced
//! publishers and subscribers: caches, history queries, miss detection).
//! Nothing else: a process with no topic, a ROS 2 node putting on a topic the
//! spec only publishes (`/rex/pose`) or on a deployment's link key
//! (`rex/a2/c2/c1/desired_plan`), a client without a certificate of the
//! authority: all refused.
//!
//! A topic's keys are `<domain>/<topic>/*/*` (rmw_zenoh's data key: the type
//! and its hash follow the topic's name, [`crate::wire::key`]): exactly that
//! topic, of any type, not the topics under it.
//!
//! The certificates come from the deployment's authority: for development,
//! [`create_dev_credentials`] makes them all beside the processes' ones
//! (`ros2.pem`, `ros2.key`, `ros2_router.pem`, `ros2_router.key`);
//! [`write_router_config`] and [`write_session_config`] then write the two
//! configurations into the same folder.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use agent_spec::model::Spec;
use agent_zenoh::security::{
    AccessPolicy, CredentialError, Credentials, PolicyError, common_name, create_dev_authority_with,
};
use serde_json::{Value, json};

/// The subject (and credential file names, `ros2.pem`, `ros2.key`) of the
/// ROS 2 side of a deployment: every ROS 2 node that connects to its router.
pub const ROS2: &str = "ros2";

/// The credential file names of the ROS 2 router (`ros2_router.pem`,
/// `ros2_router.key`).
pub const ROUTER: &str = "ros2_router";

/// The file [`write_router_config`] writes: rmw_zenohd's configuration
/// (`ZENOH_ROUTER_CONFIG_URI`).
pub const ROUTER_CONFIG: &str = "ros2_router.json5";

/// The file [`write_session_config`] writes: the ROS 2 nodes' configuration
/// (`ZENOH_SESSION_CONFIG_URI`).
pub const SESSION_CONFIG: &str = "ros2_session.json5";

/// What one subject of the router may do: the topics (fully qualified,
/// `/rex/plan`) it may put on and subscribe to.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SubjectAccess {
    /// A process's name, or [`ROS2`].
    pub name: String,
    /// The common name of its certificate.
    pub common_name: String,
    /// The topics it may put on.
    pub puts: BTreeSet<String>,
    /// The topics it may subscribe to.
    pub subscribes: BTreeSet<String>,
}

/// Who may do what at a deployment's ROS 2 router (see the module's
/// documentation).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct RouterAccess {
    /// The system.
    pub system: String,
    /// The deployment.
    pub deployment: String,
    /// The ROS domain (`ROS_DOMAIN_ID`), the first chunk of every key.
    pub domain: u32,
    /// The processes with a topic, in the spec's order, then [`ROS2`].
    pub subjects: Vec<SubjectAccess>,
}

/// Why a router's access or configuration could not be made.
#[derive(Debug, thiserror::Error)]
pub enum AccessError {
    /// No such deployment.
    #[error(transparent)]
    Policy(#[from] PolicyError),
    /// Neither the deployment nor the system has a `ros2` section.
    #[error(
        "deployment `{deployment}` shows nothing to ROS 2: neither it nor the system has a `ros2` section"
    )]
    NoRos2 {
        /// The deployment.
        deployment: String,
    },
    /// A process has the name of the ROS 2 side's or router's credentials.
    #[error(
        "deployment `{deployment}` has a process named `{name}`, the name of the ROS 2 side's credentials (`{ROS2}`, `{ROUTER}`): rename the process"
    )]
    NameTaken {
        /// The deployment.
        deployment: String,
        /// The name.
        name: String,
    },
    /// The deployment is unprotected: its router has no certificates.
    #[error(
        "deployment `{deployment}` is unprotected (`secure: false`): its ROS 2 router has no certificates to check (run rmw_zenohd as it comes)"
    )]
    NotSecure {
        /// The deployment.
        deployment: String,
    },
    /// A credential is missing, or could not be made.
    #[error(transparent)]
    Credentials(#[from] CredentialError),
    /// A configuration could not be written.
    #[error("writing {path}: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// The OS's reason.
        source: std::io::Error,
    },
}

/// Zenoh's messages of discovery: liveliness tokens, their subscribers and
/// queries.
const DISCOVERY: [&str; 3] = [
    "liveliness_token",
    "declare_liveliness_subscriber",
    "liveliness_query",
];

/// A rule of a subject: its id, flows, messages and keys.
type Grant<'a> = (String, &'a [&'a str], &'a [&'a str], Vec<String>);

impl RouterAccess {
    /// The access at the ROS 2 router of `deployment` of `spec` (a spec the
    /// checker passed): the deployment's `ros2` section (else the system's),
    /// each topic given to the process that runs its component.
    pub fn of(spec: &Spec, deployment: &str) -> Result<RouterAccess, AccessError> {
        // The policy says which deployments there are, and names them.
        AccessPolicy::of(spec, deployment)?;
        let dep = spec
            .deployment(deployment)
            .ok_or_else(|| PolicyError::UnknownDeployment {
                spec: spec.name.clone(),
                name: deployment.to_owned(),
                known: spec.deployment_names(),
            })?;
        let interface =
            agent_spec::ros2::interface(spec, Some(dep)).ok_or_else(|| AccessError::NoRos2 {
                deployment: dep.name.clone(),
            })?;
        let placed = dep.processes();
        if let Some((_, p, _)) = placed
            .iter()
            .find(|(_, p, _)| p.name == ROS2 || p.name == ROUTER)
        {
            return Err(AccessError::NameTaken {
                deployment: dep.name.clone(),
                name: p.name.clone(),
            });
        }
        let mut subjects: Vec<SubjectAccess> = placed
            .iter()
            .map(|(_, p, _)| SubjectAccess {
                name: p.name.clone(),
                common_name: common_name(&spec.name, &dep.name, &p.name),
                puts: BTreeSet::new(),
                subscribes: BTreeSet::new(),
            })
            .collect();
        let mut ros2 = SubjectAccess {
            name: ROS2.to_owned(),
            common_name: common_name(&spec.name, &dep.name, ROS2),
            puts: BTreeSet::new(),
            subscribes: BTreeSet::new(),
        };
        let process_of = |component: &str| {
            placed
                .iter()
                .position(|(_, p, _)| p.runs.iter().any(|r| r == component))
        };
        for topic in &interface.publish {
            if let Some(k) = process_of(&topic.component) {
                subjects[k].puts.insert(topic.name.clone());
                ros2.subscribes.insert(topic.name.clone());
            }
        }
        for topic in &interface.subscribe {
            if let Some(k) = process_of(&topic.component) {
                subjects[k].subscribes.insert(topic.name.clone());
                ros2.puts.insert(topic.name.clone());
            }
        }
        subjects.retain(|s| !(s.puts.is_empty() && s.subscribes.is_empty()));
        subjects.push(ros2);
        Ok(RouterAccess {
            system: spec.name.clone(),
            deployment: dep.name.clone(),
            domain: interface.domain,
            subjects,
        })
    }

    /// What subject `name` (a process, or [`ROS2`]) may do; `None` for a
    /// process with no topic, which may do nothing.
    pub fn subject(&self, name: &str) -> Option<&SubjectAccess> {
        self.subjects.iter().find(|s| s.name == name)
    }

    /// The keys of the values of `topic` (`/rex/plan`): `0/rex/plan/*/*`.
    pub fn data_key(&self, topic: &str) -> String {
        format!("{}/{}/*/*", self.domain, topic.trim_start_matches('/'))
    }

    /// The keys of what zenoh-ext's advanced publishers and subscribers of
    /// `topic` exchange besides values: `0/rex/plan/*/*/@adv/**`.
    pub fn advanced_key(&self, topic: &str) -> String {
        format!("{}/@adv/**", self.data_key(topic))
    }

    /// The keys of discovery: `@ros2_lv/<domain>/**`.
    pub fn discovery_key(&self) -> String {
        crate::wire::token::liveliness_subscriber_key(self.domain)
    }

    /// The router's `access_control` section: default deny; a subject per
    /// entry of [`RouterAccess::subjects`] by its certificate's common name,
    /// with what it may send the router and what the router may send it.
    pub fn acl(&self) -> Value {
        let mut rules = vec![json!({
            "id": "discovery",
            "permission": "allow",
            "flows": ["ingress", "egress"],
            "messages": DISCOVERY,
            "key_exprs": [self.discovery_key()],
        })];
        let mut subjects = Vec::new();
        let mut policies = Vec::new();
        for s in &self.subjects {
            let n = &s.name;
            let data = |topics: &BTreeSet<String>| -> Vec<String> {
                topics.iter().map(|t| self.data_key(t)).collect()
            };
            let advanced = |topics: &BTreeSet<String>| -> Vec<String> {
                topics.iter().map(|t| self.advanced_key(t)).collect()
            };
            let all: BTreeSet<String> = s.puts.union(&s.subscribes).cloned().collect();
            // (id, flows, messages, keys): what `s` may send the router, what
            // the router may send it.
            let grants: [Grant<'_>; 10] = [
                (format!("{n} puts"), &["ingress"], &["put"], data(&s.puts)),
                (
                    format!("{n} subscribes"),
                    &["ingress"],
                    &["declare_subscriber"],
                    data(&s.subscribes),
                ),
                (
                    format!("puts to {n}"),
                    &["egress"],
                    &["put"],
                    data(&s.subscribes),
                ),
                (
                    format!("subscriptions to {n}"),
                    &["egress"],
                    &["declare_subscriber"],
                    data(&s.puts),
                ),
                // Zenoh's interest in who matches a publisher or subscriber.
                (
                    format!("{n} matches"),
                    &["ingress", "egress"],
                    &["declare_liveliness_subscriber"],
                    data(&all),
                ),
                (
                    format!("{n} advanced"),
                    &["ingress", "egress"],
                    &DISCOVERY[..],
                    advanced(&all),
                ),
                // A publisher's cache answers the history queries of the
                // topic's subscribers.
                (
                    format!("{n} caches"),
                    &["ingress"],
                    &["declare_queryable", "reply"],
                    advanced(&s.puts),
                ),
                (
                    format!("queries to {n}"),
                    &["egress"],
                    &["query"],
                    advanced(&s.puts),
                ),
                (
                    format!("{n} asks"),
                    &["ingress"],
                    &["query"],
                    advanced(&s.subscribes),
                ),
                (
                    format!("answers to {n}"),
                    &["egress"],
                    &["declare_queryable", "reply"],
                    advanced(&s.subscribes),
                ),
            ];
            let mut ids = vec!["discovery".to_owned()];
            for (id, flows, messages, keys) in grants {
                // Zenoh refuses a rule without keys: none to grant.
                if keys.is_empty() {
                    continue;
                }
                rules.push(json!({
                    "id": id,
                    "permission": "allow",
                    "flows": flows,
                    "messages": messages,
                    "key_exprs": keys,
                }));
                ids.push(id);
            }
            subjects.push(json!({"id": n, "cert_common_names": [s.common_name]}));
            policies.push(json!({"id": n, "rules": ids, "subjects": [n]}));
        }
        json!({
            "enabled": true,
            "default_permission": "deny",
            "rules": rules,
            "subjects": subjects,
            "policies": policies,
        })
    }
}

/// A path as Zenoh's configuration takes it.
fn path_text(path: &Path) -> String {
    path.display().to_string()
}

/// The ROS 2 router's Zenoh configuration: a router listening on `listen`
/// (`tls/localhost:7447`; a `quic/` endpoint takes the same settings), with
/// the authority, certificate and key of `credentials` (the router's,
/// [`ROUTER`]), mutual TLS, no multicast scouting, and `access`'s
/// [`RouterAccess::acl`].
pub fn router_config(access: &RouterAccess, listen: &str, credentials: &Credentials) -> Value {
    json!({
        "mode": "router",
        "listen": {"endpoints": [listen]},
        "connect": {"endpoints": []},
        "scouting": {"multicast": {"enabled": false}},
        "transport": {"link": {"tls": {
            "root_ca_certificate": path_text(&credentials.authority),
            "listen_certificate": path_text(&credentials.certificate),
            "listen_private_key": path_text(&credentials.key),
            "enable_mtls": true,
            "verify_name_on_connect": true,
        }}},
        "access_control": access.acl(),
    })
}

/// A ROS 2 node's Zenoh configuration: a client of the router at `connect`
/// (`tls/localhost:7447`), proving itself with `credentials` (the ROS 2
/// side's, [`ROS2`]), no multicast scouting. A client, not rmw_zenoh's
/// default peer: everything it sends goes through the router's access
/// control.
pub fn session_config(connect: &str, credentials: &Credentials) -> Value {
    json!({
        "mode": "client",
        "connect": {"endpoints": [connect]},
        "listen": {"endpoints": []},
        "scouting": {"multicast": {"enabled": false}},
        "transport": {"link": {"tls": {
            "root_ca_certificate": path_text(&credentials.authority),
            "connect_certificate": path_text(&credentials.certificate),
            "connect_private_key": path_text(&credentials.key),
            "enable_mtls": true,
            "verify_name_on_connect": true,
        }}},
    })
}

/// Development credentials for `deployment` of `spec` in `dir`: the
/// authority and every process's (as
/// [`agent_zenoh::security::create_dev_authority`] makes them), and the ROS
/// 2 side's and router's ([`ROS2`], [`ROUTER`]), all with the names `hosts`
/// (and `localhost`, `127.0.0.1`). The files written.
pub fn create_dev_credentials(
    dir: &Path,
    spec: &Spec,
    deployment: &str,
    hosts: &[String],
) -> Result<Vec<PathBuf>, AccessError> {
    let access = RouterAccess::of(spec, deployment)?;
    let policy = AccessPolicy::of(spec, &access.deployment)?;
    Ok(create_dev_authority_with(
        dir,
        &policy,
        hosts,
        &[ROS2, ROUTER],
    )?)
}

/// Write the ROS 2 router's configuration ([`router_config`]) of secure
/// `deployment` of `spec`, listening on `listen`, to [`ROUTER_CONFIG`] in
/// `dir`, the deployment's credentials folder (which must hold `ca.pem`,
/// `ros2_router.pem` and `ros2_router.key`: [`create_dev_credentials`]).
/// Start rmw_zenohd with `ZENOH_ROUTER_CONFIG_URI=<the file>`. Returns the
/// file.
pub fn write_router_config(
    dir: &Path,
    spec: &Spec,
    deployment: &str,
    listen: &str,
) -> Result<PathBuf, AccessError> {
    let access = RouterAccess::of(spec, deployment)?;
    let secure = spec
        .deployment(&access.deployment)
        .is_some_and(agent_spec::model::Deployment::is_secure);
    if !secure {
        return Err(AccessError::NotSecure {
            deployment: access.deployment,
        });
    }
    let credentials = Credentials::in_dir(dir, ROUTER)?;
    write_json(
        &dir.join(ROUTER_CONFIG),
        &router_config(&access, listen, &credentials),
    )
}

/// Write the ROS 2 nodes' configuration ([`session_config`]), connecting to
/// the router at `connect`, to [`SESSION_CONFIG`] in `dir`, the deployment's
/// credentials folder (which must hold `ca.pem`, `ros2.pem` and `ros2.key`).
/// Start each ROS 2 node with `ZENOH_SESSION_CONFIG_URI=<the file>`. Returns
/// the file.
pub fn write_session_config(dir: &Path, connect: &str) -> Result<PathBuf, AccessError> {
    let credentials = Credentials::in_dir(dir, ROS2)?;
    write_json(
        &dir.join(SESSION_CONFIG),
        &session_config(connect, &credentials),
    )
}

/// Write `value` to `path` (JSON is JSON5).
fn write_json(path: &Path, value: &Value) -> Result<PathBuf, AccessError> {
    let text = serde_json::to_string_pretty(value).unwrap_or_else(|_| value.to_string());
    std::fs::write(path, text + "\n").map_err(|source| AccessError::Write {
        path: path.to_owned(),
        source,
    })?;
    Ok(path.to_owned())
}

#[cfg(test)]
mod tests {
    #![allow(
        clippy::unwrap_used,
        clippy::expect_used,
        reason = "a failing unwrap is a failing test"
    )]

    use super::*;

    fn rex() -> Spec {
        let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../specs/rex.ron");
        agent_spec::load(path, std::fs::read_to_string(path).unwrap())
            .unwrap()
            .spec
    }

    fn set(items: &[&str]) -> BTreeSet<String> {
        items.iter().map(|s| (*s).to_owned()).collect()
    }

    /// Whether key expression `pattern` matches the key `key`: `*` one chunk,
    /// `**` any number, neither a chunk starting with `@` (Zenoh's verbatim
    /// chunks).
    fn matches(pattern: &[&str], key: &[&str]) -> bool {
        match (pattern.first(), key.first()) {
            (None, None) => true,
            (Some(&"**"), _) => {
                matches(&pattern[1..], key)
                    || key
                        .first()
                        .is_some_and(|k| !k.starts_with('@') && matches(pattern, &key[1..]))
            }
            (Some(&"*"), Some(k)) => !k.starts_with('@') && matches(&pattern[1..], &key[1..]),
            (Some(p), Some(k)) => p == k && matches(&pattern[1..], &key[1..]),
            _ => false,
        }
    }

    /// What `acl` decides for `message` in `flow` on `key` of the subject
    /// whose certificate's common name is `cn` (default deny).
    fn allowed(acl: &Value, cn: &str, flow: &str, message: &str, key: &str) -> bool {
        assert_eq!(acl["default_permission"], "deny");
        let has = |v: &Value, s: &str| v.as_array().unwrap().iter().any(|x| x == s);
        let key: Vec<&str> = key.split('/').collect();
        let Some(subject) = acl["subjects"]
            .as_array()
            .unwrap()
            .iter()
            .find(|s| has(&s["cert_common_names"], cn))
        else {
            return false;
        };
        let id = subject["id"].as_str().unwrap();
        acl["policies"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|p| has(&p["subjects"], id))
            .flat_map(|p| p["rules"].as_array().unwrap())
            .map(|r| {
                acl["rules"]
                    .as_array()
                    .unwrap()
                    .iter()
                    .find(|rule| rule["id"] == *r)
                    .expect("a policy names a rule that exists")
            })
            .any(|rule| {
                rule["permission"] == "allow"
                    && has(&rule["flows"], flow)
                    && has(&rule["messages"], message)
                    && rule["key_exprs"].as_array().unwrap().iter().any(|k| {
                        let pattern: Vec<&str> = k.as_str().unwrap().split('/').collect();
                        matches(&pattern, &key)
                    })
            })
    }

    const PLAN: &str = "0/rex/plan/rex_msgs::msg::dds_::Plan_/RIHS01_00ff";
    const POSE: &str = "0/rex/pose/geometry_msgs::msg::dds_::PoseStamped_/RIHS01_00ff";
    const ESTIMATE: &str = "0/rex/estimate/rex_msgs::msg::dds_::Estimate_/RIHS01_00ff";
    const LINK: &str = "rex/a2/c2/c1/desired_plan";

    fn cn(process: &str) -> String {
        common_name("rex", "split_secure", process)
    }

    #[test]
    fn each_process_may_use_the_topics_of_its_components_and_ros_2_the_rest() {
        let access = RouterAccess::of(&rex(), "split_secure").unwrap();
        assert_eq!(access.domain, 0);
        let names: Vec<&str> = access.subjects.iter().map(|s| s.name.as_str()).collect();
        // `vision` runs r11, which has no topic: not a subject.
        assert_eq!(names, ["world", "locomotion", ROS2]);
        let world = access.subject("world").unwrap();
        assert_eq!(world.common_name, "world.split_secure.rex");
        assert_eq!(
            world.puts,
            set(&["/rex/pose", "/rex/imu", "/rex/camera/image/compressed"])
        );
        assert!(world.subscribes.is_empty());
        let locomotion = access.subject("locomotion").unwrap();
        assert_eq!(
            locomotion.puts,
            set(&[
                "/rex/estimate",
                "/rex/reference_path",
                "/rex/ack",
                "/rex/outcome"
            ])
        );
        assert_eq!(locomotion.subscribes, set(&["/rex/plan"]));
        let ros2 = access.subject(ROS2).unwrap();
        assert_eq!(ros2.common_name, "ros2.split_secure.rex");
        assert_eq!(ros2.puts, set(&["/rex/plan"]));
        let published: BTreeSet<String> = world.puts.union(&locomotion.puts).cloned().collect();
        assert_eq!(ros2.subscribes, published);
        assert!(access.subject("vision").is_none());
        assert_eq!(access.data_key("/rex/plan"), "0/rex/plan/*/*");
    }

    #[test]
    fn the_acl_lets_ros_2_feed_only_the_subscribed_topic() {
        let acl = RouterAccess::of(&rex(), "split_secure").unwrap().acl();
        let ros2 = cn(ROS2);
        // What the ROS 2 side may send: values of /rex/plan, subscriptions to
        // what the spec publishes.
        assert!(allowed(&acl, &ros2, "ingress", "put", PLAN));
        assert!(allowed(&acl, &ros2, "ingress", "declare_subscriber", POSE));
        for refused in [
            POSE,
            ESTIMATE,
            LINK,
            "rex/_rt/launch/stop",
            // Not the topics under a subscribed one.
            "0/rex/plan/more/rex_msgs::msg::dds_::Plan_/RIHS01_00ff",
            // Nor the same topic in another domain.
            "1/rex/plan/rex_msgs::msg::dds_::Plan_/RIHS01_00ff",
        ] {
            assert!(
                !allowed(&acl, &ros2, "ingress", "put", refused),
                "{refused}"
            );
        }
        assert!(!allowed(&acl, &ros2, "ingress", "declare_subscriber", PLAN));
        assert!(!allowed(&acl, &ros2, "ingress", "declare_subscriber", LINK));
        assert!(!allowed(&acl, &ros2, "ingress", "delete", PLAN));
        // What reaches it: the published values, not the plans.
        assert!(allowed(&acl, &ros2, "egress", "put", POSE));
        assert!(allowed(&acl, &ros2, "egress", "put", ESTIMATE));
        assert!(!allowed(&acl, &ros2, "egress", "put", PLAN));
        assert!(!allowed(&acl, &ros2, "egress", "put", LINK));
    }

    #[test]
    fn the_acl_lets_each_process_use_only_its_own_topics() {
        let acl = RouterAccess::of(&rex(), "split_secure").unwrap().acl();
        let (world, locomotion) = (cn("world"), cn("locomotion"));
        assert!(allowed(
            &acl,
            &locomotion,
            "ingress",
            "declare_subscriber",
            PLAN
        ));
        assert!(allowed(&acl, &locomotion, "egress", "put", PLAN));
        assert!(allowed(&acl, &locomotion, "ingress", "put", ESTIMATE));
        // The pose is c3's, in the world.
        assert!(!allowed(&acl, &locomotion, "ingress", "put", POSE));
        assert!(allowed(&acl, &world, "ingress", "put", POSE));
        assert!(!allowed(&acl, &locomotion, "ingress", "put", PLAN));
        assert!(!allowed(
            &acl,
            &world,
            "ingress",
            "declare_subscriber",
            PLAN
        ));
        assert!(!allowed(&acl, &world, "egress", "put", PLAN));
        for p in [&world, &locomotion] {
            assert!(!allowed(&acl, p, "ingress", "put", LINK));
            assert!(!allowed(&acl, p, "ingress", "declare_subscriber", LINK));
        }
        // vision has no topic, the launcher and strangers no subject.
        for nobody in [cn("vision"), cn("launcher"), "intruder".to_owned()] {
            for (flow, message, key) in [
                ("ingress", "put", PLAN),
                ("ingress", "declare_subscriber", POSE),
                (
                    "ingress",
                    "liveliness_token",
                    "@ros2_lv/0/1a/0/0/NN/%/%/rex",
                ),
            ] {
                assert!(!allowed(&acl, &nobody, flow, message, key), "{nobody}");
            }
        }
    }

    #[test]
    fn discovery_and_rmw_zenohs_advanced_keys_are_open_on_ones_own_topics() {
        let acl = RouterAccess::of(&rex(), "split_secure").unwrap().acl();
        let (ros2, locomotion) = (cn(ROS2), cn("locomotion"));
        let token = "@ros2_lv/0/1a/0/1/MS/%/%/rex/%rex%plan/rex_msgs::msg::dds_::Plan_/RIHS01_00ff/::,10:,:,:,,";
        for s in [&ros2, &locomotion] {
            for message in DISCOVERY {
                assert!(allowed(&acl, s, "ingress", message, token), "{s} {message}");
                assert!(allowed(&acl, s, "egress", message, token), "{s} {message}");
            }
            assert!(!allowed(
                &acl,
                s,
                "ingress",
                "liveliness_token",
                "@ros2_lv/1/x"
            ));
            assert!(!allowed(&acl, s, "ingress", "put", token));
        }
        let adv = |key: &str| format!("{key}/@adv/pub/1a/7/_");
        // The ROS 2 side publishes plans: its cache may answer, the
        // subscribers' history queries reach it.
        assert!(allowed(
            &acl,
            &ros2,
            "ingress",
            "declare_queryable",
            &adv(PLAN)
        ));
        assert!(allowed(&acl, &ros2, "ingress", "reply", &adv(PLAN)));
        assert!(allowed(&acl, &ros2, "egress", "query", &adv(PLAN)));
        assert!(allowed(&acl, &locomotion, "ingress", "query", &adv(PLAN)));
        assert!(!allowed(&acl, &locomotion, "ingress", "reply", &adv(PLAN)));
        // Nobody answers for the pose but its publisher.
        assert!(!allowed(&acl, &ros2, "ingress", "reply", &adv(POSE)));
        assert!(allowed(&acl, &ros2, "ingress", "query", &adv(POSE)));
        assert!(allowed(&acl, &cn("world"), "ingress", "reply", &adv(POSE)));
    }

    #[test]
    fn unknown_deployments_sections_and_taken_names_are_refused() {
        let spec = rex();
        let e = RouterAccess::of(&spec, "nowhere").unwrap_err();
        assert!(matches!(e, AccessError::Policy(_)), "{e}");
        assert!(e.to_string().contains("split_secure"), "{e}");
        let mut bare = spec.clone();
        bare.ros2 = None;
        for d in &mut bare.deployments {
            d.ros2 = None;
        }
        let e = RouterAccess::of(&bare, "split_secure").unwrap_err();
        assert!(e.to_string().contains("shows nothing to ROS 2"), "{e}");
        let mut taken = spec.clone();
        let dep = taken
            .deployments
            .iter_mut()
            .find(|d| d.name == "split_secure")
            .unwrap();
        dep.hosts[0].processes[2].name = ROS2.to_owned();
        let e = RouterAccess::of(&taken, "split_secure").unwrap_err();
        assert!(
            matches!(&e, AccessError::NameTaken { name, .. } if name == ROS2),
            "{e}"
        );
    }

    #[test]
    fn the_configurations_are_written_with_the_credentials_and_zenoh_opens_the_router() {
        let spec = rex();
        let dir = std::env::temp_dir().join(format!("agent-ros2-access-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        // No credentials yet: said, naming the file.
        let e = write_router_config(&dir, &spec, "split_secure", "tls/127.0.0.1:0").unwrap_err();
        assert!(e.to_string().contains("ca.pem is missing"), "{e}");
        let files = create_dev_credentials(&dir, &spec, "split_secure", &[]).unwrap();
        // The authority, the 3 processes and the launcher, ROS 2 and its router.
        assert_eq!(files.len(), 2 + 2 * 6);
        let e = write_router_config(&dir, &spec, "split", "tls/127.0.0.1:0").unwrap_err();
        assert!(matches!(e, AccessError::NotSecure { .. }), "{e}");

        let path = write_router_config(&dir, &spec, "split_secure", "tls/127.0.0.1:0").unwrap();
        assert_eq!(path, dir.join(ROUTER_CONFIG));
        let config: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        assert_eq!(config["mode"], "router");
        assert_eq!(config["listen"]["endpoints"], json!(["tls/127.0.0.1:0"]));
        let tls = &config["transport"]["link"]["tls"];
        assert_eq!(tls["enable_mtls"], true);
        for (field, file) in [
            ("root_ca_certificate", "ca.pem"),
            ("listen_certificate", "ros2_router.pem"),
            ("listen_private_key", "ros2_router.key"),
        ] {
            assert_eq!(tls[field], path_text(&dir.join(file)), "{field}");
        }
        let access = RouterAccess::of(&spec, "split_secure").unwrap();
        assert_eq!(config["access_control"], access.acl());
        // Zenoh takes it, access control and all, and listens.
        let zenoh_config = zenoh::Config::from_file(&path).unwrap();
        let router = zenoh::Wait::wait(zenoh::open(zenoh_config)).unwrap();
        zenoh::Wait::wait(router.close()).unwrap();

        let path = write_session_config(&dir, "tls/localhost:7447").unwrap();
        let config: Value = serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap();
        assert_eq!(config["mode"], "client");
        assert_eq!(
            config["connect"]["endpoints"],
            json!(["tls/localhost:7447"])
        );
        let tls = &config["transport"]["link"]["tls"];
        assert_eq!(tls["connect_certificate"], path_text(&dir.join("ros2.pem")));
        assert_eq!(tls["connect_private_key"], path_text(&dir.join("ros2.key")));
        assert!(zenoh::Config::from_file(&path).is_ok());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
