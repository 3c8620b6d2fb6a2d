//! A tank filling station as a two-agent system, written only against the public
//! `embodied` API.
//!
//! * Agent `station`: control subsystem `c1` (FSM `idle -> fill -> settle -> report`),
//!   virtual effector `e1` (pump controller), virtual receptor `r1` (level filter),
//!   real effector `E1` (a reversible pump) and real receptor `R1` (a noisy level
//!   gauge), both over one simulated tank.
//! * Agent `operator`: control subsystem `c2`, which sends orders ("bring the level
//!   to 1.2 m") one at a time and waits for each acknowledgement, like the ontology
//!   agent that sends plans to Rex.
//!
//! ```text
//!   operator.c2 ──order──▶ station.c1 ──flow──▶ e1 ──duty──▶ E1 ┐
//!        ▲                  │   ▲  ▲                          ▼ tank
//!        └──────ack─────────┘   │  └──level── r1 ◀──reading── R1 ┘
//!                               └─────measured flow── e1 ◀── E1
//! ```

#![allow(
    dead_code,
    unreachable_pub,
    reason = "a module shared by the example binary and the integration tests, each using part of it"
)]

use embodied::*;
use serde::{Deserialize, Serialize};

#[path = "world.rs"]
mod world;
pub use world::*;

// ---------------------------------------------------------------------------
// Messages

/// An order from the operator: bring the level to `level` metres.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Order {
    /// Order number.
    pub id: u32,
    /// Target level \[m\].
    pub level: f64,
}

/// The station's answer to an order.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Ack {
    /// The level was brought to `level` (filtered measurement) for order `id`.
    Done { id: u32, level: f64 },
    /// The order was refused.
    Refused { id: u32, reason: String },
}

impl Ack {
    /// The order this acknowledges.
    pub fn id(&self) -> u32 {
        match self {
            Ack::Done { id, .. } | Ack::Refused { id, .. } => *id,
        }
    }
}

// ---------------------------------------------------------------------------
// r1: the level filter (virtual receptor)

pub struct LevelFilter;

#[derive(Clone, Debug, Default)]
pub struct FilterMemory {
    /// Filtered level \[m\], once a valid reading arrived.
    pub estimate: Option<f64>,
    /// Readings rejected as implausible (NaN, outside the tank).
    pub rejected: u64,
}

#[derive(Clone, Debug, Default)]
pub struct FromGauge {
    pub level: In<f64>,
}
impl Group for FromGauge {
    const PEER: NodeKind = NodeKind::RealReceptor;
}

#[derive(Clone, Debug, Default)]
pub struct FilterInput {
    pub gauge: FromGauge,
}

#[derive(Debug, Default)]
pub struct LevelToControl {
    pub level: Out<f64>,
}
impl Group for LevelToControl {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Debug, Default)]
pub struct FilterOutput {
    pub control: LevelToControl,
}

impl Subsystem for LevelFilter {
    const KIND: SubsystemKind = SubsystemKind::VirtualReceptor;
    type Memory = FilterMemory;
    type Input = FilterInput;
    type Output = FilterOutput;
}

/// Exponential smoothing factor per reading.
pub const FILTER_ALPHA: f64 = 0.2;

/// `f_{r,r}`: smooth valid readings, count implausible ones.
fn filter_memory(m: &mut FilterMemory, x: &FilterInput) {
    let Some(&z) = x.gauge.level.fresh() else {
        return;
    };
    if !(z.is_finite() && (-0.1..=2.5).contains(&z)) {
        m.rejected += 1;
        return;
    }
    m.estimate = Some(match m.estimate {
        Some(e) => e + FILTER_ALPHA * (z - e),
        None => z,
    });
}

/// `f_{r,c}`: send the current estimate.
fn filter_to_control(m: &FilterMemory, _: &FilterInput, y: &mut LevelToControl) {
    if let Some(e) = m.estimate {
        y.level.set(e);
    }
}

pub fn filter_fsm() -> Result<Fsm<LevelFilter>, FsmBuildError> {
    Fsm::single(Behaviour::while_loop(
        "filter",
        Action::<LevelFilter>::new()
            .common(filter_memory)
            .output(|y| &mut y.control, filter_to_control),
        "false",
    ))
}

// ---------------------------------------------------------------------------
// e1: the pump controller (virtual effector)

pub struct PumpControl;

#[derive(Clone, Debug)]
pub struct PumpMemory {
    /// Current duty command.
    pub duty: f64,
    /// Largest duty change per iteration.
    pub slew: f64,
    /// Pump flow at full duty \[m³/s\].
    pub max_flow: f64,
}

