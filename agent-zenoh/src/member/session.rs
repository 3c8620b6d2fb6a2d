//! Zenoh sessions: opened as a peer or a client of a deployment (secured or
//! not), closed within a bound, and the liveliness tokens polled.

use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use zenoh::Wait;

/// A Zenoh session in peer mode, listening on `listen` (if any) and connecting
/// to `connect`, without multicast scouting (endpoints are given; multicast is
/// often unavailable between network namespaces and hosts). Peers that are not
/// up yet are retried in the background: the caller's own waits decide when to
/// give up.
pub fn open_peer(listen: Option<&str>, connect: &[&str]) -> Result<zenoh::Session, SessionError> {
    open_secure_peer(listen, connect, None)
}

/// [`open_peer`], with mutual TLS and an access control list if `secured`
/// (the endpoints are then `quic/...`: TLS 1.3 over QUIC).
pub fn open_secure_peer(
    listen: Option<&str>,
    connect: &[&str],
    secured: Option<&crate::security::Secured>,
) -> Result<zenoh::Session, SessionError> {
    open_session("peer", listen, connect, secured)
}

/// A Zenoh session in client mode connected to `connect`, with mutual TLS and
/// an access control list if `secured`: a monitor or a tool that talks to a
/// deployment through one of its processes and takes no part in routing.
pub fn open_secure_client(
    connect: &[&str],
    secured: Option<&crate::security::Secured>,
) -> Result<zenoh::Session, SessionError> {
    open_session("client", None, connect, secured)
}

fn open_session(
    mode: &str,
    listen: Option<&str>,
    connect: &[&str],
    secured: Option<&crate::security::Secured>,
) -> Result<zenoh::Session, SessionError> {
    let mut config = zenoh::Config::default();
    let mut settings: Vec<(&str, String)> = vec![
        ("mode", format!("{mode:?}")),
        ("listen/endpoints", json_list(listen.as_slice())),
        ("connect/endpoints", json_list(connect)),
        // Connect in the background, retrying every 100 ms at first, 1 s at most.
        ("connect/exit_on_failure", "false".to_owned()),
        (
            "connect/retry",
            "{period_init_ms: 100, period_max_ms: 1000, period_increase_factor: 2}".to_owned(),
        ),
        ("scouting/multicast/enabled", "false".to_owned()),
    ];
    if let Some(s) = secured {
        let path = |p: &std::path::Path| format!("{:?}", p.display().to_string());
        let c = &s.credentials;
        settings.extend([
            ("transport/link/tls/root_ca_certificate", path(&c.authority)),
            (
                "transport/link/tls/listen_certificate",
                path(&c.certificate),
            ),
            ("transport/link/tls/listen_private_key", path(&c.key)),
            (
                "transport/link/tls/connect_certificate",
                path(&c.certificate),
            ),
            ("transport/link/tls/connect_private_key", path(&c.key)),
            ("transport/link/tls/enable_mtls", "true".to_owned()),
            ("access_control", s.acl.to_string()),
        ]);
    }
    for (key, value) in settings {
        config
            .insert_json5(key, &value)
            .map_err(|e| SessionError::Setting {
                key: key.to_owned(),
                value: value.clone(),
                reason: e.to_string(),
            })?;
    }
    zenoh::open(config).wait().map_err(|e| SessionError::Open {
        reason: e.to_string(),
    })
}

/// Why a Zenoh session did not open.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum SessionError {
    /// Zenoh refused a setting of its configuration (an endpoint it cannot
    /// read, a credential's path, the access control list).
    #[error("zenoh refused setting `{key}` to {value}: {reason}")]
    Setting {
        /// The configuration's key.
        key: String,
        /// The value given (JSON5).
        value: String,
        /// Zenoh's message.
        reason: String,
    },
    /// Zenoh could not open the session (a port taken, a certificate it cannot
    /// load, ...).
    #[error("zenoh could not open the session: {reason}")]
    Open {
        /// Zenoh's message.
        reason: String,
    },
}

/// Close `session`, waiting at most `bound`: best effort (Zenoh's own bound
/// is unstable API, and its default, 10 s, is spent whole on a QUIC link whose
/// peer has already exited); the peers see the session go by its presence
/// tokens and their links' leases either way, and a close still under way ends
/// with the process.
pub(super) fn close_within(session: zenoh::Session, bound: Duration) {
    let (closed, done) = std::sync::mpsc::channel();
    let closing = std::thread::Builder::new()
        .name("zenoh-close".into())
        .spawn(move || {
            let _ = session.close().wait();
            let _ = closed.send(());
        });
    if closing.is_ok() {
        let _ = done.recv_timeout(bound);
    }
}

/// A JSON list of strings (endpoints have no characters that need more than
/// Rust's `Debug` quoting).
fn json_list(items: &[&str]) -> String {
    let items: Vec<String> = items.iter().map(|s| format!("{s:?}")).collect();
    format!("[{}]", items.join(","))
}

/// The process a presence token's key names (`<prefix><process>/<epoch>`).
pub(super) fn process_of<'k>(key: &'k str, prefix: &str) -> Option<&'k str> {
    key.strip_prefix(prefix)?.split('/').next()
}

/// Poll `key` (a liveliness key expression) until `done` says the tokens seen
/// suffice, or `timeout`. Returns the tokens' keys last seen.
pub(super) fn poll_tokens(
    session: &zenoh::Session,
    key: &str,
    timeout: Duration,
    cancel: Option<&AtomicBool>,
    mut done: impl FnMut(&[String]) -> bool,
) -> (bool, Vec<String>) {
    let start = Instant::now();
    let mut seen = Vec::new();
    loop {
        if cancel.is_some_and(|c| c.load(Ordering::Relaxed)) {
            return (false, seen);
        }
        seen.clear();
        if let Ok(replies) = session
            .liveliness()
            .get(key)
            .timeout(Duration::from_millis(300))
            .wait()
        {
            while let Ok(reply) = replies.recv() {
                if let Ok(sample) = reply.result() {
                    seen.push(sample.key_expr().as_str().to_owned());
                }
            }
        }
        if done(&seen) {
            return (true, seen);
        }
        if start.elapsed() >= timeout {
            return (false, seen);
        }
        std::thread::sleep(Duration::from_millis(50));
    }
}
