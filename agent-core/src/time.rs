//! Virtual time, periods and the iteration stamps carried by buffers.
//!
//! The paper counts the discrete time of each subsystem separately: `ι` is the
//! iteration number of one subsystem's activity. The executor additionally keeps a
//! global virtual clock in integer nanoseconds, so that subsystems with different
//! periods (multi-rate) are interleaved exactly, without floating-point drift.

use std::fmt;
use std::num::NonZeroU64;
use std::time::Duration;

use serde::{Deserialize, Serialize};

/// A point in virtual time: nanoseconds since the start of a run.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize,
)]
pub struct Time(u64);

impl Time {
    /// The start of every run.
    pub const ZERO: Time = Time(0);
    /// A time no run reaches; used for "never again".
    pub const NEVER: Time = Time(u64::MAX);

    /// The time `nanos` nanoseconds after the start.
    pub const fn from_nanos(nanos: u64) -> Time {
        Time(nanos)
    }

    /// Nanoseconds since the start.
    pub const fn as_nanos(self) -> u64 {
        self.0
    }

    /// Seconds since the start.
    pub fn as_secs_f64(self) -> f64 {
        self.0 as f64 * 1e-9
    }

    /// `self + d`, saturating at [`Time::NEVER`].
    pub fn saturating_add(self, d: Duration) -> Time {
        let nanos = u64::try_from(d.as_nanos()).unwrap_or(u64::MAX);
        Time(self.0.saturating_add(nanos))
    }

    /// The duration elapsed since `earlier` (zero if `earlier` is later).
    pub fn since(self, earlier: Time) -> Duration {
        Duration::from_nanos(self.0.saturating_sub(earlier.0))
    }
}

impl fmt::Display for Time {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if *self == Time::NEVER {
            return f.write_str("never");
        }
        write!(f, "{:.6} s", self.as_secs_f64())
    }
}

/// The period of a subsystem or a driver: how much virtual time one iteration takes.
///
/// A period is never zero; the constructors return [`PeriodError`] instead.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct Period(NonZeroU64);

/// Why a [`Period`] could not be made.
#[derive(Clone, Copy, Debug, PartialEq, thiserror::Error)]
pub enum PeriodError {
    /// The period was zero.
    #[error("a period must be positive, got zero")]
    Zero,
    /// A frequency or duration that is not a positive finite number.
    #[error("a period needs a positive finite number, got {0}")]
    NotPositive(f64),
    /// A positive period that rounds to zero nanoseconds.
    #[error("a period of {0} s rounds to 0 ns (periods are whole nanoseconds)")]
    BelowResolution(f64),
    /// The period does not fit in 64-bit nanoseconds (about 584 years) \[s\].
    #[error("a period of {0} s is too long (at most 2^64 ns, about 584 years)")]
    TooLong(f64),
}

impl Period {
    /// A period of `nanos` nanoseconds.
    pub fn from_nanos(nanos: u64) -> Result<Period, PeriodError> {
        NonZeroU64::new(nanos).map(Period).ok_or(PeriodError::Zero)
    }

    /// A period of `micros` microseconds.
    pub fn from_micros(micros: u64) -> Result<Period, PeriodError> {
        Self::from_duration(Duration::from_micros(micros))
    }

    /// A period of `millis` milliseconds.
    pub fn from_millis(millis: u64) -> Result<Period, PeriodError> {
        Self::from_duration(Duration::from_millis(millis))
    }

    /// The period of a rate of `hz` iterations per second, rounded to the nanosecond.
    pub fn from_hz(hz: f64) -> Result<Period, PeriodError> {
        if !(hz.is_finite() && hz > 0.0) {
            return Err(PeriodError::NotPositive(hz));
        }
        Self::from_secs_f64(1.0 / hz)
    }

    /// A period of `secs` seconds, rounded to the nanosecond.
    pub fn from_secs_f64(secs: f64) -> Result<Period, PeriodError> {
        if !(secs.is_finite() && secs > 0.0) {
            return Err(PeriodError::NotPositive(secs));
        }
        let nanos = (secs * 1e9).round();
        if nanos >= u64::MAX as f64 {
            return Err(PeriodError::TooLong(secs));
        }
        Self::from_nanos(nanos as u64).map_err(|_| PeriodError::BelowResolution(secs))
    }

