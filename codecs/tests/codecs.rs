//! The codec suite on the shared CMU clips and on the synthetic walker: round trips, rate
//! control, the translation-channel decision, SPIHT's prefix property, Euler unwrapping.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use codecs::bitstream::Bitstream;
use codecs::codec::{self, Params, spiht};
use codecs::{metrics, rate};
use motion::synth::{WalkParams, walking_clip};
use motion::{Clip, data, io};

fn shared() -> Vec<(String, Clip)> {
    data::shared_clips()
        .into_iter()
        .map(|f| {
            (
                f.name.clone(),
                io::read_clip(f.asf.as_deref(), &f.motion).unwrap(),
            )
        })
        .collect()
}

fn params(pairs: &[(&str, f64)]) -> Params {
    pairs.iter().map(|(k, v)| ((*k).to_string(), *v)).collect()
}

/// Encode, serialize, parse, decode, measure.
fn round_trip(name: &str, clip: &Clip, p: &Params) -> (Bitstream, metrics::Metrics) {
    let c = codec::by_name(name).unwrap();
    let s = c.encode(clip, p).unwrap();
    let parsed = Bitstream::from_bytes(&s.to_bytes().unwrap()).unwrap();
    assert_eq!(parsed, s);
    let d = codec::decode_any(&parsed, &clip.skeleton).unwrap();
    (s, metrics::compare(clip, &d).unwrap())
}

#[test]
fn shared_clips_are_present() {
    // Six clips: five AMC/ASF pairs and pieces, one BVH (see ../shared/data/mocap/README.md).
    if data::mocap_dir().is_some() {
        assert_eq!(shared().len(), 5);
    }
}

#[test]
fn every_codec_round_trips_every_shared_clip_at_its_highest_rate() {
    let mut clips = shared();
    clips.push((
        "synthetic-walk".into(),
        walking_clip(&WalkParams::default()),
    ));
    for (clip_name, clip) in &clips {
        let cases: [(&str, Params); 7] = [
            ("raw-f32", Params::new()),
            ("zstd", Params::new()),
            // C = every coefficient: K_i = max(share, C) keeps all of them.
            (
                "wavelet-perceptual",
                params(&[("alpha", 1.0), ("qp", 16.0), ("c", 4096.0)]),
            ),
            (
                "wavelet-standard",
                params(&[("alpha", 1.0), ("qp", 16.0), ("c", 4096.0)]),
            ),
            (
                "wavelet-bone",
                params(&[("alpha", 1.0), ("qp", 16.0), ("c", 4096.0)]),
            ),
            // SPIHT near its highest rate: 128 bits per value on average, shared by eq. 6.1
            // (proportional shares leave spiky low-score channels such as CMU BVH thumbs short
            // below that).
            ("spiht", params(&[("cr", 0.25)])),
            ("spiht-uniform", params(&[("cr", 0.25)])),
        ];
        for (name, p) in &cases {
            let (s, m) = round_trip(name, clip, p);
            assert!(m.rms_cm < 0.05, "{clip_name} {name}: rms {} cm", m.rms_cm);
            assert!(m.max_cm < 1.0, "{clip_name} {name}: max {} cm", m.max_cm);
            if *name == "zstd" && clip_name != "synthetic-walk" {
                // Lossless zstd of float32: only ~1.2-1.9:1 (issue 4).
                let cr = s.compression_ratio();
                assert!((1.05..2.5).contains(&cr), "{clip_name} zstd CR {cr}");
            }
        }
    }
}

#[test]
fn rate_control_reaches_every_target_within_two_percent() {
    for (clip_name, clip) in shared() {
        for name in [
            "wavelet-perceptual",
            "wavelet-standard",
            "wavelet-bone",
            "spiht",
        ] {
            let c = codec::by_name(name).unwrap();
            for target in [10.0, 20.0, 30.0, 40.0, 50.0, 60.0] {
                let s = rate::encode_to_cr(c.as_ref(), &clip, &Params::new(), target)
                    .unwrap_or_else(|e| panic!("{clip_name} {name} {target}: {e}"));
                let cr = 4.0 * (clip.channel_count() * clip.frames()) as f64
                    / s.to_bytes().unwrap().len() as f64;
                assert!(
                    (cr / target - 1.0).abs() <= 0.02,
                    "{clip_name} {name}: target {target}, got {cr}"
                );
                let d = c.decode(&s, &clip.skeleton).unwrap();
                assert_eq!(d.frames(), clip.frames());
            }
        }
    }
}

