//! Tests of the in-process channels (the link layer's own storage).

use super::*;

fn stamp(i: u64) -> Stamp {
    Stamp::new(i, Time::from_nanos(i))
}

#[test]
fn sample_keeps_latest_and_counts_overwrites() {
    let mut c = Channel::<u32>::new(Policy::Sample);
    let mut x = In::default();
    c.take_into(&mut x);
    assert!(!x.is_new() && !x.has_data());
    c.put(&mut Some(1), true, stamp(1)).unwrap();
    c.put(&mut Some(2), true, stamp(2)).unwrap();
    c.take_into(&mut x);
    assert_eq!((x.fresh(), x.stamp()), (Some(&2), Some(stamp(2))));
    c.take_into(&mut x);
    assert!(!x.is_new());
    assert_eq!(x.get(), Some(&2));
    assert_eq!(c.stats.overwritten, 1);
    assert_eq!((c.stats.sent, c.stats.delivered), (2, 1));
}

#[test]
fn queue_is_lossless_ordered_and_bounded() {
    let mut c = Channel::<u32>::new(Policy::queue(2));
    c.put(&mut Some(1), true, stamp(1)).unwrap();
    c.put(&mut Some(2), false, stamp(2)).unwrap();
    assert_eq!(c.put(&mut Some(3), true, stamp(3)), Err(2));
    assert_eq!(c.stats.overflowed, 1);
    let mut x = In::default();
    for expect in [Some(1), Some(2)] {
        c.take_into(&mut x);
        assert_eq!(x.fresh().copied(), expect);
    }
    c.take_into(&mut x);
    assert!(!x.is_new(), "an empty queue brings nothing new");
    assert_eq!(c.stats.max_pending, 2);
}

#[test]
fn moving_sends_recycle_storage() {
    let mut c = Channel::<Vec<u8>>::new(Policy::Sample);
    let mut x = In::default();
    let mut v = Some(Vec::with_capacity(64));
    c.put(&mut v, true, stamp(1)).unwrap();
    c.take_into(&mut x);
    // The receiver's previous storage (none yet) went back into the channel; on
    // the next round the storage cycles around instead of being reallocated.
    let mut w = Some(vec![9u8]);
    c.put(&mut w, true, stamp(2)).unwrap();
    c.take_into(&mut x);
    assert_eq!(x.get().map(Vec::as_slice), Some(&[9u8][..]));
    let mut u = Some(vec![7u8]);
    c.put(&mut u, true, stamp(3)).unwrap();
    assert_eq!(
        u.map(|v| v.capacity()),
        Some(64),
        "the sender got back the first buffer's storage"
    );
}
