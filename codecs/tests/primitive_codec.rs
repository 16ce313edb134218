//! The `primitive` codec (thesis ch. 5.3.4) on the shared CMU clips: round trips, the per-joint
//! error bound, monotone rate and error in `t_l`, rate control, database context errors, and
//! 10,000 mutated streams under a memory cap.
//!
//! The database is trained in the test on the shared clips (first 600 frames of each, K ≤ 12,
//! to stay fast in a debug build); the bound and the monotonicity do not depend on its quality.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]
#![expect(
    clippy::float_cmp,
    reason = "stored parameters and untouched frames are compared bit for bit"
)]

use std::sync::{Arc, OnceLock};

use cap::Cap;
use codecs::bitstream::Bitstream;
use codecs::codec::{self, Codec, CodecContext, CodecError, Params, PrimitiveCodec};
use codecs::primitives::{Database, TrainParams};
use codecs::rate;
use motion::quat::to_quaternions;
use motion::{Clip, data, io};
use proptest::prelude::*;

/// 1 GiB for the whole binary: far above what decoding the clips needs, far below what a
/// decoder trusting a corrupt count would ask for.
#[global_allocator]
static ALLOC: Cap<std::alloc::System> = Cap::new(std::alloc::System, 1 << 30);

const TRAIN_FRAMES: usize = 600;

struct Fixture {
    clips: Vec<(String, Clip)>,
    db: Arc<Database>,
    /// A second database (other seed, other K): a different fingerprint.
    other: Arc<Database>,
}

fn fixture() -> &'static Fixture {
    static F: OnceLock<Fixture> = OnceLock::new();
    F.get_or_init(|| {
        let clips: Vec<(String, Clip)> = data::shared_clips()
            .into_iter()
            .map(|f| {
                let clip = io::read_clip(f.asf.as_deref(), &f.motion).unwrap();
                (f.name, clip.excerpt(0..TRAIN_FRAMES))
            })
            .collect();
        let refs: Vec<&Clip> = clips.iter().map(|(_, c)| c).collect();
        let params = TrainParams {
            k_max: 12,
            ..TrainParams::default()
        };
        let db = Database::train(&refs, &params, |_, _| {});
        let other = Database::train(
            &refs[..1.min(refs.len())],
            &TrainParams {
                k_max: 6,
                seed: 7,
                ..params
            },
            |_, _| {},
        );
        Fixture {
            clips,
            db: Arc::new(db),
            other: Arc::new(other),
        }
    })
}

fn codec_with(db: &Arc<Database>) -> Box<dyn Codec> {
    codec::by_name_in("primitive", &CodecContext::with_primitives(Arc::clone(db))).unwrap()
}

fn params(pairs: &[(&str, f64)]) -> Params {
    pairs.iter().map(|(k, v)| ((*k).to_string(), *v)).collect()
}

/// Largest eq. 5.3 distance per joint between the decoded and the source rotations, with
/// each joint's threshold: (joint name, max distance, t_j).
fn joint_errors(source: &Clip, decoded: &Clip, t_l: f64) -> Vec<(String, f64, f64)> {
    let a = to_quaternions(source);
    let b = to_quaternions(decoded);
    assert_eq!(a.joints, b.joints);
    assert_eq!(decoded.frames(), source.frames());
    a.joints
        .iter()
        .enumerate()
        .map(|(k, &j)| {
            let joint = &source.skeleton.joints[j];
            let t = if joint.body_part.is_leg() {
                t_l
            } else {
                2.0 * t_l
            };
            let d = a.rotations[k]
                .iter()
                .zip(&b.rotations[k])
                .map(|(x, y)| x.distance(*y))
                .fold(0.0, f64::max);
            (joint.name.clone(), d, t)
        })
        .collect()
}

/// eq. 5.3's `acos(2d² − 1)` has a float64 noise floor of ~4e-8 rad near 0; the Euler round
/// trip adds ~1e-12. The bound is checked to 1e-6 rad.
const DISTANCE_TOL: f64 = 1e-6;

#[test]
fn shared_clips_are_present() {
    if data::mocap_dir().is_some() {
        assert_eq!(fixture().clips.len(), 5);
    }
}

