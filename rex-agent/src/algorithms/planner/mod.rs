//! Trajectory planners: a fragment of trajectory between two consecutive plan points.
//!
//! A planner turns a start configuration and a goal (position, and a desired heading
//! when there is one) into a time-parameterised reference `(X, Y, φ, v, ω)` sampled
//! every `dt`, the format the tracker of `e11` follows. Two planners sit behind
//! [`Planner`]: the endogenous configuration space approach ([`ecsa::Ecsa`], the
//! paper's) and a smooth polynomial planner ([`poly::Polynomial`]); which one runs is
//! a configuration value ([`PlannerKind`]), nothing else changes.

pub mod ecsa;
pub mod ground;
pub mod poly;

use serde::{Deserialize, Serialize};

use crate::model::SlipParams;

/// A configuration to reach: a position, and a heading if it matters.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Waypoint {
    /// x \[m\].
    pub x: f64,
    /// y \[m\].
    pub y: f64,
    /// Desired heading \[rad\]; `None` leaves it free.
    pub phi: Option<f64>,
}

/// A time-parameterised piece of reference trajectory.
#[derive(Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct Fragment {
    /// The plan it belongs to.
    pub plan: u32,
    /// Its position in the plan (0-based).
    pub index: u32,
    /// Sample interval \[s\].
    pub dt: f64,
    /// Reference `(X, Y, φ, v, ω)` at `k · dt`, `k = 0..=n`.
    pub states: Vec<[f64; 5]>,
    /// Whether it is the plan's last fragment (set by `c1` when it hands it over).
    pub last: bool,
    /// The stop count of `e11` that `c1` knew when it handed it over: `e11` refuses
    /// fragments older than its last stop.
    pub epoch: u32,
}

/// `Fragment 2.1 (60 × 0.05 s, (1.00, 0.00) -> (1.50, 0.50))`: short enough for traces.
impl std::fmt::Debug for Fragment {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "Fragment {}.{} ({} × {} s",
            self.plan,
            self.index,
            self.steps(),
            self.dt
        )?;
        if let (Some(a), Some(b)) = (self.states.first(), self.states.last()) {
            write!(
                f,
                ", ({:.2}, {:.2}) -> ({:.2}, {:.2})",
                a[0], a[1], b[0], b[1]
            )?;
        }
        f.write_str(")")
    }
}

impl Fragment {
    /// Number of sample intervals (the fragment lasts `steps() · dt`).
    pub fn steps(&self) -> usize {
        self.states.len().saturating_sub(1)
    }

    /// The last reference state.
    pub fn end(&self) -> Option<[f64; 5]> {
        self.states.last().copied()
    }
}

/// Limits and preferences shared by the planners.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PlannerSettings {
    /// Sample interval of fragments \[s\] (the period of `e11`).
    pub dt: f64,
    /// Cruising speed used to choose a fragment's duration \[m/s\].
    pub cruise_speed: f64,
    /// Turn rate used to choose a fragment's duration \[rad/s\].
    pub cruise_turn_rate: f64,
    /// Shortest fragment \[s\].
    pub min_duration: f64,
    /// Longest fragment \[s\]: a fragment that would need longer to respect the
    /// velocity bounds is refused ([`PlanError::TooLong`]).
    pub max_duration: f64,
    /// Speed bound the fragment must respect \[m/s\].
    pub speed_max: f64,
    /// Turn-rate bound the fragment must respect \[rad/s\].
    pub turn_rate_max: f64,
    /// Nominal slip parameters of the kinematic model (the ICR offset matters).
    pub slip: SlipParams,
}

impl Default for PlannerSettings {
    fn default() -> Self {
        PlannerSettings {
            dt: 0.05,
            cruise_speed: 0.4,
            cruise_turn_rate: 0.8,
            min_duration: 1.0,
            max_duration: 60.0,
            speed_max: 1.0,
            turn_rate_max: 1.8,
            slip: SlipParams::NOMINAL,
        }
    }
}

impl PlannerSettings {
    /// Check a fragment's peak speed and turn rate against the bounds: `Ok(None)`
    /// if they hold, `Ok(Some(longer))` with the duration to try next, or an error
    /// when that would exceed `max_duration` or after `attempt` 4.
    pub fn retime(
        &self,
        period: f64,
        peak_v: f64,
        peak_w: f64,
        attempt: usize,
    ) -> Result<Option<f64>, PlanError> {
        let (over_v, over_w) = (peak_v / self.speed_max, peak_w / self.turn_rate_max);
        let over = over_v.max(over_w);
        if over <= 1.0 {
            return Ok(None);
        }
        let longer = ((period * over * 1.1) / self.dt).ceil() * self.dt;
        if longer > self.max_duration {
            return Err(PlanError::TooLong {
                duration: longer,
                max: self.max_duration,
            });
        }
        if attempt >= 3 {
            let (what, value, bound) = if over_v >= over_w {
                ("speed", peak_v, self.speed_max)
            } else {
                ("turn rate", peak_w, self.turn_rate_max)
            };
            return Err(PlanError::TooFast { what, value, bound });
        }
        Ok(Some(longer))
    }

    /// A duration for moving from `from` to `to`: long enough for the distance at
    /// cruising speed and for the turn at the cruising turn rate, a multiple of `dt`.
    pub fn duration(&self, from: [f64; 3], to: &Waypoint) -> f64 {
        let d = (to.x - from[0]).hypot(to.y - from[1]);
        let turn = to.phi.map_or(0.0, |p| (p - from[2]).abs());
        let t = (d / self.cruise_speed)
            .max(turn / self.cruise_turn_rate)
            .max(self.min_duration);
        (t / self.dt).ceil() * self.dt
    }
}

