//! Tests of the FSM runtime and builder.

use super::*;
use crate::FsmProblem;
use crate::buffer::{In, Out};
use crate::kinds::{NodeKind, SubsystemKind};
use crate::transition::{Action, PartTarget};
use crate::{Group, Stamp, Time};

struct S;
#[derive(Default, Clone, Debug)]
struct X {
    go: In<bool>,
    stop: In<bool>,
}
#[derive(Default, Debug)]
struct Y {
    e: ToE,
}
#[derive(Default, Debug)]
struct ToE {
    n: Out<u32>,
}
impl Group for ToE {
    const PEER: NodeKind = NodeKind::VirtualEffector;
}
impl Subsystem for S {
    const KIND: SubsystemKind = SubsystemKind::Control;
    type Memory = u32;
    type Input = X;
    type Output = Y;
}

fn count() -> Action<S> {
    Action::<S>::new()
        .memory(|m: &mut u32, _: &X| *m += 1)
        .output(|y| &mut y.e, |m: &u32, _: &X, y: &mut ToE| y.n.set(*m))
}

fn builder() -> FsmBuilder<S> {
    Fsm::builder()
        .predicate("go", |_, x: &X| x.go.get() == Some(&true))
        .predicate("stop", |_, x: &X| x.stop.get() == Some(&true))
        .predicate("three", |m: &u32, _| *m >= 3)
}

#[test]
fn the_description_names_parts_relations_arcs_and_finals() {
    let fsm = builder()
        .exclusive(["go", "stop"])
        .implies("three", "go")
        .behaviour(Behaviour::repeat_loop(
            "run",
            count().named("tick").__at_field("e"),
            "three",
        ))
        .behaviour(Behaviour::while_loop("rest", Action::new(), "false"))
        .initial("run")
        .arc("run", "rest", "true")
        .build()
        .expect("a valid FSM");
    let d = fsm.describe();
    assert_eq!(d.predicates, ["go", "stop", "three"]);
    assert_eq!(d.relations.len(), 2);
    assert_eq!(d.relations[1].names(), ["three", "go"]);
    assert_eq!(d.initial, "run");
    assert_eq!(d.arcs, [("run".into(), "rest".into(), "true".into())]);
    assert!(d.finals.is_empty());
    let parts = &d.behaviours[0].parts;
    // `named` names the part added last (the output of `count`); the memory
    // part stays unnamed. Outputs come before the memory part, as they run.
    let names: Vec<_> = parts.iter().map(|p| p.name.as_deref()).collect();
    assert_eq!(names, [Some("tick"), None]);
    assert!(matches!(
        parts[0].target,
        PartTarget::Output {
            field: Some("e"),
            ..
        }
    ));
    assert_eq!(d.behaviours[1].kind, BehaviourKind::While);
}

#[test]
fn relations_must_name_declared_predicates() {
    let err = builder()
        .exclusive(["go", "gone"])
        .behaviour(Behaviour::while_loop("rest", Action::new(), "false"))
        .initial("rest")
        .build()
        .expect_err("unknown predicate");
    assert_eq!(
        err.problems,
        [FsmProblem::UnknownPredicate {
            place: "a relation".into(),
            name: "gone".into()
        }]
    );
    let err = Fsm::<S>::builder()
        .behaviour(Behaviour::while_loop(
            "rest",
            Action::new().named("x"),
            "false",
        ))
        .initial("rest")
        .build()
        .expect_err("named before any part");
    assert!(matches!(&err.problems[0], FsmProblem::Action { .. }));
}

fn input(go: bool, stop: bool) -> X {
    let s = Stamp::new(0, Time::ZERO);
    X {
        go: In::new_value(go, s),
        stop: In::new_value(stop, s),
    }
}

