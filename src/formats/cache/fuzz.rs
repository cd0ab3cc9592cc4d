//! Property-based fuzzing of the binary readers (PC2, MDD) and the OBJ-sequence pattern
//! parser: random bytes and mutations of valid files never panic, and no single allocation
//! exceeds a bound set by the input's size, whatever its header claims.
//!
//! The allocation bound is measured, not inferred: this test binary's global allocator
//! (`crate::support::testing::alloc`) records the largest request made on the current thread.

use std::io::Cursor;
use std::path::Path;

use proptest::prelude::*;

use super::mdd::MddFrames;
use super::pc2::{Pc2Frames, MAGIC};
use super::sequence::SequencePattern;
use super::FrameSource;
use crate::support::testing::alloc::largest_allocation;

/// Open `bytes` with a reader and read every frame (errors allowed, panics not); returns the
/// largest allocation. A reader that opens must report counts its bytes can hold.
fn exercise<S: FrameSource>(bytes: &[u8], open: impl FnOnce(Cursor<Vec<u8>>, u64) -> crate::Result<S>) -> usize {
    let len = bytes.len() as u64;
    let input = bytes.to_vec();
    largest_allocation(|| {
        if let Ok(mut frames) = open(Cursor::new(input), len) {
            assert!(frames.vertex_count() as u64 * frames.frame_count() as u64 * 12 <= len, "counts beyond the file");
            let mut out = vec![[0.0; 3]; frames.vertex_count()];
            for f in 0..frames.frame_count() {
                if let Err(e) = frames.read_frame(f, &mut out) {
                    let s = e.to_string();
                    assert!(s.contains(" (fix: ") && !s.contains('\n'), "{s}");
                }
            }
        }
    })
}

/// The bound: the frame buffer (12 bytes per point, at most the file) and the caller's output
/// (24 bytes per point), MDD's times as f64 (twice their bytes), and small change.
fn bound(len: usize) -> usize {
    2 * len + 4096
}

fn pc2_file(points: i32, samples: i32, data: &[f32]) -> Vec<u8> {
    let mut b = MAGIC.to_vec();
    for w in [1i32.to_le_bytes(), points.to_le_bytes(), 0f32.to_le_bytes(), 1f32.to_le_bytes(), samples.to_le_bytes()] {
        b.extend_from_slice(&w);
    }
    b.extend(data.iter().flat_map(|x| x.to_le_bytes()));
    b
}

fn mdd_file(frames: i32, points: i32, data: &[f32]) -> Vec<u8> {
    let mut b = [frames.to_be_bytes(), points.to_be_bytes()].concat();
    b.extend((0..frames).flat_map(|f| (f as f32 / 24.0).to_be_bytes()));
    b.extend(data.iter().flat_map(|x| x.to_be_bytes()));
    b
}

/// A valid file's mutations: truncation, byte flips, a header word replaced, bytes appended.
#[derive(Debug, Clone)]
enum Mutation {
    Truncate(usize),
    Flip(usize, u8),
    Word(usize, i32),
    Append(Vec<u8>),
}

fn mutate(mut bytes: Vec<u8>, mutations: &[Mutation]) -> Vec<u8> {
    for m in mutations {
        match m {
            Mutation::Truncate(at) => bytes.truncate(at % (bytes.len() + 1)),
            Mutation::Flip(at, mask) if !bytes.is_empty() => {
                let i = at % bytes.len();
                bytes[i] ^= mask;
            }
            Mutation::Word(slot, value) if bytes.len() >= 4 => {
                // Mostly header words, where the counts live.
                let i = (4 * (slot % 8)).min(bytes.len() - 4);
                bytes[i..i + 4].copy_from_slice(&value.to_le_bytes());
            }
            Mutation::Append(tail) => bytes.extend_from_slice(tail),
            _ => {}
        }
    }
    bytes
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        any::<usize>().prop_map(Mutation::Truncate),
        (any::<usize>(), 1..=255u8).prop_map(|(a, m)| Mutation::Flip(a, m)),
        (any::<usize>(), prop_oneof![any::<i32>(), Just(i32::MAX), Just(i32::MIN), Just(-1), Just(0), 1..64i32])
            .prop_map(|(s, v)| Mutation::Word(s, v)),
        prop::collection::vec(any::<u8>(), 1..40).prop_map(Mutation::Append),
    ]
}

