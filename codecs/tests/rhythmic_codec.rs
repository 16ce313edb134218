//! The `rhythmic` codec (thesis ch. 4) on the shared CMU clips and the generated walk: round
//! trips, the database section and the ratios with and without it, the blend points against a
//! brute-force search of the distance map (eq. 4.3), and corrupt streams under a memory cap.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::sync::OnceLock;

use cap::Cap;
use codecs::bitstream::Bitstream;
use codecs::codec::rhythmic::{self, RhythmicCodec, Traced};
use codecs::codec::{self, Codec, CodecError, Params};
use codecs::metrics::compare;
use motion::fk::Kinematics;
use motion::quat::to_quaternions;
use motion::synth::{WalkParams, walking_clip};
use motion::{Clip, data, io};
use proptest::prelude::*;

/// 1 GiB for the whole binary: far above what decoding the clips needs, far below what a
/// decoder trusting a corrupt count would ask for.
#[global_allocator]
static ALLOC: Cap<std::alloc::System> = Cap::new(std::alloc::System, 1 << 30);

fn shared() -> &'static [(String, Clip)] {
    static CLIPS: OnceLock<Vec<(String, Clip)>> = OnceLock::new();
    CLIPS.get_or_init(|| {
        data::shared_clips()
            .into_iter()
            .map(|f| (f.name, io::read_clip(f.asf.as_deref(), &f.motion).unwrap()))
            .collect()
    })
}

fn clip(name: &str) -> &'static Clip {
    &shared().iter().find(|(n, _)| n == name).unwrap().1
}

fn params(pairs: &[(&str, f64)]) -> Params {
    pairs.iter().map(|(k, v)| ((*k).to_string(), *v)).collect()
}

fn traced(clip: &Clip, p: &Params) -> (Bitstream, Traced) {
    let c = RhythmicCodec::new();
    let s = c.encode(clip, p).unwrap();
    let parsed = Bitstream::from_bytes(&s.to_bytes().unwrap()).unwrap();
    assert_eq!(parsed, s);
    let t = c.decode_traced(&parsed, &clip.skeleton).unwrap();
    (parsed, t)
}

#[test]
fn shared_clips_are_present() {
    if data::mocap_dir().is_some() {
        assert_eq!(shared().len(), 5);
    }
}

/// Every shared clip round-trips through the registry with the default settings, and with a
/// primitive per segment (`k` = 256) the decoder rebuilds the clip: what is left is the
/// database's 10:1 wavelet coding, the anchors' 0.5 cm / 0.5° steps and the blending.
#[test]
fn every_shared_clip_round_trips() {
    let c = RhythmicCodec::new();
    for (name, clip) in shared() {
        let s = c.encode(clip, &Params::new()).unwrap();
        assert_eq!(s.codec_id, 9);
        let parsed = Bitstream::from_bytes(&s.to_bytes().unwrap()).unwrap();
        let d = codec::decode_any(&parsed, &clip.skeleton).unwrap();
        assert_eq!(
            (d.frames(), d.channel_count()),
            (clip.frames(), clip.channel_count())
        );
        assert!(d.data().iter().all(|v| v.is_finite()), "{name}");
        let parts = rhythmic::stream_parts(&s).unwrap();
        assert_eq!(parts.total_bytes, s.byte_len());
        assert!((parts.cr_with_database() - s.compression_ratio()).abs() < 1e-9);
        // The references alone are a few bytes per segment.
        assert!(parts.cr_without_database() > 300.0, "{name}: {parts:?}");
        assert!(parts.cr_with_database() > 5.0, "{name}: {parts:?}");
        let m = compare(clip, &d).unwrap();
        assert!(m.rms_cm < 15.0, "{name}: {} cm", m.rms_cm);

        let (_, t) = traced(clip, &params(&[("k", 256.0)]));
        assert_eq!(t.primitives, t.segments.len(), "{name}");
        let m = compare(clip, &t.clip).unwrap();
        assert!(m.rms_cm < 0.5 && m.max_cm < 2.0, "{name}: {m:?}");
    }
}

/// Where the method works: a long periodic motion (the generated walk) repeats its moves, so
/// 20 primitives cover it with a small error at a high ratio, and the ratio grows with the
/// clip's length (Table 4.1's trend) while the error does not.
#[test]
fn a_long_periodic_motion_compresses_well_and_better_the_longer_it_is() {
    let crs: Vec<f64> = [10.0, 30.0]
        .into_iter()
        .map(|duration_s| {
            let walk = walking_clip(&WalkParams {
                duration_s,
                ..WalkParams::default()
            });
            let (s, t) = traced(&walk, &Params::new());
            let m = compare(&walk, &t.clip).unwrap();
            assert!(m.rms_cm < 0.5, "{duration_s} s: {} cm", m.rms_cm);
            rhythmic::stream_parts(&s).unwrap().cr_with_database()
        })
        .collect();
    assert!(crs[1] > 1.5 * crs[0] && crs[1] > 40.0, "{crs:?}");
}

