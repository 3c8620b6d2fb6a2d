//! One Gauss–Newton step of the MHE: the normal equations `JᵀJ Δ = −Jᵀr` of the
//! whole window, assembled stage by stage (block-tridiagonal in the states, with a
//! border for the parameters), from the arrival cost, the process model and each
//! stage's measurements; then the step, solved in `solve.rs`, applied within the
//! parameter bounds.

use super::{Blocks, Mhe, MheError};
use crate::algorithms::mpc::QpStrategy;
use crate::math::geometry::wrap;
use crate::model::{Dynamics, Matrix, Measured, NU, SpinRead, Vector, WheelSpin};

/// One scalar residual `r` with standard deviation `sigma` and gradients `h`
/// (states of one stage) and `hp` (parameters), added to the normal equations.
fn add_scalar<const NX: usize, const NP: usize>(
    b: &mut Blocks<NX, NP>,
    hpp: &mut Matrix<NP, NP>,
    gp: &mut Vector<NP>,
    m: &Measured<NX, NP>,
    r: f64,
    sigma: f64,
) {
    let w = 1.0 / (sigma * sigma);
    b.g += m.x * (w * r);
    b.d += m.x * m.x.transpose() * w;
    b.c += m.p * m.x.transpose() * w;
    *gp += m.p * (w * r);
    *hpp += m.p * m.p.transpose() * w;
}

/// The measurement of state component `k` itself (a pose or gyro reading;
/// its value and sigma unused).
fn unit<const NX: usize, const NP: usize>(k: usize) -> Measured<NX, NP> {
    Measured {
        value: 0.0,
        sigma: 0.0,
        x: Vector::<NX>::from_fn(|j, _| f64::from(u8::from(j == k))),
        p: Vector::<NP>::zeros(),
    }
}

/// The motion from `a` to `b` in the frame of `a` minus the measured `rel`,
/// and its Jacobians in `a` and `b` (pose components only).
fn relative_motion<const NX: usize>(
    a: &Vector<NX>,
    b: &Vector<NX>,
    rel: &[f64; 3],
) -> ([f64; 3], Matrix<3, NX>, Matrix<3, NX>) {
    let (sn, c) = a[2].sin_cos();
    let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
    let r = [
        c * dx + sn * dy - rel[0],
        -sn * dx + c * dy - rel[1],
        b[2] - a[2] - rel[2],
    ];
    // Rows of ∂r/∂x_i and ∂r/∂x_{i+1}.
    let mut ja = Matrix::<3, NX>::zeros();
    let mut jb = Matrix::<3, NX>::zeros();
    ja[(0, 0)] = -c;
    ja[(0, 1)] = -sn;
    ja[(0, 2)] = -sn * dx + c * dy;
    ja[(1, 0)] = sn;
    ja[(1, 1)] = -c;
    ja[(1, 2)] = -c * dx - sn * dy;
    ja[(2, 2)] = -1.0;
    jb[(0, 0)] = c;
    jb[(0, 1)] = sn;
    jb[(1, 0)] = -sn;
    jb[(1, 1)] = c;
    jb[(2, 2)] = 1.0;
    (r, ja, jb)
}

impl<M: Dynamics<NX, NP>, const NX: usize, const NP: usize> Mhe<M, NX, NP> {
    /// One Gauss–Newton step on the whole window.
    pub(super) fn gauss_newton(&mut self) -> Result<(), MheError> {
        let n = self.window.len() - 1;
        self.assemble()?;
        let (dx, dp) = match self.s.qp {
            QpStrategy::Structured => self.solve_structured(n)?,
            QpStrategy::Clarabel => self.solve_full(n)?,
        };
        if dx
            .iter()
            .flat_map(|v| v.iter())
            .chain(dp.iter())
            .any(|v| !v.is_finite())
        {
            return Err(MheError::Solve("the step is not finite".into()));
        }
        for (stage, d) in self.window.iter_mut().zip(&dx) {
            stage.x += d;
        }
        for k in 0..NP {
            self.p[k] = (self.p[k] + dp[k]).clamp(self.s.p_lb[k], self.s.p_ub[k]);
        }
        self.stats.steps += 1;
        Ok(())
    }

