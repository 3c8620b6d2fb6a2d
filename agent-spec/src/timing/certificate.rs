//! The certificate's text: the `Display` of an [`Analysis`] and of a
//! [`WcetSource`], and a hop's terms spelt out for the findings.

use std::fmt;

use crate::model::Policy;

use super::formulas::ms;
use super::{Analysis, ChainFigures, Hop, Thread, WcetSource};

impl fmt::Display for WcetSource {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let show = |v: Option<f64>| v.map_or_else(|| "-".to_owned(), |v| format!("{v:.4}"));
        let from = match (self.measured_ms, self.declared_ms) {
            (Some(_), _) => "measured",
            (None, Some(_)) => "declared (not in the recording)",
            (None, None) => match self.figure {
                super::Figure::Wcet => "none (not in the recording, not declared)",
                super::Figure::ReleaseJitter => "none (not in the recording, not declared: 0)",
            },
        };
        write!(
            f,
            "{} {:<10} declared_ms={} measured_max_ms={} used_ms={} from={from}",
            self.figure.field(),
            self.component,
            show(self.declared_ms),
            show(self.measured_ms),
            show(self.used_ms)
        )
    }
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
                let j = if t.release_jitter > 0 {
                    format!("  J = {:>8} ms", ms(t.release_jitter))
                } else {
                    String::new()
                };
                writeln!(
                    f,
                    "  {:<12} T = {:>8} ms  C = {:>8} ms{j}  prio {:>2}  R = {r}",
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

/// A hop's term spelt out: `T_w 10 + R_w 1.2 + L 0` (sample).
pub(super) fn hop_formula(h: &Hop, threads: &[Thread]) -> String {
    let w = threads.iter().find(|t| t.component == h.writer);
    let r = threads.iter().find(|t| t.component == h.reader);
    let (tw, rw) = w.map_or((0, 0), |t| (t.period, t.response.unwrap_or(0)));
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
            "`{}`: queue, 2 R_w {} + 2L {} + T_r {}",
            h.buffer,
            ms(2 * rw),
            ms(2 * h.latency),
            ms(tr)
        ),
    }
}
