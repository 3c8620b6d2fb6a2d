//! Adapters: how a buffer type becomes a standard ROS 2 message, and how a
//! standard message received becomes a value of an input buffer's type, said
//! in code. A spec names the message (`message: "geometry_msgs/msg/PoseStamped"`);
//! the code that knows the buffer type says how to fill it, or how to read it.

use std::fmt;
use std::sync::Arc;

use agent_core::link::remote::fingerprint;
use agent_core::trace::ErasedPayload;
use agent_core::{Payload, TypeShape, reflect};

use crate::types::standard::StandardMessage;
use crate::types::standard::builtin_interfaces::Time;
use crate::types::{DecodeError, EncodeError, Messages, encode_cdr};
use agent_mcap::cdr::read_cdr;

/// Why a value did not become a message's CDR on the publishing thread.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum TranscodeError {
    /// The value's bytes are not a value of the buffer type.
    #[error("the value's bytes are not a value of its type: {0}")]
    Decode(String),
    /// The message (own or adapted) has no CDR form for the value.
    #[error(transparent)]
    Encode(#[from] EncodeError),
    /// The bytes do not have the buffer type's shape.
    #[error("the value does not have its type's shape: {0}")]
    Shape(#[from] DecodeError),
}

/// A value's postcard bytes and its ROS stamp to the adapted message's CDR,
/// appended to the output. It holds the message's shape, which is not `Send`:
/// each is made on the thread that uses it.
pub(crate) type Transcode = dyn Fn(&[u8], Time, &mut Vec<u8>) -> Result<(), TranscodeError>;

/// Makes a [`Transcode`] (on the publishing thread); `None` when the
/// message type's shape cannot be traced.
pub(crate) type MakeTranscode = dyn Fn() -> Option<Box<Transcode>> + Send + Sync;

/// Why a message received did not become a value of its input buffer's type
/// (on the bridge's inbound thread).
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) enum Refusal {
    /// The CDR is not a message of the topic's type.
    Undecodable(String),
    /// The adapter refused the message (a value the buffer must not take).
    Rejected(String),
}

/// A message's CDR (with its encapsulation header) to the postcard bytes of a
/// value of the input buffer's type, appended to the output. It holds the
/// message's shape, which is not `Send`: each is made on the thread that uses
/// it.
pub(crate) type Decode = dyn Fn(&[u8], &mut Vec<u8>) -> Result<(), Refusal>;

/// Makes a [`Decode`] (on the inbound thread); `None` when the message
/// type's shape cannot be traced.
pub(crate) type MakeDecode = dyn Fn() -> Option<Box<Decode>> + Send + Sync;

/// How a thread of the bridge converts one topic's values, as the plan keeps
/// it: a type's shape is not `Send`, so it travels as what makes it, and is
/// made again on the thread that uses it ([`Conversion::ready`]). `F` is the
/// conversion itself: [`Transcode`] out to ROS 2, [`Decode`] in from it.
pub(crate) enum Conversion<F: ?Sized> {
    /// The message made from the buffer type: read or written by the type's
    /// shape (kept as JSON).
    Own(String),
    /// A standard message, through an adapter.
    Adapted(Arc<dyn Fn() -> Option<Box<F>> + Send + Sync>),
}

impl<F: ?Sized> Clone for Conversion<F> {
    fn clone(&self) -> Self {
        match self {
            Conversion::Own(json) => Conversion::Own(json.clone()),
            Conversion::Adapted(make) => Conversion::Adapted(make.clone()),
        }
    }
}

/// A [`Conversion`] made ready on the thread that uses it.
pub(crate) enum Prepared<F: ?Sized> {
    /// The buffer type's shape.
    Own(TypeShape),
    /// The adapter's conversion.
    Adapted(Box<F>),
}

impl<F: ?Sized> Conversion<F> {
    /// Whether the message is the buffer type's own (else a standard one).
    pub(crate) fn is_own(&self) -> bool {
        matches!(self, Conversion::Own(_))
    }

    /// The conversion with its shape, on the thread that uses it; `None`
    /// when the shape cannot be made (the plan checked that it can).
    pub(crate) fn ready(&self) -> Option<Prepared<F>> {
        match self {
            Conversion::Own(json) => {
                let (root, registry) = serde_json::from_str(json).ok()?;
                Some(Prepared::Own(TypeShape { root, registry }))
            }
            Conversion::Adapted(make) => make().map(Prepared::Adapted),
        }
    }
}

/// How the publishing thread turns a value's postcard bytes into CDR.
pub(crate) type Encoder = Conversion<Transcode>;

/// How the inbound thread turns a message's CDR into the buffer type's
/// postcard bytes.
pub(crate) type Decoder = Conversion<Decode>;

