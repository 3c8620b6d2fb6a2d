//! XXH3-128 (seed 0, default secret), the hash rmw_zenoh makes an entity's GID
//! with: the same bytes in give the same 16 bytes out as the xxHash library.
//!
//! Written from the xxHash specification (XXH3 for inputs of 0 to 16, 17 to
//! 128, 129 to 240 bytes and the long loop beyond), scalar only: a GID is made
//! once per entity from a key of a few hundred bytes, so speed does not matter.

/// The 128-bit hash as xxHash returns it: the low and high 64-bit halves.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Hash128 {
    pub(crate) low: u64,
    pub(crate) high: u64,
}

const PRIME32_1: u64 = 0x9E37_79B1;
const PRIME32_2: u64 = 0x85EB_CA77;
const PRIME32_3: u64 = 0xC2B2_AE3D;
const PRIME64_1: u64 = 0x9E37_79B1_85EB_CA87;
const PRIME64_2: u64 = 0xC2B2_AE3D_27D4_EB4F;
const PRIME64_3: u64 = 0x1656_67B1_9E37_79F9;
const PRIME64_4: u64 = 0x85EB_CA77_C2B2_AE63;
const PRIME64_5: u64 = 0x27D4_EB2F_1656_67C5;
const PRIME_MX1: u64 = 0x1656_6791_9E37_79F9;
const PRIME_MX2: u64 = 0x9FB2_1C65_1E98_DF25;

/// The default secret of XXH3 (192 bytes), a constant of the algorithm.
const SECRET: [u8; 192] = [
    0xb8, 0xfe, 0x6c, 0x39, 0x23, 0xa4, 0x4b, 0xbe, 0x7c, 0x01, 0x81, 0x2c, 0xf7, 0x21, 0xad, 0x1c,
    0xde, 0xd4, 0x6d, 0xe9, 0x83, 0x90, 0x97, 0xdb, 0x72, 0x40, 0xa4, 0xa4, 0xb7, 0xb3, 0x67, 0x1f,
    0xcb, 0x79, 0xe6, 0x4e, 0xcc, 0xc0, 0xe5, 0x78, 0x82, 0x5a, 0xd0, 0x7d, 0xcc, 0xff, 0x72, 0x21,
    0xb8, 0x08, 0x46, 0x74, 0xf7, 0x43, 0x24, 0x8e, 0xe0, 0x35, 0x90, 0xe6, 0x81, 0x3a, 0x26, 0x4c,
    0x3c, 0x28, 0x52, 0xbb, 0x91, 0xc3, 0x00, 0xcb, 0x88, 0xd0, 0x65, 0x8b, 0x1b, 0x53, 0x2e, 0xa3,
    0x71, 0x64, 0x48, 0x97, 0xa2, 0x0d, 0xf9, 0x4e, 0x38, 0x19, 0xef, 0x46, 0xa9, 0xde, 0xac, 0xd8,
    0xa8, 0xfa, 0x76, 0x3f, 0xe3, 0x9c, 0x34, 0x3f, 0xf9, 0xdc, 0xbb, 0xc7, 0xc7, 0x0b, 0x4f, 0x1d,
    0x8a, 0x51, 0xe0, 0x4b, 0xcd, 0xb4, 0x59, 0x31, 0xc8, 0x9f, 0x7e, 0xc9, 0xd9, 0x78, 0x73, 0x64,
    0xea, 0xc5, 0xac, 0x83, 0x34, 0xd3, 0xeb, 0xc3, 0xc5, 0x81, 0xa0, 0xff, 0xfa, 0x13, 0x63, 0xeb,
    0x17, 0x0d, 0xdd, 0x51, 0xb7, 0xf0, 0xda, 0x49, 0xd3, 0x16, 0x55, 0x26, 0x29, 0xd4, 0x68, 0x9e,
    0x2b, 0x16, 0xbe, 0x58, 0x7d, 0x47, 0xa1, 0xfc, 0x8f, 0xf8, 0xb8, 0xd1, 0x7a, 0xd0, 0x31, 0xce,
    0x45, 0xcb, 0x3a, 0x8f, 0x95, 0x16, 0x04, 0x28, 0xaf, 0xd7, 0xfb, 0xca, 0xbb, 0x4b, 0x40, 0x7e,
];

