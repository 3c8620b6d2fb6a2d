//! `embodied check --timing`: Rex's certificate, and a seeded defect named
//! where it is, with status 1. Needs the `cli` feature (the binary):
//! `cargo test --features cli --test spec_timing`.

#![cfg(feature = "cli")]
#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

#[path = "common/binary.rs"]
mod binary;

use binary::embodied;

#[test]
fn rex_gets_a_certificate_as_one_process_and_as_the_paper_places_it() {
    for args in [
        &["check", "--timing", "specs/rex.ron"][..],
        &[
            "check",
            "--timing",
            "specs/rex.ron",
            "--deployment",
            "paper",
        ][..],
    ] {
        let (code, out, err) = embodied(args);
        assert_eq!(code, 0, "{out}{err}");
        assert!(out.contains(": certified"), "{out}");
        assert!(out.contains("chain `mocap_to_wheels`:"), "{out}");
        assert!(out.contains("chain `camera_to_wheels`:"), "{out}");
        assert!(
            !out.contains("MISSED") && !out.contains("OVERFLOWS"),
            "{out}"
        );
    }
    // The paper's placement: e11's hop to E1 crosses hosts, with the declared 5 ms.
    let (_, out, _) = embodied(&[
        "check",
        "--timing",
        "specs/rex.ron",
        "--deployment",
        "paper",
    ]);
    assert!(out.contains("process `locomotion` on `PC1`"), "{out}");
    assert!(out.contains("latency 5 ms"), "{out}");
}

#[test]
fn a_period_changed_so_a_chain_misses_its_deadline_is_named_with_status_1() {
    let dir = std::env::temp_dir().join(format!("spec_timing_{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let text = std::fs::read_to_string("specs/rex.ron").unwrap();
    // c3, the map agent's control subsystem, at 100 ms instead of 20.
    let slow = text.replacen(
        "kind: Control,\n                    period_ms: 20.0,",
        "kind: Control,\n                    period_ms: 100.0,",
        1,
    );
    assert_ne!(slow, text, "c3's period is where this test expects it");
    let path = dir.join("rex_slow_c3.ron");
    std::fs::write(&path, slow).unwrap();
    let (code, out, err) = embodied(&["check", "--timing", path.to_str().unwrap()]);
    assert_eq!(code, 1, "{out}{err}");
    assert!(out.contains("VIOLATED") && out.contains("MISSED"), "{out}");
    assert!(
        err.contains("chain `mocap_to_wheels` can miss its deadline"),
        "{err}"
    );
    // The largest term is c3's hop: its period is in it.
    assert!(err.contains("`c3.c1.pose`: sample, M 100"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_deployment_that_does_not_exist_is_said() {
    let (code, _, err) = embodied(&[
        "check",
        "--timing",
        "specs/rex.ron",
        "--deployment",
        "papre",
    ]);
    assert_eq!(code, 1);
    assert!(err.contains("no deployment `papre`"), "{err}");
}