#[test]
fn while_tests_before_and_repeat_after() {
    let fsm = builder()
        .behaviour(Behaviour::while_loop("w", count(), "true"))
        .behaviour(Behaviour::repeat_loop("r", count(), "true"))
        .behaviour(Behaviour::while_loop("idle", Action::new(), "false"))
        .initial("w")
        .arc("w", "r", "true")
        .arc("r", "idle", "true")
        .build()
        .unwrap();
    let mut st = fsm.start();
    let (mut m, x, mut y) = (0u32, input(false, false), Y::default());
    let mut steps = Vec::new();
    // Activation 1: `w` ends before its first action (while-type); `r` runs once.
    let a = fsm
        .activate(&mut st, &mut m, &x, &mut y, |s| steps.push(*s))
        .unwrap();
    assert_eq!(a, Activated::Ran { behaviour: 1 });
    assert_eq!(m, 1);
    assert_eq!(
        steps,
        vec![Step::Entered {
            from: 0,
            arc: 0,
            to: 1,
            // Every predicate, though `true` needed none.
            predicates: Valuation {
                known: 0b111,
                value: 0b000
            }
        }]
    );
    // Activation 2: `r` tests after its first action, ends, `idle` runs forever.
    let a = fsm.activate(&mut st, &mut m, &x, &mut y, |_| {}).unwrap();
    assert_eq!(a, Activated::Ran { behaviour: 2 });
    assert_eq!(m, 1, "idle's action does nothing");
}

#[test]
fn ends_and_act_are_the_halves_of_activate() {
    let fsm = builder()
        .behaviour(Behaviour::while_loop("w", count(), "three"))
        .behaviour(Behaviour::repeat_loop("r", count(), "three"))
        .behaviour(Behaviour::while_loop("idle", count(), "false"))
        .initial("w")
        .arc("w", "r", "true")
        .arc("r", "idle", "true")
        .build()
        .unwrap();
    let x = input(false, false);
    assert_eq!(fsm.start_at(3), None);
    assert_eq!(fsm.start_at(0), Some(fsm.start()));
    // While-type: tested before the first action.
    let w = fsm.start_at(0).unwrap();
    assert!(fsm.ends(&w, &3, &x));
    assert!(!fsm.ends(&w, &2, &x));
    // Repeat-type: not tested before its first action, even if it would hold.
    let mut r = fsm.start_at(1).unwrap();
    assert!(!fsm.ends(&r, &3, &x));
    let mut probe = r;
    assert!(
        matches!(fsm.step(&mut probe, &3, &x), Ok(Step::Run)),
        "step agrees"
    );
    let (mut m, mut y) = (3u32, Y::default());
    assert_eq!(
        fsm.act(&mut r, &mut m, &x, &mut y).unwrap(),
        Activated::Ran { behaviour: 1 }
    );
    assert_eq!((m, y.e.n.written()), (4, Some(&3)), "the action ran once");
    assert!(
        r.actions_done() && r.behaviour() == 1,
        "act does not decide"
    );
    assert!(fsm.ends(&r, &m, &x));
    let mut probe = r;
    assert!(
        matches!(
            fsm.step(&mut probe, &m, &x),
            Ok(Step::Entered {
                from: 1,
                arc: 0,
                to: 2,
                ..
            })
        ),
        "step agrees"
    );
    // A behaviour whose terminal condition is `false` never ends.
    let mut i = fsm.start_at(2).unwrap();
    fsm.act(&mut i, &mut m, &x, &mut Y::default()).unwrap();
    assert!(!fsm.ends(&i, &m, &x));
    // Nothing runs in a halted FSM.
    i.halt();
    assert_eq!(
        fsm.act(&mut i, &mut m, &x, &mut Y::default()).unwrap(),
        Activated::Halted
    );
    assert_eq!(m, 5);
}