/// Bytes of input one stripe of the long loop consumes.
const STRIPE_LEN: usize = 64;
/// Bytes the secret advances by from one stripe to the next.
const SECRET_CONSUME_RATE: usize = 8;
/// Stripes in one block of the long loop: (192 - 64) / 8.
const STRIPES_PER_BLOCK: usize = (SECRET.len() - STRIPE_LEN) / SECRET_CONSUME_RATE;

/// XXH3-128 of `input` with seed 0 and the default secret.
pub(crate) fn hash128(input: &[u8]) -> Hash128 {
    match input.len() {
        0..=16 => len_0_to_16(input),
        17..=128 => len_17_to_128(input),
        129..=240 => len_129_to_240(input),
        _ => long(input),
    }
}

/// The little-endian `u64` at `at` (callers keep `at + 8` within `bytes`).
fn read64(bytes: &[u8], at: usize) -> u64 {
    let mut word = [0u8; 8];
    word.copy_from_slice(&bytes[at..at + 8]);
    u64::from_le_bytes(word)
}

/// The little-endian `u32` at `at` (callers keep `at + 4` within `bytes`).
fn read32(bytes: &[u8], at: usize) -> u32 {
    let mut word = [0u8; 4];
    word.copy_from_slice(&bytes[at..at + 4]);
    u32::from_le_bytes(word)
}

/// The full 128-bit product of two 64-bit numbers, as (low, high).
fn mul128(a: u64, b: u64) -> (u64, u64) {
    let product = u128::from(a) * u128::from(b);
    (product as u64, (product >> 64) as u64)
}

/// The 128-bit product folded to 64 bits (low xor high).
fn mul128_fold64(a: u64, b: u64) -> u64 {
    let (low, high) = mul128(a, b);
    low ^ high
}

/// XXH3's final mix of a 64-bit value.
fn avalanche(mut h: u64) -> u64 {
    h ^= h >> 37;
    h = h.wrapping_mul(PRIME_MX1);
    h ^ (h >> 32)
}

/// XXH64's final mix, which XXH3 uses for inputs of at most 3 bytes.
fn avalanche_xxh64(mut h: u64) -> u64 {
    h ^= h >> 33;
    h = h.wrapping_mul(PRIME64_2);
    h ^= h >> 29;
    h = h.wrapping_mul(PRIME64_3);
    h ^ (h >> 32)
}

fn len_0_to_16(input: &[u8]) -> Hash128 {
    let len = input.len();
    if len > 8 {
        return len_9_to_16(input);
    }
    if len >= 4 {
        return len_4_to_8(input);
    }
    if len > 0 {
        return len_1_to_3(input);
    }
    Hash128 {
        low: avalanche_xxh64(read64(&SECRET, 64) ^ read64(&SECRET, 72)),
        high: avalanche_xxh64(read64(&SECRET, 80) ^ read64(&SECRET, 88)),
    }
}

fn len_1_to_3(input: &[u8]) -> Hash128 {
    let len = input.len();
    let c1 = u32::from(input[0]);
    let c2 = u32::from(input[len >> 1]);
    let c3 = u32::from(input[len - 1]);
    let combined_low = (c1 << 16) | (c2 << 24) | c3 | ((len as u32) << 8);
    let combined_high = combined_low.swap_bytes().rotate_left(13);
    let flip_low = u64::from(read32(&SECRET, 0) ^ read32(&SECRET, 4));
    let flip_high = u64::from(read32(&SECRET, 8) ^ read32(&SECRET, 12));
    Hash128 {
        low: avalanche_xxh64(u64::from(combined_low) ^ flip_low),
        high: avalanche_xxh64(u64::from(combined_high) ^ flip_high),
    }
}

