//! What the deterministic executor delivers through its links, against a naive
//! reference of the semantics: random multi-rate systems of subsystems linked
//! in any direction of the stepping order (a writer before its reader, after
//! it, in rings), over sample links and queues. The reference keeps each
//! link's values in a plain slot or deque and, at each instant, lets every due
//! node read before any steps and sends. Every read (new or not, the value
//! held) and every link's counters must be the same. (A one-pass executor,
//! each node reading right before the first of its writers steps, was tried
//! against this test: docs/scaling.md.) An observer that asks for some of
//! the links' and nodes' events ([`Observer::link_events`],
//! [`Observer::node_events`]) is told exactly those of an every-event
//! observer's events that its asks select.

#![allow(clippy::unwrap_used, reason = "a failing unwrap is a failing test")]

use std::collections::VecDeque;

use agent_core::trace::{
    ErasedPayload, FieldPath, LinkEvents, NodeEvents, NumberBound, SendStamps, within,
};
use agent_core::*;
use proptest::prelude::*;

struct Hub;

/// What a node saw at one activation: its iteration, the input port, whether
/// the value is new, the value held.
type Seen = (u64, usize, bool, Option<u64>);

#[derive(Clone, Debug, Default)]
struct Log {
    id: u64,
    n: u64,
    /// Output `k` is written at the iterations that are multiples of `every[k]`.
    every: [u64; 2],
    seen: Vec<Seen>,
}

#[derive(Debug, Default, Clone)]
struct FromPeers {
    a: In<u64>,
    b: In<u64>,
    c: In<u64>,
}
impl Group for FromPeers {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Debug, Default, Clone)]
struct HubIn {
    p: FromPeers,
}

#[derive(Debug, Default)]
struct ToPeers {
    x: Out<u64>,
    y: Out<u64>,
}
impl Group for ToPeers {
    const PEER: NodeKind = NodeKind::Control;
}

#[derive(Debug, Default)]
struct HubOut {
    p: ToPeers,
}

impl Subsystem for Hub {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = Log;
    type Input = HubIn;
    type Output = HubOut;
}

/// The value node `id` writes on output `k` at iteration `n`.
fn value(id: u64, n: u64, k: usize) -> u64 {
    id * 1_000_000 + n * 2 + k as u64
}

fn hub_fsm() -> Fsm<Hub> {
    Fsm::single(Behaviour::while_loop(
        "run",
        Action::<Hub>::new()
            .output(
                |y| &mut y.p,
                |m: &Log, _: &HubIn, y: &mut ToPeers| {
                    if m.n.is_multiple_of(m.every[0]) {
                        y.x.set(value(m.id, m.n, 0));
                    }
                    if m.n.is_multiple_of(m.every[1]) {
                        y.y.set(value(m.id, m.n, 1));
                    }
                },
            )
            .memory(|m: &mut Log, x: &HubIn| {
                for (k, input) in [&x.p.a, &x.p.b, &x.p.c].into_iter().enumerate() {
                    m.seen.push((m.n, k, input.is_new(), input.get().copied()));
                }
                m.n += 1;
            }),
        "false",
    ))
    .unwrap()
}

/// A link: writer, its output (0: x, 1: y), reader, its input (0..3), the
/// queue's bound (`None`: a sample link).
#[derive(Clone, Copy, Debug)]
struct Wire {
    from: usize,
    out: usize,
    to: usize,
    input: usize,
    queue: Option<usize>,
}

/// Nodes (period in ms, the outputs' `every`) and their links.
#[derive(Clone, Debug)]
struct Net {
    nodes: Vec<(u64, [u64; 2])>,
    wires: Vec<Wire>,
}

fn net() -> impl Strategy<Value = Net> {
    let node = (
        prop::sample::select(vec![1u64, 2, 3, 4, 6]),
        1u64..4,
        1u64..4,
    )
        .prop_map(|(p, a, b)| (p, [a, b]));
    prop::collection::vec(node, 2..6).prop_flat_map(|nodes| {
        let n = nodes.len();
        // For each input of each node: maybe a writer (another node), its
        // output, and a policy.
        let choice = prop::option::weighted(
            0.7,
            (0..n - 1, 0usize..2, prop::option::weighted(0.5, 1usize..4)),
        );
        (Just(nodes), prop::collection::vec(choice, n * 3..=n * 3)).prop_map(|(nodes, choices)| {
            let mut wires = Vec::new();
            for (slot, c) in choices.into_iter().enumerate() {
                let Some((w, out, bound)) = c else { continue };
                let (to, input) = (slot / 3, slot % 3);
                let from = if w >= to { w + 1 } else { w };
                // A queue only where its reader is at least as fast as
                // its writer: one value at most waits (no overflow).
                let queue = bound.filter(|_| nodes[to].0 <= nodes[from].0);
                wires.push(Wire {
                    from,
                    out,
                    to,
                    input,
                    queue,
                });
            }
            Net { nodes, wires }
        })
    })
}

