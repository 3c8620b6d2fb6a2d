//! Properties of the checker: any single mutation of a valid spec (a renamed
//! reference, a changed type, a removed arc, a duplicated writer) is caught; and no
//! input, however broken, makes the loader, the span index, the checker, the report
//! or the diagrams panic, and every report stays well formed.
//!
//! The `never_panic_*` properties are the fuzzer: arbitrary bytes, soups of RON
//! tokens, and real specs (`specs/rex.ron` and the corpus of `tests/specs/`) damaged at
//! the byte, token, line and entry level (delete, duplicate, swap, insert punctuation,
//! copy one name over another). Every `cargo test` runs a short bounded pass;
//! `.ci/run` runs a longer one:
//!
//! ```text
//! PROPTEST_CASES=10000 cargo test -p embodied --test spec_properties never_panic
//! ```

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::ops::Range;

use embodied::spec::diagram::{Format, Kind, render};
use embodied::spec::model::Spec;
use embodied::spec::span::{self, SKind, SNode};
use embodied::spec::{Report, Severity, check_source, options};
use proptest::prelude::*;
use proptest::strategy::ValueTree;
use proptest::test_runner::TestRunner;

#[path = "spec_properties/damage.rs"]
mod damage;
use damage::*;

fn rex_text() -> String {
    std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/specs/rex.ron"))
        .expect("readable")
}

fn rex() -> Spec {
    options().from_str(&rex_text()).expect("rex.ron parses")
}

#[derive(Clone, Debug)]
enum Mutation {
    /// Rename the target of a reference: (which kind of reference, which one).
    Rename(u8, usize),
    /// Change the type of a linked input buffer.
    ChangeType(usize),
    /// Remove an arc.
    RemoveArc(usize),
    /// Feed an input a second time.
    DuplicateWriter(usize),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (0u8..7, any::<usize>()).prop_map(|(k, i)| Mutation::Rename(k, i)),
        any::<usize>().prop_map(Mutation::ChangeType),
        any::<usize>().prop_map(Mutation::RemoveArc),
        any::<usize>().prop_map(Mutation::DuplicateWriter),
    ]
}