/// Issue 20: the rate search costs at most 4 encodes from 10:1 to 60:1 on every shared clip
/// (the bisection it replaced took 5-8, and 7-41 at 60:1). Before short last windows were
/// coded like the window before them, the CR of `wavelet-perceptual` jumped by ~11 % at one α
/// near 60:1 on 02_01 and pirouette and the search took up to 10 encodes there; a jump still
/// makes the search step QP rather than loop (`rate.rs`).
#[test]
fn rate_search_needs_at_most_four_encodes() {
    let c = codec::by_name("wavelet-perceptual").unwrap();
    let mut counts = Vec::new();
    for (clip_name, clip) in shared() {
        for target in [10.0, 15.0, 20.0, 30.0, 40.0, 50.0, 60.0] {
            let s = rate::search_to_cr(c.as_ref(), &clip, &Params::new(), target)
                .unwrap_or_else(|e| panic!("{clip_name} {target}: {e}"));
            let cr = s.stream.compression_ratio();
            assert!(
                (cr / target - 1.0).abs() <= rate::CR_TOLERANCE,
                "{clip_name}: {cr}"
            );
            assert!(
                s.encodes <= 4,
                "{clip_name} at {target}:1 took {} encodes",
                s.encodes
            );
            counts.push(s.encodes);
        }
    }
    // SPIHT reaches its target natively: one encode.
    let spiht = codec::by_name("spiht").unwrap();
    let clip = walking_clip(&WalkParams {
        duration_s: 2.0,
        ..WalkParams::default()
    });
    let s = rate::search_to_cr(spiht.as_ref(), &clip, &Params::new(), 20.0).unwrap();
    assert_eq!(s.encodes, 1);
    println!("encodes per search: {counts:?}");
}

#[test]
fn lossless_codecs_refuse_a_target_rate() {
    let clip = walking_clip(&WalkParams {
        duration_s: 0.5,
        ..WalkParams::default()
    });
    let c = codec::by_name("zstd").unwrap();
    assert!(rate::encode_to_cr(c.as_ref(), &clip, &Params::new(), 10.0).is_err());
}

/// Decision (a): the literal rule starves the root translation; the comparable rule does not.
#[test]
fn literal_translation_rule_gives_larger_position_error_with_root_motion() {
    let walk = walking_clip(&WalkParams {
        duration_s: 6.0,
        speed_cm_s: 150.0,
        ..WalkParams::default()
    });
    let mut clips = vec![("synthetic-walk".to_string(), walk)];
    clips.extend(shared().into_iter().filter(|(n, _)| n == "02_01"));
    let c = codec::by_name("wavelet-perceptual").unwrap();
    for (clip_name, clip) in clips {
        for target in [20.0, 40.0] {
            let err = |rule: f64| {
                let s = rate::encode_to_cr(
                    c.as_ref(),
                    &clip,
                    &params(&[("translation", rule)]),
                    target,
                )
                .unwrap();
                metrics::compare(&clip, &c.decode(&s, &clip.skeleton).unwrap())
                    .unwrap()
                    .rms_cm
            };
            let (comparable, literal) = (err(0.0), err(1.0));
            assert!(
                literal > 1.2 * comparable,
                "{clip_name} CR {target}: literal {literal} cm vs comparable {comparable} cm"
            );
        }
    }
}