#[derive(Clone, Debug, Default)]
pub struct FlowFromControl {
    pub flow: In<f64>,
}
impl Group for FlowFromControl {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Clone, Debug, Default)]
pub struct FlowFromPump {
    pub flow: In<f64>,
}
impl Group for FlowFromPump {
    const PEER: NodeKind = NodeKind::RealEffector;
}

#[derive(Clone, Debug, Default)]
pub struct PumpControlInput {
    pub control: FlowFromControl,
    pub pump: FlowFromPump,
}

#[derive(Debug, Default)]
pub struct DutyToPump {
    pub duty: Out<f64>,
}
impl Group for DutyToPump {
    const PEER: NodeKind = NodeKind::RealEffector;
}

#[derive(Debug, Default)]
pub struct FlowToControl {
    pub flow: Out<f64>,
}
impl Group for FlowToControl {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Debug, Default)]
pub struct PumpControlOutput {
    pub pump: DutyToPump,
    pub control: FlowToControl,
}

impl Subsystem for PumpControl {
    const KIND: SubsystemKind = SubsystemKind::VirtualEffector;
    type Memory = PumpMemory;
    type Input = PumpControlInput;
    type Output = PumpControlOutput;
}

/// Common part: the new duty, rate-limited towards the requested flow. A missing or
/// non-finite request means "stop".
fn pump_duty(m: &mut PumpMemory, x: &PumpControlInput) {
    let wanted = x
        .control
        .flow
        .get()
        .filter(|q| q.is_finite())
        .map_or(0.0, |q| (q / m.max_flow).clamp(-1.0, 1.0));
    m.duty += (wanted - m.duty).clamp(-m.slew, m.slew);
}

pub fn pump_control_fsm() -> Result<Fsm<PumpControl>, FsmBuildError> {
    Fsm::single(Behaviour::while_loop(
        "drive",
        Action::<PumpControl>::new()
            .common(pump_duty)
            .output(
                |y| &mut y.pump,
                |m: &PumpMemory, _: &PumpControlInput, y: &mut DutyToPump| {
                    y.duty.set(m.duty);
                },
            )
            .output(
                |y| &mut y.control,
                |_: &PumpMemory, x: &PumpControlInput, y: &mut FlowToControl| {
                    if let Some(&q) = x.pump.flow.fresh() {
                        y.flow.set(q);
                    }
                },
            ),
        "false",
    ))
}

// ---------------------------------------------------------------------------
// c1: the station (control subsystem)

pub struct Station;

/// Station settings.
#[derive(Clone, Copy, Debug)]
pub struct StationParams {
    /// Accepted target levels \[m\].
    pub min_level: f64,
    pub max_level: f64,
    /// `fill` ends when the level is this close to the target \[m\].
    pub reach: f64,
    /// After settling, the order is done if the level is this close \[m\].
    pub tolerance: f64,
    /// Iterations of `settle`.
    pub settle_iterations: u32,
    /// Proportional gain [m³/s per m of level error] and flow limit \[m³/s\].
    pub gain: f64,
    pub max_flow: f64,
}

impl Default for StationParams {
    fn default() -> Self {
        StationParams {
            min_level: 0.1,
            max_level: 1.9,
            reach: 0.01,
            tolerance: 0.02,
            settle_iterations: 10,
            gain: 0.1,
            max_flow: 0.02,
        }
    }
}

#[derive(Clone, Debug)]
pub struct StationMemory {
    pub params: StationParams,
    /// The order being served.
    pub order: Option<Order>,
    /// Iterations spent in `settle`.
    pub settled: u32,
}

impl StationMemory {
    pub fn new(params: StationParams) -> Self {
        StationMemory {
            params,
            order: None,
            settled: 0,
        }
    }

    fn target(&self) -> Option<f64> {
        self.order.map(|o| o.level)
    }

    /// Why an order cannot be served, if it cannot.
    pub fn refusal(&self, order: &Order) -> Option<String> {
        let p = &self.params;
        (!(order.level.is_finite() && (p.min_level..=p.max_level).contains(&order.level))).then(
            || {
                format!(
                    "target level {} m is outside [{}, {}] m",
                    order.level, p.min_level, p.max_level
                )
            },
        )
    }
}

#[derive(Clone, Debug, Default)]
pub struct LevelFromFilter {
    pub level: In<f64>,
}
impl Group for LevelFromFilter {
    const PEER: NodeKind = NodeKind::VirtualReceptor;
}

