//! The QoS of a publisher or subscription, and the compact string rmw_zenoh
//! writes it as in liveliness tokens:
//!
//! `<reliability>:<durability>:<history>,<depth>:<deadline s>,<deadline ns>:<lifespan s>,<lifespan ns>:<liveliness>,<lease s>,<lease ns>`
//!
//! Policies are written as the numbers of `rmw`'s enums, and a field equal to
//! rmw_zenoh's default is left empty: `::,10:,:,:,,` is reliable, volatile,
//! keep-last 10, no deadline, lifespan or lease, automatic liveliness.

use std::fmt;
use std::str::FromStr;

use super::key::{NumberError, parse_decimal};

/// Declares a policy enum with the `rmw` numbers it is written as.
macro_rules! policy {
    ($(#[$doc:meta])* $name:ident, $what:literal { $($(#[$vdoc:meta])* $variant:ident = $code:literal,)* }) => {
        $(#[$doc])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum $name {
            $($(#[$vdoc])* $variant,)*
        }

        impl $name {
            /// Every value, in the order of their `rmw` numbers.
            pub const ALL: &'static [Self] = &[$(Self::$variant,)*];

            /// The number of `rmw`'s enum that the token carries.
            pub fn code(self) -> u8 {
                match self {
                    $(Self::$variant => $code,)*
                }
            }

            fn from_code(text: &str) -> Result<Self, QosError> {
                match text {
                    $(stringify!($code) => Ok(Self::$variant),)*
                    _ => Err(QosError::UnknownCode { policy: $what, code: text.to_owned() }),
                }
            }
        }
    };
}

policy!(
    /// Whether delivery is retried (`rmw_qos_reliability_policy_e`).
    Reliability, "reliability" {
        /// The middleware's default (rmw_zenoh: reliable).
        SystemDefault = 0,
        /// Retried until delivered.
        Reliable = 1,
        /// May be dropped.
        BestEffort = 2,
        /// Not set.
        Unknown = 3,
        /// Matches the majority of endpoints.
        BestAvailable = 4,
    }
);

policy!(
    /// Whether late joiners get past samples (`rmw_qos_durability_policy_e`).
    Durability, "durability" {
        /// The middleware's default (rmw_zenoh: volatile).
        SystemDefault = 0,
        /// Late joiners get the last `depth` samples.
        TransientLocal = 1,
        /// Only samples published after joining.
        Volatile = 2,
        /// Not set.
        Unknown = 3,
        /// Matches the majority of endpoints.
        BestAvailable = 4,
    }
);

policy!(
    /// How many samples are kept (`rmw_qos_history_policy_e`).
    History, "history" {
        /// The middleware's default (rmw_zenoh: keep last).
        SystemDefault = 0,
        /// The last `depth` samples.
        KeepLast = 1,
        /// Every sample.
        KeepAll = 2,
        /// Not set.
        Unknown = 3,
    }
);

policy!(
    /// How an entity's liveliness is asserted (`rmw_qos_liveliness_policy_e`;
    /// 2, the deprecated `MANUAL_BY_NODE`, is refused as rmw_zenoh does).
    Liveliness, "liveliness" {
        /// The middleware's default (rmw_zenoh: automatic).
        SystemDefault = 0,
        /// Asserted by the middleware.
        Automatic = 1,
        /// Asserted by the application, per topic.
        ManualByTopic = 3,
        /// Not set.
        Unknown = 4,
        /// Matches the majority of endpoints.
        BestAvailable = 5,
    }
);

/// A duration as `rmw_time_t` holds it: seconds and nanoseconds, both
/// unsigned and not normalised (rmw writes both as they are).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct QosDuration {
    /// Whole seconds \[s\].
    pub sec: u64,
    /// Nanoseconds \[ns\] added to `sec`.
    pub nsec: u64,
}

impl QosDuration {
    /// `RMW_DURATION_INFINITE`: no deadline, lifespan or lease.
    pub const INFINITE: Self = Self {
        sec: 9_223_372_036,
        nsec: 854_775_807,
    };
    /// `RMW_DURATION_UNSPECIFIED`: the middleware's default.
    pub const UNSPECIFIED: Self = Self { sec: 0, nsec: 0 };
}

/// A QoS profile, the fields of `rmw_qos_profile_t` that tokens carry.
///
/// The history's kind and its depth are two fields, as in `rmw` and in the
/// compact string, which writes the depth even for keep-all.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Qos {
    /// Reliability.
    pub reliability: Reliability,
    /// Durability.
    pub durability: Durability,
    /// History kind.
    pub history: History,
    /// Samples kept under keep-last, and the cache of a transient-local publisher.
    pub depth: u64,
    /// The period within which samples are expected.
    pub deadline: QosDuration,
    /// The age after which a sample is stale.
    pub lifespan: QosDuration,
    /// Liveliness kind.
    pub liveliness: Liveliness,
    /// The period within which liveliness must be asserted.
    pub liveliness_lease_duration: QosDuration,
}

impl Default for Qos {
    /// rmw_zenoh's default profile, the one whose fields the string leaves
    /// empty: reliable, volatile, keep-last 42, infinite durations, automatic.
    fn default() -> Self {
        Self {
            reliability: Reliability::Reliable,
            durability: Durability::Volatile,
            history: History::KeepLast,
            depth: 42,
            deadline: QosDuration::INFINITE,
            lifespan: QosDuration::INFINITE,
            liveliness: Liveliness::Automatic,
            liveliness_lease_duration: QosDuration::INFINITE,
        }
    }
}

/// Why a string is not a compact QoS.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum QosError {
    /// Not six `:`-separated fields.
    #[error("the QoS `{text}` has {found} `:`-separated fields, not 6")]
    FieldCount {
        /// The string.
        text: String,
        /// Its number of fields.
        found: usize,
    },
    /// A field without its `,`-separated components.
    #[error("the QoS {policy} field `{field}` has {found} `,`-separated parts, not {expected}")]
    PartCount {
        /// Which field.
        policy: &'static str,
        /// The field.
        field: String,
        /// Its number of parts.
        found: usize,
        /// The number it must have.
        expected: usize,
    },
    /// A policy number that `rmw` does not define.
    #[error("the QoS {policy} `{code}` is not one of rmw's values")]
    UnknownCode {
        /// Which policy.
        policy: &'static str,
        /// The text found.
        code: String,
    },
    /// A depth or duration that is not a number.
    #[error("the QoS {part}: {source}")]
    Number {
        /// Which part.
        part: &'static str,
        /// What is wrong.
        source: NumberError,
    },
}

