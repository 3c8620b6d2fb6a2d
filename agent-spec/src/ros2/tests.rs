//! The name rules against the examples and rules of ROS 2's design article
//! "Topic and Service name mapping to DDS", `rmw`'s validators, REP 144 and
//! `rosidl`; the defaults of an interface; and arbitrary text never panicking
//! a check.

use proptest::prelude::*;

use super::*;
use crate::model::Policy;

/// The rule `check` finds in `name`, and the text it points at.
fn broken(check: fn(&str) -> Result<(), NameError>, name: &str) -> (Rule, String) {
    match check(name) {
        Ok(()) => panic!("`{name}` passed"),
        Err(e) => (e.rule, name[e.at].to_owned()),
    }
}

#[test]
fn the_articles_valid_names_are_topics_but_for_substitutions_and_urls() {
    for name in [
        "foo", "abc123", "_foo", "Foo", "BAR", "~", "foo/bar", "~/foo", "foo/_bar",
    ] {
        assert_eq!(check_topic(name), Ok(()), "{name}");
    }
    // Valid in ROS 2, refused in specs: a substitution's keys are not fixed,
    // and a spec writes the name it stands for; URLs are not names.
    assert_eq!(
        broken(check_topic, "{foo}_bar"),
        (Rule::Substitution, "{foo}".into())
    );
    assert_eq!(
        broken(check_topic, "foo/{ping}/bar"),
        (Rule::Substitution, "{ping}".into())
    );
    for url in ["rosservice:///foo", "rostopic://foo/bar"] {
        assert_eq!(broken(check_topic, url), (Rule::Character(':'), ":".into()));
    }
}

#[test]
fn the_articles_invalid_names_are_refused_with_the_rule_they_break() {
    let cases = [
        ("123abc", Rule::StartsWithDigit, "1"),
        ("123", Rule::StartsWithDigit, "1"),
        ("foo bar", Rule::Character(' '), " "),
        (" ", Rule::Character(' '), " "),
        ("foo//bar", Rule::EmptyToken, "//"),
        ("foo/", Rule::TrailingSlash, "/"),
        ("foo_/bar", Rule::UnderscoreBeforeSlash, "_/"),
        ("~foo", Rule::Tilde, "~"),
        ("foo~", Rule::Tilde, "~"),
        ("foo~/bar", Rule::Tilde, "~"),
        ("foo/~bar", Rule::Tilde, "~"),
        ("/~", Rule::Tilde, "~"),
        ("foo/~/bar", Rule::Tilde, "~"),
    ];
    for (name, rule, at) in cases {
        assert_eq!(broken(check_topic, name), (rule, at.to_owned()), "{name}");
    }
}

#[test]
fn each_rule_of_topic_names() {
    // Must not be empty.
    assert_eq!(check_topic("").map_err(|e| e.rule), Err(Rule::Empty));
    // Alphanumerics, `_` and `/` only (ASCII: `é` is not alphanumeric here).
    assert_eq!(
        broken(check_topic, "pose-2d"),
        (Rule::Character('-'), "-".into())
    );
    assert_eq!(
        broken(check_topic, "posé"),
        (Rule::Character('é'), "é".into())
    );
    // No token starts with a digit, the first or a later one.
    assert_eq!(
        broken(check_topic, "/a/2b"),
        (Rule::StartsWithDigit, "2".into())
    );
    assert_eq!(check_topic("a2/b3"), Ok(()));
    // No trailing `/`, not even the root alone; no repeated `/`.
    assert_eq!(broken(check_topic, "/"), (Rule::TrailingSlash, "/".into()));
    assert_eq!(broken(check_topic, "~/"), (Rule::TrailingSlash, "/".into()));
    assert_eq!(broken(check_topic, "//a"), (Rule::EmptyToken, "//".into()));
    // Single underscores (the article's tokens; stricter than rcl).
    assert_eq!(
        broken(check_topic, "a__b"),
        (Rule::DoubleUnderscore, "__".into())
    );
    assert_eq!(
        broken(check_topic, "/__a"),
        (Rule::DoubleUnderscore, "__".into())
    );
    assert_eq!(
        check_topic("_a_b_"),
        Ok(()),
        "a last token may end with `_`"
    );
    // Balanced braces are refused as any substitution; so are stray ones.
    assert_eq!(broken(check_topic, "a}"), (Rule::Substitution, "}".into()));
    assert_eq!(broken(check_topic, "{a"), (Rule::Substitution, "{".into()));
}

