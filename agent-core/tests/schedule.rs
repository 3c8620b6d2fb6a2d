//! The deterministic executor's schedule against a naive reference: random
//! multi-rate systems of subsystems that run on, finish, break their FSM's
//! contract or fail their action, and real drivers (receptors stepped last)
//! that fail now and then, under every error policy, some nodes started late:
//! the executor activates the same nodes at the same instants in the same
//! order as a reference that visits every node at every instant.

#![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

use std::sync::mpsc::Receiver;

use agent_core::*;
use proptest::prelude::*;

struct Node;

impl Subsystem for Node {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = u32;
    type Input = ();
    type Output = ();
}

/// What a node does at its activations.
#[derive(Clone, Copy, Debug)]
enum Sort {
    /// A subsystem that acts at every activation.
    Forever,
    /// A subsystem whose only behaviour ends after `h` actions: halted at
    /// its activation `h`.
    Finish(u32),
    /// A subsystem whose behaviour ends after `h` actions with no arc
    /// holding: a contract violation at its activation `h`.
    Violate(u32),
    /// A subsystem whose action fails at every activation.
    Fail,
    /// A real receptor whose steps `k` with `k % f == f - 1` fail.
    Receptor(u32),
    /// A real effector whose steps `k` with `k % f == f - 1` fail.
    Effector(u32),
}

fn is_driver(sort: Sort) -> bool {
    matches!(sort, Sort::Receptor(_) | Sort::Effector(_))
}

fn count() -> Action<Node> {
    Action::<Node>::new().memory(|m: &mut u32, _: &()| *m += 1)
}

fn fsm(sort: Sort) -> Fsm<Node> {
    match sort {
        Sort::Forever => Fsm::single(Behaviour::while_loop("run", count(), "false")).unwrap(),
        Sort::Finish(h) => Fsm::<Node>::builder()
            .predicate("done", move |m: &u32, _| *m >= h)
            .behaviour(Behaviour::while_loop("run", count(), "done"))
            .final_behaviour("run")
            .initial("run")
            .build()
            .unwrap(),
        Sort::Violate(h) => Fsm::<Node>::builder()
            .predicate("done", move |m: &u32, _| *m >= h)
            .predicate("never", |_: &u32, _| false)
            .behaviour(Behaviour::while_loop("run", count(), "done"))
            .behaviour(Behaviour::while_loop("other", count(), "false"))
            .arc("run", "other", "never")
            .initial("run")
            .build()
            .unwrap(),
        Sort::Fail => Fsm::single(Behaviour::while_loop(
            "run",
            Action::<Node>::new()
                .memory(|_: &mut u32, _: &()| Err::<(), _>(ActionError::failed("no"))),
            "false",
        ))
        .unwrap(),
        Sort::Receptor(_) | Sort::Effector(_) => unreachable!("a driver"),
    }
}

/// A driver failing every `every`-th step.
struct Device<const RECEPTOR: bool> {
    every: u32,
    steps: u32,
}

impl<const RECEPTOR: bool> Driver for Device<RECEPTOR> {
    const KIND: DeviceKind = if RECEPTOR {
        DeviceKind::Receptor
    } else {
        DeviceKind::Effector
    };
    type Input = ();
    type Output = ();
    fn step(&mut self, _: DriverContext<'_>, _: &(), _: &mut ()) -> Result<(), DriverError> {
        let k = self.steps;
        self.steps += 1;
        if k % self.every == self.every - 1 {
            return Err(DriverError::new("no"));
        }
        Ok(())
    }
}

