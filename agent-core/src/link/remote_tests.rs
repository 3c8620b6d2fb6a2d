//! The inbox and the sender of links between processes.

use super::*;

fn inbox<T: Payload>(policy: Policy) -> (Arc<Inbox>, Arc<SharedStats>) {
    let stats = Arc::new(SharedStats::default());
    let inbox = Arc::new(Inbox::new(
        "k".into(),
        fingerprint::<T>(),
        std::any::type_name::<T>(),
        policy,
        stats.clone(),
    ));
    (inbox, stats)
}

/// A publisher that hands its messages to an inbox directly.
struct Loop(Arc<Inbox>);
impl Publisher for Loop {
    fn put(&mut self, message: &[u8]) -> Result<(), TransportError> {
        self.0.deliver(message);
        Ok(())
    }
}

fn sender<T: Payload>(to: &Arc<Inbox>, epoch: u64) -> RemoteTx {
    RemoteTx::new(
        Some(Box::new(Loop(to.clone()))),
        "k".into(),
        fingerprint::<T>(),
        epoch,
        Arc::new(SharedStats::default()),
    )
}

fn stamp(i: u64) -> Stamp {
    Stamp::new(i, Time::from_nanos(i * 10))
}

#[test]
fn a_queue_carries_values_in_order_with_their_stamps() {
    let (inbox, stats) = inbox::<Vec<u16>>(Policy::queue(4));
    let mut tx = sender::<Vec<u16>>(&inbox, 7);
    for i in 1..=3u16 {
        tx.put(&vec![i; i as usize], stamp(u64::from(i))).unwrap();
    }
    let mut x = In::default();
    for i in 1..=3u16 {
        inbox.take_into(&mut x, Time::NEVER).unwrap();
        assert_eq!(x.fresh(), Some(&vec![i; i as usize]));
        assert_eq!(x.stamp(), Some(stamp(u64::from(i))));
    }
    inbox.take_into(&mut x, Time::NEVER).unwrap();
    assert!(!x.is_new());
    assert_eq!(stats.snapshot().delivered, 3);
}

#[test]
fn a_sample_keeps_the_latest() {
    let (inbox, stats) = inbox::<f64>(Policy::Sample);
    let mut tx = sender::<f64>(&inbox, 7);
    for i in 1..=5 {
        tx.put(&(i as f64), stamp(i)).unwrap();
    }
    let mut x = In::default();
    inbox.take_into(&mut x, Time::NEVER).unwrap();
    assert_eq!(x.fresh(), Some(&5.0));
    assert_eq!(stats.snapshot().overwritten, 4);
}

/// A publisher that hands its messages to an inbox and keeps a copy of each,
/// as an eavesdropper on the network would.
struct Tap(Arc<Inbox>, Arc<Mutex<Vec<Vec<u8>>>>);
impl Publisher for Tap {
    fn put(&mut self, message: &[u8]) -> Result<(), TransportError> {
        self.1
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
            .push(message.to_vec());
        self.0.deliver(message);
        Ok(())
    }
}

#[test]
fn a_sample_replayed_is_refused_not_put_back_as_the_latest() {
    let (inbox, stats) = inbox::<f64>(Policy::Sample);
    let seen = Arc::new(Mutex::new(Vec::new()));
    let mut tx = RemoteTx::new(
        Some(Box::new(Tap(inbox.clone(), seen.clone()))),
        "k".into(),
        fingerprint::<f64>(),
        7,
        Arc::new(SharedStats::default()),
    );
    tx.put(&1.0, stamp(1)).unwrap();
    tx.put(&2.0, stamp(2)).unwrap();
    let mut x = In::default();
    inbox.take_into(&mut x, Time::NEVER).unwrap();
    assert_eq!(x.fresh(), Some(&2.0));
    // The first message again, sent by whoever saw it go by.
    let first = seen.lock().unwrap()[0].clone();
    inbox.deliver(&first);
    assert_eq!(
        inbox.take_into(&mut x, Time::NEVER),
        Err(RemoteProblem::Duplicate {
            expected: 3,
            got: 1
        })
    );
    inbox.take_into(&mut x, Time::NEVER).unwrap();
    assert!(!x.is_new(), "the old value is not taken again");
    assert_eq!(x.get(), Some(&2.0));
    assert_eq!(stats.snapshot().refused, 1);
}

