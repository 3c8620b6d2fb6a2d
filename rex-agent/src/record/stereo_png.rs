//! [`StereoPng`]: the camera's pairs on their raw channel as two PNG images.
//!
//! Format `rex.stereo-png/1`, after the wire header:
//!
//! * `1`, then the pair's postcard bytes up to its images (sequence number,
//!   time, width, height: exactly as the link carried them), the left image's
//!   PNG length (`u32`, little-endian), the left PNG, the right PNG: for a
//!   pair whose two images are `width x height` 8-bit pixels;
//! * `0`, then the value's bytes verbatim: anything else (a pair whose sizes
//!   disagree, bytes that are not a pair).
//!
//! PNG (8-bit grayscale, fast compression) predicts each pixel from its
//! neighbours: the camera's noisy images shrink more than in the file's zstd
//! chunks, in less time (docs/measurements.md, "The recorder's encodings";
//! `bench_record`).

use embodied::record::{Codec, DecodeError};
use serde_bytes::Bytes;

use crate::payload::StereoPair;
use crate::world::camera::kitti::MAX_PNG_SIDE;

/// The codec of [`StereoPair`] (see the module's documentation).
#[derive(Clone, Copy, Debug, Default)]
pub struct StereoPng;

/// The name a recording's raw channel gives.
pub(super) const NAME: &str = "rex.stereo-png/1";

const VERBATIM: u8 = 0;
const PNG: u8 = 1;

/// The fields of a pair before its images, in postcard's order.
type Head = (u64, f64, u32, u32);

/// A pair in parts: the bytes of its head as they came, the head, and its two
/// images (pixels, or PNGs).
pub(super) struct Parts<'a> {
    prefix: &'a [u8],
    head: Head,
    pub(super) left: &'a [u8],
    right: &'a [u8],
}

/// A pair's postcard bytes, split. `None` when the bytes are not exactly the
/// canonical encoding of a pair (the codec then keeps them verbatim).
fn split(body: &[u8]) -> Option<Parts<'_>> {
    let (head, rest): (Head, _) = postcard::take_from_bytes(body).ok()?;
    let prefix = &body[..body.len() - rest.len()];
    if postcard::to_allocvec(&head).ok()? != prefix {
        return None;
    }
    let (left, after_left): (&[u8], _) = postcard::take_from_bytes(rest).ok()?;
    let (right, end): (&[u8], _) = postcard::take_from_bytes(after_left).ok()?;
    let canonical = |whole: &[u8], after: &[u8], image: &[u8]| {
        whole.len() - after.len() == varint_len(image.len()) + image.len()
    };
    let n = (head.2 as usize).checked_mul(head.3 as usize)?;
    // Only what `decode` takes back: a side beyond MAX_PNG_SIDE goes verbatim.
    (end.is_empty()
        && head.2 <= MAX_PNG_SIDE
        && head.3 <= MAX_PNG_SIDE
        && canonical(rest, after_left, left)
        && canonical(after_left, end, right)
        && n > 0
        && left.len() == n
        && right.len() == n)
        .then_some(Parts {
            prefix,
            head,
            left,
            right,
        })
}

/// The length of postcard's varint for `n`.
fn varint_len(n: usize) -> usize {
    (usize::BITS - n.leading_zeros()).div_ceil(7).max(1) as usize
}

/// `image` (`w x h`, 8-bit gray) as a PNG, appended to `out`.
pub(crate) fn encode_png(image: &[u8], w: u32, h: u32, out: &mut Vec<u8>) -> bool {
    let mut encoder = png::Encoder::new(out, w, h);
    encoder.set_color(png::ColorType::Grayscale);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Fast);
    let Ok(mut writer) = encoder.write_header() else {
        return false;
    };
    writer.write_image_data(image).is_ok() && writer.finish().is_ok()
}

