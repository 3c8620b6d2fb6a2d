//! How a wheel's slip settles after its torque changes: what the lateral
//! model's encoder prediction ([`super::Lateral`], through
//! [`super::Dynamics::encoder_rates_settling`]) takes from the plant's wheel
//! spin, which the model otherwise eliminates.
//!
//! The plant's wheel `J_w θ̈ = τ − r F_x − r μ_r N sg(r θ̇)` with
//! `θ̇ = (v_ix + s) / r` gives, for the slip `s`,
//!
//! ```text
//! κ ṡ = g − μ_x N sg(s),     κ = J_w / r²
//! ```
//!
//! where `g = τ / r − μ_r N sg − κ v̇_ix` is what the ground is asked for, the
//! lateral model's `g_i` (as the fraction `ζ = g / (μ_x N)` of the bound). The
//! model takes `s` as settled at once, `sg(s) = ζ`; its time constant is
//! `κ / (μ_x N sg′(s))`: a millisecond on concrete at no slip, 8 ms on ice,
//! and 80 ms on ice at 80 % of the bound, against the MHE's 50 ms samples. On
//! ice the settled slip was wrong often enough to bias the MHE's friction
//! (`μ_x` high, the rolling resistance `μ_r` low): the encoders, read at the end
//! of a sample, still show part of the slip of the torque before.
//!
//! So the MHE predicts each encoder from the slip its previous reading showed,
//! integrated over the sample under the torque of the interval ([`settle_slip`]:
//! backward Euler, stable at any stiffness; the slip of the previous reading
//! enters as data), and as the encoder counts it: the mean over its counting
//! window (the plant's 10 ms; [`super::Lateral::with_encoder_window`]), not
//! the slip at the sample's instant. On ice it took most of what was left of
//! the MHE's average `μ_r` error. The measurements of this module's choices:
//! docs/measurements.md, "The lateral-slip model's friction".

use super::dynamics::{sg, sg_inverse, sg_prime};

/// Backward Euler steps over one sample. With a counting window the last one
/// crosses the window (two inside it leave fewer before it, whose lag
/// dominates: a larger error against the finely integrated equation).
const STEPS: usize = 5;

/// The slip `h` seconds after `start` \[m/s\] of a wheel whose ground is asked
/// for the fraction `zeta` (`|ζ| < 1`) of its traction bound `cap = μ_x N`
/// \[N\], the wheel's spin inertia at its rim being `kappa = J_w / r²` \[kg\]:
/// `κ ṡ = cap (ζ − sg(s))` by backward Euler in five steps; with a `window`
/// \[s\], the slip's mean over the last `window` seconds of the `h` (an encoder
/// counts its ticks over such a window: the plant's over 10 ms, a fifth of the
/// MHE's sample, in which the slip on ice moves by up to 70 % of its way).
/// Returns the slip and its derivatives by `zeta` and by `cap`.
///
/// Each step's implicit equation is increasing in `s` with its root between
/// the step's start and the settled slip `sg⁻¹(ζ)`: Newton's method kept
/// inside that bracket (bisection where a Newton step leaves it). With a
/// window, the first four steps reach its start and the last crosses it; its
/// mean is the trapezoid of its two ends. With `h = 0` the slip is `start`; as
/// `h` grows it tends to `sg⁻¹(ζ)`, the settled one. `None` for inputs outside
/// that (`|ζ| ≥ 1`, which no slip settles at; `h` or `window` negative; a
/// bound, inertia or smoothing not positive; anything not finite) or a result
/// that is not finite.
pub fn settle_slip(
    k_s: f64,
    kappa: f64,
    cap: f64,
    zeta: f64,
    start: f64,
    h: f64,
    window: f64,
) -> Option<(f64, f64, f64)> {
    let valid = zeta.abs() < 1.0
        && start.is_finite()
        && [h, window].iter().all(|v| *v >= 0.0 && v.is_finite())
        && [k_s, kappa, cap].iter().all(|v| *v > 0.0 && v.is_finite());
    if !valid {
        return None;
    }
    let wheel = Wheel {
        k_s,
        cap,
        zeta,
        settled: sg_inverse(k_s, zeta).0,
    };
    let window = window.min(h);
    let before = if window > 0.0 { STEPS - 1 } else { STEPS };
    let c = (h - window) / before as f64 * cap / kappa;
    let mut slip = Slip {
        s: start,
        by_zeta: 0.0,
        by_cap: 0.0,
    };
    for _ in 0..before {
        slip = wheel.step(slip, c);
    }
    if window > 0.0 {
        // The mean over the window: the trapezoid of its two ends.
        let end = wheel.step(slip, window * cap / kappa);
        slip = Slip {
            s: 0.5 * (slip.s + end.s),
            by_zeta: 0.5 * (slip.by_zeta + end.by_zeta),
            by_cap: 0.5 * (slip.by_cap + end.by_cap),
        };
    }
    [slip.s, slip.by_zeta, slip.by_cap]
        .iter()
        .all(|v| v.is_finite())
        .then_some((slip.s, slip.by_zeta, slip.by_cap))
}

