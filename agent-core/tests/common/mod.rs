//! Fixtures shared by the executor's and the system builder's tests: a counting
//! control subsystem and an effector that records what it receives, linked.

#![allow(dead_code, reason = "each test file uses part of the fixtures")]
#![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

use agent_core::*;

// ---------------------------------------------------------------------------
// A control subsystem that counts and sends its count to its effector (every
// `every`-th iteration), and an effector that records what it receives.

pub(crate) struct Counter;

#[derive(Clone, Debug)]
pub(crate) struct CounterMemory {
    pub(crate) n: u64,
    pub(crate) every: u64,
}

#[derive(Debug, Default)]
pub(crate) struct CountToE {
    pub(crate) count: Out<u64>,
}
impl Group for CountToE {
    const PEER: NodeKind = NodeKind::VirtualEffector;
}

#[derive(Debug, Default)]
pub(crate) struct CounterOut {
    pub(crate) e: CountToE,
}

#[derive(Debug, Default, Clone)]
pub(crate) struct EchoFromE {
    pub(crate) echo: In<u64>,
}
impl Group for EchoFromE {
    const PEER: NodeKind = NodeKind::VirtualEffector;
}

#[derive(Debug, Default, Clone)]
pub(crate) struct CounterIn {
    pub(crate) e: EchoFromE,
}

impl Subsystem for Counter {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = CounterMemory;
    type Input = CounterIn;
    type Output = CounterOut;
}

pub(crate) fn counter_fsm() -> Fsm<Counter> {
    Fsm::single(Behaviour::while_loop(
        "count",
        Action::<Counter>::new()
            .output(
                |y| &mut y.e,
                |m: &CounterMemory, _: &CounterIn, y: &mut CountToE| {
                    if m.n.is_multiple_of(m.every) {
                        y.count.set(m.n);
                    }
                },
            )
            .memory(|m: &mut CounterMemory, _: &CounterIn| m.n += 1),
        "false",
    ))
    .unwrap()
}

pub(crate) struct Recv;

#[derive(Clone, Debug, Default)]
pub(crate) struct RecvMemory {
    /// (own iteration, value, stamp) of every fresh value.
    pub(crate) got: Vec<(u64, u64, Stamp)>,
    /// `is_new()` at each iteration.
    pub(crate) fresh: Vec<bool>,
    pub(crate) iteration: u64,
}

#[derive(Debug, Default, Clone)]
pub(crate) struct FromC {
    pub(crate) count: In<u64>,
}
impl Group for FromC {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Debug, Default, Clone)]
pub(crate) struct RecvIn {
    pub(crate) c: FromC,
}

#[derive(Debug, Default)]
pub(crate) struct EchoToC {
    pub(crate) echo: Out<u64>,
}
impl Group for EchoToC {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Debug, Default)]
pub(crate) struct RecvOut {
    pub(crate) c: EchoToC,
}

impl Subsystem for Recv {
    const KIND: SubsystemKind = SubsystemKind::VirtualEffector;
    type Memory = RecvMemory;
    type Input = RecvIn;
    type Output = RecvOut;
}

pub(crate) fn recv_fsm(require: bool) -> Fsm<Recv> {
    Fsm::single(Behaviour::while_loop(
        "record",
        Action::<Recv>::new()
            .output(
                |y| &mut y.c,
                move |m: &RecvMemory, x: &RecvIn, y: &mut EchoToC| {
                    // Written first, so that a failure below shows that a failed
                    // action sends nothing.
                    y.echo.set(m.iteration);
                    if require {
                        x.c.count.require()?;
                    }
                    Ok::<(), ActionError>(())
                },
            )
            .memory(|m: &mut RecvMemory, x: &RecvIn| {
                if let Some(&v) = x.c.count.fresh() {
                    m.got.push((m.iteration, v, x.c.count.stamp().unwrap()));
                }
                m.fresh.push(x.c.count.is_new());
                m.iteration += 1;
            }),
        "false",
    ))
    .unwrap()
}

pub(crate) fn ms(n: u64) -> Period {
    Period::from_millis(n).unwrap()
}

pub(crate) fn t_ms(n: u64) -> Time {
    Time::from_nanos(n * 1_000_000)
}

pub(crate) struct Pair {
    pub(crate) system: System,
    pub(crate) c: SubsystemHandle<Counter>,
    pub(crate) e: SubsystemHandle<Recv>,
    pub(crate) down: LinkId,
}

