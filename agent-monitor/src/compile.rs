//! Monitors made from a spec: names resolved to indices, bounds to
//! nanoseconds, invariants to expressions over predicate indices ([`Monitors::new`]).

use agent_core::Expr;
use agent_spec::Spec;
use agent_spec::model::Subsystem;

use crate::*;

fn positive_ns(
    kind: ContractKind,
    contract: &str,
    value: f64,
    unit: f64,
) -> Result<u64, BuildError> {
    let ns = value * unit;
    if value.is_finite() && value > 0.0 && ns < u64::MAX as f64 {
        Ok(ns.round() as u64)
    } else {
        Err(BuildError::Bound {
            kind,
            contract: contract.to_owned(),
            value,
        })
    }
}

/// The period of component `name` (ns; 0 if the spec has no such component
/// or its period is not a positive finite number).
fn period_ns(spec: &Spec, name: &str) -> u64 {
    let subsystems = spec.agents.iter().flat_map(|a| a.subsystems.iter());
    let devices = spec.agents.iter().flat_map(|a| a.devices.iter());
    let period = subsystems
        .map(|s| (&s.name, s.period_ms))
        .chain(devices.map(|d| (&d.name, d.period_ms)))
        .find(|(n, _)| *n == name)
        .map_or(0.0, |(_, p)| p);
    if period.is_finite() && period > 0.0 {
        (period * 1e6).round() as u64
    } else {
        0
    }
}

/// The component a `component.group.buffer` name starts with.
fn component(name: &str) -> &str {
    name.split('.').next().unwrap_or(name)
}

fn intern(names: &mut Vec<String>, name: &str) -> u32 {
    match names.iter().position(|n| n == name) {
        Some(i) => i as u32,
        None => {
            names.push(name.to_owned());
            (names.len() - 1) as u32
        }
    }
}

impl Monitors {
    /// The monitors of `spec`'s contracts (none: a spec without contracts).
    pub fn new(spec: &Spec) -> Result<Monitors, BuildError> {
        let subsystems: Vec<&Subsystem> = spec
            .agents
            .iter()
            .flat_map(|a| a.subsystems.iter())
            .collect();
        let mut m = Monitors {
            contracts: Vec::new(),
            inputs: Vec::new(),
            outputs: Vec::new(),
            subsystems: subsystems
                .iter()
                .map(|s| SubsystemInfo {
                    name: s.name.clone(),
                    behaviours: s.behaviours.iter().map(|b| b.name.clone()).collect(),
                    predicates: s.predicates.iter().map(|p| p.name.clone()).collect(),
                    initial: s
                        .fsm
                        .initial
                        .as_ref()
                        .and_then(|i| s.behaviours.iter().position(|b| &b.name == i))
                        .map(|i| BehaviourId(i as u32)),
                })
                .collect(),
            ranges_of: Vec::new(),
            freshness: Vec::new(),
            rates: Vec::new(),
            bounds: Vec::new(),
            ranges: Vec::new(),
            responses: Vec::new(),
            invariants: Vec::new(),
            next_deadline: None,
            silent: 0,
            activations: false,
            index: Index::default(),
        };
        let Some(c) = &spec.contracts else {
            return Ok(m);
        };
        // A contract on a whole fan (`c2.c1[*].plan`) is one per element.
        let c = &c.per_element(spec);
        for f in &c.freshness {
            let contract = m.add(ContractKind::Freshness, &f.input, component(&f.input));
            let max = positive_ns(ContractKind::Freshness, &f.input, f.max_age_ms, 1e6)?;
            let input = InputId(intern(&mut m.inputs, &f.input));
            let reader = m.subsystem(component(&f.input));
            m.freshness.push(FreshnessM {
                contract,
                input,
                max,
                period: period_ns(spec, component(&f.input)),
                reader,
                held: None,
                held_at: None,
            });
        }
        for r in &c.rates {
            let contract = m.add(ContractKind::Rate, &r.input, component(&r.input));
            let window = positive_ns(ContractKind::Rate, &r.input, 1.0 / r.min_hz, 1e9)?;
            let input = InputId(intern(&mut m.inputs, &r.input));
            m.rates.push(RateM {
                contract,
                input,
                window,
                last: Time::ZERO,
                reported: false,
            });
        }
        for b in &c.bounds {
            m.add_bound(b)?;
        }
        for r in &c.ranges {
            let contract = m.add(ContractKind::Range, &r.name, component(&r.buffer));
            m.ranges_of.push((r.buffer.clone(), r.field.clone()));
            m.ranges.push(RangeM {
                contract,
                min: r.min,
                max: r.max,
                active: true,
            });
        }
        for r in &c.responses {
            let contract = m.add(ContractKind::Response, &r.name, component(&r.response));
            let within = positive_ns(ContractKind::Response, &r.name, r.within_s, 1e9)?;
            let trigger = OutputId(intern(&mut m.outputs, &r.trigger));
            let response = OutputId(intern(&mut m.outputs, &r.response));
            m.responses.push(ResponseM {
                contract,
                trigger,
                response,
                within,
                pending: None,
                last_response: None,
            });
        }
        for i in &c.invariants {
            m.add_invariant(i)?;
        }
        m.reindex();
        Ok(m)
    }

