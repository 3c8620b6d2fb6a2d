//! The timing analysis of a spec: per host, process and thread, the
//! worst-case response times under the real-time executor's fixed priorities;
//! per declared chain, the worst-case data age and reaction time; per queue
//! link, the bound it needs. The result is a certificate ([`Analysis`], shown
//! by its `Display`) or findings in the checker's format.
//!
//! # The executor this models
//!
//! `agent-core`'s real-time executor runs every node on a thread of its own
//! (drivers sharing an environment share one thread: not modelled here, see
//! below) and asks for `SCHED_FIFO` priorities: the threads ranked by period
//! among the periods of the whole system (so every process of a deployment
//! ranks alike, and a host's threads are rate-monotonic across its
//! processes), the shortest at priority 80, each longer period one lower,
//! never below 1; equal periods share a priority ([`priorities`]). It does not pin
//! threads to cores. A thread's activation of instant `k·T` reads its inputs at
//! its start (values stamped at or before `k·T` only), steps, and writes its
//! outputs at its end; a sample link keeps the latest value, a queue link
//! delivers one value per activation of its reader, in order.
//!
//! # Assumptions (what the certificate rests on)
//!
//! * Each component is a thread of its own; its worst-case execution time (the
//!   spec's `timing.wcet`, per activation: reading, stepping, sending) bounds
//!   every activation, including the operating system's overheads.
//! * On a host, only the threads of the deployment's processes run at
//!   real-time priorities, and they got them (`RtReport::rt_priority`).
//! * Threads are not pinned. The analysis takes a host's threads as one
//!   uniprocessor task set (Joseph & Pandya 1986; Audsley et al. 1993): on
//!   `m >= 1` cores under global fixed priorities the interference a job
//!   suffers while it waits is at most `1/m` of its higher-priority threads'
//!   work in the window, carry-in included, which is at most twice the
//!   uniprocessor term when those threads meet their deadlines; so for
//!   `m >= 2` the uniprocessor response time bounds it, and for `m = 1` it is
//!   exact. Threads of the same priority interfere with each other (FIFO
//!   among equals), and a thread of another process on the host interferes
//!   with a thread of its own priority or below whatever their periods.
//! * Release jitter and blocking are zero: threads share no locks (links are
//!   wait-free), and the executor releases each instant on an absolute clock.
//! * A value between two processes of a deployment arrives within the
//!   deployment's declared latency (`timing.latency`) of its write.
//! * A queue link's writer writes at most once per activation, or at most once
//!   per declared `timing.writes` interval.
//!
//! Every figure is in integer nanoseconds (`ceil` is exact); WCETs are rounded
//! up to the nanosecond, periods to the nearest one.

use std::collections::BTreeMap;
use std::fmt;
use std::ops::Range;

use crate::diag::{Code, Finding};
use crate::model::{Link, Policy, Spec, Timing, Writes};
use crate::span::{SNode, Seg};

use Seg::{Field as F, Item as I};

/// The highest priority the executor asks for (`RtConfig::realtime`).
pub const TOP_PRIORITY: u8 = 80;

/// The least fixed point of `R = C + Σ ⌈R / T_j⌉ C_j` over the interfering
/// threads `higher` (period `T_j`, WCET `C_j`), iterated from `R = C` (Joseph
/// & Pandya 1986; Audsley, Burns, Richardson, Tindell & Wellings 1993); `None`
/// when it passes `deadline` (not schedulable). All in the same unit.
pub fn response_time(wcet: u64, higher: &[(u64, u64)], deadline: u64) -> Option<u64> {
    let mut r = wcet;
    loop {
        if r > deadline {
            return None;
        }
        let mut next = u128::from(wcet);
        for &(t, c) in higher {
            let t = u128::from(t.max(1));
            next += u128::from(r).div_ceil(t) * u128::from(c);
        }
        let next = u64::try_from(next).unwrap_or(u64::MAX);
        if next == r {
            return Some(r);
        }
        r = next;
    }
}

/// Liu & Layland's (1973) utilisation bound `n (2^(1/n) - 1)` of `n` tasks
/// under rate-monotonic priorities: a task set at or below it is schedulable
/// on one core (a sufficient test, not a necessary one); 1 for no task.
pub fn liu_layland(n: usize) -> f64 {
    if n == 0 {
        return 1.0;
    }
    let n = n as f64;
    n * (2f64.powf(1.0 / n) - 1.0)
}