/// Eq. 4.3 at every pair of the join's windows from an FK of our own (one pose per frame), and
/// the pair the decoder chose is the first smallest of them. Only the frames strictly between
/// the pair are changed, and those by SLERP from frame x to frame y.
#[test]
fn blend_points_are_the_minimum_of_a_brute_force_distance_map() {
    let clip = clip("charleston1");
    let (_, t) = traced(clip, &Params::new());
    assert_eq!(t.joins.len(), t.segments.len() - 1);
    let kin = Kinematics::new(&clip.skeleton);
    let mut values = Vec::new();
    let mut points = Vec::new();
    let poses: Vec<Vec<[f64; 3]>> = (0..t.unblended.frames())
        .map(|f| {
            t.unblended.frame_into(f, &mut values);
            kin.pose(&values, &mut points);
            points.clone()
        })
        .collect();
    let window = |len: usize| ((0.25 * len as f64).round() as usize).min(len / 2);
    let mut moved = 0;
    for (j, pair) in t.joins.iter().zip(t.segments.windows(2)) {
        let e = pair[1].start;
        assert_eq!(j.frame, e);
        let mut best = (0, 0, f64::INFINITY);
        for x in e - window(pair[0].len())..e {
            for y in e..e + window(pair[1].len()) {
                let d: f64 = poses[x]
                    .iter()
                    .zip(&poses[y])
                    .map(|(a, b)| (0..3).map(|i| (a[i] - b[i]).powi(2)).sum::<f64>())
                    .sum();
                if d < best.2 {
                    best = (x, y, d);
                }
            }
        }
        assert_eq!((j.from, j.to), (best.0, best.1), "join at {e}");
        assert!((j.distance - best.2).abs() <= 1e-9 * best.2.max(1.0));
        moved += usize::from(j.to - j.from >= 2);
    }
    assert!(moved > 0, "no join blended anything");
    // Frames outside every (x, y) keep the pieces' rotations; inside they are the SLERP.
    let (a, b) = (to_quaternions(&t.unblended), to_quaternions(&t.clip));
    let inside = |f: usize| t.joins.iter().any(|j| j.from < f && f < j.to);
    for f in 0..clip.frames() {
        for (k, (ra, rb)) in a.rotations.iter().zip(&b.rotations).enumerate() {
            let expected = match t.joins.iter().find(|j| j.from < f && f < j.to) {
                Some(j) => ra[j.from].slerp(ra[j.to], (f - j.from) as f64 / (j.to - j.from) as f64),
                None => ra[f],
            };
            // The output holds what the joint's channels can: compare 3-dof joints only.
            if clip.skeleton.joints[a.joints[k]].dofs.len() == 3 {
                let d = rb[f].distance(expected);
                assert!(d < 1e-6, "frame {f} joint {k} (inside {}): {d}", inside(f));
            }
        }
    }
}

/// Without blending the pieces are played as placed; `anchor = 0` (the literal reading: the
/// root carried on by each piece's velocity) sends one anchor instead of one per segment and
/// drifts away from the source's path.
#[test]
fn blending_and_anchors_can_be_switched_off() {
    let clip = &clip("lambada").excerpt(0..1200);
    let (_, plain) = traced(clip, &params(&[("blend", 0.0)]));
    assert!(plain.joins.is_empty());
    assert_eq!(plain.clip, plain.unblended);
    let (s1, anchored) = traced(clip, &Params::new());
    let (s0, literal) = traced(clip, &params(&[("anchor", 0.0)]));
    assert!(s0.byte_len() < s1.byte_len());
    let (m1, m0) = (
        compare(clip, &anchored.clip).unwrap(),
        compare(clip, &literal.clip).unwrap(),
    );
    assert!(
        m0.rms_cm > 3.0 * m1.rms_cm,
        "{} vs {}",
        m0.rms_cm,
        m1.rms_cm
    );
}

