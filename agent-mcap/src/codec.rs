//! [`Codec`]: a lossless encoding of one payload type's values on their raw
//! channels, in place of their postcard bytes.
//!
//! A raw channel records each value exactly as a link carries it, and the
//! chunks of the file are compressed (zstd) as a whole. That suits small
//! values; a camera's images are better and more cheaply compressed by an
//! image codec (PNG shrinks a sensor's noisy images more than zstd, in less
//! time: docs/measurements.md, "The recorder's encodings"). A codec does that
//! for one payload type: the recorder writes `codec.encode(body)` after the wire
//! header, names the codec in the raw channel's metadata (`codec`), and a
//! replay given the same codec ([`crate::ReplayOptions::codecs`]) decodes each
//! value back to the exact bytes the link carried. A replay that is not given
//! it refuses clearly ([`crate::ReplayError::Codec`]).
//!
//! The contract is losslessness: `decode(encode(b)) == b` for every `b`, also
//! for bytes that are not a valid value (a codec keeps those verbatim behind a
//! tag of its own). A [`crate::Derive`] may reuse the encoding (for example the
//! image the codec already compressed): [`crate::Derive::message_encoded`].

/// A lossless encoding of one payload type's values (see the module's
/// documentation). Runs on the recorder's writer thread and in a replay.
pub trait Codec: Send + Sync {
    /// The payload type whose values it encodes, as the system names it
    /// ([`agent_core::trace::LinkInfo::payload`]: `std::any::type_name`).
    fn payload(&self) -> &str;
    /// Its name and version, written in the raw channel's metadata: a replay
    /// decodes with the codec of this name.
    fn name(&self) -> &str;
    /// Encode a value's postcard bytes `body` into `out` (empty). Any bytes,
    /// valid or not, must decode back to themselves.
    fn encode(&self, body: &[u8], out: &mut Vec<u8>);
    /// Decode `data` (what `encode` wrote) into `out` (empty): the value's
    /// postcard bytes. An error says what in `data` is wrong.
    fn decode(&self, data: &[u8], out: &mut Vec<u8>) -> Result<(), DecodeError>;
}

/// What in a codec's data is wrong: data that `encode` did not write (a
/// damaged or foreign file).
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{reason}")]
pub struct DecodeError {
    /// What is wrong, in words.
    pub reason: String,
}

impl DecodeError {
    /// An error saying `reason`.
    pub fn new(reason: impl Into<String>) -> DecodeError {
        DecodeError {
            reason: reason.into(),
        }
    }
}

/// The metadata key of a raw channel that names its codec.
pub const CODEC_KEY: &str = "codec";