#[test]
fn a_value_stamped_after_the_reading_instant_waits_for_it() {
    // stamp(i) is at 10·i ns.
    let (inbox, stats) = inbox::<u32>(Policy::queue(4));
    let mut tx = sender::<u32>(&inbox, 7);
    for i in 1..=2u32 {
        tx.put(&i, stamp(u64::from(i))).unwrap();
    }
    let mut x = In::<u32>::default();
    let mut got = Vec::new();
    for now in [0, 9, 10, 15, 25] {
        inbox.take_into(&mut x, Time::from_nanos(now)).unwrap();
        got.push(x.fresh().copied());
    }
    assert_eq!(got, [None, None, Some(1), None, Some(2)]);
    assert_eq!(stats.snapshot().delivered, 2);
}

#[test]
fn a_gap_a_foreign_type_and_an_overflow_are_reported() {
    let (inbox, _) = inbox::<u32>(Policy::queue(2));
    let mut tx = sender::<u32>(&inbox, 7);
    tx.put(&1, stamp(1)).unwrap();
    tx.header.seq += 1; // a message lost on the way
    tx.put(&3, stamp(3)).unwrap();
    tx.put(&4, stamp(4)).unwrap(); // the queue holds two
    let mut x = In::default();
    assert_eq!(
        inbox.take_into(&mut x, Time::NEVER),
        Err(RemoteProblem::Gap {
            expected: 2,
            got: 3
        })
    );
    assert_eq!(
        inbox.take_into(&mut x, Time::NEVER),
        Err(RemoteProblem::Overflow { bound: 2 })
    );
    inbox.take_into(&mut x, Time::NEVER).unwrap();
    assert_eq!(x.fresh(), Some(&1));

    let mut foreign = sender::<(u32, u32)>(&inbox, 8);
    foreign.put(&(1, 2), stamp(5)).unwrap();
    assert_eq!(inbox.problem_count(), 3, "gap, overflow, foreign type");
    // Problems come first, then the value 3 still waiting.
    assert!(matches!(
        inbox.take_into(&mut x, Time::NEVER),
        Err(RemoteProblem::Fingerprint { .. })
    ));
    inbox.take_into(&mut x, Time::NEVER).unwrap();
    assert_eq!(x.fresh(), Some(&3));
}

#[test]
fn values_sent_before_a_queue_listened_are_a_gap_and_a_repeat_is_refused() {
    let (inbox, _) = inbox::<u32>(Policy::queue(8));
    let mut tx = sender::<u32>(&inbox, 7);
    tx.header.seq = 4; // four values went out before the inbox listened
    tx.put(&5, stamp(5)).unwrap();
    let mut x = In::default();
    assert_eq!(
        inbox.take_into(&mut x, Time::NEVER),
        Err(RemoteProblem::Gap {
            expected: 1,
            got: 5
        })
    );
    inbox.take_into(&mut x, Time::NEVER).unwrap();
    assert_eq!(x.fresh(), Some(&5));
    tx.header.seq = 4; // the same message again
    tx.put(&5, stamp(5)).unwrap();
    assert_eq!(
        inbox.take_into(&mut x, Time::NEVER),
        Err(RemoteProblem::Duplicate {
            expected: 6,
            got: 5
        })
    );
    inbox.take_into(&mut x, Time::NEVER).unwrap();
    assert!(!x.is_new(), "the repeat was not delivered");
}

#[test]
fn a_late_joiner_starts_counting_at_its_first_value_and_an_early_one_does_not() {
    // Whether the run joins late is known only after it subscribed: the
    // first value may come before or after `start`.
    for (late, before_start) in [(true, true), (true, false), (false, true), (false, false)] {
        let (inbox, _) = inbox::<u32>(Policy::queue(8));
        inbox.defer_start();
        let mut tx = sender::<u32>(&inbox, 7);
        tx.header.seq = 4; // four values went to this sender's earlier receivers
        if before_start {
            tx.put(&5, stamp(5)).unwrap();
            inbox.start(late);
        } else {
            inbox.start(late);
            tx.put(&5, stamp(5)).unwrap();
        }
        let mut x = In::default();
        let first = inbox.take_into(&mut x, Time::NEVER);
        if late {
            assert_eq!(first, Ok(()), "late={late} before_start={before_start}");
            assert_eq!(x.fresh(), Some(&5));
        } else {
            assert_eq!(
                first,
                Err(RemoteProblem::Gap {
                    expected: 1,
                    got: 5
                }),
                "late={late} before_start={before_start}"
            );
        }
        // Later gaps are gaps for everyone.
        tx.header.seq += 1;
        tx.put(&7, stamp(7)).unwrap();
        let mut problems = 0;
        for _ in 0..4 {
            if let Err(p) = inbox.take_into(&mut x, Time::NEVER) {
                assert_eq!(
                    p,
                    RemoteProblem::Gap {
                        expected: 6,
                        got: 7
                    }
                );
                problems += 1;
            }
        }
        assert_eq!(problems, 1);
    }
}