/// A slip with its derivatives by `ζ` and by the bound.
#[derive(Clone, Copy)]
struct Slip {
    s: f64,
    by_zeta: f64,
    by_cap: f64,
}

/// What a step of [`settle_slip`] needs of the wheel.
struct Wheel {
    k_s: f64,
    cap: f64,
    zeta: f64,
    settled: f64,
}

impl Wheel {
    /// One backward Euler step `s − from = c (ζ − sg(s))`, `c = Δt cap / κ`.
    fn step(&self, from: Slip, c: f64) -> Slip {
        let (k_s, zeta) = (self.k_s, self.zeta);
        let mut s = from.s;
        let (mut lo, mut hi) = (from.s.min(self.settled), from.s.max(self.settled));
        // sg and sg′ at the step's slip, as of the last evaluation.
        let (mut sgs, mut slope) = (sg(k_s, s), sg_prime(k_s, s));
        for _ in 0..100 {
            let g = s - from.s - c * (zeta - sgs);
            if g > 0.0 {
                hi = s;
            } else {
                lo = s;
            }
            let mut next = s - g / (1.0 + c * slope);
            if !(next >= lo && next <= hi) {
                next = 0.5 * (lo + hi);
            }
            let step = next - s;
            s = next;
            sgs = sg(k_s, s);
            slope = sg_prime(k_s, s);
            if step.abs() <= 1e-14 {
                break;
            }
        }
        // Differentiating the step's equation (`c` is proportional to the bound).
        let d = 1.0 + c * slope;
        Slip {
            s,
            by_zeta: (from.by_zeta + c) / d,
            by_cap: (from.by_cap + c / self.cap * (zeta - sgs)) / d,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::dynamics::{EarlierReading, NOT_READ, check};
    use crate::model::{Dynamics, Lateral, PlatformParams, Vector};

    const KS: f64 = 20.0;
    /// The peers' platform: `J_w / r²` = 1 kg; ice's bound on a wheel.
    const KAPPA: f64 = 1.0;
    const ICE: f64 = 0.1 * 98.1;

    #[test]
    fn the_slip_starts_where_it_was_and_settles_where_the_ground_takes_the_traction() {
        for (zeta, start) in [
            (0.5, 0.0),
            (-0.8, 0.3),
            (0.0, -1.0),
            (0.95, 2.0),
            (0.3, 0.3),
        ] {
            let settled = sg_inverse(KS, zeta).0;
            for window in [0.0, 0.01] {
                let at = |h: f64| {
                    settle_slip(KS, KAPPA, ICE, zeta, start, h, window)
                        .unwrap()
                        .0
                };
                let s = at(0.0);
                assert!((s - start).abs() < 1e-12, "{zeta} {start}: {s}");
                let s = at(1e4);
                assert!((s - settled).abs() < 1e-6, "{zeta} {start}: {s} {settled}");
                // Monotone in between, never past the settled slip.
                let mut last = start;
                for k in 1..=20 {
                    let s = at(0.005 * f64::from(k));
                    let toward = (settled - start).signum();
                    assert!((s - last) * toward >= -1e-12, "{zeta} {start} {window}");
                    assert!((settled - s) * toward >= -1e-12, "{zeta} {start} {window}");
                    last = s;
                }
            }
        }
    }

    #[test]
    fn inputs_no_slip_settles_at_are_refused() {
        for (zeta, start, h, window, cap) in [
            (1.0, 0.0, 0.05, 0.0, ICE),
            (-1.2, 0.0, 0.05, 0.0, ICE),
            (f64::NAN, 0.0, 0.05, 0.0, ICE),
            (0.5, f64::INFINITY, 0.05, 0.0, ICE),
            (0.5, 0.0, -0.05, 0.0, ICE),
            (0.5, 0.0, f64::NAN, 0.0, ICE),
            (0.5, 0.0, 0.05, -0.01, ICE),
            (0.5, 0.0, 0.05, f64::NAN, ICE),
            (0.5, 0.0, 0.05, 0.0, 0.0),
        ] {
            assert!(
                settle_slip(KS, KAPPA, cap, zeta, start, h, window).is_none(),
                "{zeta} {start} {h} {window} {cap}"
            );
        }
        assert!(settle_slip(KS, 0.0, ICE, 0.5, 0.0, 0.05, 0.0).is_none());
    }

    #[test]
    fn the_slip_follows_the_wheel_equation() {
        // Against the ODE integrated finely (explicit Euler, 1 µs), at the
        // end and as the mean over the last 10 ms (what an encoder counts):
        // within what backward Euler in five steps leaves, a few percent of
        // the way (measured: 4.5-5.1 % for the window's mean, of which the
        // steps before the window lag most).
        for (zeta, start, h) in [(0.5, 0.0, 0.05_f64), (-0.8, 0.2, 0.05), (0.9, 0.0, 0.02)] {
            let window: f64 = 0.01;
            let (mut s, mut sum) = (start, 0.0);
            let steps = (h / 1e-6).round() as usize;
            let counted = (window / 1e-6).round() as usize;
            for k in 0..steps {
                let next = s + 1e-6 * ICE * (zeta - sg(KS, s)) / KAPPA;
                if k >= steps - counted {
                    sum += 0.5 * (s + next);
                }
                s = next;
            }
            let mean = sum / counted as f64;
            let way = (sg_inverse(KS, zeta).0 - start).abs();
            let (be, _, _) = settle_slip(KS, KAPPA, ICE, zeta, start, h, 0.0).unwrap();
            assert!((be - s).abs() < 0.05 * way, "{zeta} {start} {h}: {be} {s}");
            let (be, _, _) = settle_slip(KS, KAPPA, ICE, zeta, start, h, window).unwrap();
            assert!(
                (be - mean).abs() < 0.06 * way,
                "{zeta} {start} {h}: {be} {mean}"
            );
            // It is the count over the window that it predicts, not the slip
            // at the end.
            assert!((be - mean).abs() < (be - s).abs(), "{be} {mean} {s}");
        }
    }

    #[test]
    fn its_derivatives_match_finite_differences() {
        for (zeta, start, cap, window) in [
            (0.5, 0.0, ICE, 0.0),
            (-0.8, 0.3, ICE, 0.0),
            (0.2, -0.05, 78.5, 0.0),
            (0.5, 0.0, ICE, 0.01),
            (-0.8, 0.3, ICE, 0.01),
        ] {
            let (_, dz, dc) = settle_slip(KS, KAPPA, cap, zeta, start, 0.05, window).unwrap();
            let e = 1e-6;
            let slip = |cap: f64, zeta: f64| {
                settle_slip(KS, KAPPA, cap, zeta, start, 0.05, window)
                    .unwrap()
                    .0
            };
            let fd_z = (slip(cap, zeta + e) - slip(cap, zeta - e)) / (2.0 * e);
            let ec = 1e-6 * cap;
            let fd_c = (slip(cap + ec, zeta) - slip(cap - ec, zeta)) / (2.0 * ec);
            assert!((dz - fd_z).abs() < 1e-6 * (1.0 + fd_z.abs()), "{dz} {fd_z}");
            assert!((dc - fd_c).abs() < 1e-6 * (1.0 + fd_c.abs()), "{dc} {fd_c}");
        }
    }

    /// A point of the lateral model on ice with every wheel below its bound.
    fn ice_point() -> (Lateral, Vector<6>, Vector<4>, Vector<3>) {
        (
            Lateral::new(PlatformParams::peer_default()),
            Vector::from([0.3, -0.2, 0.7, 0.4, 0.02, 0.6]),
            Vector::from([0.5, 0.4, 0.3, 0.2]),
            Vector::from([0.1, 0.07, 0.01]),
        )
    }

    #[test]
    fn from_the_settled_slip_or_without_a_reading_the_prediction_is_the_settled_one() {
        let (m, x, u, p) = ice_point();
        let settled = m.encoder_rates(&x, &u, &p);
        assert!(settled.iter().all(Option::is_some));
        // No readings before (NaN), or no time since: bit for bit.
        for (previous, h) in [([f64::NAN; 4], 0.05), ([0.0; 4], 0.0)] {
            let again = m.encoder_rates_settling(
                &EarlierReading {
                    x,
                    rates: previous,
                    h,
                },
                &x,
                &u,
                &p,
                &NOT_READ,
            );
            for (a, b) in settled.iter().zip(&again) {
                let (a, b) = (a.as_ref().unwrap(), b.as_ref().unwrap());
                assert_eq!(a.value.to_bits(), b.value.to_bits());
                assert_eq!((a.x, a.p), (b.x, b.p));
            }
        }
        // Readings that already showed the settled slip, at the same state:
        // the same rates, counted over a window or not.
        let previous = settled.map(|m| m.map_or(f64::NAN, |m| m.value));
        let counting = m.clone().with_encoder_window(0.01).unwrap();
        let lags = |m: &Lateral, rates: [f64; 4]| {
            m.encoder_rates_settling(&EarlierReading { x, rates, h: 0.05 }, &x, &u, &p, &NOT_READ)
                .map(|m| m.map_or(f64::NAN, |m| m.value))
        };
        for (a, b) in previous.iter().zip(lags(&counting, previous)) {
            assert!((a - b).abs() < 1e-9, "{a} {b}");
        }
        let from = m.encoder_rates_settling(
            &EarlierReading {
                x,
                rates: previous,
                h: 0.05,
            },
            &x,
            &u,
            &p,
            &NOT_READ,
        );
        for (a, b) in settled.iter().zip(&from) {
            let (a, b) = (a.as_ref().unwrap(), b.as_ref().unwrap());
            assert!((a.value - b.value).abs() < 1e-9, "{} {}", a.value, b.value);
        }
        // Readings of a wheel still at the body's speed (no slip yet): the
        // prediction lies between that and the settled rate.
        let x_prev = x;
        let rolling = [0, 1, 2, 3].map(|i| {
            let dy = PlatformParams::peer_default().contacts()[i][1];
            (x[3] - dy * x[5]) / 0.1
        });
        let lagged = m.encoder_rates_settling(
            &EarlierReading {
                x: x_prev,
                rates: rolling,
                h: 0.05,
            },
            &x,
            &u,
            &p,
            &NOT_READ,
        );
        for i in 0..4 {
            let (a, b) = (
                settled[i].as_ref().unwrap().value,
                lagged[i].as_ref().unwrap().value,
            );
            let t = (b - rolling[i]) / (a - rolling[i]);
            assert!(t > 0.5 && t < 1.0, "wheel {i}: {t}");
            // Counted over the last 10 ms, the rate is the window's mean,
            // short of the instant's.
            let counted = (lags(&counting, rolling)[i] - rolling[i]) / (a - rolling[i]);
            assert!(counted > 0.3 && counted < t, "wheel {i}: {counted} {t}");
        }
        for bad in [-0.01, f64::NAN, f64::INFINITY] {
            assert!(m.clone().with_encoder_window(bad).is_none());
        }
    }

    #[test]
    fn the_settling_predictions_gradients_match_finite_differences() {
        let (m, x, u, p) = ice_point();
        let previous = [4.5, 4.0, 3.0, 3.2];
        let x_prev = Vector::from([0.28, -0.21, 0.68, 0.38, 0.02, 0.55]);
        let counting = m.clone().with_encoder_window(0.01).unwrap();
        for (m, i) in [&m, &counting]
            .into_iter()
            .flat_map(|m| (0..4).map(move |i| (m, i)))
        {
            check::measured(
                &format!("settling encoder {i}"),
                |x, p| {
                    m.encoder_rates_settling(
                        &EarlierReading {
                            x: x_prev,
                            rates: previous,
                            h: 0.05,
                        },
                        x,
                        &u,
                        p,
                        &NOT_READ,
                    )[i]
                        .expect("every wheel below its bound")
                },
                &x,
                &p,
            );
        }
    }
}