/// The executor's priorities for threads of the given periods (every
/// thread of the system: each process ranks its threads among the whole
/// system's periods): distinct periods ranked from the shortest, `top` minus
/// the rank, never below 1.
pub fn priorities(periods: &[u64], top: u8) -> Vec<u8> {
    let mut distinct = periods.to_vec();
    distinct.sort_unstable();
    distinct.dedup();
    periods
        .iter()
        .map(|p| {
            let rank = distinct.iter().position(|d| d == p).unwrap_or(0);
            top.saturating_sub(u8::try_from(rank).unwrap_or(u8::MAX))
                .max(1)
        })
        .collect()
}

/// The bound a queue link needs: the most values in it when one is written,
/// that one included, `⌈(T_r + J_r + 2 (J_w + L)) / I⌉` for a reader of
/// period `T_r` taking one value per activation whose reads start up to `J_r`
/// after its releases, a writer whose writes end up to `J_w` after their
/// earliest ends and come at least `I` apart, and a latency of at most `L`;
/// `None` when the writer may outpace the reader (`I < T_r`): no bound holds.
/// The derivation is in `docs/spec-reference.md` (Timing analysis).
pub fn queue_needs(
    reader_period: u64,
    reader_jitter: u64,
    writer_jitter: u64,
    latency: u64,
    interval: u64,
) -> Option<u64> {
    if interval < reader_period || interval == 0 {
        return None;
    }
    let window = u128::from(reader_period)
        + u128::from(reader_jitter)
        + 2 * (u128::from(writer_jitter) + u128::from(latency));
    u64::try_from(window.div_ceil(u128::from(interval))).ok()
}

/// Milliseconds to nanoseconds, rounded up (WCETs, latencies).
fn ns_up(ms: f64) -> u64 {
    // Finite and positive: the checker refuses other values before the analysis runs.
    (ms * 1e6).ceil().clamp(0.0, u64::MAX as f64) as u64
}

/// Milliseconds to nanoseconds, rounded to the nearest (periods).
fn ns(ms: f64) -> u64 {
    (ms * 1e6).round().clamp(0.0, u64::MAX as f64) as u64
}

/// Nanoseconds as milliseconds for people: `12.5`, `0.8`.
pub fn ms(ns: u64) -> String {
    let s = format!("{:.6}", ns as f64 / 1e6);
    let s = s.trim_end_matches('0').trim_end_matches('.');
    s.to_owned()
}

/// One thread: a component, where it runs, its timing.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Thread {
    /// The component.
    pub component: String,
    /// Its process.
    pub process: String,
    /// Its host.
    pub host: String,
    /// Period `T` \[ns\] (its deadline too).
    pub period: u64,
    /// Worst-case execution time `C` \[ns\].
    pub wcet: u64,
    /// `SCHED_FIFO` priority, as the executor assigns it in its process.
    pub priority: u8,
    /// Worst-case response time `R` \[ns\]; `None`: above the period.
    pub response: Option<u64>,
}

impl Thread {
    /// `R - C`: how much later than its earliest an activation may start
    /// reading (its reads are at its start) or end writing.
    pub fn jitter(&self) -> Option<u64> {
        self.response.map(|r| r - self.wcet.min(r))
    }
}

/// A process's part of the certificate.
#[derive(Clone, Debug, PartialEq)]
pub struct ProcessFigures {
    /// Its name.
    pub name: String,
    /// Its host.
    pub host: String,
    /// `Σ C/T` of its threads.
    pub utilisation: f64,
    /// Liu & Layland's bound for its number of threads.
    pub bound: f64,
}

/// One hop of a chain and its terms \[ns\].
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Hop {
    /// The output buffer, `component.group.buffer`.
    pub buffer: String,
    /// Writer and reader.
    pub writer: String,
    /// The reader.
    pub reader: String,
    /// The link's policy.
    pub policy: Policy,
    /// The latency `L` added between processes.
    pub latency: u64,
    /// Its term of the data age: sample `M + R_w + L`; queue `R_w + J_w + 2L + T_r`
    /// (`M` the greatest time between writes, the writer's period `T_w` unless declared).
    pub age: u64,
    /// Its term of the reaction time: sample `(M - T_w) + R_w + L + T_r`; queue
    /// `(M - T_w) + R_w + J_w + 2L + T_r`.
    pub reaction: u64,
}

