//! ROS 2 messages as data: a message's package and name, its constants and
//! its fields with their ROS 2 types, and the `.msg` text (`ros2msg`) they
//! render to. The recorder's schemas are made from this model
//! ([`messages`](super::messages)), and so are REP 2011's type descriptions
//! and hashes (the `agent-ros2` crate), so the two cannot disagree.

use std::fmt;

/// A message type's full name: its package and its name
/// (`std_msgs`, `Header`), a message (`msg`) of that package.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct MsgName {
    /// The ROS 2 package (`std_msgs`, `embodied`, `rex_msgs`).
    pub package: String,
    /// The message's name in it (`Header`).
    pub name: String,
}

impl MsgName {
    /// The message `name` of `package`.
    pub fn new(package: impl Into<String>, name: impl Into<String>) -> Self {
        MsgName {
            package: package.into(),
            name: name.into(),
        }
    }

    /// The name as `.msg` files write a field's type and a `MSG:` line:
    /// `std_msgs/Header`.
    pub fn short(&self) -> String {
        format!("{}/{}", self.package, self.name)
    }
}

/// `std_msgs/msg/Header`: the name REP 2011, MCAP's `ros2` profile and the
/// ROS 2 tools give the type.
impl fmt::Display for MsgName {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}/msg/{}", self.package, self.name)
    }
}

/// A ROS 2 primitive type, as `.msg` files name it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[allow(missing_docs, reason = "each variant is the `.msg` type of its name")]
pub enum Primitive {
    Bool,
    /// `byte` (an IDL `octet`).
    Byte,
    /// `char`: an unsigned 8-bit integer in ROS 2 (IDL `uint8`).
    Char,
    Int8,
    Uint8,
    Int16,
    Uint16,
    Int32,
    Uint32,
    Int64,
    Uint64,
    Float32,
    Float64,
}

impl Primitive {
    /// The name in a `.msg` file (`uint32`, `float64`).
    pub fn msg_name(self) -> &'static str {
        match self {
            Primitive::Bool => "bool",
            Primitive::Byte => "byte",
            Primitive::Char => "char",
            Primitive::Int8 => "int8",
            Primitive::Uint8 => "uint8",
            Primitive::Int16 => "int16",
            Primitive::Uint16 => "uint16",
            Primitive::Int32 => "int32",
            Primitive::Uint32 => "uint32",
            Primitive::Int64 => "int64",
            Primitive::Uint64 => "uint64",
            Primitive::Float32 => "float32",
            Primitive::Float64 => "float64",
        }
    }
}

/// What one element of a field is: a primitive, a string or a message.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub enum BaseType {
    /// A primitive.
    Primitive(Primitive),
    /// A UTF-8 string; `Some(n)` is `string<=n` (at most `n` bytes).
    String(Option<usize>),
    /// A message (in any package).
    Message(MsgName),
}

/// How many elements a field holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Arity {
    /// One: `float64 x`.
    One,
    /// Exactly `n` (a static array): `float64[9] covariance`.
    Array(usize),
    /// At most `n` (a bounded sequence): `int32[<=1] k`.
    Bounded(usize),
    /// Any number (an unbounded sequence): `uint8[] data`.
    Unbounded,
}

/// A field's ROS 2 type: its elements' type and how many. ROS 2 nests no
/// arrays in arrays, so an array's elements are a primitive, a string or a
/// message.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct FieldType {
    /// The type of each element.
    pub base: BaseType,
    /// One element, or an array's kind.
    pub arity: Arity,
}

impl FieldType {
    /// One primitive.
    pub fn primitive(p: Primitive) -> Self {
        FieldType {
            base: BaseType::Primitive(p),
            arity: Arity::One,
        }
    }

    /// One unbounded string.
    pub fn string() -> Self {
        FieldType {
            base: BaseType::String(None),
            arity: Arity::One,
        }
    }

    /// One message.
    pub fn message(name: MsgName) -> Self {
        FieldType {
            base: BaseType::Message(name),
            arity: Arity::One,
        }
    }

    /// This element type as a static array of `n`.
    pub fn array(self, n: usize) -> Self {
        FieldType {
            arity: Arity::Array(n),
            ..self
        }
    }

    /// This element type as a sequence of at most `n`.
    pub fn bounded(self, n: usize) -> Self {
        FieldType {
            arity: Arity::Bounded(n),
            ..self
        }
    }

    /// This element type as an unbounded sequence.
    pub fn unbounded(self) -> Self {
        FieldType {
            arity: Arity::Unbounded,
            ..self
        }
    }
}

