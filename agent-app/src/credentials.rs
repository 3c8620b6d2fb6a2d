//! `credentials --deployment D DIR [--ros2-listen ENDPOINT]`: the development
//! credentials of a secure deployment, made once and kept, for launches that
//! others must know the certificates of (a ROS 2 router's access control):
//!
//! - a development authority (`ca.pem`, `ca.key`) and, for every process of
//!   the deployment and the launcher, `<process>.pem` and `<process>.key`
//!   (what `launch` makes for one launch when given no `--credentials`);
//! - when the deployment (or the system) has a `ros2` section, the ROS 2
//!   side's too: the certificate of the ROS 2 nodes (`ros2.pem`, `ros2.key`)
//!   and of their router (`ros2_router.pem`, `ros2_router.key`), the router's
//!   Zenoh configuration (`ros2_router.json5`: listening on ENDPOINT, mutual
//!   TLS, the access control generated from the spec) and the nodes'
//!   (`ros2_session.json5`: clients of that router).
//!
//! It prints the files written, then what to type next. It never overwrites
//! an authority: a folder that holds one is refused.

use std::path::Path;

use crate::error::{AppError, Status};
use crate::{Application, Common};

/// Where the ROS 2 router listens when `--ros2-listen` is not given.
pub const ROS2_LISTEN: &str = "tls/localhost:7447";

/// The authority's files: their presence in DIR means DIR holds credentials
/// already.
#[cfg_attr(
    not(feature = "distributed"),
    allow(dead_code, reason = "checked only where credentials are made")
)]
const AUTHORITY: [&str; 2] = ["ca.pem", "ca.key"];

/// `credentials DIR`: make the development credentials of `--deployment` in
/// `dir` (and the ROS 2 side's, its router listening on `listen`, default
/// [`ROS2_LISTEN`]).
#[cfg(feature = "distributed")]
pub(crate) fn credentials<A: Application>(
    app: &mut A,
    config: &A::Config,
    common: &Common,
    dir: &Path,
    listen: Option<&str>,
) -> Result<Status, AppError> {
    let spec = app.spec(config)?;
    let spec = &spec.spec;
    let shown = dir.display();
    let invalid =
        |why: &dyn std::fmt::Display| AppError::invalid(format!("credentials {shown}: {why}"));
    let Some(deployment) = common.deployment.as_deref() else {
        return Err(invalid(&format_args!(
            "give the deployment: `--deployment NAME` (the spec's deployments: {})",
            spec.deployment_names()
        )));
    };
    let Some(dep) = spec.deployment(deployment) else {
        return Err(invalid(&format_args!(
            "spec `{}` has no deployment `{deployment}` (it has: {})",
            spec.name,
            spec.deployment_names()
        )));
    };
    if !dep.is_secure() {
        return Err(invalid(&format_args!(
            "deployment `{deployment}` is unprotected (`secure: false` in the spec): it takes no credentials"
        )));
    }
    let section = agent_spec::ros2::section(spec, Some(dep));
    let listen = match (listen, section) {
        (Some(l), None) => {
            return Err(invalid(&format_args!(
                "--ros2-listen {l}: deployment `{deployment}` shows nothing to ROS 2 (neither it nor the system has a `ros2` section)"
            )));
        }
        (Some(l), Some(_)) => l,
        (None, _) => ROS2_LISTEN,
    };
    let (connect, listen_host) =
        endpoints(listen).map_err(|why| invalid(&format_args!("--ros2-listen {listen}: {why}")))?;
    if let Some(held) = AUTHORITY.iter().map(|f| dir.join(f)).find(|p| p.exists()) {
        return Err(invalid(&format_args!(
            "{} exists: the folder holds an authority already, and its keys are never overwritten (choose an empty folder, or remove it)",
            held.display()
        )));
    }
    if dir.exists() && !dir.is_dir() {
        return Err(invalid(&"not a folder"));
    }
    // Absolute, so that the configurations and the commands said work from
    // any folder.
    let dir = std::path::absolute(dir).map_err(|e| invalid(&e))?;
    let mut hosts: Vec<String> = dep.hosts.iter().filter_map(|h| h.address.clone()).collect();
    if section.is_some() && !hosts.contains(&listen_host) {
        // The router's certificate must bear the name its clients reach it at.
        hosts.push(listen_host);
    }
    let program = crate::output::program();
    #[cfg(feature = "ros2")]
    if let Some(section) = section {
        return ros2_side(
            spec, deployment, section, &dir, &hosts, listen, &connect, &program,
        );
    }
    #[cfg(not(feature = "ros2"))]
    let _ = (&connect, listen);
    let policy =
        agent_zenoh::security::AccessPolicy::of(spec, deployment).map_err(|e| invalid(&e))?;
    let written = agent_zenoh::security::create_dev_authority(&dir, &policy, &hosts)
        .map_err(|e| AppError::Run(format!("credentials {shown}: {e}")))?;
    say_written(&written);
    if section.is_some() {
        crate::output::warn(format_args!(
            "deployment `{deployment}` has a `ros2` section, and this program is built without the feature `ros2`: no credentials for its ROS 2 side"
        ));
    }
    crate::output::out(format_args!(
        "\nnext:\n  {program} launch --deployment {deployment} --credentials {}\n",
        dir.display()
    ));
    Ok(Status::Success)
}