/// `value` as a field: empty when it equals the default.
fn field<T: PartialEq + fmt::Display>(value: T, default: T) -> String {
    if value == default {
        String::new()
    } else {
        value.to_string()
    }
}

/// A policy field: its code, or the default when empty.
fn policy_field<T>(
    text: &str,
    default: T,
    parse: fn(&str) -> Result<T, QosError>,
) -> Result<T, QosError> {
    if text.is_empty() {
        Ok(default)
    } else {
        parse(text)
    }
}

/// A number field: its value, or the default when empty.
fn number_field(text: &str, default: u64, part: &'static str) -> Result<u64, QosError> {
    if text.is_empty() {
        Ok(default)
    } else {
        parse_decimal(text).map_err(|source| QosError::Number { part, source })
    }
}

/// The `,`-separated parts of a field, which must be `N` of them.
fn parts<'a, const N: usize>(
    field: &'a str,
    policy: &'static str,
) -> Result<[&'a str; N], QosError> {
    let found: Vec<&str> = field.split(',').collect();
    <[&str; N]>::try_from(found.as_slice()).map_err(|_| QosError::PartCount {
        policy,
        field: field.to_owned(),
        found: found.len(),
        expected: N,
    })
}

/// A duration from its seconds and nanoseconds parts.
fn duration(
    [sec, nsec]: [&str; 2],
    default: QosDuration,
    part: &'static str,
) -> Result<QosDuration, QosError> {
    Ok(QosDuration {
        sec: number_field(sec, default.sec, part)?,
        nsec: number_field(nsec, default.nsec, part)?,
    })
}

impl Qos {
    /// The default profile with keep-last `depth`.
    pub fn keep_last(depth: u64) -> Self {
        Self {
            history: History::KeepLast,
            depth,
            ..Self::default()
        }
    }

    /// The default profile with keep-all.
    pub fn keep_all() -> Self {
        Self {
            history: History::KeepAll,
            ..Self::default()
        }
    }

    /// This profile, best effort.
    pub fn best_effort(self) -> Self {
        Self {
            reliability: Reliability::BestEffort,
            ..self
        }
    }

    /// This profile, transient local.
    pub fn transient_local(self) -> Self {
        Self {
            durability: Durability::TransientLocal,
            ..self
        }
    }

    /// The compact string, exactly as rmw_zenoh writes it.
    pub fn to_compact(&self) -> String {
        let d = Self::default();
        let duration = |value: QosDuration, default: QosDuration| {
            format!(
                "{},{}",
                field(value.sec, default.sec),
                field(value.nsec, default.nsec)
            )
        };
        format!(
            "{}:{}:{},{}:{}:{}:{},{}",
            field(self.reliability.code(), d.reliability.code()),
            field(self.durability.code(), d.durability.code()),
            field(self.history.code(), d.history.code()),
            field(self.depth, d.depth),
            duration(self.deadline, d.deadline),
            duration(self.lifespan, d.lifespan),
            field(self.liveliness.code(), d.liveliness.code()),
            duration(self.liveliness_lease_duration, d.liveliness_lease_duration),
        )
    }

