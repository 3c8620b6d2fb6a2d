//! REP 2011's type description of a message and its `RIHS01_` hash.
//!
//! A type description is the message and every message it refers to,
//! directly or not (sorted by name), each a list of fields with a field
//! type id, a capacity (an array's size or a sequence's bound), a string
//! capacity and the nested type's name. Constants and default values are not
//! part of it. The hash is the SHA-256 of its canonical JSON: the keys in the
//! order of `type_description_interfaces`' messages, `", "` and `": "` as
//! separators, non-ASCII escaped (Python's `json.dumps` as
//! `rosidl_generator_type_description` calls it).

use std::collections::BTreeSet;
use std::fmt::Write as _;

use agent_mcap::cdr::{Arity, BaseType, Field, FieldType, Message, Messages, MsgName, Primitive};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::wire::TypeHash;

/// The field ROS 2 gives a message without fields, so that every structure
/// has one (`uint8`, as CDR's one byte for an empty message).
pub const EMPTY_MESSAGE_FIELD: &str = "structure_needs_at_least_one_member";

/// Why messages have no type description.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum DescriptionError {
    /// A field names a message the set does not hold.
    #[error("the field `{field}` of `{message}` is a `{missing}`, which is not among the messages")]
    Missing {
        /// The message whose field it is (`pkg/msg/Name`).
        message: String,
        /// The field.
        field: String,
        /// The message it names.
        missing: String,
    },
}

/// A field's type in a type description (`type_description_interfaces/msg/FieldType`).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FieldTypeDescription {
    /// The kind of element, plus 48 for a static array, 96 for a bounded
    /// sequence, 144 for an unbounded one (`FieldType`'s constants).
    pub type_id: u8,
    /// A static array's size or a bounded sequence's bound; else 0.
    pub capacity: u64,
    /// A bounded string's bound; else 0.
    pub string_capacity: u64,
    /// A nested message's full name (`std_msgs/msg/Header`); else empty.
    pub nested_type_name: String,
}

/// A field in a type description (`type_description_interfaces/msg/Field`,
/// without its default value, which the hash leaves out).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FieldDescription {
    /// The field's name.
    pub name: String,
    /// Its type.
    #[serde(rename = "type")]
    pub ty: FieldTypeDescription,
}

/// One message in a type description
/// (`type_description_interfaces/msg/IndividualTypeDescription`).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct IndividualTypeDescription {
    /// `std_msgs/msg/Header`.
    pub type_name: String,
    /// The fields, in order.
    pub fields: Vec<FieldDescription>,
}

/// A message's type description (`type_description_interfaces/msg/TypeDescription`).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TypeDescription {
    /// The message.
    pub type_description: IndividualTypeDescription,
    /// Every message it refers to, directly or not, sorted by name.
    pub referenced_type_descriptions: Vec<IndividualTypeDescription>,
}

impl TypeDescription {
    /// The description of `messages`' root: it and the messages reachable
    /// from it through their fields, found among `messages`.
    pub fn of(messages: &Messages) -> Result<TypeDescription, DescriptionError> {
        // As rosidl: the names reached from the root's fields, sorted.
        let mut reached = BTreeSet::new();
        let mut queue = nested(&messages.root);
        while let Some((from, field, name)) = queue.pop() {
            if reached.contains(&name) {
                continue;
            }
            let Some(m) = messages.get(name) else {
                return Err(DescriptionError::Missing {
                    message: from.to_string(),
                    field: field.to_owned(),
                    missing: name.to_string(),
                });
            };
            reached.insert(name);
            queue.extend(nested(m));
        }
        let referenced = reached
            .into_iter()
            .filter_map(|name| messages.get(name))
            .map(individual);
        let mut referenced: Vec<_> = referenced.collect();
        referenced.sort_by(|a, b| a.type_name.cmp(&b.type_name));
        Ok(TypeDescription {
            type_description: individual(&messages.root),
            referenced_type_descriptions: referenced,
        })
    }

    /// The canonical JSON REP 2011 hashes.
    pub fn canonical_json(&self) -> String {
        let mut out = String::from("{\"type_description\": ");
        write_individual(&mut out, &self.type_description);
        out.push_str(", \"referenced_type_descriptions\": [");
        for (k, t) in self.referenced_type_descriptions.iter().enumerate() {
            if k > 0 {
                out.push_str(", ");
            }
            write_individual(&mut out, t);
        }
        out.push_str("]}");
        out
    }

