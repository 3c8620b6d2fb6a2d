//! Missions of the ontology agent: sequences of plans, loaded from RON files.
//!
//! ```ron
//! (
//!     name: "square",
//!     plans: [
//!         [(x: 0.0, y: 0.0), (x: 2.0, y: 0.0), (x: 2.0, y: 2.0)],
//!         [(x: 0.0, y: 2.0), (x: 0.0, y: 0.0)],
//!     ],
//! )
//! ```
//!
//! A mission with no plans (`plans: []`, the shipped mission `listen`)
//! *listens*: a2 sends nothing, and the plans come from another sender into
//! `c1`'s input `c2.desired_plan` (the ROS 2 topic `/rex/plan`, with
//! `rex --realtime --ros2`). See [`Mission::listens`].

use std::path::Path;

use serde::{Deserialize, Serialize};

use crate::config::{self, ConfigError, Invalid, Validate, finite};
use crate::payload::{Plan, Point2};

/// A mission: plans sent one after the other, each after the previous was acknowledged.
///
/// With no plans it listens ([`Mission::listens`]).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Mission {
    /// Name (`square`).
    pub name: String,
    /// The plans, each a list of points to pass in order.
    pub plans: Vec<Vec<Point2>>,
}

impl Validate for Mission {
    fn validate(&self) -> Result<(), Invalid> {
        // The name names the report's folder: an identifier, never a path.
        if embodied::names::check(&self.name).is_err() {
            return Err((
                "name".into(),
                format!("{:?}", self.name),
                "must be an identifier (letters, digits and `_`): it names the report's folder",
            ));
        }
        // No plans is allowed: the mission listens (see `Mission::listens`).
        for (i, plan) in self.plans.iter().enumerate() {
            for (k, p) in plan.iter().enumerate() {
                finite(&format!("plans[{i}][{k}].x"), p.x)?;
                finite(&format!("plans[{i}][{k}].y"), p.y)?;
            }
        }
        Ok(())
    }
}

impl Mission {
    /// Load a mission file.
    pub fn load(path: &Path) -> Result<Mission, ConfigError> {
        config::load(path)
    }

    /// Load one of the shipped missions (`square`, `figure_eight`, `slalom`,
    /// `listen`).
    pub fn shipped(name: &str) -> Result<Mission, ConfigError> {
        Mission::load(&config::missions_dir().join(format!("{name}.ron")))
    }

    /// The names of the shipped missions that drive Rex (those `--mission all`
    /// runs in turn).
    pub const SHIPPED: [&'static str; 3] = ["square", "figure_eight", "slalom"];

    /// The shipped mission that listens: no plans from a2 ([`Mission::listens`]).
    pub const LISTEN: &'static str = "listen";

    /// Whether `name` names a shipped mission ([`Mission::SHIPPED`] or
    /// [`Mission::LISTEN`]) rather than a mission file.
    pub fn is_shipped(name: &str) -> bool {
        Mission::SHIPPED.contains(&name) || name == Mission::LISTEN
    }

    /// Whether the mission listens: it has no plans, so a2 sends nothing and
    /// `c1` executes the plans another sender puts into its input
    /// `c2.desired_plan` (the ROS 2 topic `/rex/plan` with `--ros2`; the first
    /// with any id, then each numbered after the newest). a2 never settles
    /// such a mission (it keeps receiving the acknowledgements, outcomes and
    /// progress `c1` sends, as its own only those of its plans), so the run
    /// ends at its time limit or on a signal, never by the mission's end;
    /// every plan `c1` took is judged.
    pub fn listens(&self) -> bool {
        self.plans.is_empty()
    }

    /// Plan number `k` (ids start at 1).
    pub fn plan(&self, k: usize) -> Option<Plan> {
        self.plans.get(k).map(|points| Plan {
            id: k as u32 + 1,
            points: points.clone(),
            first: 0,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shipped_missions_load() {
        for name in Mission::SHIPPED {
            let m = Mission::shipped(name).unwrap_or_else(|e| panic!("{name}: {e}"));
            assert_eq!(m.name, name);
            assert!(m.plans.iter().all(|p| p.len() >= 2));
        }
    }

    #[test]
    fn the_listening_mission_loads_with_no_plans_and_listens() {
        assert!(Mission::is_shipped(Mission::LISTEN));
        assert!(
            !Mission::SHIPPED.contains(&Mission::LISTEN),
            "`all` drives Rex"
        );
        let m = Mission::shipped(Mission::LISTEN).unwrap();
        assert_eq!(m.name, "listen");
        assert!(m.plans.is_empty() && m.listens());
        assert_eq!(m.plan(0), None, "a2 has nothing to send");
        // Any mission file with no plans listens; one with plans does not.
        let m = config::parse::<Mission>(Path::new("m.ron"), "(name: \"x\", plans: [])").unwrap();
        assert!(m.listens());
        for name in Mission::SHIPPED {
            assert!(Mission::is_shipped(name));
            assert!(!Mission::shipped(name).unwrap().listens(), "{name}");
        }
        assert!(!Mission::is_shipped("listen.ron"));
    }

    #[test]
    fn bad_missions_are_rejected() {
        let err = config::parse::<Mission>(
            Path::new("m.ron"),
            "(name: \"x\", plans: [[(x: NaN, y: 0.0)]])",
        )
        .unwrap_err();
        assert!(err.to_string().contains("plans[0][0].x"), "{err}");
        // A third coordinate is refused, not ignored.
        let err = config::parse::<Mission>(
            Path::new("m.ron"),
            "(name: \"x\", plans: [[(x: 1.0, y: 0.0, z: 2.0)]])",
        )
        .unwrap_err();
        assert!(
            err.to_string().contains("m.ron:1:") && err.to_string().contains("`z`"),
            "{err}"
        );
        // The name becomes a folder of the report: no paths.
        for name in ["../x", "/tmp/x", "", "a/b", "."] {
            let text = format!("(name: {name:?}, plans: [[(x: 1.0, y: 0.0)]])");
            let err = config::parse::<Mission>(Path::new("m.ron"), &text).unwrap_err();
            assert!(err.to_string().contains("m.ron: name = "), "{name}: {err}");
        }
    }
}