fn len_4_to_8(input: &[u8]) -> Hash128 {
    let len = input.len();
    let input_low = u64::from(read32(input, 0));
    let input_high = u64::from(read32(input, len - 4));
    let keyed = (input_low | (input_high << 32)) ^ (read64(&SECRET, 16) ^ read64(&SECRET, 24));
    let (mut low, mut high) = mul128(keyed, PRIME64_1.wrapping_add((len as u64) << 2));
    high = high.wrapping_add(low << 1);
    low ^= high >> 3;
    low ^= low >> 35;
    low = low.wrapping_mul(PRIME_MX2);
    low ^= low >> 28;
    Hash128 {
        low,
        high: avalanche(high),
    }
}

fn len_9_to_16(input: &[u8]) -> Hash128 {
    let len = input.len();
    let flip_low = read64(&SECRET, 32) ^ read64(&SECRET, 40);
    let flip_high = read64(&SECRET, 48) ^ read64(&SECRET, 56);
    let input_low = read64(input, 0);
    let mut input_high = read64(input, len - 8);
    let (mut m_low, mut m_high) = mul128(input_low ^ input_high ^ flip_low, PRIME64_1);
    m_low = m_low.wrapping_add(((len - 1) as u64) << 54);
    input_high ^= flip_high;
    m_high = m_high
        .wrapping_add(input_high)
        .wrapping_add((input_high & 0xFFFF_FFFF).wrapping_mul(PRIME32_2 - 1));
    m_low ^= m_high.swap_bytes();
    let (h_low, h_high) = mul128(m_low, PRIME64_2);
    Hash128 {
        low: avalanche(h_low),
        high: avalanche(h_high.wrapping_add(m_high.wrapping_mul(PRIME64_2))),
    }
}

/// Sixteen bytes of input mixed with sixteen bytes of secret.
fn mix16(input: &[u8], at: usize, secret_at: usize) -> u64 {
    mul128_fold64(
        read64(input, at) ^ read64(&SECRET, secret_at),
        read64(input, at + 8) ^ read64(&SECRET, secret_at + 8),
    )
}

/// Two sixteen-byte pieces of input (at `first` and `second`) mixed into `acc`.
fn mix32(acc: Hash128, input: &[u8], first: usize, second: usize, secret_at: usize) -> Hash128 {
    let low = acc.low.wrapping_add(mix16(input, first, secret_at))
        ^ read64(input, second).wrapping_add(read64(input, second + 8));
    let high = acc.high.wrapping_add(mix16(input, second, secret_at + 16))
        ^ read64(input, first).wrapping_add(read64(input, first + 8));
    Hash128 { low, high }
}

/// The last step shared by the 17 to 240 byte paths.
fn finish_mid(acc: Hash128, len: usize) -> Hash128 {
    let low = acc.low.wrapping_add(acc.high);
    let high = acc
        .low
        .wrapping_mul(PRIME64_1)
        .wrapping_add(acc.high.wrapping_mul(PRIME64_4))
        .wrapping_add((len as u64).wrapping_mul(PRIME64_2));
    Hash128 {
        low: avalanche(low),
        high: 0u64.wrapping_sub(avalanche(high)),
    }
}

fn len_17_to_128(input: &[u8]) -> Hash128 {
    let len = input.len();
    let mut acc = Hash128 {
        low: (len as u64).wrapping_mul(PRIME64_1),
        high: 0,
    };
    if len > 32 {
        if len > 64 {
            if len > 96 {
                acc = mix32(acc, input, 48, len - 64, 96);
            }
            acc = mix32(acc, input, 32, len - 48, 64);
        }
        acc = mix32(acc, input, 16, len - 32, 32);
    }
    acc = mix32(acc, input, 0, len - 16, 0);
    finish_mid(acc, len)
}

