//! The transition functions of Rex read and write what the spec says. A run of each
//! simulated deployment with the executor's audit (`ExecConfig::audit`) records, for
//! every transition function, the input buffers it read and the output buffers it
//! wrote: each must be in that function's `reads` / `writes` in `specs/rex.ron`, and
//! every input the spec says it reads, it read. Memory is not observed (a memory
//! field is a plain Rust value): the spec's memory reads and writes are checked by
//! the spec checker only (they name fields of the memory, in the function's target).

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use std::collections::{BTreeMap, BTreeSet};
use std::time::Duration;

use embodied::spec::model::{Spec, Subsystem as SpecSubsystem, Target};
use embodied::{AuditEvent, ExecConfig, Executor, Observer, SystemInfo};
use rex_agent::mission::Mission;
use rex_agent::system::{RexConfig, build_deployment, default_spec, load_spec};
use rex_agent::world::WorldConfig;

/// `(component, function)` -> (inputs read, outputs written), as `group.buffer`.
type Seen = BTreeMap<(String, String), (BTreeSet<String>, BTreeSet<String>)>;

/// Collects what the audit sees, by component and function name.
#[derive(Default)]
struct Audit {
    info: Option<SystemInfo>,
    seen: Seen,
    events: u64,
}

impl Observer for Audit {
    fn start(&mut self, system: &SystemInfo) {
        self.info = Some(system.clone());
    }

    fn audit(&mut self, e: &AuditEvent) {
        let Some(info) = &self.info else { return };
        let node = &info.nodes[e.node];
        let (Some(shape), Some(fsm)) = (&node.shape, &node.fsm) else {
            return;
        };
        let part = &fsm.behaviours[e.behaviour].parts[e.part];
        let function = part.name.as_deref().unwrap_or("<unnamed>").to_owned();
        let entry = self.seen.entry((node.name.clone(), function)).or_default();
        entry
            .0
            .extend(e.reads.names(shape.inputs).map(|(g, b)| format!("{g}.{b}")));
        entry.1.extend(
            e.writes
                .names(shape.outputs)
                .map(|(g, b)| format!("{g}.{b}")),
        );
        self.events += 1;
    }
}

fn subsystem<'s>(spec: &'s Spec, name: &str) -> &'s SpecSubsystem {
    spec.agents
        .iter()
        .flat_map(|a| &a.subsystems)
        .find(|s| s.name == name)
        .unwrap_or_else(|| panic!("no subsystem `{name}` in the spec"))
}

/// The input buffers a spec function reads, as `group.buffer` (its memory reads
/// left out), and the output buffers it writes.
fn declared(sub: &SpecSubsystem, function: &str) -> (BTreeSet<String>, BTreeSet<String>) {
    let f = sub
        .functions
        .iter()
        .find(|f| f.name == function)
        .unwrap_or_else(|| panic!("`{}` has no function `{function}` in the spec", sub.name));
    let reads = f
        .reads
        .iter()
        .filter_map(|r| match r.split_once('.') {
            Some(_) => Some(r.clone()),
            // The checker's rule: a bare name is a memory field if there is one.
            None if sub.memory.iter().any(|m| &m.name == r) => None,
            None => sub
                .inputs
                .iter()
                .find(|g| g.buffers.iter().any(|b| &b.name == r))
                .map(|g| format!("{}.{r}", g.peer)),
        })
        .collect();
    let writes = match &f.target {
        Target::Output(peer) => f.writes.iter().map(|w| format!("{peer}.{w}")).collect(),
        Target::Memory | Target::Common => BTreeSet::new(),
    };
    (reads, writes)
}

fn run(deployment: &str, seconds: u64) -> Audit {
    let mission = Mission::shipped("square").unwrap();
    let config = RexConfig::new(WorldConfig::shipped().unwrap(), mission);
    let (system, _) = build_deployment(&config, deployment).unwrap();
    let audit = ExecConfig {
        audit: true,
        ..ExecConfig::default()
    };
    let mut exec = Executor::with_observer(system, audit, Audit::default());
    exec.run_for(Duration::from_secs(seconds)).unwrap();
    exec.into_observer()
}

