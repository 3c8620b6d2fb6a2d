//! A sample link thinned to its readers' instants gives each read what a link
//! in one process gives it, and publishes about two values a read (its own
//! and its fallback's).

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

use proptest::prelude::*;

use super::*;
use crate::buffer::In;
use crate::kinds::Policy;
use crate::link::Channel;
use crate::link::remote::{Inbox, Publisher, RemoteTx, TransportError, fingerprint};
use crate::link::stats::SharedStats;
use crate::time::Stamp;

fn ms(n: u64) -> Period {
    Period::from_millis(n).unwrap()
}

fn at(n: u64) -> Time {
    Time::from_nanos(n * 1_000_000)
}

#[test]
fn a_reader_as_fast_as_the_writer_sees_every_value() {
    assert_eq!(ReadGrid::new(ms(10), [ms(10)]), None);
    assert_eq!(ReadGrid::new(ms(10), [ms(50), ms(5)]), None);
    assert_eq!(ReadGrid::new(ms(10), []), None);
}

#[test]
fn reads_are_the_first_instants_strictly_after_a_write() {
    let grid = ReadGrid::new(ms(1), [ms(50), ms(100), ms(30)]).unwrap();
    // 100 ms is a multiple of 50 ms: its reads are among 50 ms's; each
    // reader's fallback is a tenth of its period before its reads.
    assert_eq!(
        grid.instants,
        vec![
            (30_000_000, 0),
            (50_000_000, 0),
            (30_000_000, 3_000_000),
            (50_000_000, 5_000_000),
            (100_000_000, 10_000_000),
        ]
    );
    assert_eq!(grid.next_read(at(0)), 27_000_000);
    assert_eq!(grid.next_read(at(27)), 30_000_000);
    assert_eq!(grid.next_read(at(30)), 45_000_000);
    assert_eq!(grid.next_read(at(45)), 50_000_000);
    assert_eq!(grid.next_read(at(50)), 57_000_000);
    assert_eq!(grid.next_read(at(88)), 90_000_000);
    assert!(!grid.last_before(at(48), 50_000_000));
    assert!(grid.last_before(at(49), 50_000_000));
    assert!(grid.last_before(at(55), 50_000_000));
    // A fallback no earlier than the writer's last activation: none.
    let slow = ReadGrid::new(ms(10), [ms(50)]).unwrap();
    assert_eq!(slow.instants, vec![(50_000_000, 0)]);
}

/// A publisher that hands each message to every reader's inbox at once, and
/// counts them.
struct Wire(Vec<Arc<Inbox>>, Arc<AtomicU64>);
impl Publisher for Wire {
    fn put(&mut self, message: &[u8]) -> Result<(), TransportError> {
        self.1.fetch_add(1, Ordering::Relaxed);
        for inbox in &self.0 {
            inbox.deliver(message);
        }
        Ok(())
    }
}

/// A writer of period `writer` ms to readers of periods `readers` ms, over a
/// thinned link between processes and over links in one process.
struct Bench {
    writer: u64,
    readers: Vec<u64>,
    tx: RemoteTx,
    inboxes: Vec<Arc<Inbox>>,
    channels: Vec<Channel<u64>>,
    published: Arc<AtomicU64>,
    stats: Arc<SharedStats>,
}

impl Bench {
    fn new(writer: u64, readers: &[u64]) -> Bench {
        let inboxes: Vec<Arc<Inbox>> = readers
            .iter()
            .map(|_| {
                Arc::new(Inbox::new(
                    "k".into(),
                    fingerprint::<u64>(),
                    "u64",
                    Policy::Sample,
                    Arc::default(),
                ))
            })
            .collect();
        let published = Arc::new(AtomicU64::new(0));
        let stats = Arc::new(SharedStats::default());
        let grid = ReadGrid::new(ms(writer), readers.iter().map(|&r| ms(r)));
        let tx = RemoteTx::new(
            Some(Box::new(Wire(inboxes.clone(), published.clone()))),
            "k".into(),
            fingerprint::<u64>(),
            7,
            stats.clone(),
        )
        .at_reads(grid);
        Bench {
            writer,
            readers: readers.to_vec(),
            tx,
            inboxes,
            channels: readers
                .iter()
                .map(|_| Channel::new(Policy::Sample))
                .collect(),
            published,
            stats,
        }
    }

    /// Run to `end` ms as the deterministic executor orders an instant (the
    /// reads, then the writer's send); the writer writes at its `k`-th
    /// activation if `writes(k)`, and is not activated at all where `skipped`.
    /// Each reader's (instant, fresh value, stamp) over both links.
    #[allow(clippy::type_complexity, reason = "a test's pair of traces")]
    fn run(
        &mut self,
        end: u64,
        writes: impl Fn(u64) -> bool,
        skipped: impl Fn(u64) -> bool,
    ) -> (Vec<Vec<(u64, Option<u64>)>>, Vec<Vec<(u64, Option<u64>)>>) {
        let n = self.readers.len();
        let (mut away, mut here) = (vec![Vec::new(); n], vec![Vec::new(); n]);
        let mut xs: Vec<(In<u64>, In<u64>)> = (0..n).map(|_| Default::default()).collect();
        for t in 0..=end {
            for (i, &r) in self.readers.iter().enumerate() {
                if t % r != 0 {
                    continue;
                }
                let (x_away, x_here) = &mut xs[i];
                self.inboxes[i].take_into(x_away, at(t)).unwrap();
                self.channels[i].take_into(x_here);
                away[i].push((t, x_away.fresh().copied()));
                here[i].push((t, x_here.fresh().copied()));
            }
            if t % self.writer != 0 || skipped(t) {
                continue;
            }
            let stamp = Stamp::new(t / self.writer, at(t));
            if writes(t / self.writer) {
                for c in &mut self.channels {
                    c.put(&mut Some(t), false, stamp).unwrap();
                }
                self.tx.put(&t, stamp).unwrap();
            } else {
                self.tx.idle(at(t)).unwrap();
            }
        }
        (away, here)
    }

