//! Live (codec-in-the-loop) staircase end to end: the example's generated source clips,
//! `study check` / `study simulate` encoding each trial's stimulus on the fly and logging its
//! parameters, CR and error, and a simulated observer whose detection follows the real decoded
//! error recovered by the analysis within its confidence interval.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};

use codecs::synth::{WalkParams, walking_clip};

fn examples() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../examples")
}

/// The five generated motions of `examples/live/` (thesis ch. 5 used five motions in turn):
/// (name, motion file, walk parameters). AMC clips are 120 Hz (what the reader assumes);
/// BVH clips carry their own rate.
fn example_motions() -> Vec<(&'static str, &'static str, WalkParams)> {
    let base = WalkParams {
        duration_s: 1.5,
        ..WalkParams::default()
    };
    vec![
        ("walk", "walk.amc", base),
        (
            "stroll",
            "stroll.bvh",
            WalkParams {
                frame_rate_hz: 60.0,
                speed_cm_s: 80.0,
                cycle_hz: 0.7,
                amplitude: 0.8,
                ..base
            },
        ),
        (
            "brisk",
            "brisk.bvh",
            WalkParams {
                frame_rate_hz: 60.0,
                speed_cm_s: 160.0,
                cycle_hz: 1.1,
                amplitude: 1.1,
                ..base
            },
        ),
        (
            "march",
            "march.bvh",
            WalkParams {
                frame_rate_hz: 60.0,
                speed_cm_s: 100.0,
                cycle_hz: 0.8,
                amplitude: 1.4,
                ..base
            },
        ),
        (
            "sway",
            "sway.bvh",
            WalkParams {
                frame_rate_hz: 60.0,
                speed_cm_s: 60.0,
                cycle_hz: 0.6,
                amplitude: 1.2,
                ..base
            },
        ),
    ]
}

/// The checked-in clips of `examples/live/clips` are exactly what `codecs::synth` generates
/// (run with `REGENERATE_LIVE_EXAMPLE=1` to rewrite them after a change to the generator).
#[test]
fn example_clips_are_the_generated_motions() {
    let dir = examples().join("live/clips");
    let regenerate = std::env::var_os("REGENERATE_LIVE_EXAMPLE").is_some();
    let tmp =
        Path::new(env!("CARGO_TARGET_TMPDIR")).join(format!("live-clips-{}", std::process::id()));
    std::fs::create_dir_all(&tmp).unwrap();
    for (name, file, params) in example_motions() {
        let clip = walking_clip(&params);
        let out = if regenerate { dir.clone() } else { tmp.clone() };
        let asf = file.ends_with(".amc").then(|| out.join("walker.asf"));
        codecs::io::write_clip(&clip, &out.join(file), asf.as_deref()).unwrap();
        if !regenerate {
            for f in std::iter::once(file).chain(asf.as_ref().map(|_| "walker.asf")) {
                assert_eq!(
                    std::fs::read(tmp.join(f)).unwrap(),
                    std::fs::read(dir.join(f)).unwrap(),
                    "{name}: examples/live/clips/{f} differs from the generator (REGENERATE_LIVE_EXAMPLE=1)"
                );
            }
        }
    }
}