#[test]
fn every_shared_clip_round_trips_within_its_joint_thresholds() {
    let f = fixture();
    let c = codec_with(&f.db);
    for (name, clip) in &f.clips {
        let s = c.encode(clip, &params(&[("t_l", 0.01)])).unwrap();
        assert_eq!(s.codec_id, 8);
        assert_eq!(s.params["db"], f64::from(f.db.fingerprint()));
        assert_eq!(s.params["t_l"], 0.01);
        let parsed = Bitstream::from_bytes(&s.to_bytes().unwrap()).unwrap();
        assert_eq!(parsed, s);
        let ctx = CodecContext::with_primitives(Arc::clone(&f.db));
        let d = codec::decode_any_in(&parsed, &clip.skeleton, &ctx).unwrap();
        assert_eq!(d.frames(), clip.frames());
        assert_eq!(d.channel_count(), clip.channel_count());
        for (joint, err, t) in joint_errors(clip, &d, 0.01) {
            assert!(err <= t + DISTANCE_TOL, "{name} {joint}: {err} > {t}");
        }
        let cr = s.compression_ratio();
        assert!(cr > 3.0, "{name}: CR {cr}");
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, failure_persistence: Some(Box::new(proptest::test_runner::FileFailurePersistence::WithSource("proptest-regressions"))), ..ProptestConfig::default() })]

    /// Thesis 5.3.4's contract, over clips, thresholds, start frames and both grids of the
    /// differences (16 normalized frames where they fit, or always the segment's own): every
    /// decoded frame (hence every segment's maximum) is within t_j of the source, for every
    /// joint.
    #[test]
    fn every_decoded_segment_is_within_its_threshold(
        which in 0usize..5,
        t_l in 0.002f64..0.05,
        upper in prop_oneof![Just(2.0), 1.0f64..4.0],
        start in 0usize..200,
        normalized in 0u8..2,
    ) {
        let f = fixture();
        let (name, clip) = &f.clips[which % f.clips.len()];
        let piece = clip.excerpt(start..start + 240);
        let c = codec_with(&f.db);
        let p = params(&[
            ("t_l", t_l),
            ("upper_ratio", upper),
            ("normalized", f64::from(normalized)),
        ]);
        let s = c.encode(&piece, &p).unwrap();
        let d = c.decode(&s, &piece.skeleton).unwrap();
        let qa = to_quaternions(&piece);
        let qb = to_quaternions(&d);
        prop_assert_eq!(&qa.joints, &qb.joints);
        prop_assert_eq!(d.frames(), piece.frames());
        for (k, &j) in qa.joints.iter().enumerate() {
            let joint = &piece.skeleton.joints[j];
            let t = if joint.body_part.is_leg() { t_l } else { upper * t_l };
            for (fr, (x, y)) in qa.rotations[k].iter().zip(&qb.rotations[k]).enumerate() {
                let e = x.distance(*y);
                prop_assert!(e <= t + DISTANCE_TOL, "{name}+{start} {} frame {fr}: {e} > {t}", joint.name);
            }
        }
    }
}

/// Differences on the 16 normalized frames (the default) code fewer bytes than at each
/// segment's own length on every shared clip, within the same bound; a stream from before the
/// `normalized` parameter (no such key) decodes as own-length, as it was written.
#[test]
fn normalized_differences_are_smaller_and_old_streams_decode_as_before() {
    let f = fixture();
    let c = codec_with(&f.db);
    for (name, clip) in &f.clips {
        let n = c.encode(clip, &params(&[("t_l", 0.01)])).unwrap();
        assert_eq!(n.params["normalized"], 1.0);
        let own = c
            .encode(clip, &params(&[("t_l", 0.01), ("normalized", 0.0)]))
            .unwrap();
        assert!(
            n.byte_len() < own.byte_len(),
            "{name}: {} normalized, {} own length",
            n.byte_len(),
            own.byte_len()
        );
        let mut old = own.clone();
        old.params.remove("normalized");
        assert_eq!(
            c.decode(&old, &clip.skeleton).unwrap(),
            c.decode(&own, &clip.skeleton).unwrap()
        );
    }
}