    /// A compact string parsed back. Fields may hold their default
    /// explicitly; extra fields or parts are refused rather than ignored.
    pub fn parse_compact(text: &str) -> Result<Self, QosError> {
        let fields: Vec<&str> = text.split(':').collect();
        let [
            reliability,
            durability,
            history,
            deadline,
            lifespan,
            liveliness,
        ] = <[&str; 6]>::try_from(fields.as_slice()).map_err(|_| QosError::FieldCount {
            text: text.to_owned(),
            found: fields.len(),
        })?;
        let d = Self::default();
        let [history, depth] = parts::<2>(history, "history")?;
        let [liveliness, lease @ ..] = parts::<3>(liveliness, "liveliness")?;
        Ok(Self {
            reliability: policy_field(reliability, d.reliability, Reliability::from_code)?,
            durability: policy_field(durability, d.durability, Durability::from_code)?,
            history: policy_field(history, d.history, History::from_code)?,
            depth: number_field(depth, d.depth, "depth")?,
            deadline: duration(parts(deadline, "deadline")?, d.deadline, "deadline")?,
            lifespan: duration(parts(lifespan, "lifespan")?, d.lifespan, "lifespan")?,
            liveliness: policy_field(liveliness, d.liveliness, Liveliness::from_code)?,
            liveliness_lease_duration: duration(lease, d.liveliness_lease_duration, "lease")?,
        })
    }
}

impl fmt::Display for Qos {
    /// The compact string ([`Qos::to_compact`]).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.to_compact())
    }
}

impl FromStr for Qos {
    type Err = QosError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        Self::parse_compact(text)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The QoS of the design document's tokens: the listener's and the
    /// services' (keep-last 10) and the talker's (keep-last 7).
    #[test]
    fn the_design_documents_qos_strings() {
        assert_eq!(Qos::keep_last(10).to_compact(), "::,10:,:,:,,");
        assert_eq!(Qos::keep_last(7).to_compact(), "::,7:,:,:,,");
        assert_eq!("::,10:,:,:,,".parse(), Ok(Qos::keep_last(10)));
        assert_eq!(Qos::default().to_compact(), "::,:,:,:,,");
        assert_eq!("::,:,:,:,,".parse(), Ok(Qos::default()));
    }

    /// The example of rmw_zenoh's `qos_to_keyexpr` comment, whose fields are
    /// in the same order (it writes every field; the defaults are empty here).
    #[test]
    fn every_field_in_its_place() {
        let qos = Qos {
            reliability: Reliability::BestEffort,
            durability: Durability::TransientLocal,
            history: History::KeepAll,
            depth: 10,
            deadline: QosDuration { sec: 5, nsec: 0 },
            lifespan: QosDuration {
                sec: 60,
                nsec: 3000,
            },
            liveliness: Liveliness::ManualByTopic,
            liveliness_lease_duration: QosDuration::UNSPECIFIED,
        };
        assert_eq!(qos.to_compact(), "2:1:2,10:5,0:60,3000:3,0,0");
        assert_eq!(Qos::parse_compact("2:1:2,10:5,0:60,3000:3,0,0"), Ok(qos));
        // Explicit defaults read as the defaults.
        assert_eq!(
            Qos::parse_compact("1:2:1,42:9223372036,854775807:,:1,,"),
            Ok(Qos::default())
        );
        assert_eq!(Qos::keep_last(1).best_effort().to_compact(), "2::,1:,:,:,,");
    }

    #[test]
    fn malformed_strings_name_what_is_wrong() {
        assert!(matches!(
            Qos::parse_compact("::,10:,:,:,,:"),
            Err(QosError::FieldCount { found: 7, .. })
        ));
        assert!(matches!(
            Qos::parse_compact("::10:,:,:,,"),
            Err(QosError::PartCount {
                policy: "history",
                ..
            })
        ));
        assert!(matches!(
            Qos::parse_compact("::,10:,:,:,"),
            Err(QosError::PartCount {
                policy: "liveliness",
                ..
            })
        ));
        assert_eq!(
            Qos::parse_compact("9::,10:,:,:,,"),
            Err(QosError::UnknownCode {
                policy: "reliability",
                code: "9".into()
            })
        );
        assert!(matches!(
            Qos::parse_compact("::,:,:,:2,,"),
            Err(QosError::UnknownCode {
                policy: "liveliness",
                ..
            })
        ));
        assert!(matches!(
            Qos::parse_compact("::,-1:,:,:,,"),
            Err(QosError::Number { part: "depth", .. })
        ));
    }
}
