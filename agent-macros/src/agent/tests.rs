//! Tests of the stages of `agent!`: arguments, loading and checking, generation.

use super::*;

const SPEC: &str = r#"(
    name: "t",
    agents: [(
        name: "a",
        subsystems: [
            (
                name: "c1", kind: Control, period_ms: 10.0,
                memory: [(name: "count", type: "u32")],
                inputs: [(peer: "e1", buffers: [(name: "done", type: "bool")])],
                outputs: [(peer: "e1", buffers: [(name: "go", type: "Option<u32>")])],
                predicates: [(name: "finished", reads: ["done"])],
                functions: [
                    (name: "ce", target: Output("e1"), writes: ["go"]),
                    (name: "cc", target: Memory, writes: ["count"]),
                ],
                behaviours: [
                    (name: "run", kind: Repeat, functions: ["ce", "cc"], terminal: "finished"),
                    (name: "rest", kind: While, terminal: "false"),
                ],
                fsm: (initial: "run", arcs: [(from: "run", to: "rest", when: "true")]),
            ),
            (
                name: "e1", kind: VirtualEffector, period_ms: 10.0,
                inputs: [(peer: "c1", buffers: [(name: "go", type: "Option<u32>")])],
                outputs: [(peer: "c1", buffers: [(name: "done", type: "bool")])],
                functions: [(name: "ec", target: Output("c1"), writes: ["done"])],
                behaviours: [(name: "serve", kind: While, functions: ["ec"], terminal: "false")],
                fsm: (initial: "serve"),
            ),
        ],
    )],
    links: [
        (from: "c1.e1.go", to: "e1.c1.go"),
        (from: "e1.c1.done", to: "c1.e1.done"),
    ],
)"#;

fn args(tokens: TokenStream) -> AgentArgs {
    parse(tokens).expect("valid arguments")
}

#[test]
fn arguments_are_named_and_required() {
    let a = args(quote!(
        spec = "s.ron",
        agent = "a1",
        memory_derive = [Default]
    ));
    assert_eq!(a.spec.value(), "s.ron");
    assert_eq!(a.memory_derive.len(), 1);
    let e = parse(quote!(spec = "s.ron")).err().expect("no agent");
    assert!(
        e.to_string().contains("agent = \\\"<name>\\\"")
            || e.to_string().contains("agent = \"<name>\""),
        "{e}"
    );
}

#[test]
fn a_spec_becomes_modules_traits_and_fsms() {
    let a = args(quote!(spec = "t.ron", agent = "a"));
    let found = load(&a.spec, SPEC.into(), &a.agent).expect("a valid spec");
    let code = generate(&found, &a, None).expect("generates").to_string();
    for needle in [
        "pub mod c1",
        "pub struct C1",
        "pub struct Memory { # [doc = \" Spec type: `u32`.\"] pub count : u32 }",
        "pub struct FromE1",
        "pub go : :: embodied :: Out < Option < u32 > >",
        "# [group (peer = VirtualEffector)]",
        "fn ce (memory : & Memory , input : & Input , output : & mut ToE1)",
        "fn cc (memory : & mut Memory , input : & Input)",
        "fn finished (memory : & Memory , input : & Input) -> bool",
        ". output (| __y | & mut __y . e1 , F :: ce) . named (\"ce\") . __at_field (\"e1\")",
        ". arc (\"run\" , \"rest\" , \"true\")",
        "pub mod e1",
    ] {
        assert!(code.contains(needle), "`{needle}` not in {code}");
    }
}

#[test]
fn checker_errors_name_file_line_and_column() {
    let a = args(quote!(spec = "t.ron", agent = "a"));
    let broken = SPEC.replace("terminal: \"finished\"", "terminal: \"finishd\"");
    let e = load(&a.spec, broken, &a.agent)
        .expect("loads")
        .errors
        .expect("unknown predicate");
    let text = e.to_string();
    assert!(text.starts_with("t.ron:17:85:"), "{text}");
    assert!(text.contains("error[spec::unknown_predicate]"), "{text}");
    let e = load(&a.spec, SPEC.into(), &syn::parse_quote!("a9"))
        .err()
        .expect("no agent");
    assert!(e.to_string().contains("its agents: a"), "{e}");
}

#[test]
fn unparsable_types_point_into_the_spec() {
    let a = args(quote!(spec = "t.ron", agent = "a"));
    let found = load(&a.spec, SPEC.replace("\"u32\"", "\"Vec<u32\""), &a.agent)
        .expect("the checker does not parse types");
    let e = generate(&found, &a, None).expect_err("bad type");
    assert!(e.to_string().contains("t.ron:8:"), "{e}");
    assert!(e.to_string().contains("memory `count`"), "{e}");
}

