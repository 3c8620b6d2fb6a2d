//! The key expression of a topic's (or a service's) data:
//! `<domain>/<fully qualified name without its leading />/<DDS type name>/<type hash>`,
//! with the type written as DDS knows it (`std_msgs::msg::dds_::String_`) and
//! the hash as REP 2011 prints it (`RIHS01_<64 hex digits>`).

use std::fmt;
use std::str::FromStr;

use super::names::{NameError, validate_topic_name};

/// Why a decimal number in a key is not one.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum NumberError {
    /// The field is empty.
    #[error("an empty number")]
    Empty,
    /// A character other than an ASCII digit.
    #[error("`{text}` is not a decimal number")]
    NotDecimal {
        /// The text.
        text: String,
    },
    /// Too large for the field.
    #[error("`{text}` is too large")]
    TooLarge {
        /// The text.
        text: String,
    },
}

/// A decimal number of ASCII digits only (no sign, no spaces), as rmw_zenoh
/// writes ids, depths and durations.
pub(crate) fn parse_decimal<T: FromStr>(text: &str) -> Result<T, NumberError> {
    if text.is_empty() {
        return Err(NumberError::Empty);
    }
    if !text.bytes().all(|b| b.is_ascii_digit()) {
        return Err(NumberError::NotDecimal {
            text: text.to_owned(),
        });
    }
    // Digits only, so the one way left to fail is overflow.
    text.parse().map_err(|_| NumberError::TooLarge {
        text: text.to_owned(),
    })
}

/// The kind of interface a type belongs to: the middle part of `pkg/msg/Type`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Interface {
    /// A message (`msg`).
    Msg,
    /// A service, or its request or response (`srv`).
    Srv,
    /// An action's parts (`action`).
    Action,
}

impl Interface {
    /// The folder name of the interface kind (`msg`, `srv`, `action`).
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Msg => "msg",
            Self::Srv => "srv",
            Self::Action => "action",
        }
    }

    fn parse(text: &str) -> Option<Self> {
        match text {
            "msg" => Some(Self::Msg),
            "srv" => Some(Self::Srv),
            "action" => Some(Self::Action),
            _ => None,
        }
    }
}

/// Why a type name is not a ROS 2 interface type.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TypeNameError {
    /// Not `package/kind/Name`.
    #[error("the type name `{name}` is not `package/msg/Name` (three parts separated by `/`)")]
    NotThreeParts {
        /// The name.
        name: String,
    },
    /// The middle part is not `msg`, `srv` or `action`.
    #[error("the type name `{name}` has `{kind}` where `msg`, `srv` or `action` belongs")]
    UnknownInterface {
        /// The name.
        name: String,
        /// The middle part.
        kind: String,
    },
    /// The package or type part is not an identifier.
    #[error(
        "the type name `{name}` has `{part}`, not an identifier (an ASCII letter, then letters, digits and `_`)"
    )]
    NotIdentifier {
        /// The name.
        name: String,
        /// The part.
        part: String,
    },
    /// Not the DDS form `package::msg::dds_::Name_`.
    #[error("`{name}` is not a DDS type name of the form `package::msg::dds_::Name_`")]
    NotDds {
        /// The text.
        name: String,
    },
}

/// A ROS 2 interface type, `std_msgs/msg/String`, which rmw_zenoh writes in
/// keys in its DDS form `std_msgs::msg::dds_::String_`.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct TypeName {
    package: String,
    interface: Interface,
    name: String,
}

fn is_identifier(text: &str) -> bool {
    text.starts_with(|c: char| c.is_ascii_alphabetic())
        && text.bytes().all(|b| b.is_ascii_alphanumeric() || b == b'_')
}

impl TypeName {
    /// The type `name` of `package`'s `interface` kind, both identifiers.
    pub fn new(package: &str, interface: Interface, name: &str) -> Result<Self, TypeNameError> {
        let whole = format!("{package}/{}/{name}", interface.as_str());
        for part in [package, name] {
            if !is_identifier(part) {
                return Err(TypeNameError::NotIdentifier {
                    name: whole,
                    part: part.to_owned(),
                });
            }
        }
        Ok(Self {
            package: package.to_owned(),
            interface,
            name: name.to_owned(),
        })
    }