/// A chain's part of the certificate.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ChainFigures {
    /// Its name.
    pub name: String,
    /// The hops.
    pub hops: Vec<Hop>,
    /// The receptor's period `T_0` (the reaction time waits for its next sample).
    pub first_period: u64,
    /// The effector's response time `R_n`.
    pub last_response: u64,
    /// Worst-case data age: `Σ age terms + R_n`.
    pub age: u64,
    /// Worst-case reaction time: `T_0 + Σ reaction terms + R_n`.
    pub reaction: u64,
    /// The declared deadlines.
    pub max_age: Option<u64>,
    /// The declared reaction deadline.
    pub max_reaction: Option<u64>,
}

/// A queue link's part of the certificate.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct QueueFigures {
    /// `from -> to`.
    pub link: String,
    /// Its bound.
    pub has: usize,
    /// What it needs; `None`: the writer may outpace the reader.
    pub needs: Option<u64>,
    /// Reader period, reader jitter, writer jitter, latency, write interval \[ns\].
    pub terms: [u64; 5],
}

/// A freshness contract as far as the periods tell.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FreshnessFigures {
    /// The input buffer.
    pub input: String,
    /// The largest age of a value its reader takes \[ns\]; `None`: its writer
    /// is not schedulable.
    pub bound: Option<u64>,
    /// The contract's largest age \[ns\].
    pub max_age: u64,
}

/// The analysis of one deployment (or of the system as one process).
#[derive(Clone, Debug, PartialEq)]
pub struct Analysis {
    /// The deployment; `None`: the whole system in one process.
    pub deployment: Option<String>,
    /// Every thread, by host then priority.
    pub threads: Vec<Thread>,
    /// Every process.
    pub processes: Vec<ProcessFigures>,
    /// Every chain whose components run.
    pub chains: Vec<ChainFigures>,
    /// Chains left out, with why.
    pub skipped: Vec<(String, String)>,
    /// Every queue link whose two ends run.
    pub queues: Vec<QueueFigures>,
    /// The freshness contracts: proven from the periods where the bound is
    /// within the contract, else left to the monitors (not a violation here:
    /// a freshness contract speaks of runs).
    pub freshness: Vec<FreshnessFigures>,
    /// Violations and missing figures, in the checker's format.
    pub findings: Vec<Finding>,
}

impl Analysis {
    /// Whether everything holds.
    pub fn is_certified(&self) -> bool {
        self.findings.is_empty()
    }
}

/// Spans from the span index.
#[derive(Clone, Copy)]
struct Spans<'a>(Option<&'a SNode>);

impl Spans<'_> {
    fn at(&self, path: &[Seg<'_>]) -> Range<usize> {
        let Some(root) = self.0 else { return 0..0 };
        for n in (0..=path.len()).rev() {
            if let Some(node) = root.at(&path[..n]) {
                return node.content_span();
            }
        }
        0..0
    }
}

/// The margin a measured execution time is multiplied by to stand for a WCET
/// (`--wcet-from`): a recording's largest time is what happened, not a worst
/// case, so the analysis takes 20 % more.
pub const WCET_MARGIN: f64 = 1.2;

/// Where one component's WCET comes from, after [`use_measured_wcets`].
#[derive(Clone, Debug, PartialEq)]
pub struct WcetSource {
    /// The component.
    pub component: String,
    /// The WCET declared in the spec \[ms\], if any.
    pub declared_ms: Option<f64>,
    /// The largest execution time measured \[ms\], if the recording has it.
    pub measured_ms: Option<f64>,
    /// The WCET the analysis takes \[ms\]: measured × margin, else declared.
    pub used_ms: Option<f64>,
}

impl fmt::Display for WcetSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let show = |v: Option<f64>| v.map_or_else(|| "-".to_owned(), |v| format!("{v:.4}"));
        let from = match (self.measured_ms, self.declared_ms) {
            (Some(_), _) => "measured",
            (None, Some(_)) => "declared (not in the recording)",
            (None, None) => "none (not in the recording, not declared)",
        };
        write!(
            f,
            "wcet {:<10} declared_ms={} measured_max_ms={} used_ms={} from={from}",
            self.component,
            show(self.declared_ms),
            show(self.measured_ms),
            show(self.used_ms)
        )
    }
}

