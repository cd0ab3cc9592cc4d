//! The two codings a crate file's structural sections (and its large int arrays) are stored
//! in, as usd-core reads them (`TfFastCompression`, `Sdf_IntegerCompression`):
//!
//! - [`fast_compression`]: a zero byte ("one chunk") and one LZ4 block. We write the block as a
//!   single literal run: a valid LZ4 block that any LZ4 decoder reads, without a match search.
//!   The sections it holds are small (indices, not geometry), so the bytes saved by real
//!   matching would be a few kilobytes at most.
//! - [`compressed_ints`]: 32-bit integers as differences to their predecessor, each tagged by a
//!   2-bit code (the most common difference, or an 8-, 16- or 32-bit value), then
//!   [`fast_compression`].

use std::collections::HashMap;

/// `TfFastCompression` of `bytes`: `0` (one chunk) and an LZ4 block of one literal run.
pub fn fast_compression(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(bytes.len() + bytes.len() / 255 + 3);
    out.push(0);
    // The block's only sequence: a token whose high nibble is the literal length (15 means
    // "more length bytes follow": 255s and a final byte below 255), then the literals.
    let n = bytes.len();
    out.push((n.min(15) as u8) << 4);
    if n >= 15 {
        let mut rest = n - 15;
        while rest >= 255 {
            out.push(255);
            rest -= 255;
        }
        out.push(rest as u8);
    }
    out.extend_from_slice(bytes);
    out
}

/// `Sdf_IntegerCompression` of `ints` (the caller stores the count separately).
pub fn compressed_ints(ints: &[i32]) -> Vec<u8> {
    fast_compression(&encoded_ints(ints))
}

/// The integer coding before LZ4: the most common difference (ties: the largest), the 2-bit
/// codes of every integer (4 per byte, first in the low bits), then the values not coded as the
/// common one, in the smallest of 8, 16 or 32 bits that holds them.
pub fn encoded_ints(ints: &[i32]) -> Vec<u8> {
    if ints.is_empty() {
        return Vec::new();
    }
    let deltas: Vec<i32> = ints.iter().scan(0i32, |prev, &x| Some(x.wrapping_sub(std::mem::replace(prev, x)))).collect();
    let mut counts: HashMap<i32, usize> = HashMap::new();
    let (mut common, mut best) = (0i32, 0usize);
    for &d in &deltas {
        let c = counts.entry(d).or_insert(0);
        *c += 1;
        if *c > best || (*c == best && d > common) {
            (common, best) = (d, *c);
        }
    }
    let mut out = common.to_le_bytes().to_vec();
    let codes_at = out.len();
    out.resize(codes_at + deltas.len().div_ceil(4), 0);
    for (i, &d) in deltas.iter().enumerate() {
        let code = if d == common {
            0
        } else if let Ok(x) = i8::try_from(d) {
            out.extend_from_slice(&x.to_le_bytes());
            1
        } else if let Ok(x) = i16::try_from(d) {
            out.extend_from_slice(&x.to_le_bytes());
            2
        } else {
            out.extend_from_slice(&d.to_le_bytes());
            3
        };
        out[codes_at + i / 4] |= code << (2 * (i % 4));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The worked example of usd-core's integer coding (integerCoding.cpp), byte for byte.
    #[test]
    fn integer_coding_matches_the_reference_example() {
        let encoded = encoded_ints(&[123, 124, 125, 100125, 100125, 100126, 100126]);
        // common 1; codes 01 00 00 11 | 01 00 01; int8(123) int32(100000) int8(0) int8(0).
        let mut expected = 1i32.to_le_bytes().to_vec();
        expected.extend([0b1100_0001, 0b0001_0001]);
        expected.push(123);
        expected.extend(100000i32.to_le_bytes());
        expected.extend([0, 0]);
        assert_eq!(encoded, expected);
    }

    #[test]
    fn literal_runs_spell_their_length() {
        assert_eq!(fast_compression(b"abc"), [0, 0x30, b'a', b'b', b'c']);
        let long = vec![7u8; 15 + 255 + 3];
        let c = fast_compression(&long);
        assert_eq!(&c[..4], &[0, 0xf0, 255, 3]);
        assert_eq!(&c[4..], &long[..]);
        assert_eq!(fast_compression(&[]), [0, 0]);
    }
}
