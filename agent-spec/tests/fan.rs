//! Fans in a spec: a group with `peers` is one group per peer, its elements
//! named `component.group[k].buffer` in links; the checker resolves each
//! element to its own peer and reports, with a span, an index the fan lacks,
//! a fan named without an index, an index on an ordinary group, and an element
//! left unlinked.

#![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

use agent_spec::{Code, Report, check_source};

/// A hub `c2` with a fan `c1` of `peers` peers `c1_0`...; robots `c1_0`... of
/// which the first `robots` exist; `links` as RON.
fn spec(peers: usize, robots: usize, links: &str) -> String {
    let names: Vec<String> = (0..peers).map(|k| format!("\"c1_{k}\"")).collect();
    let peers = names.join(", ");
    let mut agents = format!(
        r#"(
            name: "a2",
            subsystems: [(
                name: "c2",
                kind: Control,
                period_ms: 10.0,
                inputs: [(peer: "c1", peers: [{peers}], buffers: [(name: "ack", type: "u64")])],
                outputs: [(peer: "c1", peers: [{peers}], buffers: [(name: "plan", type: "u64")])],
                functions: [
                    (name: "dispatch", target: Output("c1"), reads: ["c1.ack"], writes: ["plan"]),
                ],
                behaviours: [(name: "run", kind: While, functions: ["dispatch"], terminal: "false")],
                fsm: (initial: "run"),
            )],
        ),"#
    );
    for k in 0..robots {
        agents.push_str(&format!(
            r#"(
            name: "a1_{k}",
            subsystems: [(
                name: "c1_{k}",
                kind: Control,
                period_ms: 10.0,
                inputs: [(peer: "c2", buffers: [(name: "plan", type: "u64")])],
                outputs: [(peer: "c2", buffers: [(name: "ack", type: "u64")])],
                functions: [
                    (name: "acknowledge", target: Output("c2"), reads: ["c2.plan"], writes: ["ack"]),
                ],
                behaviours: [(name: "run", kind: While, functions: ["acknowledge"], terminal: "false")],
                fsm: (initial: "run"),
            )],
        ),"#
        ));
    }
    format!("(name: \"fleet\", agents: [{agents}], links: [{links}])")
}

/// The links of robot `k` to element `k`.
fn robot_links(k: usize) -> String {
    format!(
        r#"(from: "c2.c1[{k}].plan", to: "c1_{k}.c2.plan"), (from: "c1_{k}.c2.ack", to: "c2.c1[{k}].ack"),"#
    )
}

fn report(peers: usize, robots: usize, links: &str) -> Report {
    let (spec, report) = check_source("fleet.ron", spec(peers, robots, links));
    assert!(spec.is_some(), "{}", report.render(100));
    report
}

/// The errors' codes and messages, with the text under each primary span.
fn errors(report: &Report) -> Vec<(Code, String, String)> {
    report
        .findings
        .iter()
        .filter(|f| f.severity() == agent_spec::Severity::Error)
        .map(|f| {
            let span = f.labels[0].span.clone();
            (f.code, f.message.clone(), report.source[span].to_owned())
        })
        .collect()
}

#[test]
fn every_element_linked_to_its_own_peer_checks() {
    for robots in [1, 3] {
        let links: String = (0..robots).map(robot_links).collect();
        let report = report(robots, robots, &links);
        assert_eq!(report.errors(), 0, "{}", report.render(100));
    }
}

#[test]
fn an_index_the_fan_lacks_is_an_error_at_the_link() {
    let links = format!("{}{}", robot_links(0), robot_links(1));
    // Two robots, a fan of one peer.
    let report = report(1, 2, &links);
    let errors = errors(&report);
    let lacking: Vec<_> = errors
        .iter()
        .filter(|(_, m, _)| m.contains("element 1 of fan `c1` of `c2`, which has 1 element"))
        .collect();
    assert_eq!(lacking.len(), 2, "{}", report.render(100));
    assert!(
        lacking
            .iter()
            .all(|(code, _, _)| *code == Code::UnknownBuffer)
    );
    // The span is the link end.
    assert_eq!(lacking[0].2, "c2.c1[1].plan", "{errors:?}");
}

#[test]
fn a_fan_of_no_peers_has_no_element() {
    let report = report(0, 1, &robot_links(0));
    let errors = errors(&report);
    assert!(
        errors.iter().any(|(_, m, span)| m
            .contains("indexes group `c1` of `c2`, which is not a fan")
            && span == "c2.c1[0].plan"),
        "{errors:?}"
    );
}

