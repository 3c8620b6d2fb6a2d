//! The promises a system makes beyond its structure: contracts on buffers and
//! behaviours, cause-effect chains with deadlines, and the timing figures
//! (worst-case execution times, latencies) that the timing analysis
//! ([`crate::timing`]) proves the chains and queues against.
//!
//! Every contract names what it constrains the way the rest of the spec does
//! (`component.group.buffer` for a buffer, `subsystem.behaviour` for a
//! behaviour) and carries its bound as plain data, so that a monitor can be
//! made from each one without the spec's text: a freshness contract is a
//! buffer and a largest age, a range a buffer, a field path and two limits.
//! A buffer of a fan is named by its element (`c2.c1[3].plan`), or by the
//! whole fan (`c2.c1[*].plan`: the contract once per element,
//! [`Contracts::per_element`]).

use serde::{Deserialize, Serialize};

/// The system's contracts: what it promises while it runs.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Contracts {
    /// The largest age of the value an activation reads from an input buffer.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub freshness: Vec<Freshness>,
    /// The lowest rate at which new values reach an input buffer.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub rates: Vec<Rate>,
    /// Bounds on how long a behaviour runs.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub bounds: Vec<Bound>,
    /// Conditions over a subsystem's predicates that hold after every activation.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub invariants: Vec<Invariant>,
    /// Numeric limits on a buffer's values.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub ranges: Vec<ValueRange>,
    /// A value on one buffer answered by a value on another within a deadline.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub responses: Vec<Response>,
    /// Cause-effect chains from a real receptor to a real effector.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub chains: Vec<Chain>,
}

impl Contracts {
    /// These contracts with every whole fan (`c2.c1[*].plan`,
    /// [`crate::fans`]) replaced by its elements: a freshness, rate or range
    /// on a whole fan is one contract per element (a range named `name`
    /// becomes `name[k]`); a response with a whole fan on one side is one
    /// response per element of it, and with the same fan's elements on both
    /// sides one per element, element `k` answered on element `k` (`name[k]`).
    /// What monitors are made from; a spec the checker passed.
    pub fn per_element(&self, spec: &crate::Spec) -> Contracts {
        use crate::fans::{elements, named};
        let mut out = Contracts {
            bounds: self.bounds.clone(),
            invariants: self.invariants.clone(),
            chains: self.chains.clone(),
            ..Contracts::default()
        };
        for f in &self.freshness {
            out.freshness.extend(
                elements(spec, &f.input)
                    .into_iter()
                    .map(|(input, _)| Freshness { input, ..f.clone() }),
            );
        }
        for r in &self.rates {
            out.rates.extend(
                elements(spec, &r.input)
                    .into_iter()
                    .map(|(input, _)| Rate { input, ..r.clone() }),
            );
        }
        for r in &self.ranges {
            out.ranges
                .extend(
                    elements(spec, &r.buffer)
                        .into_iter()
                        .map(|(buffer, k)| ValueRange {
                            name: named(&r.name, k),
                            buffer,
                            ..r.clone()
                        }),
                );
        }
        for r in &self.responses {
            let (triggers, responses) = (elements(spec, &r.trigger), elements(spec, &r.response));
            let pairs: Vec<_> = match (triggers.len(), responses.len()) {
                (_, 1) => triggers
                    .into_iter()
                    .map(|(t, k)| (t, responses[0].0.clone(), k))
                    .collect(),
                (1, _) => responses
                    .into_iter()
                    .map(|(x, k)| (triggers[0].0.clone(), x, k))
                    .collect(),
                _ => triggers
                    .into_iter()
                    .zip(responses)
                    .map(|((t, k), (x, _))| (t, x, k))
                    .collect(),
            };
            out.responses
                .extend(pairs.into_iter().map(|(trigger, response, k)| Response {
                    name: named(&r.name, k),
                    trigger,
                    response,
                    ..r.clone()
                }));
        }
        out
    }
}

/// `input`'s values are never older than `max_age_ms` when an activation reads them.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Freshness {
    /// An input buffer, `component.group.buffer` (`e11.c1.pose`).
    pub input: String,
    /// The largest age \[ms\]: the reader's instant minus the writer's instant
    /// that stamped the value.
    pub max_age_ms: f64,
}

