//! Liveliness tokens, by which ROS 2 nodes over rmw_zenoh discover each other:
//! each node and each publisher, subscription, service server and client
//! declares one while it lives, under the hermetic prefix `@ros2_lv` (which a
//! `**` never matches: subscribe to [`liveliness_subscriber_key`]).
//!
//! - node: `@ros2_lv/<domain>/<zid>/<node id>/<node id>/NN/<enclave>/<namespace>/<node>`
//! - entity: `@ros2_lv/<domain>/<zid>/<node id>/<entity id>/<MP|MS|SS|SC>/<enclave>/<namespace>/<node>/<topic>/<DDS type>/<type hash>/<qos>`
//!
//! with the enclave, namespace, node, topic, type and hash mangled ([`mangle`])
//! and the QoS compact ([`Qos::to_compact`]). ROS 2 Lyrical adds an optional
//! last chunk `backends:...` for buffer-aware entities; a parse keeps it as
//! it is and writes it back.

use std::fmt;
use std::str::FromStr;

use super::gid::Gid;
use super::key::{
    NumberError, TopicKey, TypeHash, TypeHashError, TypeName, TypeNameError, parse_decimal,
};
use super::names::{
    NameError, demangle, mangle, validate_enclave, validate_namespace, validate_node_name,
    validate_topic_name,
};
use super::qos::{Qos, QosError};

/// The first chunk of every token: rmw_zenoh's admin space.
pub const ADMIN_SPACE: &str = "@ros2_lv";

/// The first chunk of Lyrical's optional last chunk.
const BACKENDS_PREFIX: &str = "backends:";

/// The key expression that matches every token of `domain`.
pub fn liveliness_subscriber_key(domain: u32) -> String {
    format!("{ADMIN_SPACE}/{domain}/**")
}

/// A Zenoh session id as tokens carry it: lowercase hex without leading
/// zeros, as Zenoh prints its ids (the `u128` of the id's little-endian bytes).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Zid(u128);

impl Zid {
    /// The id whose value is `value`.
    pub const fn new(value: u128) -> Self {
        Self(value)
    }

    /// The id of a Zenoh session from its bytes (`ZenohId::to_le_bytes`).
    pub const fn from_le_bytes(bytes: [u8; 16]) -> Self {
        Self(u128::from_le_bytes(bytes))
    }

    /// The id's bytes, little-endian as Zenoh holds them.
    pub const fn to_le_bytes(self) -> [u8; 16] {
        self.0.to_le_bytes()
    }
}

impl fmt::Display for Zid {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{:x}", self.0)
    }
}

impl FromStr for Zid {
    type Err = TokenError;

    /// One to 32 lowercase hex digits.
    fn from_str(text: &str) -> Result<Self, Self::Err> {
        let hex = (1..=32).contains(&text.len())
            && text.bytes().all(|b| matches!(b, b'0'..=b'9' | b'a'..=b'f'));
        let value = hex.then(|| u128::from_str_radix(text, 16).ok()).flatten();
        value.map(Self).ok_or_else(|| TokenError::Zid {
            chunk: text.to_owned(),
        })
    }
}

/// What kind of endpoint an entity token announces.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum EndpointKind {
    /// `MP`: a message publisher.
    Publisher,
    /// `MS`: a message subscription.
    Subscription,
    /// `SS`: a service server.
    ServiceServer,
    /// `SC`: a service client.
    ServiceClient,
}

impl EndpointKind {
    /// Every kind.
    pub const ALL: [Self; 4] = [
        Self::Publisher,
        Self::Subscription,
        Self::ServiceServer,
        Self::ServiceClient,
    ];

    /// The two letters of the token.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Publisher => "MP",
            Self::Subscription => "MS",
            Self::ServiceServer => "SS",
            Self::ServiceClient => "SC",
        }
    }
}

/// The two letters of a node's token.
const NODE_KIND: &str = "NN";

