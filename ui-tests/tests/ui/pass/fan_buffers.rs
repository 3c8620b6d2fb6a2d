// A fan (`Fan<G>`: one group per peer, as many as the system has) in derived
// buffer structs: described as its group, found by name as `robots[k].ack`,
// fresh when any element is, its elements checked when linked.
use embodied::*;

#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub struct FromRobot {
    pub ack: In<u64>,
}

#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub struct ToRobot {
    pub plan: Out<u64>,
}

#[derive(Debug, Default, Group)]
#[group(peer = VirtualReceptor)]
pub struct FromOp {
    pub stop: In<bool>,
}

#[derive(Debug, Default, Buffers)]
pub struct HubIn {
    pub robots: Fan<FromRobot>,
    pub op: FromOp,
}

#[derive(Debug, Default, Buffers)]
pub struct HubOut {
    pub robots: Fan<ToRobot>,
}

#[derive(Debug, Default, Memory)]
pub struct HubMemory {
    pub n: u64,
    pub acks: u64,
}

#[derive(Subsystem)]
#[subsystem(kind = Control, memory = HubMemory, input = HubIn, output = HubOut)]
pub struct Hub;

#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub struct FromHub {
    pub plan: In<u64>,
}

#[derive(Debug, Default, Group)]
#[group(peer = Control)]
pub struct ToHub {
    pub ack: Out<u64>,
}

#[derive(Debug, Default, Buffers)]
pub struct RobotIn {
    pub hub: FromHub,
}

#[derive(Debug, Default, Buffers)]
pub struct RobotOut {
    pub hub: ToHub,
}

#[derive(Debug, Default, Memory)]
pub struct RobotMemory {
    pub plans: u64,
}

#[derive(Subsystem)]
#[subsystem(kind = Control, memory = RobotMemory, input = RobotIn, output = RobotOut)]
pub struct Robot;

fn hub_fsm() -> Fsm<Hub> {
    let act = Action::<Hub>::new()
        .output(
            |y| &mut y.robots,
            |m: &HubMemory, _: &HubIn, y: &mut Fan<ToRobot>| {
                for (k, r) in y.iter_mut().enumerate() {
                    r.plan.set(1000 * k as u64 + m.n);
                }
            },
        )
        .memory(|m: &mut HubMemory, x: &HubIn| {
            m.n += 1;
            m.acks += x.robots.iter().filter(|r| r.ack.is_new()).count() as u64;
        });
    Fsm::single(Behaviour::while_loop("dispatch", act, "false")).expect("one behaviour")
}

fn robot_fsm() -> Fsm<Robot> {
    let act = Action::<Robot>::new()
        .output(
            |y| &mut y.hub,
            |_: &RobotMemory, x: &RobotIn, y: &mut ToHub| {
                if let Some(&p) = x.hub.plan.fresh() {
                    y.ack.set(p);
                }
            },
        )
        .memory(|m: &mut RobotMemory, x: &RobotIn| m.plans += u64::from(x.hub.plan.is_new()));
    Fsm::single(Behaviour::while_loop("ack", act, "false")).expect("one behaviour")
}

fn fleet(fan: usize, robots: usize) -> (SystemBuilder, SubsystemHandle<Hub>) {
    let period = Period::from_millis(10).expect("a period");
    let mut b = SystemBuilder::new();
    let a0 = b.agent("a0");
    let hub = b.subsystem_with_buffers(
        a0,
        "hub",
        period,
        HubMemory::default(),
        hub_fsm(),
        HubIn {
            robots: Fan::new(fan),
            op: FromOp::default(),
        },
        HubOut {
            robots: Fan::new(fan),
        },
    );
    for k in 0..robots {
        let agent = b.agent(format!("a{}", k + 1));
        let name = format!("robot_{k}");
        b.subsystem(
            agent,
            name.as_str(),
            period,
            RobotMemory::default(),
            robot_fsm(),
        );
        b.connect_named(
            "hub",
            &format!("robots[{k}].plan"),
            &name,
            "hub.plan",
            Policy::Sample,
        );
        b.connect_named(
            &name,
            "hub.ack",
            "hub",
            &format!("robots[{k}].ack"),
            Policy::Sample,
        );
    }
    (b, hub)
}

fn main() {
    // Described as its group, under the fan's field name.
    let groups = <HubIn as Buffers>::GROUPS;
    assert_eq!(groups.len(), 2);
    assert_eq!((groups[0].name, groups[0].ty), ("robots", "Fan<FromRobot>"));
    assert_eq!(groups[0].buffers[0].name, "ack");

    // Found by name, element by element.
    let port = <HubIn as Buffers>::port("robots[2].ack").expect("element 2's ack");
    assert_eq!(port.name(), "robots[2].ack");
    assert_eq!(port.peer(), Some(NodeKind::Control));
    assert!(<HubIn as Buffers>::port("op.stop").is_some());
    for bad in [
        "robots.ack",
        "robots[x].ack",
        "robots[02].ack",
        "robots[1].nope",
        "op[1].stop",
        "robots.[1].ack",
    ] {
        assert!(<HubIn as Buffers>::port(bad).is_none(), "{bad}");
    }

    // Fresh when any element is; the next group's bits after the fan's.
    let mut x = HubIn {
        robots: Fan::new(3),
        op: FromOp::default(),
    };
    assert_eq!(x.fresh(), Fresh(0));
    x.robots[1].ack.deliver(7, Stamp::new(0, Time::ZERO));
    assert_eq!(x.fresh(), Fresh(0b01));
    x.op.stop.deliver(true, Stamp::new(0, Time::ZERO));
    assert_eq!(x.fresh(), Fresh(0b11));

    // Linked by name: every robot acknowledges its own plans.
    let (b, hub) = fleet(3, 3);
    let mut exec = Executor::new(b.build().expect("a fleet of three"), ExecConfig::default());
    exec.run_until(Time::from_nanos(50_000_000)).expect("runs");
    let acks = exec.memory(&hub).expect("the hub").acks;
    assert!(acks >= 9, "{acks} acknowledgements");

    // A robot beyond the fan: a build problem, not a panic.
    let (b, _) = fleet(2, 3);
    let err = b.build().expect_err("no element 2");
    assert!(err.to_string().contains("no `robots[2]`"), "{err}");
}