pub(crate) fn pair(
    c_period: u64,
    e_period: u64,
    every: u64,
    policy: Policy,
    require: bool,
) -> Pair {
    let mut b = SystemBuilder::new();
    let a = b.agent("a");
    let c = b.subsystem(
        a,
        "c",
        ms(c_period),
        CounterMemory { n: 0, every },
        counter_fsm(),
    );
    let e = b.subsystem(
        a,
        "e",
        ms(e_period),
        RecvMemory::default(),
        recv_fsm(require),
    );
    let down = b.connect(
        c.output(port!(CounterOut, e.count)),
        e.input(port!(RecvIn, c.count)),
        policy,
    );
    b.connect(
        e.output(port!(RecvOut, c.echo)),
        c.input(port!(CounterIn, e.echo)),
        Policy::Sample,
    );
    Pair {
        system: b.build().unwrap(),
        c,
        e,
        down,
    }
}

/// `pairs` agents `a<i>` of a pair `c<i>` → `e<i>` (declared in turn: c0, e0, c1, e1, ...), `c`
/// every `c_ms`, `e` every `e_ms`, a lossless queue from each `c` to its `e`.
pub(crate) struct Pairs {
    pub(crate) system: System,
    pub(crate) cs: Vec<SubsystemHandle<Counter>>,
    pub(crate) es: Vec<SubsystemHandle<Recv>>,
}

pub(crate) fn pairs(pairs: usize, c_ms: u64, e_ms: u64) -> Pairs {
    let mut b = SystemBuilder::new();
    let (mut cs, mut es) = (Vec::new(), Vec::new());
    for i in 0..pairs {
        let a = b.agent(format!("a{i}"));
        let c = b.subsystem(
            a,
            format!("c{i}"),
            ms(c_ms),
            CounterMemory { n: 0, every: 1 },
            counter_fsm(),
        );
        let e = b.subsystem(
            a,
            format!("e{i}"),
            ms(e_ms),
            RecvMemory::default(),
            recv_fsm(false),
        );
        b.connect(
            c.output(port!(CounterOut, e.count)),
            e.input(port!(RecvIn, c.count)),
            Policy::queue(4096),
        );
        b.connect(
            e.output(port!(RecvOut, c.echo)),
            c.input(port!(CounterIn, e.echo)),
            Policy::Sample,
        );
        cs.push(c);
        es.push(e);
    }
    Pairs {
        system: b.build().unwrap(),
        cs,
        es,
    }
}

// A virtual receptor that records the values of its real receptor.

pub(crate) struct Reader;

#[derive(Debug, Default, Clone)]
pub(crate) struct FromR {
    pub(crate) value: In<u64>,
}
impl Group for FromR {
    const PEER: NodeKind = NodeKind::RealReceptor;
}

#[derive(Debug, Default, Clone)]
pub(crate) struct ReaderIn {
    pub(crate) r: FromR,
}

impl Subsystem for Reader {
    const KIND: SubsystemKind = SubsystemKind::VirtualReceptor;
    type Memory = Vec<u64>;
    type Input = ReaderIn;
    type Output = ();
}

// ---------------------------------------------------------------------------
// An environment: a cart on a rail, a motor that moves it, an encoder that senses it.

/// The world: a cart on a rail.
#[derive(Debug, Default)]
pub(crate) struct Rail {
    pub(crate) position: f64,
}

/// E: a motor that moves the cart one unit per step.
pub(crate) struct Motor;

impl Driver for Motor {
    const KIND: DeviceKind = DeviceKind::Effector;
    type Input = ();
    type Output = ();
    fn step(&mut self, mut cx: DriverContext<'_>, _: &(), _: &mut ()) -> Result<(), DriverError> {
        cx.environment::<Rail>()?.position += 1.0;
        Ok(())
    }
}

/// R: an encoder that records the position it senses.
#[derive(Default)]
pub(crate) struct Encoder {
    pub(crate) sensed: Vec<f64>,
}

impl Driver for Encoder {
    const KIND: DeviceKind = DeviceKind::Receptor;
    type Input = ();
    type Output = ();
    fn step(&mut self, mut cx: DriverContext<'_>, _: &(), _: &mut ()) -> Result<(), DriverError> {
        let position = cx.environment::<Rail>()?.position;
        self.sensed.push(position);
        Ok(())
    }
}