/// Replace the WCETs of `spec`'s `timing` section by the execution times
/// `measured` \[ns\] (per component, the largest a recording holds) times
/// `margin`; a declared component the recording lacks keeps its declaration.
/// Measured nodes that are not components of the spec are ignored. Returns,
/// per component, where its WCET came from; `None` when the spec has no
/// `timing` section.
pub fn use_measured_wcets(
    spec: &mut Spec,
    measured: &BTreeMap<String, u64>,
    margin: f64,
) -> Option<Vec<WcetSource>> {
    let mut names: Vec<String> = spec
        .timing
        .as_ref()?
        .wcet
        .iter()
        .map(|w| w.component.clone())
        .collect();
    for c in measured.keys() {
        if component_period(spec, c).is_some() && !names.contains(c) {
            names.push(c.clone());
        }
    }
    let timing = spec.timing.as_mut()?;
    let mut out = Vec::new();
    for name in names {
        let declared = timing
            .wcet
            .iter()
            .find(|w| w.component == name)
            .map(|w| w.ms);
        let measured_ms = measured.get(&name).map(|&n| n as f64 / 1e6);
        let used = measured_ms.map(|m| m * margin).or(declared);
        if let Some(ms) = used {
            match timing.wcet.iter_mut().find(|w| w.component == name) {
                Some(w) => w.ms = ms,
                None => timing.wcet.push(crate::contracts::Wcet {
                    component: name.clone(),
                    ms,
                }),
            }
        }
        out.push(WcetSource {
            component: name,
            declared_ms: declared,
            measured_ms,
            used_ms: used,
        });
    }
    Some(out)
}

/// Analyse `spec` placed by `deployment` (`None`: the whole system as one
/// process on one host). The spec must have passed the checker; a spec without
/// a `timing` section gives an error.
pub fn analyse(
    spec: &Spec,
    index: Option<&SNode>,
    deployment: Option<&str>,
) -> Result<Analysis, String> {
    let spans = Spans(index);
    let timing = spec
        .timing
        .as_ref()
        .ok_or("the spec has no `timing` section: declare each component's worst-case execution time (`timing: (wcet: [(component: \"c1\", ms: 1.0), ...])`)")?;
    let (place, latency, dep_path) = placement(spec, timing, deployment)?;
    let mut findings = Vec::new();
    let Some((threads, processes)) = schedule(spec, timing, &spans, &place, &mut findings) else {
        return Ok(Analysis {
            deployment: deployment.map(str::to_owned),
            threads: Vec::new(),
            processes: Vec::new(),
            chains: Vec::new(),
            skipped: Vec::new(),
            queues: Vec::new(),
            freshness: Vec::new(),
            findings,
        });
    };
    let placed = Placed {
        spec,
        spans,
        timing,
        place,
        latency: latency.unwrap_or(0),
        threads,
    };
    let (queues, crossing_queues) = placed.queues(&mut findings);
    let (chains, skipped, crossing_chains) = placed.chains(&mut findings);
    let freshness = placed.freshness();
    let latency_needed = crossing_queues || crossing_chains;
    let latency_declared = latency.is_some();
    if latency_needed && !latency_declared {
        findings.push(
            Finding::new(
                Code::TimingMissing,
                spans.at(&dep_path),
                "no latency declared",
                format!(
                    "deployment `{}` carries chains or queue links between processes, but `timing.latency` gives it no bound",
                    deployment.unwrap_or_default()
                ),
            )
            .help("add `(deployment: \"<name>\", ms: <bound>)` to `timing.latency`"),
        );
    }
    Ok(Analysis {
        deployment: deployment.map(str::to_owned),
        threads: placed.threads,
        processes,
        chains,
        skipped,
        queues,
        freshness,
        findings,
    })
}

/// A spec placed and scheduled: what the chains and queues are computed from.
struct Placed<'s> {
    spec: &'s Spec,
    spans: Spans<'s>,
    timing: &'s Timing,
    place: BTreeMap<&'s str, (String, String)>,
    latency: u64,
    threads: Vec<Thread>,
}

impl<'s> Placed<'s> {
    fn thread(&self, c: &str) -> Option<&Thread> {
        self.threads.iter().find(|t| t.component == c)
    }

    fn link_of(&self, from: &str) -> Option<(usize, &Link)> {
        self.spec
            .links
            .iter()
            .enumerate()
            .find(|(_, l)| l.from == from)
    }

    /// Whether `w` and `r` run in different processes.
    fn crosses(&self, w: &str, r: &str) -> bool {
        self.place.get(w).map(|p| &p.0) != self.place.get(r).map(|p| &p.0)
    }

