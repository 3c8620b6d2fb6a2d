//! Attaching measurements to the MHE's stages: plausibility checks, gates on
//! the map poses and the encoders, visual odometry as relative motions, and
//! relocalisation after a run of rejected poses.

use super::{Mhe, Sample, Stage};
use crate::math::geometry::wrap;
use crate::model::Dynamics;

impl<M: Dynamics<NX, NP>, const NX: usize, const NP: usize> Mhe<M, NX, NP> {
    /// Attach the measurements of a sample to their stages, rejecting bad ones.
    pub(super) fn attach(&mut self, m: &Sample) {
        let n = self.window.len() - 1;
        let plausible_rate = 4.0 * self.model.platform().wheel_speed_max.max(1.0);
        let now = self.window[n].t;
        if let Some(g) = m.gyro {
            if g.is_finite() && g.abs() <= 20.0 {
                self.window[n].gyro = Some(g);
            } else {
                self.stats.rejected += 1;
            }
        }
        if let Some(h) = m.heading {
            // A jump no turn makes (a reset of the IMU between the samples, or
            // garbage) breaks the chain of increments.
            let previous = n.checked_sub(1).and_then(|i| {
                self.window[i]
                    .heading
                    .map(|h0| (h0, now - self.window[i].t))
            });
            let plausible = previous.is_none_or(|(h0, dt)| {
                wrap(h - h0).abs() <= 3.0 * self.s.max_yaw_rate * dt.abs() + 0.05
            });
            if h.is_finite() && plausible {
                self.window[n].heading = Some(h);
            } else {
                self.stats.rejected += 1;
            }
        }
        if let Some(e) = m.encoders {
            if e.iter().all(|v| v.is_finite() && v.abs() <= plausible_rate) {
                self.window[n].spin = e;
                self.window[n].encoders = Some(self.gate_encoders(n, e));
            } else {
                self.stats.rejected += 1;
            }
        }
        if let Some(l) = m.loads
            && self.s.sigma_load > 0.0
        {
            let weight = self.model.platform().mass * self.model.platform().gravity;
            if l.iter()
                .all(|v| v.is_finite() && *v >= -0.1 * weight && *v <= weight)
            {
                self.window[n].loads = Some(l);
            } else {
                self.stats.rejected += 1;
            }
        }
        if let Some(p) = m.pose {
            let sigma = [self.s.sigma_pos, self.s.sigma_phi];
            self.attach_pose(p.time, p.pose, sigma, now);
        }
        let first = self.window.front().map_or(now, |s| s.t);
        let filling = self.window.len() <= self.s.horizon;
        if let Some(mo) = m
            .motion
            .filter(|mo| !(filling && mo.from < first - 0.5 * self.s.dt))
        {
            // (A motion that began before a window still filling is of no use,
            // and nothing wrong.) Visual odometry measures a relative motion: the average velocity
            // over the interval, attached to the stage nearest its middle. (Composed
            // onto the estimate at `from` as a pose, it would repeat the estimate's
            // own error as if it were new evidence.)
            let span = mo.to - mo.from;
            let (a, b) = (self.nearest(mo.from), self.nearest(mo.to));
            // The displacement in the frame at the interval's middle: the chord of
            // an arc points along the heading half-way (in the frame at `from` it
            // would show a lateral v ω Δt / 2 that is no slip).
            let [dx, dy, dphi] = mo.delta;
            let (sh, ch) = (0.5 * dphi).sin_cos();
            let (mx, my) = (ch * dx + sh * dy, -sh * dx + ch * dy);
            let speed = [mx / span, my / span, dphi / span];
            let plausible = speed[0].abs() <= 3.0 * self.s.max_speed
                && speed[1].abs() <= 3.0 * self.s.max_speed
                && speed[2].abs() <= 3.0 * self.s.max_yaw_rate;
            match (a, b) {
                (Some(a), Some(b))
                    if span > 1e-3 && speed.iter().all(|v| v.is_finite()) && plausible =>
                {
                    // The motion between consecutive stages at that velocity (chords).
                    for k in a..b {
                        let tau = self.window[k + 1].t - self.window[k].t;
                        let turn = speed[2] * tau;
                        let (sh, ch) = (0.5 * turn).sin_cos();
                        let (ex, ey) = (speed[0] * tau, speed[1] * tau);
                        self.window[k].rel = Some([ch * ex - sh * ey, sh * ex + ch * ey, turn]);
                    }
                    if a == b {
                        // Shorter than a stage: nothing to tie together.
                        self.stats.rejected += 1;
                    }
                }
                _ => self.stats.rejected += 1,
            }
        }
    }

