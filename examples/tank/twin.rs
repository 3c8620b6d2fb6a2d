//! The tank filling station again, written with the macros: buffers, memories and
//! subsystems described by derives, behaviours and FSMs in `fsm!`. It shares the
//! messages, the world and the drivers with `agent.rs`, and is meant to behave
//! exactly like it: `tests/tank_twin.rs` asserts that both give the same trace, and
//! that the spec exported from this one is `specs/tank.ron`.
//!
//! Compare `station_fsm` here with the builder chain in `agent.rs`: the FSM reads like
//! Fig. 5 of the paper, and the compiler checks it with the spec checker (a missing
//! arc or two arcs that may hold at once are compile errors).

#![allow(
    dead_code,
    unreachable_pub,
    reason = "a module shared by the example binary and the integration tests, each using part of it"
)]

use embodied::*;

use crate::agent::{
    Ack, FILTER_ALPHA, Gauge, GaugeOutput, Noise, Order, Pump, PumpInput, PumpOutput, SetupError,
    StationParams, TankParams, world,
};

// ---------------------------------------------------------------------------
// r1: the level filter

#[derive(Clone, Debug, Default, Memory)]
pub struct FilterMemory {
    pub estimate: Option<f64>,
    pub rejected: u64,
}

#[derive(Clone, Debug, Default, Group)]
#[group(peer = RealReceptor)]
pub struct FromGauge {
    pub level: In<f64>,
}

#[derive(Clone, Debug, Default, Buffers)]
pub struct FilterInput {
    pub gauge: FromGauge,
}

#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub struct LevelToControl {
    pub level: Out<f64>,
}

#[derive(Debug, Default, Buffers)]
pub struct FilterOutput {
    pub control: LevelToControl,
}

#[derive(Subsystem)]
#[subsystem(kind = VirtualReceptor, memory = FilterMemory, input = FilterInput, output = FilterOutput)]
pub struct LevelFilter;

/// `f_{r,r}`: smooth valid readings, count implausible ones.
fn smooth(m: &mut FilterMemory, x: &FilterInput) {
    let Some(&z) = x.gauge.level.fresh() else {
        return;
    };
    if !(z.is_finite() && (-0.1..=2.5).contains(&z)) {
        m.rejected += 1;
        return;
    }
    m.estimate = Some(m.estimate.map_or(z, |e| e + FILTER_ALPHA * (z - e)));
}

/// `f_{r,c}`: send the current estimate.
fn report_level(m: &FilterMemory, _: &FilterInput, y: &mut LevelToControl) {
    if let Some(e) = m.estimate {
        y.level.set(e);
    }
}

pub fn filter_fsm() -> Result<Fsm<LevelFilter>, FsmBuildError> {
    fsm! {
        subsystem LevelFilter;
        while filter until false { common <- smooth, control <- report_level }
        initial filter;
    }
}

// ---------------------------------------------------------------------------
// e1: the pump controller

#[derive(Clone, Debug, Memory)]
pub struct PumpMemory {
    pub duty: f64,
    pub slew: f64,
    pub max_flow: f64,
}

#[derive(Clone, Debug, Default, Group)]
#[group(peer = Control)]
pub struct FlowFromControl {
    pub flow: In<f64>,
}

#[derive(Clone, Debug, Default, Group)]
#[group(peer = RealEffector)]
pub struct FlowFromPump {
    pub flow: In<f64>,
}

#[derive(Clone, Debug, Default, Buffers)]
pub struct PumpControlInput {
    pub control: FlowFromControl,
    pub pump: FlowFromPump,
}

#[derive(Debug, Default, Group)]
#[group(peer = RealEffector)]
pub struct DutyToPump {
    pub duty: Out<f64>,
}

#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub struct FlowToControl {
    pub flow: Out<f64>,
}

#[derive(Debug, Default, Buffers)]
pub struct PumpControlOutput {
    pub pump: DutyToPump,
    pub control: FlowToControl,
}

#[derive(Subsystem)]
#[subsystem(kind = VirtualEffector, memory = PumpMemory, input = PumpControlInput, output = PumpControlOutput)]
pub struct PumpControl;

/// Common part: the new duty, rate-limited towards the requested flow; a missing or
/// non-finite request means "stop".
fn rate_limit(m: &mut PumpMemory, x: &PumpControlInput) {
    let wanted = x
        .control
        .flow
        .get()
        .filter(|q| q.is_finite())
        .map_or(0.0, |q| (q / m.max_flow).clamp(-1.0, 1.0));
    m.duty += (wanted - m.duty).clamp(-m.slew, m.slew);
}

fn drive(m: &PumpMemory, _: &PumpControlInput, y: &mut DutyToPump) {
    y.duty.set(m.duty);
}

fn relay_flow(_: &PumpMemory, x: &PumpControlInput, y: &mut FlowToControl) {
    if let Some(&q) = x.pump.flow.fresh() {
        y.flow.set(q);
    }
}

