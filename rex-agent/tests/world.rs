//! Rex's world inside the framework: the platform E1, the stereo camera R1, the map
//! agent a3 with its motion capture, the ontology agent a2, all run by the executor
//! around stand-ins for a1's subsystems (the real ones come with the Rex agent).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::time::Duration;

use embodied::*;
use rex_agent::mission::Mission;
use rex_agent::world::camera::CameraConfig;
use rex_agent::world::devices::{MocapParams, Platform, StereoCamera};
// The stand-ins have a1's real buffers: the spec's links reach them by name.
use rex_agent::a1::c1::{C1Input as StubC1Input, C1Output as StubC1Output, C1ToC2, C1ToC3};
use rex_agent::a1::e11::{E11Input as StubE11Input, E11Output as StubE11Output, E11ToE1};
use rex_agent::a1::r11::{R11Input as StubR11Input, R11Output as StubR11Output, R11ToR1};
use rex_agent::payload::*;
use rex_agent::world::{self, WorldConfig};

// ---------------------------------------------------------------------------
// Stand-ins for a1's subsystems.

/// c1: acknowledges each plan as `Received` (not ready) in the iteration it
/// arrives, and as `Done` (ready) 20 iterations later, with the outcome `Reached`;
/// notes when the plans came and which acknowledgements it sent; keeps the map
/// poses.
#[derive(Subsystem)]
#[subsystem(kind = Control, memory = StubC1Memory, input = StubC1Input, output = StubC1Output)]
struct StubC1;
#[derive(Clone, Debug, Default, Memory)]
struct StubC1Memory {
    pending: Option<(u32, u32)>,
    /// Plan ids with their arrival time \[s\].
    plans: Vec<(f64, u32)>,
    /// Acknowledgements sent, with the time \[s\].
    acks: Vec<(f64, Ack)>,
    poses: Vec<(f64, MapPose)>,
    iteration: u64,
}

/// The acknowledgement `c1` sends in this iteration.
fn stub_c1_ack(m: &StubC1Memory, x: &StubC1Input) -> Option<Ack> {
    match (m.pending, x.c2.desired_plan.fresh()) {
        (Some((id, 0)), _) => Some(Ack {
            plan: id,
            status: AckStatus::Done,
        }),
        (_, Some(plan)) => Some(Ack {
            plan: plan.id,
            status: AckStatus::Received,
        }),
        _ => None,
    }
}
const C1_PERIOD: f64 = 0.01;

fn stub_c1() -> Fsm<StubC1> {
    Fsm::single(Behaviour::while_loop(
        "serve",
        Action::<StubC1>::new()
            .output(
                |y| &mut y.c2,
                |m: &StubC1Memory, x: &StubC1Input, y: &mut C1ToC2| {
                    if let Some(ack) = stub_c1_ack(m, x) {
                        if ack.status == AckStatus::Done {
                            y.outcome.set(PlanOutcome {
                                plan: ack.plan,
                                epoch: 0,
                                result: Execution::Reached { error_m: 0.0 },
                            });
                        }
                        y.ack.set(ack);
                    }
                },
            )
            .output(
                |y| &mut y.c3,
                |_: &StubC1Memory, _: &StubC1Input, y: &mut C1ToC3| {
                    y.q_est.set(State::default());
                },
            )
            .memory(|m: &mut StubC1Memory, x: &StubC1Input| {
                let now = m.iteration as f64 * C1_PERIOD;
                if let Some(ack) = stub_c1_ack(m, x) {
                    m.acks.push((now, ack));
                }
                m.pending = match m.pending {
                    Some((_, 0)) | None => None,
                    Some((id, n)) => Some((id, n - 1)),
                };
                if let Some(plan) = x.c2.desired_plan.fresh() {
                    m.plans.push((now, plan.id));
                    m.pending = Some((plan.id, 20));
                }
                if let Some(p) = x.c3.pose.fresh() {
                    m.poses.push((now, *p));
                }
                m.iteration += 1;
            }),
        "false",
    ))
    .unwrap()
}