#[test]
fn exactly_one_arc_must_hold() {
    let fsm = builder()
        .behaviour(Behaviour::repeat_loop("a", count(), "three"))
        .behaviour(Behaviour::while_loop("b", Action::new(), "false"))
        .behaviour(Behaviour::while_loop("c", Action::new(), "false"))
        .initial("a")
        .arc("a", "b", "go")
        .arc("a", "c", "stop")
        .build()
        .unwrap();
    let mut st = fsm.start();
    let mut m = 3;
    // The first activation of a repeat behaviour does not test: it runs.
    let a = fsm
        .activate(
            &mut st,
            &mut m,
            &input(false, false),
            &mut Y::default(),
            |_| {},
        )
        .unwrap();
    assert_eq!((a, m), (Activated::Ran { behaviour: 0 }, 4));
    // Now it ends, and no arc holds.
    let err = fsm
        .activate(
            &mut st,
            &mut m,
            &input(false, false),
            &mut Y::default(),
            |_| {},
        )
        .unwrap_err();
    let FsmError::NoArcHolds {
        behaviour,
        arcs,
        assignment,
    } = err
    else {
        panic!("expected NoArcHolds, got {err:?}");
    };
    assert_eq!(behaviour, "a");
    assert_eq!(arcs, "-> b [go], -> c [stop]");
    assert_eq!(assignment, "go=false, stop=false, three=true");
    // Several arcs hold.
    let err = fsm
        .activate(
            &mut st,
            &mut m,
            &input(true, true),
            &mut Y::default(),
            |_| {},
        )
        .unwrap_err();
    let FsmError::SeveralArcsHold { count, held, .. } = err else {
        panic!("expected SeveralArcsHold, got {err:?}");
    };
    assert_eq!((count, held.as_str()), (2, "-> b [go], -> c [stop]"));
    assert_eq!(st.behaviour(), 0, "a failed decision does not move the FSM");
    // Exactly one.
    let a = fsm
        .activate(
            &mut st,
            &mut m,
            &input(false, true),
            &mut Y::default(),
            |_| {},
        )
        .unwrap();
    assert_eq!(a, Activated::Ran { behaviour: 2 });
}

#[test]
fn livelock_is_detected() {
    let fsm = builder()
        .behaviour(Behaviour::while_loop("a", Action::new(), "true"))
        .behaviour(Behaviour::while_loop("b", Action::new(), "true"))
        .initial("a")
        .arc("a", "b", "true")
        .arc("b", "a", "true")
        .build()
        .unwrap();
    let mut st = fsm.start();
    let err = fsm
        .activate(
            &mut st,
            &mut 0,
            &input(false, false),
            &mut Y::default(),
            |_| {},
        )
        .unwrap_err();
    assert!(
        matches!(err, FsmError::Livelock { transitions: 2, .. }),
        "{err:?}"
    );
}

#[test]
fn final_behaviour_halts() {
    let fsm = builder()
        .behaviour(Behaviour::repeat_loop("once", count(), "true"))
        .initial("once")
        .final_behaviour("once")
        .build()
        .unwrap();
    let mut st = fsm.start();
    let mut m = 0;
    let x = input(false, false);
    assert_eq!(
        fsm.activate(&mut st, &mut m, &x, &mut Y::default(), |_| {})
            .unwrap(),
        Activated::Ran { behaviour: 0 }
    );
    let mut steps = vec![];
    assert_eq!(
        fsm.activate(&mut st, &mut m, &x, &mut Y::default(), |s| steps.push(*s))
            .unwrap(),
        Activated::Halted
    );
    assert_eq!(steps, vec![Step::Finished]);
    assert!(st.is_halted());
    assert_eq!(m, 1);
}

#[test]
fn build_reports_every_problem() {
    let err = builder()
        .predicate("go", |_, _| true)
        .behaviour(Behaviour::while_loop("a", count(), "go && "))
        .behaviour(Behaviour::while_loop("a", count(), "false"))
        .behaviour(Behaviour::repeat_loop("lost", count(), "nope"))
        .behaviour(Behaviour::repeat_loop("dead_end", count(), "go"))
        .behaviour(Behaviour::repeat_loop(
            "twice",
            Action::<S>::new()
                .memory(|_: &mut u32, _: &X| {})
                .memory(|_: &mut u32, _: &X| {}),
            "false",
        ))
        .initial("a")
        .arc("a", "dead_end", "go")
        .arc("a", "nowhere", "stop")
        .arc("dead_end", "twice", "unknown_pred")
        .final_behaviour("ghost")
        .build()
        .unwrap_err();
    let text = err.to_string();
    for needle in [
        "behaviour `a` is defined twice",
        "predicate `go` is defined twice",
        "terminal condition of `a`",
        "uses predicate `nope`",
        "names behaviour `nowhere`",
        "uses predicate `unknown_pred`",
        "names behaviour `ghost`",
        "`lost` cannot be reached",
        "`lost` can end",
        "the memory part is set twice",
    ] {
        assert!(text.contains(needle), "missing {needle:?} in:\n{text}");
    }
    // Root causes only: `dead_end`'s arc exists (its condition is what is wrong), and
    // the second `a` is a duplicate, not an unreachable behaviour.
    for cascade in ["`dead_end` can end", "behaviour `a` cannot be reached"] {
        assert!(!text.contains(cascade), "cascade {cascade:?} in:\n{text}");
    }
}

