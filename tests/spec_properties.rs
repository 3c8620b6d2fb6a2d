//! Properties of the checker: any single mutation of a valid spec (a renamed
//! reference, a changed type, a removed arc, a duplicated writer) is caught; and no
//! input, however broken, makes the checker or the diagrams panic (a bounded fuzz run
//! on every `cargo test`).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use embodied::spec::diagram::{Format, Kind, render};
use embodied::spec::model::Spec;
use embodied::spec::{Severity, check_source, options};
use proptest::prelude::*;

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

    #[test]
    fn arbitrary_bytes_never_panic(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        let text = String::from_utf8_lossy(&bytes).into_owned();
        let _ = check_source("fuzz.ron", text);
    }

    #[test]
    fn damaged_specs_never_panic(
        edits in prop::collection::vec((any::<usize>(), 0usize..40, prop::sample::select(vec!["", "(", ")", "[", "]", ",", "\"", ":", "x", "Queue(0)", "\"c1\"", "true", "-1.0", "//", "é", "\\"])), 1..6),
        kind in 0usize..3,
        format in 0usize..3,
    ) {
        let mut text = rex_text();
        for (at, len, insert) in &edits {
            let mut start = at % (text.len() + 1);
            while !text.is_char_boundary(start) { start -= 1; }
            let mut end = (start + len).min(text.len());
            while !text.is_char_boundary(end) { end -= 1; }
            text.replace_range(start..end.max(start), insert);
        }
        let (spec, report) = check_source("damaged.ron", text);
        let _ = report.render(80);
        let _ = report.short();
        if let Some(spec) = spec {
            let kind = [Kind::Fsm, Kind::Structure, Kind::Dataflow][kind];
            let format = [Format::Dot, Format::Mermaid, Format::Svg][format];
            let _ = render(&spec, kind, None, format);
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
