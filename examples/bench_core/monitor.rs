//! `bench_core`'s monitor figures: the monitors of Rex's contracts
//! (specs/rex.ron) watching a system with Rex's names, links, payload types
//! and predicates where those contracts read ([`rex_shaped`]: this crate
//! cannot build Rex itself), run without and with the watch in alternating
//! batches ([`monitor_cost`]).

use std::time::{Duration, Instant};

use embodied::*;

use super::{BATCH, BATCHES, Pose, REX_SPEC, median};

mod rex_shaped {
    use embodied::*;

    use super::Pose;

    /// The wheels' torques, as e11 sends them (`rex_agent`'s `Torques`).
    pub(super) type Torques = [f64; 4];

    /// e11's buffers towards the platform E1 and the control c1.
    #[derive(Debug, Default, Group)]
    #[group(peer = RealEffector)]
    pub(super) struct E11ToE1 {
        pub(super) tau: Out<Torques>,
    }
    #[derive(Debug, Default, Group)]
    #[group(peer = RealEffector)]
    pub(super) struct E11FromE1 {
        pub(super) encoders: In<[f64; 4]>,
        pub(super) imu: In<[f64; 3]>,
    }
    #[derive(Debug, Default, Group)]
    #[group(peer = Control)]
    pub(super) struct E11FromC1 {
        pub(super) pose: In<Pose>,
    }
    #[derive(Debug, Default, Buffers)]
    pub(super) struct E11In {
        pub(super) platform: E11FromE1,
        pub(super) c1: E11FromC1,
    }
    #[derive(Debug, Default, Buffers)]
    pub(super) struct E11Out {
        pub(super) platform: E11ToE1,
    }

    #[derive(Debug, Default, Group)]
    #[group(peer = VirtualEffector)]
    pub(super) struct C1ToE11 {
        pub(super) pose: Out<Pose>,
    }
    #[derive(Debug, Default, Group)]
    #[group(peer = Control)]
    pub(super) struct C1FromC3 {
        pub(super) pose: In<Pose>,
    }
    #[derive(Debug, Default, Group)]
    #[group(peer = Control)]
    pub(super) struct C1FromC2 {
        pub(super) desired_plan: In<u64>,
    }
    #[derive(Debug, Default, Group)]
    #[group(peer = Control)]
    pub(super) struct C1ToC2 {
        pub(super) ack: Out<u64>,
    }
    #[derive(Debug, Default, Buffers)]
    pub(super) struct C1In {
        pub(super) c3: C1FromC3,
        pub(super) c2: C1FromC2,
    }
    #[derive(Debug, Default, Buffers)]
    pub(super) struct C1Out {
        pub(super) e11: C1ToE11,
        pub(super) c2: C1ToC2,
    }

    #[derive(Debug, Default, Group)]
    #[group(peer = Control)]
    pub(super) struct C2ToC1 {
        pub(super) desired_plan: Out<u64>,
    }
    #[derive(Debug, Default, Group)]
    #[group(peer = Control)]
    pub(super) struct C2FromC1 {
        pub(super) ack: In<u64>,
    }
    #[derive(Debug, Default, Buffers)]
    pub(super) struct C2In {
        pub(super) c1: C2FromC1,
    }
    #[derive(Debug, Default, Buffers)]
    pub(super) struct C2Out {
        pub(super) c1: C2ToC1,
    }

    #[derive(Debug, Default, Group)]
    #[group(peer = Control)]
    pub(super) struct C3ToC1 {
        pub(super) pose: Out<Pose>,
    }
    #[derive(Debug, Default, Buffers)]
    pub(super) struct C3Out {
        pub(super) c1: C3ToC1,
    }

    #[derive(Debug, Default, Memory)]
    pub(super) struct Count {
        n: u64,
    }

    #[derive(Subsystem)]
    #[subsystem(kind = VirtualEffector, memory = Count, input = E11In, output = E11Out)]
    pub(super) struct E11;

    #[derive(Subsystem)]
    #[subsystem(kind = Control, memory = Count, input = C1In, output = C1Out)]
    pub(super) struct C1;

    #[derive(Subsystem)]
    #[subsystem(kind = Control, memory = Count, input = C2In, output = C2Out)]
    pub(super) struct C2;

    #[derive(Subsystem)]
    #[subsystem(kind = Control, memory = Count, input = (), output = C3Out)]
    pub(super) struct C3;

    /// The platform E1: reads the torques, sends the encoders and the IMU.
    #[derive(Debug, Default)]
    pub(super) struct Platform {
        n: u64,
    }

    #[derive(Debug, Default, Buffers)]
    pub(super) struct PlatformIn {
        pub(super) tau: In<Torques>,
    }

    #[derive(Debug, Default, Buffers)]
    pub(super) struct PlatformOut {
        pub(super) encoders: Out<[f64; 4]>,
        pub(super) imu: Out<[f64; 3]>,
    }

    impl Driver for Platform {
        const KIND: DeviceKind = DeviceKind::Effector;
        type Input = PlatformIn;
        type Output = PlatformOut;