    fn published(&self) -> u64 {
        self.published.load(Ordering::Relaxed)
    }
}

#[test]
fn a_1_ms_writer_read_every_50_ms_publishes_40_values_a_second() {
    let mut bench = Bench::new(1, &[50]);
    let (away, here) = bench.run(1_000, |_| true, |_| false);
    assert_eq!(away, here);
    // The values written at 44 and 49, 94 and 99, ..., 994 and 999 ms: a
    // read's fallback and its own.
    assert_eq!(bench.published(), 40);
    assert_eq!(away[0][1], (50, Some(49)));
    assert_eq!(bench.inboxes[0].stats().overwritten, 20, "the fallbacks");
    let stats = bench.stats.snapshot();
    assert_eq!((stats.sent, stats.overwritten), (1_001, 960));
}

#[test]
fn a_read_whose_own_value_is_late_takes_the_fallback() {
    let mut bench = Bench::new(1, &[50]);
    let (away, _) = bench.run(48, |_| true, |_| false);
    assert_eq!(bench.published(), 1, "the fallback, written at 44 ms");
    // The read at 50 ms comes before the value written at 49 ms arrives.
    let mut x = In::<u64>::default();
    bench.inboxes[0].take_into(&mut x, at(50)).unwrap();
    assert_eq!(x.fresh(), Some(&44));
    assert_eq!(away[0], vec![(0, None)]);
}

#[test]
fn a_value_written_before_activations_without_a_write_is_published_at_the_last_before_the_read() {
    // Written at 0, 10, 20, ... ms only: the value of 40 ms is held through
    // the activations of 41..49 ms and published at 49 ms.
    let mut bench = Bench::new(1, &[50]);
    let (away, here) = bench.run(200, |k| k % 10 == 0, |_| false);
    assert_eq!(away, here);
    assert_eq!(away[0][1], (50, Some(40)));
    assert_eq!(bench.published(), 4);
}

#[test]
fn a_held_value_whose_read_was_missed_goes_late_rather_than_never() {
    // The writer is not activated from 44 to 60 ms (an overrun skipped its
    // instants): the value of 43 ms missed the fallback at 45 and the read at
    // 50 and goes at 61 ms, before the value written then is held.
    let mut bench = Bench::new(1, &[50]);
    let (away, _) = bench.run(100, |_| true, |t| (44..=60).contains(&t));
    assert_eq!(away[0][1], (50, None));
    assert_eq!(
        bench.inboxes[0].stats().overwritten,
        2,
        "43, then 94, 99 ms"
    );
    assert_eq!(away[0][2], (100, Some(99)));
    assert_eq!(bench.published(), 3, "43 ms late, 94 and 99 ms in time");
}

#[test]
fn a_halting_writer_publishes_what_it_holds() {
    let mut bench = Bench::new(1, &[50]);
    bench.run(10, |_| true, |_| false);
    assert_eq!(bench.published(), 0);
    bench.tx.flush().unwrap();
    assert_eq!(bench.published(), 1);
    let mut x = In::<u64>::default();
    bench.inboxes[0].take_into(&mut x, at(50)).unwrap();
    assert_eq!(x.fresh(), Some(&10));
    bench.tx.flush().unwrap();
    assert_eq!(bench.published(), 1, "nothing held: nothing sent");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    /// Any writer period, readers of any periods, any pattern of writes: every
    /// read over the thinned link takes what the links in one process give,
    /// and no more values cross than twice the reads (a value and its fallback).
    #[test]
    fn every_read_takes_what_a_link_in_one_process_gives(
        writer in 1u64..12,
        readers in proptest::collection::vec(1u64..60, 1..4),
        pattern in proptest::collection::vec(any::<bool>(), 1..9),
    ) {
        let mut bench = Bench::new(writer, &readers);
        let writes = |k: u64| pattern[(k % pattern.len() as u64) as usize];
        let (away, here) = bench.run(600, writes, |_| false);
        prop_assert_eq!(away, here);
        let reads: u64 = (1..=600u64)
            .filter(|t| readers.iter().any(|r| t % r == 0))
            .count() as u64;
        let written = (0..=600 / writer).filter(|&k| writes(k)).count() as u64;
        // A read's value and each reader's fallbacks, each written before it.
        let mut periods = readers.clone();
        periods.sort_unstable();
        periods.dedup();
        let fallbacks: u64 = periods.iter().map(|r| 600 / r + 1).sum();
        prop_assert!(bench.published() <= (reads + fallbacks).min(written) + 2);
    }
}
