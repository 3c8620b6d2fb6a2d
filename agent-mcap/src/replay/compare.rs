//! Comparing what the replayed subsystem does, instant by instant, with the
//! recording, and saying where and how they first differ.

use std::collections::{BTreeMap, VecDeque};

use agent_core::{Time, TypeShape};
use serde_json::Value;

use super::verdict::{Difference, Divergence, Replayed};
use super::{Event, Recorded};
use crate::json::to_json;
use crate::record::transition_json;

/// The comparison's state.
pub(super) struct Compare<'a> {
    /// The replayed subsystem.
    pub(super) node: &'a agent_core::trace::NodeInfo,
    pub(super) info: &'a agent_core::SystemInfo,
    /// The payload shapes of the links out of it (to name a field).
    pub(super) shapes: &'a BTreeMap<usize, Option<TypeShape>>,
    pub(super) recorded_behaviour: String,
    pub(super) replayed_behaviour: String,
    /// Values compared equal, switches compared equal.
    pub(super) compared: u64,
    pub(super) switched: u64,
}

/// A switch as compared: without the arc's text.
fn comparable(mut v: Value) -> Value {
    if let Some(o) = v.as_object_mut() {
        o.remove("condition");
    }
    v
}

fn entered(v: &Value) -> Option<String> {
    v.get("to")?.as_str().map(str::to_owned)
}

impl Compare<'_> {
    fn json(&self, link: usize, body: &[u8]) -> Value {
        match self.shapes.get(&link).and_then(Option::as_ref) {
            Some(shape) => to_json(shape, body).unwrap_or_else(|_| hex(body)),
            None => hex(body),
        }
    }

    fn divergence(&self, time: Time, iteration: u64, what: Difference) -> Divergence {
        Divergence {
            node: self.node.name.clone(),
            time,
            iteration,
            what,
            recorded_behaviour: self.recorded_behaviour.clone(),
            replayed_behaviour: self.replayed_behaviour.clone(),
        }
    }

    /// The recorded behaviour up to and including instant `t`.
    fn follow_recorded(&mut self, t: Time, switches: &VecDeque<(u64, Value)>) {
        if let Some(to) = switches
            .iter()
            .take_while(|(at, _)| *at <= t.as_nanos())
            .filter_map(|(_, v)| entered(v))
            .last()
        {
            self.recorded_behaviour = to;
        }
    }

    /// Compare one instant's events; then what was recorded up to it and not
    /// replayed.
    pub(super) fn instant(
        &mut self,
        t: Time,
        iteration: u64,
        events: Vec<Event>,
        outputs: &mut BTreeMap<usize, VecDeque<Recorded>>,
        switches: &mut VecDeque<(u64, Value)>,
    ) -> Option<Divergence> {
        for event in events {
            match event {
                Event::Switch {
                    time,
                    iteration: it,
                    step,
                } => {
                    let replayed = comparable(transition_json(self.node, time, it, step));
                    match switches.front() {
                        Some((at, v))
                            if *at == time.as_nanos() && comparable(v.clone()) == replayed =>
                        {
                            if let Some(to) = entered(v) {
                                self.recorded_behaviour = to;
                            }
                            if let Some(to) = entered(&replayed) {
                                self.replayed_behaviour = to;
                            }
                            switches.pop_front();
                            self.switched += 1;
                        }
                        other => {
                            let recorded = other
                                .filter(|(at, _)| *at <= time.as_nanos())
                                .map(|(_, v)| comparable(v.clone()).to_string());
                            return Some(self.divergence(
                                time,
                                iteration,
                                Difference::Switch {
                                    recorded,
                                    replayed: Some(replayed.to_string()),
                                },
                            ));
                        }
                    }
                }
                Event::Transfer { link, stamp, bytes } => {
                    let name = self.info.links[link].name.clone();
                    let queue = outputs.entry(link).or_default();
                    match queue.front() {
                        Some(r) if r.stamp == stamp && r.body == bytes => {
                            queue.pop_front();
                            self.compared += 1;
                        }
                        Some(r) if r.stamp.time == stamp.time => {
                            let (rec, rep) = (self.json(link, &r.body), self.json(link, &bytes));
                            let (field, a, b) = first_difference(&rec, &rep)
                                .unwrap_or_else(|| (String::new(), hex(&r.body), hex(&bytes)));
                            self.follow_recorded(t, switches);
                            return Some(self.divergence(
                                t,
                                iteration,
                                Difference::Value {
                                    link: name,
                                    field,
                                    recorded: a.to_string(),
                                    replayed: b.to_string(),
                                },
                            ));
                        }
                        _ => {
                            let replayed = self.json(link, &bytes).to_string();
                            self.follow_recorded(t, switches);
                            return Some(self.divergence(
                                t,
                                iteration,
                                Difference::Extra {
                                    link: name,
                                    replayed,
                                },
                            ));
                        }
                    }
                }
            }
        }
        // Recorded at or before this instant and not replayed.
        self.missing(Some(t), iteration, outputs, switches)
    }

    fn missing(
        &mut self,
        upto: Option<Time>,
        iteration: u64,
        outputs: &mut BTreeMap<usize, VecDeque<Recorded>>,
        switches: &mut VecDeque<(u64, Value)>,
    ) -> Option<Divergence> {
        let due = |at: Time| upto.is_none_or(|t| at <= t);
        let output = outputs
            .iter()
            .filter_map(|(k, q)| Some((*k, q.front()?)))
            .filter(|(_, r)| due(r.stamp.time))
            .min_by_key(|(_, r)| r.stamp.time);
        let switch = switches
            .front()
            .filter(|(at, _)| due(Time::from_nanos(*at)));
        match (output, switch) {
            (Some((k, r)), s) if s.is_none_or(|(at, _)| r.stamp.time.as_nanos() < *at) => {
                let at = r.stamp.time;
                let recorded = self.json(k, &r.body).to_string();
                let link = self.info.links[k].name.clone();
                self.follow_recorded(at, switches);
                Some(self.divergence(at, iteration, Difference::Missing { link, recorded }))
            }
            (_, Some((at, v))) => {
                let recorded = Some(comparable(v.clone()).to_string());
                Some(self.divergence(
                    Time::from_nanos(*at),
                    iteration,
                    Difference::Switch {
                        recorded,
                        replayed: None,
                    },
                ))
            }
            _ => None,
        }
    }

    /// The verdict at the end of the replay (at `end`, after `replayed` of the
    /// `recorded` iterations, `fed` values fed): what the recording has and the
    /// replay never did, else a different number of iterations, else
    /// equivalent.
    pub(super) fn end(
        &mut self,
        (end, replayed, recorded): (Time, u64, u64),
        fed: u64,
        outputs: &mut BTreeMap<usize, VecDeque<Recorded>>,
        switches: &mut VecDeque<(u64, Value)>,
    ) -> Replayed {
        let divergence = self.missing(None, replayed, outputs, switches).or_else(|| {
            (replayed != recorded).then(|| {
                self.divergence(end, replayed, Difference::Iterations { recorded, replayed })
            })
        });
        match divergence {
            Some(d) => Replayed::Diverged(Box::new(d)),
            None => Replayed::Equivalent {
                iterations: replayed,
                transfers: self.compared + fed,
                switches: self.switched,
            },
        }
    }
}

