//! One Gauss–Newton step of the MHE: the normal equations `JᵀJ Δ = −Jᵀr` of the
//! whole window, assembled stage by stage (block-tridiagonal in the states, with a
//! border for the slip parameters), from the arrival cost, the process model and
//! each stage's measurements; then the step, solved in `solve.rs`, applied within
//! the parameter bounds.

use super::{Blocks, Mhe, MheError, NP, NX, slip};
use crate::algorithms::geometry::wrap;
use crate::algorithms::mpc::QpStrategy;
use crate::algorithms::mpc::linalg::Mat;
use crate::world::model::{SlipParams, State5, Torques};

impl Mhe {
    /// One Gauss–Newton step on the whole window.
    pub(super) fn gauss_newton(&mut self) -> Result<(), MheError> {
        let n = self.window.len() - 1;
        self.assemble()?;
        let (dx, dp) = match self.s.qp {
            QpStrategy::Structured => self.solve_structured(n)?,
            QpStrategy::Clarabel => self.solve_full(n)?,
        };
        if dx.iter().flatten().chain(&dp).any(|v| !v.is_finite()) {
            return Err(MheError::Solve("the step is not finite".into()));
        }
        for (stage, d) in self.window.iter_mut().zip(&dx) {
            for k in 0..NX {
                stage.x[k] += d[k];
            }
        }
        for k in 0..NP {
            self.p[k] = (self.p[k] + dp[k]).clamp(self.s.p_lb[k], self.s.p_ub[k]);
        }
        self.stats.steps += 1;
        Ok(())
    }

