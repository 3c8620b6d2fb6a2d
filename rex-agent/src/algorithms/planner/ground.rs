//! Timing a planned fragment for the ground: a path the platform could follow
//! on concrete may ask more of ice than it can give. The planners plan
//! kinematically; this checks what following a fragment would ask of each
//! wheel's traction on the ground the estimator knows
//! ([`Lateral::traction_demand`]), and slows the fragment down (the same path,
//! a longer time: speeds scale by `1/α`, accelerations by `1/α²`) until it asks
//! at most a margin of it. A fragment that would need more than the longest
//! duration allowed cannot be executed on that ground: an error that says why.

use super::Fragment;
use crate::model::{Friction, Lateral};

/// How fragments are timed for the ground.
#[derive(Clone, Debug, PartialEq)]
pub struct GroundTiming {
    /// The platform's lateral-slip model.
    pub model: Lateral,
    /// The largest fraction of a wheel's traction bound a fragment may ask for
    /// (the rest is the tracker's, to correct errors).
    pub margin: f64,
    /// The longest a fragment may become \[s\].
    pub max_duration: f64,
    /// The ground fragments are timed for while the estimate has not settled
    /// (the slipperiest one expected): the platform starts carefully on a
    /// ground it has not driven on yet.
    pub cautious: Friction,
}

/// Why a fragment cannot be timed for the ground.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GroundError {
    /// Even slowed down to the longest duration it asks more than the margin.
    #[error(
        "the ground (μ_x {mu_long:.2}, μ_y {mu_lat:.2}) cannot deliver fragment {index} of plan {plan}: slowed to {max_duration:.0} s it still asks {demand:.0}% of a wheel's traction (at most {margin:.0}%)"
    )]
    TooSlippery {
        /// The plan.
        plan: u32,
        /// The fragment.
        index: u32,
        /// The ground's longitudinal friction.
        mu_long: f64,
        /// The ground's lateral friction.
        mu_lat: f64,
        /// What it asks at the longest duration \[%\] (infinite: a turn the
        /// ground cannot carry at any speed the samples have).
        demand: f64,
        /// The margin \[%\].
        margin: f64,
        /// The longest duration \[s\].
        max_duration: f64,
    },
    /// The ground estimate is not finite or not positive.
    #[error("the ground estimate is not usable: {0:?}")]
    BadEstimate(Friction),
}

/// How much longer each attempt makes the fragment.
const STEP: f64 = 1.05;
/// The most attempts: 1.05²⁰⁰ is 17,000 times longer.
const MAX_STEPS: usize = 200;

impl GroundTiming {
    /// The largest traction demand of `f` slowed by `factor` on `ground`
    /// (speeds and turn rates from the samples, their rates by central
    /// differences); infinite where the ground cannot carry a sample's turn.
    pub fn demand(&self, f: &Fragment, ground: &Friction, factor: f64) -> f64 {
        let n = f.states.len();
        let dt = f.dt * factor;
        let mut peak = 0.0f64;
        for k in 0..n {
            let (a, b) = (k.saturating_sub(1), (k + 1).min(n - 1));
            let span = (b - a) as f64 * dt;
            let rate = |i: usize| {
                if span > 0.0 {
                    (f.states[b][i] - f.states[a][i]) / factor / span
                } else {
                    0.0
                }
            };
            let s = f.states[k];
            let demand = self
                .model
                .traction_demand(s[3] / factor, s[4] / factor, rate(3), rate(4), ground)
                .unwrap_or(f64::INFINITY);
            peak = peak.max(demand);
        }
        peak
    }

    /// `f` timed for `ground`: itself when it asks at most `margin` of the
    /// traction, else slowed by the smallest factor (in steps of 5 %) that
    /// makes it so.
    pub fn time(&self, f: &Fragment, ground: &Friction) -> Result<Fragment, GroundError> {
        let usable = |v: f64| v.is_finite() && v > 0.0;
        if !(usable(ground.mu_long) && usable(ground.mu_lat) && ground.rolling.is_finite()) {
            return Err(GroundError::BadEstimate(*ground));
        }
        let duration = f.steps() as f64 * f.dt;
        let mut factor = 1.0;
        let mut demand = self.demand(f, ground, factor);
        for _ in 0..MAX_STEPS {
            let longer = duration * factor * STEP;
            // A NaN duration or limit ends the search too.
            if demand <= self.margin || longer.is_nan() || longer > self.max_duration {
                break;
            }
            factor *= STEP;
            demand = self.demand(f, ground, factor);
        }
        if demand <= self.margin {
            return Ok(if factor > 1.0 {
                f.slowed(factor)
            } else {
                f.clone()
            });
        }
        Err(GroundError::TooSlippery {
            plan: f.plan,
            index: f.index,
            mu_long: ground.mu_long,
            mu_lat: ground.mu_lat,
            demand: 100.0 * demand,
            margin: 100.0 * self.margin,
            max_duration: self.max_duration,
        })
    }
}