#[test]
fn every_function_reads_and_writes_only_what_the_spec_lists() {
    let spec = load_spec(&default_spec()).unwrap();
    let mut undeclared = Vec::new();
    let mut functions = BTreeSet::new();
    let mut observed: Seen = BTreeMap::new();
    // Without visual odometry for long enough to run plans; with it briefly, for
    // r11's functions.
    for (deployment, seconds) in [("simulation_without_vo", 40), ("simulation", 3)] {
        let audit = run(deployment, seconds);
        assert!(
            audit.events > 1000,
            "{deployment}: the audit saw too little"
        );
        for ((component, function), (reads, writes)) in &audit.seen {
            let (may_read, may_write) = declared(subsystem(&spec, component), function);
            for r in reads.difference(&may_read) {
                undeclared.push(format!("{component}::{function} reads `{r}`"));
            }
            for w in writes.difference(&may_write) {
                undeclared.push(format!("{component}::{function} writes `{w}`"));
            }
            functions.insert(format!("{component}::{function}"));
            let o = observed
                .entry((component.clone(), function.clone()))
                .or_default();
            o.0.extend(reads.iter().cloned());
            o.1.extend(writes.iter().cloned());
        }
    }
    // The other way: every input the spec says a function reads, it read in these
    // runs (so the reads of buffers are the spec's, not only within it). Writes
    // depend on events (an outcome arriving during B3), so the writes the runs did
    // not see are only listed.
    let (mut unread, mut unwritten) = (Vec::new(), Vec::new());
    for ((component, function), (reads, writes)) in &observed {
        let (may_read, may_write) = declared(subsystem(&spec, component), function);
        for r in may_read.difference(reads) {
            unread.push(format!("{component}::{function} never read `{r}`"));
        }
        for w in may_write.difference(writes) {
            unwritten.push(format!("{component}::{function} never wrote `{w}`"));
        }
    }
    eprintln!("writes listed in the spec, not seen in these runs: {unwritten:#?}");
    assert!(
        unread.is_empty(),
        "the spec lists reads the code did not do (a stale entry, or a run too short):\n  {}",
        unread.join("\n  ")
    );
    undeclared.sort();
    undeclared.dedup();
    assert!(
        undeclared.is_empty(),
        "what the code does and the spec does not list:\n  {}",
        undeclared.join("\n  ")
    );
    // The audit saw every transition function of the spec run (the square mission
    // goes through every behaviour of every subsystem).
    let all: BTreeSet<String> = spec
        .agents
        .iter()
        .flat_map(|a| &a.subsystems)
        .flat_map(|s| {
            s.functions
                .iter()
                .map(move |f| format!("{}::{}", s.name, f.name))
        })
        .collect();
    let never: Vec<&String> = all.difference(&functions).collect();
    assert!(never.is_empty(), "never ran: {never:?}");
}

#[test]
fn an_undeclared_read_is_found() {
    // The audit is not vacuous: with `c1.steps` taken out of the spec's reads of
    // e11's `ee_steps`, the run reports that the code reads it.
    let spec = load_spec(&default_spec()).unwrap();
    let mut sub = subsystem(&spec, "e11").clone();
    let f = sub
        .functions
        .iter_mut()
        .find(|f| f.name == "ee_steps")
        .unwrap();
    f.reads.retain(|r| r != "c1.steps");
    let audit = run("simulation_without_vo", 5);
    let (reads, _) = &audit.seen[&("e11".to_owned(), "ee_steps".to_owned())];
    let (may_read, _) = declared(&sub, "ee_steps");
    let undeclared: Vec<&String> = reads.difference(&may_read).collect();
    assert_eq!(undeclared, ["c1.steps"], "{reads:?} against {may_read:?}");
    // And with the spec as it is, nothing is undeclared.
    let (may_read, _) = declared(subsystem(&spec, "e11"), "ee_steps");
    assert!(reads.is_subset(&may_read), "{reads:?} against {may_read:?}");
}