#[test]
fn a_transition_carries_the_value_of_every_predicate() {
    let fsm = builder()
        .behaviour(Behaviour::while_loop("w", count(), "go"))
        .behaviour(Behaviour::while_loop("idle", Action::new(), "false"))
        .initial("w")
        .arc("w", "idle", "true")
        .build()
        .unwrap();
    let mut st = fsm.start();
    let (mut m, mut y) = (3u32, Y::default());
    let mut steps = Vec::new();
    fsm.activate(&mut st, &mut m, &input(true, false), &mut y, |s| {
        steps.push(*s)
    })
    .unwrap();
    let [Step::Entered { predicates, .. }] = steps[..] else {
        panic!("{steps:?}");
    };
    // go, not stop, three (m = 3).
    assert_eq!(predicates.known, 0b111);
    assert_eq!(
        (0..3).map(|i| predicates.get(i)).collect::<Vec<_>>(),
        [Some(true), Some(false), Some(true)]
    );
    assert_eq!(predicates.get(3), None);
    assert_eq!(predicates.get(64), None);
}

#[test]
fn clones_share_one_definition_and_keep_their_own_states() {
    let fsm = builder()
        .behaviour(Behaviour::repeat_loop("run", count(), "three"))
        .behaviour(Behaviour::while_loop("rest", Action::new(), "false"))
        .initial("run")
        .arc("run", "rest", "true")
        .build()
        .unwrap();
    let other = fsm.clone();
    assert!(Arc::ptr_eq(&fsm.def, &other.def), "one definition");
    // Two subsystems on the same definition: each its state and memory.
    let (mut a, mut b) = (fsm.start(), other.start());
    let (mut ma, mut mb, x) = (0u32, 0u32, input(false, false));
    let mut y = Y::default();
    for _ in 0..3 {
        fsm.activate(&mut a, &mut ma, &x, &mut y, |_| {}).unwrap();
    }
    other.activate(&mut b, &mut mb, &x, &mut y, |_| {}).unwrap();
    assert_eq!((ma, mb), (3, 1));
    assert_eq!(
        a.behaviour(),
        0,
        "run ends after its action, at the next activation"
    );
    fsm.activate(&mut a, &mut ma, &x, &mut y, |_| {}).unwrap();
    assert_eq!(
        (a.behaviour(), b.behaviour()),
        (1, 0),
        "a rests, b still runs"
    );
}

#[test]
fn a_shared_fsm_is_not_regraphed_and_says_so() {
    let fsm = builder()
        .behaviour(Behaviour::while_loop("run", count(), "false"))
        .initial("run")
        .build()
        .unwrap();
    let graph = FsmGraph {
        initial: "run".into(),
        arcs: Vec::new(),
        terminals: vec![("run".into(), "three".into())],
        finals: vec!["run".into()],
    };
    let kept = fsm.clone();
    assert!(!fsm.has_graph(&graph));
    let err = fsm.regraph(&graph).unwrap_err();
    assert_eq!(err.problems, vec![FsmProblem::Shared]);
    // Alone again, it is.
    let alone = kept.clone();
    drop(kept);
    let regraphed = alone.regraph(&graph).unwrap();
    assert!(regraphed.is_final(0));
    // A clone of an FSM that has the graph is passed through, shared: the
    // conditions compared as resolved, not as written.
    let same = FsmGraph {
        terminals: vec![("run".into(), "(three)".into())],
        ..graph.clone()
    };
    let shared = regraphed.clone();
    assert!(shared.has_graph(&same));
    let passed = shared.regraph(&same).unwrap();
    assert!(Arc::ptr_eq(&passed.def, &regraphed.def));
    let other = FsmGraph {
        finals: Vec::new(),
        ..graph.clone()
    };
    assert!(!regraphed.has_graph(&other), "not final there");
    let x = input(false, false);
    assert!(regraphed.terminal_holds(0, &3, &x) && !regraphed.terminal_holds(0, &2, &x));
}