/// `float64[9]`, `std_msgs/Header`, `string<=8[<=2]`: the type as a `.msg`
/// file writes it.
impl fmt::Display for FieldType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match &self.base {
            BaseType::Primitive(p) => f.write_str(p.msg_name())?,
            BaseType::String(None) => f.write_str("string")?,
            BaseType::String(Some(n)) => write!(f, "string<={n}")?,
            BaseType::Message(m) => f.write_str(&m.short())?,
        }
        match self.arity {
            Arity::One => Ok(()),
            Arity::Array(n) => write!(f, "[{n}]"),
            Arity::Bounded(n) => write!(f, "[<={n}]"),
            Arity::Unbounded => f.write_str("[]"),
        }
    }
}

/// A field of a message: its name and type.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Field {
    /// The name (`frame_id`).
    pub name: String,
    /// The ROS 2 type.
    pub ty: FieldType,
}

impl Field {
    /// The field `name` of type `ty`.
    pub fn new(name: impl Into<String>, ty: FieldType) -> Self {
        Field {
            name: name.into(),
            ty,
        }
    }
}

/// A constant of a message (`uint32 IDLE=0`): the names the recorder gives
/// an enum's variants. Constants are not part of a message's value nor of
/// its REP 2011 type description.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Constant {
    /// The name (`IDLE`).
    pub name: String,
    /// Its primitive type.
    pub ty: Primitive,
    /// The value as the `.msg` file writes it (`0`).
    pub value: String,
}

/// One message type: its name, constants and fields, in order.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Message {
    /// Package and name.
    pub name: MsgName,
    /// The constants, written before the fields.
    pub constants: Vec<Constant>,
    /// The fields, in their order on the wire (none: an empty message,
    /// which CDR encodes as one byte).
    pub fields: Vec<Field>,
}

impl Message {
    /// A message of these fields and no constants.
    pub fn new(name: MsgName, fields: Vec<Field>) -> Self {
        Message {
            name,
            constants: Vec::new(),
            fields,
        }
    }

    /// The definition as a `.msg` file holds it: one line per constant, then
    /// one per field.
    pub fn msg_text(&self) -> String {
        let mut text = String::new();
        for c in &self.constants {
            text.push_str(&format!("{} {}={}\n", c.ty.msg_name(), c.name, c.value));
        }
        for field in &self.fields {
            text.push_str(&format!("{} {}\n", field.ty, field.name));
        }
        text
    }

    /// The messages this one's fields name, in field order, once each.
    pub fn uses(&self) -> Vec<&MsgName> {
        let mut out: Vec<&MsgName> = Vec::new();
        for field in &self.fields {
            if let BaseType::Message(m) = &field.ty.base
                && !out.contains(&m)
            {
                out.push(m);
            }
        }
        out
    }
}

/// A message and every message it uses, directly or not: what a `ros2msg`
/// schema and a REP 2011 type description hold.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Messages {
    /// The message itself.
    pub root: Message,
    /// The others, each once.
    pub referenced: Vec<Message>,
}

impl Messages {
    /// The root's full name.
    pub fn name(&self) -> &MsgName {
        &self.root.name
    }

    /// The message `name` among these.
    pub fn get(&self, name: &MsgName) -> Option<&Message> {
        std::iter::once(&self.root)
            .chain(&self.referenced)
            .find(|m| m.name == *name)
    }

    /// The concatenated definition MCAP's `ros2msg` encoding and ROS 2 bags
    /// use: the root's, then each other's behind a line of 80 `=` and
    /// `MSG: <package>/<Name>`, in the order of `referenced`.
    pub fn msg_text(&self) -> String {
        let mut text = self.root.msg_text();
        for m in &self.referenced {
            text.push_str(&"=".repeat(80));
            text.push_str(&format!("\nMSG: {}\n", m.name.short()));
            text.push_str(&m.msg_text());
        }
        text
    }

    /// These messages with every name, theirs and their fields' nested
    /// types', replaced by `rename`'s (to put a message made from a Rust type
    /// into the package and name ROS 2 knows it by).
    pub fn renamed(&self, rename: impl Fn(&MsgName) -> MsgName) -> Messages {
        let message = |m: &Message| Message {
            name: rename(&m.name),
            constants: m.constants.clone(),
            fields: m
                .fields
                .iter()
                .map(|f| {
                    let base = match &f.ty.base {
                        BaseType::Message(n) => BaseType::Message(rename(n)),
                        other => other.clone(),
                    };
                    let ty = FieldType {
                        base,
                        arity: f.ty.arity,
                    };
                    Field::new(f.name.clone(), ty)
                })
                .collect(),
        };
        Messages {
            root: message(&self.root),
            referenced: self.referenced.iter().map(message).collect(),
        }
    }
}