/// The measured parts of a stream add up to its payload (to the range coder's flush), and the
/// reference errors say which segments were coded.
#[test]
fn costs_add_up_to_the_stream() {
    let f = fixture();
    let c = PrimitiveCodec::new(Arc::clone(&f.db));
    for (name, clip) in &f.clips {
        let (s, k) = c.costs(clip, &params(&[("t_l", 0.01)])).unwrap();
        let bits: f64 = k.bits.iter().sum();
        let payload = 8.0 * s.payload.len() as f64;
        assert!(
            bits <= payload && payload <= bits + 8.0 * 6.0,
            "{name}: {bits} bits counted, payload {payload}"
        );
        assert!(k.bits.iter().all(|&b| b >= 0.0));
        assert_eq!(k.reference_error.len(), k.segments);
        let within = k.reference_error.iter().filter(|&&e| e <= 1.0).count();
        assert_eq!(within + k.coded, k.segments, "{name}");
        assert!(k.normalized <= k.coded && k.coefficients >= k.coded);
        assert_eq!(
            k.segment_frames,
            clip.frames() * to_quaternions(clip).joints.len()
        );
    }
    assert!(c.costs(&f.clips[0].1, &params(&[("cr", 10.0)])).is_err());
}

#[test]
fn smaller_t_l_gives_lower_error_and_lower_cr() {
    let f = fixture();
    let c = codec_with(&f.db);
    let ts = [0.0025, 0.005, 0.01, 0.02, 0.04];
    for (name, clip) in &f.clips {
        let mut last: Option<(f64, f64)> = None;
        for &t in &ts {
            let s = c.encode(clip, &params(&[("t_l", t)])).unwrap();
            let d = c.decode(&s, &clip.skeleton).unwrap();
            let rms = codecs::metrics::compare(clip, &d).unwrap().rms_cm;
            let cr = s.compression_ratio();
            if let Some((cr0, rms0)) = last {
                // Monotone within 2 %: a threshold is a bound, not a target.
                assert!(cr >= cr0 * 0.98, "{name}: CR {cr0} at t/2, {cr} at t = {t}");
                assert!(
                    rms >= rms0 * 0.98,
                    "{name}: RMS {rms0} at t/2, {rms} at t = {t}"
                );
            }
            last = Some((cr, rms));
        }
        let (cr_hi, _) = last.unwrap();
        let s_lo = c.encode(clip, &params(&[("t_l", ts[0])])).unwrap();
        assert!(
            cr_hi > 1.5 * s_lo.compression_ratio(),
            "{name}: CR barely moves with t_l"
        );
    }
}

#[test]
fn rate_control_searches_t_l_upwards_and_reports_unreachable_targets() {
    let f = fixture();
    let c = codec_with(&f.db);
    let (name, clip) = &f.clips[0];
    for target in [8.0, 12.0, 16.0] {
        let s = rate::encode_to_cr(c.as_ref(), clip, &Params::new(), target).unwrap();
        let cr = s.compression_ratio();
        assert!(
            (cr / target - 1.0).abs() <= 0.02,
            "{name}: {cr} for {target}"
        );
        assert!(!s.params.contains_key("cr"));
    }
    // Larger targets need larger thresholds.
    let t = |target: f64| {
        rate::encode_to_cr(c.as_ref(), clip, &Params::new(), target)
            .unwrap()
            .params["t_l"]
    };
    assert!(t(8.0) < t(16.0));
    match rate::encode_to_cr(c.as_ref(), clip, &Params::new(), 5000.0) {
        Err(CodecError::Rate { closest, .. }) => assert!(closest < 5000.0),
        other => panic!("{other:?}"),
    }
}

/// Issue 20: the search on `t_l` reaches a target in at most 4 encodes, on every clip.
#[test]
fn rate_search_needs_at_most_four_encodes() {
    let f = fixture();
    let c = codec_with(&f.db);
    for (name, clip) in &f.clips {
        for target in [8.0, 12.0, 16.0, 20.0, 30.0] {
            let s = rate::search_to_cr(c.as_ref(), clip, &Params::new(), target)
                .unwrap_or_else(|e| panic!("{name} {target}: {e}"));
            let cr = s.stream.compression_ratio();
            assert!(
                (cr / target - 1.0).abs() <= rate::CR_TOLERANCE,
                "{name}: {cr}"
            );
            assert!(
                s.encodes <= 4,
                "{name} at {target}:1: {} encodes",
                s.encodes
            );
        }
    }
}

