//! The attachment of every sample rmw_zenoh puts (and of service requests and
//! replies): the sequence number and the source timestamp \[ns since the UNIX
//! epoch\], each an `i64` little-endian, then the GID as Zenoh's serializer
//! writes a 16-byte array: its length (one byte, 16), then the bytes.

use super::gid::{GID_LEN, Gid};

/// The length of an attachment \[bytes\]: 8 + 8 + 1 + 16.
pub const ATTACHMENT_LEN: usize = 8 + 8 + 1 + GID_LEN;

/// Where the GID's length byte sits.
const GID_LENGTH_AT: usize = 16;

/// Why bytes are not an attachment.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum AttachmentError {
    /// Fewer bytes than an attachment has.
    #[error(
        "the attachment has {len} bytes, fewer than the {ATTACHMENT_LEN} of sequence number, timestamp and GID"
    )]
    TooShort {
        /// The number of bytes.
        len: usize,
    },
    /// More bytes than an attachment has.
    #[error(
        "the attachment has {len} bytes, more than the {ATTACHMENT_LEN} of sequence number, timestamp and GID"
    )]
    TooLong {
        /// The number of bytes.
        len: usize,
    },
    /// The GID's length byte is not 16.
    #[error("the attachment's GID length is {found}, not {GID_LEN}")]
    GidLength {
        /// The length byte.
        found: u8,
    },
}

/// What a sample carries beside its payload.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Attachment {
    /// The publisher's count of its samples, from 1 (a service reply echoes
    /// the request's): a subscriber detects lost samples from gaps.
    pub sequence_number: i64,
    /// When the sample was published \[ns since the UNIX epoch\].
    pub source_timestamp_ns: i64,
    /// The publisher's (or the requesting client's) GID.
    pub gid: Gid,
}

impl Attachment {
    /// The attachment's bytes, in a fixed-size array (no allocation).
    pub fn encode(&self) -> [u8; ATTACHMENT_LEN] {
        let mut bytes = [0u8; ATTACHMENT_LEN];
        bytes[..8].copy_from_slice(&self.sequence_number.to_le_bytes());
        bytes[8..GID_LENGTH_AT].copy_from_slice(&self.source_timestamp_ns.to_le_bytes());
        bytes[GID_LENGTH_AT] = GID_LEN as u8;
        bytes[GID_LENGTH_AT + 1..].copy_from_slice(&self.gid.to_bytes());
        bytes
    }

    /// The attachment in `bytes`, which must be exactly one attachment. A
    /// wrong GID length is reported before a wrong total length: it says more.
    pub fn decode(bytes: &[u8]) -> Result<Self, AttachmentError> {
        if let Some(&found) = bytes.get(GID_LENGTH_AT)
            && usize::from(found) != GID_LEN
        {
            return Err(AttachmentError::GidLength { found });
        }
        let Ok(exact) = <&[u8; ATTACHMENT_LEN]>::try_from(bytes) else {
            return Err(if bytes.len() < ATTACHMENT_LEN {
                AttachmentError::TooShort { len: bytes.len() }
            } else {
                AttachmentError::TooLong { len: bytes.len() }
            });
        };
        let mut sequence = [0u8; 8];
        sequence.copy_from_slice(&exact[..8]);
        let mut timestamp = [0u8; 8];
        timestamp.copy_from_slice(&exact[8..GID_LENGTH_AT]);
        let mut gid = [0u8; GID_LEN];
        gid.copy_from_slice(&exact[GID_LENGTH_AT + 1..]);
        Ok(Self {
            sequence_number: i64::from_le_bytes(sequence),
            source_timestamp_ns: i64::from_le_bytes(timestamp),
            gid: Gid::from_bytes(gid),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn example() -> Attachment {
        Attachment {
            sequence_number: 1,
            source_timestamp_ns: 1_700_000_000_123_456_789,
            gid: Gid::from_bytes([
                0xeb, 0x85, 0xfa, 0x88, 0x3b, 0x78, 0x46, 0xdc, 0x44, 0x8a, 0x45, 0x01, 0x89, 0x0a,
                0xd0, 0x62,
            ]),
        }
    }

    /// The layout of the design document: 8 + 8 bytes little-endian, the
    /// length 16, the 16 bytes of the GID.
    #[test]
    fn the_bytes_are_laid_out_as_the_design_document_says() {
        let bytes = example().encode();
        assert_eq!(bytes.len(), 33);
        assert_eq!(&bytes[..8], &[1, 0, 0, 0, 0, 0, 0, 0]);
        assert_eq!(&bytes[8..16], &1_700_000_000_123_456_789_i64.to_le_bytes());
        assert_eq!(bytes[16], 16);
        assert_eq!(&bytes[17..], &example().gid.to_bytes());
        assert_eq!(Attachment::decode(&bytes), Ok(example()));
    }

    #[test]
    fn negative_numbers_survive() {
        let attachment = Attachment {
            sequence_number: -1,
            source_timestamp_ns: i64::MIN,
            ..example()
        };
        assert_eq!(Attachment::decode(&attachment.encode()), Ok(attachment));
    }

    #[test]
    fn wrong_lengths_are_refused_with_what_is_wrong() {
        let bytes = example().encode();
        assert_eq!(
            Attachment::decode(&bytes[..32]),
            Err(AttachmentError::TooShort { len: 32 })
        );
        assert_eq!(
            Attachment::decode(&[]),
            Err(AttachmentError::TooShort { len: 0 })
        );
        let mut long = bytes.to_vec();
        long.push(0);
        assert_eq!(
            Attachment::decode(&long),
            Err(AttachmentError::TooLong { len: 34 })
        );
        let mut wrong = bytes;
        wrong[16] = 15;
        assert_eq!(
            Attachment::decode(&wrong),
            Err(AttachmentError::GidLength { found: 15 })
        );
        // A 15-byte GID with its own length byte: the length is what is wrong.
        assert_eq!(
            Attachment::decode(&wrong[..32]),
            Err(AttachmentError::GidLength { found: 15 })
        );
    }
}
