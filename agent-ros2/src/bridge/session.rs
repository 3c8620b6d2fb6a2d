//! The bridge's Zenoh session: opened as a client of a router (rmw_zenohd,
//! where ROS 2 nodes find each other) or as a peer, or one the caller has.
//! In a secure deployment, a client over TLS proving itself with its
//! process's certificate ([`SessionOptions::tls_client`]), which the router's
//! access control knows by its common name ([`crate::access`]).

use zenoh::Wait;

use agent_zenoh::security::Credentials;

use super::BridgeError;

/// The endpoint rmw_zenohd listens on by default.
pub const ROUTER_ENDPOINT: &str = "tcp/localhost:7447";

/// How the bridge takes part in the Zenoh network.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Mode {
    /// A client of a router: what ROS 2 nodes over rmw_zenoh are to
    /// rmw_zenohd (their default is peer, which also routes through it).
    #[default]
    Client,
    /// A peer: connects to the endpoints and may talk to other peers
    /// directly.
    Peer,
}

/// The session a bridge opens.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SessionOptions {
    /// Client or peer.
    pub mode: Mode,
    /// The endpoints it connects to; default [`ROUTER_ENDPOINT`].
    pub connect: Vec<String>,
    /// The endpoints it listens on (a peer); default none.
    pub listen: Vec<String>,
}

impl Default for SessionOptions {
    fn default() -> Self {
        Self {
            mode: Mode::Client,
            connect: vec![ROUTER_ENDPOINT.to_owned()],
            listen: Vec::new(),
        }
    }
}

impl SessionOptions {
    /// A client of the router at `endpoint` (`tcp/localhost:7447`).
    pub fn client(endpoint: &str) -> Self {
        Self {
            connect: vec![endpoint.to_owned()],
            ..Self::default()
        }
    }

    /// A client of the router at the TLS `endpoint` (`tls/localhost:7447`;
    /// `quic/...` works too) of a secure deployment, proving itself with
    /// `credentials` (its process's certificate and key, checked against
    /// the deployment's authority, which must have issued the router's
    /// certificate too, for one of the endpoint's host names). The
    /// credentials ride in the endpoint's own Zenoh configuration
    /// (`tls/host:port#root_ca_certificate_file=...;enable_mtls=true`), so
    /// the options stay as they are otherwise; a path with a character that
    /// configuration cannot carry (`;`, `#`, `=`, `|`, `?`) is refused.
    pub fn tls_client(endpoint: &str, credentials: &Credentials) -> Result<Self, BridgeError> {
        let mut settings = Vec::new();
        for (key, path) in [
            ("root_ca_certificate_file", &credentials.authority),
            ("connect_certificate_file", &credentials.certificate),
            ("connect_private_key_file", &credentials.key),
        ] {
            let text = path.display().to_string();
            if let Some(c) = text.chars().find(|c| ";#=|?".contains(*c)) {
                return Err(BridgeError::Setting {
                    key: "connect/endpoints".to_owned(),
                    value: text.clone(),
                    reason: format!(
                        "`{c}` cannot be in a path of Zenoh's endpoint configuration: move the credentials"
                    ),
                });
            }
            settings.push(format!("{key}={text}"));
        }
        settings.push("enable_mtls=true".to_owned());
        settings.push("verify_name_on_connect=true".to_owned());
        let separator = if endpoint.contains('#') { ';' } else { '#' };
        Ok(Self::client(&format!(
            "{endpoint}{separator}{}",
            settings.join(";")
        )))
    }

    /// Open the session. Multicast scouting is off (the endpoints are
    /// given); a client that reaches no router fails here, saying so.
    pub fn open(&self) -> Result<zenoh::Session, BridgeError> {
        let list =
            |items: &[String]| serde_json::to_string(items).unwrap_or_else(|_| "[]".to_owned());
        let mode = match self.mode {
            Mode::Client => "\"client\"",
            Mode::Peer => "\"peer\"",
        };
        let settings = [
            ("mode", mode.to_owned()),
            ("connect/endpoints", list(&self.connect)),
            ("listen/endpoints", list(&self.listen)),
            ("scouting/multicast/enabled", "false".to_owned()),
        ];
        let mut config = zenoh::Config::default();
        for (key, value) in settings {
            config
                .insert_json5(key, &value)
                .map_err(|e| BridgeError::Setting {
                    key: key.to_owned(),
                    value: value.clone(),
                    reason: e.to_string(),
                })?;
        }
        zenoh::open(config)
            .wait()
            .map_err(|e| BridgeError::Session {
                endpoints: self.connect.join(", "),
                reason: e.to_string(),
            })
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

    use super::*;

    fn credentials(dir: &str) -> Credentials {
        Credentials {
            authority: format!("{dir}/ca.pem").into(),
            certificate: format!("{dir}/locomotion.pem").into(),
            key: format!("{dir}/locomotion.key").into(),
        }
    }

    #[test]
    fn a_tls_client_carries_its_credentials_in_the_endpoint() {
        let o = SessionOptions::tls_client("tls/localhost:7447", &credentials("/c")).unwrap();
        assert_eq!(o.mode, Mode::Client);
        assert!(o.listen.is_empty());
        assert_eq!(
            o.connect,
            ["tls/localhost:7447#root_ca_certificate_file=/c/ca.pem;\
                 connect_certificate_file=/c/locomotion.pem;\
                 connect_private_key_file=/c/locomotion.key;\
                 enable_mtls=true;verify_name_on_connect=true"]
        );
        // An endpoint with a configuration of its own keeps it.
        let o =
            SessionOptions::tls_client("tls/localhost:7447#so_rcvbuf=65536", &credentials("/c"))
                .unwrap();
        assert!(
            o.connect[0]
                .starts_with("tls/localhost:7447#so_rcvbuf=65536;root_ca_certificate_file="),
            "{:?}",
            o.connect
        );
    }

    #[test]
    fn a_path_the_endpoint_cannot_carry_is_refused() {
        let e = SessionOptions::tls_client("tls/localhost:7447", &credentials("/a;b")).unwrap_err();
        assert!(e.to_string().contains("`;`"), "{e}");
        assert!(e.to_string().contains("/a;b/ca.pem"), "{e}");
    }

    #[test]
    fn zenoh_takes_the_endpoint_and_says_when_no_router_answers() {
        // Files that exist (their content is not read before a link is made).
        let dir = std::env::temp_dir().join(format!("agent-ros2-tls-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let c = credentials(&dir.display().to_string());
        for f in [&c.authority, &c.certificate, &c.key] {
            std::fs::write(f, "").unwrap();
        }
        let port = std::net::TcpListener::bind("127.0.0.1:0")
            .and_then(|l| l.local_addr())
            .unwrap()
            .port();
        let o = SessionOptions::tls_client(&format!("tls/127.0.0.1:{port}"), &c).unwrap();
        let Err(e) = o.open() else {
            panic!("a session with no router");
        };
        assert!(matches!(e, BridgeError::Session { .. }), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