/// Without deployments, no credentials.
#[cfg(not(feature = "distributed"))]
pub(crate) fn credentials<A: Application>(
    _app: &mut A,
    _config: &A::Config,
    _common: &Common,
    dir: &Path,
    _listen: Option<&str>,
) -> Result<Status, AppError> {
    Err(AppError::invalid(format!(
        "credentials {}: built without the feature `distributed`: no deployments over Zenoh",
        dir.display()
    )))
}

/// The endpoint ROS 2 nodes and the bridges connect to for a router listening
/// on `listen` (a `tls/HOST:PORT`; a wildcard host is reached at
/// `localhost`), and the host the router's certificate must name.
#[cfg_attr(
    not(feature = "distributed"),
    allow(dead_code, reason = "checked only where credentials are made")
)]
fn endpoints(listen: &str) -> Result<(String, String), String> {
    let Some(address) = listen.strip_prefix("tls/") else {
        return Err(
            "the ROS 2 router of a secure deployment listens over mutual TLS: give a tls/HOST:PORT endpoint".into(),
        );
    };
    let Some((host, port)) = address.rsplit_once(':') else {
        return Err("expected tls/HOST:PORT".into());
    };
    if host.is_empty() || port.parse::<u16>().map_or(true, |p| p == 0) {
        return Err("expected tls/HOST:PORT, with a port of 1-65535".into());
    }
    let host = host.trim_start_matches('[').trim_end_matches(']');
    let reached = match host {
        "0.0.0.0" | "::" => "localhost",
        h => h,
    };
    let connect = if reached.contains(':') {
        format!("tls/[{reached}]:{port}")
    } else {
        format!("tls/{reached}:{port}")
    };
    Ok((connect, reached.to_owned()))
}

