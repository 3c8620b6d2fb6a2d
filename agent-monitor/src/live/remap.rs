//! A node's predicates, from its FSM's bits to the spec's, in a few table
//! lookups rather than a loop over the bits.

/// A map of some of 64 source bits onto target bits, each source bit to at
/// most one target bit: one table of 256 words per source byte that holds a
/// mapped bit, so that [`Remap::apply`] costs a lookup per such byte.
#[derive(Clone, Debug, Default)]
pub(super) struct Remap {
    bytes: Vec<(u32, Box<[u64; 256]>)>,
}

impl Remap {
    /// Source bit `f` to target bit `k`, for each `(f, k)` of `pairs` (both
    /// below 64; any other pair is ignored).
    pub(super) fn new(pairs: &[(u8, u8)]) -> Remap {
        let mut bytes: Vec<(u32, Box<[u64; 256]>)> = Vec::new();
        for &(f, k) in pairs.iter().filter(|(f, k)| *f < 64 && *k < 64) {
            let byte = u32::from(f / 8);
            let at = match bytes.iter().position(|(b, _)| *b == byte) {
                Some(at) => at,
                None => {
                    bytes.push((byte, Box::new([0; 256])));
                    bytes.len() - 1
                }
            };
            let table = &mut bytes[at].1;
            for (v, word) in table.iter_mut().enumerate() {
                if v >> (f % 8) & 1 == 1 {
                    *word |= 1 << k;
                }
            }
        }
        Remap { bytes }
    }

    /// The target bits of the source bits set in `x`.
    #[inline]
    pub(super) fn apply(&self, x: u64) -> u64 {
        (self.bytes.iter()).fold(0, |a, (b, t)| a | t[(x >> (8 * b)) as usize & 0xff])
    }
}

#[cfg(test)]
mod tests {
    use super::Remap;

    /// The loop it replaces.
    fn slow(pairs: &[(u8, u8)], x: u64) -> u64 {
        (pairs.iter()).fold(0, |a, &(f, k)| a | (x >> f & 1) << k)
    }

    #[test]
    fn maps_as_the_loop_over_the_bits_does() {
        // A fixed generator: the same cases every run.
        let mut seed = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            seed ^= seed << 13;
            seed ^= seed >> 7;
            seed ^= seed << 17;
            seed
        };
        for _ in 0..200 {
            let n = (next() % 20) as usize;
            let mut targets: Vec<u8> = (0..64).collect();
            let mut pairs = Vec::new();
            for _ in 0..n {
                let f = (next() % 64) as u8;
                if pairs.iter().any(|(g, _)| *g == f) {
                    continue;
                }
                let k = targets.swap_remove((next() % targets.len() as u64) as usize);
                pairs.push((f, k));
            }
            let remap = Remap::new(&pairs);
            for _ in 0..50 {
                let x = next();
                assert_eq!(remap.apply(x), slow(&pairs, x), "{pairs:?} {x:#x}");
            }
            assert_eq!(remap.apply(u64::MAX), slow(&pairs, u64::MAX));
            assert_eq!(remap.apply(0), 0);
        }
        assert_eq!(Remap::new(&[]).apply(u64::MAX), 0);
        // Out of range pairs are ignored.
        assert_eq!(Remap::new(&[(64, 0), (0, 64), (3, 1)]).apply(0b1000), 0b10);
    }
}