pub fn pump_control_fsm() -> Result<Fsm<PumpControl>, FsmBuildError> {
    fsm! {
        subsystem PumpControl;
        while drive until false { common <- rate_limit, pump <- drive, control <- relay_flow }
        initial drive;
    }
}

// ---------------------------------------------------------------------------
// c1: the station

#[derive(Clone, Debug, Memory)]
pub struct StationMemory {
    pub params: StationParams,
    pub order: Option<Order>,
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

    fn refusal(&self) -> Option<String> {
        let order = self.order?;
        crate::agent::StationMemory::new(self.params).refusal(&order)
    }

    fn level_error(&self, x: &StationInput) -> Option<f64> {
        Some((self.order?.level - *x.filter.level.get()?).abs())
    }
}

#[derive(Clone, Debug, Default, Group)]
#[group(peer = VirtualReceptor)]
pub struct LevelFromFilter {
    pub level: In<f64>,
}

#[derive(Clone, Debug, Default, Group)]
#[group(peer = VirtualEffector)]
pub struct FlowFromPumpControl {
    pub flow: In<f64>,
}

#[derive(Clone, Debug, Default, Group)]
#[group(peer = Control)]
pub struct FromOperator {
    pub order: In<Order>,
}

#[derive(Clone, Debug, Default, Buffers)]
pub struct StationInput {
    pub filter: LevelFromFilter,
    pub pump: FlowFromPumpControl,
    pub operator: FromOperator,
}

#[derive(Debug, Default, Group)]
#[group(peer = VirtualEffector)]
pub struct FlowToPumpControl {
    pub flow: Out<f64>,
}

#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub struct ToOperator {
    pub ack: Out<Ack>,
}

#[derive(Debug, Default, Buffers)]
pub struct StationOutput {
    pub pump: FlowToPumpControl,
    pub operator: ToOperator,
}

#[derive(Subsystem)]
#[subsystem(kind = Control, memory = StationMemory, input = StationInput, output = StationOutput)]
pub struct Station;

fn stop_pump(_: &StationMemory, _: &StationInput, y: &mut FlowToPumpControl) {
    y.flow.set(0.0);
}

/// `f_{c,c}` of `idle`: take a new order.
fn take_order(m: &mut StationMemory, x: &StationInput) {
    if let Some(order) = x.operator.order.fresh() {
        m.order = Some(*order);
    }
}

/// `f_{c,e}` of `fill`: proportional flow towards the target.
fn fill_flow(
    m: &StationMemory,
    x: &StationInput,
    y: &mut FlowToPumpControl,
) -> Result<(), ActionError> {
    let level = *x.filter.level.require()?;
    let target = m
        .order
        .map(|o| o.level)
        .ok_or_else(|| ActionError::failed("fill without an order"))?;
    let p = &m.params;
    y.flow
        .set((p.gain * (target - level)).clamp(-p.max_flow, p.max_flow));
    Ok(())
}

