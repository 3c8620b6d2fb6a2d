//! The bridge costs a node's thread no allocation per value: each value's
//! bytes go into a slot buffer that circulates between the thread's tap and
//! the publishing thread. A counting allocator watches only the test's
//! thread, which stands for a node's: it hands the bridge a thousand values
//! of a published link (a `String` and a `Vec` inside each) and allocates
//! nothing doing so, whether the publishing thread keeps up or the ring is
//! full and values are dropped.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

mod common;

use std::time::Duration;

use agent_core::allocations::{CountingAllocator, count};
use agent_core::trace::{Observer, TransferEvent};
use agent_core::{Stamp, Time};
use agent_ros2::bridge::{Bridge, BridgeOptions, Mode, Plan, SessionOptions};
use common::{adapters, spec, status_at, system};

#[global_allocator]
static ALLOCATOR: CountingAllocator = CountingAllocator;

#[test]
fn handing_values_to_the_bridge_allocates_nothing_on_the_nodes_thread() {
    let plan = Plan::new(&spec(common::ROS2), None, &system(), &adapters()).unwrap();
    let link = plan.topics[1].link;
    let alone = SessionOptions {
        mode: Mode::Peer,
        connect: vec![],
        listen: vec![],
    };
    let options = BridgeOptions {
        session: alone,
        slots: 16,
        ..BridgeOptions::default()
    };
    let mut bridge = Bridge::start(plan, options).unwrap();
    let values: Vec<_> = (0..1000).map(status_at).collect();
    let (allocations, ()) = count(|| {
        for (k, value) in (0u64..).zip(&values) {
            let stamp = Stamp::new(k, Time::from_nanos(k * 10_000_000));
            bridge.transfer(&TransferEvent { link, stamp }, value);
            if k % 100 == 0 {
                // Let the publishing thread drain the ring now and then.
                std::thread::sleep(Duration::from_millis(5));
            }
        }
    })
    .expect("the counting allocator is installed above");
    assert_eq!(allocations, 0);
    let report = bridge.finish().unwrap();
    let status = &report.topics[1];
    assert_eq!(status.published + status.dropped, 1000, "{report:?}");
    assert!(status.published > 0, "{report:?}");
    assert_eq!(status.encode_failures, 0);
}