    /// Build the blocks of `JᵀJ` and `Jᵀr` at the current window.
    fn assemble(&mut self) -> Result<(), MheError> {
        let n = self.window.len() - 1;
        let s = &self.s;
        let p = slip(&self.p);
        for b in &mut self.blocks[..=n] {
            *b = Blocks::default();
        }
        let mut hpp = Mat::<NP, NP>::zero();
        let mut gp = [0.0; NP];
        // Arrival cost.
        let x0 = self.window[0].x;
        for k in 0..NX {
            let w = 1.0 / s.sigma_x0[k].powi(2);
            self.blocks[0].d.0[k][k] += w;
            let e = if k == 2 {
                wrap(x0[k] - self.x_bar[k])
            } else {
                x0[k] - self.x_bar[k]
            };
            self.blocks[0].g[k] += w * e;
        }
        for k in 0..NP {
            let w = 1.0 / s.sigma_p[k].powi(2);
            hpp.0[k][k] += w;
            gp[k] += w * (self.p[k] - self.p_bar[k]);
        }
        // Measurements.
        let wheel_r = self.model.params.wheel_radius;
        let contacts = self.model.params.contacts();
        for i in 0..=n {
            let st = self.window[i];
            let loads = st.loads.map(|l| (l, self.load_model(&st.x, &st.u, &p)));
            let b = &mut self.blocks[i];
            let mut scalar = |h: &[f64; NX], hp: &[f64; NP], r: f64, sigma: f64| {
                let w = 1.0 / (sigma * sigma);
                for a in 0..NX {
                    b.g[a] += w * h[a] * r;
                    for c in 0..NX {
                        b.d.0[a][c] += w * h[a] * h[c];
                    }
                    for c in 0..NP {
                        b.c.0[c][a] += w * hp[c] * h[a];
                    }
                }
                for a in 0..NP {
                    gp[a] += w * hp[a] * r;
                    for c in 0..NP {
                        hpp.0[a][c] += w * hp[a] * hp[c];
                    }
                }
            };
            let unit =
                |k: usize| -> [f64; NX] { std::array::from_fn(|j| f64::from(u8::from(j == k))) };
            let no_p = [0.0; NP];
            if let Some(pose) = st.pose {
                scalar(&unit(0), &no_p, st.x[0] - pose[0], st.pose_sigma[0]);
                scalar(&unit(1), &no_p, st.x[1] - pose[1], st.pose_sigma[0]);
                scalar(&unit(2), &no_p, st.x[2] - pose[2], st.pose_sigma[1]);
            }
            if let Some(g) = st.gyro {
                scalar(&unit(4), &no_p, st.x[4] - g, s.sigma_gyro);
            }
            if let Some(e) = st.encoders {
                let r = wheel_r;
                for k in 0..4 {
                    let dy = contacts[k][1];
                    let mut h = [0.0; NX];
                    h[3] = 1.0 / r;
                    h[4] = -dy / r;
                    scalar(
                        &h,
                        &no_p,
                        (st.x[3] - dy * st.x[4]) / r - e[k],
                        s.sigma_encoder,
                    );
                }
            }
            if let Some((l, (pred, jx, jp))) = loads {
                for k in 0..4 {
                    scalar(&jx[k], &jp[k], pred[k] - l[k], s.sigma_load);
                }
            }
        }
        // Visual odometry: r = motion from x_i to x_{i+1} in the frame of x_i − measured.
        for i in 0..n {
            let Some(rel) = self.window[i].rel else {
                continue;
            };
            let (a, b) = (self.window[i].x, self.window[i + 1].x);
            let (sn, c) = a[2].sin_cos();
            let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
            let r = [
                c * dx + sn * dy - rel[0],
                -sn * dx + c * dy - rel[1],
                b[2] - a[2] - rel[2],
            ];
            // Rows of ∂r/∂x_i and ∂r/∂x_{i+1}.
            let ja = [
                [-c, -sn, -sn * dx + c * dy, 0.0, 0.0],
                [sn, -c, -c * dx - sn * dy, 0.0, 0.0],
                [0.0, 0.0, -1.0, 0.0, 0.0],
            ];
            let jb = [
                [c, sn, 0.0, 0.0, 0.0],
                [-sn, c, 0.0, 0.0, 0.0],
                [0.0, 0.0, 1.0, 0.0, 0.0],
            ];
            let w = [
                1.0 / s.sigma_vo_step.powi(2),
                1.0 / s.sigma_vo_step.powi(2),
                1.0 / s.sigma_vo_turn.powi(2),
            ];
            for k in 0..3 {
                for m in 0..NX {
                    self.blocks[i].g[m] += w[k] * ja[k][m] * r[k];
                    self.blocks[i + 1].g[m] += w[k] * jb[k][m] * r[k];
                    for q in 0..NX {
                        self.blocks[i].d.0[m][q] += w[k] * ja[k][m] * ja[k][q];
                        self.blocks[i + 1].d.0[m][q] += w[k] * jb[k][m] * jb[k][q];
                        self.blocks[i].o.0[m][q] += w[k] * ja[k][m] * jb[k][q];
                    }
                }
            }
        }
        // IMU heading: r = (φ_{i+1} − φ_i) − (h_{i+1} − h_i), the integrated gyro.
        let w = 1.0 / s.sigma_heading_step.powi(2);
        for i in 0..n {
            let (Some(h0), Some(h1)) = (self.window[i].heading, self.window[i + 1].heading) else {
                continue;
            };
            let r = (self.window[i + 1].x[2] - self.window[i].x[2]) - wrap(h1 - h0);
            self.blocks[i].d.0[2][2] += w;
            self.blocks[i + 1].d.0[2][2] += w;
            self.blocks[i].o.0[2][2] -= w;
            self.blocks[i].g[2] -= w * r;
            self.blocks[i + 1].g[2] += w * r;
        }
        // Dynamics: r = x_{i+1} − F(x_i, u_i, p), weights 1/σ_w².
        for i in 0..n {
            let st = self.window[i];
            let (next, j) = self
                .model
                .rk4_sensitivities(&st.x, &st.u, &p, s.dt, s.rk4_steps);
            if next.iter().any(|v| !v.is_finite()) {
                return Err(MheError::Solve("the model prediction is not finite".into()));
            }
            self.lin[i] = j;
            let x1 = self.window[i + 1].x;
            let r: [f64; NX] = std::array::from_fn(|k| x1[k] - next[k]);
            let w: [f64; NX] = s.sigma_w.map(|v| 1.0 / (v * v));
            let a = Mat(j.x);
            let pm = Mat(j.p);
            // W A and W P (rows scaled).
            let wa = Mat(std::array::from_fn(|k| a.0[k].map(|v| v * w[k])));
            let wp = Mat(std::array::from_fn(|k| pm.0[k].map(|v| v * w[k])));
            let wr: [f64; NX] = std::array::from_fn(|k| w[k] * r[k]);
            {
                let b = &mut self.blocks[i];
                b.d = b.d.add(&a.tmul(&wa));
                for c in 0..NX {
                    for k in 0..NX {
                        b.o.0[c][k] -= wa.0[k][c];
                    }
                    b.g[c] -= a.col_dot(c, &wr);
                }
                b.c = b.c.add(&pm.tmul(&wa));
            }
            {
                let b = &mut self.blocks[i + 1];
                for k in 0..NX {
                    b.d.0[k][k] += w[k];
                    b.g[k] += wr[k];
                    for c in 0..NP {
                        b.c.0[c][k] -= wp.0[k][c];
                    }
                }
            }
            hpp = hpp.add(&pm.tmul(&wp));
            for c in 0..NP {
                gp[c] -= pm.col_dot(c, &wr);
            }
        }
        self.hpp = hpp;
        self.gp = gp;
        Ok(())
    }
}