#[test]
fn keywords_become_raw_identifiers_and_self_is_refused() {
    assert_eq!(ident("type").to_string(), "r#type");
    assert_eq!(ident("A4x4").to_string(), "A4x4");
    // The checker refuses what can be no Rust code (one rule, agent-core's and
    // agent-spec's names), so `agent!` reports its finding.
    let a = args(quote!(spec = "t.ron", agent = "a"));
    let e = load(&a.spec, SPEC.replace("\"count\"", "\"self\""), &a.agent)
        .expect("loads")
        .errors
        .expect("refused");
    assert!(e.to_string().contains("error[spec::invalid_name]"), "{e}");
    assert!(e.to_string().contains("`self`"), "{e}");
    for (name, why) in [("__", "no Rust type name"), ("memory", "already has")] {
        let spec = SPEC.replace("e1", name);
        let e = load(&a.spec, spec, &a.agent)
            .expect("loads")
            .errors
            .expect("refused");
        assert!(e.to_string().contains(why), "{e}");
    }
    // And the generator refuses them on its own (a spec it did not check).
    let mut found = load(&a.spec, SPEC.into(), &a.agent).expect("valid");
    found.loaded.spec.agents[0].subsystems[0].memory[0].name = "self".into();
    let e = generate(&found, &a, None).expect_err("not an identifier");
    assert!(e.to_string().contains("`self`"), "{e}");
}

#[test]
fn each_finding_is_reported_once_by_the_agent_it_belongs_to() {
    const MINI: &str = include_str!("../../../tests/specs/valid/minimal.ron");
    let (a1, a2) = (syn::parse_quote!("a1"), syn::parse_quote!("a2"));
    let file: LitStr = syn::parse_quote!("mini.ron");
    let errors = |text: &str, agent: &LitStr| {
        load(&file, text.to_owned(), agent)
            .expect("loads")
            .errors
            .map(|e| e.into_iter().map(|e| e.to_string()).collect::<Vec<_>>())
            .unwrap_or_default()
    };
    // The errors of another agent are one line: how many, the first, where to look.
    let summary =
        |errors: &[String]| errors.len() == 1 && errors[0].contains("1 error outside agent `a1`");
    // In a2's subsystem: a2's finding in full; a1 says there is one elsewhere.
    let typo = MINI.replace("terminal: \"acked\"", "terminal: \"ackd\"");
    assert!(summary(&errors(&typo, &a1)), "{:?}", errors(&typo, &a1));
    let of_a2 = errors(&typo, &a2);
    assert_eq!(of_a2.len(), 1, "{of_a2:?}");
    assert!(of_a2[0].contains("spec::unknown_predicate"), "{of_a2:?}");
    assert!(of_a2[0].contains("did you mean `acked`"), "{of_a2:?}");
    // A link belongs to the agent it leaves: c2 -> c1 is a2's.
    let link = MINI.replace(
        "(from: \"c2.c1.order\", to: \"c1.c2.order\", policy: Queue(2))",
        "(from: \"c2.c1.order\", to: \"c1.c2.order\", policy: Queue(0))",
    );
    assert!(summary(&errors(&link, &a1)));
    assert!(errors(&link, &a2)[0].contains("spec::queue_bound"));
    // A finding outside every agent and link (a deployment that does not place
    // c2, pointing at the deployment's name) goes to the first agent, a1, in
    // full; a2 gets the one line.
    let unplaced = MINI.replace(
        "runs: [\"c1\", \"e1\", \"E1\", \"c2\"]",
        "runs: [\"c1\", \"e1\", \"E1\"]",
    );
    let of_a1 = errors(&unplaced, &a1);
    assert!(
        of_a1.len() == 1 && of_a1[0].contains("spec::deploy_missing"),
        "{of_a1:?}"
    );
    let of_a2 = errors(&unplaced, &a2);
    assert!(
        of_a2.len() == 1 && of_a2[0].contains("1 error outside agent `a2`"),
        "{of_a2:?}"
    );
    // The code of the agent with the finding is still generated.
    let a = args(quote!(spec = "mini.ron", agent = "a2"));
    let found = load(&a.spec, typo, &a.agent).expect("loads");
    assert!(
        generate(&found, &a, None).is_ok(),
        "items despite the finding"
    );
}

#[test]
fn a_fan_of_the_spec_is_a_fan_of_its_group_and_its_function_writes_every_element() {
    const HUB: &str = include_str!("../../../tests/fan_hub.ron");
    let a = args(quote!(spec = "fan_hub.ron", agent = "a0"));
    let found = load(&a.spec, HUB.into(), &a.agent).expect("loads");
    assert!(found.errors.is_none(), "a valid spec");
    let code = generate(&found, &a, None).expect("generates").to_string();
    for fan in ["Fan < FromRobots >", "Fan < ToRobots >"] {
        assert!(code.contains("pub robots : "), "{code}");
        assert!(code.contains(fan), "{fan} in {code}");
    }
    // `send` writes every element of the fan.
    assert!(
        code.contains(
            "fn send (memory : & Memory , input : & Input , output : & mut :: embodied :: Fan < ToRobots >)"
        ),
        "{code}"
    );
}