/// Why a key expression is not a liveliness token.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TokenError {
    /// The first chunk is not `@ros2_lv`.
    #[error("`{key}` is not under `{ADMIN_SPACE}`")]
    NotLiveliness {
        /// The key.
        key: String,
    },
    /// Neither a node's 9 chunks nor an entity's 13 (or 14 with backends).
    #[error("the token `{key}` has {found} chunks: a node's has 9, an entity's 13 or 14")]
    ChunkCount {
        /// The key.
        key: String,
        /// Its number of chunks.
        found: usize,
    },
    /// A chunk is empty (`//`).
    #[error("the token `{key}` has an empty chunk at {index}")]
    EmptyChunk {
        /// The key.
        key: String,
        /// The chunk's index.
        index: usize,
    },
    /// The domain id is not a number.
    #[error("the token's domain id: {0}")]
    Domain(NumberError),
    /// The Zenoh session id is not one.
    #[error("the token's Zenoh session id `{chunk}` is not 1 to 32 lowercase hex digits")]
    Zid {
        /// The chunk.
        chunk: String,
    },
    /// The node id is not a number.
    #[error("the token's node id: {0}")]
    NodeId(NumberError),
    /// The entity id is not a number.
    #[error("the token's entity id: {0}")]
    EntityId(NumberError),
    /// The kind is none of `NN`, `MP`, `MS`, `SS`, `SC`.
    #[error("the token's entity kind `{kind}` is none of NN, MP, MS, SS, SC")]
    UnknownKind {
        /// The chunk.
        kind: String,
    },
    /// The number of chunks does not fit the kind.
    #[error("the token `{key}` of kind {kind} has {found} chunks")]
    KindChunkCount {
        /// The key.
        key: String,
        /// The kind's letters.
        kind: String,
        /// Its number of chunks.
        found: usize,
    },
    /// A node's token whose two ids differ.
    #[error("the node token has node id {node_id} but entity id {entity_id}")]
    NodeIdMismatch {
        /// The node id.
        node_id: u64,
        /// The entity id.
        entity_id: u64,
    },
    /// A name is not valid.
    #[error(transparent)]
    Name(#[from] NameError),
    /// The type is not a DDS type name.
    #[error(transparent)]
    TypeName(#[from] TypeNameError),
    /// The type hash is not one.
    #[error(transparent)]
    TypeHash(#[from] TypeHashError),
    /// The QoS is not a compact QoS.
    #[error(transparent)]
    Qos(#[from] QosError),
    /// The last chunk is not Lyrical's `backends:...`.
    #[error("the token's last chunk `{chunk}` does not start with `backends:`")]
    Backends {
        /// The chunk.
        chunk: String,
    },
}

/// A node's token: which node, in which session and domain.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct NodeToken {
    domain: u32,
    zid: Zid,
    node_id: u64,
    enclave: String,
    namespace: String,
    name: String,
}

/// `name` with an empty one read as the root `/`.
fn rooted(name: &str) -> &str {
    if name.is_empty() { "/" } else { name }
}

impl NodeToken {
    /// The token of node `name` in `namespace` (empty: the root), number
    /// `node_id` of session `zid`, in `domain`, with no enclave.
    pub fn new(
        domain: u32,
        zid: Zid,
        node_id: u64,
        namespace: &str,
        name: &str,
    ) -> Result<Self, NameError> {
        let namespace = rooted(namespace);
        validate_namespace(namespace)?;
        validate_node_name(name)?;
        Ok(Self {
            domain,
            zid,
            node_id,
            enclave: "/".to_owned(),
            namespace: namespace.to_owned(),
            name: name.to_owned(),
        })
    }

    /// This node in the SROS `enclave` (empty: none).
    pub fn with_enclave(self, enclave: &str) -> Result<Self, NameError> {
        let enclave = rooted(enclave);
        validate_enclave(enclave)?;
        Ok(Self {
            enclave: enclave.to_owned(),
            ..self
        })
    }

    /// The ROS domain id.
    pub fn domain(&self) -> u32 {
        self.domain
    }

    /// The Zenoh session id.
    pub fn zid(&self) -> Zid {
        self.zid
    }

    /// The node's id within its session.
    pub fn node_id(&self) -> u64 {
        self.node_id
    }

    /// The SROS enclave (`/` for none).
    pub fn enclave(&self) -> &str {
        &self.enclave
    }

    /// The namespace (`/` for the root).
    pub fn namespace(&self) -> &str {
        &self.namespace
    }

    /// The node's name.
    pub fn name(&self) -> &str {
        &self.name
    }

    /// The chunks every token of this node starts with, up to the node's name.
    fn prefix(&self, entity_id: u64, kind: &str) -> String {
        format!(
            "{ADMIN_SPACE}/{}/{}/{}/{entity_id}/{kind}/{}/{}/{}",
            self.domain,
            self.zid,
            self.node_id,
            mangle(&self.enclave),
            mangle(&self.namespace),
            mangle(&self.name)
        )
    }

    /// The node's token key expression.
    pub fn key_expr(&self) -> String {
        self.prefix(self.node_id, NODE_KIND)
    }
}

/// A publisher's, subscription's, service server's or client's token: its
/// node, its topic (or service), type, type hash and QoS.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct EntityToken {
    node: NodeToken,
    entity_id: u64,
    kind: EndpointKind,
    topic: String,
    type_name: TypeName,
    type_hash: TypeHash,
    qos: Qos,
    backends: Option<String>,
}

impl EntityToken {
    /// The token of entity `entity_id` of `node`: a `kind` on the fully
    /// qualified `topic` (or service) of `type_name` and `type_hash`.
    pub fn new(
        node: NodeToken,
        entity_id: u64,
        kind: EndpointKind,
        topic: &str,
        type_name: TypeName,
        type_hash: TypeHash,
        qos: Qos,
    ) -> Result<Self, NameError> {
        validate_topic_name(topic)?;
        Ok(Self {
            node,
            entity_id,
            kind,
            topic: topic.to_owned(),
            type_name,
            type_hash,
            qos,
            backends: None,
        })
    }

    /// This entity with Lyrical's buffer backends chunk (`backends:cpu:`),
    /// kept as it is written.
    pub fn with_backends(self, chunk: &str) -> Result<Self, TokenError> {
        let valid = chunk.starts_with(BACKENDS_PREFIX)
            && !chunk.contains(['/', '*', '$', '?', '#'])
            && !chunk.is_empty();
        if !valid {
            return Err(TokenError::Backends {
                chunk: chunk.to_owned(),
            });
        }
        Ok(Self {
            backends: Some(chunk.to_owned()),
            ..self
        })
    }

    /// The node the entity belongs to.
    pub fn node(&self) -> &NodeToken {
        &self.node
    }

    /// The entity's id within its session.
    pub fn entity_id(&self) -> u64 {
        self.entity_id
    }

    /// What kind of endpoint it is.
    pub fn kind(&self) -> EndpointKind {
        self.kind
    }

    /// The fully qualified topic (or service) name.
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

    /// The QoS.
    pub fn qos(&self) -> &Qos {
        &self.qos
    }

    /// Lyrical's buffer backends chunk, if the token has one.
    pub fn backends(&self) -> Option<&str> {
        self.backends.as_deref()
    }

    /// The key its data travels on.
    pub fn topic_key(&self) -> TopicKey {
        // The topic name was checked when this token was made.
        TopicKey::from_checked(
            self.node.domain,
            self.topic.clone(),
            self.type_name.clone(),
            self.type_hash,
        )
    }

    /// The entity's token key expression.
    pub fn key_expr(&self) -> String {
        let mut key = format!(
            "{}/{}/{}/{}/{}",
            self.node.prefix(self.entity_id, self.kind.as_str()),
            mangle(&self.topic),
            mangle(&self.type_name.dds()),
            mangle(&self.type_hash.to_string()),
            self.qos.to_compact()
        );
        if let Some(backends) = &self.backends {
            key.push('/');
            key.push_str(backends);
        }
        key
    }

    /// The entity's GID, the hash of its token ([`Gid::of_token_key`]).
    pub fn gid(&self) -> Gid {
        Gid::of_token_key(&self.key_expr())
    }
}

/// A liveliness token parsed into the node or entity it announces.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
#[expect(
    clippy::large_enum_variant,
    reason = "most tokens are entities': a box would only add an allocation to the common case"
)]
pub enum LivelinessToken {
    /// A node (`NN`).
    Node(NodeToken),
    /// A publisher, subscription, service server or client.
    Entity(EntityToken),
}