/// Make the deployment's credentials with the ROS 2 side's, and the
/// router's and nodes' configurations; say the files and what to type next
/// (with `program`).
#[cfg(all(feature = "distributed", feature = "ros2"))]
#[allow(clippy::too_many_arguments, reason = "the command's parts, checked")]
fn ros2_side(
    spec: &agent_spec::Spec,
    deployment: &str,
    section: &agent_spec::model::Ros2,
    dir: &Path,
    hosts: &[String],
    listen: &str,
    connect: &str,
    program: &str,
) -> Result<Status, AppError> {
    use agent_ros2::access::{
        ROUTER_CONFIG, RouterAccess, SESSION_CONFIG, create_dev_credentials, write_router_config,
        write_session_config,
    };
    let shown = dir.display();
    // What the spec cannot give (a process named as the ROS 2 side), before
    // anything is written.
    RouterAccess::of(spec, deployment)
        .map_err(|e| AppError::invalid(format!("credentials {shown}: {e}")))?;
    let failed = |e: &dyn std::fmt::Display| AppError::Run(format!("credentials {shown}: {e}"));
    let mut written =
        create_dev_credentials(dir, spec, deployment, hosts).map_err(|e| failed(&e))?;
    written.push(write_router_config(dir, spec, deployment, listen).map_err(|e| failed(&e))?);
    written.push(write_session_config(dir, connect).map_err(|e| failed(&e))?);
    say_written(&written);
    let node = agent_spec::ros2::node_of(spec, section);
    let namespace = agent_spec::ros2::namespace_of(section);
    let topic = section.publish.first().map_or_else(
        || "/parameter_events".to_owned(),
        |t| agent_spec::ros2::expand_topic(&t.topic, node, namespace),
    );
    crate::output::out(format_args!(
        "\nnext:\n  \
         # the ROS 2 router (rmw_zenohd), listening on {listen}:\n  \
         ZENOH_ROUTER_CONFIG_URI={shown}/{ROUTER_CONFIG} ros2 run rmw_zenoh_cpp rmw_zenohd\n  \
         # the deployment, its bridges reaching that router:\n  \
         {program} launch --deployment {deployment} --credentials {shown} --ros2={connect}\n  \
         # any ROS 2 node, with the ROS 2 side's certificate:\n  \
         ZENOH_SESSION_CONFIG_URI={shown}/{SESSION_CONFIG} RMW_IMPLEMENTATION=rmw_zenoh_cpp ros2 topic echo {topic}\n"
    ));
    Ok(Status::Success)
}

/// Say each file written, one a line, on standard output.
#[cfg(feature = "distributed")]
fn say_written(written: &[std::path::PathBuf]) {
    for path in written {
        crate::output::out(format_args!("{}\n", path.display()));
    }
}