    /// The latency `L` of a hop from `w` to `r`: 0 inside a process.
    fn hop_latency(&self, w: &str, r: &str) -> u64 {
        if self.crosses(w, r) { self.latency } else { 0 }
    }

    /// What `timing.writes` declares for the link from `from`, named by either end.
    fn declared(&self, from: &str) -> Option<&'s Writes> {
        let to = self
            .spec
            .links
            .iter()
            .find(|l| l.from == from)
            .map(|l| l.to.as_str());
        self.timing
            .writes
            .iter()
            .find(|w| w.link == from || Some(w.link.as_str()) == to)
    }

    /// A hop's age and reaction terms: from the writer's release to the
    /// release of the reader activation that takes the value (or reacts).
    fn terms(
        &self,
        from: &str,
        policy: Policy,
        w: &Thread,
        r: &Thread,
        (rw, jw): (u64, u64),
        l: u64,
    ) -> (u64, u64) {
        // M: the greatest time between two writing activations' releases
        // (the period unless declared); M - T_w the wait for the next one.
        let m = self.gap_of(from, w);
        match policy {
            Policy::Sample => (m + rw + l, (m - w.period) + rw + l + r.period),
            Policy::Queue { .. } => {
                let t = rw + jw + 2 * l + r.period;
                (t, (m - w.period) + t)
            }
        }
    }

    /// Each freshness contract whose input's link runs here: the largest age
    /// of a value its reader takes (the reader's release minus the writer's
    /// release that stamped it), which is the hop's age term.
    fn freshness(&self) -> Vec<FreshnessFigures> {
        let Some(c) = &self.spec.contracts else {
            return Vec::new();
        };
        c.freshness
            .iter()
            .filter_map(|f| {
                let link = self.spec.links.iter().find(|l| l.to == f.input)?;
                let writer = link.from.split('.').next()?;
                let reader = f.input.split('.').next()?;
                let (w, r) = (self.thread(writer)?, self.thread(reader)?);
                let bound = w.response.zip(w.jitter()).map(|rj| {
                    self.terms(
                        &link.from,
                        link.policy,
                        w,
                        r,
                        rj,
                        self.hop_latency(writer, reader),
                    )
                    .0
                });
                Some(FreshnessFigures {
                    input: f.input.clone(),
                    bound,
                    max_age: ns(f.max_age_ms),
                })
            })
            .collect()
    }

    /// `I`: the least time between two writing activations' releases.
    fn interval_of(&self, from: &str, writer: &Thread) -> u64 {
        self.declared(from)
            .and_then(|w| w.min_interval_ms)
            .map_or(writer.period, |v| ns(v).max(writer.period))
    }

    /// `M`: the greatest time between two writing activations' releases.
    fn gap_of(&self, from: &str, writer: &Thread) -> u64 {
        self.declared(from)
            .and_then(|w| w.max_interval_ms)
            .map_or(writer.period, |v| ns_up(v).max(writer.period))
    }

    /// Every queue link whose ends run: the bound it needs; findings for the
    /// ones that can overflow. Also whether one crosses processes.
    fn queues(&self, findings: &mut Vec<Finding>) -> (Vec<QueueFigures>, bool) {
        let mut latency_needed = false;
        // Queue links.
        let mut queues = Vec::new();
        for (k, link) in self.spec.links.iter().enumerate() {
            let Policy::Queue { bound } = link.policy else {
                continue;
            };
            let writer = link.from.split('.').next().unwrap_or_default();
            let reader = link.to.split('.').next().unwrap_or_default();
            let (Some(w), Some(r)) = (self.thread(writer), self.thread(reader)) else {
                continue;
            };
            let (Some(jw), Some(jr)) = (w.jitter(), r.jitter()) else {
                continue; // unschedulable: said above
            };
            let l = self.hop_latency(writer, reader);
            latency_needed |= l > 0
                || self.place.get(writer).map(|p| &p.0) != self.place.get(reader).map(|p| &p.0);
            let interval = self.interval_of(&link.from, w);
            let needs = queue_needs(r.period, jr, jw, l, interval);
            let figures = QueueFigures {
                link: format!("{} -> {}", link.from, link.to),
                has: bound,
                needs,
                terms: [r.period, jr, jw, l, interval],
            };
            let broken = needs.is_none_or(|n| n > bound as u64);
            if broken {
                let label = match needs {
                    Some(n) => format!("Queue({bound}); needs {n}"),
                    None => "the writer outpaces the reader".into(),
                };
                let message = match needs {
                    Some(n) => format!(
                        "queue link `{}` can overflow: it may hold {n} values when one is written, above its bound {bound}",
                        figures.link
                    ),
                    None => format!(
                        "queue link `{}` can overflow: its writer may write every {} ms, faster than its reader takes one value (every {} ms)",
                        figures.link,
                        ms(interval),
                        ms(r.period)
                    ),
                };
                findings.push(
                    Finding::new(
                        Code::QueueOverflow,
                        self.spans.at(&[F("links"), I(k), F("policy")]),
                        label,
                        message,
                    )
                    .help(format!(
                        "⌈(T_r + J_r + 2(J_w + L)) / I⌉ with T_r = {} ms (`{reader}`), J_r = {} ms, J_w = {} ms (`{writer}`), L = {} ms, I = {} ms; raise the bound, or declare a longer write interval in `timing.writes` if the writer writes less often",
                        ms(r.period), ms(jr), ms(jw), ms(l), ms(interval)
                    )),
                );
            }
            queues.push(figures);
        }
        (queues, latency_needed)
    }

    /// Every declared chain whose components run: its terms and totals;
    /// findings for missed deadlines. Also the chains left out, and whether a
    /// hop crosses processes.
    fn chains(
        &self,
        findings: &mut Vec<Finding>,
    ) -> (Vec<ChainFigures>, Vec<(String, String)>, bool) {
        let mut latency_needed = false;
        // Chains.
        let mut chains = Vec::new();
        let mut skipped = Vec::new();
        let contracts = self.spec.contracts.as_ref();
        for (ci, ch) in contracts
            .map(|c| c.chains.as_slice())
            .unwrap_or(&[])
            .iter()
            .enumerate()
        {
            let mut hops = Vec::new();
            let mut ok = true;
            let mut last = None;
            let mut first = None;
            for (hi, hop) in ch.path.iter().enumerate() {
                let mut parts = hop.split('.');
                let (Some(writer), Some(reader)) = (parts.next(), parts.next()) else {
                    ok = false;
                    break;
                };
                let (Some(w), Some(r)) = (self.thread(writer), self.thread(reader)) else {
                    skipped.push((
                        ch.name.clone(),
                        format!("`{writer}` or `{reader}` does not run here"),
                    ));
                    ok = false;
                    break;
                };
                let (Some(rw), Some(jw)) = (w.response, w.jitter()) else {
                    skipped.push((ch.name.clone(), format!("`{writer}` is not schedulable")));
                    ok = false;
                    break;
                };
                let policy = self.link_of(hop).map_or(Policy::Sample, |(_, l)| l.policy);
                let l = self.hop_latency(writer, reader);
                if self.place.get(writer).map(|p| &p.0) != self.place.get(reader).map(|p| &p.0) {
                    latency_needed = true;
                }
                let (age, reaction) = self.terms(hop, policy, w, r, (rw, jw), l);
                if hi == 0 {
                    first = Some(w.period);
                }
                last = Some(r);
                hops.push(Hop {
                    buffer: hop.clone(),
                    writer: writer.to_owned(),
                    reader: reader.to_owned(),
                    policy,
                    latency: l,
                    age,
                    reaction,
                });
            }
            if !ok {
                continue;
            }
            let (Some(first), Some(last)) = (first, last) else {
                continue;
            };
            let Some(rn) = last.response else {
                skipped.push((
                    ch.name.clone(),
                    format!("`{}` is not schedulable", last.component),
                ));
                continue;
            };
            let age = hops.iter().map(|h| h.age).sum::<u64>() + rn;
            let reaction = first + hops.iter().map(|h| h.reaction).sum::<u64>() + rn;
            let figures = ChainFigures {
                name: ch.name.clone(),
                hops,
                first_period: first,
                last_response: rn,
                age,
                reaction,
                max_age: ch.max_age_ms.map(ns),
                max_reaction: ch.max_reaction_ms.map(ns),
            };
            self.deadlines(ci, &ch.name, &figures, findings);
            chains.push(figures);
        }
        (chains, skipped, latency_needed)
    }

    /// Findings for chain `ci`'s figures above their deadlines: at the
    /// deadline, with the hop of the largest term.
    fn deadlines(
        &self,
        ci: usize,
        name: &str,
        figures: &ChainFigures,
        findings: &mut Vec<Finding>,
    ) {
        let at = [F("contracts"), F("chains"), I(ci)];
        for (what, value, limit, field, pick) in [
            ("data age", figures.age, figures.max_age, "max_age_ms", 0),
            (
                "reaction time",
                figures.reaction,
                figures.max_reaction,
                "max_reaction_ms",
                1,
            ),
        ] {
            let Some(limit) = limit.filter(|l| value > *l) else {
                continue;
            };
            let Some((hi, worst)) = figures
                .hops
                .iter()
                .enumerate()
                .max_by_key(|(_, h)| if pick == 0 { h.age } else { h.reaction })
            else {
                continue;
            };
            let term = if pick == 0 { worst.age } else { worst.reaction };
            let terms = figures
                .hops
                .iter()
                .map(|h| ms(if pick == 0 { h.age } else { h.reaction }))
                .collect::<Vec<_>>()
                .join(" + ");
            let formula = if pick == 0 {
                format!("{terms} + R_n {}", ms(figures.last_response))
            } else {
                format!(
                    "T_0 {} + {terms} + R_n {}",
                    ms(figures.first_period),
                    ms(figures.last_response)
                )
            };
            findings.push(
            Finding::new(
                Code::ChainDeadline,
                self.spans.at(&[at[0], at[1], at[2], F(field)]),
                format!("{what} up to {} ms", ms(value)),
                format!(
                    "chain `{}` can miss its deadline: its worst-case {what} {} ms passes {} ms",
                    name,
                    ms(value),
                    ms(limit)
                ),
            )
            .label(
                self.spans.at(&[at[0], at[1], at[2], F("path"), I(hi)]),
                format!("largest term: {} ms ({})", ms(term), hop_formula(worst, &self.threads)),
            )
            .help(format!(
                "{what} = {formula} ms; shorten the periods on the chain, or relax the deadline"
            )),
        );
        }
    }
}