fn policy(w: &Wire) -> Policy {
    w.queue
        .map_or(Policy::Sample, |bound| Policy::Queue { bound })
}

/// Per node, what it read at each activation; per link, (sent, delivered,
/// overwritten).
type Delivered = (Vec<Vec<Seen>>, Vec<(u64, u64, u64)>);

/// The system of `net`: its nodes' handles and its links.
fn build(net: &Net) -> (System, Vec<SubsystemHandle<Hub>>, Vec<LinkId>) {
    let mut b = SystemBuilder::new();
    let mut handles = Vec::new();
    for (i, &(period, every)) in net.nodes.iter().enumerate() {
        let agent = b.agent(format!("a{i}"));
        let memory = Log {
            id: i as u64 + 1,
            every,
            ..Log::default()
        };
        let period = Period::from_millis(period).unwrap();
        handles.push(b.subsystem(agent, format!("c{i}"), period, memory, hub_fsm()));
    }
    let mut links = Vec::new();
    for w in &net.wires {
        let out: Port<HubOut, Out<u64>> = match w.out {
            0 => port!(HubOut, p.x),
            _ => port!(HubOut, p.y),
        };
        let input: Port<HubIn, In<u64>> = match w.input {
            0 => port!(HubIn, p.a),
            1 => port!(HubIn, p.b),
            _ => port!(HubIn, p.c),
        };
        let link = b.connect(
            handles[w.from].output(out),
            handles[w.to].input(input),
            policy(w),
        );
        links.push(link);
    }
    (b.build().unwrap(), handles, links)
}

/// The executor's reads and the links' counters.
fn run(net: &Net, end_ms: u64) -> Delivered {
    let (system, handles, links) = build(net);
    let mut x = Executor::new(system, ExecConfig::default());
    x.run_until(Time::from_nanos(end_ms * 1_000_000)).unwrap();
    let seen = handles
        .iter()
        .map(|h| x.memory(h).unwrap().seen.clone())
        .collect();
    let stats = links
        .iter()
        .map(|&l| {
            let s = x.link_stats(l).unwrap();
            (s.sent, s.delivered, s.overwritten)
        })
        .collect();
    (seen, stats)
}

/// A link's storage in the reference.
enum Store {
    Sample { slot: Option<u64>, unread: bool },
    Queue(VecDeque<u64>),
}

/// The semantics, naively: at each instant every due node reads (in order),
/// then every due node steps and sends (in order).
fn reference(net: &Net, end_ms: u64) -> Delivered {
    let n = net.nodes.len();
    let mut store: Vec<Store> = (net.wires.iter())
        .map(|w| match w.queue {
            None => Store::Sample {
                slot: None,
                unread: false,
            },
            Some(_) => Store::Queue(VecDeque::new()),
        })
        .collect();
    let mut stats = vec![(0u64, 0u64, 0u64); net.wires.len()];
    let mut held: Vec<[Option<u64>; 3]> = vec![[None; 3]; n];
    let mut iteration = vec![0u64; n];
    let mut seen: Vec<Vec<Seen>> = vec![Vec::new(); n];
    for t in 0..end_ms {
        let due: Vec<usize> = (0..n).filter(|&i| t % net.nodes[i].0 == 0).collect();
        for &i in &due {
            let mut new = [false; 3];
            for (l, w) in net.wires.iter().enumerate().filter(|(_, w)| w.to == i) {
                let taken = match &mut store[l] {
                    Store::Sample { slot, unread } => (std::mem::replace(unread, false))
                        .then_some(*slot)
                        .flatten(),
                    Store::Queue(q) => q.pop_front(),
                };
                if let Some(v) = taken {
                    held[i][w.input] = Some(v);
                    new[w.input] = true;
                    stats[l].1 += 1;
                }
            }
            for k in 0..3 {
                seen[i].push((iteration[i], k, new[k], held[i][k]));
            }
        }
        for &i in &due {
            let (m, every) = (iteration[i], net.nodes[i].1);
            for (l, w) in net.wires.iter().enumerate().filter(|(_, w)| w.from == i) {
                if !m.is_multiple_of(every[w.out]) {
                    continue;
                }
                let v = value(i as u64 + 1, m, w.out);
                match &mut store[l] {
                    Store::Sample { slot, unread } => {
                        if *unread {
                            stats[l].2 += 1;
                        }
                        *slot = Some(v);
                        *unread = true;
                    }
                    Store::Queue(q) => q.push_back(v),
                }
                stats[l].0 += 1;
            }
            iteration[i] += 1;
        }
    }
    (seen, stats)
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(256))]

    #[test]
    fn every_read_and_link_counter_is_the_semantics(net in net()) {
        let end_ms = 48;
        let (seen, stats) = run(&net, end_ms);
        let (want_seen, want_stats) = reference(&net, end_ms);
        for (i, (got, want)) in seen.iter().zip(&want_seen).enumerate() {
            prop_assert_eq!(got, want, "node c{}'s reads", i);
        }
        prop_assert_eq!(stats, want_stats, "(sent, delivered, overwritten) per link");
    }
}

