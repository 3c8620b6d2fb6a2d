//! rmw_zenoh's wire format, the strings and bytes a ROS 2 node over Zenoh
//! reads and writes, as a pure library (no Zenoh session here): a bridge uses
//! it from whatever session it has.
//!
//! - [`key`]: the key expression of a topic's data ([`TopicKey`]), with the
//!   type in its DDS form ([`TypeName`]) and the REP 2011 hash ([`TypeHash`]);
//! - [`attachment`]: the 33 bytes beside every sample ([`Attachment`]);
//! - [`gid`]: the GID of a publisher, the hash of its token ([`Gid`]);
//! - [`qos`]: the QoS profile and its compact string in tokens ([`Qos`]);
//! - [`names`]: name checks, qualification and mangling.
//!
//! # Which rmw_zenoh
//! The formats are those of rmw_zenoh_cpp 0.6.7, the release of ROS 2 Kilted,
//! read in its `docs/design.md` and its sources; the unit tests are the design
//! document's own examples.

pub mod attachment;
pub mod gid;
pub mod key;
pub mod names;
pub mod qos;
mod xxh3;

pub use attachment::{ATTACHMENT_LEN, Attachment, AttachmentError};
pub use gid::{GID_LEN, Gid};
pub use key::{
    Interface, KeyError, NumberError, TopicKey, TypeHash, TypeHashError, TypeName, TypeNameError,
};
pub use names::{
    NameError, NameKind, demangle, mangle, qualify_topic, validate_enclave, validate_namespace,
    validate_node_name, validate_topic_name,
};
pub use qos::{Durability, History, Liveliness, Qos, QosDuration, QosError, Reliability};
