//! Where each component runs, and its thread's priority and response time:
//! the threads of a placement, with the findings for the missing WCETs and the
//! threads that can miss their deadlines.

use std::collections::BTreeMap;

use crate::diag::{Code, Finding};
use crate::model::{Spec, Timing};
use crate::span::Seg;

use super::formulas::{liu_layland, ms, ns, ns_up, priorities, response_time_with_jitter};
use super::{ProcessFigures, Spans, TOP_PRIORITY, Thread, component_period};
use Seg::{Field as F, Item as I};

/// Where each component runs (process, host), the deployment's latency if
/// declared, and the path of its name; the whole system in one process
/// without a deployment.
pub(super) fn placement<'s>(
    spec: &'s Spec,
    timing: &Timing,
    deployment: Option<&str>,
) -> Result<Placement<'s>, String> {
    // Where each component runs: (process, host).
    let mut place: BTreeMap<&str, (String, String)> = BTreeMap::new();
    let mut latency = Some(0u64);
    let mut dep_path: Vec<Seg<'static>> = vec![F("name")];
    match deployment {
        None => {
            for (_, s) in spec.subsystems() {
                place.insert(&s.name, (spec.name.clone(), "(one host)".into()));
            }
            for d in spec.agents.iter().flat_map(|a| &a.devices) {
                place.insert(&d.name, (spec.name.clone(), "(one host)".into()));
            }
        }
        Some(name) => {
            let (k, dep) = spec
                .deployments
                .iter()
                .enumerate()
                .find(|(_, d)| d.name == name)
                .ok_or_else(|| {
                    format!(
                        "no deployment `{name}`; deployments: {}",
                        spec.deployment_names()
                    )
                })?;
            dep_path = vec![F("deployments"), I(k), F("name")];
            for h in &dep.hosts {
                for p in &h.processes {
                    for c in &p.runs {
                        place.insert(c, (p.name.clone(), h.name.clone()));
                    }
                }
            }
            match timing.latency.iter().find(|l| l.deployment == name) {
                Some(l) => latency = Some(ns_up(l.ms)),
                None => latency = None,
            }
        }
    }
    Ok((place, latency, dep_path))
}

/// Where each component runs, the latency, the deployment's name's path.
pub(super) type Placement<'s> = (
    BTreeMap<&'s str, (String, String)>,
    Option<u64>,
    Vec<Seg<'static>>,
);

