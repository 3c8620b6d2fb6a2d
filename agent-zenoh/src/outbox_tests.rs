#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::sync::mpsc;

use super::*;

/// A sink that waits for the gate before its first message (as Zenoh's `put`
/// may wait), then records what it is given.
struct Gated {
    gate: Option<mpsc::Receiver<()>>,
    got: Got,
    /// Whether the gate was never opened in time (a put that waited for the sink).
    timed_out: Arc<AtomicBool>,
}

impl Sink for Gated {
    fn send(&mut self, message: Vec<u8>) -> Result<(), String> {
        if let Some(gate) = self.gate.take()
            && gate.recv_timeout(Duration::from_secs(20)).is_err()
        {
            self.timed_out.store(true, Ordering::Relaxed);
        }
        self.got.lock().unwrap().push(message);
        Ok(())
    }
}

type Got = Arc<Mutex<Vec<Vec<u8>>>>;

fn gated() -> (Box<dyn Sink>, mpsc::Sender<()>, Got, Arc<AtomicBool>) {
    let (open, gate) = mpsc::channel();
    let got = Got::default();
    let timed_out = Arc::new(AtomicBool::new(false));
    let sink = Gated {
        gate: Some(gate),
        got: got.clone(),
        timed_out: timed_out.clone(),
    };
    (Box::new(sink), open, got, timed_out)
}

fn message(i: usize) -> Vec<u8> {
    (i as u32).to_le_bytes().to_vec()
}

const FLUSH: Duration = Duration::from_secs(20);

#[test]
fn a_put_never_waits_for_the_sink_and_every_message_arrives_in_order() {
    let outbox = Outbox::new("test-out");
    let (sink, open, got, timed_out) = gated();
    let mut publisher = outbox.publisher(sink, WhenFull::Refuse).unwrap();
    // The sink is stalled in its first message until the gate opens, which
    // happens only after every put returned.
    let capacity = CAPACITY;
    for i in 0..capacity {
        publisher.put(&message(i)).unwrap();
    }
    open.send(()).unwrap();
    assert!(outbox.flush(FLUSH));
    assert!(
        !timed_out.load(Ordering::Relaxed),
        "a put waited for the sink"
    );
    let got = got.lock().unwrap();
    assert_eq!(got.len(), capacity);
    assert!(got.iter().enumerate().all(|(i, m)| *m == message(i)));
}

#[test]
fn a_full_ring_refuses_a_queue_message_and_drops_a_sample_counting_it() {
    let outbox = Outbox::new("test-out");
    let (queue_sink, open_queue, queue_got, _) = gated();
    let (sample_sink, open_sample, sample_got, _) = gated();
    let mut queue = outbox.publisher(queue_sink, WhenFull::Refuse).unwrap();
    let mut sample = outbox.publisher(sample_sink, WhenFull::Drop).unwrap();
    // The thread holds at most the message its sink is stalled in: the ring
    // is full after `capacity` more.
    let capacity = CAPACITY;
    let mut accepted = 0;
    let mut refused = None;
    for i in 0..capacity + 2 {
        match queue.put(&message(i)) {
            Ok(()) => accepted += 1,
            Err(e) => {
                refused = Some(e);
                break;
            }
        }
    }
    let refused = refused.expect("a full ring refuses a queue message");
    assert!(
        refused.0.contains("wait for the publishing thread"),
        "{refused}"
    );
    assert!((capacity..=capacity + 1).contains(&accepted), "{accepted}");
    // Stalled in the queue's sink, the thread does not reach the sample's
    // ring: it fills, and the rest is dropped and counted, without an error.
    for i in 0..capacity + 10 {
        sample.put(&message(i)).unwrap();
    }
    assert_eq!(outbox.dropped(), 10);
    // Not everything is in the sinks' hands yet, and the flush says so.
    assert!(!outbox.flush(Duration::from_millis(50)));
    open_queue.send(()).unwrap();
    open_sample.send(()).unwrap();
    assert!(outbox.flush(FLUSH));
    let queue_got = queue_got.lock().unwrap();
    assert_eq!(queue_got.len(), accepted);
    assert!(queue_got.iter().enumerate().all(|(i, m)| *m == message(i)));
    let sample_got = sample_got.lock().unwrap();
    assert_eq!(sample_got.len(), capacity);
    assert!(sample_got.iter().enumerate().all(|(i, m)| *m == message(i)));
}