/// e11: drives the wheels at 4 rad/s (left) and 8 rad/s (right) with a proportional
/// speed loop on the encoders; resets the IMU once; sends the scripted bad commands;
/// keeps the last readings.
#[derive(Subsystem)]
#[subsystem(kind = VirtualEffector, memory = StubE11Memory, input = StubE11Input, output = StubE11Output)]
struct StubE11;
#[derive(Clone, Debug, Default, Memory)]
struct StubE11Memory {
    iteration: u64,
    last: Option<(Imu, WheelLoads, Encoders)>,
    /// Bad commands to send instead, by iteration.
    faults: Vec<(u64, Fault)>,
}

/// A bad command from the stand-in `e11`.
#[derive(Clone, Copy, Debug)]
enum Fault {
    /// These torques instead of the speed loop's.
    Torques(Torques),
    /// An IMU reset to this heading.
    Reset(f64),
}

fn stub_e11() -> Fsm<StubE11> {
    Fsm::single(Behaviour::while_loop(
        "drive",
        Action::<StubE11>::new()
            .output(
                |y| &mut y.E1,
                |m: &StubE11Memory, x: &StubE11Input, y: &mut E11ToE1| {
                    let rate = x.E1.encoders.get().map_or([0.0; 4], |e| e.rate);
                    let target = [4.0, 4.0, 8.0, 8.0];
                    y.tau.set(
                        [0, 1, 2, 3].map(|i| (1.0 * (target[i] - rate[i])).clamp(-10.0, 10.0)),
                    );
                    if m.iteration == 5 {
                        y.cmd_E11.set(ImuCommand::Reset { yaw: 0.0 });
                    }
                    for &(_, fault) in m.faults.iter().filter(|f| f.0 == m.iteration) {
                        match fault {
                            Fault::Torques(tau) => y.tau.set(tau),
                            Fault::Reset(yaw) => y.cmd_E11.set(ImuCommand::Reset { yaw }),
                        }
                    }
                },
            )
            .memory(|m: &mut StubE11Memory, x: &StubE11Input| {
                if let (Some(i), Some(f), Some(e)) =
                    (x.E1.imu.get(), x.E1.forces.get(), x.E1.encoders.get())
                {
                    m.last = Some((*i, *f, *e));
                }
                m.iteration += 1;
            }),
        "false",
    ))
    .unwrap()
}

/// r11: asks for a pair every `every` iterations up to iteration `last_ask`; notes
/// what it asked and what came.
#[derive(Subsystem)]
#[subsystem(kind = VirtualReceptor, memory = StubR11Memory, input = StubR11Input, output = StubR11Output)]
struct StubR11;
#[derive(Clone, Debug, Memory)]
struct StubR11Memory {
    iteration: u64,
    every: u64,
    last_ask: u64,
    /// (iteration, seq) of each request.
    asked: Vec<(u64, u64)>,
    /// (iteration, seq, exposure time) of each fresh pair.
    got: Vec<(u64, u64, f64)>,
    images_differ: bool,
    previous: Vec<u8>,
}

impl StubR11Memory {
    fn new(every: u64, last_ask: u64) -> Self {
        StubR11Memory {
            iteration: 0,
            every,
            last_ask,
            asked: Vec::new(),
            got: Vec::new(),
            images_differ: false,
            previous: Vec::new(),
        }
    }

    fn asks(&self) -> bool {
        self.iteration.is_multiple_of(self.every) && self.iteration <= self.last_ask
    }
}

fn stub_r11() -> Fsm<StubR11> {
    Fsm::single(Behaviour::while_loop(
        "capture",
        Action::<StubR11>::new()
            .output(
                |y| &mut y.R1,
                |m: &StubR11Memory, _: &StubR11Input, y: &mut R11ToR1| {
                    if m.asks() {
                        y.cmd_R11.set(AcquireCommand {
                            seq: m.iteration / m.every,
                        });
                    }
                },
            )
            .memory(|m: &mut StubR11Memory, x: &StubR11Input| {
                if m.asks() {
                    m.asked.push((m.iteration, m.iteration / m.every));
                }
                if let Some(pair) = x.R1.img_lr.fresh() {
                    m.got.push((m.iteration, pair.seq, pair.time));
                    if !m.previous.is_empty() && m.previous != pair.left {
                        m.images_differ = true;
                    }
                    m.previous.clone_from(&pair.left);
                }
                m.iteration += 1;
            }),
        "false",
    ))
    .unwrap()
}