#[test]
fn fully_qualified_names_are_absolute_and_at_most_247_bytes() {
    for name in [
        "/foo",
        "/bar/baz",
        "/_private/thing",
        "/public_namespace/_private/thing",
    ] {
        assert_eq!(check_full_topic(name), Ok(()), "{name}");
    }
    assert_eq!(
        broken(check_full_topic, "foo"),
        (Rule::NotAbsolute, "f".into())
    );
    assert_eq!(broken(check_full_topic, "/~/a"), (Rule::Tilde, "~".into()));
    let longest = format!("/{}", "a".repeat(TOPIC_NAME_MAX - 1));
    assert_eq!(check_full_topic(&longest), Ok(()));
    let (rule, at) = broken(check_full_topic, &format!("{longest}b"));
    assert_eq!(
        (rule, at),
        (Rule::TooLong { len: 248, max: 247 }, "b".into())
    );
}

#[test]
fn private_and_relative_names_expand_as_the_articles_table_says() {
    // (input, node `my_node` in no namespace, in `/my_ns`)
    let table = [
        ("ping", "/ping", "/my_ns/ping"),
        ("/ping", "/ping", "/ping"),
        ("~", "/my_node", "/my_ns/my_node"),
        ("~/ping", "/my_node/ping", "/my_ns/my_node/ping"),
    ];
    for (input, root, in_ns) in table {
        assert_eq!(expand_topic(input, "my_node", "/"), root, "{input}");
        assert_eq!(expand_topic(input, "my_node", "/my_ns"), in_ns, "{input}");
    }
}

#[test]
fn namespaces_are_absolute_without_trailing_slash_and_at_most_245_bytes() {
    for ns in ["/", "/rex", "/lab/rex_1", "/_hidden"] {
        assert_eq!(check_namespace(ns), Ok(()), "{ns}");
    }
    let cases = [
        ("", Rule::Empty, ""),
        ("rex", Rule::NotAbsolute, "r"),
        ("/rex/", Rule::TrailingSlash, "/"),
        ("/a//b", Rule::EmptyToken, "//"),
        ("/1a", Rule::StartsWithDigit, "1"),
        ("/a-b", Rule::Character('-'), "-"),
        ("/~", Rule::Tilde, "~"),
        ("/{ns}", Rule::Substitution, "{"),
        // A relative topic follows the namespace after a `/`: `/lab_/pose`.
        ("/lab_", Rule::TrailingUnderscore, "_"),
    ];
    for (ns, rule, at) in cases {
        assert_eq!(broken(check_namespace, ns), (rule, at.to_owned()), "{ns:?}");
    }
    let longest = format!("/{}", "n".repeat(NAMESPACE_MAX - 1));
    assert_eq!(check_namespace(&longest), Ok(()));
    assert!(matches!(
        check_namespace(&format!("{longest}n")).map_err(|e| e.rule),
        Err(Rule::TooLong { len: 246, max: 245 })
    ));
}

#[test]
fn node_names_are_identifiers_of_at_most_255_bytes() {
    for node in ["rex", "_rex", "Rex2", "a__b"] {
        assert_eq!(check_node(node), Ok(()), "{node}");
    }
    let cases = [
        ("2rex", Rule::StartsWithDigit, "2"),
        ("rex-1", Rule::Character('-'), "-"),
        ("/rex", Rule::Character('/'), "/"),
        ("~", Rule::Character('~'), "~"),
    ];
    for (node, rule, at) in cases {
        assert_eq!(broken(check_node, node), (rule, at.to_owned()), "{node}");
    }
    assert_eq!(check_node("").map_err(|e| e.rule), Err(Rule::Empty));
    assert_eq!(check_node(&"n".repeat(255)), Ok(()));
    assert!(matches!(
        check_node(&"n".repeat(256)).map_err(|e| e.rule),
        Err(Rule::TooLong { len: 256, max: 255 })
    ));
}