#[test]
fn a_reader_before_and_after_its_writer_in_a_ring() {
    // c0 -> c1 -> c2 -> c0, one period: each reads the value its writer sent
    // one instant before, whether the writer steps before it (c0 -> c1) or
    // after it (c2 -> c0).
    let net = Net {
        nodes: vec![(1, [1, 1]); 3],
        wires: (0..3)
            .map(|i| Wire {
                from: i,
                out: 0,
                to: (i + 1) % 3,
                input: 0,
                queue: (i == 1).then_some(1),
            })
            .collect(),
    };
    let (seen, stats) = run(&net, 5);
    assert_eq!(seen, reference(&net, 5).0);
    // c1 at iteration 3 holds c0's value of iteration 2, new.
    assert!(seen[1].contains(&(3, 0, true, Some(value(1, 2, 0)))));
    // c0 at iteration 3 holds c2's value of iteration 2 (c2 steps after c0).
    assert!(seen[0].contains(&(3, 0, true, Some(value(3, 2, 0)))));
    assert_eq!(stats, vec![(5, 4, 0); 3]);
}

/// One event an observer was told: a send (link, instant, iteration, the
/// value), a read (link, instant, the value's instant), an activation or a
/// transition (node, instant).
#[derive(Clone, Debug, PartialEq)]
enum Told {
    Transfer(usize, Time, u64, f64),
    Read(usize, Time, Time),
    Action(usize, Time),
    Transition(usize, Time),
    /// At an instant, a link whose last sends' instants the observer asked
    /// the executor to keep, and the one its table holds.
    Stamp(usize, Time, Option<Time>),
}

/// An observer that asks for `links` and `nodes` (every event where `None`)
/// and logs what it is told.
struct Asking {
    links: Option<Vec<LinkEvents>>,
    nodes: Option<Vec<NodeEvents>>,
    told: std::sync::Arc<std::sync::Mutex<Vec<Told>>>,
    /// The executor's table of the last sends' instants, once given.
    stamps: Option<SendStamps>,
}

impl Asking {
    fn log(&self, t: Told) {
        self.told.lock().unwrap().push(t);
    }
}

impl Observer for Asking {
    fn link_events(&self, link: usize) -> LinkEvents {
        (self.links.as_ref()).map_or_else(LinkEvents::all, |l| l[link].clone())
    }
    fn node_events(&self, node: usize) -> NodeEvents {
        (self.nodes.as_ref()).map_or_else(NodeEvents::all, |n| n[node])
    }
    fn transfer(&mut self, e: &TransferEvent, value: &dyn ErasedPayload) {
        let x = value.number_at(&FieldPath::parse("")).unwrap().unwrap();
        self.log(Told::Transfer(e.link, e.stamp.time, e.stamp.iteration, x));
    }
    fn read(&mut self, e: &ReadEvent) {
        self.log(Told::Read(e.link, e.time, e.stamp.time));
    }
    fn action(&mut self, e: &ActionEvent) {
        self.log(Told::Action(e.node, e.time));
    }
    fn transition(&mut self, e: &TransitionEvent) {
        self.log(Told::Transition(e.node, e.time));
    }
    fn stamps(&mut self, stamps: &SendStamps) {
        self.stamps = Some(stamps.clone());
    }
    fn instant(&mut self, time: Time) {
        let (Some(links), Some(stamps)) = (&self.links, &self.stamps) else {
            return;
        };
        for (l, w) in links.iter().enumerate() {
            if w.stamps {
                self.log(Told::Stamp(l, time, stamps.last(l)));
            }
        }
    }
}