    /// Build the blocks of `JᵀJ` and `Jᵀr` at the current window: the arrival
    /// cost, each stage's measurements, the visual odometry, the IMU heading
    /// and the dynamics, in this order.
    fn assemble(&mut self) -> Result<(), MheError> {
        let n = self.window.len() - 1;
        for b in &mut self.blocks[..=n] {
            *b = Blocks::default();
        }
        let mut hpp = Matrix::<NP, NP>::zeros();
        let mut gp = Vector::<NP>::zeros();
        self.add_arrival_cost(&mut hpp, &mut gp);
        for i in 0..=n {
            self.add_measurements(i, &mut hpp, &mut gp);
        }
        self.add_odometry();
        self.add_heading();
        self.add_dynamics(&mut hpp, &mut gp)?;
        self.hpp = hpp;
        self.gp = gp;
        Ok(())
    }

    /// The arrival cost: the first state and the parameters against their
    /// priors.
    fn add_arrival_cost(&mut self, hpp: &mut Matrix<NP, NP>, gp: &mut Vector<NP>) {
        let s = &self.s;
        let x0 = self.window[0].x;
        for k in 0..NX {
            let w = 1.0 / s.sigma_x0[k].powi(2);
            self.blocks[0].d[(k, k)] += w;
            let e = if k == 2 {
                wrap(x0[k] - self.x_bar[k])
            } else {
                x0[k] - self.x_bar[k]
            };
            self.blocks[0].g[k] += w * e;
        }
        for k in 0..NP {
            let w = 1.0 / s.sigma_p[k].powi(2);
            hpp[(k, k)] += w;
            gp[k] += w * (self.p[k] - self.p_bar[k]);
        }
    }

    /// Stage `i`'s measurements: the pose, the gyro, the encoders and the
    /// force sensors.
    fn add_measurements(&mut self, i: usize, hpp: &mut Matrix<NP, NP>, gp: &mut Vector<NP>) {
        let s = &self.s;
        let p = self.p;
        let st = self.window[i];
        // The torques of the interval that ends here: what the encoders and
        // the force sensors saw just before this instant.
        let u_in = if i > 0 { self.window[i - 1].u } else { st.u };
        let loads = st.loads.map(|l| {
            // The wheels' spin read here, with their accelerations over
            // that interval.
            let spin = match i.checked_sub(1).map(|k| &self.window[k]) {
                Some(before) => WheelSpin {
                    start: before.spin,
                    end: st.spin,
                }
                .read_at(1.0, st.t - before.t),
                None => SpinRead::rates(st.spin),
            };
            (l, self.load_model(&st.x, &u_in, &p, &spin))
        });
        let encoders = st.encoders.map(|e| (e, self.encoder_prediction(i, &p)));
        let b = &mut self.blocks[i];
        if let Some(pose) = st.pose {
            for k in 0..3 {
                let sigma = st.pose_sigma[usize::from(k == 2)];
                add_scalar(b, hpp, gp, &unit(k), st.x[k] - pose[k], sigma);
            }
        }
        if let Some(g) = st.gyro {
            let k = M::YAW_RATE;
            add_scalar(b, hpp, gp, &unit(k), st.x[k] - g, s.sigma_gyro);
        }
        if let Some((e, predicted)) = encoders {
            for (reading, m) in e.iter().zip(predicted) {
                // A wheel the model cannot predict (spinning) or one gated
                // out when it arrived (NaN) is left out.
                if !reading.is_finite() {
                    continue;
                }
                if let Some(m) = m {
                    let sigma = s.sigma_encoder.hypot(m.sigma);
                    add_scalar(b, hpp, gp, &m, m.value - reading, sigma);
                }
            }
        }
        if let Some((l, predicted)) = loads {
            for (k, m) in predicted.iter().enumerate() {
                let sigma = s.sigma_load.hypot(m.sigma);
                add_scalar(b, hpp, gp, m, m.value - l[k], sigma);
            }
        }
    }

    /// Visual odometry: `r` = the motion from `x_i` to `x_{i+1}` in the frame
    /// of `x_i` − the measured one.
    fn add_odometry(&mut self) {
        let s = &self.s;
        for i in 0..self.window.len() - 1 {
            let Some(rel) = self.window[i].rel else {
                continue;
            };
            let (r, ja, jb) = relative_motion(&self.window[i].x, &self.window[i + 1].x, &rel);
            let w = Vector::<3>::new(
                1.0 / s.sigma_vo_step.powi(2),
                1.0 / s.sigma_vo_step.powi(2),
                1.0 / s.sigma_vo_turn.powi(2),
            );
            let wr = Vector::<3>::from_fn(|k, _| w[k] * r[k]);
            let wja = Matrix::<3, NX>::from_fn(|k, m| w[k] * ja[(k, m)]);
            let wjb = Matrix::<3, NX>::from_fn(|k, m| w[k] * jb[(k, m)]);
            self.blocks[i].g += ja.tr_mul(&wr);
            self.blocks[i + 1].g += jb.tr_mul(&wr);
            self.blocks[i].d += ja.tr_mul(&wja);
            self.blocks[i + 1].d += jb.tr_mul(&wjb);
            self.blocks[i].o += ja.tr_mul(&wjb);
        }
    }

