//! The raw channels' framing: the values of a link, each behind its length.

/// The message encoding of the raw channels: one or more values of the link,
/// in the order sent, each a little-endian `u32` length and then the value as
/// a link between processes carries it (the 41-byte
/// [`agent_core::WireHeader`], then the value's postcard bytes or its codec's
/// encoding). A raw message holds the values the writer took from one batch
/// of the executor's (about 64 KiB): a link sending at 1 kHz costs tens of
/// messages a second, not a thousand (docs/measurements.md, "The recorder's
/// encodings"). Its log time is its first value's instant; each value's own is
/// in its header.
pub const FRAMES_ENCODING: &str = "embodied-wire-frames/1";

/// The message encoding of the raw channels of earlier recordings: one value
/// per message, the wire header then the body. Replays read it still.
pub const WIRE_ENCODING: &str = "embodied-wire/1";

/// The values of a raw message of `encoding` ([`FRAMES_ENCODING`] or
/// [`WIRE_ENCODING`]), each a wire message ([`agent_core::WireHeader::read`]
/// splits it into header and body); an error says where the framing is cut.
pub fn raw_values<'a>(
    encoding: &str,
    data: &'a [u8],
) -> impl Iterator<Item = Result<&'a [u8], String>> + 'a {
    let framed = encoding == FRAMES_ENCODING;
    let mut rest = Some(data);
    let mut at = 0usize;
    std::iter::from_fn(move || {
        let r = rest.take()?;
        if !framed {
            return Some(Ok(r));
        }
        if r.is_empty() {
            return None;
        }
        let Some(len) = r
            .get(..4)
            .map(|b| u32::from_le_bytes([b[0], b[1], b[2], b[3]]) as usize)
        else {
            return Some(Err(format!(
                "a value's length cut short at byte {at} of the message"
            )));
        };
        let Some(value) = r.get(4..4 + len) else {
            return Some(Err(format!(
                "a value of {len} bytes at byte {at} of a message of {} bytes",
                data.len()
            )));
        };
        rest = Some(&r[4 + len..]);
        at += 4 + len;
        Some(Ok(value))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn framed(values: &[&[u8]]) -> Vec<u8> {
        let mut out = Vec::new();
        for v in values {
            out.extend_from_slice(&(v.len() as u32).to_le_bytes());
            out.extend_from_slice(v);
        }
        out
    }

    #[test]
    fn values_come_back_in_order_and_a_cut_is_named() {
        let data = framed(&[b"abc", b"", b"defgh"]);
        let values: Vec<_> = raw_values(FRAMES_ENCODING, &data).collect();
        assert_eq!(values, [Ok(&b"abc"[..]), Ok(&b""[..]), Ok(&b"defgh"[..])]);
        assert_eq!(raw_values(FRAMES_ENCODING, &[]).count(), 0);
        // Cut anywhere inside: the whole values before the cut, then one
        // error saying where, then nothing.
        for cut in 1..data.len() {
            let values: Vec<_> = raw_values(FRAMES_ENCODING, &data[..cut]).collect();
            let (last, whole) = values.split_last().expect("something");
            assert!(whole.iter().all(Result::is_ok), "cut at {cut}");
            let whole_values = match cut {
                0..=6 => 0,
                7..=10 => 1,
                _ => 2,
            };
            if [7, 11].contains(&cut) {
                assert!(last.is_ok(), "cut at {cut} is between values");
                continue;
            }
            assert_eq!(whole.len(), whole_values, "cut at {cut}");
            let e = last.clone().expect_err("the cut");
            assert!(
                e.contains(&format!("{cut} bytes")) || e.contains("cut short"),
                "{e}"
            );
        }
        // The earlier encoding: the message is the value.
        let values: Vec<_> = raw_values(WIRE_ENCODING, b"xyz").collect();
        assert_eq!(values, [Ok(&b"xyz"[..])]);
    }
}