/// Decision (b): C is raised to the coarsest band, so α → 0 still keeps the low-pass content.
#[test]
fn minimum_kept_is_at_least_the_coarsest_band() {
    // With α = 0 and C = 0 only the enforced minimum survives: the whole approximation band.
    // D4 with periodization puts a slice's mean entirely in that band, so every channel keeps
    // its mean over every 256-frame slice (and the short last one); dropping one approximation
    // coefficient would move a quarter of the slice.
    let clip = walking_clip(&WalkParams {
        duration_s: 2.5,
        ..WalkParams::default()
    });
    let c = codec::by_name("wavelet-standard").unwrap();
    let s = c
        .encode(&clip, &params(&[("alpha", 0.0), ("c", 0.0), ("qp", 12.0)]))
        .unwrap();
    let d = c.decode(&s, &clip.skeleton).unwrap();
    assert_eq!(
        (d.channel_count(), d.frames()),
        (clip.channel_count(), clip.frames())
    );
    for ch in 0..clip.channel_count() {
        for (a, b) in clip.channel(ch).chunks(256).zip(d.channel(ch).chunks(256)) {
            let mean = |x: &[f64]| x.iter().sum::<f64>() / x.len() as f64;
            let range = a.iter().fold(f64::NEG_INFINITY, |m, &v| m.max(v))
                - a.iter().fold(f64::INFINITY, |m, &v| m.min(v));
            // A full slice keeps its mean to quantization error; the short last slice (44 frames,
            // odd lengths extended at some levels) to a few percent of its range.
            let maxabs = a.iter().fold(0.0f64, |m, v| m.max(v.abs()));
            let tol = if a.len() == 256 {
                1e-3 * (1.0 + range) + 2e-3 * maxabs
            } else {
                0.05 * range + 2e-3 * maxabs
            };
            assert!(
                (mean(a) - mean(b)).abs() <= tol,
                "channel {ch}: {} vs {}",
                mean(a),
                mean(b)
            );
        }
    }
}

#[test]
fn spiht_prefixes_decode_with_decreasing_error() {
    let mut clips = shared();
    clips.push((
        "synthetic-walk".into(),
        walking_clip(&WalkParams::default()),
    ));
    let c = codec::by_name("spiht").unwrap();
    for (clip_name, clip) in clips {
        let full = c.encode(&clip, &params(&[("cr", 10.0)])).unwrap();
        let mut last = f64::INFINITY;
        let mut last_bytes = 0;
        for fraction in [0.25, 0.5, 1.0] {
            let cut = spiht::truncate(&full, fraction).unwrap();
            let bytes = cut.to_bytes().unwrap();
            assert!(bytes.len() > last_bytes);
            last_bytes = bytes.len();
            let d = c
                .decode(&Bitstream::from_bytes(&bytes).unwrap(), &clip.skeleton)
                .unwrap();
            let m = metrics::compare(&clip, &d).unwrap();
            assert!(
                m.rms_cm < last,
                "{clip_name}: {fraction} of the stream gives {} cm ≥ {last}",
                m.rms_cm
            );
            last = m.rms_cm;
        }
        assert_eq!(spiht::truncate(&full, 1.0).unwrap(), full);
    }
}

#[test]
fn euler_wraps_cost_nothing() {
    // Turn a rotation channel so it crosses ±180°, as real spins do, and wrap it.
    let clip = walking_clip(&WalkParams {
        duration_s: 4.0,
        ..WalkParams::default()
    });
    let c = clip
        .channels()
        .iter()
        .position(|ch| ch.kind.is_rotation())
        .unwrap();
    let mut wrapped = clip.clone();
    for (f, v) in wrapped.channel_mut(c).iter_mut().enumerate() {
        let mut a = *v + 170.0 + 60.0 * (f as f64 * 0.02).sin();
        codecs::codec::wrap_degrees(std::slice::from_mut(&mut a));
        *v = a;
    }
    assert!(
        wrapped
            .channel(c)
            .windows(2)
            .any(|w| (w[1] - w[0]).abs() > 300.0),
        "test clip must wrap"
    );
    let p = params(&[("cr", 20.0)]);
    for name in ["wavelet-perceptual", "spiht"] {
        let (_, m_plain) = round_trip(name, &clip, &p);
        let (_, m_wrapped) = round_trip(name, &wrapped, &p);
        assert!(
            m_wrapped.mean_angle_deg < 1.0,
            "{name}: angle error {}",
            m_wrapped.mean_angle_deg
        );
        assert!(
            m_wrapped.rms_cm < 2.0 * m_plain.rms_cm + 0.5,
            "{name}: {} vs {}",
            m_wrapped.rms_cm,
            m_plain.rms_cm
        );
    }
}

#[test]
fn a_stream_for_another_skeleton_is_refused() {
    let clip = walking_clip(&WalkParams {
        duration_s: 0.5,
        ..WalkParams::default()
    });
    let s = codec::by_name("wavelet-perceptual")
        .unwrap()
        .encode(&clip, &Params::new())
        .unwrap();
    let mut other = clip.skeleton.clone();
    other.joints[1].name.push('x');
    assert!(codec::decode_any(&s, &other).is_err());
    assert!(
        codec::by_name("spiht")
            .unwrap()
            .decode(&s, &clip.skeleton)
            .is_err()
    );
}