// ---------------------------------------------------------------------------

struct Handles {
    c1: SubsystemHandle<StubC1>,
    e11: SubsystemHandle<StubE11>,
    r11: SubsystemHandle<StubR11>,
    c2: SubsystemHandle<rex_agent::world::partners::Ontology>,
    map: world::MapAgentHandles,
    platform: DriverHandle<Platform>,
    camera: DriverHandle<StereoCamera>,
}

fn world_config() -> WorldConfig {
    WorldConfig {
        camera: CameraConfig {
            width: 160,
            height: 120,
            focal: 100.0,
            ..CameraConfig::default()
        },
        mocap: MocapParams {
            dropout_rate: 0.03,
            dropout_length: 0.2,
            ..MocapParams::default()
        },
        ..WorldConfig::shipped().unwrap()
    }
}

/// What the stand-ins do, beyond their defaults.
struct Stubs {
    /// r11's period \[ms\] and memory (what it asks for).
    r11_ms: u64,
    r11: StubR11Memory,
    /// e11's memory (its bad commands).
    e11: StubE11Memory,
    /// a2's mission.
    mission: Mission,
    /// Where the camera renders.
    render: OffloadMode,
}

impl Default for Stubs {
    fn default() -> Self {
        Stubs {
            r11_ms: 20,
            r11: StubR11Memory::new(3, u64::MAX),
            e11: StubE11Memory::default(),
            mission: Mission::shipped("square").unwrap(),
            render: OffloadMode::Worker,
        }
    }
}

/// The period of component `name` in `specs/rex.ron` \[s\].
fn spec_period(name: &str) -> f64 {
    let spec = rex_agent::system::load_spec(&rex_agent::system::default_spec()).unwrap();
    spec::Assembly::all(&spec)
        .period(name)
        .unwrap()
        .as_secs_f64()
}

fn build(config: &WorldConfig) -> (System, Handles) {
    build_with(config, Stubs::default())
}

fn build_with(config: &WorldConfig, stubs: Stubs) -> (System, Handles) {
    let spec = rex_agent::system::load_spec(&rex_agent::system::default_spec()).unwrap();
    let mut sys = spec::Assembly::new(&spec, "simulation").unwrap();
    sys.set_period("r11", Period::from_millis(stubs.r11_ms).unwrap())
        .unwrap();
    let c1 = sys
        .stand_in("c1", StubC1Memory::default(), stub_c1())
        .unwrap();
    let e11 = sys.stand_in("e11", stubs.e11, stub_e11()).unwrap();
    let r11 = sys.stand_in("r11", stubs.r11, stub_r11()).unwrap();
    world::add_environment(&mut sys);
    let platform = world::add_platform(&mut sys, config).unwrap();
    let camera = world::add_camera(&mut sys, config, stubs.render).unwrap();
    let c2 = world::add_ontology(&mut sys, stubs.mission).unwrap();
    let map = world::add_map_agent(&mut sys, config).unwrap();
    (
        sys.build().unwrap_or_else(|e| panic!("{e}")),
        Handles {
            c1,
            e11,
            r11,
            c2,
            map,
            platform,
            camera,
        },
    )
}

#[test]
fn the_world_runs_inside_the_framework() {
    let config = world_config();
    let (system, h) = build(&config);
    let mut exec = Executor::new(system, ExecConfig::default());
    let mocap_ages = run_watching_the_mocap(&mut exec, &h, Time::from_nanos(6_000_000_000));
    the_platform_moved_under_e11s_torques(&exec, &h, &config);
    images_come_only_when_asked(&exec, &h);
    poses_reach_c1_late_with_dropouts(&exec, &h, &config, &mocap_ages);
    // The ontology agent sent both plans of the square and finished.
    let ids: Vec<u32> = exec
        .memory(&h.c1)
        .unwrap()
        .plans
        .iter()
        .map(|p| p.1)
        .collect();
    assert_eq!(ids, vec![1, 2]);
    assert_eq!(exec.memory(&h.c2).unwrap().acks.len(), 2);
    assert_eq!(exec.behaviour(&h.c2), Some("done"));
    assert!(exec.is_halted(h.c2.id()));
    assert!(exec.report().errors.is_empty());
}