/// A `w x h` 8-bit gray PNG's pixels.
fn decode_png(data: &[u8], w: u32, h: u32) -> Result<Vec<u8>, String> {
    if w > MAX_PNG_SIDE || h > MAX_PNG_SIDE {
        return Err(format!(
            "the pair says {w}x{h} pixels; at most {MAX_PNG_SIDE} in each direction"
        ));
    }
    let mut decoder = png::Decoder::new(std::io::Cursor::new(data));
    // No transformation: 8-bit gray is what it must be, as it is.
    decoder.set_transformations(png::Transformations::IDENTITY);
    let mut reader = decoder.read_info().map_err(|e| format!("not a PNG: {e}"))?;
    let info = reader.info();
    if info.size() != (w, h)
        || info.color_type != png::ColorType::Grayscale
        || info.bit_depth != png::BitDepth::Eight
    {
        return Err(format!(
            "a {:?} {:?} PNG of {:?} pixels, where the pair says 8-bit gray {w}x{h}",
            info.bit_depth,
            info.color_type,
            info.size()
        ));
    }
    let mut pixels = vec![0; reader.output_buffer_size()];
    reader
        .next_frame(&mut pixels)
        .and_then(|_| reader.finish())
        .map_err(|e| format!("a damaged PNG: {e}"))?;
    Ok(pixels)
}

/// The PNG form's parts (the images as PNGs).
pub(super) fn parts(data: &[u8]) -> Option<Parts<'_>> {
    let rest = data.strip_prefix(&[PNG])?;
    let (head, after): (Head, _) = postcard::take_from_bytes(rest).ok()?;
    let prefix = &rest[..rest.len() - after.len()];
    let len = u32::from_le_bytes(after.get(..4)?.try_into().ok()?) as usize;
    let left = after.get(4..4usize.checked_add(len)?)?;
    let right = after.get(4 + len..)?;
    Some(Parts {
        prefix,
        head,
        left,
        right,
    })
}

impl Codec for StereoPng {
    fn payload(&self) -> &str {
        std::any::type_name::<StereoPair>()
    }

    fn name(&self) -> &str {
        NAME
    }

    fn encode(&self, body: &[u8], out: &mut Vec<u8>) {
        let start = out.len();
        if let Some(Parts {
            prefix,
            head: (_, _, w, h),
            left,
            right,
        }) = split(body)
        {
            out.push(PNG);
            out.extend_from_slice(prefix);
            let at = out.len();
            out.extend_from_slice(&[0; 4]);
            let left_ok = encode_png(left, w, h, out);
            let len = u32::try_from(out.len() - at - 4).ok();
            if let (true, Some(len)) = (left_ok, len) {
                out[at..at + 4].copy_from_slice(&len.to_le_bytes());
                if encode_png(right, w, h, out) {
                    return;
                }
            }
            out.truncate(start);
        }
        out.push(VERBATIM);
        out.extend_from_slice(body);
    }

    fn decode(&self, data: &[u8], out: &mut Vec<u8>) -> Result<(), DecodeError> {
        decode_pair(data, out).map_err(DecodeError::new)
    }
}