impl Prepared<Transcode> {
    /// The value's CDR (with its encapsulation header) appended to `out`.
    pub(crate) fn encode(
        &self,
        bytes: &[u8],
        stamp: Time,
        out: &mut Vec<u8>,
    ) -> Result<(), TranscodeError> {
        match self {
            Prepared::Own(shape) => Ok(agent_mcap::cdr::write_cdr(shape, bytes, out)?),
            Prepared::Adapted(transcode) => transcode(bytes, stamp, out),
        }
    }
}

impl Prepared<Decode> {
    /// The postcard bytes of the value the CDR message `cdr` (with its
    /// encapsulation header) stands for, appended to `out`; on an error
    /// `out` may hold a part of it.
    pub(crate) fn decode(&self, cdr: &[u8], out: &mut Vec<u8>) -> Result<(), Refusal> {
        match self {
            Prepared::Own(shape) => {
                read_cdr(shape, cdr, out).map_err(|e| Refusal::Undecodable(e.to_string()))
            }
            Prepared::Adapted(decode) => decode(cdr, out),
        }
    }
}

/// One registered conversion from a standard message to a buffer type.
#[derive(Clone)]
pub(crate) struct InboundAdapter {
    /// The buffer type's fingerprint, as the system's links report it.
    pub(crate) payload: u64,
    /// The buffer type's Rust name (for errors).
    pub(crate) payload_name: &'static str,
    /// The message, with every message it uses.
    pub(crate) messages: Messages,
    /// Whether the message type's shape can be traced (else the plan
    /// refuses it).
    pub(crate) traceable: bool,
    /// The conversion's maker.
    pub(crate) make: Arc<MakeDecode>,
}

/// One registered conversion from a buffer type to a standard message.
#[derive(Clone)]
pub(crate) struct Adapter {
    /// The buffer type's fingerprint, as the system's links report it.
    pub(crate) payload: u64,
    /// The buffer type's Rust name (for errors).
    pub(crate) payload_name: &'static str,
    /// The message, with every message it uses.
    pub(crate) messages: Messages,
    /// Whether the message type's shape can be traced (else the plan
    /// refuses it).
    pub(crate) traceable: bool,
    /// The conversion's maker.
    pub(crate) make: Arc<MakeTranscode>,
}

/// The conversions between buffer types and standard ROS 2 messages a bridge
/// may use: the spec names a topic's message, and the plan picks the adapter
/// of that message for the buffer's type, [`Adapters::publish`] for a
/// published output, [`Adapters::subscribe`] for a subscribed input (a
/// standard message without one is an error before anything runs).
///
/// ```
/// use agent_ros2::bridge::Adapters;
/// use agent_ros2::types::standard::geometry_msgs::{Point, Pose, PoseStamped};
/// use agent_ros2::types::standard::std_msgs::Header;
///
/// #[derive(Clone, Debug, serde::Serialize, serde::Deserialize)]
/// struct MapPose { x: f64, y: f64 }
///
/// let adapters = Adapters::new().publish::<MapPose, PoseStamped>(|pose, stamp| PoseStamped {
///     header: Header { stamp, frame_id: "map".into() },
///     pose: Pose {
///         position: Point { x: pose.x, y: pose.y, z: 0.0 },
///         ..Pose::default()
///     },
/// });
/// let adapters = adapters.subscribe::<PoseStamped, MapPose>(|pose| {
///     let p = pose.pose.position;
///     if p.x.is_finite() && p.y.is_finite() {
///         Ok(MapPose { x: p.x, y: p.y })
///     } else {
///         Err(format!("a pose off the map: ({}, {})", p.x, p.y))
///     }
/// });
/// assert_eq!(adapters.len(), 2);
/// ```
#[derive(Clone, Default)]
pub struct Adapters {
    list: Vec<Adapter>,
    inbound: Vec<InboundAdapter>,
}

impl fmt::Debug for Adapters {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_list()
            .entries(
                self.list
                    .iter()
                    .map(|a| format!("{} -> {}", a.payload_name, a.messages.name()))
                    .chain(
                        self.inbound
                            .iter()
                            .map(|a| format!("{} -> {}", a.messages.name(), a.payload_name)),
                    ),
            )
            .finish()
    }
}

impl Adapters {
    /// No adapter: every published or subscribed buffer is its own message.
    pub fn new() -> Self {
        Self::default()
    }