/// The first field (a path like `points[3].x`) where two JSON values differ,
/// with the two values there.
pub fn first_difference(a: &Value, b: &Value) -> Option<(String, Value, Value)> {
    fn walk(path: &mut String, a: &Value, b: &Value) -> Option<(String, Value, Value)> {
        match (a, b) {
            (Value::Object(x), Value::Object(y)) => {
                for (k, va) in x {
                    let len = path.len();
                    if !path.is_empty() {
                        path.push('.');
                    }
                    path.push_str(k);
                    let found = match y.get(k) {
                        Some(vb) => walk(path, va, vb),
                        None => Some((path.clone(), va.clone(), Value::Null)),
                    };
                    if found.is_some() {
                        return found;
                    }
                    path.truncate(len);
                }
                y.iter()
                    .find(|(k, _)| !x.contains_key(*k))
                    .map(|(k, vb)| (format!("{path}.{k}"), Value::Null, vb.clone()))
            }
            (Value::Array(x), Value::Array(y)) => {
                for (i, (va, vb)) in x.iter().zip(y).enumerate() {
                    let len = path.len();
                    path.push_str(&format!("[{i}]"));
                    if let Some(found) = walk(path, va, vb) {
                        return Some(found);
                    }
                    path.truncate(len);
                }
                (x.len() != y.len()).then(|| {
                    (
                        format!("{path}.len()"),
                        Value::from(x.len()),
                        Value::from(y.len()),
                    )
                })
            }
            _ => (a != b).then(|| (path.clone(), a.clone(), b.clone())),
        }
    }
    walk(&mut String::new(), a, b)
}

fn hex(bytes: &[u8]) -> Value {
    let mut s = String::with_capacity(2 * bytes.len().min(64) + 3);
    for b in bytes.iter().take(64) {
        s.push_str(&format!("{b:02x}"));
    }
    if bytes.len() > 64 {
        s.push_str("...");
    }
    Value::String(s)
}