#[test]
fn a_fan_is_named_with_an_index() {
    let links =
        r#"(from: "c2.c1.plan", to: "c1_0.c2.plan"), (from: "c1_0.c2.ack", to: "c2.c1[0].ack"),"#;
    let report = report(1, 1, links);
    let errors = errors(&report);
    assert!(
        errors
            .iter()
            .any(|(_, m, _)| m.contains("names fan `c1` of `c2` without an element")),
        "{errors:?}"
    );
}

#[test]
fn malformed_indices_are_errors() {
    for index in ["x", "", "01", "-1", "99999999999999999999999"] {
        let links = format!(
            r#"(from: "c2.c1[{index}].plan", to: "c1_0.c2.plan"), (from: "c1_0.c2.ack", to: "c2.c1[0].ack"),"#
        );
        let report = report(1, 1, &links);
        let errors = errors(&report);
        assert!(
            errors
                .iter()
                .any(|(code, _, span)| *code == Code::UnknownBuffer
                    && span == &format!("c2.c1[{index}].plan")),
            "[{index}]: {errors:?}"
        );
    }
}

#[test]
fn an_element_must_reach_its_own_peer() {
    // Element 1 linked to robot 0 (whose group is for `c2` too): the element's
    // peer is `c1_1`, so the groups do not name each other.
    let links = format!(
        "{}{}",
        robot_links(0),
        r#"(from: "c2.c1[1].plan", to: "c1_0.c2.plan"),"#
    );
    let report = report(2, 1, &links);
    assert!(
        report.findings.iter().any(|f| f.code == Code::PeerMismatch),
        "{}",
        report.render(100)
    );
}

#[test]
fn an_unlinked_element_is_reported_by_its_index() {
    // Three peers, robots 0 and 2 linked: element 1's plan is read by nobody
    // and its ack fed by nothing.
    let links = format!("{}{}", robot_links(0), robot_links(2));
    let (_, report) = check_source("fleet.ron", spec(3, 3, &links));
    let messages: Vec<&str> = report.findings.iter().map(|f| f.message.as_str()).collect();
    assert!(
        messages.contains(&"input `c2.c1[1].ack` is fed by no output"),
        "{messages:?}"
    );
    assert!(
        messages.contains(&"output `c2.c1[1].plan` is linked to no input"),
        "{messages:?}"
    );
    assert!(
        !messages
            .iter()
            .any(|m| m.contains("c2.c1[0]") || m.contains("c2.c1[2]")),
        "{messages:?}"
    );
}

/// The fleet of three robots, all linked, with `extra` (RON fields of the
/// system: `contracts: (...)`, `ros2: (...)`) added.
fn fleet_with(extra: &str) -> (Option<agent_spec::Spec>, Report) {
    let links: String = (0..3).map(robot_links).collect();
    let text = spec(3, 3, &links);
    let text = format!("{}, {extra})", text.strip_suffix(')').unwrap());
    check_source("fleet.ron", text)
}

#[test]
fn contracts_name_one_element_or_every_element_of_a_fan() {
    let (spec, report) = fleet_with(
        r#"contracts: (
            freshness: [(input: "c2.c1[1].ack", max_age_ms: 50.0)],
            rates: [(input: "c2.c1[*].ack", min_hz: 10.0)],
            ranges: [
                (name: "plan", buffer: "c2.c1[*].plan", max: 100.0),
                (name: "ack_0", buffer: "c2.c1[0].ack", min: 0.0),
            ],
            responses: [
                (name: "acked", trigger: "c2.c1[*].plan", response: "c2.c1[*].ack", within_s: 1.0),
                (name: "first", trigger: "c2.c1[0].plan", response: "c2.c1[*].ack", within_s: 1.0),
            ],
        )"#,
    );
    assert_eq!(report.errors(), 0, "{}", report.render(100));
    let spec = spec.unwrap();
    let each = spec.contracts.as_ref().unwrap().per_element(&spec);
    let rates: Vec<&str> = each.rates.iter().map(|r| r.input.as_str()).collect();
    assert_eq!(rates, ["c2.c1[0].ack", "c2.c1[1].ack", "c2.c1[2].ack"]);
    let ranges: Vec<(&str, &str)> = each
        .ranges
        .iter()
        .map(|r| (r.name.as_str(), r.buffer.as_str()))
        .collect();
    assert_eq!(
        ranges,
        [
            ("plan[0]", "c2.c1[0].plan"),
            ("plan[1]", "c2.c1[1].plan"),
            ("plan[2]", "c2.c1[2].plan"),
            ("ack_0", "c2.c1[0].ack"),
        ]
    );
    let responses: Vec<(&str, &str, &str)> = each
        .responses
        .iter()
        .map(|r| (r.name.as_str(), r.trigger.as_str(), r.response.as_str()))
        .collect();
    assert_eq!(
        responses,
        [
            ("acked[0]", "c2.c1[0].plan", "c2.c1[0].ack"),
            ("acked[1]", "c2.c1[1].plan", "c2.c1[1].ack"),
            ("acked[2]", "c2.c1[2].plan", "c2.c1[2].ack"),
            ("first[0]", "c2.c1[0].plan", "c2.c1[0].ack"),
            ("first[1]", "c2.c1[0].plan", "c2.c1[1].ack"),
            ("first[2]", "c2.c1[0].plan", "c2.c1[2].ack"),
        ]
    );
    assert_eq!(each.freshness[0].input, "c2.c1[1].ack");
}