#[derive(Clone, Debug, Default)]
pub struct FlowFromPumpControl {
    pub flow: In<f64>,
}
impl Group for FlowFromPumpControl {
    const PEER: NodeKind = NodeKind::VirtualEffector;
}

#[derive(Clone, Debug, Default)]
pub struct FromOperator {
    pub order: In<Order>,
}
impl Group for FromOperator {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Clone, Debug, Default)]
pub struct StationInput {
    pub filter: LevelFromFilter,
    pub pump: FlowFromPumpControl,
    pub operator: FromOperator,
}

#[derive(Debug, Default)]
pub struct FlowToPumpControl {
    pub flow: Out<f64>,
}
impl Group for FlowToPumpControl {
    const PEER: NodeKind = NodeKind::VirtualEffector;
}

#[derive(Debug, Default)]
pub struct ToOperator {
    pub ack: Out<Ack>,
}
impl Group for ToOperator {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Debug, Default)]
pub struct StationOutput {
    pub pump: FlowToPumpControl,
    pub operator: ToOperator,
}

impl Subsystem for Station {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = StationMemory;
    type Input = StationInput;
    type Output = StationOutput;
}

fn stop_pump(_: &StationMemory, _: &StationInput, y: &mut FlowToPumpControl) {
    y.flow.set(0.0);
}

/// `f_{c,c}` of `idle`: take a new order.
fn take_order(m: &mut StationMemory, x: &StationInput) {
    if let Some(order) = x.operator.order.fresh() {
        m.order = Some(*order);
    }
}

/// `f_{c,e}` of `fill`: proportional flow towards the target (fills or drains).
fn fill_flow(
    m: &StationMemory,
    x: &StationInput,
    y: &mut FlowToPumpControl,
) -> Result<(), ActionError> {
    let level = *x.filter.level.require()?;
    let target = m
        .target()
        .ok_or_else(|| ActionError::failed("fill without an order"))?;
    let p = &m.params;
    y.flow
        .set((p.gain * (target - level)).clamp(-p.max_flow, p.max_flow));
    Ok(())
}

/// `f_{c,T}` of `report`: acknowledge the order.
fn acknowledge(m: &StationMemory, x: &StationInput, y: &mut ToOperator) {
    let Some(order) = m.order else { return };
    y.ack.set(match m.refusal(&order) {
        Some(reason) => Ack::Refused {
            id: order.id,
            reason,
        },
        None => Ack::Done {
            id: order.id,
            level: x.filter.level.get().copied().unwrap_or(f64::NAN),
        },
    });
}

fn level_error(m: &StationMemory, x: &StationInput) -> Option<f64> {
    Some((m.target()? - *x.filter.level.get()?).abs())
}

pub fn station_fsm() -> Result<Fsm<Station>, FsmBuildError> {
    Fsm::builder()
        .predicate("has_order", |m: &StationMemory, _| m.order.is_some())
        .predicate("order_valid", |m: &StationMemory, _| {
            m.order.is_some_and(|o| m.refusal(&o).is_none())
        })
        .predicate("reached", |m: &StationMemory, x: &StationInput| {
            level_error(m, x).is_some_and(|e| e <= m.params.reach)
        })
        .predicate("settled", |m: &StationMemory, _| {
            m.settled >= m.params.settle_iterations
        })
        .predicate("in_tolerance", |m: &StationMemory, x: &StationInput| {
            level_error(m, x).is_some_and(|e| e <= m.params.tolerance)
        })
        .behaviour(Behaviour::while_loop(
            "idle",
            Action::<Station>::new()
                .output(|y| &mut y.pump, stop_pump)
                .memory(take_order),
            "has_order",
        ))
        .behaviour(Behaviour::repeat_loop(
            "fill",
            Action::<Station>::new()
                .output(|y| &mut y.pump, fill_flow)
                .memory(|m: &mut StationMemory, _: &StationInput| m.settled = 0),
            "reached",
        ))
        .behaviour(Behaviour::while_loop(
            "settle",
            Action::<Station>::new()
                .output(|y| &mut y.pump, stop_pump)
                .memory(|m: &mut StationMemory, _: &StationInput| m.settled += 1),
            "settled",
        ))
        .behaviour(Behaviour::repeat_loop(
            "report",
            Action::<Station>::new()
                .output(|y| &mut y.operator, acknowledge)
                .output(|y| &mut y.pump, stop_pump)
                .memory(|m: &mut StationMemory, _: &StationInput| m.order = None),
            "true",
        ))
        .initial("idle")
        .arc("idle", "fill", "order_valid")
        .arc("idle", "report", "!order_valid")
        .arc("fill", "settle", "true")
        .arc("settle", "report", "in_tolerance")
        .arc("settle", "fill", "!in_tolerance")
        .arc("report", "idle", "true")
        .build()
}