/// [`StereoPng`]'s decoding, its error in words.
fn decode_pair(data: &[u8], out: &mut Vec<u8>) -> Result<(), String> {
    match data.first() {
        Some(&VERBATIM) => {
            out.extend_from_slice(&data[1..]);
            Ok(())
        }
        Some(&PNG) => {
            let Parts {
                prefix,
                head: (_, _, w, h),
                left,
                right,
            } = parts(data).ok_or("a PNG form cut short")?;
            let left = decode_png(left, w, h).map_err(|e| format!("left image: {e}"))?;
            let right = decode_png(right, w, h).map_err(|e| format!("right image: {e}"))?;
            out.extend_from_slice(prefix);
            let images = (Bytes::new(&left), Bytes::new(&right));
            *out = postcard::to_extend(&images, std::mem::take(out)).map_err(|e| e.to_string())?;
            Ok(())
        }
        Some(tag) => Err(format!("form {tag} (0 or 1 expected)")),
        None => Err("no bytes".into()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn pair(w: u32, h: u32, seed: u8) -> StereoPair {
        let n = (w * h) as usize;
        StereoPair {
            seq: 7,
            time: 0.7,
            width: w,
            height: h,
            left: (0..n).map(|k| (k as u8).wrapping_mul(seed)).collect(),
            right: (0..n).map(|k| (k as u8) ^ seed).collect(),
        }
    }

    fn round_trip(body: &[u8]) -> (Vec<u8>, Vec<u8>) {
        let mut encoded = Vec::new();
        StereoPng.encode(body, &mut encoded);
        let mut decoded = Vec::new();
        StereoPng.decode(&encoded, &mut decoded).unwrap();
        (encoded, decoded)
    }

    #[test]
    fn a_pair_goes_as_two_pngs_and_comes_back_exactly() {
        let body = postcard::to_allocvec(&pair(64, 48, 3)).unwrap();
        let (encoded, decoded) = round_trip(&body);
        assert_eq!(encoded[0], PNG);
        assert_eq!(decoded, body);
        let p = parts(&encoded).unwrap();
        assert_eq!(p.head, (7, 0.7, 64, 48));
        assert_eq!(decode_png(p.left, 64, 48).unwrap(), pair(64, 48, 3).left);
        assert_eq!(decode_png(p.right, 64, 48).unwrap(), pair(64, 48, 3).right);
    }

    #[test]
    fn a_pair_whose_sizes_disagree_goes_verbatim() {
        let mut p = pair(8, 8, 5);
        p.right.pop();
        let body = postcard::to_allocvec(&p).unwrap();
        let (encoded, decoded) = round_trip(&body);
        assert_eq!(encoded[0], VERBATIM);
        assert_eq!(decoded, body);
        // An empty pair too.
        let body = postcard::to_allocvec(&StereoPair::default()).unwrap();
        assert_eq!(round_trip(&body).1, body);
        // A side longer than a PNG may have here: verbatim, so it comes back.
        let body = postcard::to_allocvec(&pair(MAX_PNG_SIDE + 1, 1, 2)).unwrap();
        let (encoded, decoded) = round_trip(&body);
        assert_eq!(encoded[0], VERBATIM);
        assert_eq!(decoded, body);
    }

    #[test]
    fn a_damaged_encoding_is_an_error() {
        let body = postcard::to_allocvec(&pair(16, 16, 9)).unwrap();
        let mut encoded = Vec::new();
        StereoPng.encode(&body, &mut encoded);
        let mut out = Vec::new();
        for cut in [1, 10, encoded.len() / 2, encoded.len() - 1] {
            out.clear();
            assert!(
                StereoPng.decode(&encoded[..cut], &mut out).is_err(),
                "{cut}"
            );
        }
        assert!(StereoPng.decode(&[], &mut out).is_err());
        assert!(StereoPng.decode(&[2, 0], &mut out).is_err());
    }

    proptest! {
        /// Any bytes, a pair or not, come back as they were.
        #[test]
        fn any_bytes_come_back_as_they_were(body in prop::collection::vec(any::<u8>(), 0..300)) {
            prop_assert_eq!(round_trip(&body).1, body);
        }

        /// Any pair comes back exactly, and by its PNGs when its sizes agree.
        #[test]
        fn any_pair_comes_back_exactly(w in 1u32..40, h in 1u32..40, seed in any::<u8>(), seq in any::<u64>(), time in any::<f64>()) {
            let mut p = pair(w, h, seed);
            p.seq = seq;
            p.time = time;
            let body = postcard::to_allocvec(&p).unwrap();
            let (encoded, decoded) = round_trip(&body);
            prop_assert_eq!(encoded[0], PNG);
            prop_assert_eq!(decoded, body);
        }

        /// Damaged encodings are an error or some bytes, never a panic.
        #[test]
        fn damaged_encodings_never_panic(at in any::<prop::sample::Index>(), byte in any::<u8>()) {
            let body = postcard::to_allocvec(&pair(12, 10, 3)).unwrap();
            let mut encoded = Vec::new();
            StereoPng.encode(&body, &mut encoded);
            let k = at.index(encoded.len());
            encoded[k] = byte;
            let mut out = Vec::new();
            let _ = StereoPng.decode(&encoded, &mut out);
        }
    }
}