    /// Publish values of buffer type `B` as the standard message `M`, made by
    /// `adapt` from the value and its stamp (the instant the value stands for,
    /// on the wall clock: for the message's header). A later adapter for the
    /// same `B` and `M` replaces this one.
    pub fn publish<B, M>(mut self, adapt: impl Fn(&B, Time) -> M + Send + Sync + 'static) -> Self
    where
        B: Payload,
        M: StandardMessage,
    {
        let payload = fingerprint::<B>();
        let messages = M::messages();
        let traceable = reflect::<M>().is_some();
        let adapt = Arc::new(adapt);
        let make = move || -> Option<Box<Transcode>> {
            let shape: TypeShape = reflect::<M>()?;
            let adapt = adapt.clone();
            Some(Box::new(
                move |bytes: &[u8], stamp: Time, out: &mut Vec<u8>| {
                    let value: B = postcard::from_bytes(bytes)
                        .map_err(|e| TranscodeError::Decode(e.to_string()))?;
                    encode_cdr(&adapt(&value, stamp), &shape, out)?;
                    Ok(())
                },
            ))
        };
        self.list
            .retain(|a| !(a.payload == payload && a.messages.name() == messages.name()));
        self.list.push(Adapter {
            payload,
            payload_name: std::any::type_name::<B>(),
            messages,
            traceable,
            make: Arc::new(make),
        });
        self
    }

    /// Feed an input buffer of type `B` from a topic of the standard message
    /// `M`: each message received is decoded from its CDR (by `M`'s shape,
    /// every length and value checked) and given to `adapt`, whose value the
    /// buffer takes; an `Err` refuses the message (a value the buffer must
    /// not take, a NaN for example), with the reason, and the bridge counts
    /// it. `adapt` runs on the bridge's inbound thread and must not panic: a
    /// panic there ends the feeding of every subscribed topic
    /// ([`Bridge::finish`](super::Bridge::finish) says so). A later adapter
    /// for the same `M` and `B` replaces this one.
    pub fn subscribe<M, B>(
        mut self,
        adapt: impl Fn(M) -> Result<B, String> + Send + Sync + 'static,
    ) -> Self
    where
        M: StandardMessage,
        B: Payload,
    {
        let payload = fingerprint::<B>();
        let messages = M::messages();
        let traceable = reflect::<M>().is_some();
        let adapt = Arc::new(adapt);
        let make = move || -> Option<Box<Decode>> {
            let shape: TypeShape = reflect::<M>()?;
            let adapt = adapt.clone();
            Some(Box::new(move |cdr: &[u8], out: &mut Vec<u8>| {
                let mut bytes = Vec::new();
                read_cdr(&shape, cdr, &mut bytes)
                    .map_err(|e| Refusal::Undecodable(e.to_string()))?;
                let message: M = postcard::from_bytes(&bytes)
                    .map_err(|e| Refusal::Undecodable(e.to_string()))?;
                let value = adapt(message).map_err(Refusal::Rejected)?;
                // On an error `out` is left as it was.
                ErasedPayload::encode(&value, out)
                    .map_err(|e| Refusal::Rejected(format!("the adapter's value: {e}")))
            }))
        };
        self.inbound
            .retain(|a| !(a.payload == payload && a.messages.name() == messages.name()));
        self.inbound.push(InboundAdapter {
            payload,
            payload_name: std::any::type_name::<B>(),
            messages,
            traceable,
            make: Arc::new(make),
        });
        self
    }

    /// The number of adapters, either way.
    pub fn len(&self) -> usize {
        self.list.len() + self.inbound.len()
    }

    /// Whether there is none.
    pub fn is_empty(&self) -> bool {
        self.list.is_empty() && self.inbound.is_empty()
    }

    /// The adapter of the buffer type whose fingerprint is `payload` to the
    /// message named `message` (`geometry_msgs/msg/PoseStamped`).
    pub(crate) fn find(&self, payload: u64, message: &str) -> Option<&Adapter> {
        self.list
            .iter()
            .find(|a| a.payload == payload && a.messages.name().to_string() == message)
    }

    /// The messages some adapter makes of the buffer type `payload` (for an
    /// error that says what is there).
    pub(crate) fn messages_of(&self, payload: u64) -> Vec<String> {
        self.list
            .iter()
            .filter(|a| a.payload == payload)
            .map(|a| a.messages.name().to_string())
            .collect()
    }

    /// The adapter of the message named `message` to the buffer type whose
    /// fingerprint is `payload`.
    pub(crate) fn find_inbound(&self, payload: u64, message: &str) -> Option<&InboundAdapter> {
        self.inbound
            .iter()
            .find(|a| a.payload == payload && a.messages.name().to_string() == message)
    }

    /// The messages some adapter reads into the buffer type `payload`.
    pub(crate) fn inbound_messages_of(&self, payload: u64) -> Vec<String> {
        self.inbound
            .iter()
            .filter(|a| a.payload == payload)
            .map(|a| a.messages.name().to_string())
            .collect()
    }
}