#[test]
fn a_contract_on_a_fan_element_the_fan_lacks_or_misnames_is_an_error_at_its_name() {
    // (the buffer as written, what the message says, what the help says)
    let cases = [
        (
            "c2.c1[5].ack",
            "names element 5 of fan `c1` of `c2`, which has 3 element(s)",
            "an index below 3",
        ),
        (
            "c2.c1_1.ack",
            "names `c1_1`, which is element 1 of fan `c1` of `c2`",
            "`c2.c1[1].ack`",
        ),
        (
            "c2.c1[*].acks",
            "names no buffer `acks` of fan `c1` of `c2`",
            "did you mean `c2.c1[*].ack`?",
        ),
        (
            "c2.c11[0].ack",
            "names fan `c11`, which `c2` does not have on that side",
            "did you mean `c1`?",
        ),
        (
            "c1_0.c2[*].plan",
            "indexes group `c2` of `c1_0`, which is not a fan",
            "a group with `peers` is a fan",
        ),
        (
            "c2.c1[03].ack",
            "does not index fan `c1` of `c2` with a number",
            "or `[*]`, every element",
        ),
    ];
    for (buffer, message, help) in cases {
        let (_, report) = fleet_with(&format!(
            r#"contracts: (rates: [(input: "{buffer}", min_hz: 10.0)])"#
        ));
        let errors: Vec<_> = report
            .findings
            .iter()
            .filter(|f| f.severity() == agent_spec::Severity::Error)
            .collect();
        assert_eq!(errors.len(), 1, "{buffer}: {}", report.render(100));
        let f = errors[0];
        assert_eq!(f.code, Code::UnknownBuffer, "{buffer}");
        assert!(f.message.contains(message), "{buffer}: {}", f.message);
        let helps = format!("{:?}", f.help);
        assert!(helps.contains(help), "{buffer}: {helps}");
        assert_eq!(&report.source[f.labels[0].span.clone()], buffer);
    }
}

#[test]
fn a_whole_fan_is_no_link_end_and_an_ordinary_group_has_no_whole_fan() {
    let links = format!(
        "{}{}",
        robot_links(0),
        r#"(from: "c2.c1[*].plan", to: "c1_1.c2.plan"),"#
    );
    let (_, report) = check_source("fleet.ron", spec(2, 2, &links));
    let every = report
        .findings
        .iter()
        .find(|f| {
            f.message
                .contains("names every element of fan `c1` of `c2`")
        })
        .unwrap_or_else(|| panic!("{}", report.render(100)));
    assert_eq!(
        &report.source[every.labels[0].span.clone()],
        "c2.c1[*].plan"
    );

    // c1_0's ordinary group is no fan: its `[*]` is refused as such.
    let (_, report) = fleet_with(
        r#"contracts: (responses: [
            (name: "bad", trigger: "c2.c1[*].plan", response: "c1_0.c2[*].ack", within_s: 1.0),
        ])"#,
    );
    assert!(
        report.findings.iter().any(|f| f
            .message
            .contains("indexes group `c2` of `c1_0`, which is not a fan")),
        "{}",
        report.render(100)
    );
}

