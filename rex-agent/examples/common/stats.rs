//! The statistics the benches print for ours and the peers alike.

/// The `q`-quantile of `v` (sorted in place): the nearest rank.
pub(crate) fn percentile(v: &mut [f64], q: f64) -> f64 {
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        return f64::NAN;
    }
    let i = (q * (v.len() - 1) as f64).round() as usize;
    v[i.min(v.len() - 1)]
}

/// Times (ms): median, mean, p95, p99, max.
#[derive(Clone, Copy, Debug, Default)]
pub(crate) struct Stats {
    pub(crate) median: f64,
    pub(crate) mean: f64,
    pub(crate) p95: f64,
    pub(crate) p99: f64,
    pub(crate) max: f64,
}

impl Stats {
    pub(crate) fn of(v: &[f64]) -> Stats {
        let mut v = v.to_vec();
        Stats {
            median: percentile(&mut v, 0.5),
            mean: v.iter().sum::<f64>() / v.len().max(1) as f64,
            p95: percentile(&mut v, 0.95),
            p99: percentile(&mut v, 0.99),
            max: v.iter().copied().fold(f64::NAN, f64::max),
        }
    }
}

impl Stats {
    /// Ours over the peer's: `median .., mean .., p99 .., max ..`.
    pub(crate) fn ratios(&self, peer: &Stats) -> String {
        format!(
            "median {:.3}, mean {:.3}, p99 {:.3}, max {:.3}",
            self.median / peer.median,
            self.mean / peer.mean,
            self.p99 / peer.p99,
            self.max / peer.max
        )
    }
}

impl std::fmt::Display for Stats {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "median {:.4} ms, mean {:.4}, p95 {:.4}, p99 {:.4}, max {:.4}",
            self.median, self.mean, self.p95, self.p99, self.max
        )
    }
}