impl Mhe {
    /// Predicted wheel loads of the force sensors and their Jacobians: static loads
    /// plus the transfer of the body accelerations `a_x = v̇ + x₀ω²`,
    /// `a_y = vω − x₀ω̇` (as the plant computes them).
    fn load_model(
        &self,
        x: &State5,
        u: &Torques,
        p: &SlipParams,
    ) -> ([f64; 4], [[f64; NX]; 4], [[f64; NP]; 4]) {
        let pr = &self.model.params;
        let f = self.model.f(x, u, p);
        let j = self.model.f_jacobians(x, u, p);
        let (v, w, x0) = (x[3], x[4], p.x_icr);
        let ax = f[3] + x0 * w * w;
        let ay = v * w - x0 * f[4];
        let mut ax_x = j.x[3];
        ax_x[4] += 2.0 * x0 * w;
        let mut ax_p = j.p[3];
        ax_p[0] += w * w;
        let mut ay_x: [f64; NX] = std::array::from_fn(|k| -x0 * j.x[4][k]);
        ay_x[3] += w;
        ay_x[4] += v;
        let mut ay_p: [f64; NP] = std::array::from_fn(|k| -x0 * j.p[4][k]);
        ay_p[0] -= f[4];
        let long = pr.mass * pr.cog_height / (2.0 * (pr.front + pr.rear));
        let lat = pr.mass * pr.cog_height / (4.0 * pr.half_track);
        let n0 = pr.static_loads();
        let d = pr.contacts();
        let mut loads = [0.0; 4];
        let mut jx = [[0.0; NX]; 4];
        let mut jp = [[0.0; NP]; 4];
        for i in 0..4 {
            let front = if d[i][0] > 0.0 { -1.0 } else { 1.0 };
            let left = if d[i][1] > 0.0 { -1.0 } else { 1.0 };
            loads[i] = n0[i] + front * long * ax + left * lat * ay;
            jx[i] = std::array::from_fn(|k| front * long * ax_x[k] + left * lat * ay_x[k]);
            jp[i] = std::array::from_fn(|k| front * long * ax_p[k] + left * lat * ay_p[k]);
        }
        (loads, jx, jp)
    }
}