        fn step(
            &mut self,
            _: DriverContext<'_>,
            x: &PlatformIn,
            y: &mut PlatformOut,
        ) -> Result<(), DriverError> {
            self.n += 1;
            let tau = x.tau.get().copied().unwrap_or_default();
            let n = self.n as f64;
            y.encoders
                .set([n + tau[0], n + tau[1], n + tau[2], n + tau[3]]);
            y.imu.set([tau[0] * 0.1, 0.0, 9.81]);
            Ok(())
        }
    }

    fn track(m: &Count, x: &E11In, y: &mut E11ToE1) {
        let enc = x.platform.encoders.get().copied().unwrap_or_default();
        let imu = x.platform.imu.get().copied().unwrap_or_default();
        let p = x.c1.pose.get().copied().unwrap_or_default();
        // Within the contracts' ±10 N m: at most 8.5 + 0.001.
        let t = ((m.n % 16) as f64 - 8.0)
            + 0.01 * (enc[0] - enc[1] + imu[0]).clamp(-50.0, 50.0)
            + 1e-3 * (p.x - p.y).sin();
        y.tau.set([t, -t, t * 0.5, -t * 0.5]);
    }

    fn relay(m: &Count, x: &C1In, y: &mut C1ToE11) {
        let mut p = x.c3.pose.get().copied().unwrap_or_default();
        p.phi += (m.n & 1) as f64;
        y.pose.set(p);
    }

    fn acknowledge(_: &Count, x: &C1In, y: &mut C1ToC2) {
        if let Some(&plan) = x.c2.desired_plan.get() {
            y.ack.set(plan);
        }
    }

    fn order(m: &Count, x: &C2In, y: &mut C2ToC1) {
        y.desired_plan
            .set(m.n + x.c1.ack.get().copied().unwrap_or(0));
    }

    fn capture(m: &Count, _: &(), y: &mut C3ToC1) {
        let n = m.n as f64;
        y.pose.set(Pose {
            x: n * 1e-3,
            y: -n * 1e-3,
            phi: 0.1,
        });
    }

    fn tick<X>(m: &mut Count, _: &X) {
        m.n += 1;
    }

    /// Rex's nodes and the links its contracts read, every node on one period
    /// (a cycle: each of the five acts once).
    pub(super) fn system() -> Result<System, Box<dyn std::error::Error>> {
        let period = Period::from_millis(1)?;
        let mut b = SystemBuilder::new();
        let (a1, a2, a3) = (b.agent("a1"), b.agent("a2"), b.agent("a3"));
        let e11 = fsm! {
            subsystem E11;
            while B1 until false { platform <- track, memory <- tick }
            initial B1;
        }?;
        let c1 = fsm! {
            subsystem C1;
            while B1 until false { e11 <- relay, c2 <- acknowledge, memory <- tick }
            initial B1;
        }?;
        // With the predicates of c2 that Rex's invariant reads (evaluated
        // after each activation, for the watch).
        let c2 = fsm! {
            subsystem C2;
            predicates {
                more: |m: &Count, _| m.n < u64::MAX,
                lost: |m: &Count, _| m.n == u64::MAX,
            }
            while B1 until false { c1 <- order, memory <- tick }
            initial B1;
        }?;
        let c3 = fsm! {
            subsystem C3;
            while B1 until false { c1 <- capture, memory <- tick }
            initial B1;
        }?;
        let c1 = b.subsystem(a1, "c1", period, Count::default(), c1);
        let e11 = b.subsystem(a1, "e11", period, Count::default(), e11);
        let platform = b.driver(a1, "E1", period, Platform::default());
        let c2 = b.subsystem(a2, "c2", period, Count::default(), c2);
        let c3 = b.subsystem(a3, "c3", period, Count::default(), c3);
        let (sample, queue) = (Policy::Sample, Policy::queue(4));
        b.connect(
            e11.output(port!(E11Out, platform.tau)),
            platform.input(port!(PlatformIn, tau)),
            sample,
        );
        b.connect(
            platform.output(port!(PlatformOut, encoders)),
            e11.input(port!(E11In, platform.encoders)),
            sample,
        );
        b.connect(
            platform.output(port!(PlatformOut, imu)),
            e11.input(port!(E11In, platform.imu)),
            sample,
        );
        b.connect(
            c1.output(port!(C1Out, e11.pose)),
            e11.input(port!(E11In, c1.pose)),
            sample,
        );
        b.connect(
            c3.output(port!(C3Out, c1.pose)),
            c1.input(port!(C1In, c3.pose)),
            sample,
        );
        b.connect(
            c2.output(port!(C2Out, c1.desired_plan)),
            c1.input(port!(C1In, c2.desired_plan)),
            queue,
        );
        b.connect(
            c1.output(port!(C1Out, c2.ack)),
            c2.input(port!(C2In, c1.ack)),
            queue,
        );
        Ok(b.build()?)
    }
}

