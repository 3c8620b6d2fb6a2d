//! The spec is the structure of Rex: for every deployment of `specs/rex.ron`, the
//! spec exported from the system `system::build_deployment` builds equals the spec's
//! own, restricted to the components the deployment runs: agents, components,
//! kinds, periods, memory, groups, buffers and their types, predicates, functions
//! and their targets, behaviours with their kinds, functions and terminal
//! conditions, FSM arcs with their conditions, finals, links with their policies.
//! (The functions' reads and writes of buffers are what the code does, not what it
//! states: `tests/audit.rs` observes them.)
//!
//! And the structure is reviewed: `tests/structure/<deployment>.ron` holds the
//! structure each deployment built last time it was accepted. A change of the spec
//! alone (a period, a link policy, a buffer) fails here with the line that differs
//! until the change is accepted with `UPDATE_STRUCTURE=1 cargo test -p rex-agent
//! --test structure` (and the code follows it: a buffer the code does not have
//! fails the build of the system, naming it).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use embodied::spec::export::{difference, spec_of, to_ron};
use embodied::spec::model::Spec;
use rex_agent::mission::Mission;
use rex_agent::system::{RexConfig, build_deployment, default_spec, load_spec};
use rex_agent::world::WorldConfig;

/// `spec` as deployment `name` runs it: without the omitted components and the
/// links that reach them, without deployments.
fn deployed(spec: &Spec, name: &str) -> Spec {
    let deployment = spec.deployments.iter().find(|d| d.name == name).unwrap();
    let runs: Vec<&str> = deployment.runs().collect();
    let mut out = spec.clone();
    for a in &mut out.agents {
        a.subsystems.retain(|s| runs.contains(&s.name.as_str()));
        a.devices.retain(|d| runs.contains(&d.name.as_str()));
    }
    out.agents
        .retain(|a| !(a.subsystems.is_empty() && a.devices.is_empty()));
    let component = |end: &str| end.split('.').next().unwrap_or("").to_owned();
    out.links.retain(|l| {
        runs.contains(&component(&l.from).as_str()) && runs.contains(&component(&l.to).as_str())
    });
    out.deployments.clear();
    out
}

fn config() -> RexConfig {
    let mission = Mission::shipped("square").unwrap();
    RexConfig::new(WorldConfig::shipped().unwrap(), mission)
}

fn built(config: &RexConfig, deployment: &str) -> Spec {
    let (system, _) = build_deployment(config, deployment)
        .unwrap_or_else(|e| panic!("deployment `{deployment}`: {e}"));
    spec_of("rex", system.info()).unwrap().structure()
}

fn accepted_path(deployment: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/structure")
        .join(format!("{deployment}.ron"))
}

/// Where `built` differs from the accepted structure of `deployment`.
fn unaccepted(deployment: &str, built: &Spec) -> Option<String> {
    let path = accepted_path(deployment);
    let text = std::fs::read_to_string(&path).unwrap_or_default();
    let accepted: Option<Spec> = ron::Options::default()
        .with_default_extension(ron::extensions::Extensions::IMPLICIT_SOME)
        .from_str(&text)
        .ok();
    let d = match &accepted {
        Some(a) => difference(a, built)?,
        None => format!("{} is missing or unreadable", path.display()),
    };
    Some(format!(
        "deployment `{deployment}` differs from {}: {d}\n(accept the change with UPDATE_STRUCTURE=1)",
        path.display()
    ))
}

#[test]
fn every_deployment_builds_the_accepted_structure() {
    let spec = load_spec(&default_spec()).unwrap();
    let update = std::env::var_os("UPDATE_STRUCTURE").is_some();
    for deployment in &spec.deployments {
        let built = built(&config(), &deployment.name);
        if update {
            std::fs::create_dir_all(accepted_path("x").parent().unwrap()).unwrap();
            std::fs::write(accepted_path(&deployment.name), to_ron(&built).unwrap()).unwrap();
        } else if let Some(d) = unaccepted(&deployment.name, &built) {
            panic!("{d}");
        }
    }
}

