//! ROS 2 message types as data: the messages of a buffer type (made by the
//! recorder's mapping, [`agent_mcap::cdr::messages`], in a package named for
//! ROS 2, `rex_msgs` say), the standard messages a ROS user expects
//! ([`standard`]), their REP 2011 type descriptions and `RIHS01_` hashes
//! ([`TypeDescription`], [`type_hash`]), and values encoded as the CDR those
//! messages describe ([`encode_cdr`]).
//!
//! ```
//! use agent_ros2::types::standard::{StandardMessage, geometry_msgs::PoseStamped};
//! use agent_ros2::types::type_hash;
//!
//! let messages = PoseStamped::messages();
//! assert_eq!(messages.name().to_string(), "geometry_msgs/msg/PoseStamped");
//! let hash = type_hash(&messages).unwrap().to_string();
//! assert!(hash.starts_with("RIHS01_") && hash.len() == 7 + 64);
//! ```

use agent_core::trace::ErasedPayload;
use agent_core::{Payload, TypeShape};
use agent_mcap::cdr::write_cdr;

mod description;
pub mod standard;

pub use agent_mcap::cdr::{
    Arity, BaseType, Constant, DecodeError, Field, FieldType, Message, Messages, MsgName,
    Primitive, Unsupported, messages,
};
pub use description::{
    DescriptionError, EMPTY_MESSAGE_FIELD, FieldDescription, FieldTypeDescription,
    IndividualTypeDescription, TypeDescription, type_hash,
};

/// Why a value has no CDR form.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum EncodeError {
    /// Serde refused the value.
    #[error(transparent)]
    Value(#[from] agent_core::trace::EncodeError),
    /// The value does not have the shape given.
    #[error("the value does not have the shape given: {0}")]
    Shape(#[from] DecodeError),
}

/// `root` and the messages among `known` that it uses, directly or not, in
/// order of name; a message that `known` lacks is left out (and
/// [`TypeDescription::of`] then says which).
pub fn with_references(root: Message, known: &[Message]) -> Messages {
    let mut referenced: Vec<Message> = Vec::new();
    let mut queue: Vec<MsgName> = root.uses().into_iter().cloned().collect();
    while let Some(name) = queue.pop() {
        if name == root.name || referenced.iter().any(|m| m.name == name) {
            continue;
        }
        if let Some(m) = known.iter().find(|m| m.name == name) {
            queue.extend(m.uses().into_iter().cloned());
            referenced.push(m.clone());
        }
    }
    referenced.sort_by(|a, b| a.name.cmp(&b.name));
    Messages { root, referenced }
}

/// `value` as a ROS 2 CDR message (the 4-byte encapsulation header, then the
/// little-endian body) of the messages [`messages`] makes for `shape`, which
/// is `value`'s type's ([`agent_core::reflect`]), appended to `out`. For a
/// [`standard`] type that is its standard message. On an error `out` holds a
/// part of the message.
pub fn encode_cdr<T: Payload>(
    value: &T,
    shape: &TypeShape,
    out: &mut Vec<u8>,
) -> Result<(), EncodeError> {
    let mut bytes = Vec::new();
    value.encode(&mut bytes)?;
    write_cdr(shape, &bytes, out)?;
    Ok(())
}

#[cfg(test)]
mod tests;
