//! A smooth polynomial planner: a cubic Hermite curve between the two positions with
//! tangents along the start and goal headings, followed with a quintic rest-to-rest
//! time scaling. The reference heading is made consistent with the ICR offset (notes
//! §1.2). Closed form, no iteration: the alternative the paper compares against in
//! spirit (OPCM is an optimisation method; this one shows that swapping the planner
//! changes nothing else).

use super::{
    Fragment, PlanError, PlanStats, Planner, PlannerSettings, Waypoint, heading_for, nearest_angle,
};

/// The polynomial planner.
#[derive(Clone, Debug)]
pub struct Polynomial {
    /// Settings.
    pub settings: PlannerSettings,
}

impl Polynomial {
    /// A planner with these settings.
    pub fn new(settings: PlannerSettings) -> Polynomial {
        Polynomial { settings }
    }
}

/// Quintic time scaling `s(τ) = 10τ³ − 15τ⁴ + 6τ⁵` and its first derivative.
fn scaling(tau: f64) -> (f64, f64) {
    let t2 = tau * tau;
    (
        t2 * tau * (10.0 - 15.0 * tau + 6.0 * t2),
        30.0 * t2 * (1.0 - 2.0 * tau + t2),
    )
}

/// The Hermite curve from the start to the goal position, with tangents along
/// the start and end headings scaled by the distance.
struct Curve {
    from: [f64; 3],
    to: [f64; 2],
    dist: f64,
    /// The end heading: the goal's, or towards the goal (the start's if it is
    /// there), the nearest turn from the start's.
    end_phi: f64,
    t0: [f64; 2],
    t1: [f64; 2],
}

impl Curve {
    fn new(from: [f64; 3], to: &Waypoint) -> Curve {
        let (dx, dy) = (to.x - from[0], to.y - from[1]);
        let dist = dx.hypot(dy);
        let end_phi = nearest_angle(
            to.phi
                .unwrap_or(if dist > 1e-9 { dy.atan2(dx) } else { from[2] }),
            from[2],
        );
        Curve {
            from,
            to: [to.x, to.y],
            dist,
            end_phi,
            // Hermite tangents along the headings, scaled by the distance.
            t0: [dist * from[2].cos(), dist * from[2].sin()],
            t1: [dist * end_phi.cos(), dist * end_phi.sin()],
        }
    }

    /// The position at curve parameter `sv`, and its derivative in `sv`.
    fn point(&self, sv: f64) -> ([f64; 2], [f64; 2]) {
        let (from, to, t0, t1) = (self.from, self.to, self.t0, self.t1);
        let (h00, h10, h01, h11) = (
            2.0 * sv.powi(3) - 3.0 * sv.powi(2) + 1.0,
            sv.powi(3) - 2.0 * sv.powi(2) + sv,
            -2.0 * sv.powi(3) + 3.0 * sv.powi(2),
            sv.powi(3) - sv.powi(2),
        );
        let (d00, d10, d01, d11) = (
            6.0 * sv * sv - 6.0 * sv,
            3.0 * sv * sv - 4.0 * sv + 1.0,
            -6.0 * sv * sv + 6.0 * sv,
            3.0 * sv * sv - 2.0 * sv,
        );
        let x = h00 * from[0] + h10 * t0[0] + h01 * to[0] + h11 * t1[0];
        let y = h00 * from[1] + h10 * t0[1] + h01 * to[1] + h11 * t1[1];
        let (px, py) = (
            d00 * from[0] + d10 * t0[0] + d01 * to[0] + d11 * t1[0],
            d00 * from[1] + d10 * t0[1] + d01 * to[1] + d11 * t1[1],
        );
        ([x, y], [px, py])
    }