#[cfg(test)]
mod tests {
    #![allow(
        clippy::unwrap_used,
        clippy::expect_used,
        reason = "a failing unwrap is a failing test"
    )]

    use super::*;

    #[test]
    fn the_router_is_reached_where_it_listens_a_wildcard_at_localhost() {
        let ok = |l: &str| endpoints(l).unwrap();
        assert_eq!(
            ok("tls/localhost:7447"),
            ("tls/localhost:7447".into(), "localhost".into())
        );
        assert_eq!(
            ok("tls/0.0.0.0:7450"),
            ("tls/localhost:7450".into(), "localhost".into())
        );
        assert_eq!(
            ok("tls/[::]:7450"),
            ("tls/localhost:7450".into(), "localhost".into())
        );
        assert_eq!(
            ok("tls/10.0.0.2:7447"),
            ("tls/10.0.0.2:7447".into(), "10.0.0.2".into())
        );
        assert_eq!(
            ok("tls/[::1]:7447"),
            ("tls/[::1]:7447".into(), "::1".into())
        );
        for bad in [
            "tcp/localhost:7447",
            "quic/localhost:7447",
            "tls/localhost",
            "tls/:7447",
            "tls/h:0",
            "tls/h:x",
        ] {
            let e = endpoints(bad).expect_err(bad);
            assert!(e.contains("tls/HOST:PORT"), "{bad}: {e}");
        }
    }

    #[cfg(feature = "distributed")]
    mod made {
        #![allow(
            clippy::unwrap_used,
            clippy::expect_used,
            reason = "a failing unwrap is a failing test"
        )]

        use std::path::PathBuf;

        use super::super::*;
        use crate::App;

        fn rex() -> App {
            App::new(
                "rex.ron",
                include_str!(concat!(env!("CARGO_MANIFEST_DIR"), "/../specs/rex.ron")),
            )
        }

        /// A folder of this test's own, not there yet.
        fn folder(name: &str) -> PathBuf {
            let dir = std::env::temp_dir().join(format!(
                "agent-app-credentials-{}-{name}",
                std::process::id()
            ));
            let _ = std::fs::remove_dir_all(&dir);
            dir
        }

        fn common(deployment: Option<&str>) -> Common {
            Common {
                deployment: deployment.map(str::to_owned),
                ..Common::default()
            }
        }

        #[test]
        fn refused_deployments_and_endpoints_write_nothing() {
            let dir = folder("refused");
            let cases: [(Option<&str>, Option<&str>, &str); 4] = [
                (None, None, "--deployment NAME"),
                (Some("nowhere"), None, "no deployment `nowhere`"),
                (Some("split"), None, "unprotected"),
                (
                    Some("split_secure"),
                    Some("tcp/127.0.0.1:7447"),
                    "--ros2-listen tcp/127.0.0.1:7447: the ROS 2 router of a secure deployment listens over mutual TLS",
                ),
            ];
            for (deployment, listen, said) in cases {
                let e = credentials(&mut rex(), &(), &common(deployment), &dir, listen)
                    .expect_err(said);
                assert_eq!(e.status(), Status::Invalid, "{e}");
                let e = e.to_string();
                assert!(
                    e.starts_with(&format!("credentials {}: ", dir.display())),
                    "{e}"
                );
                assert!(e.contains(said), "{said}: {e}");
                assert!(!dir.exists(), "{said}: {} written", dir.display());
            }
        }

        #[cfg(feature = "ros2")]
        #[test]
        fn a_secure_deployment_with_a_ros_2_side_gets_every_credential_and_both_configurations_once()
         {
            let dir = folder("split_secure");
            let listen = "tls/127.0.0.1:7999";
            let status = credentials(
                &mut rex(),
                &(),
                &common(Some("split_secure")),
                &dir,
                Some(listen),
            )
            .unwrap();
            assert_eq!(status, Status::Success);
            for name in ["ca", "world", "locomotion", "vision", "ros2", "ros2_router"] {
                for ext in ["pem", "key"] {
                    let file = dir.join(format!("{name}.{ext}"));
                    assert!(file.is_file(), "{}", file.display());
                }
            }
            #[cfg(unix)]
            {
                use std::os::unix::fs::PermissionsExt as _;
                let mode = std::fs::metadata(dir.join("ca.key"))
                    .unwrap()
                    .permissions()
                    .mode();
                assert_eq!(mode & 0o077, 0, "ca.key readable by others: {mode:o}");
            }
            let json = |f: &str| -> serde_json::Value {
                serde_json::from_str(&std::fs::read_to_string(dir.join(f)).unwrap()).unwrap()
            };
            let router = json("ros2_router.json5");
            assert_eq!(router["mode"], "router", "{router}");
            assert_eq!(
                router["listen"]["endpoints"],
                serde_json::json!([listen]),
                "{router}"
            );
            let acl = router["access_control"].to_string();
            assert!(acl.contains("ros2.split_secure.rex"), "{acl}");
            assert!(acl.contains("\"deny\""), "{acl}");
            let tls = router["transport"]["link"]["tls"].to_string();
            let absolute = std::path::absolute(&dir).unwrap();
            assert!(
                tls.contains(&absolute.join("ros2_router.key").display().to_string()),
                "{tls}"
            );
            let session = json("ros2_session.json5");
            assert_eq!(session["mode"], "client", "{session}");
            assert_eq!(
                session["connect"]["endpoints"],
                serde_json::json!([listen]),
                "{session}"
            );
            assert!(
                session
                    .to_string()
                    .contains(&absolute.join("ros2.key").display().to_string()),
                "{session}"
            );

            // Never again in the same folder: the keys stay.
            let key = std::fs::read(dir.join("ca.key")).unwrap();
            let e = credentials(&mut rex(), &(), &common(Some("split_secure")), &dir, None)
                .expect_err("an authority is there");
            assert_eq!(e.status(), Status::Invalid);
            assert!(e.to_string().contains("ca.pem exists"), "{e}");
            assert_eq!(std::fs::read(dir.join("ca.key")).unwrap(), key);
            std::fs::remove_dir_all(&dir).unwrap();
        }
    }
}
