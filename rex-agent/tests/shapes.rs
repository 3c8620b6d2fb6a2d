//! Every buffer Rex sends has a traceable shape, so that a recording can show
//! its values as JSON with a schema (Foxglove plots any field of them): no
//! payload hides an enum where the tracer cannot reach it.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use embodied::record::json::{json_schema, to_json};
use rex_agent::mission::Mission;
use rex_agent::payload::{Ack, AckStatus, Execution, PlanOutcome};
use rex_agent::system::{RexConfig, build_deployment};
use rex_agent::world::WorldConfig;

#[test]
fn every_buffer_of_rex_has_a_shape_and_a_schema() {
    let config = RexConfig::new(
        WorldConfig::shipped().unwrap(),
        Mission::shipped("figure_eight").unwrap(),
    );
    let (system, _) = build_deployment(&config, "simulation").unwrap();
    let links = &system.info().links;
    assert!(links.len() > 25, "{}", links.len());
    for (k, link) in links.iter().enumerate() {
        let shape = system
            .payload_shape(k)
            .unwrap_or_else(|| panic!("{}: `{}` has no shape", link.name, link.payload));
        let schema = json_schema(&shape, link.payload);
        assert!(
            schema.get("type").is_some() || schema.get("oneOf").is_some(),
            "{}: {schema}",
            link.name
        );
    }
    assert_eq!(system.payload_shape(links.len()), None, "no such link");
}

#[test]
fn acknowledgements_and_outcomes_read_as_json_without_their_types() {
    let config = RexConfig::new(
        WorldConfig::shipped().unwrap(),
        Mission::shipped("figure_eight").unwrap(),
    );
    let (system, _) = build_deployment(&config, "simulation").unwrap();
    let link = |name: &str| {
        let k = system
            .info()
            .links
            .iter()
            .position(|l| l.name == name)
            .unwrap_or_else(|| panic!("no link {name}"));
        system.payload_shape(k).unwrap()
    };
    let ack = Ack {
        plan: 2,
        status: AckStatus::Failed("the planner gave up".into()),
    };
    assert_eq!(
        to_json(
            &link("c1.c2.ack -> c2.c1.ack"),
            &postcard::to_allocvec(&ack).unwrap()
        )
        .unwrap(),
        serde_json::to_value(&ack).unwrap()
    );
    let outcome = PlanOutcome {
        plan: 1,
        epoch: 0,
        result: Execution::Reached { error_m: 0.004 },
    };
    assert_eq!(
        to_json(
            &link("c1.c2.outcome -> c2.c1.outcome"),
            &postcard::to_allocvec(&outcome).unwrap()
        )
        .unwrap(),
        serde_json::to_value(&outcome).unwrap()
    );
}
