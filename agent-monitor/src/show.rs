//! A violation as one line: `t=... subsystem=... contract=kind:name: values`.

use std::fmt;
use std::time::Duration;

use crate::*;

pub(crate) struct Shown<'a> {
    pub(crate) m: &'a Monitors,
    pub(crate) v: &'a Violation,
}

fn ms(d: Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

impl fmt::Display for Shown<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let v = self.v;
        let (kind, name, sub) = match self.m.contract(v.contract) {
            Some(c) => (c.kind.to_string(), c.name.as_str(), c.subsystem.as_str()),
            None => ("?".to_owned(), "?", "?"),
        };
        write!(
            f,
            "t={:.6}s subsystem={sub} contract={kind}:{name}: ",
            v.time.as_secs_f64()
        )?;
        match v.broke {
            Broke::Age { age, max } => write!(f, "age {:.3} ms > {:.3} ms", ms(age), ms(max)),
            Broke::Silent { since, window } => write!(
                f,
                "no value for {:.3} ms since t={:.6}s",
                ms(window),
                since.as_secs_f64()
            ),
            Broke::Lasted { entered, max } => write!(
                f,
                "entered at t={:.6}s, still running after {:.3} s",
                entered.as_secs_f64(),
                max.as_secs_f64()
            ),
            Broke::Iterations {
                entered,
                iterations,
                max,
            } => write!(
                f,
                "entered at t={:.6}s, {iterations} iterations > {max}",
                entered.as_secs_f64()
            ),
            Broke::OutOfRange { value, min, max } => {
                write!(f, "value {value} outside [")?;
                match min {
                    Some(m) => write!(f, "{m}, ")?,
                    None => f.write_str("-inf, ")?,
                }
                match max {
                    Some(m) => write!(f, "{m}]"),
                    None => f.write_str("inf]"),
                }
            }
            Broke::Unanswered { trigger, within } => write!(
                f,
                "trigger at t={:.6}s unanswered within {:.3} s",
                trigger.as_secs_f64(),
                within.as_secs_f64()
            ),
            Broke::False { predicates, reads } => {
                f.write_str("false with")?;
                let names = self
                    .m
                    .invariants
                    .iter()
                    .find(|i| i.contract == v.contract)
                    .map_or(&[][..], |i| self.m.predicate_names(i.subsystem));
                for k in (0..64).filter(|k| reads >> k & 1 == 1) {
                    let value = predicates >> k & 1 == 1;
                    match names.get(k) {
                        Some(n) => write!(f, " {n}={value}")?,
                        None => write!(f, " #{k}={value}")?,
                    }
                }
                Ok(())
            }
        }
    }
}
