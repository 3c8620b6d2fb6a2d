//! The token formats against the design document's examples, and what a
//! malformed token is refused for.

use super::*;

const STRING_HASH: &str = "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18";
const ADD_TWO_INTS_HASH: &str =
    "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a";

fn node(zid: &str, name: &str) -> NodeToken {
    NodeToken::new(0, zid.parse().unwrap(), 0, "/", name).unwrap()
}

fn entity(
    node: NodeToken,
    kind: EndpointKind,
    topic: &str,
    type_name: &str,
    hash: &str,
    depth: u64,
) -> EntityToken {
    let type_name = type_name.parse().unwrap();
    let hash = hash.parse().unwrap();
    EntityToken::new(
        node,
        10,
        kind,
        topic,
        type_name,
        hash,
        Qos::keep_last(depth),
    )
    .unwrap()
}

/// The five examples of the design document's graph cache section
/// (rmw_zenoh 0.6.7, Kilted).
fn design_document_examples() -> Vec<(LivelinessToken, String)> {
    let listener = node("aac3178e146ba6f1fc6e6a4085e77f21", "listener");
    let talker = node("8b20917502ee955ac4476e0266340d5c", "talker");
    let server = node("f9980ee0495eaafb3e38f0d19e2eae12", "add_two_ints_server");
    let client = node("e1dc8d1b45ae8717fce78689cc655685", "add_two_ints_client");
    let (string, add) = ("std_msgs/msg/String", "example_interfaces/srv/AddTwoInts");
    let (add_dds, string_dds) = (
        "example_interfaces::srv::dds_::AddTwoInts_",
        "std_msgs::msg::dds_::String_",
    );
    use EndpointKind::*;
    vec![
        (
            LivelinessToken::Node(listener.clone()),
            "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener".to_owned(),
        ),
        (
            LivelinessToken::Entity(entity(
                listener,
                Subscription,
                "/chatter",
                string,
                STRING_HASH,
                10,
            )),
            format!(
                "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/10/MS/%/%/listener/%chatter/{string_dds}/{STRING_HASH}/::,10:,:,:,,"
            ),
        ),
        (
            LivelinessToken::Entity(entity(
                talker,
                Publisher,
                "/chatter",
                string,
                STRING_HASH,
                7,
            )),
            format!(
                "@ros2_lv/0/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/{string_dds}/{STRING_HASH}/::,7:,:,:,,"
            ),
        ),
        (
            LivelinessToken::Entity(entity(
                server,
                ServiceServer,
                "/add_two_ints",
                add,
                ADD_TWO_INTS_HASH,
                10,
            )),
            format!(
                "@ros2_lv/0/f9980ee0495eaafb3e38f0d19e2eae12/0/10/SS/%/%/add_two_ints_server/%add_two_ints/{add_dds}/{ADD_TWO_INTS_HASH}/::,10:,:,:,,"
            ),
        ),
        (
            LivelinessToken::Entity(entity(
                client,
                ServiceClient,
                "/add_two_ints",
                add,
                ADD_TWO_INTS_HASH,
                10,
            )),
            format!(
                "@ros2_lv/0/e1dc8d1b45ae8717fce78689cc655685/0/10/SC/%/%/add_two_ints_client/%add_two_ints/{add_dds}/{ADD_TWO_INTS_HASH}/::,10:,:,:,,"
            ),
        ),
    ]
}

#[test]
fn the_design_documents_tokens_are_made_and_parsed() {
    for (token, key) in design_document_examples() {
        assert_eq!(token.key_expr(), key);
        assert_eq!(LivelinessToken::parse(&key), Ok(token));
    }
}

#[test]
fn a_discovered_publisher_tells_its_topic_type_hash_qos_and_data_key() {
    let key = &design_document_examples()[2].1;
    let LivelinessToken::Entity(talker) = LivelinessToken::parse(key).unwrap() else {
        panic!("the talker's token is an entity's");
    };
    assert_eq!(talker.kind(), EndpointKind::Publisher);
    assert_eq!(talker.node().name(), "talker");
    assert_eq!(talker.node().namespace(), "/");
    assert_eq!(talker.topic(), "/chatter");
    assert_eq!(talker.type_name().to_string(), "std_msgs/msg/String");
    assert_eq!(talker.type_hash().to_string(), STRING_HASH);
    assert_eq!(talker.qos().depth, 7);
    assert_eq!(
        talker.topic_key().to_string(),
        format!("0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}")
    );
    assert_eq!(talker.gid(), Gid::of_token_key(key));
}