fn len_129_to_240(input: &[u8]) -> Hash128 {
    let len = input.len();
    let mut acc = Hash128 {
        low: (len as u64).wrapping_mul(PRIME64_1),
        high: 0,
    };
    for round in 0..4 {
        acc = mix32(acc, input, 32 * round, 32 * round + 16, 32 * round);
    }
    acc = Hash128 {
        low: avalanche(acc.low),
        high: avalanche(acc.high),
    };
    for round in 4..len / 32 {
        acc = mix32(
            acc,
            input,
            32 * round,
            32 * round + 16,
            3 + 32 * (round - 4),
        );
    }
    // The last 32 bytes, with the secret's tail (136 - 17 - 16 = 103).
    acc = mix32(acc, input, len - 16, len - 32, 103);
    finish_mid(acc, len)
}

/// One 64-byte stripe accumulated with the secret from `secret_at`.
fn accumulate_stripe(acc: &mut [u64; 8], input: &[u8], at: usize, secret_at: usize) {
    for lane in 0..8 {
        let value = read64(input, at + 8 * lane);
        let keyed = value ^ read64(&SECRET, secret_at + 8 * lane);
        acc[lane ^ 1] = acc[lane ^ 1].wrapping_add(value);
        acc[lane] = acc[lane].wrapping_add((keyed & 0xFFFF_FFFF).wrapping_mul(keyed >> 32));
    }
}

/// The scramble after each full block of the long loop.
fn scramble(acc: &mut [u64; 8]) {
    let secret_at = SECRET.len() - STRIPE_LEN;
    for lane in 0..8 {
        let mut value = acc[lane];
        value ^= value >> 47;
        value ^= read64(&SECRET, secret_at + 8 * lane);
        acc[lane] = value.wrapping_mul(PRIME32_1);
    }
}

/// The accumulators folded to 64 bits from `start`, with the secret from `secret_at`.
fn merge(acc: &[u64; 8], secret_at: usize, start: u64) -> u64 {
    let mut result = start;
    for pair in 0..4 {
        result = result.wrapping_add(mul128_fold64(
            acc[2 * pair] ^ read64(&SECRET, secret_at + 16 * pair),
            acc[2 * pair + 1] ^ read64(&SECRET, secret_at + 16 * pair + 8),
        ));
    }
    avalanche(result)
}