/// `f_{c,T}` of `report`: acknowledge the order.
fn acknowledge(m: &StationMemory, x: &StationInput, y: &mut ToOperator) {
    let Some(order) = m.order else { return };
    y.ack.set(match m.refusal() {
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

fn has_order(m: &StationMemory, _: &StationInput) -> bool {
    m.order.is_some()
}

fn order_valid(m: &StationMemory, _: &StationInput) -> bool {
    m.order.is_some() && m.refusal().is_none()
}

fn reached(m: &StationMemory, x: &StationInput) -> bool {
    m.level_error(x).is_some_and(|e| e <= m.params.reach)
}

fn settled(m: &StationMemory, _: &StationInput) -> bool {
    m.settled >= m.params.settle_iterations
}

fn in_tolerance(m: &StationMemory, x: &StationInput) -> bool {
    m.level_error(x).is_some_and(|e| e <= m.params.tolerance)
}

fn restart_settling(m: &mut StationMemory, _: &StationInput) {
    m.settled = 0;
}

fn count_settling(m: &mut StationMemory, _: &StationInput) {
    m.settled += 1;
}

fn forget_order(m: &mut StationMemory, _: &StationInput) {
    m.order = None;
}

/// The station's FSM (the paper's Fig. 5 for this agent).
pub fn station_fsm() -> Result<Fsm<Station>, FsmBuildError> {
    fsm! {
        subsystem Station;
        predicates { has_order, order_valid, reached, settled, in_tolerance }
        relations { order_valid => has_order }

        while idle until has_order      { pump <- stop_pump, memory <- take_order }
        repeat fill until reached       { pump <- fill_flow, memory <- restart_settling }
        while settle until settled      { pump <- stop_pump, memory <- count_settling }
        repeat report until true        { operator <- acknowledge, pump <- stop_pump, memory <- forget_order }

        initial idle;
        idle -> fill when order_valid;
        idle -> report when !order_valid;
        fill -> settle;
        settle -> report when in_tolerance;
        settle -> fill when !in_tolerance;
        report -> idle;
    }
}

// ---------------------------------------------------------------------------
// c2: the operator

#[derive(Clone, Debug, Default, Memory)]
pub struct OperatorMemory {
    pub mission: Vec<Order>,
    pub next: usize,
    pub acks: Vec<Ack>,
}

#[derive(Clone, Debug, Default, Group)]
#[group(peer = Control)]
pub struct FromStation {
    pub ack: In<Ack>,
}

#[derive(Clone, Debug, Default, Buffers)]
pub struct OperatorInput {
    pub station: FromStation,
}

#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub struct ToStation {
    pub order: Out<Order>,
}

#[derive(Debug, Default, Buffers)]
pub struct OperatorOutput {
    pub station: ToStation,
}

#[derive(Subsystem)]
#[subsystem(kind = Control, memory = OperatorMemory, input = OperatorInput, output = OperatorOutput)]
pub struct Operator;

fn record_ack(m: &mut OperatorMemory, x: &OperatorInput) {
    if let Some(ack) = x.station.ack.fresh() {
        m.acks.push(ack.clone());
    }
}

fn send_order(m: &OperatorMemory, _: &OperatorInput, y: &mut ToStation) {
    if let Some(o) = m.mission.get(m.next) {
        y.order.set(*o);
    }
}

fn advance(m: &mut OperatorMemory, x: &OperatorInput) {
    record_ack(m, x);
    m.next += 1;
}

fn more(m: &OperatorMemory, _: &OperatorInput) -> bool {
    m.next < m.mission.len()
}

fn acked(m: &OperatorMemory, x: &OperatorInput) -> bool {
    let sent = m.next.checked_sub(1).and_then(|i| m.mission.get(i));
    x.station
        .ack
        .fresh()
        .zip(sent)
        .is_some_and(|(a, o)| a.id() == o.id)
}

pub fn operator_fsm() -> Result<Fsm<Operator>, FsmBuildError> {
    fsm! {
        subsystem Operator;
        predicates { more, acked }

        while next_order until true { }
        repeat send until true      { station <- send_order, memory <- advance }
        while wait until acked      { }
        repeat done until true      { memory <- record_ack }

        initial next_order;
        next_order -> send when more;
        next_order -> done when !more;
        send -> wait;
        wait -> next_order;
        final done;
    }
}

// ---------------------------------------------------------------------------
// The system: the same components, periods and links as `agent::build`.

/// Handles to the interesting parts of a built system.
pub struct Plant {
    pub station: SubsystemHandle<Station>,
    pub operator: SubsystemHandle<Operator>,
}

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
    let ms = Period::from_millis;
    let station = sys.subsystem(
        station_agent,
        "c1",
        ms(50)?,
        StationMemory::new(StationParams::default()),
        station_fsm()?,
    );
    let pump_control = sys.subsystem(
        station_agent,
        "e1",
        ms(10)?,
        PumpMemory {
            duty: 0.0,
            slew: 0.2,
            max_flow: params.max_flow,
        },
        pump_control_fsm()?,
    );
    let filter = sys.subsystem(
        station_agent,
        "r1",
        ms(10)?,
        FilterMemory::default(),
        filter_fsm()?,
    );
    let pump = sys.driver(station_agent, "E1", ms(1)?, Pump { rejected: 0 });
    let gauge = sys.driver(
        station_agent,
        "R1",
        ms(10)?,
        Gauge {
            noise: Noise::new(seed),
        },
    );
    let operator = sys.subsystem(
        operator_agent,
        "c2",
        ms(100)?,
        OperatorMemory {
            mission,
            ..OperatorMemory::default()
        },
        operator_fsm()?,
    );
    let (sample, queue) = (Policy::Sample, Policy::queue(4));
    sys.connect(
        operator.output(port!(OperatorOutput, station.order)),
        station.input(port!(StationInput, operator.order)),
        queue,
    );
    sys.connect(
        station.output(port!(StationOutput, operator.ack)),
        operator.input(port!(OperatorInput, station.ack)),
        queue,
    );
    sys.connect(
        station.output(port!(StationOutput, pump.flow)),
        pump_control.input(port!(PumpControlInput, control.flow)),
        sample,
    );
    sys.connect(
        pump_control.output(port!(PumpControlOutput, control.flow)),
        station.input(port!(StationInput, pump.flow)),
        sample,
    );
    sys.connect(
        pump_control.output(port!(PumpControlOutput, pump.duty)),
        pump.input(port!(PumpInput, duty)),
        sample,
    );
    sys.connect(
        pump.output(port!(PumpOutput, flow)),
        pump_control.input(port!(PumpControlInput, pump.flow)),
        sample,
    );
    sys.connect(
        gauge.output(port!(GaugeOutput, level)),
        filter.input(port!(FilterInput, gauge.level)),
        sample,
    );
    sys.connect(
        filter.output(port!(FilterOutput, control.level)),
        station.input(port!(StationInput, filter.level)),
        sample,
    );
    Ok((sys.build()?, Plant { station, operator }))
}