/// Run until `end` instant by instant, to see each pose the motion capture
/// sends when it sends it: their ages then \[s\].
fn run_watching_the_mocap(exec: &mut Executor, h: &Handles, end: Time) -> Vec<f64> {
    let mut mocap_sent = 0;
    let mut mocap_ages = Vec::new();
    while exec.next_instant().is_some_and(|t| t < end) {
        exec.step().unwrap();
        let mocap = exec.driver(&h.map.mocap).unwrap();
        if mocap.counts().0 > mocap_sent {
            mocap_sent = mocap.counts().0;
            let (sent_at, pose) = mocap.last_delivered().unwrap();
            mocap_ages.push(sent_at - pose.time);
        }
    }
    mocap_ages
}

/// The platform moved under e11's torques and its sensors reached e11; the
/// IMU obeyed the reset command.
fn the_platform_moved_under_e11s_torques(exec: &Executor, h: &Handles, config: &WorldConfig) {
    let plant = exec.driver(&h.platform).unwrap().plant();
    let s = plant.state;
    assert!(
        s.x.hypot(s.y) > 0.3 && s.phi.abs() > 0.1,
        "moved and turned: {s:?}"
    );
    let (imu, loads, enc) = exec.memory(&h.e11).unwrap().last.unwrap();
    assert!(
        imu.yaw_rate > 0.0 && imu.yaw_rate < 2.0,
        "turning left: gyro {}",
        imu.yaw_rate
    );
    assert!(
        (loads.load.iter().sum::<f64>() - config.platform.mass * config.platform.gravity).abs()
            < 20.0
    );
    assert!(
        enc.rate[2] > enc.rate[0] && enc.rate[0] > 0.0,
        "right wheels faster: {:?}",
        enc.rate
    );
    assert_eq!(
        exec.driver(&h.platform).unwrap().resets(),
        1,
        "the IMU obeyed the reset command"
    );
    // The reset aligned the integrated heading with the true one (both start at 0):
    assert!(
        (imu.yaw - s.phi).abs() < 0.05,
        "IMU heading {} vs true {}",
        imu.yaw,
        s.phi
    );
}

/// Images come only when asked, one camera step later at the earliest, every
/// request answered in order.
fn images_come_only_when_asked(exec: &Executor, h: &Handles) {
    let r = exec.memory(&h.r11).unwrap();
    assert!(r.got.len() >= 50, "{} pairs", r.got.len());
    for &(at, seq, time) in &r.got {
        let &(asked_at, _) = r.asked.iter().find(|(_, s)| *s == seq).expect("asked for");
        assert!(
            at > asked_at,
            "pair {seq} asked at ι={asked_at}, received at ι={at}"
        );
        assert!(time > asked_at as f64 * 0.02, "exposed after the command");
    }
    let seqs: Vec<u64> = r.got.iter().map(|g| g.1).collect();
    assert!(
        seqs.windows(2).all(|w| w[1] == w[0] + 1),
        "every request answered, in order"
    );
    assert!(r.images_differ, "the view changes as the platform moves");
    assert_eq!(
        exec.driver(&h.camera).unwrap().frames(),
        r.asked.len() as u64
    );
}