fn long(input: &[u8]) -> Hash128 {
    let len = input.len();
    let mut acc = [
        PRIME32_3, PRIME64_1, PRIME64_2, PRIME64_3, PRIME64_4, PRIME32_2, PRIME64_5, PRIME32_1,
    ];
    let block_len = STRIPE_LEN * STRIPES_PER_BLOCK;
    let blocks = (len - 1) / block_len;
    for block in 0..blocks {
        for stripe in 0..STRIPES_PER_BLOCK {
            let at = block * block_len + stripe * STRIPE_LEN;
            accumulate_stripe(&mut acc, input, at, stripe * SECRET_CONSUME_RATE);
        }
        scramble(&mut acc);
    }
    let stripes = ((len - 1) - block_len * blocks) / STRIPE_LEN;
    for stripe in 0..stripes {
        let at = blocks * block_len + stripe * STRIPE_LEN;
        accumulate_stripe(&mut acc, input, at, stripe * SECRET_CONSUME_RATE);
    }
    // The last stripe, with the secret 7 bytes before its end.
    accumulate_stripe(
        &mut acc,
        input,
        len - STRIPE_LEN,
        SECRET.len() - STRIPE_LEN - 7,
    );
    Hash128 {
        low: merge(&acc, 11, (len as u64).wrapping_mul(PRIME64_1)),
        high: merge(
            &acc,
            SECRET.len() - STRIPE_LEN - 11,
            !(len as u64).wrapping_mul(PRIME64_2),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A deterministic input of `len` bytes.
    fn input(len: usize) -> Vec<u8> {
        (0..len).map(|i| ((i * 31 + 7) % 251) as u8).collect()
    }

    /// Hashes of `input(len)` by the xxHash library 0.8.4 (through the Python
    /// `xxhash` 4.1.0 package's `xxh3_128_intdigest`, high half first): every
    /// length class and the edges between them.
    const REFERENCE: [(usize, u128); 40] = [
        (0, 0x99aa06d3014798d86001c324468d497f),
        (1, 0x495b62073ef70ca44c5cca45d0f4811f),
        (2, 0x12b2847aa0de5aaaa7e250c97710ff27),
        (3, 0x46f66cb93538156515f7093b173d005c),
        (4, 0x7fefeeffb4d0eab3b987ca5d9241572a),
        (5, 0x2fbb16712b4bf1d5752a86982353f4f3),
        (7, 0x9194efbddb0d752c90d8d40e8b5ca9c4),
        (8, 0x803c675a846cc6c256bb836ceb6d4baa),
        (9, 0x365644c233ffe5c213af585c9bf5827d),
        (12, 0x40d4cd441c999504f0a84df510a4da0e),
        (16, 0xda917c385cc874c00d463cb04ceffbaf),
        (17, 0xd443578f2c4e2fb495c34448580e19c8),
        (31, 0xdeb01d8ab3a909306841d88c0d471a16),
        (32, 0x7e6bb3a654986c3373367e068a010989),
        (33, 0x97fbf3ce109f139623a0b885a7dac302),
        (48, 0xf29a0ba30bb219c4d4c38ade81fc7508),
        (63, 0x0d1ff0ca9aa9ba0e0d81652c4d7253ff),
        (64, 0x3515800f003ddbd064524fe2047012df),
        (65, 0x7fd00229a220a25b3b589ad4300ec5d5),
        (96, 0x0f5fdafe3c60a2ba6aaa14172a8f6957),
        (97, 0x203fb0b6f9a8419aaedfb1405f779a9d),
        (127, 0x659e0a0b25c7075a72400e87372440e9),
        (128, 0x22c34350373a38ae5b77925b2c683a12),
        (129, 0xc4a7d8f7893f2090d6d9e73553568be1),
        (159, 0x17f6464a68a4263ef9870ba424c5db9c),
        (160, 0x3c1fd79640cf3c229df001f621092150),
        (161, 0x0d36b5d3da1cd8f35d4e13a4bb87ee91),
        (192, 0x40503b1b9d3d611e5f3d8d1c640eaa77),
        (239, 0x9a032056470c2a3686bba9345dc34ac3),
        (240, 0xe29d70b8920fd24bc6ed4333f79384f8),
        (241, 0xf91b3cb8ed0fa91a07525dbc14902c7f),
        (255, 0x95bf93be894101733e64256196c9377b),
        (256, 0x6e4ce5e0d8c8f76fa49b06aa88ab05e1),
        (1023, 0x0789e58514a0668bfe4f1eaedb87b59b),
        (1024, 0xf53a1b1e9f1efedfe2898655db7bc9ee),
        (1025, 0xa906cca0f6e772a7134c652ba3d6fb9e),
        (2047, 0xf2fde42d5c7fd7712c2cbae270fe8aec),
        (2048, 0xaceedd29e1caaad363a78a59658d80f4),
        (2049, 0xaa660af6b116a0d40bfdaada21607d33),
        (3000, 0x7f30bf741f8b32824b4d4c38d3c7d2b6),
    ];

    #[test]
    fn every_length_class_equals_the_xxhash_library() {
        for (len, expected) in REFERENCE {
            let hash = hash128(&input(len));
            let got = (u128::from(hash.high) << 64) | u128::from(hash.low);
            assert_eq!(got, expected, "XXH3-128 of {len} bytes");
        }
    }
}
