//! The pure arithmetic of the analysis: response times, the utilisation
//! bound, the executor's priorities, the bound a queue link needs, and the
//! conversions between milliseconds and nanoseconds.

/// The least fixed point of `R = C + Σ ⌈R / T_j⌉ C_j` over the interfering
/// threads `higher` (period `T_j`, WCET `C_j`), iterated from `R = C` (Joseph
/// & Pandya 1986; Audsley, Burns, Richardson, Tindell & Wellings 1993); `None`
/// when it passes `deadline` (not schedulable). All in the same unit. Without
/// release jitter: [`response_time_with_jitter`] with every jitter 0.
pub fn response_time(wcet: u64, higher: &[(u64, u64)], deadline: u64) -> Option<u64> {
    fixed_point(wcet, 0, deadline, higher.iter().map(|&(t, c)| (t, c, 0)))
}

/// The worst-case response time, from the release, of a thread of WCET `C`
/// whose activations start up to `J` after their releases (release jitter),
/// under the interfering threads `higher` (period `T_j`, WCET `C_j`, release
/// jitter `J_j`): `R = J + w` with `w` the least fixed point of
/// `w = C + Σ ⌈(w + J_j) / T_j⌉ C_j` (Audsley, Burns, Richardson, Tindell &
/// Wellings 1993, with release jitter); `None` when `R` passes `deadline`.
/// A late-starting interferer can crowd more of its jobs into the window,
/// hence `J_j` in the ceiling. All in the same unit.
pub fn response_time_with_jitter(
    wcet: u64,
    jitter: u64,
    higher: &[(u64, u64, u64)],
    deadline: u64,
) -> Option<u64> {
    fixed_point(wcet, jitter, deadline, higher.iter().copied())
}

/// `J + w`, `w = C + Σ ⌈(w + J_j) / T_j⌉ C_j` iterated from `w = C`; `None`
/// past `deadline`.
fn fixed_point(
    wcet: u64,
    jitter: u64,
    deadline: u64,
    higher: impl Iterator<Item = (u64, u64, u64)> + Clone,
) -> Option<u64> {
    let budget = deadline.checked_sub(jitter)?;
    let mut w = wcet;
    loop {
        if w > budget {
            return None;
        }
        let mut next = u128::from(wcet);
        for (t, c, j) in higher.clone() {
            let t = u128::from(t.max(1));
            next += (u128::from(w) + u128::from(j)).div_ceil(t) * u128::from(c);
        }
        let next = u64::try_from(next).unwrap_or(u64::MAX);
        if next == w {
            return Some(jitter + w);
        }
        w = next;
    }
}

/// Liu & Layland's (1973) utilisation bound `n (2^(1/n) - 1)` of `n` tasks
/// under rate-monotonic priorities: a task set at or below it is schedulable
/// on one core (a sufficient test, not a necessary one); 1 for no task.
pub fn liu_layland(n: usize) -> f64 {
    if n == 0 {
        return 1.0;
    }
    let n = n as f64;
    n * (2f64.powf(1.0 / n) - 1.0)
}

/// The executor's priorities for threads of the given periods (every
/// thread of the system: each process ranks its threads among the whole
/// system's periods): distinct periods ranked from the shortest, `top` minus
/// the rank, never below 1.
pub fn priorities(periods: &[u64], top: u8) -> Vec<u8> {
    let mut distinct = periods.to_vec();
    distinct.sort_unstable();
    distinct.dedup();
    periods
        .iter()
        .map(|p| {
            let rank = distinct.iter().position(|d| d == p).unwrap_or(0);
            top.saturating_sub(u8::try_from(rank).unwrap_or(u8::MAX))
                .max(1)
        })
        .collect()
}

/// The bound a queue link needs: the most values in it when one is written,
/// that one included, `⌈(T_r + S_r + 2 (E_w + L)) / I⌉` for a reader of
/// period `T_r` taking one value per activation whose reads start up to `S_r`
/// after its releases, a writer whose writes end up to `E_w` after their
/// releases (the spread of its ends: its response time, as an activation may
/// run shorter than its WCET) and come at least `I` apart, and a latency of
/// at most `L`; `None` when the writer may outpace the reader (`I < T_r`):
/// no bound holds. The derivation is in `docs/spec-reference.md` (Timing
/// analysis).
pub fn queue_needs(
    reader_period: u64,
    reader_lag: u64,
    writer_spread: u64,
    latency: u64,
    interval: u64,
) -> Option<u64> {
    if interval < reader_period || interval == 0 {
        return None;
    }
    let window = u128::from(reader_period)
        + u128::from(reader_lag)
        + 2 * (u128::from(writer_spread) + u128::from(latency));
    u64::try_from(window.div_ceil(u128::from(interval))).ok()
}

/// Milliseconds to nanoseconds, rounded up (WCETs, latencies).
pub(super) fn ns_up(ms: f64) -> u64 {
    // Finite and positive: the checker refuses other values before the analysis runs.
    (ms * 1e6).ceil().clamp(0.0, u64::MAX as f64) as u64
}

/// Milliseconds to nanoseconds, rounded to the nearest (periods).
pub(super) fn ns(ms: f64) -> u64 {
    (ms * 1e6).round().clamp(0.0, u64::MAX as f64) as u64
}

/// Nanoseconds as milliseconds for people: `12.5`, `0.8`.
pub fn ms(ns: u64) -> String {
    let s = format!("{:.6}", ns as f64 / 1e6);
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_owned()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn liu_layland_bound() {
        assert!((liu_layland(1) - 1.0).abs() < 1e-12);
        assert!((liu_layland(2) - 0.828_427).abs() < 1e-6);
        assert!((liu_layland(3) - 0.779_763).abs() < 1e-6);
        assert!(liu_layland(1000) > std::f64::consts::LN_2);
    }

    #[test]
    fn priorities_are_rate_monotonic_with_ties_and_a_floor() {
        assert_eq!(priorities(&[10, 50, 10, 1], 80), vec![79, 78, 79, 80]);
        assert_eq!(priorities(&[1, 2, 3], 2), vec![2, 1, 1]);
    }
}