    fn add(&mut self, kind: ContractKind, name: &str, subsystem: &str) -> ContractId {
        self.contracts.push(ContractInfo {
            kind,
            name: name.to_owned(),
            subsystem: subsystem.to_owned(),
        });
        ContractId((self.contracts.len() - 1) as u32)
    }

    fn add_bound(&mut self, b: &agent_spec::contracts::Bound) -> Result<(), BuildError> {
        let kind = ContractKind::Bound;
        let unknown = |what: String| BuildError::Unknown {
            kind,
            contract: b.behaviour.clone(),
            what,
        };
        let (sub, beh) = b
            .behaviour
            .split_once('.')
            .ok_or_else(|| unknown("not `subsystem.behaviour`".to_owned()))?;
        let subsystem = self
            .subsystem(sub)
            .ok_or_else(|| unknown(format!("no subsystem `{sub}`")))?;
        let behaviour = self
            .behaviour(subsystem, beh)
            .ok_or_else(|| unknown(format!("no behaviour `{beh}` in `{sub}`")))?;
        let max = b
            .max_s
            .map(|s| positive_ns(kind, &b.behaviour, s, 1e9))
            .transpose()?;
        let contract = self.add(kind, &b.behaviour, sub);
        self.bounds.push(BoundM {
            contract,
            subsystem,
            behaviour,
            max,
            max_iterations: b.max_iterations,
            run: None,
            lasted_reported: false,
            iterations_reported: false,
        });
        Ok(())
    }

    fn add_invariant(&mut self, i: &agent_spec::contracts::Invariant) -> Result<(), BuildError> {
        let kind = ContractKind::Invariant;
        let unknown = |what: String| BuildError::Unknown {
            kind,
            contract: i.name.clone(),
            what,
        };
        let subsystem = self
            .subsystem(&i.subsystem)
            .ok_or_else(|| unknown(format!("no subsystem `{}`", i.subsystem)))?;
        let predicates = &self.subsystems[subsystem.0 as usize].predicates;
        let parsed = Expr::parse(&i.holds)
            .map_err(|e| unknown(format!("`{}` does not parse: {}", i.holds, e.message)))?;
        let holds = parsed.try_map(&mut |name: &String| {
            predicates
                .iter()
                .position(|p| p == name)
                .ok_or_else(|| unknown(format!("no predicate `{name}` in `{}`", i.subsystem)))
        })?;
        let mut uses = Some(0u64);
        holds.for_each_atom(&mut |&k| {
            uses = uses.and_then(|u| (k < 64).then_some(u | 1 << k));
        });
        let contract = self.add(kind, &i.name, &i.subsystem);
        self.invariants.push(InvariantM {
            contract,
            subsystem,
            holds,
            uses,
            last: None,
        });
        Ok(())
    }
}
