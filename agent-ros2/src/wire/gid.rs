//! GIDs: the 16 bytes that name a publisher (or a service client) to the
//! subscribers of its samples.
//!
//! rmw_zenoh makes an entity's GID by hashing the key expression of its
//! liveliness token with XXH3-128 (the low 64 bits, then the high 64 bits,
//! each little-endian), and every peer that discovers the entity computes the
//! same GID from the same token. We do the same, rather than draw a random
//! GID: the GID in our samples' attachments then equals the one ROS 2 tools
//! show for our publisher (`ros2 topic info --verbose`), and it is unique per
//! entity because the token holds the Zenoh session id and the entity id.

use std::fmt;

use super::xxh3;

/// The length of a GID \[bytes\].
pub const GID_LEN: usize = 16;

/// A publisher's (or a service client's) global id.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Gid([u8; GID_LEN]);

impl Gid {
    /// The GID of these bytes.
    pub const fn from_bytes(bytes: [u8; GID_LEN]) -> Self {
        Self(bytes)
    }

    /// The bytes, as the attachment carries them.
    pub const fn to_bytes(self) -> [u8; GID_LEN] {
        self.0
    }

    /// The GID rmw_zenoh gives the entity whose liveliness token has the key
    /// expression `token_key`: its XXH3-128, low half first, little-endian.
    pub fn of_token_key(token_key: &str) -> Self {
        let hash = xxh3::hash128(token_key.as_bytes());
        let mut bytes = [0u8; GID_LEN];
        bytes[..8].copy_from_slice(&hash.low.to_le_bytes());
        bytes[8..].copy_from_slice(&hash.high.to_le_bytes());
        Self(bytes)
    }
}

impl fmt::Display for Gid {
    /// The bytes as 32 lowercase hex digits, in order.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        self.0.iter().try_for_each(|byte| write!(f, "{byte:02x}"))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_talkers_gid_is_the_xxh3_of_its_token_low_half_first() {
        // The design document's `talker` publisher; the expected bytes are the
        // xxHash library's XXH3-128 of the key (0x62d00a8901458a44_dc46783b88fa85eb)
        // laid out as rmw_zenoh copies it on a little-endian machine.
        let token = "@ros2_lv/0/8b20917502ee955ac4476e0266340d5c/0/10/MP/%/%/talker/%chatter/\
                     std_msgs::msg::dds_::String_/\
                     RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18/::,7:,:,:,,";
        assert_eq!(
            Gid::of_token_key(token).to_string(),
            "eb85fa883b7846dc448a4501890ad062"
        );
    }

    #[test]
    fn entities_differing_only_in_their_id_get_different_gids() {
        let a = Gid::of_token_key(
            "@ros2_lv/0/1/0/10/MP/%/%/n/%t/p::msg::dds_::T_/TypeHashNotSupported/::,:,:,:,,",
        );
        let b = Gid::of_token_key(
            "@ros2_lv/0/1/0/11/MP/%/%/n/%t/p::msg::dds_::T_/TypeHashNotSupported/::,:,:,:,,",
        );
        assert_ne!(a, b);
        assert_eq!(Gid::from_bytes(a.to_bytes()), a);
    }
}
