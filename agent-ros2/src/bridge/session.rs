//! The bridge's Zenoh session: opened as a client of a router (rmw_zenohd,
//! where ROS 2 nodes find each other) or as a peer, or one the caller has.

use zenoh::Wait;

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