#[test]
fn package_names_follow_rep_144() {
    for package in ["rex_msgs", "geometry_msgs", "ab", "a2"] {
        assert_eq!(check_package(package), Ok(()), "{package}");
    }
    let cases = [
        ("Rex_msgs", Rule::Uppercase('R'), "R"),
        ("rex-msgs", Rule::Character('-'), "-"),
        ("2d_msgs", Rule::StartsWithDigit, "2"),
        ("_msgs", Rule::StartsWithUnderscore, "_"),
        ("rex__msgs", Rule::DoubleUnderscore, "__"),
        ("rex_", Rule::TrailingUnderscore, "_"),
        ("r", Rule::TooShort, "r"),
    ];
    for (package, rule, at) in cases {
        assert_eq!(
            broken(check_package, package),
            (rule, at.to_owned()),
            "{package}"
        );
    }
}

#[test]
fn message_types_are_package_msg_type() {
    for message in [
        "geometry_msgs/msg/PoseStamped",
        "sensor_msgs/msg/Imu",
        "rex_msgs/msg/Plan2",
    ] {
        assert_eq!(check_message(message), Ok(()), "{message}");
    }
    let cases = [
        (
            "geometry_msgs/PoseStamped",
            Rule::MessageForm,
            "geometry_msgs/PoseStamped",
        ),
        ("a/msg/b/C", Rule::MessageForm, "a/msg/b/C"),
        ("rex_msgs/msg/", Rule::MessageForm, "rex_msgs/msg/"),
        ("/msg/Plan", Rule::MessageForm, "/msg/Plan"),
        ("//", Rule::MessageForm, "//"),
        ("Geometry_msgs/msg/Pose", Rule::Uppercase('G'), "G"),
        ("rex_msgs/srv/Plan", Rule::NotMsg, "srv"),
        ("rex_msgs//Plan", Rule::NotMsg, "/"),
        ("rex_msgs/msg/plan", Rule::TypeStart('p'), "p"),
        ("rex_msgs/msg/Plan_2", Rule::Character('_'), "_"),
    ];
    for (message, rule, at) in cases {
        assert_eq!(
            broken(check_message, message),
            (rule, at.to_owned()),
            "{message}"
        );
    }
}

#[test]
fn qos_follows_the_link_unless_the_spec_says_otherwise() {
    let queue = QosProfile::of_link(Some(Policy::queue(4)));
    assert_eq!((queue.reliability, queue.depth), (Reliability::Reliable, 4));
    let sample = QosProfile::of_link(Some(Policy::Sample));
    assert_eq!(
        (sample.reliability, sample.depth),
        (Reliability::BestEffort, 1)
    );
    let unlinked = QosProfile::of_link(None);
    assert_eq!(
        (unlinked.reliability, unlinked.depth),
        (Reliability::Reliable, 1)
    );
    assert_eq!(queue.durability, Durability::Volatile);
    let over = Qos {
        depth: Some(10),
        durability: Some(Durability::TransientLocal),
        ..Qos::default()
    };
    let mixed = sample.with(Some(&over));
    assert_eq!(
        (mixed.reliability, mixed.depth, mixed.durability),
        (Reliability::BestEffort, 10, Durability::TransientLocal)
    );
    assert_eq!(sample.with(None), sample);
}

/// `tests/specs/valid/minimal.ron` (c1, e1, E1 of a1; c2 of a2) with `extra`
/// inserted before its links, and `deployment` inserted in its deployment.
fn minimal(extra: &str, deployment: &str) -> Spec {
    let path = concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../tests/specs/valid/minimal.ron"
    );
    let text = std::fs::read_to_string(path)
        .unwrap()
        .replace("    links: [", &format!("{extra}\n    links: ["))
        .replace(
            "(name: \"one\", hosts:",
            &format!("(name: \"one\", {deployment} hosts:"),
        );
    crate::options().from_str(&text).unwrap()
}

#[test]
fn an_interface_applies_the_defaults_and_the_links_policies() {
    let spec = minimal(
        r#"ros2: (
            publish: [(buffer: "c1.c2.ack", topic: "ack"), (buffer: "e1.c1.done", topic: "~/done")],
            subscribe: [(buffer: "c1.c2.order", topic: "/order", message: "std_msgs/msg/Float64", qos: (depth: 1))],
        ),"#,
        "",
    );
    let shown = interface(&spec, None).unwrap();
    assert_eq!(
        (shown.domain, shown.node.as_str(), shown.namespace.as_str()),
        (0, "mini", "/")
    );
    assert_eq!(shown.package, "mini_msgs");
    let ack = &shown.publish[0];
    assert_eq!(
        (ack.name.as_str(), ack.component.as_str(), ack.ty.as_str()),
        ("/ack", "c1", "bool")
    );
    assert_eq!(
        (ack.qos.reliability, ack.qos.depth),
        (Reliability::Reliable, 2)
    );
    assert_eq!(ack.message, None);
    let done = &shown.publish[1];
    assert_eq!(done.name, "/mini/done");
    assert_eq!(
        done.qos.reliability,
        Reliability::BestEffort,
        "a sample link"
    );
    let order = &shown.subscribe[0];
    assert_eq!(order.name, "/order");
    assert_eq!(order.message.as_deref(), Some("std_msgs/msg/Float64"));
    assert_eq!(
        (order.qos.reliability, order.qos.depth),
        (Reliability::Reliable, 1)
    );
}