/// The map agent: poses reach c1 late, with dropouts, each between `latency`
/// and `latency` plus a period old when sent (`mocap_ages`); c3 keeps a1's
/// estimate.
fn poses_reach_c1_late_with_dropouts(
    exec: &Executor,
    h: &Handles,
    config: &WorldConfig,
    mocap_ages: &[f64],
) {
    let c1 = exec.memory(&h.c1).unwrap();
    assert!(c1.poses.len() > 100);
    for (arrived, p) in &c1.poses {
        assert!(
            p.time <= arrived - config.mocap.latency + 1e-9,
            "latency: {} at {arrived}",
            p.time
        );
    }
    // When the motion capture sends a pose it is between `latency` and `latency`
    // plus one of its periods (and the platform's 1 ms step) old.
    let mocap_period = spec_period("R3");
    assert!(mocap_ages.len() > 100, "{} poses", mocap_ages.len());
    for &age in mocap_ages {
        assert!(
            age >= config.mocap.latency - 1e-9
                && age <= config.mocap.latency + mocap_period + 1e-3 + 1e-9,
            "a pose {age} s old when sent (latency {} s, period {mocap_period} s)",
            config.mocap.latency
        );
    }
    let (delivered, dropped) = exec.driver(&h.map.mocap).unwrap().counts();
    assert_eq!(delivered as usize, mocap_ages.len());
    assert!(
        dropped > 0 && delivered > 100,
        "{delivered} delivered, {dropped} dropped"
    );
    assert!(
        exec.memory(&h.map.c3).unwrap().estimate.is_some(),
        "c3 keeps a1's estimate"
    );
}

#[test]
fn no_command_means_no_new_image() {
    // r11 runs four times as often as the camera and asks for a pair every 40 ms
    // until 400 ms, then stops asking; the run goes on to 1 s.
    let config = world_config();
    let (r11_ms, every, last_ask) = (5u64, 8u64, 80u64);
    let (system, h) = build_with(
        &config,
        Stubs {
            r11_ms,
            r11: StubR11Memory::new(every, last_ask),
            ..Stubs::default()
        },
    );
    let mut exec = Executor::new(system, ExecConfig::default());
    exec.run_for(Duration::from_millis(1000)).unwrap();
    let r = exec.memory(&h.r11).unwrap();
    let camera_period = spec_period("R1");
    let platform_step = spec_period("E1");
    let r11_period = r11_ms as f64 * 1e-3;
    assert_eq!(r.asked.len() as u64, last_ask / every + 1);
    assert_eq!(r.iteration, 200, "r11 kept running after it stopped asking");

    // Every request answered once, in order, and nothing else: the camera rendered
    // exactly the pairs asked for and r11 saw exactly those as new.
    let asked: Vec<u64> = r.asked.iter().map(|a| a.1).collect();
    let got: Vec<u64> = r.got.iter().map(|g| g.1).collect();
    assert_eq!(got, asked);
    assert_eq!(exec.driver(&h.camera).unwrap().frames(), asked.len() as u64);
    // After the last request only the pairs still on their way when it was made
    // arrive (the last one among them), then nothing for the remaining 0.5 s.
    let on_the_way: Vec<u64> = r
        .asked
        .iter()
        .filter(|a| !r.got.iter().any(|g| g.1 == a.1 && g.0 <= last_ask))
        .map(|a| a.1)
        .collect();
    let after: Vec<u64> = r
        .got
        .iter()
        .filter(|g| g.0 > last_ask)
        .map(|g| g.1)
        .collect();
    assert_eq!(after, on_the_way);
    assert_eq!(after.last(), Some(&(last_ask / every)));
    let last_arrival = r.got.last().unwrap().0 as f64 * r11_period;
    assert!(
        last_arrival < 0.5,
        "the last pair came soon after it was asked for, at {last_arrival} s"
    );
    assert!(!exec.input(&h.r11).unwrap().R1.img_lr.is_new());

    // A pair is exposed after it is asked for and delivered at the camera's next
    // step at the earliest: r11 (reading every 5 ms) sees it more than one camera
    // period after the exposure.
    for &(at, seq, time) in &r.got {
        let (asked_at, _) = r.asked[seq as usize];
        let (asked_t, got_t) = (asked_at as f64 * r11_period, at as f64 * r11_period);
        // The exposure shows the platform after the step of that instant.
        let exposed = time - platform_step;
        assert!(
            exposed > asked_t - 1e-9,
            "pair {seq} exposed at {exposed} s, asked for at {asked_t} s"
        );
        assert!(
            got_t > exposed + camera_period + 1e-9,
            "pair {seq} exposed at {exposed} s, received at {got_t} s: not a camera period later"
        );
        assert!(
            got_t <= asked_t + 3.0 * camera_period + 1e-9,
            "pair {seq} asked for at {asked_t} s came late, at {got_t} s"
        );
    }
}

