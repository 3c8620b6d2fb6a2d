//! Round trips of rmw_zenoh's wire format for arbitrary valid values: what we
//! write parses back to the same value (keys, tokens, QoS, attachments), and a
//! parse of anything, valid or damaged, returns an error rather than panics.

#![allow(
    clippy::expect_used,
    reason = "the strategies build valid values: a failing expect is a failing test"
)]

use agent_ros2::wire::{
    ATTACHMENT_LEN, Attachment, AttachmentError, Durability, EndpointKind, EntityToken, Gid,
    History, Interface, Liveliness, LivelinessToken, NodeToken, Qos, QosDuration, Reliability,
    TopicKey, TypeHash, TypeName, Zid, demangle, mangle, qualify_topic,
};
use proptest::prelude::*;
use proptest::sample::select;

/// One ROS name token: a letter or `_`, then letters, digits and `_`.
fn token() -> impl Strategy<Value = String> {
    "[a-zA-Z_][a-zA-Z0-9_]{0,7}"
}

/// A fully qualified topic name of one to four tokens.
fn topic() -> impl Strategy<Value = String> {
    prop::collection::vec(token(), 1..=4).prop_map(|tokens| format!("/{}", tokens.join("/")))
}

/// A namespace or an enclave: the root, or an absolute name.
fn namespace() -> impl Strategy<Value = String> {
    prop_oneof![Just("/".to_owned()), topic()]
}

fn type_name() -> impl Strategy<Value = TypeName> {
    (
        "[a-z][a-z0-9_]{0,9}",
        select(vec![Interface::Msg, Interface::Srv, Interface::Action]),
        "[A-Z][A-Za-z0-9_]{0,9}",
    )
        .prop_map(|(package, interface, name)| {
            TypeName::new(&package, interface, &name).expect("identifiers by construction")
        })
}

fn type_hash() -> impl Strategy<Value = TypeHash> {
    prop_oneof![
        Just(TypeHash::NotSupported),
        any::<[u8; 32]>().prop_map(TypeHash::Rihs01),
    ]
}

fn duration() -> impl Strategy<Value = QosDuration> {
    prop_oneof![
        Just(QosDuration::INFINITE),
        Just(QosDuration::UNSPECIFIED),
        (any::<u64>(), any::<u64>()).prop_map(|(sec, nsec)| QosDuration { sec, nsec }),
    ]
}

fn qos() -> impl Strategy<Value = Qos> {
    (
        (
            select(Reliability::ALL),
            select(Durability::ALL),
            select(History::ALL),
            prop_oneof![Just(42u64), any::<u64>()],
        ),
        (duration(), duration(), select(Liveliness::ALL), duration()),
    )
        .prop_map(
            |(
                (reliability, durability, history, depth),
                (deadline, lifespan, liveliness, lease),
            )| {
                Qos {
                    reliability,
                    durability,
                    history,
                    depth,
                    deadline,
                    lifespan,
                    liveliness,
                    liveliness_lease_duration: lease,
                }
            },
        )
}

fn node() -> impl Strategy<Value = NodeToken> {
    (
        any::<u32>(),
        any::<u128>(),
        any::<u64>(),
        (namespace(), namespace(), token()),
    )
        .prop_map(|(domain, zid, node_id, (enclave, namespace, name))| {
            NodeToken::new(domain, Zid::new(zid), node_id, &namespace, &name)
                .and_then(|node| node.with_enclave(&enclave))
                .expect("valid names by construction")
        })
}

fn entity() -> impl Strategy<Value = EntityToken> {
    (
        (node(), any::<u64>(), select(EndpointKind::ALL.to_vec())),
        (topic(), type_name(), type_hash(), qos()),
        prop::option::of("backends:[a-z]{1,5}:[a-z0-9%]{0,6}(;[a-z]{1,5}:)?"),
    )
        .prop_map(|((node, id, kind), (topic, name, hash, qos), backends)| {
            let entity = EntityToken::new(node, id, kind, &topic, name, hash, qos)
                .expect("a valid topic by construction");
            match backends {
                Some(chunk) => entity.with_backends(&chunk).expect("a backends chunk"),
                None => entity,
            }
        })
}

fn liveliness_token() -> impl Strategy<Value = LivelinessToken> {
    prop_oneof![
        node().prop_map(LivelinessToken::Node),
        entity().prop_map(LivelinessToken::Entity),
    ]
}

fn topic_key() -> impl Strategy<Value = TopicKey> {
    (any::<u32>(), topic(), type_name(), type_hash()).prop_map(|(domain, topic, name, hash)| {
        TopicKey::new(domain, &topic, name, hash).expect("a valid topic by construction")
    })
}

fn attachment() -> impl Strategy<Value = Attachment> {
    (any::<i64>(), any::<i64>(), any::<[u8; 16]>()).prop_map(|(sequence, timestamp, gid)| {
        Attachment {
            sequence_number: sequence,
            source_timestamp_ns: timestamp,
            gid: Gid::from_bytes(gid),
        }
    })
}