#[test]
fn a_deployments_section_replaces_the_systems_and_omitted_components_drop_out() {
    let system = r#"ros2: (domain: 7, node: "robot", namespace: "/lab",
        publish: [(buffer: "c1.c2.ack", topic: "ack"), (buffer: "e1.c1.done", topic: "done")]),"#;
    let own = r#"ros2: (publish: [(buffer: "c1.c2.ack", topic: "acks")]),"#;
    let spec = minimal(system, own);
    let one = spec.deployment("one").unwrap();
    let shown = interface(&spec, Some(one)).unwrap();
    assert_eq!(
        (shown.domain, shown.node.as_str()),
        (0, "mini"),
        "not merged"
    );
    assert_eq!(shown.publish.len(), 1);
    assert_eq!(shown.publish[0].name, "/acks");
    // The system's section in a deployment that does not run e1: e1's topic is left out.
    let mut spec = minimal(system, "");
    let dep = &mut spec.deployments[0];
    dep.hosts[0].processes[0].runs.retain(|r| r != "e1");
    dep.omit.push("e1".into());
    let shown = interface(&spec, spec.deployments.first()).unwrap();
    assert_eq!((shown.domain, shown.namespace.as_str()), (7, "/lab"));
    let names: Vec<&str> = shown.publish.iter().map(|t| t.name.as_str()).collect();
    assert_eq!(names, ["/lab/ack"]);
    assert_eq!(interface(&minimal("", ""), None), None, "shows nothing");
}

#[test]
fn an_outputs_policy_is_its_largest_queue() {
    let mut spec = minimal("", "");
    let mut second = spec.links[1].clone();
    second.policy = Policy::queue(9);
    spec.links.push(second);
    let mut third = spec.links[1].clone();
    third.policy = Policy::Sample;
    spec.links.push(third);
    assert_eq!(
        link_policy(&spec, "c1.c2.ack", true),
        Some(Policy::queue(9))
    );
    assert_eq!(
        link_policy(&spec, "c1.c2.order", false),
        Some(Policy::queue(2))
    );
    assert_eq!(
        link_policy(&spec, "e1.c1.speed", false),
        Some(Policy::Sample)
    );
    assert_eq!(link_policy(&spec, "c1.c2.nothing", true), None);
}

/// Every check on `name`: no panic, and an error points at bytes of `name`
/// on character boundaries, non-empty unless `name` is.
fn sound(name: &str) -> Result<(), TestCaseError> {
    for check in [
        check_topic,
        check_full_topic,
        check_namespace,
        check_node,
        check_package,
        check_message,
    ] {
        if let Err(e) = check(name) {
            prop_assert!(e.at.end <= name.len(), "{name:?}: {e:?}");
            prop_assert!(name.is_char_boundary(e.at.start) && name.is_char_boundary(e.at.end));
            prop_assert!(e.at.start < e.at.end || name.is_empty(), "{name:?}: {e:?}");
            prop_assert!(!e.to_string().is_empty());
        }
    }
    Ok(())
}

proptest! {
    #[test]
    fn arbitrary_text_never_panics_a_check(name in any::<String>()) {
        sound(&name)?;
    }

    #[test]
    fn name_like_text_never_panics_and_accepted_topics_expand_to_full_names(
        name in "[a-zA-Z0-9_/~{}: é-]{0,24}",
    ) {
        sound(&name)?;
        if check_topic(&name).is_ok() {
            for namespace in ["/", "/ns", "/a/b"] {
                let full = expand_topic(&name, "node", namespace);
                prop_assert_eq!(check_full_topic(&full), Ok(()), "{} in {}", name, namespace);
            }
        }
    }
}
