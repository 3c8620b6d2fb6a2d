//! The timing analysis against textbook task sets and hand-computed systems,
//! seeded defects found where they are, and the contracts' checks.

#![allow(
    clippy::unwrap_used,
    clippy::expect_used,
    reason = "a failing unwrap is a failing test"
)]

use agent_spec::timing::{
    Analysis, analyse, liu_layland, queue_needs, response_time, response_time_with_jitter,
};
use agent_spec::{Code, Report, load};
use proptest::prelude::*;

const MS: u64 = 1_000_000;

/// A chain R1 -> r1 -> c1 -> e1 -> E1 in one agent; `{r1}`: r1's period,
/// `{policy}`: the policy of `c1.e1.x`, `{e1}`: e1's period, `{contracts}`:
/// more contract entries.
fn system(r1: f64, policy: &str, e1: f64, chain_extra: &str, contracts: &str) -> String {
    let sub = |name: &str, kind: &str, period: f64, ins: &str, outs: &str| {
        format!(
            "(name: \"{name}\", kind: {kind}, period_ms: {period:?}, inputs: [{ins}], outputs: [{outs}],
              behaviours: [(name: \"run\", kind: While, terminal: \"false\")], fsm: (initial: \"run\")),"
        )
    };
    let g = |peer: &str, ty: &str| {
        format!("(peer: \"{peer}\", buffers: [(name: \"x\", type: \"{ty}\")])")
    };
    format!(
        "(
    name: \"chainy\",
    agents: [(
        name: \"a1\",
        subsystems: [
            {r1s}
            {c1s}
            {e1s}
        ],
        devices: [
            (name: \"R1\", kind: Receptor, period_ms: 10.0, outputs: [{R1o}]),
            (name: \"E1\", kind: Effector, period_ms: 1.0, inputs: [{E1i}]),
        ],
    )],
    links: [
        (from: \"R1.r1.x\", to: \"r1.R1.x\"),
        (from: \"r1.c1.x\", to: \"c1.r1.x\"),
        (from: \"c1.e1.x\", to: \"e1.c1.x\", policy: {policy}),
        (from: \"e1.E1.x\", to: \"E1.e1.x\"),
    ],
    deployments: [
        (name: \"two\", hosts: [
            (name: \"pc\", processes: [(name: \"sense\", runs: [\"R1\", \"r1\"]), (name: \"act\", runs: [\"c1\", \"e1\", \"E1\"])]),
        ]),
        (name: \"apart\", hosts: [
            (name: \"pc1\", processes: [(name: \"sense\", runs: [\"R1\", \"r1\"])]),
            (name: \"pc2\", processes: [(name: \"act\", runs: [\"c1\", \"e1\", \"E1\"])]),
        ]),
    ],
    contracts: (
        chains: [(name: \"sense_to_act\", path: [\"R1.r1.x\", \"r1.c1.x\", \"c1.e1.x\", \"e1.E1.x\"], max_age_ms: 60.0, max_reaction_ms: 60.0{chain_extra})],
        {contracts}
    ),
    timing: (
        wcet: [
            (component: \"R1\", ms: 1.0), (component: \"r1\", ms: 1.0), (component: \"c1\", ms: 1.0),
            (component: \"e1\", ms: 1.0), (component: \"E1\", ms: 0.1),
        ],
        latency: [(deployment: \"two\", ms: 2.0), (deployment: \"apart\", ms: 2.0)],
    ),
)",
        r1s = sub("r1", "VirtualReceptor", r1, &g("R1", "f64"), &g("c1", "[f64; 2]")),
        c1s = sub("c1", "Control", 10.0, &g("r1", "[f64; 2]"), &g("e1", "f64")),
        e1s = sub("e1", "VirtualEffector", e1, &format!("{}, {}", g("c1", "f64"), g("E1", "f64")).replacen("(peer: \"E1\", buffers: [(name: \"x\", type: \"f64\")])", "(peer: \"E1\", buffers: [(name: \"y\", type: \"f64\")])", 1), &g("E1", "f64")),
        R1o = g("r1", "f64"),
        E1i = g("e1", "f64"),
    )
    .replace("(from: \"e1.E1.x\", to: \"E1.e1.x\"),", "(from: \"e1.E1.x\", to: \"E1.e1.x\"),\n        (from: \"E1.e1.y\", to: \"e1.E1.y\"),")
    .replace(
        "(name: \"E1\", kind: Effector, period_ms: 1.0, inputs: [",
        "(name: \"E1\", kind: Effector, period_ms: 1.0, outputs: [(peer: \"e1\", buffers: [(name: \"y\", type: \"f64\")])], inputs: [",
    )
}

/// Check `text`; the report, and the analysis of `deployment`.
fn run(text: &str, deployment: Option<&str>) -> (Report, Analysis) {
    let loaded = load("t.ron", text).unwrap_or_else(|r| panic!("{}", r.render(100)));
    let report = agent_spec::check(&loaded);
    let analysis = analyse(&loaded.spec, loaded.index.as_ref(), deployment).expect("analysable");
    (report, analysis)
}

fn under(report: &Report, code: Code) -> Vec<&str> {
    report
        .findings
        .iter()
        .filter(|f| f.code == code)
        .map(|f| &report.source[f.labels[0].span.clone()])
        .collect()
}

fn errors(report: &Report) -> Vec<Code> {
    report
        .findings
        .iter()
        .filter(|f| f.severity() == agent_spec::Severity::Error)
        .map(|f| f.code)
        .collect()
}

#[test]
fn response_times_of_a_textbook_task_set() {
    // Burns & Wellings, "Real-Time Systems and Programming Languages" (4th ed.,
    // §11.5): a (T 7, C 3), b (T 12, C 3), c (T 20, C 5): R = 3, 6, 20; U = 0.929
    // passes no Liu & Layland test (0.780 for 3 tasks), yet every task is schedulable.
    assert_eq!(response_time(3, &[], 7), Some(3));
    assert_eq!(response_time(3, &[(7, 3)], 12), Some(6));
    assert_eq!(response_time(5, &[(7, 3), (12, 3)], 20), Some(20));
    let u = 3.0 / 7.0 + 3.0 / 12.0 + 5.0 / 20.0;
    assert!(u > liu_layland(3));
    // T 4 C 2 above T 6 C 3: R = 3, 5, 7 > 6: not schedulable.
    assert_eq!(response_time(3, &[(4, 2)], 6), None);
}

#[test]
fn release_jitter_delays_a_thread_and_crowds_its_interferers() {
    // Own J counts from the release: R = J + w.
    assert_eq!(response_time_with_jitter(2, 1, &[(10, 3, 0)], 20), Some(6));
    // An interferer released up to 8 late can put two of its jobs in the
    // window: w = 2 + ⌈(w + 8)/10⌉·3 = 8, R = 9 (5 without the jitters).
    assert_eq!(response_time_with_jitter(2, 1, &[(10, 3, 8)], 20), Some(9));
    assert_eq!(response_time(2, &[(10, 3)], 20), Some(5));
    // Every jitter 0: the plain recurrence.
    assert_eq!(
        response_time_with_jitter(5, 0, &[(7, 3, 0), (12, 3, 0)], 20),
        response_time(5, &[(7, 3), (12, 3)], 20)
    );
    // The jitter itself can break the deadline: J 16 + w 5 > 20.
    assert_eq!(response_time_with_jitter(2, 16, &[(10, 3, 0)], 20), None);
    assert_eq!(response_time_with_jitter(2, 25, &[], 20), None);
}

#[test]
fn a_declared_release_jitter_enters_the_certificate() {
    let with = system(20.0, "Sample", 5.0, "", "").replace(
        "latency: [(deployment:",
        "release_jitter: [(component: \"E1\", ms: 0.3), (component: \"c1\", ms: 0.5)],\n        latency: [(deployment:",
    );
    let (report, a) = run(&with, None);
    assert!(report.is_ok(), "{}", report.render(100));
    let r = |c: &str| a.threads.iter().find(|t| t.component == c).unwrap();
    // E1 (T 1, C 0.1, J 0.3): R = 0.3 + 0.1.
    assert_eq!(r("E1").response, Some(4 * MS / 10));
    // e1 (C 1): w = 1 + ⌈(w + 0.3)/1⌉·0.1 = 1.2 (⌈1.5⌉ = 2 jobs of E1), no own J.
    assert_eq!(r("e1").response, Some(12 * MS / 10));
    // c1 (C 1, J 0.5), with R1 at its priority: w = 1 + 4·0.1 + 1 (e1) + 1 (R1)
    // = 3.4 as before (⌈(3.4 + 0.3)/1⌉ = 4 jobs of E1), R = 0.5 + 3.4.
    assert_eq!(r("c1").response, Some(39 * MS / 10));
    assert!(a.to_string().contains("J =      0.5 ms"), "{a}");
    // A jitter that eats the period: E1 unschedulable, named with its J.
    let late = with.replace(
        "(component: \"E1\", ms: 0.3)",
        "(component: \"E1\", ms: 0.95)",
    );
    let (report, _) = run(&late, None);
    let f = report
        .findings
        .iter()
        .find(|f| f.code == Code::Unschedulable)
        .unwrap_or_else(|| panic!("{}", report.render(100)));
    assert!(
        f.labels[0].text.contains("J = 0.95 ms"),
        "{}",
        f.labels[0].text
    );
}

#[test]
fn a_release_jitter_of_an_unknown_component_or_negative_is_refused() {
    let bad = system(20.0, "Sample", 5.0, "", "").replace(
        "latency: [(deployment:",
        "release_jitter: [(component: \"c11\", ms: 0.3), (component: \"e1\", ms: -1.0), (component: \"e1\", ms: 0.0)],\n        latency: [(deployment:",
    );
    let loaded = load("t.ron", bad).unwrap_or_else(|r| panic!("{}", r.render(100)));
    let report = agent_spec::check(&loaded);
    let text = report.render(100);
    assert!(text.contains("did you mean `c1`"), "{text}");
    assert!(
        text.contains("release jitter -1 ms is not a finite number of at least 0"),
        "{text}"
    );
    assert!(
        text.contains("the release jitter of `e1` is given twice"),
        "{text}"
    );
}

#[test]
fn queue_needs_follows_its_formula() {
    // ⌈(T_r + S_r + 2 (E_w + L)) / I⌉
    assert_eq!(queue_needs(10, 0, 0, 0, 10), Some(1));
    assert_eq!(queue_needs(10, 1, 0, 0, 10), Some(2));
    assert_eq!(queue_needs(10, 4, 2, 0, 10), Some(2));
    assert_eq!(queue_needs(50, 4, 2, 1, 55), Some(2));
    assert_eq!(queue_needs(50, 0, 0, 0, 100), Some(1));
    // A writer faster than its reader fills any queue.
    assert_eq!(queue_needs(50, 0, 0, 0, 10), None);
}

#[test]
fn a_sound_system_gets_a_certificate_with_hand_computed_figures() {
    let (report, a) = run(&system(20.0, "Sample", 5.0, "", ""), None);
    assert!(report.is_ok(), "{}", report.render(100));
    assert!(a.is_certified(), "{:?}", a.findings);
    // One host; priorities E1 80, e1 79, R1 and c1 78, r1 77.
    let r = |c: &str| a.threads.iter().find(|t| t.component == c).unwrap();
    assert_eq!(
        (
            r("E1").priority,
            r("e1").priority,
            r("c1").priority,
            r("R1").priority,
            r("r1").priority
        ),
        (80, 79, 78, 78, 77)
    );
    // R_E1 = 0.1; R_e1 = 1 + 2·0.1; R_R1 = R_c1 = 1 + 4·0.1 + 1 + 1; R_r1 = 1 + 5·0.1 + 3.
    assert_eq!(r("E1").response, Some(MS / 10));
    assert_eq!(r("e1").response, Some(12 * MS / 10));
    assert_eq!(r("c1").response, Some(34 * MS / 10));
    assert_eq!(r("R1").response, Some(34 * MS / 10));
    assert_eq!(r("r1").response, Some(45 * MS / 10));
    let c = &a.chains[0];
    // Data age: (10 + 3.4) + (20 + 4.5) + (10 + 3.4) + (5 + 1.2) + R_E1 0.1 = 57.6.
    assert_eq!(c.age, 576 * MS / 10);
    // Reaction: T_R1 10 + (3.4 + 20) + (4.5 + 10) + (3.4 + 5) + (1.2 + 1) + 0.1 = 58.6.
    assert_eq!(c.reaction, 586 * MS / 10);
    let text = a.to_string();
    assert!(
        text.contains("certified") && text.contains("chain `sense_to_act`"),
        "{text}"
    );
}

#[test]
fn a_queue_hop_adds_the_writers_end_spread_and_its_queue_is_sized() {
    let (report, a) = run(&system(20.0, "Queue(2)", 5.0, "", ""), None);
    let hop = &a.chains[0].hops[2];
    // 2 R_c1 (its ends spread over R_c1 3.4) + T_e1 5 = 11.8, both for age
    // and reaction.
    assert_eq!((hop.age, hop.reaction), (118 * MS / 10, 118 * MS / 10));
    // ⌈(T_r 5 + S_r 0.2 + 2 E_w 6.8) / I 10⌉ = 2: Queue(2) suffices, exactly.
    assert_eq!(a.queues[0].needs, Some(2));
    // Age 13.4 + 24.5 + 11.8 + 6.2 + 0.1 = 56 holds; the reaction time
    // 10 + 23.4 + 14.5 + 11.8 + 2.2 + 0.1 = 62 passes 60, at the queue's hop.
    assert_eq!((a.chains[0].age, a.chains[0].reaction), (56 * MS, 62 * MS));
    let f: Vec<_> = report
        .findings
        .iter()
        .filter(|f| f.code == Code::ChainDeadline)
        .collect();
    assert_eq!(f.len(), 1, "{}", report.render(100));
    assert!(
        f[0].message.contains("reaction time 62 ms passes 60 ms"),
        "{}",
        f[0].message
    );
    // The largest term: R_R1 3.4 + T_r1 20 at the first hop.
    assert_eq!(&report.source[f[0].labels[1].span.clone()], "R1.r1.x");
}

#[test]
fn seeded_defect_a_longer_period_breaks_the_chain_at_its_hop() {
    // r1 at 40 ms instead of 20: the age grows by 20 ms to 77.6 > 60.
    let (report, a) = run(&system(40.0, "Sample", 5.0, "", ""), None);
    assert_eq!(a.chains[0].age, 776 * MS / 10);
    assert_eq!(
        errors(&report),
        vec![Code::ChainDeadline, Code::ChainDeadline],
        "{}",
        report.render(100)
    );
    // Pointed at the deadline, with the hop of the largest term as second label.
    assert_eq!(under(&report, Code::ChainDeadline), ["60.0", "60.0"]);
    let f = &report.findings[0];
    assert!(f.message.contains("chain `sense_to_act`"), "{}", f.message);
    assert_eq!(&report.source[f.labels[1].span.clone()], "r1.c1.x");
    assert!(
        f.labels[1].text.contains("T_w 40") || f.labels[1].text.contains("M 40"),
        "{}",
        f.labels[1].text
    );
}

#[test]
fn seeded_defect_a_queue_too_small_is_named_at_its_policy() {
    // e1 at 10 ms: J_e1 and J_c1 no longer fit one window: Queue(1) needs 2.
    let (report, a) = run(&system(20.0, "Queue(1)", 10.0, "", ""), None);
    assert_eq!(a.queues[0].needs, Some(2));
    assert_eq!(
        under(&report, Code::QueueOverflow),
        ["Queue(1)"],
        "{}",
        report.render(100)
    );
    // And a reader slower than its writer: no bound holds.
    let (report, a) = run(&system(20.0, "Queue(8)", 20.0, "", ""), None);
    assert_eq!(a.queues[0].needs, None);
    assert!(
        report
            .findings
            .iter()
            .any(|f| f.code == Code::QueueOverflow && f.message.contains("faster than its reader")),
        "{}",
        report.render(100)
    );
}

#[test]
fn a_deployment_adds_its_latency_between_processes() {
    let (_, one) = run(&system(20.0, "Sample", 5.0, "", ""), None);
    let (_, apart) = run(&system(20.0, "Sample", 5.0, "", ""), Some("apart"));
    assert!(apart.is_certified(), "{apart}{:?}", apart.findings);
    // Only r1 -> c1 crosses processes (sense -> act): + L 2 ms on that hop.
    let hops: Vec<u64> = apart.chains[0].hops.iter().map(|h| h.latency).collect();
    assert_eq!(hops, [0, 2 * MS, 0, 0]);
    let c = &apart.chains[0];
    assert_eq!(
        c.age,
        c.hops.iter().map(|h| h.age).sum::<u64>() + c.last_response
    );
    assert!(apart.to_string().contains("latency 2 ms"));
    // Each host has fewer threads: shorter responses, and the hop's 2 ms on top.
    let r = |c: &str| {
        apart
            .threads
            .iter()
            .find(|t| t.component == c)
            .unwrap()
            .response
    };
    assert_eq!(r("r1"), Some(2 * MS)); // 1 + R1's 1 (priority 80 in `sense`)
    assert!(one.chains[0].age > 0);
}

#[test]
fn processes_on_one_host_are_ranked_together_and_interfere() {
    // `two`: sense and act on one host. Every process ranks its threads among
    // the whole system's periods, as the executor does: E1 (1 ms, in `act`)
    // takes 80 and R1 (10 ms, in `sense`) a lower priority, so E1 meets its
    // period, and R1 suffers E1's interference across the processes.
    let (report, two) = run(&system(20.0, "Sample", 5.0, "", ""), Some("two"));
    assert!(report.is_ok());
    let thread = |c: &str| two.threads.iter().find(|t| t.component == c).unwrap();
    let (e1, r1) = (thread("E1"), thread("R1"));
    assert_ne!(e1.process, r1.process);
    assert_eq!((e1.priority, e1.response), (80, Some(e1.wcet)));
    assert!(r1.priority < e1.priority, "{two}");
    assert!(
        r1.response.is_some_and(|r| r > r1.wcet),
        "R1 waits for E1 of the other process: {two}"
    );
    assert!(
        two.findings.iter().all(|f| f.code != Code::Unschedulable),
        "{two}"
    );
}

#[test]
fn contracts_name_what_exists_with_did_you_mean() {
    let contracts = r#"
        freshness: [(input: "e1.c1.xx", max_age_ms: 5.0), (input: "e1.c1.x", max_age_ms: -1.0)],
        bounds: [(behaviour: "c1.runn", max_s: 1.0), (behaviour: "c9.run", max_iterations: 3)],
        invariants: [(name: "i", subsystem: "c1", holds: "ready && !done")],
        ranges: [
            (name: "ok", buffer: "r1.c1.x", field: "1", min: -1.0, max: 1.0),
            (name: "out", buffer: "r1.c1.x", field: "2", max: 1.0),
            (name: "ok", buffer: "e1.E1.x", min: 2.0, max: 1.0),
        ],
        responses: [(name: "r", trigger: "c1.e1.x", response: "e1.c1.x", within_s: 0.0)],
    "#;
    let (report, _) = run(&system(20.0, "Sample", 5.0, "", contracts), None);
    assert_eq!(
        under(&report, Code::UnknownBuffer),
        ["e1.c1.xx"],
        "{}",
        report.render(100)
    );
    assert!(
        report
            .findings
            .iter()
            .any(|f| f.code == Code::UnknownBehaviour && f.help.contains("did you mean `run`?"))
    );
    assert_eq!(under(&report, Code::UnknownComponent), ["c9.run"]);
    assert_eq!(under(&report, Code::UnknownPredicate), ["ready", "done"]);
    assert_eq!(under(&report, Code::DuplicateName), ["ok"]);
    // -1, a field past the array's end, limits the wrong way round, a zero deadline.
    assert_eq!(
        under(&report, Code::Contract),
        ["-1.0", "2", "1.0", "0.0"],
        "{}",
        report.render(100)
    );
}

#[test]
fn a_chain_that_does_not_connect_is_named_at_its_hop() {
    let text = system(20.0, "Sample", 5.0, "", "").replace(
        r#"path: ["R1.r1.x", "r1.c1.x", "c1.e1.x", "e1.E1.x"]"#,
        r#"path: ["r1.c1.x", "c1.e1.x", "E1.e1.y"]"#,
    );
    let loaded = load("t.ron", text).unwrap_or_else(|r| panic!("{}", r.render(100)));
    let report = agent_spec::check(&loaded);
    // Starts at r1 (not a receptor), jumps from e1 to E1, ends at e1 (not an effector).
    assert_eq!(
        under(&report, Code::Chain),
        ["r1.c1.x", "E1.e1.y", "E1.e1.y"],
        "{}",
        report.render(100)
    );
}

#[test]
fn a_missing_wcet_is_said_and_nothing_is_certified() {
    let text = system(20.0, "Sample", 5.0, "", "").replace(r#"(component: "r1", ms: 1.0), "#, "");
    let (report, a) = run(&text, None);
    assert!(!a.is_certified());
    assert!(
        report
            .findings
            .iter()
            .any(|f| f.code == Code::TimingMissing && f.message.contains("`r1`")),
        "{}",
        report.render(100)
    );
}

proptest! {
    /// The response time is a fixed point of the recurrence, at least C, and
    /// a schedulable thread stays schedulable with a smaller WCET.
    #[test]
    fn response_time_is_a_fixed_point(
        c in 1u64..50,
        higher in proptest::collection::vec((1u64..200, 1u64..20), 0..5),
        shrink in 0u64..50,
    ) {
        let deadline = 1_000;
        if let Some(r) = response_time(c, &higher, deadline) {
            prop_assert!(r >= c && r <= deadline);
            let again = c + higher.iter().map(|&(t, cj)| r.div_ceil(t) * cj).sum::<u64>();
            prop_assert_eq!(again, r);
            let smaller = c.saturating_sub(shrink).max(1);
            let r2 = response_time(smaller, &higher, deadline);
            prop_assert!(r2.is_some_and(|r2| r2 <= r));
        }
    }
}

/// A fixed-priority preemptive uniprocessor, simulated in unit steps over
/// `horizon`: task `i` of period `T_i`, WCET `C_i` and release jitter `J_i`
/// released at `k·T_i`, ready `lateness(i, k) ≤ J_i` later, running
/// `work(i, k)` units (1 to `C_i`: a job may run shorter than its WCET). The
/// shorter period runs first, as the executor's priorities say; equal
/// periods share a priority and run in the order their jobs became ready
/// (`SCHED_FIFO` among equals). Returns each task's largest response time,
/// from the release to the end of the job (`None` if a job did not finish
/// within a period of the horizon).
fn simulate_fixed_priority(
    tasks: &[(u64, u64, u64)],
    lateness: &dyn Fn(usize, u64) -> u64,
    work: &dyn Fn(usize, u64) -> u64,
    horizon: u64,
) -> Vec<Option<u64>> {
    // Every pending job: (task, release, ready, work left).
    let mut jobs: Vec<(usize, u64, u64, u64)> = Vec::new();
    let mut worst = vec![Some(0u64); tasks.len()];
    for now in 0..horizon {
        for (i, &(t, c, j)) in tasks.iter().enumerate() {
            if now % t == 0 {
                let k = now / t;
                jobs.push((i, now, now + lateness(i, k).min(j), work(i, k).clamp(1, c)));
            }
        }
        // The ready job of the shortest period; among equals, the first ready.
        let running = jobs
            .iter()
            .enumerate()
            .filter(|(_, job)| job.2 <= now)
            .min_by_key(|(_, job)| (tasks[job.0].0, job.2, job.1))
            .map(|(n, _)| n);
        if let Some(n) = running {
            jobs[n].3 -= 1;
            if jobs[n].3 == 0 {
                let (i, release, ..) = jobs.remove(n);
                worst[i] = worst[i].map(|w| w.max(now + 1 - release));
            }
        }
    }
    for &(i, release, ..) in &jobs {
        // A job released long enough before the horizon that should have ended.
        if release + tasks[i].0 < horizon {
            worst[i] = None;
        }
    }
    worst
}

proptest! {
    /// Soundness of the response time with release jitter against a
    /// simulated fixed-priority processor whose jobs start late by any
    /// amount up to their jitter and run any time up to their WCET, with
    /// tasks of equal periods at one priority: every measured response time
    /// is within the bound of every thread the analysis calls schedulable
    /// (the interference of every other task of its period or shorter).
    #[test]
    fn response_time_with_jitter_bounds_a_simulated_processor(
        tasks in proptest::collection::vec(
            (prop_oneof![Just(10u64), Just(20u64), 5u64..40], 1u64..6, 0u64..6),
            1..5,
        ),
        seed in any::<u64>(),
    ) {
        let mix = |i: usize, k: u64, salt: u64| {
            (seed ^ salt ^ (i as u64).wrapping_mul(0x9E37_79B9) ^ k.wrapping_mul(0x85EB_CA6B))
                .wrapping_mul(0xC2B2_AE35)
        };
        // A mix of on-time, worst and scattered wake-ups, and of whole and
        // short jobs.
        let lateness = |i: usize, k: u64| match mix(i, k, 1) % 4 {
            0 => 0,
            1 => u64::MAX,
            h => mix(i, k, h) >> 8,
        };
        let work = |i: usize, k: u64| match mix(i, k, 2) % 3 {
            0 => u64::MAX,
            _ => 1 + (mix(i, k, 3) >> 8) % tasks[i].1,
        };
        let measured = simulate_fixed_priority(&tasks, &lateness, &work, 2_000);
        // Each task interfered with by every other of its period or shorter;
        // its bound holds when all of those meet their deadlines too.
        let bounds: Vec<Option<u64>> = tasks
            .iter()
            .enumerate()
            .map(|(i, &(t, c, j))| {
                let higher: Vec<_> = (0..tasks.len())
                    .filter(|&o| o != i && tasks[o].0 <= t)
                    .map(|o| tasks[o])
                    .collect();
                response_time_with_jitter(c, j, &higher, t)
            })
            .collect();
        for (i, &(t, ..)) in tasks.iter().enumerate() {
            let above_ok = (0..tasks.len()).all(|o| tasks[o].0 > t || bounds[o].is_some());
            if let (Some(b), true) = (bounds[i], above_ok) {
                let m = measured[i];
                prop_assert!(m.is_some_and(|m| m <= b), "task {i} {tasks:?}: measured {m:?} above {b}");
            }
        }
    }
}

/// One hop simulated as the executor runs it: the writer's activations
/// released at least `interval` apart (sporadically), each ending within
/// `[1, R_w]` of its release (an activation may run much shorter than its
/// WCET), in order, its value delivered up to `latency`
/// later (in order); the reader released every `T_r`, reading at most
/// `S_r` (its start lag) after its release the oldest value delivered before its read and
/// stamped at or before its release. Returns the most values in the queue
/// when one is delivered (it included) and the longest time from a value's
/// writer release to the release of the reader activation that takes it.
/// The reader is first released at `reader_phase`, the writer not before.
#[allow(clippy::too_many_arguments, reason = "the hop's figures, named")]
fn simulate_queue_hop(
    seed: u64,
    rw: u64,
    interval: u64,
    extra_gap: u64,
    (tr, jr): (u64, u64),
    latency: u64,
    reader_phase: u64,
) -> (usize, u64) {
    // A small xorshift: the same runs for the same seed.
    let mut state = seed | 1;
    let mut rand = move |n: u64| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        if n == 0 { 0 } else { state % (n + 1) }
    };
    // Writer: release, delivery.
    let mut values = Vec::new();
    // Both start on the common clock: the writer's first release is not
    // before the reader's first.
    let (mut a, mut last_f, mut last_d) = (reader_phase + rand(interval), 0, 0);
    while a < 200 * interval.max(tr) {
        let f = (a + 1 + rand(rw - 1)).max(last_f);
        let d = (f + rand(latency)).max(last_d);
        values.push((a, d));
        (last_f, last_d) = (f, d);
        a += interval + rand(extra_gap);
    }
    let (mut queue, mut most, mut wait) = (std::collections::VecDeque::new(), 0, 0);
    let mut next = 0;
    let mut b = reader_phase;
    let end = values.last().map_or(0, |v| v.1) + 4 * tr;
    while b < end {
        let s = b + rand(jr);
        // Deliveries before this read, each counted as it enters.
        while next < values.len() && values[next].1 < s {
            queue.push_back(values[next]);
            most = most.max(queue.len());
            next += 1;
        }
        if let Some(&(stamp, _)) = queue.front()
            && stamp <= b
        {
            queue.pop_front();
            wait = wait.max(b - stamp);
        }
        b += tr;
    }
    (most, wait)
}

proptest! {
    /// The queue bound and the queue hop's term hold in a simulation of the
    /// executor's read and write points, for writers no faster than their reader.
    #[test]
    fn queue_bound_and_hop_term_hold_in_simulation(
        seed in 1u64..u64::MAX,
        cw in 1u64..20,
        jitter_w in 0u64..30,
        tr in 5u64..60,
        jr in 0u64..20,
        faster_by in 0u64..40,
        extra_gap in 0u64..20,
        latency in 0u64..15,
        reader_phase in 0u64..60,
    ) {
        let rw = cw + jitter_w;
        let interval = tr + faster_by; // I >= T_r
        let needs = queue_needs(tr, jr, rw, latency, interval).unwrap();
        let (most, wait) =
            simulate_queue_hop(seed, rw, interval, extra_gap, (tr, jr), latency, reader_phase);
        prop_assert!(most as u64 <= needs, "held {most} > needs {needs}");
        // Age term of a queue hop: 2 R_w + 2L + T_r.
        let term = 2 * rw + 2 * latency + tr;
        prop_assert!(wait <= term, "waited {wait} > term {term}");
    }
}

#[test]
fn the_queue_bound_is_reached_or_nearly_in_simulation() {
    // A writer whose ends spread over 10 at the reader's rate: needs
    // ⌈(10 + 5 + 2·10) / 10⌉ = 4; the worst of many runs holds within one of it.
    let needs = queue_needs(10, 5, 10, 0, 10).unwrap();
    assert_eq!(needs, 4);
    let most = (1..2000u64)
        .map(|seed| simulate_queue_hop(seed, 10, 10, 0, (10, 5), 0, seed % 10).0)
        .max()
        .unwrap();
    assert!(
        most as u64 <= needs && most as u64 + 1 >= needs,
        "held at most {most}"
    );
}

#[test]
fn a_writer_shorter_than_its_wcet_bunches_its_values() {
    // WCET 19, response 20, every 5 ms, its reader every 5 ms: with every
    // activation ending between 19 and 20 after its release, the writes
    // would come about 5 apart and 2 values would do (⌈(5 + 2·1) / 5⌉); but
    // an activation may end 1 after its release, behind one that took 20:
    // several values arrive at once. The bound counts the ends' spread as
    // R_w: ⌈(5 + 2·20) / 5⌉ = 9.
    let needs = queue_needs(5, 0, 20, 0, 5).unwrap();
    assert_eq!(needs, 9);
    let most = (1..500u64)
        .map(|seed| simulate_queue_hop(seed, 20, 5, 0, (5, 0), 0, seed % 5).0)
        .max()
        .unwrap();
    assert!(
        most > 2,
        "held at most {most}: the spread R_w - C_w undercounts"
    );
    assert!(most as u64 <= needs, "held {most} > needs {needs}");
}

#[test]
fn a_freshness_contract_on_a_whole_fan_is_analysed_per_element() {
    // A hub c2 whose fan of inputs `c1` has two peers, c1_0 and c1_1 (10 ms).
    let robot = |k: usize| {
        format!(
            r#"(name: "a1_{k}", subsystems: [(name: "c1_{k}", kind: Control, period_ms: 10.0,
                inputs: [(peer: "c2", buffers: [(name: "plan", type: "u64")])],
                outputs: [(peer: "c2", buffers: [(name: "ack", type: "u64")])],
                behaviours: [(name: "run", kind: While, terminal: "false")], fsm: (initial: "run"))]),"#
        )
    };
    let text = format!(
        r#"(name: "fleet", agents: [
            (name: "a2", subsystems: [(name: "c2", kind: Control, period_ms: 20.0,
                inputs: [(peer: "c1", peers: ["c1_0", "c1_1"], buffers: [(name: "ack", type: "u64")])],
                outputs: [(peer: "c1", peers: ["c1_0", "c1_1"], buffers: [(name: "plan", type: "u64")])],
                behaviours: [(name: "run", kind: While, terminal: "false")], fsm: (initial: "run"))]),
            {r0} {r1}
        ],
        links: [
            (from: "c2.c1[0].plan", to: "c1_0.c2.plan"), (from: "c1_0.c2.ack", to: "c2.c1[0].ack"),
            (from: "c2.c1[1].plan", to: "c1_1.c2.plan"), (from: "c1_1.c2.ack", to: "c2.c1[1].ack"),
        ],
        contracts: (freshness: [(input: "c2.c1[*].ack", max_age_ms: 15.0)]),
        timing: (wcet: [(component: "c2", ms: 1.0), (component: "c1_0", ms: 1.0), (component: "c1_1", ms: 1.0)]),
        )"#,
        r0 = robot(0),
        r1 = robot(1),
    );
    let (report, a) = run(&text, None);
    assert!(report.is_ok(), "{}", report.render(100));
    let inputs: Vec<&str> = a.freshness.iter().map(|f| f.input.as_str()).collect();
    assert_eq!(inputs, ["c2.c1[0].ack", "c2.c1[1].ack"]);
    // c1_k (T 10, R 2: the two at one priority) writes, c2 reads: age < 10 + 2.
    assert!(a.freshness.iter().all(|f| f.bound == Some(12 * MS)), "{a}");
}

#[test]
fn freshness_is_proven_from_the_periods_where_it_can_be() {
    let contracts = r#"freshness: [(input: "e1.c1.x", max_age_ms: 20.0), (input: "c1.r1.x", max_age_ms: 20.0)],"#;
    let (report, a) = run(&system(20.0, "Sample", 5.0, "", contracts), None);
    assert!(report.is_ok(), "{}", report.render(100));
    // e1 reads c1's value: age < T_c1 10 + R_c1 3.4 = 13.4 <= 20: proven.
    // c1 reads r1's: < T_r1 20 + R_r1 4.5 = 24.5 > 20: left to the monitor.
    let bound = |i: &str| a.freshness.iter().find(|f| f.input == i).unwrap().bound;
    assert_eq!(bound("e1.c1.x"), Some(134 * MS / 10));
    assert_eq!(bound("c1.r1.x"), Some(245 * MS / 10));
    let text = a.to_string();
    assert!(
        text.contains("freshness e1.c1.x: age < 13.4 ms, contract 20 ms: proven"),
        "{text}"
    );
    assert!(
        text.contains("freshness c1.r1.x: age < 24.5 ms, contract 20 ms: not proven"),
        "{text}"
    );
    assert!(
        a.is_certified(),
        "a freshness contract speaks of runs: not a violation here"
    );
}

/// A sample hop simulated as the executor runs it: the writer released every
/// `T_w` (from a phase not before the reader's), ending within `[C_w, R_w]`,
/// delivered up to `latency` later; the reader released every `T_r` takes
/// the newest value delivered before its read (at most `S_r` late) and
/// stamped at or before its release. The largest age (reader release minus
/// the stamp of the value it takes) once the writer's first value is in.
fn simulate_sample_hop(
    seed: u64,
    (tw, cw, rw): (u64, u64, u64),
    (tr, jr): (u64, u64),
    latency: u64,
    phase: u64,
) -> u64 {
    let mut state = seed | 1;
    let mut rand = move |n: u64| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        if n == 0 { 0 } else { state % (n + 1) }
    };
    let mut values = Vec::new();
    let (mut a, mut last_f, mut last_d) = (phase, 0, 0);
    while a < 300 * tw.max(tr) {
        let f = (a + cw + rand(rw - cw)).max(last_f);
        let d = (f + rand(latency)).max(last_d);
        values.push((a, d));
        (last_f, last_d) = (f, d);
        a += tw;
    }
    let mut worst = 0;
    // From the first value's latest delivery on (before it, the reader holds
    // nothing the writer wrote).
    let mut b = 0;
    while b < phase + rw + latency {
        b += tr;
    }
    while b < 299 * tw.max(tr) {
        let s = b + rand(jr);
        let held = values
            .iter()
            .filter(|(stamp, d)| *d < s && *stamp <= b)
            .map(|(stamp, _)| *stamp)
            .max();
        if let Some(stamp) = held {
            worst = worst.max(b - stamp);
        }
        b += tr;
    }
    worst
}

proptest! {
    /// The sample hop's age term `T_w + R_w + L` holds in simulation.
    #[test]
    fn sample_hop_age_holds_in_simulation(
        seed in 1u64..u64::MAX,
        tw in 2u64..50,
        cw in 1u64..10,
        jitter_w in 0u64..20,
        tr in 2u64..50,
        jr in 0u64..20,
        latency in 0u64..10,
        phase in 0u64..50,
    ) {
        let rw = (cw + jitter_w).min(tw); // a schedulable writer: R_w <= T_w
        let cw = cw.min(rw);
        let worst = simulate_sample_hop(seed, (tw, cw, rw), (tr, jr), latency, phase);
        prop_assert!(worst <= tw + rw + latency, "age {worst} > T_w + R_w + L = {}", tw + rw + latency);
    }
}