    /// The package (`std_msgs`).
    pub fn package(&self) -> &str {
        &self.package
    }

    /// The interface kind (`msg`).
    pub fn interface(&self) -> Interface {
        self.interface
    }

    /// The type's own name (`String`).
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The DDS form rmw_zenoh puts in keys and tokens: `std_msgs::msg::dds_::String_`.
    pub fn dds(&self) -> String {
        format!(
            "{}::{}::dds_::{}_",
            self.package,
            self.interface.as_str(),
            self.name
        )
    }

    /// A type from its DDS form (`std_msgs::msg::dds_::String_`).
    pub fn parse_dds(text: &str) -> Result<Self, TypeNameError> {
        let not_dds = || TypeNameError::NotDds {
            name: text.to_owned(),
        };
        let (scope, rest) = text.split_once("::dds_::").ok_or_else(not_dds)?;
        let name = rest.strip_suffix('_').ok_or_else(not_dds)?;
        let (package, kind) = scope.split_once("::").ok_or_else(not_dds)?;
        let interface = Interface::parse(kind).ok_or_else(|| TypeNameError::UnknownInterface {
            name: text.to_owned(),
            kind: kind.to_owned(),
        })?;
        Self::new(package, interface, name)
    }
}

impl fmt::Display for TypeName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}/{}/{}",
            self.package,
            self.interface.as_str(),
            self.name
        )
    }
}

impl FromStr for TypeName {
    type Err = TypeNameError;

    /// A type from its ROS form, `std_msgs/msg/String`.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let mut parts = text.split('/');
        let (Some(package), Some(kind), Some(name), None) =
            (parts.next(), parts.next(), parts.next(), parts.next())
        else {
            return Err(TypeNameError::NotThreeParts {
                name: text.to_owned(),
            });
        };
        let interface = Interface::parse(kind).ok_or_else(|| TypeNameError::UnknownInterface {
            name: text.to_owned(),
            kind: kind.to_owned(),
        })?;
        Self::new(package, interface, name)
    }
}

/// The prefix of a REP 2011 type hash of version 1.
const RIHS01_PREFIX: &str = "RIHS01_";
/// What Humble's rmw_zenoh writes where a hash belongs.
const NOT_SUPPORTED: &str = "TypeHashNotSupported";

/// Why a type hash string is not one.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TypeHashError {
    /// Neither `RIHS01_...` nor `TypeHashNotSupported`.
    #[error("`{text}` is neither `RIHS01_<64 hex digits>` nor `TypeHashNotSupported`")]
    UnknownForm {
        /// The text.
        text: String,
    },
    /// `RIHS01_` not followed by 64 lowercase hex digits.
    #[error("`{text}` does not have 64 lowercase hex digits after `RIHS01_`")]
    BadDigits {
        /// The text.
        text: String,
    },
}

/// A type's hash as keys and tokens carry it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TypeHash {
    /// REP 2011 version 1: the SHA-256 of the type description.
    Rihs01([u8; 32]),
    /// `TypeHashNotSupported`, from ROS 2 releases before type hashes (Humble).
    NotSupported,
}

impl fmt::Display for TypeHash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Self::Rihs01(digest) => {
                f.write_str(RIHS01_PREFIX)?;
                digest.iter().try_for_each(|byte| write!(f, "{byte:02x}"))
            }
            Self::NotSupported => f.write_str(NOT_SUPPORTED),
        }
    }
}

fn lower_hex_digit(byte: u8) -> Option<u8> {
    match byte {
        b'0'..=b'9' => Some(byte - b'0'),
        b'a'..=b'f' => Some(byte - b'a' + 10),
        _ => None,
    }
}

impl FromStr for TypeHash {
    type Err = TypeHashError;

    fn from_str(text: &str) -> Result<Self, Self::Err> {
        if text == NOT_SUPPORTED {
            return Ok(Self::NotSupported);
        }
        let Some(digits) = text.strip_prefix(RIHS01_PREFIX) else {
            return Err(TypeHashError::UnknownForm {
                text: text.to_owned(),
            });
        };
        let bad = || TypeHashError::BadDigits {
            text: text.to_owned(),
        };
        if digits.len() != 64 {
            return Err(bad());
        }
        let mut digest = [0u8; 32];
        for (byte, pair) in digest.iter_mut().zip(digits.as_bytes().chunks_exact(2)) {
            let high = lower_hex_digit(pair[0]).ok_or_else(bad)?;
            let low = lower_hex_digit(pair[1]).ok_or_else(bad)?;
            *byte = (high << 4) | low;
        }
        Ok(Self::Rihs01(digest))
    }
}

