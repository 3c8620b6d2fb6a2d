//! The fleet's one `c2`, built with a `Fan` of the robots' `c1_k`, exports as
//! the fleet's spec says it: the same fan (`c1`, its peers `c1_0`... in
//! order, on both sides), links naming its elements, and the exported spec,
//! as RON text read back, passes the checker (with visual odometry: every
//! group of every robot linked).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use embodied::spec::export::{spec_of, to_ron};
use rex_agent::fleet::{self, Fleet, Warehouse};

#[test]
fn the_fleets_c2_exports_its_fan_as_the_fleets_spec_has_it() {
    let fleet = Fleet::in_warehouse(Warehouse::short(3), true).unwrap();
    let spec = fleet.spec();
    let (system, _) = fleet::build(&spec, fleet.deployment(), &fleet.configs().unwrap()).unwrap();
    let exported = spec_of(&spec.name, system.info()).unwrap();
    let text = to_ron(&exported).unwrap();
    let (read, report) = embodied::spec::check_source("fleet.ron", text.as_str());
    assert!(report.is_ok(), "{}", report.short());
    let read = read.unwrap();
    let c2 = |s: &embodied::spec::Spec| s.subsystem("c2").cloned().expect("c2");
    let (ours, theirs) = (c2(&read), c2(&spec));
    let fans = |s: &embodied::spec::model::Subsystem| {
        let groups = s.inputs.iter().chain(&s.outputs);
        groups
            .map(|g| (g.peer.clone(), g.peers.clone(), g.buffers.len()))
            .collect::<Vec<_>>()
    };
    assert_eq!(fans(&ours), fans(&theirs));
    assert_eq!(ours.inputs[0].peers, ["c1_0", "c1_1", "c1_2"]);
    // Every link of the fan's elements, as the spec writes it.
    let fan_links = |s: &embodied::spec::Spec| {
        let mut links: Vec<(String, String)> = s
            .links
            .iter()
            .filter(|l| l.from.starts_with("c2.") || l.to.starts_with("c2."))
            .map(|l| (l.from.clone(), l.to.clone()))
            .collect();
        links.sort();
        links
    };
    let links = fan_links(&read);
    let per_robot = ours.inputs[0].buffers.len() + ours.outputs[0].buffers.len();
    assert_eq!(
        links.len(),
        3 * per_robot,
        "each buffer once a robot: {links:?}"
    );
    assert_eq!(links, fan_links(&spec));
}
