//! Reports of two probes paired by instant. A watcher often needs what one
//! component did at `t` beside what another saw at the same `t` (a
//! controller's activation beside the simulated world's true state, to
//! measure its error without a period's lag). In the deterministic executor
//! the reports of an instant come together; in real time, and from the
//! processes of a deployment, each probe's come when its thread or process
//! sends them, in any order. [`Pairs`] holds each side until the other has
//! passed its instant.

use std::collections::BTreeMap;

use agent_core::Time;

/// Reports of a sampled side (`A`, at its instants) waiting for those of a
/// reference side (`B`, at its own, denser, instants), paired by instant.
///
/// ```
/// use agent_app::Pairs;
/// use agent_core::Time;
///
/// let ms = |k: u64| Time::from_nanos(k * 1_000_000);
/// let mut pairs = Pairs::default();
/// pairs.sample(ms(20), "e11 at 20 ms");
/// pairs.reference(ms(10), 1.0);
/// assert!(pairs.take(false).is_empty(), "the reference has not reached 20 ms");
/// pairs.reference(ms(20), 2.0);
/// assert_eq!(pairs.take(false), [(ms(20), "e11 at 20 ms", Some(2.0))]);
/// ```
#[derive(Clone, Debug)]
pub struct Pairs<A, B> {
    samples: Vec<(Time, A)>,
    references: BTreeMap<Time, B>,
    /// The latest instant of a sample: references from it on may still be
    /// needed.
    latest: Time,
}

impl<A, B> Default for Pairs<A, B> {
    fn default() -> Self {
        Pairs {
            samples: Vec::new(),
            references: BTreeMap::new(),
            latest: Time::ZERO,
        }
    }
}

impl<A, B: Clone> Pairs<A, B> {
    /// A report of the sampled side at `t`.
    pub fn sample(&mut self, t: Time, a: A) {
        self.latest = self.latest.max(t);
        self.samples.push((t, a));
    }

    /// A report of the reference side at `t`.
    pub fn reference(&mut self, t: Time, b: B) {
        self.references.insert(t, b);
    }

    /// The samples whose instant the reference side has reached (all of
    /// them once the run is `finished`), in time order, each with the
    /// reference of its instant if there is one. References no longer needed
    /// (older than every sample waiting and than the latest sample) are
    /// dropped: a sample's reference often arrives before it.
    pub fn take(&mut self, finished: bool) -> Vec<(Time, A, Option<B>)> {
        let reached = self
            .references
            .keys()
            .next_back()
            .copied()
            .unwrap_or(Time::ZERO);
        self.samples.sort_by_key(|s| s.0);
        let split = self
            .samples
            .iter()
            .position(|s| !(s.0 <= reached || finished))
            .unwrap_or(self.samples.len());
        let ready: Vec<_> = self
            .samples
            .drain(..split)
            .map(|(t, a)| {
                let b = self.references.get(&t).cloned();
                (t, a, b)
            })
            .collect();
        let keep_from = self.samples.first().map_or(self.latest, |s| s.0);
        self.references = self.references.split_off(&keep_from);
        ready
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn samples_wait_for_their_reference_in_any_order() {
        let ms = |k: u64| Time::from_nanos(k * 1_000_000);
        let mut pairs = Pairs::default();
        pairs.sample(ms(10), 'a');
        pairs.reference(ms(20), 2);
        pairs.reference(ms(10), 1);
        assert_eq!(pairs.take(false), [(ms(10), 'a', Some(1))]);
        pairs.sample(ms(30), 'c');
        assert!(pairs.take(false).is_empty(), "the reference is at 20 ms");
        pairs.reference(ms(30), 3);
        assert_eq!(pairs.take(false), [(ms(30), 'c', Some(3))]);
        // At the end every sample is taken, paired or not.
        pairs.sample(ms(40), 'd');
        assert_eq!(pairs.take(true), [(ms(40), 'd', None)]);
        assert!(pairs.take(true).is_empty());
    }

    #[test]
    fn references_older_than_every_sample_are_dropped() {
        let ms = |k: u64| Time::from_nanos(k * 1_000_000);
        let mut pairs: Pairs<(), u64> = Pairs::default();
        for k in 0..100 {
            pairs.reference(ms(k), k);
        }
        pairs.sample(ms(50), ());
        assert_eq!(pairs.take(false), [(ms(50), (), Some(50))]);
        assert_eq!(pairs.references.len(), 50, "those from 50 ms on are kept");
    }
}
