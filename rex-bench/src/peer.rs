//! The benchmark problems of `peers/casadi_nmpc.py` and `peers/casadi_mhe.py`, with
//! their constants, so that our figures and the peers' are measured on the same
//! problem: the figure-eight reference (lemniscate of Gerono, slip-consistent heading,
//! notes §1.2), the closed loop (plant = the same model with 10 RK4 steps per
//! interval), the start offset, the measurement noise levels.

use rex_agent::algorithms::mpc::mhe::{Sample, TimedPose};
use rex_agent::algorithms::mpc::nmpc::{Nmpc, NmpcError, NmpcSettings};
use rex_agent::algorithms::planner::nearest_angle;
use rex_agent::math::rng::Rng;
use rex_agent::model::{PlatformParams, Reduced, SlipParams, State5, Torques};

/// Interval \[s\] (`DT`).
pub const DT: f64 = 0.05;
/// Closed-loop steps: one lap (`N_SIM`).
pub const N_SIM: usize = 200;
/// RK4 steps per interval of the simulated plant (`RK4_STEPS_PLANT`).
pub const PLANT_RK4_STEPS: usize = 10;
/// Half-width of the lemniscate \[m\] (`REF_A`).
pub const REF_A: f64 = 1.0;
/// One lap \[s\] (`REF_PERIOD`).
pub const REF_PERIOD: f64 = 10.0;
/// Initial state = reference at 0 plus this (`INIT_OFFSET`).
pub const INIT_OFFSET: State5 = [0.10, -0.10, 0.0, 0.0, 0.0];
/// The transient excluded from the steady RMS \[s\] (`SS_SKIP_S`).
pub const SS_SKIP_S: f64 = 2.0;

/// The figure-eight reference `(X, Y, φ, v, ω)` at `t`, with the heading and
/// speed made consistent with the lateral-slip constraint at the nominal ICR
/// offset: `v = √(s² − (x₀ω)²)`, `φ = ψ + atan2(x₀ω, v)` (φ wrapped to (−π, π];
/// see [`reference_run`] for the unwrapped sequence).
pub fn reference(t: f64) -> State5 {
    let w = 2.0 * std::f64::consts::PI / REF_PERIOD;
    let (x, y) = (REF_A * (w * t).sin(), 0.5 * REF_A * (2.0 * w * t).sin());
    let (dx, dy) = (REF_A * w * (w * t).cos(), REF_A * w * (2.0 * w * t).cos());
    let (ddx, ddy) = (
        -REF_A * w * w * (w * t).sin(),
        -2.0 * REF_A * w * w * (2.0 * w * t).sin(),
    );
    let s2 = dx * dx + dy * dy;
    let psi = dy.atan2(dx);
    let om = (dx * ddy - dy * ddx) / s2;
    let lat = SlipParams::NOMINAL.x_icr * om;
    let v = (s2 - lat * lat).max(0.0).sqrt();
    [x, y, psi + lat.atan2(v), v, om]
}

/// The reference at `k · DT` for `k = 0..n`, heading unwrapped over the run.
pub fn reference_run(n: usize) -> Vec<State5> {
    let mut out: Vec<State5> = (0..n).map(|k| reference(k as f64 * DT)).collect();
    for k in 1..out.len() {
        let prev = out[k - 1][2];
        out[k][2] = nearest_angle(out[k][2], prev);
    }
    out
}

/// The platform of the peers.
pub fn model() -> Reduced {
    Reduced::new(PlatformParams::peer_default())
}

/// Parameters of the plant in the MHE problem (`P_TRUE_MHE`).
pub const P_TRUE_MHE: SlipParams = SlipParams {
    x_icr: 0.06,
    mu_s: 0.07,
    mu_l: 0.60,
};

/// Standard deviations of the MHE problem's measurements `(X, Y, φ, ω_gyro,
/// θ̇_1..θ̇_4)` (`SIGMA_POS`, `SIGMA_PHI`, `SIGMA_GYRO`, `SIGMA_ENC`).
pub const SIGMA_Y: [f64; 8] = [0.02, 0.02, 0.01, 0.01, 0.05, 0.05, 0.05, 0.05];

/// The data of the MHE problem: true states `x_0..x_N_SIM`, applied torques
/// `u_0..u_{N_SIM−1}`, measurements `y_0..y_N_SIM`.
#[derive(Clone, Debug)]
pub struct MheData {
    /// True states.
    pub xs: Vec<State5>,
    /// Torques applied over each interval.
    pub us: Vec<Torques>,
    /// Noisy measurements `(X, Y, φ, ω, θ̇_1..4)`.
    pub ys: Vec<[f64; 8]>,
}

impl MheData {
    /// The MHE's sample at `k`: the pose (at `k · DT`), the gyro and the encoders.
    pub fn sample(&self, k: usize) -> Sample {
        let y = self.ys[k];
        Sample {
            pose: Some(TimedPose {
                time: k as f64 * DT,
                pose: [y[0], y[1], y[2]],
            }),
            gyro: Some(y[3]),
            encoders: Some([y[4], y[5], y[6], y[7]]),
            ..Sample::default()
        }
    }
}

/// The peer's data set: the plant with [`P_TRUE_MHE`] driven around the figure
/// eight by the NMPC (real-time iteration, nominal parameters) that knows the true
/// state, measurements with [`SIGMA_Y`] noise from a seeded generator (NumPy's in
/// the peer, so the samples differ, not their statistics).
pub fn mhe_data(seed: u64) -> Result<MheData, NmpcError> {
    let model = model();
    let settings = NmpcSettings::default();
    let n = settings.horizon;
    let reference = reference_run(N_SIM + n + 1);
    let mut nmpc = Nmpc::new(model.clone(), settings)?;
    let mut rng = Rng::new(seed);
    let mut measure = |x: &State5| -> [f64; 8] {
        let enc = model.wheel_rates(x[3], x[4]);
        let clean = [x[0], x[1], x[2], x[4], enc[0], enc[1], enc[2], enc[3]];
        std::array::from_fn(|i| clean[i] + rng.gauss(SIGMA_Y[i]))
    };
    let mut x = reference[0];
    for i in 0..5 {
        x[i] += INIT_OFFSET[i];
    }
    let mut data = MheData {
        xs: vec![x],
        us: Vec::new(),
        ys: vec![measure(&x)],
    };
    for k in 0..N_SIM {
        let c = nmpc.control(&x, &reference[k..=k + n], &SlipParams::NOMINAL.to_array())?;
        x = model.rk4_5(&x, &c.torques, &P_TRUE_MHE, DT, PLANT_RK4_STEPS);
        data.us.push(c.torques);
        data.xs.push(x);
        data.ys.push(measure(&x));
    }
    Ok(data)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Golden values of notes §1.6: `x_d(0)` and `x_d(1.25 s)` (written as printed
    /// there, not as constants).
    #[test]
    #[expect(
        clippy::approx_constant,
        reason = "the golden values as the notes print them"
    )]
    fn reference_golden_values() {
        let r = reference_run(26);
        let golden = [
            (
                0,
                [0.0, 0.0, std::f64::consts::FRAC_PI_4, 0.888576587632, 0.0],
            ),
            (
                25,
                [
                    0.707106781187,
                    0.5,
                    -0.120289882395,
                    0.441077818479,
                    -1.777153175263,
                ],
            ),
        ];
        for (k, g) in golden {
            for i in 0..5 {
                assert!(
                    (r[k][i] - g[i]).abs() < 1e-9,
                    "x_d[{k}][{i}] = {} vs {}",
                    r[k][i],
                    g[i]
                );
            }
        }
    }
}