/// New values reach `input` at least `min_hz` times a second.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Rate {
    /// An input buffer, `component.group.buffer`.
    pub input: String,
    /// The lowest rate \[Hz\].
    pub min_hz: f64,
}

/// A behaviour ends within a time, or within a number of iterations, or both.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bound {
    /// `subsystem.behaviour` (`c1.B2`).
    pub behaviour: String,
    /// The longest run \[s\], from the activation that enters it to the one that ends it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_s: Option<f64>,
    /// The most iterations of its elementary action.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_iterations: Option<u64>,
}

/// A condition over one subsystem's predicates, in the language of its arcs,
/// that holds after every activation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Invariant {
    /// Name, unique among the invariants.
    pub name: String,
    /// The subsystem whose predicates it uses.
    pub subsystem: String,
    /// The condition (`"!stopped || plan_new"`).
    pub holds: String,
}

/// The values of a buffer (or of a numeric field of its type) stay within limits.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ValueRange {
    /// Name, unique among the ranges.
    pub name: String,
    /// A buffer: `component.group.buffer` (an input or an output) or
    /// `subsystem.memory_buffer`.
    pub buffer: String,
    /// A path into the buffer's type (`left`, `wheels.0`); none: the buffer is a number.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub field: Option<String>,
    /// The least value allowed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min: Option<f64>,
    /// The greatest value allowed.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max: Option<f64>,
}

/// After a value is written to `trigger`, a value is written to `response`
/// within `within_s`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Response {
    /// Name, unique among the responses.
    pub name: String,
    /// A buffer, `component.group.buffer`.
    pub trigger: String,
    /// A buffer, `component.group.buffer`.
    pub response: String,
    /// The deadline \[s\].
    pub within_s: f64,
}

/// A cause-effect chain: output buffers, each written by the component that
/// read the previous one, from a real receptor's output to the output that
/// reaches a real effector.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Chain {
    /// Name, unique among the chains.
    pub name: String,
    /// The hops: output buffers `component.group.buffer`; the first written
    /// by a real receptor, the last read by a real effector, each hop's peer
    /// the writer of the next.
    pub path: Vec<String>,
    /// The largest data age \[ms\]: from the receptor's activation that sampled
    /// to the end of the effector's activation that acts on it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_age_ms: Option<f64>,
    /// The largest reaction time \[ms\]: from a change at the receptor to the
    /// end of the first effector activation that acts on it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_reaction_ms: Option<f64>,
}

/// What the timing analysis is given: execution times, latencies, write rates.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Timing {
    /// Worst-case execution time of one activation of each component.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub wcet: Vec<Wcet>,
    /// Per deployment, the bound on the delay of a value between two of its processes.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub latency: Vec<Latency>,
    /// Links written less often than once per activation of their writer.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub writes: Vec<Writes>,
    /// Per component, how late the operating system may start an activation
    /// after its release; a component not listed: 0.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub release_jitter: Vec<ReleaseJitter>,
}

/// The worst-case execution time of one activation of a component.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Wcet {
    /// A subsystem or device.
    pub component: String,
    /// Its worst-case execution time \[ms\] (reading, stepping, sending).
    pub ms: f64,
}

/// The release jitter of a component's activations: the largest time from an
/// activation's release (its instant on the absolute clock) to its thread
/// running, the operating system's wake-up lateness (what `cyclictest`
/// measures of a host; a recording's `/timing` channel holds each node's).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ReleaseJitter {
    /// A subsystem or device.
    pub component: String,
    /// Its release jitter \[ms\], 0 or more.
    pub ms: f64,
}

/// The largest delay of a value on a link between two processes of a deployment.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Latency {
    /// A deployment.
    pub deployment: String,
    /// The bound \[ms\], from the end of the writer's activation to the value
    /// being in the reader's process.
    pub ms: f64,
}

/// How often a link's writer writes, when not at every activation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Writes {
    /// The link, by either end (`component.group.buffer`; its input end
    /// names it as well as its output end, each input having one writer).
    pub link: String,
    /// A queue link: the least time between the releases of two writing
    /// activations \[ms\] (default: the writer's period). Bounds how fast the
    /// queue fills.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub min_interval_ms: Option<f64>,
    /// The greatest time between the releases of two writing activations
    /// \[ms\] (default: the writer's period), each write carrying what its
    /// activation read. Lengthens the chains through the link.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub max_interval_ms: Option<f64>,
}