    /// A period of `ms` milliseconds, as specs write them, rounded to the
    /// nanosecond. The spec checker, the generated code and the runtime all use
    /// this rule, so a period the checker accepts is one the runtime can run.
    ///
    /// ```
    /// use agent_core::{Period, PeriodError};
    /// assert_eq!(Period::from_millis_f64(9.0)?.as_nanos(), 9_000_000);
    /// assert_eq!(Period::from_millis_f64(1e-7), Err(PeriodError::BelowResolution(1e-10)));
    /// assert!(matches!(Period::from_millis_f64(1e308), Err(PeriodError::TooLong(_))));
    /// assert_eq!(Period::from_millis_f64(-1.0), Err(PeriodError::NotPositive(-1.0)));
    /// # Ok::<(), PeriodError>(())
    /// ```
    pub fn from_millis_f64(ms: f64) -> Result<Period, PeriodError> {
        if !(ms.is_finite() && ms > 0.0) {
            return Err(PeriodError::NotPositive(ms));
        }
        Self::from_secs_f64(ms * 1e-3)
    }

    /// A period equal to `d`.
    pub fn from_duration(d: Duration) -> Result<Period, PeriodError> {
        let nanos =
            u64::try_from(d.as_nanos()).map_err(|_| PeriodError::TooLong(d.as_secs_f64()))?;
        Self::from_nanos(nanos)
    }

    /// The period in nanoseconds (never zero).
    pub const fn as_nanos(self) -> u64 {
        self.0.get()
    }

    /// The period as a [`Duration`].
    pub fn as_duration(self) -> Duration {
        Duration::from_nanos(self.0.get())
    }

    /// The period in seconds.
    pub fn as_secs_f64(self) -> f64 {
        self.0.get() as f64 * 1e-9
    }
}

impl fmt::Display for Period {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:?}", self.as_duration())
    }
}

/// When a buffer's content was written: the writer's iteration `ι` and the virtual time.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
pub struct Stamp {
    /// Iteration of the writing subsystem (or driver) in which the value was computed.
    pub iteration: u64,
    /// Virtual time at which the value was sent.
    pub time: Time,
}

impl Stamp {
    /// A stamp for iteration `iteration` at `time`.
    pub const fn new(iteration: u64, time: Time) -> Stamp {
        Stamp { iteration, time }
    }
}

impl fmt::Display for Stamp {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "ι={} @ {}", self.iteration, self.time)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_period_is_an_error() {
        assert_eq!(Period::from_millis(0), Err(PeriodError::Zero));
        assert_eq!(Period::from_nanos(0), Err(PeriodError::Zero));
        assert_eq!(
            Period::from_duration(Duration::ZERO),
            Err(PeriodError::Zero)
        );
        assert!(matches!(
            Period::from_hz(0.0),
            Err(PeriodError::NotPositive(_))
        ));
        assert!(matches!(
            Period::from_hz(f64::NAN),
            Err(PeriodError::NotPositive(_))
        ));
        assert!(matches!(
            Period::from_secs_f64(-1.0),
            Err(PeriodError::NotPositive(_))
        ));
        // 0.1 ns rounds to zero nanoseconds.
        assert_eq!(
            Period::from_secs_f64(1e-10),
            Err(PeriodError::BelowResolution(1e-10))
        );
        assert!(matches!(
            Period::from_secs_f64(1e300),
            Err(PeriodError::TooLong(_))
        ));
    }

    #[test]
    fn periods_are_exact_in_nanoseconds() {
        assert_eq!(Period::from_hz(1000.0).unwrap().as_nanos(), 1_000_000);
        assert_eq!(Period::from_millis(50).unwrap().as_nanos(), 50_000_000);
        assert_eq!(
            Period::from_hz(3.0).unwrap().as_nanos(),
            333_333_333,
            "rounded to the nanosecond"
        );
    }

    #[test]
    fn time_arithmetic_saturates() {
        let t = Time::from_nanos(u64::MAX - 1).saturating_add(Duration::from_secs(1));
        assert_eq!(t, Time::NEVER);
        assert_eq!(
            Time::from_nanos(5).since(Time::from_nanos(9)),
            Duration::ZERO
        );
    }
}