fn valid_data() -> impl Strategy<Value = (i32, i32, Vec<f32>)> {
    (1..6i32, 1..6i32).prop_flat_map(|(p, s)| (Just(p), Just(s), prop::collection::vec(-1e3f32..1e3, (3 * p * s) as usize)))
}

fn pc2_open(c: Cursor<Vec<u8>>, len: u64) -> crate::Result<Pc2Frames<Cursor<Vec<u8>>>> {
    Pc2Frames::new(Path::new("fuzz.pc2"), c, len, 24.0)
}

fn mdd_open(c: Cursor<Vec<u8>>, len: u64) -> crate::Result<MddFrames<Cursor<Vec<u8>>>> {
    MddFrames::new(Path::new("fuzz.mdd"), c, len, Some(24.0))
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 3000, failure_persistence: None, ..ProptestConfig::default() })]

    #[test]
    fn pc2_random_bytes(bytes in prop::collection::vec(any::<u8>(), 0..200), magic in any::<bool>()) {
        // Half the inputs get the signature, so the header checks behind it are reached.
        let bytes = if magic { [MAGIC.as_slice(), &bytes].concat() } else { bytes };
        prop_assert!(exercise(&bytes, pc2_open) <= bound(bytes.len()));
    }

    #[test]
    fn pc2_mutations((p, s, data) in valid_data(), mutations in prop::collection::vec(mutation(), 0..4)) {
        let valid = pc2_file(p, s, &data);
        let mut frames = pc2_open(Cursor::new(valid.clone()), valid.len() as u64).expect("a valid file opens");
        let mut out = vec![[0.0; 3]; p as usize];
        frames.read_frame(s as usize - 1, &mut out).expect("a valid frame reads");
        prop_assert_eq!(out[0][0], data[3 * p as usize * (s as usize - 1)] as f64);
        let bytes = mutate(valid, &mutations);
        prop_assert!(exercise(&bytes, pc2_open) <= bound(bytes.len()));
    }

    #[test]
    fn mdd_random_bytes(bytes in prop::collection::vec(any::<u8>(), 0..200), small in any::<bool>()) {
        // Half the inputs start with small big-endian counts, so the size checks are reached.
        let bytes = if small { [[0, 0, 0, bytes.len() as u8 % 5 + 1, 0, 0, 0, 2].as_slice(), &bytes].concat() } else { bytes };
        prop_assert!(exercise(&bytes, mdd_open) <= bound(bytes.len()));
    }

    #[test]
    fn mdd_mutations((p, f, data) in valid_data(), mutations in prop::collection::vec(mutation(), 0..4)) {
        let valid = mdd_file(f, p, &data);
        prop_assert!(mdd_open(Cursor::new(valid.clone()), valid.len() as u64).is_ok());
        let bytes = mutate(valid, &mutations);
        prop_assert!(exercise(&bytes, mdd_open) <= bound(bytes.len()));
    }

    #[test]
    fn sequence_patterns_spell_each_number_once(
        name in prop::collection::vec(prop::sample::select(vec!['#', '%', '0', '4', 'd', '1', 'a', '_', '.', '/']), 0..16).prop_map(|c| c.into_iter().collect::<String>()),
        number in prop_oneof![0..100u64, any::<u64>().prop_map(|n| n % 1_000_000_000_000)],
        digits in prop::collection::vec(prop::sample::select(vec!['0', '1', '7', '9', 'x']), 0..22).prop_map(|c| c.into_iter().collect::<String>()),
    ) {
        if let Ok(pattern) = SequencePattern::parse(Path::new(&name)) {
            let spelled = pattern.file_name(number);
            prop_assert_eq!(pattern.number_of(&spelled), Some(number), "{} -> {}", name, spelled);
            // Any file name that matches spells its number the one way the pattern writes it.
            let candidate = pattern.with_digits(&digits);
            if let Some(n) = pattern.number_of(&candidate) {
                prop_assert_eq!(pattern.file_name(n), candidate);
            }
        }
    }
}

#[test]
fn the_probe_sees_allocations() {
    let largest = largest_allocation(|| {
        std::hint::black_box(vec![0u8; 123_456]);
    });
    assert!(largest >= 123_456);
    // A header claiming 2^31 points x 2^31 samples allocates nothing of that size.
    let bytes = pc2_file(i32::MAX, i32::MAX, &[0.0; 6]);
    assert!(exercise(&bytes, pc2_open) <= bound(bytes.len()));
}