/// What an observer asking for `links` and `nodes` is told over `end_ms`.
fn told(net: &Net, links: Option<Vec<LinkEvents>>, nodes: Option<Vec<NodeEvents>>) -> Vec<Told> {
    let told = std::sync::Arc::default();
    let observer = Asking {
        links,
        nodes,
        told: std::sync::Arc::clone(&told),
        stamps: None,
    };
    let (system, _, _) = build(net);
    let mut x = Executor::with_observer(system, ExecConfig::default(), observer);
    x.run_until(Time::from_nanos(12_000_000)).unwrap();
    drop(x);
    told.lock().unwrap().clone()
}

/// Per link: every send or none, every read or none, a bound on the values
/// sent (a send out of it told); per node: its transitions or not, its
/// activations or not.
fn asks(links: usize, nodes: usize) -> impl Strategy<Value = (Vec<LinkEvents>, Vec<NodeEvents>)> {
    let link = (
        any::<bool>(),
        any::<bool>(),
        prop::option::of(1_000_000u64..6_000_000),
        any::<bool>(),
    )
        .prop_map(|(transfers, reads, max, stamps)| LinkEvents {
            transfers,
            reads,
            stamps,
            out_of: max
                .map(|m| NumberBound {
                    path: FieldPath::parse(""),
                    min: None,
                    max: Some(m as f64),
                })
                .into_iter()
                .collect(),
            older_than: None,
        });
    let node = (any::<bool>(), any::<bool>()).prop_map(|(transitions, actions)| NodeEvents {
        transitions,
        actions: if actions { 1 } else { 0 },
    });
    (
        prop::collection::vec(link, links..=links),
        prop::collection::vec(node, nodes..=nodes),
    )
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]
    #[test]
    fn an_observer_is_told_the_events_it_asks_for_and_no_others(
        (net, (links, nodes)) in net().prop_flat_map(|net| {
            let (l, n) = (net.wires.len(), net.nodes.len());
            (Just(net), asks(l, n))
        })
    ) {
        let every = told(&net, None, None);
        // The every-event observer is told each send and each value taken.
        let (_, stats) = run(&net, 12);
        for (l, &(sent, delivered, _)) in stats.iter().enumerate() {
            let count = |f: fn(&Told) -> Option<usize>| {
                every.iter().filter(|t| f(t) == Some(l)).count() as u64
            };
            prop_assert_eq!(count(|t| match t { Told::Transfer(l, ..) => Some(*l), _ => None }), sent);
            prop_assert_eq!(count(|t| match t { Told::Read(l, ..) => Some(*l), _ => None }), delivered);
        }
        let wanted = |t: &Told| match *t {
            Told::Transfer(l, _, _, x) => links[l].transfers
                || links[l].out_of.iter().any(|b| !within(x, b.min, b.max)),
            Told::Read(l, ..) => links[l].reads,
            Told::Action(n, _) => nodes[n].action(Some(0)),
            Told::Transition(n, _) => nodes[n].transitions,
            Told::Stamp(..) => false,
        };
        let expected: Vec<Told> = every.iter().filter(|t| wanted(t)).cloned().collect();
        let (stamps, got): (Vec<Told>, Vec<Told>) = told(&net, Some(links.clone()), Some(nodes.clone()))
            .into_iter()
            .partition(|t| matches!(t, Told::Stamp(..)));
        prop_assert_eq!(got, expected);
        // At each instant, the table holds the instant of each asked link's
        // last send before it (the executor gives it when any link asks).
        let instants = every.iter().filter_map(|t| match t {
            Told::Action(_, at) => Some(*at),
            _ => None,
        });
        let mut instants: Vec<Time> = instants.collect();
        instants.dedup();
        let asked = links.iter().filter(|w| w.stamps).count();
        prop_assert_eq!(stamps.len(), instants.len() * asked);
        for t in &stamps {
            if let Told::Stamp(l, at, last) = *t {
                let sent = every.iter().filter_map(|e| match *e {
                    Told::Transfer(k, time, ..) if k == l && time < at => Some(time),
                    _ => None,
                });
                prop_assert_eq!(last, sent.max(), "link {} at {:?}", l, at);
            }
        }
    }
}