/// Why a key expression is not a topic's data key.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum KeyError {
    /// Fewer than the four parts `<domain>/<name>/<type>/<hash>`.
    #[error(
        "the key `{key}` has {found} chunks, fewer than the 4 of `<domain>/<name>/<type>/<hash>`"
    )]
    TooFewChunks {
        /// The key.
        key: String,
        /// Its number of `/`-separated chunks.
        found: usize,
    },
    /// The domain id is not a number.
    #[error("the domain id of the key: {0}")]
    Domain(NumberError),
    /// The topic name is not a valid one.
    #[error(transparent)]
    Topic(#[from] NameError),
    /// The type is not a DDS type name.
    #[error(transparent)]
    TypeName(#[from] TypeNameError),
    /// The hash is not a type hash.
    #[error(transparent)]
    TypeHash(#[from] TypeHashError),
}

/// The key a topic's (or a service's) data travels on: what a publisher puts
/// to and a subscriber subscribes to, so that only the same domain, name, type
/// and type hash meet.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct TopicKey {
    domain: u32,
    topic: String,
    type_name: TypeName,
    type_hash: TypeHash,
}

impl TopicKey {
    /// The key of the fully qualified `topic` (`/chatter`) in `domain`.
    pub fn new(
        domain: u32,
        topic: &str,
        type_name: TypeName,
        type_hash: TypeHash,
    ) -> Result<Self, NameError> {
        validate_topic_name(topic)?;
        Ok(Self {
            domain,
            topic: topic.to_owned(),
            type_name,
            type_hash,
        })
    }

    /// The key of a topic name already checked by [`validate_topic_name`].
    pub(crate) fn from_checked(
        domain: u32,
        topic: String,
        type_name: TypeName,
        type_hash: TypeHash,
    ) -> Self {
        Self {
            domain,
            topic,
            type_name,
            type_hash,
        }
    }

    /// The ROS domain id.
    pub fn domain(&self) -> u32 {
        self.domain
    }

    /// The fully qualified topic name, with its leading `/`.
    pub fn topic(&self) -> &str {
        &self.topic
    }

    /// The message (or service) type.
    pub fn type_name(&self) -> &TypeName {
        &self.type_name
    }

    /// The type's hash.
    pub fn type_hash(&self) -> &TypeHash {
        &self.type_hash
    }

    /// A key expression parsed back: its topic name may have several chunks.
    pub fn parse(key: &str) -> Result<Self, KeyError> {
        let chunks: Vec<&str> = key.split('/').collect();
        let [domain, name @ .., type_name, type_hash] = chunks.as_slice() else {
            return Err(KeyError::TooFewChunks {
                key: key.to_owned(),
                found: chunks.len(),
            });
        };
        if name.is_empty() {
            return Err(KeyError::TooFewChunks {
                key: key.to_owned(),
                found: chunks.len(),
            });
        }
        let domain = parse_decimal(domain).map_err(KeyError::Domain)?;
        let topic = format!("/{}", name.join("/"));
        let type_name = TypeName::parse_dds(type_name)?;
        let type_hash = type_hash.parse()?;
        Ok(Self::new(domain, &topic, type_name, type_hash)?)
    }
}

impl fmt::Display for TopicKey {
    /// The key expression, `0/chatter/std_msgs::msg::dds_::String_/RIHS01_...`.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        // The name is valid, so it starts with `/` and does not end with one.
        let name = self.topic.strip_prefix('/').unwrap_or(&self.topic);
        write!(
            f,
            "{}/{}/{}/{}",
            self.domain,
            name,
            self.type_name.dds(),
            self.type_hash
        )
    }
}

impl FromStr for TopicKey {
    type Err = KeyError;