/// A sink that refuses every other message, and says when it is dropped.
struct Refusing(usize, Arc<AtomicBool>);

impl Sink for Refusing {
    fn send(&mut self, _: Vec<u8>) -> Result<(), String> {
        self.0 += 1;
        if self.0.is_multiple_of(2) {
            Err(format!("refused message {}", self.0))
        } else {
            Ok(())
        }
    }
}

impl Drop for Refusing {
    fn drop(&mut self) {
        self.1.store(true, Ordering::Relaxed);
    }
}

fn eventually(what: &str, f: impl Fn() -> bool) {
    let deadline = Instant::now() + FLUSH;
    while !f() {
        assert!(Instant::now() < deadline, "{what}");
        std::thread::sleep(Duration::from_millis(1));
    }
}

#[test]
fn what_the_sink_refuses_is_reported_by_the_next_put() {
    let outbox = Outbox::new("test-out");
    let sink_gone = Arc::new(AtomicBool::new(false));
    let sink = Box::new(Refusing(0, sink_gone.clone()));
    let mut publisher = outbox.publisher(sink, WhenFull::Refuse).unwrap();
    publisher.put(b"one").unwrap();
    publisher.put(b"two").unwrap();
    assert!(outbox.flush(FLUSH));
    let e = publisher.put(b"three").unwrap_err();
    assert!(e.0.contains("refused message 2"), "{e}");
    // Reported once: the next put goes through.
    publisher.put(b"four").unwrap();
    assert!(outbox.flush(FLUSH));
    assert!(!sink_gone.load(Ordering::Relaxed));
    drop(publisher);
    eventually("a publisher gone, its sink is dropped", || {
        sink_gone.load(Ordering::Relaxed)
    });
}

#[test]
fn the_thread_outlives_the_outbox_while_a_publisher_lives_then_ends() {
    let outbox = Outbox::new("test-out");
    assert!(outbox.ended(), "no thread before the first publisher");
    let (sink, open, got, _) = gated();
    open.send(()).unwrap();
    let mut publisher = outbox.publisher(sink, WhenFull::Refuse).unwrap();
    let ended = {
        let outbox = &outbox;
        move || outbox.ended()
    };
    publisher.put(b"before").unwrap();
    assert!(outbox.flush(FLUSH));
    assert!(!ended());
    // The owner's end alone does not end the thread: a publisher still puts.
    let shared = outbox.shared().unwrap();
    shared.owner_gone.store(true, Ordering::Release);
    publisher.put(b"after").unwrap();
    eventually("the message put after the owner's end is sent", || {
        got.lock().unwrap().len() == 2
    });
    assert!(!ended());
    drop(publisher);
    eventually("the thread ends with the last publisher", ended);
    assert_eq!(
        *got.lock().unwrap(),
        [b"before".to_vec(), b"after".to_vec()]
    );
}

#[test]
fn a_sample_ring_holds_a_bounded_number_of_bytes() {
    let outbox = Outbox::new("test-out");
    let (sink, open, got, _) = gated();
    let mut images = outbox.publisher(sink, WhenFull::Drop).unwrap();
    let image = vec![7u8; 1 << 20];
    // The sink is stalled (in the first image, or before it): beyond the
    // bytes bound, images are dropped and counted.
    for _ in 0..40 {
        images.put(&image).unwrap();
    }
    let kept = 40 - outbox.dropped() as usize;
    assert!(
        (SAMPLE_BYTES >> 20..=(SAMPLE_BYTES >> 20) + 1).contains(&kept),
        "{kept} kept"
    );
    open.send(()).unwrap();
    assert!(outbox.flush(FLUSH));
    assert_eq!(got.lock().unwrap().len(), kept);
    // Drained, the ring takes images again, even one larger than the bound.
    images.put(&image).unwrap();
    assert!(outbox.flush(FLUSH));
    images.put(&vec![1u8; SAMPLE_BYTES + 1]).unwrap();
    assert!(outbox.flush(FLUSH));
    assert_eq!(got.lock().unwrap().len(), kept + 2);
    assert_eq!(outbox.dropped() as usize, 40 - kept);
}
