//! rmw_zenoh's wire format, the strings and bytes a ROS 2 node over Zenoh
//! reads and writes, as a pure library (no Zenoh session here): a bridge uses
//! it from whatever session it has.
//!
//! - [`key`]: the key expression of a topic's data ([`TopicKey`]), with the
//!   type in its DDS form ([`TypeName`]) and the REP 2011 hash ([`TypeHash`]);
//! - [`attachment`]: the 33 bytes beside every sample ([`Attachment`]);
//! - [`gid`]: the GID of a publisher, the hash of its token ([`Gid`]);
//! - [`token`]: the liveliness tokens of nodes and their publishers,
//!   subscriptions, service servers and clients ([`LivelinessToken`]), made
//!   and parsed, so that our agents are discovered and discover ROS 2 nodes;
//! - [`qos`]: the QoS profile and its compact string in tokens ([`Qos`]);
//! - [`names`]: name checks, qualification and mangling.
//!
//! # Which rmw_zenoh
//! The formats are those of rmw_zenoh_cpp 0.6.7, the release of ROS 2 Kilted
//! (the first ROS 2 release with rmw_zenoh as a tier-1 middleware), read in
//! its `docs/design.md` and its sources (`liveliness_utils.cpp`,
//! `attachment_helpers.cpp`, `qos.cpp`); the unit tests are the design
//! document's own examples. The Lyrical (0.10.5) and Rolling (0.12.0) releases
//! keep them, byte for byte, with one addition: buffer-aware entities (messages
//! with `rosidl::Buffer` fields) end their token with an optional chunk
//! `backends:<name>:<metadata>;...`, which [`LivelinessToken::parse`] keeps
//! and writes back, and publish on extra keys (`<key>/_buf_cpu`,
//! `<key>/_buf/<gid>`) we neither use nor need: every endpoint also keeps the
//! plain key. Jazzy's rmw_zenoh writes the same formats from 0.2.4 on
//! (checked in 0.2.10), but 0.2.0 to 0.2.3 named each field of the
//! attachment, which [`Attachment::decode`] refuses. Humble's (0.1.x) writes
//! `TypeHashNotSupported` for the hash ([`TypeHash::NotSupported`]).

pub mod attachment;
pub mod gid;
pub mod key;
pub mod names;
pub mod qos;
pub mod token;
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
pub use token::{
    ADMIN_SPACE, EndpointKind, EntityToken, LivelinessToken, NodeToken, TokenError, Zid,
    liveliness_subscriber_key,
};