#[test]
fn a_bad_command_is_counted_once_and_a_bad_reset_is_rejected() {
    // e11 (50 ms) sends one NaN torque command at 0.5 s, a NaN IMU reset at 0.75 s
    // and one out-of-bounds command at 1 s; the platform steps at 1 ms, so each bad
    // torque command is in force for 50 plant steps.
    let config = world_config();
    let (system, h) = build_with(
        &config,
        Stubs {
            e11: StubE11Memory {
                faults: vec![
                    (10, Fault::Torques([f64::NAN, 1.0, 1.0, 1.0])),
                    (15, Fault::Reset(f64::NAN)),
                    (20, Fault::Torques([40.0, 0.0, 0.0, -40.0])),
                ],
                ..StubE11Memory::default()
            },
            ..Stubs::default()
        },
    );
    let mut exec = Executor::new(system, ExecConfig::default());
    exec.run_for(Duration::from_millis(540)).unwrap();
    let p = exec.driver(&h.platform).unwrap();
    assert_eq!(p.command_stats().not_finite, 1);
    let (tau, at) = p.command().unwrap();
    assert_eq!(tau, [0.0, 1.0, 1.0, 1.0], "the NaN torque is zero");
    assert!((0.5..0.502).contains(&at), "arrived at {at}");

    exec.run_for(Duration::from_millis(500)).unwrap();
    let p = exec.driver(&h.platform).unwrap();
    assert_eq!(p.command_stats().out_of_bounds, 1);
    let (tau, at) = p.command().unwrap();
    assert_eq!(tau, [10.0, 0.0, 0.0, -10.0], "clamped to the torque bound");
    assert!((1.0..1.002).contains(&at), "arrived at {at}");

    exec.run_for(Duration::from_millis(1000)).unwrap();
    let p = exec.driver(&h.platform).unwrap();
    assert_eq!(
        p.command_stats(),
        rex_agent::model::CommandStats {
            not_finite: 1,
            out_of_bounds: 1
        },
        "one count per bad command, however many steps it was in force"
    );
    assert_eq!(p.rejected_resets(), 1, "the NaN reset");
    assert_eq!(p.resets(), 1, "the good reset at iteration 5");
    assert!(p.plant().state.x.is_finite() && p.plant().state.omega.is_finite());
    assert_eq!(p.plant().integration_stats().singular, 0);
    assert!(exec.report().errors.is_empty());
}

#[test]
fn the_ontology_sends_the_next_plan_only_after_the_final_ack() {
    // Four plans; c1 answers each with `Received` (not ready) at once and `Done`
    // (ready) 200 ms later, two of c2's periods: a2 must wait for `Done`.
    let config = world_config();
    let point = |x: f64, y: f64| Point2 { x, y };
    let mission = Mission {
        name: "four".into(),
        plans: (0..4)
            .map(|k| vec![point(f64::from(k), 0.0), point(f64::from(k), 1.0)])
            .collect(),
    };
    let (system, h) = build_with(
        &config,
        Stubs {
            mission,
            ..Stubs::default()
        },
    );
    let mut exec = Executor::new(system, ExecConfig::default());
    exec.run_for(Duration::from_secs(4)).unwrap();
    let c1 = exec.memory(&h.c1).unwrap();
    let ids: Vec<u32> = c1.plans.iter().map(|p| p.1).collect();
    assert_eq!(ids, vec![1, 2, 3, 4], "every plan once, in order");
    let sent = |plan: u32, ready: bool| {
        c1.acks
            .iter()
            .find(|(_, a)| a.plan == plan && a.ready() == ready)
            .map(|(t, _)| *t)
    };
    for pair in c1.plans.windows(2) {
        let ((_, k), (next_at, next)) = (pair[0], pair[1]);
        let (received, done) = (sent(k, false), sent(k, true));
        assert!(
            done.is_some_and(|done| next_at > done),
            "plan {next} reached c1 at {next_at} s, before the final ack of plan {k} \
             (sent at {done:?} s; `Received` at {received:?} s)"
        );
        let (received, done) = (received.unwrap(), done.unwrap());
        assert!(
            done - received > 2.0 * spec_period("c2") - 1e-9,
            "c2 had time to (wrongly) act on `Received`"
        );
    }
    // c2 kept the final acks only, and finished.
    let c2 = exec.memory(&h.c2).unwrap();
    let kept: Vec<(u32, bool)> = c2.acks.iter().map(|a| (a.plan, a.ready())).collect();
    assert_eq!(kept, vec![(1, true), (2, true), (3, true), (4, true)]);
    assert_eq!(exec.behaviour(&h.c2), Some("done"));
}