    /// The IMU heading: `r = (φ_{i+1} − φ_i) − (h_{i+1} − h_i)`, the
    /// integrated gyro.
    fn add_heading(&mut self) {
        let w = 1.0 / self.s.sigma_heading_step.powi(2);
        for i in 0..self.window.len() - 1 {
            let (Some(h0), Some(h1)) = (self.window[i].heading, self.window[i + 1].heading) else {
                continue;
            };
            let r = (self.window[i + 1].x[2] - self.window[i].x[2]) - wrap(h1 - h0);
            self.blocks[i].d[(2, 2)] += w;
            self.blocks[i + 1].d[(2, 2)] += w;
            self.blocks[i].o[(2, 2)] -= w;
            self.blocks[i].g[2] -= w * r;
            self.blocks[i + 1].g[2] += w * r;
        }
    }

    /// The dynamics: `r = x_{i+1} − F(x_i, u_i, p)`, weights `1/σ_w²`; an
    /// error if a prediction is not finite.
    fn add_dynamics(
        &mut self,
        hpp: &mut Matrix<NP, NP>,
        gp: &mut Vector<NP>,
    ) -> Result<(), MheError> {
        let s = &self.s;
        let p = self.p;
        let w = Vector::<NX>::from(s.sigma_w.map(|v| 1.0 / (v * v)));
        for i in 0..self.window.len() - 1 {
            let st = self.window[i];
            let spin = WheelSpin {
                start: st.spin,
                end: self.window[i + 1].spin,
            };
            let j =
                self.model
                    .rk4_sensitivities_spinning(&st.x, &st.u, &p, s.dt, s.rk4_steps, &spin);
            if j.value.iter().any(|v| !v.is_finite()) {
                return Err(MheError::Solve("the model prediction is not finite".into()));
            }
            let r = self.window[i + 1].x - j.value;
            // W A, W P (rows scaled) and W r.
            let wa = Matrix::<NX, NX>::from_fn(|k, c| w[k] * j.x[(k, c)]);
            let wp = Matrix::<NX, NP>::from_fn(|k, c| w[k] * j.p[(k, c)]);
            let wr = r.component_mul(&w);
            {
                let b = &mut self.blocks[i];
                b.d += j.x.tr_mul(&wa);
                b.o -= wa.transpose();
                b.g -= j.x.tr_mul(&wr);
                b.c += j.p.tr_mul(&wa);
            }
            {
                let b = &mut self.blocks[i + 1];
                b.d += Matrix::<NX, NX>::from_diagonal(&w);
                b.g += wr;
                b.c -= wp.transpose();
            }
            *hpp += j.p.tr_mul(&wp);
            *gp -= j.p.tr_mul(&wr);
        }
        Ok(())
    }

    /// Predicted wheel loads of the force sensors and their gradients: static
    /// loads plus the transfer of the body accelerations the model predicts
    /// ([`Dynamics::body_accelerations`], as the plant computes them).
    fn load_model(
        &self,
        x: &Vector<NX>,
        u: &Vector<NU>,
        p: &Vector<NP>,
        spin: &SpinRead,
    ) -> [Measured<NX, NP>; 4] {
        let pr = self.model.platform();
        let [ax, ay] = self.model.body_accelerations(x, u, p, spin);
        let long = pr.mass * pr.cog_height / (2.0 * (pr.front + pr.rear));
        let lat = pr.mass * pr.cog_height / (4.0 * pr.half_track);
        let n0 = pr.static_loads();
        let d = pr.contacts();
        std::array::from_fn(|i| {
            let front = if d[i][0] > 0.0 { -long } else { long };
            let left = if d[i][1] > 0.0 { -lat } else { lat };
            Measured {
                value: n0[i] + front * ax.value + left * ay.value,
                sigma: 0.0,
                x: ax.x * front + ay.x * left,
                p: ax.p * front + ay.p * left,
            }
        })
    }
}