#[test]
fn unknown_and_out_of_range_parameters_are_refused() {
    let clip = walking_clip(&WalkParams {
        duration_s: 0.5,
        ..WalkParams::default()
    });
    let c = codec::by_name("wavelet-perceptual").unwrap();
    assert!(c.encode(&clip, &params(&[("bogus", 1.0)])).is_err());
    assert!(c.encode(&clip, &params(&[("qp", 40.0)])).is_err());
    assert!(c.encode(&clip, &params(&[("alpha", 2.0)])).is_err());
    assert!(
        codec::by_name("spiht")
            .unwrap()
            .encode(&clip, &params(&[("cr", 0.05)]))
            .is_err()
    );
}

#[test]
fn registry_names_and_ids_are_unique() {
    let r = codec::registry();
    for (i, a) in r.iter().enumerate() {
        for b in &r[i + 1..] {
            assert_ne!(a.name(), b.name());
            assert_ne!(a.id(), b.id());
        }
        assert_eq!(codec::by_id(a.id()).unwrap().name(), a.name());
    }
}

/// Decision (c): wavelet-perceptual's default allocation (position sensitivity, one threshold and
/// step per slice in position units) against the paper's K_i = α·l_i·v_i·N·W/ΣA as printed
/// (`allocation = 1`), at the same compression ratio.
#[test]
fn position_allocation_beats_the_printed_rule() {
    let mut clips = shared();
    clips.push((
        "synthetic-walk".into(),
        walking_clip(&WalkParams {
            duration_s: 4.0,
            speed_cm_s: 150.0,
            ..WalkParams::default()
        }),
    ));
    let c = codec::by_name("wavelet-perceptual").unwrap();
    for (clip_name, clip) in clips {
        for target in [20.0, 40.0] {
            let err = |allocation: f64| {
                let s = rate::encode_to_cr(
                    c.as_ref(),
                    &clip,
                    &params(&[("allocation", allocation)]),
                    target,
                )
                .unwrap();
                assert!((s.params["allocation"] - allocation).abs() < 1e-12);
                metrics::compare(&clip, &c.decode(&s, &clip.skeleton).unwrap())
                    .unwrap()
                    .rms_cm
            };
            let (position, paper) = (err(0.0), err(1.0));
            assert!(
                position < paper,
                "{clip_name} CR {target}: position {position} cm vs paper {paper} cm"
            );
        }
    }
}

/// Payload formats from 2 on start with a version byte; a version-1 stream (no version byte,
/// its first payload byte is the range coder's initial 0) or any other version is refused, not
/// decoded.
#[test]
fn old_wavelet_payload_versions_are_refused() {
    let clip = walking_clip(&WalkParams {
        duration_s: 1.0,
        ..WalkParams::default()
    });
    for name in ["wavelet-perceptual", "wavelet-standard", "wavelet-bone"] {
        let c = codec::by_name(name).unwrap();
        let s = c.encode(&clip, &Params::new()).unwrap();
        assert_eq!(s.payload[0], codec::wavelet_codec::PAYLOAD_VERSION);
        for v in [0u8, 1, 2, 4, 255] {
            let mut old = s.clone();
            old.payload[0] = v;
            let e = c.decode(&old, &clip.skeleton).unwrap_err().to_string();
            assert!(e.contains("payload format version"), "{name} v{v}: {e}");
        }
        let mut empty = s.clone();
        empty.payload.clear();
        assert!(c.decode(&empty, &clip.skeleton).is_err());
    }
}

/// A large wavelet stream has two lanes (decoded on two threads) and round-trips; a lane
/// header that does not fit the stream is refused, naming what is wrong.
#[test]
fn wavelet_lanes_round_trip_and_bad_lane_headers_are_refused() {
    let (_, clip) = shared()
        .into_iter()
        .find(|(n, _)| n == "lambada")
        .expect("the shared clips include lambada");
    let c = codec::by_name("wavelet-perceptual").unwrap();
    // 4:1: well above the 16 KiB at which lanes run in parallel.
    let s = c.encode(&clip, &params(&[("cr", 4.0)])).unwrap();
    assert!(s.payload.len() > 16 * 1024, "{}", s.payload.len());
    assert_eq!(s.payload[1], 2, "two lanes");
    let m = codecs::metrics::compare(&clip, &c.decode(&s, &clip.skeleton).unwrap()).unwrap();
    assert!(m.rms_cm < 0.05, "{}", m.rms_cm);
    for (byte, value, why) in [
        (1usize, 0u8, "lanes for"),
        (1, 200, "lanes for"),
        (5, 0xFF, "lane longer than the payload"),
    ] {
        let mut bad = s.clone();
        bad.payload[byte] = value;
        let e = c.decode(&bad, &clip.skeleton).unwrap_err().to_string();
        assert!(e.contains(why), "byte {byte} = {value}: {e}");
    }
    let mut cut = s.clone();
    cut.payload.truncate(4);
    let e = c.decode(&cut, &clip.skeleton).unwrap_err().to_string();
    assert!(e.contains("lane lengths truncated"), "{e}");
}

