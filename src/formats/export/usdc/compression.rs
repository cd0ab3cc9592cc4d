//! The two codings a crate file's structural sections (and its large int arrays) are stored
//! in, as usd-core reads them (`TfFastCompression`, `Sdf_IntegerCompression`):
//!
//! - [`fast_compression`]: a zero byte ("one chunk") and one LZ4 block, from a greedy match
//!   search over a table of the last position of each hashed 4 bytes (LZ4's own fast mode,
//!   without its acceleration heuristics). The sections it holds are small (indices, not
//!   geometry), so a better search would save a few hundred bytes at most.
//! - [`compressed_ints`]: 32-bit integers as differences to their predecessor, each tagged by a
//!   2-bit code (the most common difference, or an 8-, 16- or 32-bit value), then
//!   [`fast_compression`].
//!
//! Kept rather than `lz4_flex`: another matcher gives other bytes, and the usdc files of the
//! demo and the paper scenes are pinned byte for byte, for little gain: on the demo's twist.usdc
//! the reference LZ4 library's fast mode writes the structural sections in 1,498 bytes against
//! our 1,512 (of a 30,344-byte file), its HC level 9 in 1,417.

use std::collections::HashMap;

/// `TfFastCompression` of `bytes`: `0` (one chunk) and an LZ4 block.
pub fn fast_compression(bytes: &[u8]) -> Vec<u8> {
    let mut out = Vec::with_capacity(bytes.len() + bytes.len() / 255 + 16);
    out.push(0);
    lz4_block(bytes, &mut out);
    out
}

/// The LZ4 block format's limits: a match is at least 4 bytes, its offset at most 65535, the
/// last match starts at least 12 bytes before the end and the last 5 bytes are literals.
const MIN_MATCH: usize = 4;
const MAX_OFFSET: usize = 65535;
const MATCH_START_LIMIT: usize = 12;
const LAST_LITERALS: usize = 5;
const HASH_BITS: u32 = 12;

/// One LZ4 block: sequences of (literals, match), the last one literals only.
pub(crate) fn lz4_block(input: &[u8], out: &mut Vec<u8>) {
    let n = input.len();
    let mut last_seen = vec![usize::MAX; 1 << HASH_BITS];
    let (mut anchor, mut i) = (0, 0);
    let four = |at: usize| u32::from_le_bytes(input[at..at + 4].try_into().expect("4 bytes"));
    while i + MATCH_START_LIMIT <= n {
        let hash = (four(i).wrapping_mul(2_654_435_761) >> (32 - HASH_BITS)) as usize;
        let candidate = std::mem::replace(&mut last_seen[hash], i);
        if candidate != usize::MAX && i - candidate <= MAX_OFFSET && four(candidate) == four(i) {
            let mut len = MIN_MATCH;
            while i + len < n - LAST_LITERALS && input[candidate + len] == input[i + len] {
                len += 1;
            }
            push_sequence(out, &input[anchor..i], Some((i - candidate, len)));
            i += len;
            anchor = i;
        } else {
            i += 1;
        }
    }
    push_sequence(out, &input[anchor..], None);
}

/// A token (literal length, match length - 4, 15 meaning "more bytes follow": 255s and a final
/// byte below 255), the literals, and the match's offset and length.
fn push_sequence(out: &mut Vec<u8>, literals: &[u8], matched: Option<(usize, usize)>) {
    let extra = matched.map_or(0, |(_, len)| len - MIN_MATCH);
    out.push(((literals.len().min(15) as u8) << 4) | extra.min(15) as u8);
    push_length(out, literals.len());
    out.extend_from_slice(literals);
    if let Some((offset, _)) = matched {
        out.extend_from_slice(&(offset as u16).to_le_bytes());
        push_length(out, extra);
    }
}

fn push_length(out: &mut Vec<u8>, len: usize) {
    if len >= 15 {
        let mut rest = len - 15;
        while rest >= 255 {
            out.push(255);
            rest -= 255;
        }
        out.push(rest as u8);
    }
}

/// `Sdf_IntegerCompression` of `ints` (the caller stores the count separately).
pub fn compressed_ints(ints: &[i32]) -> Vec<u8> {
    fast_compression(&encoded_ints(ints))
}

/// The integer coding before LZ4: the most common difference (ties: the largest), the 2-bit
/// codes of every integer (4 per byte, first in the low bits), then the values not coded as the
/// common one, in the smallest of 8, 16 or 32 bits that holds them.
pub(crate) fn encoded_ints(ints: &[i32]) -> Vec<u8> {
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

    /// A plain LZ4 block decoder (the format's definition), to check our blocks against.
    fn lz4_decode(block: &[u8]) -> Vec<u8> {
        let (mut out, mut i) = (Vec::new(), 0);
        let length = |i: &mut usize, nibble: usize| {
            let mut len = nibble;
            if nibble == 15 {
                loop {
                    let b = block[*i];
                    *i += 1;
                    len += b as usize;
                    if b != 255 {
                        break;
                    }
                }
            }
            len
        };
        loop {
            let token = block[i] as usize;
            i += 1;
            let literals = length(&mut i, token >> 4);
            out.extend_from_slice(&block[i..i + literals]);
            i += literals;
            if i == block.len() {
                return out;
            }
            let offset = u16::from_le_bytes([block[i], block[i + 1]]) as usize;
            i += 2;
            let len = length(&mut i, token & 15) + MIN_MATCH;
            assert!(offset > 0 && offset <= out.len(), "offset {offset} at {}", out.len());
            for _ in 0..len {
                out.push(out[out.len() - offset]);
            }
        }
    }

    #[test]
    fn lz4_blocks_decode_to_their_input_and_keep_the_format_limits() {
        let mut inputs: Vec<Vec<u8>> = vec![vec![], b"abc".to_vec(), vec![7; 12], vec![7; 13], vec![0; 100_000]];
        inputs.push((0..5000u32).flat_map(|i| (i % 37 * 1000 + i / 100).to_le_bytes()).collect());
        inputs.push((0..70_000u32).map(|i| (i.wrapping_mul(2_654_435_761) >> 13) as u8).collect());
        inputs.push(b"the tokens of a layer: points\0extent\0points\0offsets\0pointIndices\0points\0".repeat(30));
        for input in inputs {
            let c = fast_compression(&input);
            assert_eq!(c[0], 0);
            assert_eq!(lz4_decode(&c[1..]), input, "{} bytes", input.len());
            if input.len() > 64 && input.iter().all(|&b| b == input[0]) {
                assert!(c.len() < input.len() / 100, "a run compresses: {} -> {}", input.len(), c.len());
            }
        }
        assert_eq!(fast_compression(b"abc"), [0, 0x30, b'a', b'b', b'c']);
        assert_eq!(fast_compression(&[]), [0, 0]);
    }
}