/// `text` damaged at `at` (a byte offset, taken modulo its length): a
/// character inserted, the byte removed, or the text cut there.
fn damaged(text: &str, at: usize, how: u8, inserted: char) -> String {
    let at = if text.is_empty() { 0 } else { at % text.len() };
    let (head, tail) = text.split_at(at);
    match how % 3 {
        0 => format!("{head}{inserted}{tail}"),
        1 => format!("{head}{}", tail.get(1..).unwrap_or("")),
        _ => head.to_owned(),
    }
}

/// Characters that matter to the formats, and a few that do not belong.
fn wire_char() -> impl Strategy<Value = char> {
    select("/%:,_@0129afNPMSCX*é -".chars().collect::<Vec<_>>())
}

proptest! {
    #[test]
    fn topic_keys_round_trip(key in topic_key()) {
        let text = key.to_string();
        prop_assert!(!text.starts_with('/'));
        prop_assert_eq!(TopicKey::parse(&text), Ok(key));
    }

    #[test]
    fn liveliness_tokens_round_trip(token in liveliness_token()) {
        let key = token.key_expr();
        prop_assert!(key.split('/').all(|chunk| !chunk.is_empty()));
        let parsed = LivelinessToken::parse(&key);
        prop_assert_eq!(&parsed, &Ok(token.clone()));
        if let LivelinessToken::Entity(entity) = &token {
            prop_assert_eq!(entity.gid(), Gid::of_token_key(&key));
            prop_assert_eq!(TopicKey::parse(&entity.topic_key().to_string()), Ok(entity.topic_key()));
        }
    }

    #[test]
    fn qos_round_trips(qos in qos()) {
        prop_assert_eq!(Qos::parse_compact(&qos.to_compact()), Ok(qos));
    }

    #[test]
    fn attachments_round_trip(attachment in attachment()) {
        let bytes = attachment.encode();
        prop_assert_eq!(bytes.len(), ATTACHMENT_LEN);
        prop_assert_eq!(Attachment::decode(&bytes), Ok(attachment));
    }

    #[test]
    fn names_mangle_and_qualify(ns in namespace(), node in token(), relative in topic()) {
        prop_assert_eq!(demangle(&mangle(&ns)), ns.clone());
        let relative = relative.trim_start_matches('/');
        let qualified = qualify_topic(relative, &ns, &node).expect("valid parts");
        let prefix = if ns == "/" { String::new() } else { ns.clone() };
        prop_assert_eq!(&qualified, &format!("{prefix}/{relative}"));
        prop_assert_eq!(qualify_topic(&qualified, "/elsewhere", &node), Ok(qualified.clone()));
    }

    #[test]
    fn parses_of_arbitrary_text_never_panic(text in any::<String>()) {
        let _ = TopicKey::parse(&text);
        let _ = LivelinessToken::parse(&text);
        let _ = Qos::parse_compact(&text);
        let _ = text.parse::<TypeHash>();
        let _ = text.parse::<TypeName>();
        let _ = TypeName::parse_dds(&text);
        let _ = text.parse::<Zid>();
        let _ = qualify_topic(&text, "/", "node");
    }

    /// Valid keys damaged one character at a time reach the deep parts of the
    /// parsers; whatever still parses is a value that writes and parses back.
    #[test]
    fn damaged_keys_never_panic_and_what_parses_is_stable(
        token in liveliness_token(),
        key in topic_key(),
        at in any::<usize>(),
        how in any::<u8>(),
        inserted in wire_char(),
    ) {
        if let Ok(parsed) = LivelinessToken::parse(&damaged(&token.key_expr(), at, how, inserted)) {
            prop_assert_eq!(LivelinessToken::parse(&parsed.key_expr()), Ok(parsed));
        }
        if let Ok(parsed) = TopicKey::parse(&damaged(&key.to_string(), at, how, inserted)) {
            prop_assert_eq!(TopicKey::parse(&parsed.to_string()), Ok(parsed));
        }
        let qos = match &token {
            LivelinessToken::Entity(entity) => entity.qos().to_compact(),
            LivelinessToken::Node(_) => Qos::default().to_compact(),
        };
        if let Ok(parsed) = Qos::parse_compact(&damaged(&qos, at, how, inserted)) {
            prop_assert_eq!(Qos::parse_compact(&parsed.to_compact()), Ok(parsed));
        }
    }

    #[test]
    fn decoding_arbitrary_bytes_never_panics(bytes in prop::collection::vec(any::<u8>(), 0..64)) {
        match Attachment::decode(&bytes) {
            Ok(attachment) => {
                prop_assert_eq!(bytes.len(), ATTACHMENT_LEN);
                prop_assert_eq!(&attachment.encode()[..], &bytes[..]);
            }
            Err(AttachmentError::GidLength { found }) => prop_assert_ne!(found, 16),
            Err(AttachmentError::TooShort { len }) => prop_assert!(len < ATTACHMENT_LEN),
            Err(AttachmentError::TooLong { len }) => prop_assert!(len > ATTACHMENT_LEN),
        }
    }
}