#[test]
fn a_flood_of_bad_messages_is_counted_in_bounded_memory() {
    let (inbox, _) = inbox::<u32>(Policy::Sample);
    for _ in 0..1000 {
        inbox.deliver(&[7]);
    }
    assert_eq!(inbox.problem_count(), 1000);
    let mut x = In::<u32>::default();
    let reported = (0..1000)
        .take_while(|_| inbox.take_into(&mut x, Time::NEVER).is_err())
        .count();
    assert_eq!(
        reported, MAX_PROBLEMS,
        "the first ones wait; all are counted"
    );
}

#[test]
fn a_restarted_sender_is_not_a_gap() {
    let (inbox, _) = inbox::<u32>(Policy::queue(8));
    let mut first = sender::<u32>(&inbox, 7);
    first.put(&1u32, stamp(1)).unwrap();
    first.put(&2u32, stamp(2)).unwrap();
    // Its process was seen to go; the new one numbers from 1 again.
    inbox.peer_lost("sender");
    let mut again = sender::<u32>(&inbox, 9);
    again.put(&3u32, stamp(1)).unwrap();
    let mut x = In::<u32>::default();
    // The loss is reported first (problems wait before values), then every
    // value, in order.
    assert!(matches!(
        inbox.take_into(&mut x, Time::NEVER),
        Err(RemoteProblem::PeerLost { .. })
    ));
    for v in 1..=3u32 {
        inbox.take_into(&mut x, Time::NEVER).unwrap();
        assert_eq!(x.fresh(), Some(&v));
    }
    assert_eq!(inbox.restarts(), 1);
}

#[test]
fn a_second_sender_while_the_first_runs_is_refused_and_counted() {
    let (inbox, stats) = inbox::<u32>(Policy::queue(8));
    let mut owner = sender::<u32>(&inbox, 7);
    let mut intruder = sender::<u32>(&inbox, 66);
    owner.put(&1u32, stamp(1)).unwrap();
    for v in 0..5u32 {
        intruder.put(&(100 + v), stamp(2)).unwrap();
    }
    owner.put(&2u32, stamp(3)).unwrap();
    let mut x = In::<u32>::default();
    let mut values: Vec<u32> = Vec::new();
    let mut intruders = 0;
    for _ in 0..10 {
        match inbox.take_into(&mut x, Time::NEVER) {
            Ok(()) => values.extend(x.fresh().copied()),
            Err(RemoteProblem::Intruder {
                current: 7,
                got: 66,
            }) => intruders += 1,
            Err(e) => panic!("{e}"),
        }
    }
    assert_eq!(values, [1, 2], "the owner's values, in order, none lost");
    assert_eq!(intruders, 5);
    assert_eq!(stats.snapshot().refused, 5);
    assert_eq!(inbox.restarts(), 0);
}

#[test]
fn an_announced_epoch_is_the_only_sender_whatever_comes_first() {
    let (inbox, stats) = inbox::<u32>(Policy::queue(8));
    inbox.expect(7);
    // Another sender first: refused, though the link heard nobody yet.
    sender::<u32>(&inbox, 66).put(&9u32, stamp(1)).unwrap();
    let mut owner = sender::<u32>(&inbox, 7);
    owner.put(&1u32, stamp(1)).unwrap();
    // The owner restarts and announces its new epoch before its values come;
    // its old epoch's values are no longer its own.
    inbox.expect(8);
    let mut again = sender::<u32>(&inbox, 8);
    again.put(&2u32, stamp(2)).unwrap();
    owner.put(&3u32, stamp(3)).unwrap();
    let mut x = In::<u32>::default();
    let mut values: Vec<u32> = Vec::new();
    let mut refused = 0;
    for _ in 0..6 {
        match inbox.take_into(&mut x, Time::NEVER) {
            Ok(()) => values.extend(x.fresh().copied()),
            Err(RemoteProblem::Intruder { .. }) => refused += 1,
            Err(e) => panic!("{e}"),
        }
    }
    assert_eq!(values, [1, 2]);
    assert_eq!(refused, 2);
    assert_eq!(stats.snapshot().refused, 2);
    assert_eq!(inbox.restarts(), 1);
}

