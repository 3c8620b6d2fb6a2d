//! The bridge on real Zenoh sessions, without Python (so plain `cargo test`
//! runs it): a client without a router fails to start, saying where it
//! looked; on a session of the caller's, another session sees the tokens and
//! samples in rmw_zenoh's format (read back with our wire module, against
//! the CDR of the values sent), and the caller's session stays open.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

mod common;

use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use agent_core::{ExecConfig, Executor};
use agent_ros2::bridge::{Bridge, BridgeError, BridgeOptions, Mode, Plan, SessionOptions};
use agent_ros2::types::encode_cdr;
use agent_ros2::wire::{Attachment, LivelinessToken};
use common::{Status, adapters, spec, status_at, system};
use zenoh::Wait;
use zenoh::sample::SampleKind;

/// A localhost TCP endpoint free a moment ago.
fn free_endpoint() -> String {
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    format!("tcp/127.0.0.1:{port}")
}

#[test]
fn a_client_without_a_router_fails_to_start_saying_where() {
    let plan = Plan::new(&spec(common::ROS2), None, &system(), &adapters()).unwrap();
    let endpoint = free_endpoint();
    let options = BridgeOptions {
        session: SessionOptions::client(&endpoint),
        ..BridgeOptions::default()
    };
    let error = Bridge::start(plan, options).unwrap_err();
    assert!(matches!(error, BridgeError::Session { .. }), "{error}");
    assert!(error.to_string().contains(&endpoint), "{error}");
}

/// What the watching session received.
#[derive(Default)]
struct Watched {
    tokens: Vec<(SampleKind, String)>,
    samples: Vec<(String, Vec<u8>, Vec<u8>)>,
}

#[test]
fn on_a_session_of_ours_the_tokens_and_samples_are_rmw_zenohs() {
    let endpoint = free_endpoint();
    let peer = |listen: Vec<String>, connect: Vec<String>| SessionOptions {
        mode: Mode::Peer,
        connect,
        listen,
    };
    let watcher = peer(vec![endpoint.clone()], vec![]).open().unwrap();
    let watched = Arc::new(Mutex::new(Watched::default()));
    let w = watched.clone();
    let _tokens = watcher
        .liveliness()
        .declare_subscriber("@ros2_lv/**")
        .history(true)
        .callback(move |s| {
            let mut w = w.lock().unwrap();
            w.tokens.push((s.kind(), s.key_expr().to_string()));
        })
        .wait()
        .unwrap();
    let w = watched.clone();
    let _data = watcher
        .declare_subscriber("0/**")
        .callback(move |s| {
            let attachment = s.attachment().map(|a| a.to_bytes().to_vec());
            let mut w = w.lock().unwrap();
            w.samples.push((
                s.key_expr().to_string(),
                s.payload().to_bytes().to_vec(),
                attachment.unwrap_or_default(),
            ));
        })
        .wait()
        .unwrap();

    let session = peer(vec![], vec![endpoint]).open().unwrap();
    let plan = Plan::new(&spec(common::ROS2), None, &system(), &adapters()).unwrap();
    let bridge = Bridge::on_session(plan, session.clone(), &BridgeOptions::default()).unwrap();
    assert!(bridge.wait_for_subscribers(Duration::from_secs(10)));
    let node = bridge.node_token().key_expr();
    let status = bridge.publisher_tokens()[1].clone();
    let mut exec = Executor::with_observer(system(), ExecConfig::default(), bridge);
    exec.run_for(Duration::from_millis(100)).unwrap();
    let report = exec.into_observer().finish().unwrap();
    assert!(!session.is_closed(), "the caller's session is left open");
    let n = report.topics[1].published;
    assert!(n >= 10, "{report:?}");

    let deadline = Instant::now() + Duration::from_secs(10);
    let key = status.topic_key().to_string();
    loop {
        let w = watched.lock().unwrap();
        let got = w.samples.iter().filter(|s| s.0 == key).count() as u64;
        let gone = w
            .tokens
            .iter()
            .filter(|t| t.0 == SampleKind::Delete)
            .count();
        if (got == n && gone == 3) || Instant::now() > deadline {
            break;
        }
        drop(w);
        std::thread::sleep(Duration::from_millis(20));
    }
    let w = watched.lock().unwrap();
    let put: Vec<&String> = w
        .tokens
        .iter()
        .filter(|t| t.0 == SampleKind::Put)
        .map(|t| &t.1)
        .collect();
    assert!(
        put.contains(&&node) && put.contains(&&status.key_expr()),
        "{put:?}"
    );
    assert_eq!(
        LivelinessToken::parse(&status.key_expr()).unwrap(),
        LivelinessToken::Entity(status.clone())
    );
    assert_eq!(
        w.tokens
            .iter()
            .filter(|t| t.0 == SampleKind::Delete)
            .count(),
        3,
        "the node's and both publishers' tokens vanish at the end"
    );
    let shape = agent_core::reflect::<Status>().unwrap();
    let statuses: Vec<_> = w.samples.iter().filter(|s| s.0 == key).collect();
    assert_eq!(statuses.len() as u64, n);
    for ((_, payload, attachment), k) in statuses.into_iter().zip(0u32..) {
        let attachment = Attachment::decode(attachment).unwrap();
        assert_eq!(attachment.sequence_number, i64::from(k) + 1);
        assert_eq!(attachment.gid, status.gid());
        let mut cdr = Vec::new();
        encode_cdr(&status_at(k), &shape, &mut cdr).unwrap();
        assert_eq!(payload, &cdr, "status {k}");
    }
}

/// The caller closes its session under the bridge: the values in the rings
/// are counted as refused, and finishing still undeclares what it holds
/// (Zenoh 1.10 accepts undeclarations on a closed session, so nothing is in
/// `close_errors`) and returns the counts.
#[test]
fn finishing_on_a_closed_session_keeps_the_counts() {
    let session = SessionOptions {
        mode: Mode::Peer,
        connect: vec![],
        listen: vec![],
    }
    .open()
    .unwrap();
    let plan = Plan::new(&spec(common::ROS2), None, &system(), &adapters()).unwrap();
    let bridge = Bridge::on_session(plan, session.clone(), &BridgeOptions::default()).unwrap();
    let mut exec = Executor::with_observer(system(), ExecConfig::default(), bridge);
    exec.run_for(Duration::from_millis(50)).unwrap();
    let bridge = exec.into_observer();
    session.close().wait().unwrap();
    let report = bridge.finish().unwrap();
    for topic in &report.topics {
        assert_eq!(topic.published + topic.put_failures, 5, "{report:?}");
    }
    assert!(report.close_errors.is_empty(), "{report:?}");
}