#[test]
fn without_a_database_the_codec_is_listed_but_refuses_clearly() {
    let f = fixture();
    let (_, clip) = &f.clips[0];
    let listed = codec::registry_in(&CodecContext::default());
    assert!(
        listed
            .iter()
            .any(|c| c.name() == "primitive" && c.id() == 8)
    );
    // The plain registry keeps the context-free codecs only; by_name/by_id still find it.
    assert!(codec::registry().iter().all(|c| c.name() != "primitive"));
    let bare = codec::by_name("primitive").unwrap();
    assert_eq!(codec::by_id(8).unwrap().name(), "primitive");
    let e = bare.encode(clip, &Params::new()).unwrap_err().to_string();
    assert!(
        e.contains("needs a primitive database") && e.contains("--db"),
        "{e}"
    );
    let s = codec_with(&f.db).encode(clip, &Params::new()).unwrap();
    let e = codec::decode_any(&s, &clip.skeleton)
        .unwrap_err()
        .to_string();
    assert!(e.contains("needs a primitive database"), "{e}");
    assert!(matches!(
        PrimitiveCodec::without_database().decode(&s, &clip.skeleton),
        Err(CodecError::NoDatabase { .. })
    ));
}

#[test]
fn a_mismatched_database_is_refused_naming_both_fingerprints() {
    let f = fixture();
    let (_, clip) = &f.clips[0];
    let s = codec_with(&f.db).encode(clip, &Params::new()).unwrap();
    let (a, b) = (f.db.fingerprint(), f.other.fingerprint());
    assert_ne!(a, b);
    let ctx = CodecContext::with_primitives(Arc::clone(&f.other));
    let e = codec::decode_any_in(&s, &clip.skeleton, &ctx).unwrap_err();
    assert!(matches!(e, CodecError::DatabaseMismatch { .. }), "{e:?}");
    let text = e.to_string();
    assert!(
        text.contains(&format!("{a:08x}")) && text.contains(&format!("{b:08x}")),
        "{text}"
    );
    // The parameters may name the database too (a manifest's params re-encoded).
    let e = codec_with(&f.other)
        .encode(clip, &params(&[("db", f64::from(a))]))
        .unwrap_err();
    assert!(matches!(e, CodecError::DatabaseMismatch { .. }), "{e:?}");
    let ok = codec_with(&f.db).encode(clip, &params(&[("db", f64::from(a))]));
    assert!(ok.is_ok());
    // A database file that is truncated or altered is refused before any codec sees it.
    let bytes = f.db.to_bytes();
    let p = std::path::Path::new("shared.pdb");
    for cut in [0, 7, 20, bytes.len() / 2, bytes.len() - 1] {
        let e = Database::from_bytes(&bytes[..cut], p)
            .unwrap_err()
            .to_string();
        assert!(e.contains("shared.pdb"), "{e}");
    }
    let mut bad = bytes.clone();
    bad[bytes.len() / 3] ^= 0x10;
    assert!(
        Database::from_bytes(&bad, p)
            .unwrap_err()
            .to_string()
            .contains("checksum")
    );
}

#[test]
fn smoothing_changes_only_frames_near_segment_joins() {
    let f = fixture();
    let (_, clip) = &f.clips[3 % f.clips.len()];
    let c = codec_with(&f.db);
    let plain = c.encode(clip, &params(&[("t_l", 0.02)])).unwrap();
    let smooth = c
        .encode(clip, &params(&[("t_l", 0.02), ("smooth", 4.0)]))
        .unwrap();
    // Smoothing is the decoder's: the payload is the same, the parameter differs.
    assert_eq!(plain.payload, smooth.payload);
    let a = c.decode(&plain, &clip.skeleton).unwrap();
    let b = c.decode(&smooth, &clip.skeleton).unwrap();
    let changed = (0..clip.frames())
        .filter(|&fr| (0..clip.channel_count()).any(|ch| a.value(ch, fr) != b.value(ch, fr)))
        .count();
    assert!(changed > 0 && changed < clip.frames(), "{changed}");
    assert!(b.data().iter().all(|v| v.is_finite()));
}