/// SPIHT's position-aware energy (default) against eq. 6.3 as printed (`allocation = 1`), on
/// the real clips (on the synthetic walker, whose channels all move alike, the two are within
/// 10 % of each other).
#[test]
fn spiht_position_allocation_beats_the_printed_energy() {
    let clips = shared();
    let c = codec::by_name("spiht").unwrap();
    for (clip_name, clip) in clips {
        for target in [20.0, 40.0] {
            let err = |allocation: f64| {
                let s = c
                    .encode(
                        &clip,
                        &params(&[("cr", target), ("allocation", allocation)]),
                    )
                    .unwrap();
                metrics::compare(&clip, &c.decode(&s, &clip.skeleton).unwrap())
                    .unwrap()
                    .rms_cm
            };
            let (position, printed) = (err(0.0), err(1.0));
            assert!(
                position < printed,
                "{clip_name} CR {target}: position {position} cm vs printed {printed} cm"
            );
        }
    }
}

/// SPIHT payloads carry a version tag; a version-1 payload (starting with its side-information
/// length) or another version is refused, and truncation keeps the tag.
#[test]
fn old_spiht_payload_versions_are_refused() {
    let clip = walking_clip(&WalkParams {
        duration_s: 1.0,
        ..WalkParams::default()
    });
    let c = codec::by_name("spiht").unwrap();
    let s = c.encode(&clip, &Params::new()).unwrap();
    assert_eq!(&s.payload[..4], &[b'S', spiht::PAYLOAD_VERSION, 0, 0xFF]);
    let cut = spiht::truncate(&s, 0.5).unwrap();
    assert!(c.decode(&cut, &clip.skeleton).is_ok());
    let mut v1 = s.clone();
    v1.payload.drain(..4);
    let e = c.decode(&v1, &clip.skeleton).unwrap_err().to_string();
    assert!(e.contains("payload format version 1"), "{e}");
    assert!(spiht::truncate(&v1, 0.5).is_err());
    let mut v3 = s.clone();
    v3.payload[1] = 3;
    let e = c.decode(&v3, &clip.skeleton).unwrap_err().to_string();
    assert!(e.contains("payload format version 3"), "{e}");
}

/// Every rate the searches may try encodes: α = 1 with the finest quantizer on a clip with
/// constant channels (a near-zero selection threshold) still fits the entropy coder, and low
/// targets (3:1, 5:1 on the real clips) are reached.
#[test]
fn wavelet_perceptual_encodes_at_any_rate() {
    let mut clips = shared();
    clips.push((
        "synthetic-walk".into(),
        walking_clip(&WalkParams {
            duration_s: 2.0,
            ..WalkParams::default()
        }),
    ));
    let c = codec::by_name("wavelet-perceptual").unwrap();
    for (clip_name, clip) in clips {
        for qp in [4.0, 10.0, 16.0] {
            for alpha in [1e-4, 0.5, 0.999_999, 1.0] {
                let s = c
                    .encode(&clip, &params(&[("alpha", alpha), ("qp", qp)]))
                    .unwrap_or_else(|e| panic!("{clip_name} qp {qp} α {alpha}: {e}"));
                c.decode(&s, &clip.skeleton).unwrap();
            }
        }
        // The synthetic walker is too smooth for 3:1 even at the finest settings (about 4:1).
        let targets: &[f64] = if clip_name == "synthetic-walk" {
            &[5.0]
        } else {
            &[3.0, 5.0]
        };
        for &target in targets {
            let s = rate::encode_to_cr(c.as_ref(), &clip, &Params::new(), target)
                .unwrap_or_else(|e| panic!("{clip_name} CR {target}: {e}"));
            assert!((s.compression_ratio() / target - 1.0).abs() <= 0.02);
        }
    }
}