    /// The `RIHS01_` hash of this description ([`TypeHash::Rihs01`]).
    pub fn hash(&self) -> TypeHash {
        TypeHash::Rihs01(Sha256::digest(self.canonical_json().as_bytes()).into())
    }
}

/// The `RIHS01_` hash of `messages`' root (see [`TypeDescription::of`]).
pub fn type_hash(messages: &Messages) -> Result<TypeHash, DescriptionError> {
    Ok(TypeDescription::of(messages)?.hash())
}

/// `(message, field, nested type)` for each field of `m` that is a message.
fn nested(m: &Message) -> Vec<(&MsgName, &str, &MsgName)> {
    m.fields
        .iter()
        .filter_map(|f| match &f.ty.base {
            BaseType::Message(n) => Some((&m.name, f.name.as_str(), n)),
            _ => None,
        })
        .collect()
}

fn individual(m: &Message) -> IndividualTypeDescription {
    let fields = if m.fields.is_empty() {
        let dummy = Field::new(EMPTY_MESSAGE_FIELD, FieldType::primitive(Primitive::Uint8));
        vec![field(&dummy)]
    } else {
        m.fields.iter().map(field).collect()
    };
    IndividualTypeDescription {
        type_name: m.name.to_string(),
        fields,
    }
}

fn field(f: &Field) -> FieldDescription {
    let (element, string_capacity, nested_type_name) = match &f.ty.base {
        BaseType::Primitive(p) => (primitive_id(*p), 0, String::new()),
        BaseType::String(None) => (17, 0, String::new()),
        BaseType::String(Some(n)) => (21, *n as u64, String::new()),
        BaseType::Message(m) => (1, 0, m.to_string()),
    };
    let (offset, capacity) = match f.ty.arity {
        Arity::One => (0, 0),
        Arity::Array(n) => (48, n as u64),
        Arity::Bounded(n) => (96, n as u64),
        Arity::Unbounded => (144, 0),
    };
    FieldDescription {
        name: f.name.clone(),
        ty: FieldTypeDescription {
            type_id: element + offset,
            capacity,
            string_capacity,
            nested_type_name,
        },
    }
}

/// `FieldType`'s id of a primitive (`char` is IDL's `uint8` in ROS 2,
/// `byte` its `octet`).
fn primitive_id(p: Primitive) -> u8 {
    match p {
        Primitive::Int8 => 2,
        Primitive::Uint8 | Primitive::Char => 3,
        Primitive::Int16 => 4,
        Primitive::Uint16 => 5,
        Primitive::Int32 => 6,
        Primitive::Uint32 => 7,
        Primitive::Int64 => 8,
        Primitive::Uint64 => 9,
        Primitive::Float32 => 10,
        Primitive::Float64 => 11,
        Primitive::Bool => 15,
        Primitive::Byte => 16,
    }
}

fn write_individual(out: &mut String, t: &IndividualTypeDescription) {
    out.push_str("{\"type_name\": ");
    write_string(out, &t.type_name);
    out.push_str(", \"fields\": [");
    for (k, f) in t.fields.iter().enumerate() {
        if k > 0 {
            out.push_str(", ");
        }
        out.push_str("{\"name\": ");
        write_string(out, &f.name);
        let _ = write!(
            out,
            ", \"type\": {{\"type_id\": {}, \"capacity\": {}, \"string_capacity\": {}, \
             \"nested_type_name\": ",
            f.ty.type_id, f.ty.capacity, f.ty.string_capacity
        );
        write_string(out, &f.ty.nested_type_name);
        out.push_str("}}");
    }
    out.push_str("]}");
}

/// A JSON string as Python's `json.dumps` writes it with `ensure_ascii`:
/// printable ASCII as it is, the rest escaped (UTF-16 units).
fn write_string(out: &mut String, s: &str) {
    out.push('"');
    for c in s.chars() {
        match c {
            '"' => out.push_str("\\\""),
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            '\u{8}' => out.push_str("\\b"),
            '\u{c}' => out.push_str("\\f"),
            ' '..='~' => out.push(c),
            _ => {
                let mut units = [0u16; 2];
                for u in c.encode_utf16(&mut units) {
                    let _ = write!(out, "\\u{u:04x}");
                }
            }
        }
    }
    out.push('"');
}