/// `specs/rex.ron` with `from` replaced by `to` once, as a file of its own.
fn edited_spec(tag: &str, from: &str, to: &str) -> RexConfig {
    let text = std::fs::read_to_string(default_spec()).unwrap();
    assert!(text.contains(from), "{from}");
    let path = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("rex_{tag}.ron"));
    std::fs::write(&path, text.replacen(from, to, 1)).unwrap();
    let mut config = config();
    config.spec = path;
    config
}

#[test]
fn a_change_of_the_spec_alone_is_named() {
    // A period: the system follows the spec, and the review names the change.
    let config = edited_spec("period", "period_ms: 50.0,", "period_ms: 40.0,");
    let d = unaccepted("simulation", &built(&config, "simulation")).expect("a difference");
    assert!(
        d.contains("period_ms: 50.0") && d.contains("period_ms: 40.0"),
        "{d}"
    );
    // A link policy.
    let config = edited_spec(
        "policy",
        r#"(from: "c1.e11.traj", to: "e11.c1.traj", policy: Queue(4)),"#,
        r#"(from: "c1.e11.traj", to: "e11.c1.traj", policy: Queue(3)),"#,
    );
    let d = unaccepted("simulation", &built(&config, "simulation")).expect("a difference");
    assert!(d.contains("Queue(4)") && d.contains("Queue(3)"), "{d}");
    // A buffer the code does not have: the system is not built, and the error
    // names the buffer and what the component has.
    let config = edited_spec(
        "buffer",
        r#"(from: "c1.e11.steps", to: "e11.c1.steps", policy: Queue(4)),"#,
        r#"(from: "c1.e11.step_count", to: "e11.c1.steps", policy: Queue(4)),"#,
    );
    let text = std::fs::read_to_string(&config.spec).unwrap();
    let text = text
        .replacen(
            r#"(name: "steps", type: "u32", doc: "steps to execute the fragment"),"#,
            r#"(name: "step_count", type: "u32", doc: "steps to execute the fragment"),"#,
            1,
        )
        .replacen(
            r#"writes: ["traj", "steps", "notify", "pose", "A4x4"]"#,
            r#"writes: ["traj", "step_count", "notify", "pose", "A4x4"]"#,
            1,
        );
    std::fs::write(&config.spec, text).unwrap();
    let err = build_deployment(&config, "simulation")
        .expect_err("the code has no such buffer")
        .to_string();
    assert!(
        err.contains("`c1` has no output buffer `e11.step_count`") && err.contains("e11.steps"),
        "{err}"
    );
}

#[test]
fn every_deployment_builds_the_structure_of_the_spec() {
    let spec = load_spec(&default_spec()).unwrap();
    assert!(spec.deployments.len() >= 3, "paper, simulation, without VO");
    for deployment in &spec.deployments {
        let (system, _) = build_deployment(&config(), &deployment.name)
            .unwrap_or_else(|e| panic!("deployment `{}`: {e}", deployment.name));
        let built = spec_of(&spec.name, system.info()).unwrap().structure();
        let expected = deployed(&spec, &deployment.name).structure();
        if let Some(d) = difference(&expected, &built) {
            // Both texts in full, to compare with a diff tool.
            let dir = std::path::Path::new(env!("CARGO_TARGET_TMPDIR")).join("structure");
            std::fs::create_dir_all(&dir).unwrap();
            let (e, b) = (
                dir.join(format!("{}.spec.ron", deployment.name)),
                dir.join(format!("{}.built.ron", deployment.name)),
            );
            std::fs::write(&e, to_ron(&expected).unwrap()).unwrap();
            std::fs::write(&b, to_ron(&built).unwrap()).unwrap();
            panic!(
                "deployment `{}`: {d}\n(in full: {} and {})",
                deployment.name,
                e.display(),
                b.display()
            );
        }
    }
}