#[test]
fn a_ros_2_entry_on_a_whole_fan_is_one_topic_per_element() {
    let (spec, report) = fleet_with(
        r#"ros2: (
            publish: [(buffer: "c2.c1[*].plan", topic: "plans"), (buffer: "c2.c1[1].plan", topic: "second")],
            subscribe: [(buffer: "c2.c1[2].ack", topic: "ack_2")],
        )"#,
    );
    assert_eq!(report.errors(), 0, "{}", report.render(100));
    let spec = spec.unwrap();
    let interface = agent_spec::ros2::interface(&spec, None).unwrap();
    let published: Vec<(&str, &str)> = interface
        .publish
        .iter()
        .map(|t| (t.buffer.as_str(), t.name.as_str()))
        .collect();
    assert_eq!(
        published,
        [
            ("c2.c1[0].plan", "/plans_0"),
            ("c2.c1[1].plan", "/plans_1"),
            ("c2.c1[2].plan", "/plans_2"),
            ("c2.c1[1].plan", "/second"),
        ]
    );
    assert_eq!(interface.subscribe[0].buffer, "c2.c1[2].ack");
    assert_eq!(interface.subscribe[0].ty, "u64");

    let (_, report) = fleet_with(r#"ros2: (publish: [(buffer: "c2.c1[7].plan", topic: "plans")])"#);
    let f = report
        .findings
        .iter()
        .find(|f| f.severity() == agent_spec::Severity::Error)
        .unwrap_or_else(|| panic!("{}", report.render(100)));
    assert!(
        f.message
            .contains("element 7 of fan `c1` of `c2`, which has 3"),
        "{}",
        f.message
    );
    assert_eq!(&report.source[f.labels[0].span.clone()], "c2.c1[7].plan");
}

#[test]
fn a_whole_fans_topics_meet_the_other_entries_and_ross_rules_element_by_element() {
    // `plans_1` is element 1's topic already; `c2.c1[2].ack` is fed by
    // element 2's `acks_2` already; `plans_` would make `plans__0`.
    let (_, report) = fleet_with(
        r#"ros2: (
            publish: [(buffer: "c2.c1[*].plan", topic: "plans"), (buffer: "c2.c1[0].plan", topic: "plans_1")],
            subscribe: [(buffer: "c2.c1[*].ack", topic: "acks"), (buffer: "c2.c1[2].ack", topic: "other")],
        )"#,
    );
    let messages: Vec<&str> = report.findings.iter().map(|f| f.message.as_str()).collect();
    assert!(
        messages.contains(
            &"topic `/plans_1` is published twice, from `c2.c1[1].plan` and `c2.c1[0].plan`"
        ),
        "{messages:#?}"
    );
    assert!(
        messages.contains(&"input `c2.c1[2].ack` is fed by two topics, `/acks_2` and `/other`"),
        "{messages:#?}"
    );
    let (_, report) =
        fleet_with(r#"ros2: (publish: [(buffer: "c2.c1[*].plan", topic: "plans_")])"#);
    assert!(
        report
            .findings
            .iter()
            .any(|f| f.code == Code::Ros2Name && f.message.contains("`/plans__0` for element 0")),
        "{}",
        report.render(100)
    );
}

#[test]
fn a_response_pairs_whole_fans_of_as_many_elements() {
    // A hub whose fan of inputs has 2 peers and whose fan of outputs 3.
    let text = r#"(name: "f", agents: [(name: "a", subsystems: [
        (
            name: "hub", kind: Control, period_ms: 10.0,
            inputs: [(peer: "from", peers: ["r0", "r1"], buffers: [(name: "ack", type: "u64")])],
            outputs: [(peer: "to", peers: ["r0", "r1", "r2"], buffers: [(name: "plan", type: "u64")])],
            behaviours: [(name: "run", kind: While, terminal: "false")], fsm: (initial: "run"),
        ),
    ])], contracts: (responses: [
        (name: "acked", trigger: "hub.to[*].plan", response: "hub.from[*].ack", within_s: 1.0),
    ]))"#;
    let (_, report) = check_source("f.ron", text);
    let f = report
        .findings
        .iter()
        .find(|f| f.code == Code::Contract)
        .unwrap_or_else(|| panic!("{}", report.render(100)));
    assert!(
        f.message.contains("response `acked` pairs fans of different sizes: `hub.to[*].plan` has 3 element(s), `hub.from[*].ack` 2"),
        "{}",
        f.message
    );
    assert_eq!(&report.source[f.labels[0].span.clone()], "hub.from[*].ack");
}
