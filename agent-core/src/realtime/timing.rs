//! What the real-time executor measures of each node: wake-up jitter, compute
//! time, overruns. Recorded into fixed histograms (`hdrhistogram`, 2 significant
//! digits, allocated when the thread starts), so measuring allocates nothing per
//! period.

use std::fmt;
use std::time::Duration;

use hdrhistogram::Histogram;

use crate::time::Period;

/// Percentiles of a duration over a run.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Spread {
    /// Median.
    pub p50: Duration,
    /// 99th percentile.
    pub p99: Duration,
    /// Largest.
    pub max: Duration,
}

impl fmt::Display for Spread {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let us = |d: Duration| d.as_secs_f64() * 1e6;
        write!(
            f,
            "{:>9.1} {:>9.1} {:>9.1}",
            us(self.p50),
            us(self.p99),
            us(self.max)
        )
    }
}

/// How one node kept its period.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct NodeTiming {
    /// The node's name.
    pub name: String,
    /// The thread it ran on.
    pub thread: String,
    /// Its period.
    pub period: Period,
    /// Activations executed.
    pub activations: u64,
    /// How late its thread woke after each deadline (the thread's instants:
    /// the nodes of a thread share it).
    pub jitter: Spread,
    /// How long each activation took (decision, action, send; the first
    /// node of an instant on its thread also carries the reads of every node
    /// due then, which all read before any steps).
    pub compute: Spread,
    /// From each activation's deadline (its instant) to its end: the
    /// response time, with the wake-up's lateness, the reads, and the nodes
    /// that ran before it on its thread in that instant.
    pub response: Spread,
    /// Activations that ended after the node's next deadline.
    pub overruns: u64,
}

/// One series of durations: a fixed histogram (`u32` counts, 2 significant
/// digits over 1 ns to a minute: about 15 KB), allocated once.
struct Series(Option<Histogram<u32>>);

/// Durations recorded are clamped to this (one minute), the histograms' range.
const RANGE_NS: u64 = 60_000_000_000;

impl Series {
    fn new() -> Series {
        Series(Histogram::<u32>::new_with_bounds(1, RANGE_NS, 2).ok())
    }

    #[inline]
    fn record(&mut self, ns: u64) {
        if let Some(h) = &mut self.0 {
            h.saturating_record(ns.clamp(1, RANGE_NS));
        }
    }

    fn spread(&self) -> Spread {
        match &self.0 {
            Some(h) if !h.is_empty() => Spread {
                p50: Duration::from_nanos(h.value_at_quantile(0.5)),
                p99: Duration::from_nanos(h.value_at_quantile(0.99)),
                max: Duration::from_nanos(h.max()),
            },
            _ => Spread::default(),
        }
    }
}

/// How late one thread woke after each of its instants' deadlines: every node
/// of the thread due at an instant woke then, so the thread keeps one series
/// for them all.
pub(crate) struct Wakes(Series);

impl Wakes {
    pub(crate) fn new() -> Wakes {
        Wakes(Series::new())
    }

    #[inline]
    pub(crate) fn record(&mut self, jitter_ns: u64) {
        self.0.record(jitter_ns);
    }
}

/// The histograms of one node, filled by its thread.
pub(crate) struct Recorder {
    compute: Series,
    response: Series,
    pub(crate) activations: u64,
    pub(crate) overruns: u64,
}

impl Recorder {
    pub(crate) fn new() -> Recorder {
        Recorder {
            compute: Series::new(),
            response: Series::new(),
            activations: 0,
            overruns: 0,
        }
    }

    #[inline]
    pub(crate) fn record(&mut self, compute_ns: u64, response_ns: u64) {
        self.activations += 1;
        self.compute.record(compute_ns);
        self.response.record(response_ns);
    }

    /// The node's timing; its jitter is its thread's (`wakes`).
    pub(crate) fn finish(
        &self,
        name: String,
        thread: String,
        period: Period,
        wakes: &Wakes,
    ) -> NodeTiming {
        NodeTiming {
            name,
            thread,
            period,
            activations: self.activations,
            jitter: wakes.0.spread(),
            compute: self.compute.spread(),
            response: self.response.spread(),
            overruns: self.overruns,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_come_from_what_was_recorded() {
        let (mut r, mut w) = (Recorder::new(), Wakes::new());
        for i in 1..=100u64 {
            w.record(i * 1000);
            r.record(5000, i * 1000 + 5000);
        }
        let t = r.finish("n".into(), "t".into(), Period::from_millis(1).unwrap(), &w);
        assert_eq!(t.activations, 100);
        let near = |d: Duration, us: f64| (d.as_secs_f64() * 1e6 - us).abs() <= us * 0.02;
        assert!(near(t.jitter.p50, 50.0), "{:?}", t.jitter);
        assert!(near(t.jitter.p99, 99.0), "{:?}", t.jitter);
        assert!(near(t.jitter.max, 100.0), "{:?}", t.jitter);
        assert!(near(t.compute.max, 5.0), "{:?}", t.compute);
        assert!(near(t.response.max, 105.0), "{:?}", t.response);
    }
}
