//! Mutated bitstreams: every alteration is an error, never a panic, with bounded memory.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::sync::OnceLock;

use codecs::bitstream::Bitstream;
use codecs::codec::{self, Params};
use motion::synth::{WalkParams, walking_clip};
use motion::{Clip, Skeleton};
use proptest::prelude::*;

/// A short clip coded by every codec: (clip, serialized streams).
fn corpus() -> &'static (Clip, Vec<Vec<u8>>) {
    static CORPUS: OnceLock<(Clip, Vec<Vec<u8>>)> = OnceLock::new();
    CORPUS.get_or_init(|| {
        let clip = walking_clip(&WalkParams {
            duration_s: 0.6,
            ..WalkParams::default()
        });
        let mut p = Params::new();
        let streams = codec::registry()
            .iter()
            .map(|c| {
                p.clear();
                if c.name().starts_with("wavelet") {
                    p.insert("window".into(), 64.0);
                }
                c.encode(&clip, &p).unwrap().to_bytes().unwrap()
            })
            .collect();
        (clip, streams)
    })
}

/// Offsets of the 32-bit length-like fields (channels, frames, payload length) of a stream.
fn length_fields(bytes: &[u8]) -> [usize; 3] {
    let s = Bitstream::from_bytes(bytes).unwrap();
    let params: usize = s.params.keys().map(|k| 1 + k.len() + 8).sum();
    let ch = 8 + params + 8;
    [ch, ch + 4, ch + 4 + 4 + 8]
}

#[derive(Debug, Clone)]
enum Mutation {
    Flip(Vec<usize>),
    Truncate(usize),
    Extend(Vec<u8>),
    LengthField(usize, u32),
    Overwrite(usize, u8),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        prop::collection::vec(any::<usize>(), 1..8).prop_map(Mutation::Flip),
        any::<usize>().prop_map(Mutation::Truncate),
        prop::collection::vec(any::<u8>(), 1..16).prop_map(Mutation::Extend),
        (0usize..3, any::<u32>()).prop_map(|(f, v)| Mutation::LengthField(f, v)),
        (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Mutation::Overwrite(i, b)),
    ]
}

fn apply(bytes: &[u8], m: &Mutation) -> Option<Vec<u8>> {
    let mut b = bytes.to_vec();
    match m {
        Mutation::Flip(bits) => {
            let n = b.len() * 8;
            let mut seen = std::collections::BTreeSet::new();
            for &bit in bits {
                seen.insert(bit % n);
            }
            // Flips that cancel out leave the stream unchanged; skip those.
            for bit in seen {
                b[bit / 8] ^= 1 << (bit % 8);
            }
        }
        Mutation::Truncate(n) => b.truncate(n % b.len()),
        Mutation::Extend(extra) => b.extend_from_slice(extra),
        Mutation::LengthField(f, v) => {
            let at = length_fields(bytes)[*f];
            b[at..at + 4].copy_from_slice(&v.to_le_bytes());
        }
        Mutation::Overwrite(i, v) => {
            let i = i % b.len();
            b[i] = *v;
        }
    }
    (b != bytes).then_some(b)
}

fn decode_all(bytes: &[u8], skeleton: &Skeleton) -> bool {
    match Bitstream::from_bytes(bytes) {
        Ok(s) => codec::decode_any(&s, skeleton).is_ok(),
        Err(_) => false,
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 10_000, failure_persistence: Some(Box::new(proptest::test_runner::FileFailurePersistence::WithSource("proptest-regressions"))), ..ProptestConfig::default() })]

    /// 10,000 mutated streams per run: every one is refused (CRC, sizes, limits), none panics.
    #[test]
    fn mutated_streams_are_errors(which in 0usize..8, m in mutation()) {
        let (clip, streams) = corpus();
        let original = &streams[which % streams.len()];
        if let Some(bad) = apply(original, &m) {
            prop_assert!(!decode_all(&bad, &clip.skeleton), "accepted after {m:?}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 1_000, failure_persistence: Some(Box::new(proptest::test_runner::FileFailurePersistence::WithSource("proptest-regressions"))), ..ProptestConfig::default() })]

    /// Payload corruption behind a recomputed CRC (what a buggy encoder or an attacker makes)
    /// reaches the codecs' own checks: they return Ok or Err, never panic, never allocate past
    /// the stream limits, and any clip they return has finite values and the right shape.
    #[test]
    fn payload_corruption_behind_a_valid_crc_never_panics(
        which in 0usize..8,
        edits in prop::collection::vec((any::<usize>(), any::<u8>()), 1..6),
        cut in proptest::option::of(any::<usize>()),
    ) {
        let (clip, streams) = corpus();
        let mut s = Bitstream::from_bytes(&streams[which % streams.len()]).unwrap();
        if !s.payload.is_empty() {
            for (i, v) in &edits {
                let n = s.payload.len();
                s.payload[i % n] = *v;
            }
            if let Some(c) = cut {
                let n = s.payload.len();
                s.payload.truncate(c % n);
            }
        }
        let bytes = s.to_bytes().unwrap();
        let parsed = Bitstream::from_bytes(&bytes).unwrap();
        if let Ok(d) = codec::decode_any(&parsed, &clip.skeleton) {
            prop_assert_eq!(d.frames(), clip.frames());
            prop_assert!(d.data().iter().all(|v| v.is_finite()));
        }
    }
}

#[test]
fn every_single_bit_flip_of_every_codec_stream_is_detected() {
    let (clip, streams) = corpus();
    for original in streams {
        // Long raw streams: every bit of the header and trailer, every 7th of the payload.
        for bit in (0..original.len() * 8)
            .filter(|b| *b < 800 || *b >= original.len() * 8 - 64 || b % 7 == 0)
        {
            let mut b = original.clone();
            b[bit / 8] ^= 1 << (bit % 8);
            assert!(
                !decode_all(&b, &clip.skeleton),
                "flip of bit {bit} accepted"
            );
        }
        assert!(decode_all(original, &clip.skeleton));
    }
}

#[test]
fn frame_count_beyond_the_limits_is_refused_before_allocation() {
    let (clip, streams) = corpus();
    let mut s = Bitstream::from_bytes(&streams[2]).unwrap();
    s.frames = u32::MAX;
    let bytes = s.to_bytes().unwrap();
    assert!(Bitstream::from_bytes(&bytes).is_err());
    s.frames = 1 << 21; // within max_frames, but × channels beyond max_values
    let bytes = s.to_bytes().unwrap();
    assert!(Bitstream::from_bytes(&bytes).is_err());
    assert!(codec::decode_any(&s, &clip.skeleton).is_err());
}