#[test]
fn a_value_stamped_far_ahead_is_refused_and_holds_nothing_behind_it() {
    let (inbox, stats) = inbox::<u32>(Policy::queue(8));
    let mut tx = sender::<u32>(&inbox, 7);
    tx.put(&77u32, Stamp::new(1, Time::from_nanos(1 << 63)))
        .unwrap();
    tx.put(&1u32, stamp(1)).unwrap();
    let now = Time::from_nanos(1_000_000_000);
    let mut x = In::<u32>::default();
    assert!(matches!(
        inbox.take_into(&mut x, now),
        Err(RemoteProblem::Implausible { lead: 5, .. })
    ));
    inbox.take_into(&mut x, now).unwrap();
    assert_eq!(x.fresh(), Some(&1), "the value behind it comes through");
    assert_eq!(stats.snapshot().refused, 1);
    // Ahead, but within the lead: it waits for its instant, as any value.
    tx.put(&2u32, Stamp::new(2, Time::from_nanos(3_000_000_000)))
        .unwrap();
    inbox.take_into(&mut x, now).unwrap();
    assert!(!x.is_new());
    inbox
        .take_into(&mut x, Time::from_nanos(3_000_000_000))
        .unwrap();
    assert_eq!(x.fresh(), Some(&2));
}

#[test]
fn a_body_longer_than_its_value_is_refused() {
    let (inbox, stats) = inbox::<[f64; 4]>(Policy::Sample);
    let mut m = Vec::new();
    write_header(
        &mut m,
        &Header {
            fingerprint: fingerprint::<[f64; 4]>(),
            epoch: 1,
            seq: 1,
            stamp: stamp(1),
        },
    );
    // Torques from the first 32 bytes of a 10 MB body: not a value of this link.
    m.resize(HEADER_LEN + (10 << 20), 0x3f);
    inbox.deliver(&m);
    let mut x = In::<[f64; 4]>::default();
    let e = inbox.take_into(&mut x, Time::NEVER).expect_err("refused");
    assert!(e.to_string().contains("bytes after the value"), "{e}");
    assert!(!x.is_new());
    assert_eq!(stats.snapshot().refused, 1);
}

#[test]
fn every_refused_message_is_counted_though_few_wait_to_be_reported() {
    let (inbox, stats) = inbox::<u32>(Policy::Sample);
    for _ in 0..380 {
        inbox.deliver(&[1, 2, 3]);
    }
    assert_eq!(stats.snapshot().refused, 380);
    assert_eq!(inbox.problem_count(), 380);
}

#[test]
fn truncated_and_alien_messages_are_errors_not_panics() {
    let (inbox, _) = inbox::<u32>(Policy::Sample);
    let mut x = In::<u32>::default();
    for m in [&[][..], &[1, 2, 3][..], &[9; 50][..]] {
        inbox.deliver(m);
        assert!(matches!(
            inbox.take_into(&mut x, Time::NEVER),
            Err(RemoteProblem::Decode(_))
        ));
    }
    // A header with the right fingerprint and a body that does not decode.
    let mut m = Vec::new();
    write_header(
        &mut m,
        &Header {
            fingerprint: fingerprint::<u32>(),
            epoch: 1,
            seq: 1,
            stamp: stamp(1),
        },
    );
    m.push(0xff);
    inbox.deliver(&m);
    assert!(matches!(
        inbox.take_into(&mut x, Time::NEVER),
        Err(RemoteProblem::Decode(_))
    ));
}

#[test]
fn fingerprints_tell_shapes_apart() {
    #[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
    struct A {
        x: f64,
    }
    #[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
    struct B {
        x: f64,
        y: f64,
    }
    assert_eq!(fingerprint::<A>(), fingerprint::<A>());
    assert_ne!(fingerprint::<A>(), fingerprint::<B>());
    assert_ne!(fingerprint::<u32>(), fingerprint::<u64>());
    assert_ne!(fingerprint::<Vec<f64>>(), fingerprint::<[f64; 3]>());
}