    fn from_str(key: &str) -> Result<Self, Self::Err> {
        Self::parse(key)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const STRING_HASH: &str =
        "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18";
    const ADD_TWO_INTS_HASH: &str =
        "RIHS01_e118de6bf5eeb66a2491b5bda11202e7b68f198d6f67922cf30364858239c81a";

    fn key(domain: u32, topic: &str, type_name: &str, hash: &str) -> TopicKey {
        TopicKey::new(
            domain,
            topic,
            type_name.parse().unwrap(),
            hash.parse().unwrap(),
        )
        .unwrap()
    }

    /// The three examples of the design document's key expression section.
    #[test]
    fn the_design_documents_keys_are_made_and_parsed() {
        let examples = [
            (
                key(0, "/chatter", "std_msgs/msg/String", STRING_HASH),
                format!("0/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"),
            ),
            (
                key(0, "/robot1/chatter", "std_msgs/msg/String", STRING_HASH),
                format!("0/robot1/chatter/std_msgs::msg::dds_::String_/{STRING_HASH}"),
            ),
            (
                key(
                    2,
                    "/add_two_ints",
                    "example_interfaces/srv/AddTwoInts",
                    ADD_TWO_INTS_HASH,
                ),
                format!(
                    "2/add_two_ints/example_interfaces::srv::dds_::AddTwoInts_/{ADD_TWO_INTS_HASH}"
                ),
            ),
        ];
        for (key, text) in examples {
            assert_eq!(key.to_string(), text);
            assert_eq!(TopicKey::parse(&text), Ok(key));
        }
    }

    #[test]
    fn humble_keys_carry_no_hash() {
        let text = "0/chatter/std_msgs::msg::dds_::String_/TypeHashNotSupported";
        let parsed = TopicKey::parse(text).unwrap();
        assert_eq!(parsed.type_hash(), &TypeHash::NotSupported);
        assert_eq!(parsed.topic(), "/chatter");
        assert_eq!(parsed.to_string(), text);
    }

    #[test]
    fn type_names_convert_between_ros_and_dds_forms() {
        let name: TypeName = "geometry_msgs/msg/PoseStamped".parse().unwrap();
        assert_eq!(name.dds(), "geometry_msgs::msg::dds_::PoseStamped_");
        assert_eq!(TypeName::parse_dds(&name.dds()), Ok(name.clone()));
        assert_eq!(name.to_string(), "geometry_msgs/msg/PoseStamped");
        assert!(matches!(
            "std_msgs/String".parse::<TypeName>(),
            Err(TypeNameError::NotThreeParts { .. })
        ));
        assert!(matches!(
            "std_msgs/idl/String".parse::<TypeName>(),
            Err(TypeNameError::UnknownInterface { .. })
        ));
        assert!(matches!(
            "std-msgs/msg/String".parse::<TypeName>(),
            Err(TypeNameError::NotIdentifier { .. })
        ));
        assert!(matches!(
            TypeName::parse_dds("std_msgs::msg::String"),
            Err(TypeNameError::NotDds { .. })
        ));
    }

    #[test]
    fn malformed_keys_name_what_is_wrong() {
        let good_tail = format!("std_msgs::msg::dds_::String_/{STRING_HASH}");
        assert!(matches!(
            TopicKey::parse(&format!("0/{good_tail}")),
            Err(KeyError::TooFewChunks { found: 3, .. })
        ));
        assert!(matches!(
            TopicKey::parse(&format!("x/chatter/{good_tail}")),
            Err(KeyError::Domain(NumberError::NotDecimal { .. }))
        ));
        assert!(matches!(
            TopicKey::parse(&format!("4294967296/chatter/{good_tail}")),
            Err(KeyError::Domain(NumberError::TooLarge { .. }))
        ));
        assert!(matches!(
            TopicKey::parse(&format!("0/chat*ter/{good_tail}")),
            Err(KeyError::Topic(NameError::InvalidCharacter { .. }))
        ));
        assert!(matches!(
            TopicKey::parse("0/chatter/std_msgs::msg::dds_::String_/RIHS02_00"),
            Err(KeyError::TypeHash(TypeHashError::UnknownForm { .. }))
        ));
        let upper = STRING_HASH.to_uppercase();
        assert!(matches!(
            upper.parse::<TypeHash>(),
            Err(TypeHashError::BadDigits { .. })
        ));
    }
}