/// The threads of the components in `place` with their WCETs, the
/// executor's priorities and their response times, and each process's
/// figures; `None` (with a finding) when a WCET is missing.
pub(super) fn schedule(
    spec: &Spec,
    timing: &Timing,
    spans: &Spans<'_>,
    place: &BTreeMap<&str, (String, String)>,
    findings: &mut Vec<Finding>,
) -> Option<(Vec<Thread>, Vec<ProcessFigures>)> {
    // Threads with their WCETs.
    let mut threads = Vec::new();
    let mut missing = Vec::new();
    for (c, (process, host)) in place {
        let Some(period) = component_period(spec, c) else {
            continue;
        };
        match timing.wcet.iter().find(|w| w.component == *c) {
            Some(w) => threads.push(Thread {
                component: (*c).to_owned(),
                process: process.clone(),
                host: host.clone(),
                period: ns(period),
                wcet: ns_up(w.ms),
                release_jitter: timing
                    .release_jitter
                    .iter()
                    .find(|j| j.component == *c)
                    .map_or(0, |j| ns_up(j.ms)),
                priority: 0,
                response: None,
            }),
            None => missing.push(*c),
        }
    }
    if !missing.is_empty() {
        findings.push(
            Finding::new(
                Code::TimingMissing,
                spans.at(&[F("timing"), F("wcet")]),
                "no WCET for some components",
                format!(
                    "the timing analysis needs the worst-case execution time of {}",
                    missing
                        .iter()
                        .map(|c| format!("`{c}`"))
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )
            .help("add `(component: \"<name>\", ms: <WCET>)` to `timing.wcet` for each"),
        );
        return None;
    }
    // Priorities as the executor assigns them: each thread's period ranked
    // among the periods of the whole system, in every process alike.
    let periods: Vec<u64> = threads.iter().map(|t| t.period).collect();
    for (t, p) in threads.iter_mut().zip(priorities(&periods, TOP_PRIORITY)) {
        t.priority = p;
    }
    let mut by_process: BTreeMap<String, Vec<usize>> = BTreeMap::new();
    for (i, t) in threads.iter().enumerate() {
        by_process.entry(t.process.clone()).or_default().push(i);
    }
    let mut processes = Vec::new();
    for (name, members) in &by_process {
        let utilisation = members
            .iter()
            .map(|&i| threads[i].wcet as f64 / threads[i].period as f64)
            .sum();
        processes.push(ProcessFigures {
            name: name.clone(),
            host: threads[members[0]].host.clone(),
            utilisation,
            bound: liu_layland(members.len()),
        });
    }
    // Response times per host.
    let all = threads.clone();
    for t in &mut threads {
        let higher: Vec<(u64, u64, u64)> = all
            .iter()
            .filter(|o| o.host == t.host && o.component != t.component && o.priority >= t.priority)
            .map(|o| (o.period, o.wcet, o.release_jitter))
            .collect();
        t.response = response_time_with_jitter(t.wcet, t.release_jitter, &higher, t.period);
    }
    unschedulable(&threads, timing, spans, findings);
    threads.sort_by(|a, b| {
        (&a.host, std::cmp::Reverse(a.priority), &a.component).cmp(&(
            &b.host,
            std::cmp::Reverse(b.priority),
            &b.component,
        ))
    });
    Some((threads, processes))
}

/// A finding for each thread whose response time passes its period, with the
/// threads that can delay it.
fn unschedulable(
    threads: &[Thread],
    timing: &Timing,
    spans: &Spans<'_>,
    findings: &mut Vec<Finding>,
) {
    let all = threads;
    for t in threads {
        if t.response.is_none() {
            let path = wcet_path(&t.component, timing);
            let interferers: Vec<String> = all
                .iter()
                .filter(|o| {
                    o.host == t.host && o.component != t.component && o.priority >= t.priority
                })
                .map(|o| {
                    let j = if o.release_jitter > 0 {
                        format!(" J={}", ms(o.release_jitter))
                    } else {
                        String::new()
                    };
                    format!("`{}` (T={} C={}{j})", o.component, ms(o.period), ms(o.wcet))
                })
                .collect();
            findings.push(
                Finding::new(
                    Code::Unschedulable,
                    spans.at(&path),
                    format!(
                        "C = {} ms, {}T = {} ms",
                        ms(t.wcet),
                        if t.release_jitter > 0 {
                            format!("J = {} ms, ", ms(t.release_jitter))
                        } else {
                            String::new()
                        },
                        ms(t.period)
                    ),
                    format!(
                        "thread `{}` (process `{}`, priority {}) can miss its deadline: its response time passes its period {} ms",
                        t.component,
                        t.process,
                        t.priority,
                        ms(t.period)
                    ),
                )
                .help(format!(
                    "threads at its priority or above on host `{}`: {}; lower a WCET, lengthen a period, or move a component to another host",
                    t.host,
                    if interferers.is_empty() { "(none)".into() } else { interferers.join(", ") }
                )),
            );
        }
    }
}

/// The path of a component's WCET entry.
fn wcet_path(name: &str, timing: &crate::model::Timing) -> Vec<Seg<'static>> {
    timing
        .wcet
        .iter()
        .position(|w| w.component == name)
        .map_or(vec![F("timing")], |i| {
            vec![F("timing"), F("wcet"), I(i), F("ms")]
        })
}