// ---------------------------------------------------------------------------
// c2: the operator (control subsystem of the second agent)

pub struct Operator;

#[derive(Clone, Debug, Default)]
pub struct OperatorMemory {
    /// Orders to send, in order.
    pub mission: Vec<Order>,
    /// Index of the next order to send.
    pub next: usize,
    /// Acknowledgements received.
    pub acks: Vec<Ack>,
}

#[derive(Clone, Debug, Default)]
pub struct FromStation {
    pub ack: In<Ack>,
}
impl Group for FromStation {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Clone, Debug, Default)]
pub struct OperatorInput {
    pub station: FromStation,
}

#[derive(Debug, Default)]
pub struct ToStation {
    pub order: Out<Order>,
}
impl Group for ToStation {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Debug, Default)]
pub struct OperatorOutput {
    pub station: ToStation,
}

impl Subsystem for Operator {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = OperatorMemory;
    type Input = OperatorInput;
    type Output = OperatorOutput;
}

/// Keep a fresh acknowledgement (the behaviour that follows `wait` does it, in the
/// activation in which the acknowledgement arrived).
fn record_ack(m: &mut OperatorMemory, x: &OperatorInput) {
    if let Some(ack) = x.station.ack.fresh() {
        m.acks.push(ack.clone());
    }
}

pub fn operator_fsm() -> Result<Fsm<Operator>, FsmBuildError> {
    Fsm::builder()
        .predicate("more", |m: &OperatorMemory, _| m.next < m.mission.len())
        .predicate("acked", |m: &OperatorMemory, x: &OperatorInput| {
            let sent = m.next.checked_sub(1).and_then(|i| m.mission.get(i));
            x.station
                .ack
                .fresh()
                .zip(sent)
                .is_some_and(|(a, o)| a.id() == o.id)
        })
        .behaviour(Behaviour::while_loop(
            "next_order",
            Action::<Operator>::new(),
            "true",
        ))
        .behaviour(Behaviour::repeat_loop(
            "send",
            Action::<Operator>::new()
                .output(
                    |y| &mut y.station,
                    |m: &OperatorMemory, _: &OperatorInput, y: &mut ToStation| {
                        if let Some(o) = m.mission.get(m.next) {
                            y.order.set(*o);
                        }
                    },
                )
                .memory(|m: &mut OperatorMemory, x: &OperatorInput| {
                    record_ack(m, x);
                    m.next += 1;
                }),
            "true",
        ))
        .behaviour(Behaviour::while_loop(
            "wait",
            Action::<Operator>::new(),
            "acked",
        ))
        .behaviour(Behaviour::repeat_loop(
            "done",
            Action::<Operator>::new().memory(record_ack),
            "true",
        ))
        .initial("next_order")
        .arc("next_order", "send", "more")
        .arc("next_order", "done", "!more")
        .arc("send", "wait", "true")
        .arc("wait", "next_order", "true")
        .final_behaviour("done")
        .build()
}

// ---------------------------------------------------------------------------
// The system

/// Handles to the interesting parts of a built system.
pub struct Plant {
    pub station: SubsystemHandle<Station>,
    pub operator: SubsystemHandle<Operator>,
    pub filter: SubsystemHandle<LevelFilter>,
    pub pump: DriverHandle<Pump>,
}

/// Everything that can go wrong while building the system.
#[derive(Debug)]
pub enum SetupError {
    Fsm(FsmBuildError),
    Period(PeriodError),
    Build(BuildError),
}

impl std::error::Error for SetupError {}

impl std::fmt::Display for SetupError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            SetupError::Fsm(e) => e.fmt(f),
            SetupError::Period(e) => e.fmt(f),
            SetupError::Build(e) => e.fmt(f),
        }
    }
}
impl From<FsmBuildError> for SetupError {
    fn from(e: FsmBuildError) -> Self {
        SetupError::Fsm(e)
    }
}
impl From<PeriodError> for SetupError {
    fn from(e: PeriodError) -> Self {
        SetupError::Period(e)
    }
}
impl From<BuildError> for SetupError {
    fn from(e: BuildError) -> Self {
        SetupError::Build(e)
    }
}

