//! What Rex's ROS 2 tests share: the bridge's plan of the shipped spec, and
//! Rex's own messages in it for our stand-in for a ROS 2 node to register.

#![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

use embodied::ros2::bridge::Plan;
use rex_agent::mission::Mission;
use rex_agent::system::{RexConfig, build};
use rex_agent::world::WorldConfig;
use serde_json::{Value, json};

/// The bridge's plan of the shipped spec for the shipped mission `mission`
/// (without the camera unless `camera`: no visual odometry, no `R1.` topic),
/// and the configuration it was built from.
pub(crate) fn bridge_plan(mission: &str, camera: bool) -> (Plan, RexConfig) {
    let mut config = RexConfig::new(
        WorldConfig::shipped().unwrap(),
        Mission::shipped(mission).unwrap(),
    );
    if !camera {
        config.visual_odometry = false;
    }
    let (system, _) = build(&config).unwrap();
    let text = std::fs::read_to_string(&config.spec).unwrap();
    let mut spec: embodied::spec::Spec = embodied::spec::options().from_str(&text).unwrap();
    if !camera {
        let section = spec.ros2.as_mut().unwrap();
        section.publish.retain(|t| !t.buffer.starts_with("R1."));
    }
    let plan = Plan::new(&spec, None, &system, &rex_agent::ros2::adapters()).unwrap();
    (plan, config)
}

/// Rex's own messages (`[name, .msg text]`) the bridge of `plan` publishes
/// and subscribes to, each once, for the node to register.
#[allow(
    dead_code,
    reason = "ros2_package reads the plan's type hashes, not its messages' texts"
)]
pub(crate) fn own_messages(plan: &Plan) -> Vec<Value> {
    let mut own: Vec<Value> = Vec::new();
    let messages = plan
        .topics
        .iter()
        .map(|t| &t.messages)
        .chain(plan.subscriptions.iter().map(|t| &t.messages));
    for m in messages.filter(|m| m.name().package == "rex_msgs") {
        let entry = json!([m.name().to_string(), m.msg_text()]);
        if !own.contains(&entry) {
            own.push(entry);
        }
    }
    own
}