/// Where each component runs (process, host), the deployment's latency if
/// declared, and the path of its name; the whole system in one process
/// without a deployment.
fn placement<'s>(
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
type Placement<'s> = (
    BTreeMap<&'s str, (String, String)>,
    Option<u64>,
    Vec<Seg<'static>>,
);

/// The threads of the components in `place` with their WCETs, the
/// executor's priorities and their response times, and each process's
/// figures; `None` (with a finding) when a WCET is missing.
fn schedule(
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
        let higher: Vec<(u64, u64)> = all
            .iter()
            .filter(|o| o.host == t.host && o.component != t.component && o.priority >= t.priority)
            .map(|o| (o.period, o.wcet))
            .collect();
        t.response = response_time(t.wcet, &higher, t.period);
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

/// A hop's term spelt out: `T_w 10 + R_w 1.2 + L 0` (sample).
fn hop_formula(h: &Hop, threads: &[Thread]) -> String {
    let w = threads.iter().find(|t| t.component == h.writer);
    let r = threads.iter().find(|t| t.component == h.reader);
    let (tw, rw, jw) = w.map_or((0, 0, 0), |t| {
        (t.period, t.response.unwrap_or(0), t.jitter().unwrap_or(0))
    });
    let tr = r.map_or(0, |t| t.period);
    match h.policy {
        Policy::Sample => format!(
            "`{}`: sample, M {} + R_w {} + L {}",
            h.buffer,
            ms(h.age.saturating_sub(rw + h.latency).max(tw)),
            ms(rw),
            ms(h.latency)
        ),
        Policy::Queue { .. } => format!(
            "`{}`: queue, R_w {} + J_w {} + 2L {} + T_r {}",
            h.buffer,
            ms(rw),
            ms(jw),
            ms(2 * h.latency),
            ms(tr)
        ),
    }
}

/// The period of a subsystem or device, in ms.
fn component_period(spec: &Spec, name: &str) -> Option<f64> {
    spec.subsystem(name).map(|s| s.period_ms).or_else(|| {
        spec.agents
            .iter()
            .flat_map(|a| &a.devices)
            .find(|d| d.name == name)
            .map(|d| d.period_ms)
    })
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

impl fmt::Display for Analysis {
    /// The certificate: per host and process, the threads with `T`, `C`, the
    /// priority and `R`; per chain, each hop's terms and the totals against the
    /// deadlines; per queue link, the bound it needs against the one it has.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let verdict = if self.is_certified() {
            "certified"
        } else {
            "VIOLATED"
        };
        match &self.deployment {
            Some(d) => writeln!(f, "timing of deployment `{d}`: {verdict}")?,
            None => writeln!(f, "timing of the system as one process: {verdict}")?,
        }
        for p in &self.processes {
            let quick = if p.utilisation <= p.bound {
                "passes"
            } else {
                "inconclusive: see the response times"
            };
            writeln!(
                f,
                "process `{}` on `{}`: U = {:.4}, Liu & Layland bound {:.4} ({quick})",
                p.name, p.host, p.utilisation, p.bound
            )?;
            for t in self.threads.iter().filter(|t| t.process == p.name) {
                let r = t
                    .response
                    .map_or("> T (misses)".into(), |r| format!("{} ms", ms(r)));
                writeln!(
                    f,
                    "  {:<12} T = {:>8} ms  C = {:>8} ms  prio {:>2}  R = {r}",
                    t.component,
                    ms(t.period),
                    ms(t.wcet),
                    t.priority
                )?;
            }
        }
        for c in &self.chains {
            write_chain(f, c)?;
        }
        for (name, why) in &self.skipped {
            writeln!(f, "chain `{name}`: not analysed here ({why})")?;
        }
        for x in &self.freshness {
            let (verdict, bound) = match x.bound {
                Some(b) if b <= x.max_age => ("proven", format!("< {} ms", ms(b))),
                Some(b) => ("not proven: left to the monitor", format!("< {} ms", ms(b))),
                None => ("not proven: left to the monitor", "unbounded".into()),
            };
            writeln!(
                f,
                "freshness {}: age {bound}, contract {} ms: {verdict}",
                x.input,
                ms(x.max_age)
            )?;
        }
        for q in &self.queues {
            let needs = q
                .needs
                .map_or("unbounded (writer outpaces reader)".into(), |n| {
                    n.to_string()
                });
            let ok = q.needs.is_some_and(|n| n <= q.has as u64);
            writeln!(
                f,
                "queue {}: needs {needs}, has {} {}",
                q.link,
                q.has,
                if ok { "ok" } else { "OVERFLOWS" }
            )?;
        }
        Ok(())
    }
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
                .map(|o| format!("`{}` (T={} C={})", o.component, ms(o.period), ms(o.wcet)))
                .collect();
            findings.push(
                Finding::new(
                    Code::Unschedulable,
                    spans.at(&path),
                    format!("C = {} ms, T = {} ms", ms(t.wcet), ms(t.period)),
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

/// A chain's lines of the certificate.
fn write_chain(f: &mut fmt::Formatter<'_>, c: &ChainFigures) -> fmt::Result {
    writeln!(f, "chain `{}`:", c.name)?;
    for h in &c.hops {
        writeln!(
            f,
            "  {:<24} {:<10} age +{} ms, reaction +{} ms{}",
            h.buffer,
            h.policy.to_string(),
            ms(h.age),
            ms(h.reaction),
            if h.latency > 0 {
                format!(" (latency {} ms)", ms(h.latency))
            } else {
                String::new()
            }
        )?;
    }
    let vs = |v: u64, l: Option<u64>| match l {
        Some(l) if v <= l => format!("{} ms <= {} ms ok", ms(v), ms(l)),
        Some(l) => format!("{} ms > {} ms MISSED", ms(v), ms(l)),
        None => format!("{} ms (no deadline)", ms(v)),
    };
    writeln!(
        f,
        "  data age      = Σ + R_n {} = {}",
        ms(c.last_response),
        vs(c.age, c.max_age)
    )?;
    writeln!(
        f,
        "  reaction time = T_0 {} + Σ + R_n {} = {}",
        ms(c.first_period),
        ms(c.last_response),
        vs(c.reaction, c.max_reaction)
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn liu_layland_bound() {
        assert!((liu_layland(1) - 1.0).abs() < 1e-12);
        assert!((liu_layland(2) - 0.828_427).abs() < 1e-6);
        assert!((liu_layland(3) - 0.779_763).abs() < 1e-6);
        assert!(liu_layland(1000) > std::f64::consts::LN_2);
    }

    #[test]
    fn priorities_are_rate_monotonic_with_ties_and_a_floor() {
        assert_eq!(priorities(&[10, 50, 10, 1], 80), vec![79, 78, 79, 80]);
        assert_eq!(priorities(&[1, 2, 3], 2), vec![2, 1, 1]);
    }
}