/// Build the two-agent system: the station with its devices, and the operator with
/// its mission. `seed` seeds the gauge noise.
pub fn build(
    mission: Vec<Order>,
    initial_level: f64,
    seed: u64,
) -> Result<(System, Plant), SetupError> {
    let params = TankParams::default();
    let mut sys = SystemBuilder::new();
    sys.environment(world(params, initial_level));
    let station_agent = sys.agent("station");
    let operator_agent = sys.agent("operator");

    let station = StationParts::add(&mut sys, station_agent, params, seed)?;
    let operator = sys.subsystem(
        operator_agent,
        "c2",
        Period::from_millis(100)?,
        OperatorMemory {
            mission,
            ..OperatorMemory::default()
        },
        operator_fsm()?,
    );
    connect_agents(&mut sys, &station.c1, &operator);
    station.connect(&mut sys);

    Ok((
        sys.build()?,
        Plant {
            station: station.c1,
            operator,
            filter: station.r1,
            pump: station.pump,
        },
    ))
}

/// The components of agent `station`.
struct StationParts {
    c1: SubsystemHandle<Station>,
    e1: SubsystemHandle<PumpControl>,
    r1: SubsystemHandle<LevelFilter>,
    pump: DriverHandle<Pump>,
    gauge: DriverHandle<Gauge>,
}

impl StationParts {
    /// Add the station's subsystems and drivers to `agent`.
    fn add(
        sys: &mut SystemBuilder,
        agent: AgentId,
        params: TankParams,
        seed: u64,
    ) -> Result<StationParts, SetupError> {
        let c1 = sys.subsystem(
            agent,
            "c1",
            Period::from_millis(50)?,
            StationMemory::new(StationParams::default()),
            station_fsm()?,
        );
        let e1 = sys.subsystem(
            agent,
            "e1",
            Period::from_millis(10)?,
            PumpMemory {
                duty: 0.0,
                slew: 0.2,
                max_flow: params.max_flow,
            },
            pump_control_fsm()?,
        );
        let r1 = sys.subsystem(
            agent,
            "r1",
            Period::from_millis(10)?,
            FilterMemory::default(),
            filter_fsm()?,
        );
        let pump = sys.driver(agent, "E1", Period::from_millis(1)?, Pump { rejected: 0 });
        let gauge = sys.driver(
            agent,
            "R1",
            Period::from_millis(10)?,
            Gauge {
                noise: Noise::new(seed),
            },
        );
        Ok(StationParts {
            c1,
            e1,
            r1,
            pump,
            gauge,
        })
    }

    /// Inside the station agent: data ports.
    fn connect(&self, sys: &mut SystemBuilder) {
        let StationParts {
            c1: station,
            e1: pump_control,
            r1: filter,
            pump,
            gauge,
        } = self;
        sys.connect(
            station.output(port!(StationOutput, pump.flow)),
            pump_control.input(port!(PumpControlInput, control.flow)),
            Policy::Sample,
        );
        sys.connect(
            pump_control.output(port!(PumpControlOutput, control.flow)),
            station.input(port!(StationInput, pump.flow)),
            Policy::Sample,
        );
        sys.connect(
            pump_control.output(port!(PumpControlOutput, pump.duty)),
            pump.input(port!(PumpInput, duty)),
            Policy::Sample,
        );
        sys.connect(
            pump.output(port!(PumpOutput, flow)),
            pump_control.input(port!(PumpControlInput, pump.flow)),
            Policy::Sample,
        );
        sys.connect(
            gauge.output(port!(GaugeOutput, level)),
            filter.input(port!(FilterInput, gauge.level)),
            Policy::Sample,
        );
        sys.connect(
            filter.output(port!(FilterOutput, control.level)),
            station.input(port!(StationInput, filter.level)),
            Policy::Sample,
        );
    }
}

/// Transmission buffers between the agents: lossless queues.
fn connect_agents(
    sys: &mut SystemBuilder,
    station: &SubsystemHandle<Station>,
    operator: &SubsystemHandle<Operator>,
) {
    sys.connect(
        operator.output(port!(OperatorOutput, station.order)),
        station.input(port!(StationInput, operator.order)),
        Policy::queue(4),
    );
    sys.connect(
        station.output(port!(StationOutput, operator.ack)),
        operator.input(port!(OperatorInput, station.ack)),
        Policy::queue(4),
    );
}
/// The default mission: four levels and one refused order.
pub fn default_mission() -> Vec<Order> {
    [1.2, 0.4, f64::NAN, 1.8, 0.9]
        .into_iter()
        .zip(1..)
        .map(|(level, id)| Order { id, level })
        .collect()
}