/// The system of `nodes` (sort, period in ms) declared in that order, each
/// subsystem a control subsystem in an agent of its own, each driver in the
/// agent of the subsystem before it (the first node is a subsystem); the
/// receiver of every activation's (instant, node).
fn system(nodes: &[(Sort, u64)]) -> (System, Probes<Activation>, Receiver<Activation>) {
    let mut b = SystemBuilder::new();
    let (mut probes, rx) = Probes::new(1 << 20);
    let mut a = None;
    for (i, &(sort, p)) in nodes.iter().enumerate() {
        if !is_driver(sort) {
            a = Some(b.agent(format!("a{i}")));
        }
        let a = a.unwrap();
        let period = Period::from_millis(p).unwrap();
        let name = format!("n{i}");
        match sort {
            Sort::Receptor(every) => {
                let h = b.driver(a, name, period, Device::<true> { every, steps: 0 });
                probes.driver(&h, move |t, _| Some((t, i)));
            }
            Sort::Effector(every) => {
                let h = b.driver(a, name, period, Device::<false> { every, steps: 0 });
                probes.driver(&h, move |t, _| Some((t, i)));
            }
            _ => {
                let h = b.subsystem(a, name, period, 0, fsm(sort));
                probes.subsystem(&h, move |p| Some((p.time, i)));
            }
        }
    }
    (b.build().unwrap(), probes, rx)
}

/// An activation: its instant, its node (the index in the declaration).
type Activation = (Time, usize);

/// What the reference saw: every activation, the error count, the instants
/// executed, whether it stopped, and the next instant after the run.
#[derive(Debug, PartialEq, Eq)]
struct Outcome {
    trace: Vec<Activation>,
    errors: u64,
    instants: u64,
    stopped: bool,
    next: Option<Time>,
}

/// The reference: at each instant, every node visited to find those due, in
/// declaration order with the real receptors last; each node's outcome from
/// its sort and activation count; the error policy applied as documented.
fn reference(
    nodes: &[(Sort, u64)],
    on_error: OnError,
    starts: &[(usize, u64)],
    end: u64,
) -> Outcome {
    const NEVER: u64 = u64::MAX;
    let ns = |ms: u64| ms * 1_000_000;
    let mut next = vec![0; nodes.len()];
    for &(i, from) in starts {
        let p = ns(nodes[i].1);
        next[i] = ns(from).div_ceil(p) * p;
    }
    let mut visits = vec![0u32; nodes.len()];
    let receptor = |i: usize| matches!(nodes[i].0, Sort::Receptor(_));
    let order: Vec<usize> = (0..nodes.len())
        .filter(|&i| !receptor(i))
        .chain((0..nodes.len()).filter(|&i| receptor(i)))
        .collect();
    let (mut trace, mut errors, mut instants, mut safe_stopped) = (Vec::new(), 0, 0, false);
    loop {
        let t = next.iter().copied().min().unwrap_or(NEVER);
        if t == NEVER || t >= ns(end) {
            break;
        }
        for &i in &order {
            if next[i] != t {
                continue;
            }
            trace.push((Time::from_nanos(t), i));
            let k = visits[i];
            visits[i] += 1;
            let fails = |f: u32| k % f == f - 1;
            // (an error, whether the node halts)
            let (error, halts) = match nodes[i].0 {
                Sort::Forever => (false, false),
                Sort::Finish(h) => (false, k == h),
                Sort::Violate(h) => (k == h, k == h),
                Sort::Fail => (true, false),
                Sort::Receptor(f) | Sort::Effector(f) => (fails(f), false),
            };
            if error {
                errors += 1;
                if on_error == OnError::Stop {
                    // The run call returns the error before the probes see
                    // the activation.
                    trace.pop();
                    let next = next.iter().copied().min().map(Time::from_nanos);
                    return Outcome {
                        trace,
                        errors,
                        instants,
                        stopped: true,
                        next,
                    };
                }
            }
            next[i] = if halts { NEVER } else { t + ns(nodes[i].1) };
            if error && on_error == OnError::SafeStop && !safe_stopped {
                safe_stopped = true;
                for (j, (sort, _)) in nodes.iter().enumerate() {
                    if !is_driver(*sort) {
                        next[j] = NEVER;
                    }
                }
            }
        }
        instants += 1;
    }
    let next = next
        .iter()
        .copied()
        .min()
        .filter(|&t| t != NEVER)
        .map(Time::from_nanos);
    Outcome {
        trace,
        errors,
        instants,
        stopped: false,
        next,
    }
}