#[test]
fn namespaces_and_enclaves_are_mangled() {
    let zid = Zid::from_le_bytes([0x21, 0x43, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0]);
    assert_eq!(zid.to_string(), "4321");
    let rex = NodeToken::new(3, zid, 2, "/robot1", "rex")
        .unwrap()
        .with_enclave("/rex/secure")
        .unwrap();
    let pose = EntityToken::new(
        rex.clone(),
        5,
        EndpointKind::Publisher,
        "/robot1/pose",
        "geometry_msgs/msg/PoseStamped".parse().unwrap(),
        TypeHash::NotSupported,
        Qos::keep_last(1).best_effort(),
    )
    .unwrap();
    let key = "@ros2_lv/3/4321/2/5/MP/%rex%secure/%robot1/rex/%robot1%pose/\
               geometry_msgs::msg::dds_::PoseStamped_/TypeHashNotSupported/2::,1:,:,:,,";
    assert_eq!(pose.key_expr(), key);
    assert_eq!(
        LivelinessToken::parse(key),
        Ok(LivelinessToken::Entity(pose))
    );
    assert_eq!(
        rex.key_expr(),
        "@ros2_lv/3/4321/2/2/NN/%rex%secure/%robot1/rex"
    );
    assert_eq!(liveliness_subscriber_key(3), "@ros2_lv/3/**");
}

#[test]
fn lyricals_backends_chunk_is_kept() {
    let key = format!("{}/backends:cpu:", design_document_examples()[2].1);
    let token = LivelinessToken::parse(&key).unwrap();
    let LivelinessToken::Entity(entity) = &token else {
        panic!("an entity's token");
    };
    assert_eq!(entity.backends(), Some("backends:cpu:"));
    assert_eq!(token.key_expr(), key);
    assert!(matches!(
        LivelinessToken::parse(&format!("{}/other", design_document_examples()[2].1)),
        Err(TokenError::Backends { .. })
    ));
}

#[test]
fn malformed_tokens_name_what_is_wrong() {
    let talker = &design_document_examples()[2].1;
    let with = |from: &str, to: &str| LivelinessToken::parse(&talker.replacen(from, to, 1));
    assert!(matches!(
        with("@ros2_lv", "@ros2"),
        Err(TokenError::NotLiveliness { .. })
    ));
    assert!(matches!(
        with("/::,7:,:,:,,", ""),
        Err(TokenError::ChunkCount { found: 12, .. })
    ));
    assert!(matches!(
        with("/0/10/", "//10/"),
        Err(TokenError::EmptyChunk { index: 3, .. })
    ));
    assert!(matches!(
        with("@ros2_lv/0/", "@ros2_lv/x/"),
        Err(TokenError::Domain(_))
    ));
    assert!(matches!(
        with("8b20917502ee", "8B20917502EE"),
        Err(TokenError::Zid { .. })
    ));
    assert!(matches!(
        with("/0/10/", "/0/-1/"),
        Err(TokenError::EntityId(_))
    ));
    assert!(matches!(
        with("/MP/", "/XP/"),
        Err(TokenError::UnknownKind { .. })
    ));
    assert!(matches!(
        with("/%chatter/", "/chatter/"),
        Err(TokenError::Name(NameError::NotAbsolute { .. }))
    ));
    assert!(matches!(
        with("dds_::String_", "String"),
        Err(TokenError::TypeName(_))
    ));
    assert!(matches!(
        with("RIHS01_df", "RIHS01_DF"),
        Err(TokenError::TypeHash(_))
    ));
    assert!(matches!(with("::,7:", ":9:,7:"), Err(TokenError::Qos(_))));
    assert!(matches!(
        with("/talker/", "/tal%ker/"),
        Err(TokenError::Name(_))
    ));
    let listener = &design_document_examples()[0].1;
    assert!(matches!(
        LivelinessToken::parse(&listener.replace("/0/0/NN/", "/0/1/NN/")),
        Err(TokenError::NodeIdMismatch {
            node_id: 0,
            entity_id: 1
        })
    ));
    assert!(matches!(
        LivelinessToken::parse(&talker.replace("/MP/", "/NN/").replace("/0/10/", "/0/0/")),
        Err(TokenError::KindChunkCount { found: 13, .. })
    ));
    assert!(matches!(
        LivelinessToken::parse(&listener.replace("/NN/", "/MP/")),
        Err(TokenError::KindChunkCount { found: 9, .. })
    ));
}
