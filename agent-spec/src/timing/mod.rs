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
//! * Blocking is zero: threads share no locks (links are wait-free).
//! * The executor releases each instant on an absolute clock, but the
//!   operating system wakes a thread up to its release jitter `J` late
//!   (`timing.release_jitter`, 0 for a component not listed; with
//!   `--wcet-from`, each node's largest wake-up lateness in the recording
//!   times [`WCET_MARGIN`]). A thread's response time counts from its
//!   release: `R = J + w`, `w = C + Σ ⌈(w + J_j) / T_j⌉ C_j`
//!   ([`response_time_with_jitter`]). A `J` of 0 claims wake-ups on time: on
//!   a general-purpose kernel a late wake-up (a tenth of a millisecond to a
//!   millisecond on a virtual machine) can then pass the bound.
//! * A value between two processes of a deployment arrives within the
//!   deployment's declared latency (`timing.latency`) of its write.
//! * A queue link's writer writes at most once per activation, or at most once
//!   per declared `timing.writes` interval.
//!
//! Every figure is in integer nanoseconds (`ceil` is exact); WCETs are rounded
//! up to the nanosecond, periods to the nearest one.

mod certificate;
mod chains;
mod formulas;
mod schedule;

use std::collections::BTreeMap;
use std::ops::Range;

use crate::diag::{Code, Finding};
use crate::model::{Policy, Spec, Timing};
use crate::span::{SNode, Seg};

pub use formulas::{
    liu_layland, ms, priorities, queue_needs, response_time, response_time_with_jitter,
};

use chains::Placed;
use schedule::{placement, schedule};

/// The highest priority the executor asks for (`RtConfig::realtime`).
pub const TOP_PRIORITY: u8 = 80;

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
    /// Release jitter `J` \[ns\]: how late after its release an activation
    /// may start.
    pub release_jitter: u64,
    /// `SCHED_FIFO` priority, as the executor assigns it in its process.
    pub priority: u8,
    /// Worst-case response time `R` \[ns\]; `None`: above the period.
    pub response: Option<u64>,
}

impl Thread {
    /// `R - C`: how much later than its release an activation may start, and
    /// so read (its reads are at its start); its release jitter included (`R`
    /// counts from the release). An activation ends anywhere up to `R` after
    /// its release (it may run shorter than its WCET), so the spread of its
    /// ends, and of its writes, is `R` itself.
    pub fn start_lag(&self) -> Option<u64> {
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
    /// Its term of the data age: sample `M + R_w + L`; queue `2 R_w + 2L + T_r`
    /// (`M` the greatest time between writes, the writer's period `T_w` unless declared).
    pub age: u64,
    /// Its term of the reaction time: sample `(M - T_w) + R_w + L + T_r`; queue
    /// `(M - T_w) + 2 R_w + 2L + T_r`.
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
    /// Reader period, reader start lag (`R_r - C_r`), writer end spread
    /// (`R_w`), latency, write interval \[ns\].
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

/// The margin a measured execution time (or wake-up lateness) is multiplied
/// by to stand for a WCET (or release jitter) (`--wcet-from`): a recording's
/// largest time is what happened, not a worst case, so the analysis takes
/// 20 % more.
pub const WCET_MARGIN: f64 = 1.2;

/// A per-component figure of the `timing` section that a recording can
/// measure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Figure {
    /// The worst-case execution time (`timing.wcet`; a node's largest
    /// execution time).
    Wcet,
    /// The release jitter (`timing.release_jitter`; a node's largest wake-up
    /// lateness).
    ReleaseJitter,
}

impl Figure {
    /// Its field in the `timing` section.
    pub fn field(self) -> &'static str {
        match self {
            Figure::Wcet => "wcet",
            Figure::ReleaseJitter => "release_jitter",
        }
    }

    /// The figures of `timing`: (component, ms).
    fn entries(self, timing: &Timing) -> Vec<(String, f64)> {
        match self {
            Figure::Wcet => timing
                .wcet
                .iter()
                .map(|w| (w.component.clone(), w.ms))
                .collect(),
            Figure::ReleaseJitter => timing
                .release_jitter
                .iter()
                .map(|j| (j.component.clone(), j.ms))
                .collect(),
        }
    }

    /// Give `component` the figure `ms` in `timing`.
    fn set(self, timing: &mut Timing, component: &str, ms: f64) {
        match self {
            Figure::Wcet => match timing.wcet.iter_mut().find(|w| w.component == component) {
                Some(w) => w.ms = ms,
                None => timing.wcet.push(crate::contracts::Wcet {
                    component: component.to_owned(),
                    ms,
                }),
            },
            Figure::ReleaseJitter => {
                match timing
                    .release_jitter
                    .iter_mut()
                    .find(|j| j.component == component)
                {
                    Some(j) => j.ms = ms,
                    None => timing.release_jitter.push(crate::contracts::ReleaseJitter {
                        component: component.to_owned(),
                        ms,
                    }),
                }
            }
        }
    }
}

/// Where one component's WCET (or release jitter) comes from, after
/// [`use_measured_wcets`] (or [`use_measured_release_jitters`]).
#[derive(Clone, Debug, PartialEq)]
pub struct WcetSource {
    /// Which figure.
    pub figure: Figure,
    /// The component.
    pub component: String,
    /// The figure declared in the spec \[ms\], if any.
    pub declared_ms: Option<f64>,
    /// The largest value measured \[ms\], if the recording has it.
    pub measured_ms: Option<f64>,
    /// The figure the analysis takes \[ms\]: measured × margin, else declared.
    pub used_ms: Option<f64>,
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
    use_measured(spec, Figure::Wcet, measured, margin)
}

/// Replace the release jitters of `spec`'s `timing` section by the wake-up
/// latenesses `measured` \[ns\] (per component, the largest a recording
/// holds) times `margin`, as [`use_measured_wcets`] does the WCETs; a
/// component neither measured nor declared keeps a jitter of 0.
pub fn use_measured_release_jitters(
    spec: &mut Spec,
    measured: &BTreeMap<String, u64>,
    margin: f64,
) -> Option<Vec<WcetSource>> {
    use_measured(spec, Figure::ReleaseJitter, measured, margin)
}

/// [`use_measured_wcets`] for either figure.
fn use_measured(
    spec: &mut Spec,
    figure: Figure,
    measured: &BTreeMap<String, u64>,
    margin: f64,
) -> Option<Vec<WcetSource>> {
    let declared = figure.entries(spec.timing.as_ref()?);
    let mut names: Vec<String> = declared.iter().map(|(c, _)| c.clone()).collect();
    for c in measured.keys() {
        if component_period(spec, c).is_some() && !names.contains(c) {
            names.push(c.clone());
        }
    }
    let timing = spec.timing.as_mut()?;
    let mut out = Vec::new();
    for name in names {
        let declared_ms = declared.iter().find(|(c, _)| *c == name).map(|(_, ms)| *ms);
        let measured_ms = measured.get(&name).map(|&n| n as f64 / 1e6);
        let used = measured_ms.map(|m| m * margin).or(declared_ms);
        if let Some(ms) = used {
            figure.set(timing, &name, ms);
        }
        out.push(WcetSource {
            figure,
            component: name,
            declared_ms,
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