#[test]
fn the_world_is_deterministic() {
    // With a noisy camera that blurs by the motion: the noise is seeded by the
    // frame, not by the thread or the time it renders at.
    let mut config = world_config();
    config.camera.sensor = rex_agent::world::camera::SensorConfig::realistic(3);
    let run = |render| {
        let (system, _) = build_with(
            &config,
            Stubs {
                render,
                ..Stubs::default()
            },
        );
        let mut exec = Executor::with_observer(system, ExecConfig::default(), Recorder::new());
        exec.run_for(Duration::from_millis(1500)).unwrap();
        exec.into_observer().into_trace()
    };
    let (a, b) = (run(OffloadMode::Worker), run(OffloadMode::Worker));
    assert!(a.events.len() > 5_000, "{} events", a.events.len());
    assert_eq!(a.first_difference(&b), None);
    // Rendering on a worker thread or in the camera's step: the same pairs at the
    // same instants.
    assert_eq!(a.first_difference(&run(OffloadMode::Inline)), None);
}

#[test]
fn the_camera_writes_what_it_renders_as_a_kitti_sequence() {
    use rex_agent::world::camera::kitti::SequenceWriter;
    use rex_bench::kitti::Sequence;
    let dir = std::env::temp_dir().join(format!("rex-kitti-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    let config = world_config();
    let (system, h) = build(&config);
    let mut exec = Executor::new(system, ExecConfig::default());
    exec.driver_mut(&h.camera)
        .unwrap()
        .record_to(SequenceWriter::create(&dir, &config.camera).unwrap());
    exec.run_for(Duration::from_millis(600)).unwrap();
    let frames = exec.driver(&h.camera).unwrap().frames() as usize;
    let writer = exec.driver_mut(&h.camera).unwrap().take_recorder().unwrap();
    assert_eq!(writer.finish().unwrap(), frames);

    let seq = Sequence::open(&dir).unwrap();
    assert_eq!(seq.len(), frames);
    assert!((seq.focal - config.camera.focal).abs() < 1e-9);
    assert!((seq.baseline - config.camera.baseline).abs() < 1e-9);
    let poses = seq.poses.as_ref().unwrap();
    assert!(
        (poses[0][0][0] - 1.0).abs() < 1e-12 && poses[0][2][3].abs() < 1e-12,
        "first pose is the identity"
    );
    // The camera moves forward (+z in KITTI's camera frame) as the platform drives.
    let last = poses.last().unwrap();
    assert!(last[2][3] > 0.05, "forward motion {:?}", last);
    let (w, h2, left, right) = seq.frame(frames - 1).unwrap();
    assert_eq!((w, h2), (config.camera.width, config.camera.height));
    assert_ne!(left, right);

    // A damaged folder: errors name the file.
    std::fs::remove_file(dir.join("image_1").join("000001.png")).unwrap();
    let err = Sequence::open(&dir).unwrap_err().to_string();
    assert!(
        err.contains("image_1/000001.png") && err.contains("missing"),
        "{err}"
    );
    std::fs::write(dir.join("calib.txt"), "P0: 1 2 3\n").unwrap();
    let err = Sequence::open(&dir).unwrap_err().to_string();
    assert!(err.contains("calib.txt") && err.contains("P0"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}
