//! The checker against hostile specs: what crashed it, made it run away or echo its
//! input, now gets a clear finding at a bounded cost.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use embodied::spec::{Code, Report, check_source};

fn minimal() -> String {
    std::fs::read_to_string(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/specs/valid/minimal.ron"
    ))
    .unwrap()
}

/// `minimal.ron` with `c2`'s predicates, its behaviours after `wait`, and the arcs
/// from `wait` replaced.
fn with_c2(predicates: &[String], behaviours: &[String], arcs: &[String]) -> String {
    let mut preds = vec![r#"(name: "acked", reads: ["ack"])"#.to_owned()];
    preds.extend_from_slice(predicates);
    let mut arcs = arcs.to_vec();
    if arcs.is_empty() {
        arcs.push(r#"(from: "wait", to: "ask", when: "true")"#.into());
    }
    minimal()
        .replace(
            r#"predicates: [(name: "acked", reads: ["ack"])],"#,
            &format!("predicates: [{}],", preds.join(", ")),
        )
        .replace(
            r#"                        (name: "wait", kind: While, terminal: "acked"),"#,
            &format!(
                r#"                        (name: "wait", kind: While, terminal: "acked"),
{}"#,
                behaviours.join("\n")
            ),
        )
        .replace(
            r#"(from: "wait", to: "ask", when: "true"),"#,
            &format!("{},", arcs.join(",\n")),
        )
}

fn codes(report: &Report) -> Vec<Code> {
    report.findings.iter().map(|f| f.code).collect()
}

#[test]
fn deeply_nested_conditions_are_a_syntax_error_not_a_stack_overflow() {
    // Before: 20,000 nested parentheses (or 50,000 `!`) overflowed the stack of the
    // condition parser the checker and the FSM builder share (exit 134).
    for condition in [
        format!("{}acked{}", "(".repeat(20_000), ")".repeat(20_000)),
        format!("{}acked", "!".repeat(50_000)),
    ] {
        let text = with_c2(
            &[],
            &[],
            &[format!(r#"(from: "wait", to: "ask", when: "{condition}")"#)],
        );
        let (_, report) = check_source("deep.ron", text);
        assert!(
            codes(&report).contains(&Code::ConditionSyntax),
            "{}",
            report.short()
        );
        let f = report
            .findings
            .iter()
            .find(|f| f.code == Code::ConditionSyntax)
            .unwrap();
        assert!(
            f.labels[0].text.contains("nest more than 64 levels"),
            "{f:?}"
        );
        assert!(
            f.message.len() < 200,
            "the message quotes an excerpt: {}",
            f.message
        );
        let rendered = report.render(100);
        assert!(rendered.len() < 20_000, "{} bytes", rendered.len());
    }
}

#[test]
fn a_finding_past_column_65535_renders_as_an_excerpt() {
    // Before: miette panicked ("Formatting argument out of range") drawing a label
    // that far along a line.
    let condition = format!("{} || nosuch", vec!["acked"; 14_000].join(" || "));
    let text = with_c2(
        &[],
        &[],
        &[format!(r#"(from: "wait", to: "ask", when: "{condition}")"#)],
    );
    let (_, report) = check_source("long.ron", text);
    let f = report
        .findings
        .iter()
        .find(|f| f.code == Code::UnknownPredicate)
        .expect("the unknown predicate");
    let (_, col) = report.line_col(f.offset());
    assert!(col > 65_535, "column {col}");
    let rendered = report.render(100);
    assert!(rendered.contains(&format!("long.ron:{}:{col}", report.line_col(f.offset()).0)));
    assert!(rendered.contains("   │ …"), "an excerpt: {rendered}");
    assert!(rendered.contains("acked || nosuch\"),"), "{rendered}");
    assert!(rendered.contains("^^^^^^ not declared"), "{rendered}");
    assert!(
        rendered.len() < 5_000,
        "no echo of the line: {} bytes",
        rendered.len()
    );
}

/// Random 3-CNF over `vars` predicates, `clauses` clauses (a small xorshift).
fn cnf(seed: &mut u64, vars: usize, clauses: usize) -> String {
    let mut next = || {
        *seed ^= *seed << 13;
        *seed ^= *seed >> 7;
        *seed ^= *seed << 17;
        *seed
    };
    (0..clauses)
        .map(|_| {
            let lits: Vec<String> = (0..3)
                .map(|_| {
                    let v = next() as usize % vars;
                    let neg = if next() % 2 == 0 { "!" } else { "" };
                    format!("{neg}p{v}")
                })
                .collect();
            format!("({})", lits.join(" || "))
        })
        .collect::<Vec<_>>()
        .join(" && ")
}

#[test]
fn the_proof_of_ten_arcs_of_random_3_cnf_over_60_predicates_is_decided() {
    // Before: 58 s (the DPLL re-evaluated every formula at every step); forty such
    // arcs did not finish in 180 s. Each arc is 250 clauses over 60 predicates,
    // near the hardness threshold; the arcs cannot hold together, and do not cover
    // every case.
    let preds: Vec<String> = (0..60)
        .map(|i| format!(r#"(name: "p{i}", reads: ["ack"])"#))
        .collect();
    let behaviours: Vec<String> = (0..10)
        .map(|i| format!(r#"(name: "b{i}", kind: Repeat, terminal: "true"),"#))
        .collect();
    let mut seed = 0x2545_f491_4f6c_dd1d;
    let mut arcs: Vec<String> = (0..10)
        .map(|i| {
            format!(
                r#"(from: "wait", to: "b{i}", when: "{}")"#,
                cnf(&mut seed, 60, 250)
            )
        })
        .collect();
    arcs.extend((0..10).map(|i| format!(r#"(from: "b{i}", to: "ask", when: "true")"#)));
    let (_, report) = check_source("cnf.ron", with_c2(&preds, &behaviours, &arcs));
    let c = codes(&report);
    assert!(c.contains(&Code::ArcsIncomplete), "{}", report.short());
    assert!(!c.contains(&Code::ProofBudget), "{}", report.short());
    assert!(!c.contains(&Code::ArcsOverlap), "{}", report.short());
}

#[test]
fn a_parity_condition_and_its_negation_are_proven_exclusive_and_complete() {
    // Before: a 2 MB XOR over 16 predicates ran for over 300 s. Here the parity of
    // 12 predicates as a DNF (2,048 terms, 200 KB): the arcs `parity` and
    // `!(parity)` are exclusive and complete, and the proof says so.
    let n = 12;
    let preds: Vec<String> = (0..n)
        .map(|i| format!(r#"(name: "q{i}", reads: ["ack"])"#))
        .collect();
    let terms: Vec<String> = (0..1u32 << n)
        .filter(|m| m.count_ones() % 2 == 1)
        .map(|m| {
            let lits: Vec<String> = (0..n)
                .map(|k| format!("{}q{k}", if m >> k & 1 == 1 { "" } else { "!" }))
                .collect();
            format!("({})", lits.join(" && "))
        })
        .collect();
    let parity = terms.join(" || ");
    let behaviours = vec![r#"(name: "odd", kind: Repeat, terminal: "true"),"#.to_owned()];
    let arcs = vec![
        format!(r#"(from: "wait", to: "odd", when: "{parity}")"#),
        format!(r#"(from: "wait", to: "ask", when: "!({parity})")"#),
        r#"(from: "odd", to: "ask", when: "true")"#.to_owned(),
    ];
    let (_, report) = check_source("parity.ron", with_c2(&preds, &behaviours, &arcs));
    assert!(report.findings.is_empty(), "{}", report.short());
}

#[test]
fn many_findings_render_in_bounded_text() {
    // 20,000 terminal conditions naming undeclared predicates, among 20,000
    // declared: before, each finding rebuilt and listed the 20,000 names (33 s, 3 GB)
    // and drawing each scanned the file from its start (100,000 findings: 70 s).
    let preds: Vec<String> = (0..20_000)
        .map(|i| format!(r#"(name: "p{i}", reads: ["ack"])"#))
        .collect();
    let behaviours: Vec<String> = (0..20_000)
        .map(|i| format!(r#"(name: "b{i}", kind: Repeat, terminal: "q{i}"),"#))
        .collect();
    let (_, report) = check_source("many.ron", with_c2(&preds, &behaviours, &[]));
    let unknown = report
        .findings
        .iter()
        .filter(|f| f.code == Code::UnknownPredicate)
        .count();
    assert_eq!(unknown, 20_000);
    let f = report
        .findings
        .iter()
        .find(|f| f.code == Code::UnknownPredicate)
        .unwrap();
    assert!(f.help.contains("… (20001 in all)"), "{}", f.help);
    let rendered = report.render(100);
    assert!(
        rendered.contains(&format!(
            "... and {} more findings",
            report.findings.len() - Report::RENDER_MAX
        )),
        "{}",
        &rendered[rendered.len() - 300..]
    );
    assert!(rendered.len() < 3_000_000, "{} bytes", rendered.len());
    assert_eq!(report.short().lines().count(), report.findings.len());
}

#[test]
fn garbage_is_not_echoed() {
    // Before: a 10 MB garbage file made 55 MB of error text. A megabyte of garbage
    // on one line: one finding, a short excerpt.
    let garbage: String = (0..1_000_000u32)
        .map(|i| char::from(b"abc(,:]\"{0 "[(i * 7 % 11) as usize]))
        .collect();
    let (_, report) = check_source("garbage.ron", garbage);
    assert_eq!(report.findings.len(), 1);
    let rendered = report.render(100);
    assert!(
        rendered.len() < 2_000,
        "{} bytes:\n{rendered}",
        rendered.len()
    );
}

#[test]
fn a_byte_order_mark_is_skipped() {
    // Before: `Expected opening '('` at 1:1.
    let (spec, report) = check_source("bom.ron", format!("\u{feff}{}", minimal()));
    assert!(spec.is_some());
    assert!(report.findings.is_empty(), "{}", report.short());
}

#[test]
fn a_file_that_is_not_utf8_is_a_finding_with_its_position() {
    // Before: "stream did not contain valid UTF-8", without a position.
    let dir = std::env::temp_dir().join(format!("spec-hostile-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("latin1.ron");
    let mut bytes = minimal().into_bytes();
    let at = bytes.windows(6).position(|w| w == b"\"mini\"").unwrap() + 5;
    bytes.insert(at, 0xe9); // `é` in Latin-1
    std::fs::write(&path, &bytes).unwrap();
    let (spec, report) = embodied::spec::check_file(&path).unwrap();
    assert!(spec.is_none());
    assert_eq!(codes(&report), [Code::Encoding]);
    let line = report.short();
    assert!(
        line.contains(
            ":5:16: error[spec::encoding]: the file is not UTF-8 text: byte 0xe9 at 5:16"
        ),
        "{line}"
    );
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn diagrams_do_not_run_the_proof() {
    // The pigeonhole of the corpus spends the proof's whole budget; the structure
    // a diagram needs is checked without it.
    let path = std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/tests/specs/invalid/proof_budget.ron"
    ));
    let (spec, report) = embodied::spec::check_file_structure(path).unwrap();
    assert!(spec.is_some());
    assert!(report.findings.is_empty(), "{}", report.short());
    let (_, full) = embodied::spec::check_file(path).unwrap();
    assert_eq!(codes(&full), [Code::ProofBudget]);
}

#[test]
fn the_checker_refuses_every_name_and_period_the_code_generators_and_the_runtime_refuse() {
    // Before: `check` and `new` accepted `self`, `Self`, `super`, `crate`, `_`, an
    // empty or NUL-holding system name, which `agent!` refused; periods of 1e-7 ms
    // (0 ns, a `PeriodError` at run time) and 1e308 ms (saturated) passed.
    let base = minimal();
    for name in ["self", "Self", "super", "crate", "_"] {
        let text = base.replace(
            r#"(name: "count", type: "u32")"#,
            &format!(r#"(name: "{name}", type: "u32")"#),
        );
        let (_, report) = check_source("names.ron", text);
        assert!(
            codes(&report).contains(&Code::InvalidName),
            "{name}: {}",
            report.short()
        );
        assert!(
            embodied::names::check(name).is_err(),
            "the runtime's rule agrees"
        );
    }
    for system in ["", "a\0b", "two words"] {
        let text = base.replace(r#"name: "mini","#, &format!("name: {system:?},"));
        let (_, report) = check_source("system.ron", text);
        assert!(
            report
                .short()
                .contains("error[spec::invalid_name]: system name"),
            "{system:?}: {}",
            report.short()
        );
    }
    // A component whose type name would clash with its generated module's types.
    let text = base.replace(r#"name: "e1","#, r#"name: "memory","#);
    let (_, report) = check_source("component.ron", text);
    assert!(
        report
            .short()
            .contains("component name `memory` makes the type name `Memory`"),
        "{}",
        report.short()
    );
    for ms in ["1e-7", "1e308", "0.0", "-5.0"] {
        let text = base.replace("period_ms: 10.0,", &format!("period_ms: {ms},"));
        let (_, report) = check_source("period.ron", text);
        assert!(
            codes(&report).contains(&Code::Period),
            "{ms}: {}",
            report.short()
        );
        let runtime = embodied::Period::from_millis_f64(ms.parse().unwrap());
        assert!(runtime.is_err(), "the runtime's rule agrees: {ms}");
    }
    let text = base.replace("period_ms: 10.0,", "period_ms: 0.000001,");
    let (_, report) = check_source("period.ron", text);
    assert!(!codes(&report).contains(&Code::Period), "1 ns is a period");
}

#[test]
fn an_unfed_input_is_offered_an_output_that_exists() {
    // c2 sends its order under another name, and nobody links it: the help names
    // c2's output of the same type, not a `c2.c1.order` that does not exist.
    let source = minimal()
        .replace(
            r#"outputs: [(peer: "c1", buffers: [(name: "order", type: "f64")])],"#,
            r#"outputs: [(peer: "c1", buffers: [(name: "command", type: "f64")])],"#,
        )
        .replace(
            r#"functions: [(name: "send", target: Output("c1"), writes: ["order"])],"#,
            r#"functions: [(name: "send", target: Output("c1"), writes: ["command"])],"#,
        )
        .replace(
            r#"        (from: "c2.c1.order", to: "c1.c2.order", policy: Queue(2)),"#,
            "",
        );
    let (_, report) = check_source("unfed.ron", source);
    let unfed = report
        .findings
        .iter()
        .find(|f| f.code == Code::UnfedInput)
        .expect("c1.c2.order is unfed");
    assert!(
        unfed
            .help
            .contains(r#"(from: "c2.c1.command", to: "c1.c2.order")"#),
        "{}",
        unfed.help
    );
    // Without any output of that type towards c2 (c1 sends `ack` as a `u8`), the
    // help says what to add.
    let source = minimal()
        .replace(
            r#"(name: "ack", type: "bool")]),"#,
            r#"(name: "ack", type: "u8")]),"#,
        )
        .replace(
            r#"        (from: "c1.c2.ack", to: "c2.c1.ack", policy: Queue(2)),"#,
            "",
        );
    let (_, report) = check_source("unfed.ron", source);
    let unfed = report
        .findings
        .iter()
        .find(|f| f.code == Code::UnfedInput)
        .expect("c2.c1.ack is unfed");
    assert!(
        unfed
            .help
            .contains(r#"add `(name: "ack", type: "bool")` to its outputs towards `c2`"#),
        "{}",
        unfed.help
    );
}

#[test]
fn unknown_names_get_a_did_you_mean() {
    let source = minimal().replace(
        r#"(from: "idle", to: "move", when: "true"),"#,
        r#"(from: "idle", to: "mvoe", when: "true"),"#,
    );
    let (_, report) = check_source("typo.ron", source);
    let f = report
        .findings
        .iter()
        .find(|f| f.code == Code::UnknownBehaviour)
        .expect("mvoe is unknown");
    assert!(f.help.starts_with("did you mean `move`?"), "{}", f.help);
    let source = minimal().replace(
        r#"(from: "c1.e1.speed", to: "e1.c1.speed"),"#,
        r#"(from: "c11.e1.speed", to: "e1.c1.speed"),"#,
    );
    let (_, report) = check_source("typo.ron", source);
    let f = report
        .findings
        .iter()
        .find(|f| f.code == Code::UnknownComponent)
        .expect("c11 is unknown");
    assert!(f.help.starts_with("did you mean `c1`?"), "{}", f.help);
}