impl LivelinessToken {
    /// The token's key expression.
    pub fn key_expr(&self) -> String {
        match self {
            Self::Node(node) => node.key_expr(),
            Self::Entity(entity) => entity.key_expr(),
        }
    }

    /// The node the token is of, or belongs to.
    pub fn node(&self) -> &NodeToken {
        match self {
            Self::Node(node) => node,
            Self::Entity(entity) => entity.node(),
        }
    }

    /// A token key expression parsed: the node, or the entity with its topic,
    /// type, hash and QoS.
    pub fn parse(key: &str) -> Result<Self, TokenError> {
        let chunks: Vec<&str> = key.split('/').collect();
        if chunks.first() != Some(&ADMIN_SPACE) {
            return Err(TokenError::NotLiveliness {
                key: key.to_owned(),
            });
        }
        if ![9, 13, 14].contains(&chunks.len()) {
            return Err(TokenError::ChunkCount {
                key: key.to_owned(),
                found: chunks.len(),
            });
        }
        if let Some(index) = chunks.iter().position(|chunk| chunk.is_empty()) {
            return Err(TokenError::EmptyChunk {
                key: key.to_owned(),
                index,
            });
        }
        let (node, entity_id, kind) = parse_node(&chunks)?;
        if kind == NODE_KIND {
            return parse_node_token(key, &chunks, node, entity_id);
        }
        let kind = EndpointKind::ALL
            .into_iter()
            .find(|k| k.as_str() == kind)
            .ok_or_else(|| TokenError::UnknownKind {
                kind: kind.to_owned(),
            })?;
        let [topic, type_name, type_hash, qos, backends @ ..] = &chunks[9..] else {
            return Err(TokenError::KindChunkCount {
                key: key.to_owned(),
                kind: kind.as_str().to_owned(),
                found: chunks.len(),
            });
        };
        let type_name = TypeName::parse_dds(&demangle(type_name))?;
        let type_hash = demangle(type_hash).parse()?;
        let entity = EntityToken::new(
            node,
            entity_id,
            kind,
            &demangle(topic),
            type_name,
            type_hash,
            qos.parse()?,
        )?;
        match backends {
            [] => Ok(Self::Entity(entity)),
            [chunk, ..] => Ok(Self::Entity(entity.with_backends(chunk)?)),
        }
    }
}