    /// The encoder readings of stage `n` that the model can represent at the
    /// stage's predicted state ([`Dynamics::encoder_usable`]); the others
    /// become NaN, and are left out. A wheel spinning on a ground the estimate
    /// still thinks grippy reads ten times what the model predicts: taken as it
    /// is, it would make the estimate race off. (A reading that only disagrees
    /// with the current parameters is kept: it is how they are learnt.)
    fn gate_encoders(&mut self, n: usize, e: [f64; 4]) -> [f64; 4] {
        let x = self.window[n].x;
        let mut out = e;
        for (k, reading) in out.iter_mut().enumerate() {
            if !self.model.encoder_usable(k, &x, *reading) {
                *reading = f64::NAN;
                self.stats.rejected += 1;
                self.stats.rejected_encoders += 1;
            }
        }
        out
    }

    fn attach_pose(&mut self, time: f64, pose: [f64; 3], sigma: [f64; 2], now: f64) {
        let first = self.window.front().map_or(now, |s| s.t);
        if time < first - 0.5 * self.s.dt && self.window.len() <= self.s.horizon {
            // Older than a window that is still filling: the first stage was
            // anchored on a newer pose.
            return;
        }
        let Some(i) = self
            .nearest(time)
            .filter(|_| pose.iter().all(|v| v.is_finite()))
        else {
            self.stats.rejected += 1;
            return;
        };
        // The measurement moved to the stage's instant along the estimated velocity.
        let x = self.window[i].x;
        let dt = self.window[i].t - time;
        let mut at = x;
        at[0] = pose[0];
        at[1] = pose[1];
        at[2] = pose[2];
        let moved = self.shifted(&at, dt);
        let pose = [moved[0], moved[1], moved[2]];
        let since = self.last_pose_time.map_or(0.0, |t| (now - t).max(0.0));
        let radius = self.s.gate * sigma[0] + self.s.drift_rate * since;
        let dphi = wrap(pose[2] - x[2]);
        let heading_gate = self.s.gate * sigma[1] + 0.5 * self.s.drift_rate * since;
        if (pose[0] - x[0]).hypot(pose[1] - x[1]) > radius || dphi.abs() > heading_gate {
            self.stats.rejected += 1;
            self.stats.rejected_poses += 1;
            let since = *self.rejecting_since.get_or_insert(time);
            if now - since >= self.s.relocalise_after {
                let t = self.window[i].t;
                self.relocalise(t, [pose[0], pose[1], x[2] + dphi], now);
            }
            return;
        }
        self.rejecting_since = None;
        self.window[i].pose = Some([pose[0], pose[1], x[2] + dphi]);
        self.window[i].pose_sigma = sigma;
        self.last_pose_time = Some(self.last_pose_time.map_or(time, |t| t.max(time)));
    }

    /// Restart the window from a map pose that describes the time `t`: the newest
    /// stage keeps its measurements and velocities, takes the pose moved to its
    /// instant, and becomes the whole window (the arrival cost anchors on it).
    fn relocalise(&mut self, t: f64, pose: [f64; 3], now: f64) {
        let Some(last) = self.window.back().copied() else {
            return;
        };
        let mut at = last.x;
        at[0] = pose[0];
        at[1] = pose[1];
        at[2] = pose[2];
        let x = self.shifted(&at, now - t);
        self.window.clear();
        self.window.push_back(Stage {
            x,
            pose: None,
            rel: None,
            ..last
        });
        self.x_bar = x;
        self.p_bar = self.p;
        self.last_pose_time = Some(t);
        self.rejecting_since = None;
        self.stats.relocalisations += 1;
    }
}
