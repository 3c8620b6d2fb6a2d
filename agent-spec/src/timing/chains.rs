//! A spec placed and scheduled: each chain's data age and reaction time, each
//! queue link's bound, each freshness contract's bound, and the findings for
//! the ones that break.

use std::collections::BTreeMap;

use crate::diag::{Code, Finding};
use crate::model::{Link, Policy, Spec, Timing, Writes};
use crate::span::Seg;

use super::certificate::hop_formula;
use super::formulas::{ms, ns, ns_up, queue_needs};
use super::{ChainFigures, FreshnessFigures, Hop, QueueFigures, Spans, Thread};
use Seg::{Field as F, Item as I};

/// A spec placed and scheduled: what the chains and queues are computed from.
pub(super) struct Placed<'s> {
    pub(super) spec: &'s Spec,
    pub(super) spans: Spans<'s>,
    pub(super) timing: &'s Timing,
    pub(super) place: BTreeMap<&'s str, (String, String)>,
    pub(super) latency: u64,
    pub(super) threads: Vec<Thread>,
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
        rw: u64,
        l: u64,
    ) -> (u64, u64) {
        // M: the greatest time between two writing activations' releases
        // (the period unless declared); M - T_w the wait for the next one.
        let m = self.gap_of(from, w);
        match policy {
            Policy::Sample => (m + rw + l, (m - w.period) + rw + l + r.period),
            Policy::Queue { .. } => {
                // The writer's ends spread over `R_w` (an activation may end
                // as soon as it starts): `R_w` for the delivery, `R_w` more
                // for the spread of the deliveries ahead of it.
                let t = 2 * rw + 2 * l + r.period;
                (t, (m - w.period) + t)
            }
        }
    }

    /// Each freshness contract whose input's link runs here: the largest age
    /// of a value its reader takes (the reader's release minus the writer's
    /// release that stamped it), which is the hop's age term.
    pub(super) fn freshness(&self) -> Vec<FreshnessFigures> {
        let Some(c) = &self.spec.contracts else {
            return Vec::new();
        };
        // A contract on a whole fan (`c2.c1[*].ack`) is one per element.
        c.per_element(self.spec)
            .freshness
            .iter()
            .filter_map(|f| {
                let link = self.spec.links.iter().find(|l| l.to == f.input)?;
                let writer = link.from.split('.').next()?;
                let reader = f.input.split('.').next()?;
                let (w, r) = (self.thread(writer)?, self.thread(reader)?);
                let bound = w.response.map(|rw| {
                    self.terms(
                        &link.from,
                        link.policy,
                        w,
                        r,
                        rw,
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
    pub(super) fn queues(&self, findings: &mut Vec<Finding>) -> (Vec<QueueFigures>, bool) {
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
            let (Some(ew), Some(sr)) = (w.response, r.start_lag()) else {
                continue; // unschedulable: said above
            };
            let l = self.hop_latency(writer, reader);
            latency_needed |= l > 0
                || self.place.get(writer).map(|p| &p.0) != self.place.get(reader).map(|p| &p.0);
            let interval = self.interval_of(&link.from, w);
            let needs = queue_needs(r.period, sr, ew, l, interval);
            let figures = QueueFigures {
                link: format!("{} -> {}", link.from, link.to),
                has: bound,
                needs,
                terms: [r.period, sr, ew, l, interval],
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
                        "⌈(T_r + S_r + 2(R_w + L)) / I⌉ with T_r = {} ms (`{reader}`), S_r = R_r - C_r = {} ms, R_w = {} ms (`{writer}`), L = {} ms, I = {} ms; raise the bound, or declare a longer write interval in `timing.writes` if the writer writes less often",
                        ms(r.period), ms(sr), ms(ew), ms(l), ms(interval)
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
    pub(super) fn chains(
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
                let Some(rw) = w.response else {
                    skipped.push((ch.name.clone(), format!("`{writer}` is not schedulable")));
                    ok = false;
                    break;
                };
                let policy = self.link_of(hop).map_or(Policy::Sample, |(_, l)| l.policy);
                let l = self.hop_latency(writer, reader);
                if self.place.get(writer).map(|p| &p.0) != self.place.get(reader).map(|p| &p.0) {
                    latency_needed = true;
                }
                let (age, reaction) = self.terms(hop, policy, w, r, rw, l);
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