/// The node's part of a token (chunks 1 to 8), with the entity id and kind.
fn parse_node<'a>(chunks: &[&'a str]) -> Result<(NodeToken, u64, &'a str), TokenError> {
    let [
        _,
        domain,
        zid,
        node_id,
        entity_id,
        kind,
        enclave,
        namespace,
        name,
        ..,
    ] = chunks
    else {
        // The caller checked there are at least 9 chunks.
        return Err(TokenError::ChunkCount {
            key: chunks.join("/"),
            found: chunks.len(),
        });
    };
    let domain = parse_decimal(domain).map_err(TokenError::Domain)?;
    let zid = zid.parse()?;
    let node_id = parse_decimal(node_id).map_err(TokenError::NodeId)?;
    let entity_id = parse_decimal(entity_id).map_err(TokenError::EntityId)?;
    let node = NodeToken::new(domain, zid, node_id, &demangle(namespace), &demangle(name))?
        .with_enclave(&demangle(enclave))?;
    Ok((node, entity_id, kind))
}

/// A node's token from its chunks: exactly 9, and the same id twice.
fn parse_node_token(
    key: &str,
    chunks: &[&str],
    node: NodeToken,
    entity_id: u64,
) -> Result<LivelinessToken, TokenError> {
    if chunks.len() != 9 {
        return Err(TokenError::KindChunkCount {
            key: key.to_owned(),
            kind: NODE_KIND.to_owned(),
            found: chunks.len(),
        });
    }
    if entity_id != node.node_id {
        return Err(TokenError::NodeIdMismatch {
            node_id: node.node_id,
            entity_id,
        });
    }
    Ok(LivelinessToken::Node(node))
}

impl fmt::Display for LivelinessToken {
    /// The key expression ([`LivelinessToken::key_expr`]).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.key_expr())
    }
}

impl FromStr for LivelinessToken {
    type Err = TokenError;

    fn from_str(key: &str) -> Result<Self, Self::Err> {
        Self::parse(key)
    }
}

#[cfg(test)]
mod tests;
