//! The three diagram kinds of Rex in the three formats, snapshot-tested; and the
//! guide's Mermaid FSM (docs/specs.md) is the one the tool draws.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use embodied::spec::diagram::{Format, Kind, render, render_all};
use embodied::spec::{Spec, check_file};

fn rex() -> Spec {
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("specs/rex.ron");
    let (spec, report) = check_file(&path).expect("readable");
    assert!(report.is_ok(), "{}", report.render(100));
    spec.expect("parses")
}

#[test]
fn rex_diagrams_are_stable() {
    let spec = rex();
    for kind in [Kind::Fsm, Kind::Structure, Kind::Dataflow] {
        for format in [Format::Dot, Format::Mermaid, Format::Svg] {
            let text = render(&spec, kind, None, format).unwrap();
            let again = render(&spec, kind, None, format).unwrap();
            assert_eq!(text, again, "byte-stable");
            insta::with_settings!({snapshot_path => "snapshots", prepend_module_to_snapshot => false}, {
                insta::assert_snapshot!(format!("rex_{kind}_{format}"), text);
            });
        }
    }
}

/// A folder of diagrams holds each subsystem's FSM and data flow, drawn as one
/// subsystem's, and the structure of the whole system.
#[test]
fn every_diagram_of_a_spec_is_named_for_a_folder() {
    let spec = rex();
    let files = render_all(&spec);
    let names: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
    let subsystems: Vec<String> = spec.subsystems().map(|(_, s)| s.name.clone()).collect();
    assert_eq!(files.len(), 3 * subsystems.len() + 1, "{names:?}");
    for sub in &subsystems {
        let one = Some(sub.as_str());
        for (name, kind, format) in [
            (format!("fsm_{sub}.svg"), Kind::Fsm, Format::Svg),
            (format!("fsm_{sub}.mmd"), Kind::Fsm, Format::Mermaid),
            (format!("dataflow_{sub}.svg"), Kind::Dataflow, Format::Svg),
        ] {
            let text = files.iter().find(|(n, _)| *n == name).map(|(_, t)| t);
            assert_eq!(
                text,
                Some(&render(&spec, kind, one, format).unwrap()),
                "{name}"
            );
        }
    }
    let structure = render(&spec, Kind::Structure, None, Format::Svg).unwrap();
    assert!(files.contains(&("structure.svg".to_owned(), structure)));
}

#[test]
fn one_subsystem_and_its_content() {
    let spec = rex();
    let fsm = render(&spec, Kind::Fsm, Some("c1"), Format::Dot).unwrap();
    for needle in [
        r#""c1/__start" -> "c1/B1";"#,
        r#""c1/B1" -> "c1/B2" [label="plan_valid"];"#,
        r#""c1/B2" -> "c1/B3" [label="true"];"#,
        r#""c1/B3" -> "c1/B1" [label="true"];"#,
        r#"label="B2\nrepeat until plan_sent || planner_failed || stopped""#,
    ] {
        assert!(fsm.contains(needle), "missing {needle} in\n{fsm}");
    }
    assert!(!fsm.contains("e11"), "only c1");
    let svg = render(&spec, Kind::Fsm, Some("c1"), Format::Svg).unwrap();
    assert!(svg.starts_with("<svg ") && svg.ends_with("</svg>\n"));
    let c1_arcs = spec
        .agents
        .iter()
        .flat_map(|a| &a.subsystems)
        .find(|s| s.name == "c1")
        .unwrap()
        .fsm
        .arcs
        .len();
    assert_eq!(c1_arcs, 4, "B1 -> B2, B1 -> B3, B2 -> B3, B3 -> B1");
    assert_eq!(
        svg.matches("<path d=").count(),
        c1_arcs + 1 + 1,
        "one path per arc (4), the start arrow, and the arrowhead marker's triangle"
    );
    // The structure shows each link's policy when it is a queue.
    let structure = render(&spec, Kind::Structure, Some("e11"), Format::Mermaid).unwrap();
    assert!(structure.contains("agent a1") && !structure.contains("agent a2"));
    assert!(
        structure.contains(
            r#"n_c1 -->|"pose, A4x4 (queue 8), traj (queue 4), steps (queue 4), notify (queue 4)"| n_e11"#
        ),
        "{structure}"
    );
    let err = render(&spec, Kind::Fsm, Some("c9"), Format::Svg).unwrap_err();
    assert!(err.to_string().contains("no subsystem `c9`"), "{err}");
}

#[test]
fn the_guide_shows_the_rex_fsm_as_drawn() {
    let readme =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/specs.md")).unwrap();
    let drawn = render(&rex(), Kind::Fsm, Some("c1"), Format::Mermaid).unwrap();
    let block = format!("```mermaid\n{drawn}```");
    assert!(
        readme.contains(&block),
        "docs/specs.md's Mermaid block of c1 is out of date; it should read:\n{block}"
    );
}