    /// `n + 1` states `[x, y, ψ, v, 0]` along the curve, timed by the quintic
    /// scaling over `period`: `ψ` the direction of travel, or in place the
    /// heading turning from the start's to the end's.
    fn sample(&self, n: usize, period: f64) -> Vec<[f64; 5]> {
        let (from, end_phi) = (self.from, self.end_phi);
        let mut states = Vec::with_capacity(n + 1);
        let mut prev_psi = from[2];
        for k in 0..=n {
            let tau = k as f64 / n as f64;
            let (sv, sd) = scaling(tau);
            let sdot = sd / period;
            let ([x, y], [px, py]) = self.point(sv);
            let speed = px.hypot(py) * sdot;
            let (psi, v) = if self.dist > 1e-9 && px.hypot(py) > 1e-9 {
                // Drive forwards or backwards, whichever keeps the heading.
                let a = nearest_angle(py.atan2(px), prev_psi);
                let back = nearest_angle(a + std::f64::consts::PI, prev_psi);
                if (back - prev_psi).abs() < (a - prev_psi).abs() {
                    (back, -speed)
                } else {
                    (a, speed)
                }
            } else {
                // In place: turn from the start to the end heading.
                (from[2] + sv * (end_phi - from[2]), 0.0)
            };
            prev_psi = psi;
            states.push([x, y, psi, v, 0.0]);
        }
        states
    }
}

/// The yaw rates of `states` by central differences (zero at the ends), each
/// heading made slip-consistent; the peak speed and yaw rate.
fn yaw_rates(states: &mut [[f64; 5]], dt: f64, x_icr: f64) -> (f64, f64) {
    let n = states.len() - 1;
    let (mut peak_v, mut peak_w) = (0.0f64, 0.0f64);
    let psis: Vec<f64> = states.iter().map(|st| st[2]).collect();
    for k in 0..states.len() {
        let w = if k == 0 || k == n {
            0.0
        } else {
            (psis[k + 1] - psis[k - 1]) / (2.0 * dt)
        };
        states[k][4] = w;
        states[k][2] = heading_for(psis[k], states[k][3], w, x_icr);
        peak_v = peak_v.max(states[k][3].abs());
        peak_w = peak_w.max(w.abs());
    }
    (peak_v, peak_w)
}

/// The fragment of `states` at intervals `dt`, with its end's distance from
/// the goal `to`.
fn fragment(states: Vec<[f64; 5]>, to: &Waypoint, dt: f64) -> (Fragment, PlanStats) {
    let end = states[states.len() - 1];
    let error = (end[0] - to.x).hypot(end[1] - to.y);
    (
        Fragment {
            plan: 0,
            index: 0,
            dt,
            states,
            ..Fragment::default()
        },
        PlanStats {
            iterations: 0,
            restarts: 0,
            error,
        },
    )
}

impl Planner for Polynomial {
    fn name(&self) -> &'static str {
        "polynomial"
    }

    fn plan(&mut self, from: [f64; 3], to: &Waypoint) -> Result<(Fragment, PlanStats), PlanError> {
        super::check_finite(&from, to)?;
        let s = &self.settings;
        let curve = Curve::new(from, to);
        let mut period = s.duration(
            from,
            &Waypoint {
                phi: Some(curve.end_phi),
                ..*to
            },
        );
        if period > s.max_duration {
            return Err(PlanError::TooLong {
                duration: period,
                max: s.max_duration,
            });
        }
        // Longer periods until the speeds are within the limits.
        for attempt in 0..4 {
            let n = (period / s.dt).round().max(1.0) as usize;
            let mut states = curve.sample(n, period);
            let (peak_v, peak_w) = yaw_rates(&mut states, s.dt, s.slip.x_icr);
            match s.retime(period, peak_v, peak_w, attempt)? {
                None => return Ok(fragment(states, to, s.dt)),
                Some(longer) => period = longer,
            }
        }
        Err(PlanError::TooLong {
            duration: period,
            max: s.max_duration,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn reaches_the_goal_at_rest() {
        let mut p = Polynomial::new(PlannerSettings::default());
        for (x, y, phi) in [
            (2.0, 1.0, Some(0.0)),
            (0.0, 0.0, Some(1.5)),
            (1.0, -1.0, None),
        ] {
            let (f, _) = p.plan([0.0; 3], &Waypoint { x, y, phi }).unwrap();
            let end = f.end().unwrap();
            assert!((end[0] - x).hypot(end[1] - y) < 1e-9, "{end:?}");
            assert!(end[3].abs() < 1e-9 && f.states[0][3].abs() < 1e-9);
            assert!(f.states.iter().all(|s| s[3].abs() <= 1.0 + 1e-9));
        }
    }
}