#[test]
fn parts_of_another_codecs_stream_and_bad_parameters_are_refused() {
    let walk = walking_clip(&WalkParams::default());
    let spiht = codec::by_name("spiht").unwrap();
    let s = spiht.encode(&walk, &params(&[("cr", 20.0)])).unwrap();
    assert!(matches!(
        rhythmic::stream_parts(&s),
        Err(CodecError::WrongCodec { found: 6, .. })
    ));
    let c = RhythmicCodec::new();
    for (k, v) in [
        ("k", 0.0),
        ("k", 2.5),
        ("s_m", 14.0),
        ("blend", 0.7),
        ("anchor", 2.0),
    ] {
        let e = c.encode(&walk, &params(&[(k, v)])).unwrap_err().to_string();
        assert!(e.contains(k), "{k} = {v}: {e}");
    }
    // No target rate: the ratio follows from the clip's repetitions and k.
    assert!(matches!(
        codecs::rate::encode_to_cr(&c, &walk, &Params::new(), 20.0),
        Err(CodecError::Param { key, .. }) if key == "cr"
    ));
    assert!(c.encode(&walk, &params(&[("cr", 20.0)])).is_err());
}

/// A database section that is not a `wavelet-perceptual` stream of the skeleton, or another
/// payload version, is an error naming what is wrong.
#[test]
fn a_foreign_database_section_or_payload_version_is_refused() {
    let walk = walking_clip(&WalkParams::default());
    let c = RhythmicCodec::new();
    let s = c.encode(&walk, &Params::new()).unwrap();
    let mut v2 = s.clone();
    v2.payload[0] = 2;
    let e = c.decode(&v2, &walk.skeleton).unwrap_err().to_string();
    assert!(e.contains("payload format version 2"), "{e}");
    // Swap the database section for a SPIHT stream of the same clip.
    let spiht = codec::by_name("spiht").unwrap();
    let foreign = spiht
        .encode(&walk, &params(&[("cr", 10.0)]))
        .unwrap()
        .to_bytes()
        .unwrap();
    let len = u32::from_le_bytes(s.payload[1..5].try_into().unwrap()) as usize;
    let mut swapped = s.clone();
    swapped.payload = [
        &s.payload[..1],
        &(foreign.len() as u32).to_le_bytes(),
        &foreign,
        &s.payload[5 + len..],
    ]
    .concat();
    let e = c.decode(&swapped, &walk.skeleton).unwrap_err().to_string();
    assert!(e.contains("codec id 6"), "{e}");
    let mut long = s;
    long.payload[1..5].copy_from_slice(&u32::MAX.to_le_bytes());
    let e = c.decode(&long, &walk.skeleton).unwrap_err().to_string();
    assert!(e.contains("longer than the payload"), "{e}");
}

/// Streams of a short walk and of a lambada excerpt, serialized.
fn corpus() -> &'static Vec<(Clip, Vec<u8>)> {
    static C: OnceLock<Vec<(Clip, Vec<u8>)>> = OnceLock::new();
    C.get_or_init(|| {
        let walk = walking_clip(&WalkParams {
            duration_s: 1.0,
            ..WalkParams::default()
        });
        let mut clips = vec![walk];
        if data::mocap_dir().is_some() {
            clips.push(clip("lambada").excerpt(0..240));
        }
        clips
            .into_iter()
            .map(|c| {
                let bytes = RhythmicCodec::new()
                    .encode(&c, &params(&[("k", 4.0)]))
                    .unwrap()
                    .to_bytes()
                    .unwrap();
                (c, bytes)
            })
            .collect()
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 300, failure_persistence: None, ..ProptestConfig::default() })]

    /// Payload edits and cuts behind a recomputed CRC reach the decoder's own checks: an error
    /// or a finite clip of the right shape, never a panic, never an allocation past the cap.
    #[test]
    fn corrupt_payloads_are_errors_or_finite_clips(
        which in 0usize..2,
        edits in prop::collection::vec((any::<usize>(), any::<u8>()), 1..6),
        in_refs in any::<bool>(),
        cut in proptest::option::of(any::<usize>()),
    ) {
        let corpus = corpus();
        let (clip, bytes) = &corpus[which % corpus.len()];
        let mut s = Bitstream::from_bytes(bytes).unwrap();
        // Edits land in the references (after the database section) or anywhere.
        let refs_at = 5 + u32::from_le_bytes(s.payload[1..5].try_into().unwrap()) as usize;
        let n = s.payload.len();
        for (i, v) in &edits {
            let at = if in_refs { refs_at + i % (n - refs_at) } else { i % n };
            s.payload[at] = *v;
        }
        if let Some(c) = cut {
            s.payload.truncate(c % n);
        }
        let parsed = Bitstream::from_bytes(&s.to_bytes().unwrap()).unwrap();
        if let Ok(d) = RhythmicCodec::new().decode(&parsed, &clip.skeleton) {
            prop_assert_eq!(d.frames(), clip.frames());
            prop_assert!(d.data().iter().all(|v| v.is_finite()));
        }
    }
}