/// Why a fragment could not be planned.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum PlanError {
    /// A start or goal that is not finite.
    #[error("the start or the goal is not a finite configuration")]
    NotFinite,
    /// The iteration did not reach the tolerance within its bound.
    #[error("no convergence in {iterations} iterations (error {error:.2e})")]
    NoConvergence {
        /// Iterations spent.
        iterations: usize,
        /// Remaining task error.
        error: f64,
    },
    /// The Jacobian stayed singular after the allowed restarts.
    #[error("singular controls: no progress after {restarts} restarts")]
    Singular {
        /// Restarts from perturbed controls.
        restarts: usize,
    },
    /// The planning process failed (its planner panicked, or its thread is gone).
    #[error("the planning process stopped: {0}")]
    ProcessGone(String),
    /// The fragment still exceeds the speed or turn-rate bounds after being slowed
    /// down.
    #[error("the fragment exceeds the velocity bounds ({what} {value:.2}, bound {bound:.2})")]
    TooFast {
        /// `speed` or `turn rate`.
        what: &'static str,
        /// Peak value.
        value: f64,
        /// The bound.
        bound: f64,
    },
    /// Respecting the velocity bounds would make the fragment longer than
    /// `max_duration`.
    #[error(
        "the fragment would need {duration:.1} s to respect the velocity bounds, more than the {max:.1} s allowed"
    )]
    TooLong {
        /// The duration needed \[s\].
        duration: f64,
        /// `max_duration` \[s\].
        max: f64,
    },
}

/// Figures of one planning run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct PlanStats {
    /// Newton iterations (0 for non-iterative planners).
    pub iterations: usize,
    /// Restarts from perturbed controls.
    pub restarts: usize,
    /// Final task error (mixed units: m and rad).
    pub error: f64,
}

/// A trajectory planner. Implementations must be deterministic.
pub trait Planner: Send + 'static {
    /// Name for reports.
    fn name(&self) -> &'static str;

    /// Plan from `from = (X, Y, φ)` to `to`; the fragment is sampled every
    /// `settings.dt` and starts and ends at rest.
    fn plan(&mut self, from: [f64; 3], to: &Waypoint) -> Result<(Fragment, PlanStats), PlanError>;
}

/// Which planner to use.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum PlannerKind {
    /// The endogenous configuration space approach (the paper's planner).
    #[default]
    Ecsa,
    /// Smooth polynomial paths with quintic time scaling.
    Polynomial,
}

impl std::str::FromStr for PlannerKind {
    type Err = crate::config::UnknownChoice;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s {
            "ecsa" => Ok(PlannerKind::Ecsa),
            "polynomial" | "poly" => Ok(PlannerKind::Polynomial),
            _ => Err(crate::config::UnknownChoice::new(
                "planner",
                s,
                "ecsa, polynomial",
            )),
        }
    }
}

impl PlannerKind {
    /// The name used in reports and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            PlannerKind::Ecsa => "ecsa",
            PlannerKind::Polynomial => "polynomial",
        }
    }

    /// A planner of this kind.
    pub fn build(self, settings: PlannerSettings) -> Box<dyn Planner> {
        match self {
            PlannerKind::Ecsa => Box::new(ecsa::Ecsa::new(settings)),
            PlannerKind::Polynomial => Box::new(poly::Polynomial::new(settings)),
        }
    }
}

/// The angle equal to `target` modulo 2π that is closest to `reference`.
pub fn nearest_angle(target: f64, reference: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    target + ((reference - target) / tau).round() * tau
}

/// [`PlanError::NotFinite`] unless the start and the goal are finite numbers.
fn check_finite(from: &[f64; 3], to: &Waypoint) -> Result<(), PlanError> {
    let finite = from.iter().all(|v| v.is_finite())
        && to.x.is_finite()
        && to.y.is_finite()
        && to.phi.is_none_or(f64::is_finite);
    if finite {
        Ok(())
    } else {
        Err(PlanError::NotFinite)
    }
}

/// The slip-consistent heading of the kinematic model: with the ICR at `x_icr`, the
/// centre of mass moves at angle `−atan(x_icr ω / v)` to the body axis (notes §1.2).
pub fn heading_for(path_angle: f64, v: f64, omega: f64, x_icr: f64) -> f64 {
    if v.abs() < 1e-9 {
        path_angle
    } else {
        path_angle + (x_icr * omega).atan2(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angles_unwrap_towards_the_reference() {
        let a = nearest_angle(-3.0, 3.0);
        assert!((a - (-3.0 + std::f64::consts::TAU)).abs() < 1e-12);
        assert_eq!(nearest_angle(0.5, 0.4), 0.5);
    }

    #[test]
    fn durations_are_multiples_of_dt() {
        let s = PlannerSettings::default();
        let t = s.duration(
            [0.0; 3],
            &Waypoint {
                x: 1.0,
                y: 0.0,
                phi: None,
            },
        );
        assert!((t - 2.5).abs() < 1e-9);
        let t = s.duration(
            [0.0; 3],
            &Waypoint {
                x: 0.0,
                y: 0.0,
                phi: Some(3.0),
            },
        );
        assert!((t / s.dt - (t / s.dt).round()).abs() < 1e-9 && t >= 3.0 / 0.8);
    }
}