/// Nodes that act in each cycle of [`rex_shaped::system`] (c1, e11, c2, c3
/// and the platform E1).
pub(super) const REX_ACTIONS_PER_CYCLE: u64 = 5;

/// An observer that takes every event of the run and judges nothing: what
/// the executor's events cost an observer called for each (the watch asks
/// for fewer, `Observer::link_events`), with the predicates the watch asks
/// for evaluated as for it.
struct Silent {
    /// Per node: the predicates the watch wants after its activations.
    wanted: Vec<u64>,
}

impl Observer for Silent {
    fn transfer(&mut self, e: &trace::TransferEvent, value: &dyn trace::ErasedPayload) {
        std::hint::black_box((e, value));
    }
    fn read(&mut self, e: &trace::ReadEvent) {
        std::hint::black_box(e);
    }
    fn predicates_wanted(&self, node: usize) -> u64 {
        self.wanted.get(node).copied().unwrap_or(0)
    }
    fn predicates(&mut self, e: &ActionEvent, values: Valuation) {
        std::hint::black_box((e, values));
    }
}

/// One batch of instants of `exec`: ns per instant, and the allocations.
fn cycles<O: Observer>(exec: &mut Executor<O>) -> Result<(f64, u64), ExecError> {
    let before = allocations::total();
    let start = Instant::now();
    for _ in 0..BATCH {
        exec.step()?;
    }
    let ns = start.elapsed().as_nanos() as f64 / BATCH as f64;
    Ok((ns, allocations::total() - before))
}

/// What watching Rex's contracts costs the executor.
pub(super) struct MonitorCost {
    /// Median ns per cycle of the Rex-shaped system, unwatched.
    pub(super) plain_ns: f64,
    /// Median ns per cycle added by the watch.
    pub(super) watch_ns: f64,
    /// Median ns per cycle added by an observer that takes every event and
    /// judges nothing ([`Silent`]): what an observer called per event pays
    /// before it judges anything.
    pub(super) events_ns: f64,
    /// Allocations per watched cycle.
    pub(super) allocs_per_cycle: f64,
    /// The contracts judged, and those broken (0: the system keeps them).
    pub(super) judged: usize,
    pub(super) violated: usize,
}

/// The Rex-shaped system ([`rex_shaped`]) in three executors, one watched by
/// the monitors of specs/rex.ron's contracts (`embodied run`'s
/// [`agent_monitor::live::Live`] watch), one by [`Silent`], in alternating
/// batches; the watch's cost is the difference of their medians per cycle
/// (and the events' cost, [`Silent`]'s). It includes what the
/// executor does for the watch (the read and transfer events it asks for,
/// the torques' range checks compiled into their link), as a run with
/// contracts pays it.
pub(super) fn monitor_cost() -> Result<MonitorCost, Box<dyn std::error::Error>> {
    let loaded = embodied::spec::load("specs/rex.ron", REX_SPEC).map_err(|r| r.short())?;
    let monitors = agent_monitor::Monitors::new(&loaded.spec)?;
    let system = rex_shaped::system()?;
    let live = agent_monitor::live::Live::new(monitors, &system);
    let mut plain = Executor::new(rex_shaped::system()?, ExecConfig::default());
    let watch = live.watch();
    let wanted = (0..system.info().nodes.len())
        .map(|n| watch.predicates_wanted(n))
        .collect();
    drop(watch);
    let silent = Silent { wanted };
    let mut watched = Executor::with_observer(system, ExecConfig::default(), live.watch());
    let mut floor = Executor::with_observer(rex_shaped::system()?, ExecConfig::default(), silent);
    // Warm-up: buffers and queues filled, every monitor started.
    plain.run_for(Duration::from_millis(BATCH))?;
    watched.run_for(Duration::from_millis(BATCH))?;
    floor.run_for(Duration::from_millis(BATCH))?;
    let (mut plain_ns, mut watched_ns, mut floor_ns) = (Vec::new(), Vec::new(), Vec::new());
    let mut allocations = 0;
    for _ in 0..BATCHES {
        plain_ns.push(cycles(&mut plain)?.0);
        floor_ns.push(cycles(&mut floor)?.0);
        let (ns, allocs) = cycles(&mut watched)?;
        watched_ns.push(ns);
        allocations += allocs;
    }
    let errors =
        watched.report().error_count + plain.report().error_count + floor.report().error_count;
    drop(watched.into_observer()); // the watch hands its verdicts over
    let verdicts = live.verdicts();
    if errors != 0 || !verdicts.not_judged.is_empty() {
        return Err(format!(
            "the Rex-shaped runs had {errors} errors; contracts not judged: {:?}",
            verdicts.not_judged
        )
        .into());
    }
    let plain_ns = median(plain_ns);
    Ok(MonitorCost {
        plain_ns,
        watch_ns: median(watched_ns) - plain_ns,
        events_ns: median(floor_ns) - plain_ns,
        allocs_per_cycle: allocations as f64 / (BATCHES as u64 * BATCH) as f64,
        judged: verdicts.judged.len(),
        violated: verdicts.contracts_violated(),
    })
}