impl Fragment {
    /// The same path `factor` (≥ 1) times slower: the duration rounded up to a
    /// whole number of samples, positions and headings interpolated along the
    /// path, speeds and turn rates divided by the actual factor. The first and
    /// last samples keep their positions and headings (their speeds, zero on a
    /// fragment that starts and ends at rest, are divided too).
    pub fn slowed(&self, factor: f64) -> Fragment {
        let steps = self.steps();
        if steps == 0 || !(factor.is_finite() && factor > 1.0) {
            return self.clone();
        }
        let new_steps = (steps as f64 * factor).ceil() as usize;
        let actual = new_steps as f64 / steps as f64;
        let states = (0..=new_steps)
            .map(|k| {
                // The original sample time of the new sample k, in samples.
                let at = k as f64 / actual;
                let i = (at.floor() as usize).min(steps - 1);
                let t = at - i as f64;
                let (a, b) = (self.states[i], self.states[i + 1]);
                // The last sample is the old one exactly (the path's end).
                let mix = |j: usize| {
                    if t < 1.0 {
                        a[j] + t * (b[j] - a[j])
                    } else {
                        b[j]
                    }
                };
                [mix(0), mix(1), mix(2), mix(3) / actual, mix(4) / actual]
            })
            .collect();
        Fragment {
            states,
            ..self.clone()
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::algorithms::planner::{PlannerKind, PlannerSettings, Waypoint};
    use crate::model::PlatformParams;

    fn timing() -> GroundTiming {
        GroundTiming {
            model: Lateral::new(PlatformParams::peer_default()),
            margin: 0.5,
            max_duration: 60.0,
            cautious: ICE,
        }
    }

    fn fragment() -> Fragment {
        let mut planner = PlannerKind::Ecsa.build(PlannerSettings::default());
        let (f, _) = planner
            .plan(
                [0.0, 0.0, 0.0],
                &Waypoint {
                    x: 1.5,
                    y: 1.0,
                    phi: None,
                },
            )
            .expect("an easy fragment");
        f
    }

    const ICE: Friction = Friction {
        mu_long: 0.1,
        mu_lat: 0.07,
        rolling: 0.01,
    };

    #[test]
    fn slowing_keeps_the_path_and_scales_the_speeds() {
        let f = fragment();
        let g = f.slowed(1.5);
        assert_eq!(g.steps(), (f.steps() as f64 * 1.5).ceil() as usize);
        assert_eq!(g.states.first(), f.states.first());
        // The same ends, the speeds scaled (the last ones are zero to rounding).
        let (a, b) = (g.end().expect("samples"), f.end().expect("samples"));
        assert_eq!(a[..3], b[..3]);
        let peak = |f: &Fragment, i: usize| f.states.iter().map(|s| s[i].abs()).fold(0.0, f64::max);
        let actual = g.steps() as f64 / f.steps() as f64;
        assert!((peak(&g, 3) - peak(&f, 3) / actual).abs() < 0.02 * peak(&f, 3));
        // Every new sample lies on the old path (between two old samples).
        for s in &g.states {
            let near = f
                .states
                .windows(2)
                .map(|w| {
                    let (a, b) = (w[0], w[1]);
                    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
                    let len2 = (dx * dx + dy * dy).max(1e-18);
                    let t = (((s[0] - a[0]) * dx + (s[1] - a[1]) * dy) / len2).clamp(0.0, 1.0);
                    (s[0] - a[0] - t * dx).hypot(s[1] - a[1] - t * dy)
                })
                .fold(f64::INFINITY, f64::min);
            assert!(near < 1e-9, "{s:?} is {near} m off the path");
        }
        // Not slower: the same fragment.
        assert_eq!(f.slowed(1.0), f);
        assert_eq!(f.slowed(f64::NAN), f);
    }

    #[test]
    fn concrete_keeps_the_timing_and_ice_slows_it_down() {
        let t = timing();
        let f = fragment();
        let concrete = t
            .time(&f, &Friction::CONCRETE)
            .expect("concrete carries it");
        assert_eq!(concrete, f);
        assert!(
            t.demand(&f, &ICE, 1.0) > t.margin,
            "ice cannot: {}",
            t.demand(&f, &ICE, 1.0)
        );
        let ice = t.time(&f, &ICE).expect("ice carries it slower");
        assert!(
            ice.steps() > f.steps() * 5 / 4,
            "{} vs {}",
            ice.steps(),
            f.steps()
        );
        let factor = ice.steps() as f64 / f.steps() as f64;
        assert!(t.demand(&f, &ICE, factor) <= t.margin);
        // The smallest such factor, within a step.
        assert!(t.demand(&f, &ICE, factor / (STEP * STEP)) > t.margin);
    }

    #[test]
    fn an_unreachable_margin_or_a_nan_limit_ends_the_search() {
        // A margin no duration meets, with no limit to the duration (NaN, as
        // from a corrupt setting): the search stops after its last step
        // instead of running forever.
        let f = fragment();
        for max_duration in [f64::NAN, f64::INFINITY] {
            let t = GroundTiming {
                max_duration,
                margin: 1e-12,
                ..timing()
            };
            let err = t.time(&f, &ICE).expect_err("no duration asks that little");
            assert!(matches!(err, GroundError::TooSlippery { .. }), "{err}");
        }
    }

    #[test]
    fn a_ground_too_slippery_or_a_bad_estimate_is_an_error_with_the_reason() {
        // A 10 s budget: the fragment (1.8 s) would take about 17 times
        // longer on this glass.
        let t = GroundTiming {
            max_duration: 10.0,
            ..timing()
        };
        let f = fragment();
        let glass = Friction {
            mu_long: 0.003,
            mu_lat: 0.002,
            rolling: 0.0,
        };
        let err = t.time(&f, &glass).expect_err("nothing moves on it");
        assert!(matches!(err, GroundError::TooSlippery { .. }), "{err}");
        assert!(err.to_string().contains("cannot deliver fragment"), "{err}");
        for bad in [f64::NAN, -0.1, 0.0] {
            let g = Friction {
                mu_long: bad,
                ..Friction::CONCRETE
            };
            assert!(matches!(t.time(&f, &g), Err(GroundError::BadEstimate(_))));
        }
    }
}