/// One stream per clip (short pieces) for the mutation tests.
fn corpus() -> &'static Vec<(Clip, Vec<u8>)> {
    static C: OnceLock<Vec<(Clip, Vec<u8>)>> = OnceLock::new();
    C.get_or_init(|| {
        let f = fixture();
        let c = codec_with(&f.db);
        f.clips
            .iter()
            .map(|(_, clip)| {
                let piece = clip.excerpt(0..150);
                let s = c.encode(&piece, &params(&[("t_l", 0.01)])).unwrap();
                (piece, s.to_bytes().unwrap())
            })
            .collect()
    })
}

#[derive(Debug, Clone)]
enum Mutation {
    Flip(Vec<usize>),
    Truncate(usize),
    Extend(Vec<u8>),
    Overwrite(usize, u8),
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        prop::collection::vec(any::<usize>(), 1..8).prop_map(Mutation::Flip),
        any::<usize>().prop_map(Mutation::Truncate),
        prop::collection::vec(any::<u8>(), 1..16).prop_map(Mutation::Extend),
        (any::<usize>(), any::<u8>()).prop_map(|(i, b)| Mutation::Overwrite(i, b)),
    ]
}

fn apply(b: &mut Vec<u8>, m: &Mutation) {
    match m {
        Mutation::Flip(bits) => {
            let n = b.len() * 8;
            let seen: std::collections::BTreeSet<usize> = bits.iter().map(|x| x % n).collect();
            for bit in seen {
                b[bit / 8] ^= 1 << (bit % 8);
            }
        }
        Mutation::Truncate(n) => {
            let n = n % b.len();
            b.truncate(n);
        }
        Mutation::Extend(extra) => b.extend_from_slice(extra),
        Mutation::Overwrite(i, v) => {
            let i = i % b.len();
            b[i] = *v;
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 10_000, failure_persistence: Some(Box::new(proptest::test_runner::FileFailurePersistence::WithSource("proptest-regressions"))), ..ProptestConfig::default() })]

    /// 10,000 mutated streams: every changed stream is refused (the container's CRC), none
    /// panics, none allocates past the cap.
    #[test]
    fn mutated_streams_are_errors(which in 0usize..5, m in mutation()) {
        let f = fixture();
        let corpus = corpus();
        let (clip, original) = &corpus[which % corpus.len()];
        let mut b = original.clone();
        apply(&mut b, &m);
        if &b != original {
            let ctx = CodecContext::with_primitives(Arc::clone(&f.db));
            let accepted = Bitstream::from_bytes(&b)
                .is_ok_and(|s| codec::decode_any_in(&s, &clip.skeleton, &ctx).is_ok());
            prop_assert!(!accepted, "accepted after {m:?}");
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 3_000, failure_persistence: Some(Box::new(proptest::test_runner::FileFailurePersistence::WithSource("proptest-regressions"))), ..ProptestConfig::default() })]

    /// Payload corruption behind a recomputed CRC reaches the codec's own checks: Ok or Err,
    /// never a panic, and any clip returned has the right shape and finite values.
    #[test]
    fn payload_corruption_behind_a_valid_crc_never_panics(
        which in 0usize..5,
        edits in prop::collection::vec((any::<usize>(), any::<u8>()), 1..6),
        cut in proptest::option::of(any::<usize>()),
        param in proptest::option::of((0usize..4, -1e3f64..1e3)),
    ) {
        let f = fixture();
        let corpus = corpus();
        let (clip, original) = &corpus[which % corpus.len()];
        let mut s = Bitstream::from_bytes(original).unwrap();
        let n = s.payload.len();
        for (i, v) in &edits {
            s.payload[i % n] = *v;
        }
        if let Some(c) = cut {
            s.payload.truncate(c % n);
        }
        if let Some((k, v)) = param {
            let key = ["t_l", "upper_ratio", "smooth", "step_floor"][k];
            s.params.insert(key.into(), v);
        }
        let parsed = Bitstream::from_bytes(&s.to_bytes().unwrap()).unwrap();
        let ctx = CodecContext::with_primitives(Arc::clone(&f.db));
        if let Ok(d) = codec::decode_any_in(&parsed, &clip.skeleton, &ctx) {
            prop_assert_eq!(d.frames(), clip.frames());
            prop_assert!(d.data().iter().all(|v| v.is_finite()));
        }
    }
}
