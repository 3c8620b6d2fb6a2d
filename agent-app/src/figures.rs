//! A run's figures from its samples: the root mean square and the largest
//! of a measure over the run (a controller's tracking error, an
//! estimator's error), as a summary line states them.
//!
//! ```
//! use agent_app::figures::{largest, rms};
//!
//! let errors = [0.03, -0.04];
//! assert!((rms(errors) - 0.035355).abs() < 1e-6);
//! assert_eq!(largest(errors), 0.03);
//! assert_eq!((rms([]), largest([])), (0.0, 0.0), "no sample: nothing to measure");
//! ```

/// The root mean square of `values` (0 for none).
pub fn rms(values: impl IntoIterator<Item = f64>) -> f64 {
    let (n, sum) = values
        .into_iter()
        .fold((0usize, 0.0), |(n, s), v| (n + 1, s + v * v));
    if n == 0 { 0.0 } else { (sum / n as f64).sqrt() }
}

/// The largest of `values`, and at least 0 (0 for none; a NaN is passed
/// over): the worst of an error that is never negative.
pub fn largest(values: impl IntoIterator<Item = f64>) -> f64 {
    values.into_iter().fold(0.0, f64::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rms_weighs_every_sample_alike() {
        assert_eq!(rms([3.0, 4.0, 0.0, 0.0]), 2.5);
        assert_eq!(rms([-2.0]), 2.0);
        assert_eq!(rms(std::iter::empty()), 0.0);
    }

    #[test]
    fn largest_passes_over_nan_and_is_never_negative() {
        assert_eq!(largest([0.1, f64::NAN, 0.3, 0.2]), 0.3);
        assert_eq!(largest([-1.0, -2.0]), 0.0);
    }
}