/// Apply `m`; returns a description, or `None` if it does not apply to this spec.
fn apply(spec: &mut Spec, m: &Mutation) -> Option<String> {
    let subs: Vec<(usize, usize)> = spec
        .agents
        .iter()
        .enumerate()
        .flat_map(|(a, ag)| (0..ag.subsystems.len()).map(move |s| (a, s)))
        .collect();
    match *m {
        Mutation::Rename(kind, i) => {
            let (a, s) = subs[i % subs.len()];
            let sub = &mut spec.agents[a].subsystems[s];
            let pick = |n: usize| (n > 0).then(|| i / subs.len() % n);
            match kind {
                0 => {
                    // A function used by a behaviour.
                    let b = pick(sub.behaviours.len())?;
                    let fs = &mut sub.behaviours[b].functions;
                    let k = pick(fs.len())?;
                    fs[k].push('x');
                    Some(format!("function {} of {}", fs[k], sub.name))
                }
                1 => {
                    let k = pick(sub.fsm.arcs.len())?;
                    sub.fsm.arcs[k].to.push('x');
                    Some(format!("arc target in {}", sub.name))
                }
                2 => {
                    let k = pick(sub.predicates.len())?;
                    sub.predicates[k].name.push('x');
                    Some(format!(
                        "predicate {} of {}",
                        sub.predicates[k].name, sub.name
                    ))
                }
                3 => {
                    let k = pick(sub.inputs.len())?;
                    sub.inputs[k].peer.push('x');
                    Some(format!("input group peer of {}", sub.name))
                }
                4 => {
                    let f = pick(sub.functions.len())?;
                    let reads = &mut sub.functions[f].reads;
                    let k = pick(reads.len())?;
                    reads[k].push('x');
                    Some(format!("a read of {}", sub.functions[f].name))
                }
                5 => {
                    let k = i % spec.links.len();
                    spec.links[k].from.push('x');
                    Some(format!("link source {}", spec.links[k].from))
                }
                _ => {
                    let k = i % spec.links.len();
                    spec.links[k].to.push('x');
                    Some(format!("link destination {}", spec.links[k].to))
                }
            }
        }
        Mutation::ChangeType(i) => {
            let k = i % spec.links.len();
            let to = spec.links[k].to.clone();
            let parts: Vec<&str> = to.split('.').collect();
            for agent in &mut spec.agents {
                let groups = agent
                    .subsystems
                    .iter_mut()
                    .filter(|s| s.name == parts[0])
                    .flat_map(|s| s.inputs.iter_mut())
                    .chain(
                        agent
                            .devices
                            .iter_mut()
                            .filter(|d| d.name == parts[0])
                            .flat_map(|d| d.inputs.iter_mut()),
                    );
                for g in groups.filter(|g| g.peer == parts[1]) {
                    if let Some(b) = g.buffers.iter_mut().find(|b| b.name == parts[2]) {
                        b.ty = format!("Mutated<{}>", b.ty);
                        return Some(format!("type of {to}"));
                    }
                }
            }
            None
        }
        Mutation::RemoveArc(i) => {
            let with_arcs: Vec<(usize, usize)> = subs
                .iter()
                .copied()
                .filter(|&(a, s)| !spec.agents[a].subsystems[s].fsm.arcs.is_empty())
                .collect();
            let (a, s) = with_arcs[i % with_arcs.len()];
            let arcs = &mut spec.agents[a].subsystems[s].fsm.arcs;
            let arc = arcs.remove(i / with_arcs.len() % arcs.len());
            Some(format!("arc {} -> {}", arc.from, arc.to))
        }
        Mutation::DuplicateWriter(i) => {
            let k = i % spec.links.len();
            let link = spec.links[k].clone();
            spec.links.push(link);
            Some(format!("second writer of {}", spec.links[k].to))
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn single_mutations_of_rex_are_caught(m in mutation()) {
        let mut spec = rex();
        if let Some(what) = apply(&mut spec, &m) {
            let text = ron::ser::to_string_pretty(&spec, ron::ser::PrettyConfig::default()).unwrap();
            let (parsed, report) = check_source("mutated.ron", text);
            prop_assert!(parsed.is_some(), "the mutated spec must still parse:\n{}", report.render(100));
            prop_assert!(
                report.findings.iter().any(|f| f.severity() == Severity::Error),
                "mutation {m:?} ({what}) was not caught"
            );
        }
    }
}

#[test]
fn an_unmutated_round_trip_is_clean() {
    let text = ron::ser::to_string_pretty(&rex(), ron::ser::PrettyConfig::default()).unwrap();
    let (spec, report) = check_source("round_trip.ron", text);
    assert_eq!(spec, Some(rex()));
    assert!(report.findings.is_empty(), "{}", report.render(100));
}

#[test]
fn every_mutation_kind_applies_to_rex() {
    // Guard against a mutation that silently never applies (a property that cannot fail).
    for m in [
        Mutation::Rename(0, 0),
        Mutation::Rename(1, 0),
        Mutation::Rename(2, 0),
        Mutation::Rename(3, 0),
        Mutation::Rename(4, 0),
        Mutation::Rename(5, 0),
        Mutation::Rename(6, 0),
        Mutation::ChangeType(0),
        Mutation::RemoveArc(0),
        Mutation::DuplicateWriter(0),
    ] {
        assert!(apply(&mut rex(), &m).is_some(), "{m:?} does not apply");
    }
}

// ---------------------------------------------------------------------------
// The fuzzer.

/// Cases per fuzz property: `PROPTEST_CASES` if set (the bounded fuzz step of
/// `.ci/run` sets it), else `default` (the short pass of every `cargo test`).
fn fuzz_config(default: u32) -> ProptestConfig {
    let cases = std::env::var("PROPTEST_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(default);
    ProptestConfig {
        cases,
        failure_persistence: None,
        // A failure is shrunk for at most a minute, so that a bounded run still
        // prints its minimal input.
        max_shrink_time: 60_000,
        ..ProptestConfig::default()
    }
}

/// The span tree is well nested: children inside their parent, whole characters.
fn assert_spans_nest(text: &str, node: &SNode, within: &Range<usize>) {
    let s = &node.span;
    assert!(
        within.start <= s.start && s.start <= s.end && s.end <= within.end,
        "span {s:?} outside {within:?}"
    );
    assert!(text.is_char_boundary(s.start) && text.is_char_boundary(s.end));
    let children: Vec<&SNode> = match &node.kind {
        SKind::Struct { fields, .. } => {
            for f in fields {
                assert!(s.start <= f.key_span.start && f.key_span.end <= s.end);
                assert_eq!(&text[f.key_span.clone()], f.key);
            }
            fields.iter().map(|f| &f.value).collect()
        }
        SKind::Tuple { items, .. } | SKind::List(items) => items.iter().collect(),
        SKind::Map(entries) => entries.iter().flat_map(|(k, v)| [k, v]).collect(),
        SKind::Str { content, .. } => {
            assert!(
                s.start < content.start && content.end < s.end,
                "{s:?} {content:?}"
            );
            Vec::new()
        }
        SKind::Atom => Vec::new(),
    };
    for c in children {
        assert_spans_nest(text, c, s);
    }
}

/// Load, check, render and draw `text`; panics (failing the property) if anything
/// panics or a report is malformed. Returns whether the spec loaded.
fn exercise(text: &str, draw: bool) -> bool {
    if let Some(root) = span::parse(text) {
        assert_spans_nest(text, &root, &(0..text.len()));
    }
    let (spec, report) = check_source("fuzz.ron", text);
    assert_report_well_formed(&report);
    let _ = report.render(80);
    let _ = report.short();
    if let (Some(spec), true) = (&spec, draw) {
        let first = spec
            .agents
            .iter()
            .flat_map(|a| &a.subsystems)
            .map(|s| s.name.as_str())
            .next();
        for kind in [Kind::Fsm, Kind::Structure, Kind::Dataflow] {
            for format in [Format::Dot, Format::Mermaid, Format::Svg] {
                let _ = render(spec, kind, None, format);
            }
            let _ = render(spec, kind, first, Format::Svg);
        }
    }
    spec.is_some()
}

/// Findings are sorted (root causes first, each part by position), each has a
/// message and a help line, and every label is a range of whole characters of the
/// source.
fn assert_report_well_formed(report: &Report) {
    let keys: Vec<(bool, usize)> = report
        .findings
        .iter()
        .map(|f| (!f.code.is_root_cause(), f.offset()))
        .collect();
    assert!(keys.windows(2).all(|w| w[0] <= w[1]), "{keys:?}");
    for f in &report.findings {
        assert!(!f.message.is_empty() && !f.help.is_empty(), "{f:?}");
        for l in &f.labels {
            let s = &l.span;
            assert!(
                s.start <= s.end && s.end <= report.source.len(),
                "label {s:?} outside the source ({} bytes): {f:?}",
                report.source.len()
            );
            assert!(
                report.source.is_char_boundary(s.start) && report.source.is_char_boundary(s.end),
                "label {s:?} splits a character: {f:?}"
            );
        }
    }
}

proptest! {
    #![proptest_config(fuzz_config(256))]

    #[test]
    fn never_panic_on_arbitrary_bytes(
        bytes in prop::collection::vec(any::<u8>(), 0..2000),
        unicode in "\\PC{0,300}",
    ) {
        exercise(&String::from_utf8_lossy(&bytes), true);
        exercise(&unicode, true);
    }

    #[test]
    fn never_panic_on_token_soup(text in token_soup()) {
        exercise(&text, true);
    }

    #[test]
    fn never_panic_on_damaged_specs(damaged in damaged_spec()) {
        exercise(&damaged.text, true);
    }
}

#[test]
fn the_damaged_specs_reach_the_checker() {
    // A fuzzer whose damage always breaks the syntax would only test the parser: a
    // fair share of damaged specs still load, and many of those have findings their
    // seed does not have (the checker sees the damage).
    let codes = |text: &str| {
        let (_, report) = check_source("seed.ron", text);
        let mut codes: Vec<_> = report.findings.iter().map(|f| f.code).collect();
        codes.sort();
        codes.dedup();
        codes
    };
    let seed_codes: Vec<_> = SEEDS.iter().map(|(_, text)| codes(text)).collect();
    let mut runner = TestRunner::deterministic();
    let strategy = damaged_spec();
    let (mut loaded, mut new_findings) = (0, 0);
    let n = 400;
    for _ in 0..n {
        let Damaged { seed, text, .. } = strategy.new_tree(&mut runner).unwrap().current();
        let (spec, _) = check_source("damaged.ron", text.as_str());
        if spec.is_some() {
            loaded += 1;
            if codes(&text).iter().any(|c| !seed_codes[seed].contains(c)) {
                new_findings += 1;
            }
        }
    }
    assert!(loaded * 7 >= n, "only {loaded} of {n} damaged specs load");
    assert!(
        new_findings * 10 >= n,
        "only {new_findings} of {n} damaged specs load with new kinds of findings"
    );
    println!("{loaded} of {n} damaged specs load, {new_findings} with new kinds of findings");
}

#[test]
fn the_damage_applies_as_described() {
    let text = "(a: \"x y\", b: [1, 2])\n// c\nz\n";
    let ts = tokens(text);
    assert_eq!(
        ts.iter().map(|r| r.start).collect::<Vec<_>>()[..4],
        [0, 1, 2, 3]
    );
    assert_eq!(
        ts.iter().map(|r| r.end).max(),
        Some(text.len()),
        "tokens tile the text"
    );
    assert!(ts.windows(2).all(|w| w[0].end == w[1].start));
    let token_texts: Vec<&str> = ts.iter().map(|r| &text[r.clone()]).collect();
    assert!(token_texts.contains(&"\"x y\"") && token_texts.contains(&"// c"));
    let run = |d: Damage| {
        let mut t = text.to_owned();
        apply_damage(&mut t, &d);
        t
    };
    assert_eq!(run(Damage::DeleteToken(4)), "(a: , b: [1, 2])\n// c\nz\n");
    assert_eq!(
        run(Damage::DuplicateToken(1)),
        "(aa: \"x y\", b: [1, 2])\n// c\nz\n"
    );
    assert_eq!(
        run(Damage::SwapTokens(1, 7)),
        "(b: \"x y\", a: [1, 2])\n// c\nz\n"
    );
    assert_eq!(
        run(Damage::CopyToken { to: 7, from: 0 }),
        "(a: \"x y\", a: [1, 2])\n// c\nz\n",
        "a word is replaced by a word"
    );
    assert_eq!(
        run(Damage::SwapLines(0, 2)),
        "z\n// c\n(a: \"x y\", b: [1, 2])\n"
    );
    assert_eq!(
        run(Damage::DuplicateLine(1)),
        "(a: \"x y\", b: [1, 2])\n// c\n// c\nz\n"
    );
    assert_eq!(run(Damage::DeleteLine(0)), "// c\nz\n");
    assert_eq!(
        run(Damage::DeleteBytes { at: 1, len: 3 }),
        "(\"x y\", b: [1, 2])\n// c\nz\n"
    );
    assert_eq!(
        run(Damage::SwapBytes {
            at: 1,
            other: 11,
            len: 1
        }),
        "(b: \"x y\", a: [1, 2])\n// c\nz\n"
    );
    assert_eq!(
        run(Damage::InsertAtByte { at: 0, what: "é" }),
        "é(a: \"x y\", b: [1, 2])\n// c\nz\n"
    );
    // Byte positions in the middle of a character move back to its start.
    let mut t = "aé".to_owned();
    apply_damage(&mut t, &Damage::DeleteBytes { at: 2, len: 2 });
    assert_eq!(t, "a");
    assert!(SEEDS.len() > 30, "rex and the corpus are seeds");
}
