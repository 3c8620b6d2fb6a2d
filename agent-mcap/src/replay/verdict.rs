//! What a replay found: [`Replayed`], and at the first difference a
//! [`Divergence`].

use std::fmt;

use agent_core::Time;

/// What a replay found.
#[derive(Clone, Debug, PartialEq)]
pub enum Replayed {
    /// The subsystem did what the recording says, bit for bit.
    Equivalent {
        /// Elementary actions made (and recorded).
        iterations: u64,
        /// Values compared (sent by the subsystem) and fed (recorded values
        /// of the links into it).
        transfers: u64,
        /// Behaviour switches compared.
        switches: u64,
    },
    /// The first place where it did not.
    Diverged(Box<Divergence>),
}

impl Replayed {
    /// Whether the replay is equivalent.
    pub fn is_equivalent(&self) -> bool {
        matches!(self, Replayed::Equivalent { .. })
    }
}

impl fmt::Display for Replayed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Replayed::Equivalent {
                iterations,
                transfers,
                switches,
            } => write!(
                f,
                "equivalent: {iterations} iterations, {transfers} transfers, {switches} behaviour switches"
            ),
            Replayed::Diverged(d) => write!(f, "{d}"),
        }
    }
}

/// The first difference between a replay and its recording.
#[derive(Clone, Debug, PartialEq)]
pub struct Divergence {
    /// The subsystem.
    pub node: String,
    /// The instant of the first difference.
    pub time: Time,
    /// The subsystem's iteration there (its elementary actions made before).
    pub iteration: u64,
    /// What differs.
    pub what: Difference,
    /// The behaviour the recorded run was in.
    pub recorded_behaviour: String,
    /// The behaviour the replay was in.
    pub replayed_behaviour: String,
}

/// What differs at a [`Divergence`].
#[derive(Clone, Debug, PartialEq)]
pub enum Difference {
    /// A value sent on a link differs.
    Value {
        /// The link (`node.port -> node.port`).
        link: String,
        /// The first field that differs (`points[3].x`; empty: the whole value,
        /// or its bytes only, for example a NaN's).
        field: String,
        /// The recorded value of that field (JSON).
        recorded: String,
        /// The replayed one.
        replayed: String,
    },
    /// The recorded run sent a value the replay did not send (then).
    Missing {
        /// The link.
        link: String,
        /// The recorded value (JSON).
        recorded: String,
    },
    /// The replay sent a value the recorded run did not send (then).
    Extra {
        /// The link.
        link: String,
        /// The replayed value (JSON).
        replayed: String,
    },
    /// A behaviour switch differs, is missing, or is extra (`None`).
    Switch {
        /// The recorded switch (JSON).
        recorded: Option<String>,
        /// The replayed one.
        replayed: Option<String>,
    },
    /// The replay made a different number of elementary actions.
    Iterations {
        /// Recorded.
        recorded: u64,
        /// Replayed.
        replayed: u64,
    },
}

impl fmt::Display for Divergence {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "diverged at {:.3} s ({} iteration {}): ",
            self.time.as_secs_f64(),
            self.node,
            self.iteration
        )?;
        match &self.what {
            Difference::Value {
                link,
                field,
                recorded,
                replayed,
            } => {
                let field = if field.is_empty() {
                    "(the value)"
                } else {
                    field
                };
                write!(
                    f,
                    "buffer `{link}`, field {field}: recorded {recorded}, replayed {replayed}"
                )?;
            }
            Difference::Missing { link, recorded } => {
                write!(f, "buffer `{link}`: recorded {recorded}, replayed nothing")?;
            }
            Difference::Extra { link, replayed } => {
                write!(f, "buffer `{link}`: recorded nothing, replayed {replayed}")?;
            }
            Difference::Switch { recorded, replayed } => {
                let or_none = |s: &Option<String>| s.clone().unwrap_or_else(|| "none".into());
                write!(
                    f,
                    "behaviour switch: recorded {}, replayed {}",
                    or_none(recorded),
                    or_none(replayed)
                )?;
            }
            Difference::Iterations { recorded, replayed } => {
                write!(f, "recorded {recorded} iterations, replayed {replayed}")?;
            }
        }
        write!(
            f,
            "; {} was in {} (recorded) and {} (replayed)",
            self.node, self.recorded_behaviour, self.replayed_behaviour
        )
    }
}
