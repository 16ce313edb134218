//! Sweeps over codec parameters and error bounds: every combination of `params` is made at
//! every target with its own id, unreachable targets are recorded (never abort the sweep),
//! parameters a codec does not take are refused before anything is encoded; and the
//! error-bounded search returns a stream within its bound whose next smaller probe exceeds it.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

use codecs::codec::{self, Params};
use lab::bounded::{self, MAX_KNOB_ENCODES};
use lab::clips::ClipOptions;
use lab::stimulus::{self, Request};
use lab::sweep::{SweepOptions, Target, sweep};
use protocols::manifest::{REFERENCE_CODEC, StimulusManifest};

/// A fresh scratch folder holding a generated walk of `duration_s` as `clips/walk.{asf,amc}`.
fn walk_dir(name: &str, duration_s: f64) -> (PathBuf, Vec<PathBuf>) {
    let dir = std::env::temp_dir().join(format!("lab-grid-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("clips")).unwrap();
    let walk = motion::synth::walking_clip(&motion::synth::WalkParams {
        duration_s,
        ..motion::synth::WalkParams::default()
    });
    let (asf, amc) = (dir.join("clips/walk.asf"), dir.join("clips/walk.amc"));
    motion::io::write_clip(&walk, &amc, Some(&asf), files::Mode::New).unwrap();
    (dir, vec![amc, asf])
}

fn grid_options(clips: &[PathBuf], out: &Path) -> SweepOptions {
    SweepOptions {
        clips: clips.to_vec(),
        clip_options: ClipOptions::default(),
        codecs: vec!["wavelet-perceptual".into()],
        targets: vec![20.0, 40.0],
        params: vec![
            ("qp".into(), vec![9.0, 11.0]),
            ("window".into(), vec![128.0, 256.0]),
        ],
        output: out.to_path_buf(),
        jobs: 2,
        ..SweepOptions::default()
    }
}

#[test]
fn a_grid_makes_every_variant_and_records_unreachable_targets_without_aborting() {
    // 3.3 s: the walk's windows of 128 and 256 frames leave a short last one.
    let (dir, clips) = walk_dir("grid", 3.3);
    let out = dir.join("stimuli");
    let mut options = grid_options(&clips, &out);
    // 1000:1 is beyond the wavelet codec on this clip at every variant.
    options.targets.push(1000.0);
    let summary = sweep(&options, &|_, total| assert_eq!(total, 12)).unwrap();
    let text = std::fs::read_to_string(out.join("stimuli.json")).unwrap();
    let manifest: StimulusManifest = serde_json::from_str(&text).unwrap();
    assert_eq!(manifest, summary.manifest);
    let made: Vec<_> = manifest
        .stimuli
        .iter()
        .filter(|s| s.codec != REFERENCE_CODEC)
        .collect();
    let ids: BTreeSet<&str> = made.iter().map(|s| s.id.as_str()).collect();
    let mut want = BTreeSet::new();
    for qp in ["9", "11"] {
        for w in ["128", "256"] {
            for cr in ["20", "40"] {
                want.insert(format!("walk/wavelet-perceptual/qp{qp}-window{w}/cr{cr}"));
            }
        }
    }
    assert_eq!(
        ids,
        want.iter().map(String::as_str).collect::<BTreeSet<_>>()
    );
    for s in &made {
        // The variant is recorded, and it is what the stream was made with.
        assert_eq!(s.variant.len(), 2, "{}", s.id);
        for (k, v) in &s.variant {
            assert_eq!(s.params.get(k), Some(v), "{}: {k}", s.id);
        }
        assert!(s.target_max_error_cm.is_none());
        let t = s.target_cr.unwrap();
        assert!((s.achieved_cr.unwrap() / t - 1.0).abs() <= 0.02, "{}", s.id);
        let m = s.metrics.unwrap();
        assert!(m.max_cm >= m.rms_cm, "{}", s.id);
        let ww = m.worst_window_rms_cm.unwrap();
        assert!(ww >= m.rms_cm * 0.999, "{}: {ww} < {}", s.id, m.rms_cm);
        assert_eq!(m.worst_window_frames, Some(120));
        assert!(out.join(&s.file).is_file() && out.join(s.bitstream.as_ref().unwrap()).is_file());
    }
    // The unreachable ones: listed, with their reason, in the summary and rd.csv.
    let unreachable: Vec<&str> = summary.unreachable.iter().map(|u| u.id.as_str()).collect();
    assert_eq!(
        unreachable,
        [
            "walk/wavelet-perceptual/qp9-window128/cr1000",
            "walk/wavelet-perceptual/qp9-window256/cr1000",
            "walk/wavelet-perceptual/qp11-window128/cr1000",
            "walk/wavelet-perceptual/qp11-window256/cr1000",
        ]
    );
    for u in &summary.unreachable {
        assert_eq!(u.target, Target::Cr(1000.0));
        assert!(u.reason.contains("1000"), "{}", u.reason);
        assert!(
            !out.join("walk")
                .join(format!(
                    "wavelet-perceptual-{}-cr1000.mcz",
                    protocols::manifest::variant_label(&u.variant)
                ))
                .exists()
        );
    }
    let csv = std::fs::read_to_string(out.join("rd.csv")).unwrap();
    let header: Vec<&str> = csv.lines().next().unwrap().split(',').collect();
    let col = |name: &str| header.iter().position(|h| *h == name).unwrap();
    let rows: Vec<Vec<&str>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect())
        .collect();
    assert_eq!(rows.len(), 12);
    let status: Vec<&str> = rows.iter().map(|r| r[col("status")]).collect();
    assert_eq!(status.iter().filter(|s| **s == "made").count(), 8);
    assert_eq!(status.iter().filter(|s| **s == "unreachable").count(), 4);
    for r in &rows {
        assert!(r[col("params")].starts_with("qp="), "{r:?}");
        if r[col("status")] == "unreachable" {
            assert!(
                r[col("max_cm")].is_empty() && !r[col("reason")].is_empty(),
                "{r:?}"
            );
        } else {
            let (rms, max): (f64, f64) = (
                r[col("rms_cm")].parse().unwrap(),
                r[col("max_cm")].parse().unwrap(),
            );
            let ww: f64 = r[col("worst_window_rms_cm")].parse().unwrap();
            assert!(max >= ww && ww >= rms * 0.999, "{r:?}");
            assert!(ids.contains(r[col("id")]), "{r:?}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn without_params_ids_and_files_are_what_they_were() {
    let (dir, clips) = walk_dir("plain", 1.0);
    let out = dir.join("stimuli");
    let mut options = grid_options(&clips, &out);
    options.params.clear();
    options.codecs = vec!["spiht".into()];
    let summary = sweep(&options, &|_, _| {}).unwrap();
    let ids: Vec<&str> = summary
        .manifest
        .stimuli
        .iter()
        .map(|s| s.id.as_str())
        .collect();
    assert_eq!(
        ids,
        ["walk/reference", "walk/spiht/cr20", "walk/spiht/cr40"]
    );
    assert!(out.join("walk/spiht-cr20.mcz").is_file());
    let text = std::fs::read_to_string(out.join("stimuli.json")).unwrap();
    assert!(
        !text.contains("\"variant\"") && !text.contains("target_max_error_cm"),
        "{text}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn parameters_a_codec_does_not_take_are_refused_before_anything_is_made() {
    let (dir, clips) = walk_dir("refused", 1.0);
    let out = dir.join("stimuli");
    let refused = |edit: &dyn Fn(&mut SweepOptions)| {
        let mut options = grid_options(&clips, &out);
        edit(&mut options);
        let e = sweep(&options, &|_, _| panic!("nothing may be made")).unwrap_err();
        assert!(!out.exists(), "{e}");
        e.to_string()
    };
    // SPIHT has a window but no quantiser.
    let e = refused(&|o| o.codecs.push("spiht".into()));
    assert!(
        e.starts_with(
            "--param qp: codec `spiht` does not take it; it takes allocation, cr, score_arms"
        ),
        "{e}"
    );
    assert!(e.contains("window"), "{e}");
    let e = refused(&|o| o.params.push(("alpha".into(), vec![0.1])));
    assert!(e.contains("sets alpha itself"), "{e}");
    let e = refused(&|o| o.params.push(("qp".into(), vec![7.0])));
    assert!(e.contains("--param qp is given twice"), "{e}");
    let e = refused(&|o| o.params[0].1.push(9.0));
    assert!(e.contains("--param qp: 9 is listed twice"), "{e}");
    let e = refused(&|o| o.targets.clear());
    assert!(e.starts_with("nothing to make"), "{e}");
    let e = refused(&|o| o.max_errors_cm.push(-1.0));
    assert!(e.contains("--max-error-cm -1"), "{e}");
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn error_bounds_in_a_sweep_get_their_own_ids_and_targets() {
    let (dir, clips) = walk_dir("bounds", 2.0);
    let out = dir.join("stimuli");
    let mut options = grid_options(&clips, &out);
    options.params.clear();
    options.codecs = vec!["spiht".into()];
    options.targets.clear();
    // 1e-4 cm is below what the largest SPIHT stream reaches through its float32 rounding.
    options.max_errors_cm = vec![0.5, 2.0, 1e-9];
    let summary = sweep(&options, &|_, _| {}).unwrap();
    let made: Vec<_> = summary.manifest.stimuli.iter().skip(1).collect();
    let ids: Vec<&str> = made.iter().map(|s| s.id.as_str()).collect();
    assert_eq!(ids, ["walk/spiht/max0.5cm", "walk/spiht/max2cm"]);
    for s in &made {
        let bound = s.target_max_error_cm.unwrap();
        assert!(s.target_cr.is_none());
        assert!(s.metrics.unwrap().max_cm <= bound, "{}", s.id);
    }
    // A looser bound, a smaller stream.
    assert!(made[1].bytes < made[0].bytes);
    assert_eq!(summary.unreachable.len(), 1);
    assert_eq!(summary.unreachable[0].id, "walk/spiht/max0.000000001cm");
    assert!(
        summary.unreachable[0].reason.contains("not reachable"),
        "{}",
        summary.unreachable[0].reason
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Re-encodes `clip` with the knob at `value` and measures its max joint error.
fn max_error_at(
    codec: &dyn codec::Codec,
    clip: &motion::Clip,
    params: &Params,
    key: &str,
    value: f64,
) -> (f64, usize) {
    let mut p = params.clone();
    p.insert(key.into(), value);
    let made = stimulus::make(
        codec,
        clip,
        &Request {
            params: p,
            target_cr: None,
        },
    )
    .unwrap();
    (made.metrics.max_cm, made.bytes.len())
}

#[test]
#[expect(
    clippy::float_cmp,
    reason = "the search and a re-encode run the same deterministic code: equal to the bit"
)]
fn the_bounded_search_stops_where_one_step_smaller_exceeds_the_bound() {
    let clip = motion::synth::walking_clip(&motion::synth::WalkParams {
        duration_s: 2.0,
        ..motion::synth::WalkParams::default()
    });
    let window: Params = [("window".to_string(), 256.0)].into();
    let qp: Params = [("qp".to_string(), 12.0), ("window".to_string(), 256.0)].into();
    for (name, params, bound) in [
        ("spiht", window.clone(), 0.5),
        ("spiht", window, 2.0),
        ("wavelet-perceptual", qp.clone(), 1.0),
        ("wavelet-bone", qp, 1.0),
    ] {
        let codec = codec::by_name(name).unwrap();
        let b = bounded::make_within(codec.as_ref(), &clip, &params, bound).unwrap();
        assert!(
            b.made.metrics.max_cm <= bound,
            "{name}: {}",
            b.made.metrics.max_cm
        );
        assert!(b.encodes <= MAX_KNOB_ENCODES, "{name}: {}", b.encodes);
        assert!(b.qp_tried.is_empty(), "{name}: qp is given or not taken");
        if name != "spiht" {
            // The documented count: the two ends and ten bisections of a 10⁴ span.
            assert_eq!(b.encodes, 12, "{name}");
        }
        assert_eq!(
            b.made
                .stream
                .params
                .get(b.knob.key)
                .copied()
                .unwrap_or(b.value),
            b.value
        );
        let smaller = b
            .smaller
            .unwrap_or_else(|| panic!("{name}: the codec's minimum is within {bound}"));
        // One step: within 1 % of the knob, toward smaller streams.
        assert!(
            (smaller.value / b.value).ln().abs() <= bounded::KNOB_STEP.ln_1p() + 1e-12,
            "{name}"
        );
        // Measured again: what the search saw, the next step beyond the bound.
        let (max, bytes) = max_error_at(codec.as_ref(), &clip, &params, b.knob.key, smaller.value);
        assert_eq!((max, bytes), (smaller.max_cm, smaller.bytes), "{name}");
        assert!(max > bound, "{name}: {max}");
        assert!(
            bytes <= b.made.bytes.len(),
            "{name}: {bytes} > {}",
            b.made.bytes.len()
        );
        let (again, _) = max_error_at(codec.as_ref(), &clip, &params, b.knob.key, b.value);
        assert_eq!(again, b.made.metrics.max_cm, "{name}");
    }
}

#[test]
fn a_bound_the_smallest_stream_meets_takes_one_encode_and_one_no_stream_meets_is_refused() {
    let clip = motion::synth::walking_clip(&motion::synth::WalkParams {
        duration_s: 1.0,
        ..motion::synth::WalkParams::default()
    });
    let spiht = codec::by_name("spiht").unwrap();
    let b = bounded::make_within(spiht.as_ref(), &clip, &Params::new(), 1e6).unwrap();
    // On a 1-s clip SPIHT's side information alone exceeds 10 000:1's budget: one refused
    // try, then the largest ratio it reaches.
    assert_eq!((b.encodes, b.smaller, b.value), (2, None, b.knob.smallest));
    assert!(
        b.value < 1e4 && b.made.achieved_cr() > 0.99 * b.value,
        "{}",
        b.value
    );
    let wavelet = codec::by_name("wavelet-perceptual").unwrap();
    let qp: Params = [("qp".to_string(), 10.0)].into();
    let b = bounded::make_within(wavelet.as_ref(), &clip, &qp, 1e6).unwrap();
    assert_eq!((b.encodes, b.smaller, b.value), (1, None, 1e-4));
    let e = bounded::make_within(spiht.as_ref(), &clip, &Params::new(), 1e-9).unwrap_err();
    assert!(matches!(e, lab::LabError::BoundUnreachable { .. }), "{e}");
    assert!(e.to_string().contains("at cr = 1"), "{e}");
    // The knob is the search's: giving it is refused, as is a codec without one.
    let e = bounded::make_within(
        spiht.as_ref(),
        &clip,
        &[("cr".to_string(), 20.0)].into(),
        1.0,
    )
    .unwrap_err();
    assert!(e.to_string().contains("--param cr"), "{e}");
    let raw = codec::by_name("raw-f32").unwrap();
    assert!(bounded::make_within(raw.as_ref(), &clip, &Params::new(), 1.0).is_err());
}

/// Without `qp` the wavelet codecs' search walks the quantiser: at the default QP 10 the walk
/// cannot reach 0.3 cm whatever α; more bits can, and the QP kept is the one whose stream is
/// smallest among those tried, its neighbours larger or out of reach.
#[test]
fn without_qp_the_wavelet_search_walks_the_quantiser_to_the_smallest_stream() {
    let clip = motion::synth::walking_clip(&motion::synth::WalkParams {
        duration_s: 2.0,
        ..motion::synth::WalkParams::default()
    });
    let codec = codec::by_name("wavelet-perceptual").unwrap();
    let bound = 0.3;
    let fixed: Params = [("qp".to_string(), 10.0)].into();
    assert!(matches!(
        bounded::make_within(codec.as_ref(), &clip, &fixed, bound),
        Err(lab::LabError::BoundUnreachable { .. })
    ));
    let b = bounded::make_within(codec.as_ref(), &clip, &Params::new(), bound).unwrap();
    assert!(b.made.metrics.max_cm <= bound, "{}", b.made.metrics.max_cm);
    let qp = b.made.stream.params["qp"] as u32;
    assert!(qp > 10, "{qp}");
    let tried = &b.qp_tried;
    assert_eq!(tried[0], (10, None), "{tried:?}");
    let bytes = |q: u32| tried.iter().find(|t| t.0 == q).map(|t| t.1);
    assert_eq!(bytes(qp), Some(Some(b.made.bytes.len())), "{tried:?}");
    // Its neighbours were tried and are no smaller (or out of reach).
    for q in [qp - 1, qp + 1] {
        let n = bytes(q).unwrap_or_else(|| panic!("qp {q} not tried: {tried:?}"));
        assert!(n.is_none_or(|n| n >= b.made.bytes.len()), "{tried:?}");
    }
    // Every reachable QP tried ran a full knob search, every unreachable one its two ends.
    let want: usize = tried
        .iter()
        .map(|t| if t.1.is_some() { 12 } else { 2 })
        .sum();
    assert_eq!(b.encodes, want, "{tried:?}");
}