fn executor(
    nodes: &[(Sort, u64)],
    on_error: OnError,
    starts: &[(usize, u64)],
    end: u64,
) -> Outcome {
    let (system, probes, rx) = system(nodes);
    let ids: Vec<NodeId> = (0..nodes.len())
        .map(|i| system.node(&format!("n{i}")).unwrap())
        .collect();
    let config = ExecConfig {
        on_error,
        ..ExecConfig::default()
    };
    let mut x = Executor::new(system, config);
    x.watch(probes);
    for &(i, from) in starts {
        x.start_at(ids[i], Time::from_nanos(from * 1_000_000));
    }
    let stopped = x.run_until(Time::from_nanos(end * 1_000_000)).is_err();
    Outcome {
        trace: rx.try_iter().collect(),
        errors: x.report().error_count,
        instants: x.report().instants,
        stopped,
        next: x.next_instant(),
    }
}

fn subsystem() -> impl Strategy<Value = Sort> {
    prop_oneof![
        3 => Just(Sort::Forever),
        2 => (0..6u32).prop_map(Sort::Finish),
        1 => (0..12u32).prop_map(Sort::Violate),
        1 => Just(Sort::Fail),
    ]
}

fn sort() -> impl Strategy<Value = Sort> {
    prop_oneof![
        3 => Just(Sort::Forever),
        2 => (0..6u32).prop_map(Sort::Finish),
        1 => (0..12u32).prop_map(Sort::Violate),
        1 => Just(Sort::Fail),
        2 => (1..8u32).prop_map(Sort::Receptor),
        2 => (1..8u32).prop_map(Sort::Effector),
    ]
}

fn period() -> impl Strategy<Value = u64> {
    prop::sample::select(vec![1u64, 2, 3, 5, 10, 30])
}

fn policy() -> impl Strategy<Value = OnError> {
    prop_oneof![
        1 => Just(OnError::Stop),
        3 => Just(OnError::Continue),
        2 => Just(OnError::SafeStop),
    ]
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn the_executor_activates_what_a_naive_schedule_does(
        first in (subsystem(), period()),
        rest in prop::collection::vec((sort(), period()), 0..12),
        on_error in policy(),
        starts in prop::collection::vec((0..13usize, 0..40u64), 0..3),
        end in 1..120u64,
    ) {
        let nodes: Vec<(Sort, u64)> = std::iter::once(first).chain(rest).collect();
        let starts: Vec<(usize, u64)> =
            starts.into_iter().filter(|&(i, _)| i < nodes.len()).collect();
        let got = executor(&nodes, on_error, &starts, end);
        let want = reference(&nodes, on_error, &starts, end);
        prop_assert_eq!(got, want);
    }
}

/// The same, by hand: one fast node and slow ones, a slow one finishing, a
/// fast receptor failing, under `Continue`.
#[test]
fn one_fast_node_among_slow_ones() {
    let nodes = [
        (Sort::Forever, 10),
        (Sort::Receptor(3), 1),
        (Sort::Finish(2), 10),
        (Sort::Forever, 1),
        (Sort::Violate(1), 5),
    ];
    let got = executor(&nodes, OnError::Continue, &[], 40);
    let want = reference(&nodes, OnError::Continue, &[], 40);
    assert_eq!(got, want);
    // At 0: every node, the receptor last; the finishing one halts at 20 ms.
    let at = |ms: u64| -> Vec<usize> {
        got.trace
            .iter()
            .filter(|(t, _)| *t == Time::from_nanos(ms * 1_000_000))
            .map(|&(_, i)| i)
            .collect()
    };
    assert_eq!(at(0), [0, 2, 3, 4, 1]);
    assert_eq!(at(1), [3, 1]);
    assert_eq!(at(5), [3, 4, 1]);
    assert_eq!(at(10), [0, 2, 3, 1], "4 broke its contract at 5 ms");
    assert_eq!(at(20), [0, 2, 3, 1], "2 halts at its activation 2");
    assert_eq!(at(30), [0, 3, 1]);
    assert_eq!(got.errors, 1 + 40 / 3);
}
