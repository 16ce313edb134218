//! `study sweep --param` and `--max-error-cm`, and what `study encode` reports, run as a user
//! runs them: a parameter grid makes every variant with its own id, an unreachable target is
//! listed and the rest written, a parameter a codec does not take is refused before anything
//! is made, and an error-bounded encode stays within its bound.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use protocols::manifest::{REFERENCE_CODEC, StimulusManifest};

fn study(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_study"))
        .args(args)
        .output()
        .unwrap()
}

fn ok(args: &[&str]) -> String {
    let out = study(args);
    assert!(
        out.status.success(),
        "{args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

fn scratch(name: &str) -> PathBuf {
    let dir = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("sweep-grid-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn s(p: &Path) -> String {
    p.display().to_string()
}

/// A generated walk of 3.3 s (its 128- and 256-frame windows leave a short last one) as
/// `dir/walk.amc` + `dir/walk.asf`.
fn walk(dir: &Path) -> (String, String) {
    let clip = motion::synth::walking_clip(&motion::synth::WalkParams {
        duration_s: 3.3,
        ..motion::synth::WalkParams::default()
    });
    let (amc, asf) = (dir.join("walk.amc"), dir.join("walk.asf"));
    motion::io::write_clip(&clip, &amc, Some(&asf), files::Mode::New).unwrap();
    (s(&amc), s(&asf))
}

fn read_manifest(dir: &Path) -> StimulusManifest {
    serde_json::from_str(&std::fs::read_to_string(dir.join("stimuli.json")).unwrap()).unwrap()
}

/// The ids a grid of qp 9, 11 × window 128, 256 × CR 20, 40 makes for `clip` and `codec`.
fn grid_ids(clip: &str, codec: &str) -> BTreeSet<String> {
    let mut ids = BTreeSet::new();
    for qp in [9, 11] {
        for w in [128, 256] {
            for cr in [20, 40] {
                ids.insert(format!("{clip}/{codec}/qp{qp}-window{w}/cr{cr}"));
            }
        }
    }
    ids
}

/// The issue's example on a shared CMU clip: 8 stimuli per clip and codec, distinct ids.
#[test]
fn a_parameter_grid_makes_eight_stimuli_per_clip_and_codec() {
    let Some(mocap) = motion::data::mocap_dir() else {
        return;
    };
    let dir = scratch("cmu");
    let out = dir.join("stimuli");
    let stdout = ok(&[
        "sweep",
        "--clips",
        &s(&mocap.join("02_01.amc")),
        &s(&mocap.join("12.asf")),
        "--codecs",
        "wavelet-perceptual,wavelet-bone",
        "--param",
        "qp=9,11",
        "--param",
        "window=128,256",
        "--cr",
        "20,40",
        "--quiet",
        "-o",
        &s(&out),
    ]);
    assert!(stdout.starts_with("17 stimuli (1 references)"), "{stdout}");
    assert!(!stdout.contains("not reached"), "{stdout}");
    let manifest = read_manifest(&out);
    for codec in ["wavelet-perceptual", "wavelet-bone"] {
        let ids: BTreeSet<String> = manifest
            .stimuli
            .iter()
            .filter(|x| x.codec == codec)
            .map(|x| x.id.clone())
            .collect();
        assert_eq!(ids, grid_ids("02_01", codec));
    }
    let all: BTreeSet<&str> = manifest.stimuli.iter().map(|x| x.id.as_str()).collect();
    assert_eq!(all.len(), manifest.stimuli.len(), "ids are distinct");
    for x in manifest
        .stimuli
        .iter()
        .filter(|x| x.codec != REFERENCE_CODEC)
    {
        assert!(out.join(&x.file).is_file() && out.join(x.bitstream.as_ref().unwrap()).is_file());
        assert_eq!(x.params.get("qp"), x.variant.get("qp"), "{}", x.id);
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// An unreachable target is a line of the output and an `unreachable` row of rd.csv; the
/// sweep still succeeds and writes everything else.
#[test]
fn an_unreachable_target_is_listed_and_the_rest_written() {
    let dir = scratch("walk");
    let (amc, asf) = walk(&dir);
    let out = dir.join("stimuli");
    let stdout = ok(&[
        "sweep",
        "--clips",
        &amc,
        &asf,
        "--codecs",
        "wavelet-perceptual",
        "--param",
        "qp=9,11",
        "--param",
        "window=128,256",
        "--cr",
        "20,40,1000",
        "--quiet",
        "-o",
        &s(&out),
    ]);
    assert!(stdout.starts_with("9 stimuli (1 references)"), "{stdout}");
    assert!(
        stdout.contains("4 target(s) not reached (rd.csv rows with status unreachable):"),
        "{stdout}"
    );
    for qp in [9, 11] {
        for w in [128, 256] {
            assert!(
                stdout.contains(&format!(
                    "  walk/wavelet-perceptual/qp{qp}-window{w}/cr1000: "
                )),
                "{stdout}"
            );
        }
    }
    let manifest = read_manifest(&out);
    let ids: BTreeSet<String> = manifest
        .stimuli
        .iter()
        .skip(1)
        .map(|x| x.id.clone())
        .collect();
    assert_eq!(ids, grid_ids("walk", "wavelet-perceptual"));
    let csv = std::fs::read_to_string(out.join("rd.csv")).unwrap();
    assert!(
        csv.starts_with("clip,codec,params,target_cr,target_max_error_cm,status,"),
        "{csv}"
    );
    assert_eq!(csv.lines().count(), 1 + 12);
    assert_eq!(csv.matches(",unreachable,").count(), 4, "{csv}");
    assert!(
        csv.contains("walk,wavelet-perceptual,qp=9;window=128,20,,made,"),
        "{csv}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_parameter_the_codec_does_not_take_is_refused_before_anything_is_made() {
    let dir = scratch("refused");
    let (amc, asf) = walk(&dir);
    let out = dir.join("stimuli");
    let r = study(&[
        "sweep",
        "--clips",
        &amc,
        &asf,
        "--codecs",
        "spiht",
        "--param",
        "qp=9,11",
        "--cr",
        "20",
        "--quiet",
        "-o",
        &s(&out),
    ]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert!(!r.status.success());
    assert!(
        err.contains("--param qp: codec `spiht` does not take it; it takes allocation, cr,"),
        "{err}"
    );
    assert!(err.contains("window"), "{err}");
    assert!(!out.exists(), "nothing is written");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `study encode` reports the max joint error and the worst window next to the RMS, and
/// `--max-error-cm` gives a stream within the bound (decoded and measured here again).
#[test]
fn encode_reports_max_error_and_worst_window_and_keeps_an_error_bound() {
    let dir = scratch("encode");
    let (amc, asf) = walk(&dir);
    let stdout = ok(&[
        "encode",
        &amc,
        &asf,
        "--codec",
        "spiht",
        "--cr",
        "20",
        "-o",
        &s(&dir.join("cr")),
    ]);
    let first = stdout.lines().next().unwrap();
    assert!(first.starts_with("spiht: "), "{stdout}");
    assert!(first.contains(" cm, max "), "{stdout}");
    assert!(first.contains(", worst 1-s window RMS "), "{stdout}");
    assert!(
        first.contains(" cm, at ") && first.contains("(frames "),
        "{stdout}"
    );
    let bound = 0.5;
    let out = dir.join("bounded");
    let stdout = ok(&[
        "encode",
        &amc,
        &asf,
        "--codec",
        "spiht",
        "--max-error-cm",
        "0.5",
        "-o",
        &s(&out),
    ]);
    assert!(
        stdout.contains("max error ≤ 0.5 cm: cr ")
            && stdout.contains(" encodes; one step smaller (cr "),
        "{stdout}"
    );
    let bytes = std::fs::read(out.join("walk.spiht.mcz")).unwrap();
    let stream = codecs::bitstream::Bitstream::from_bytes(&bytes).unwrap();
    let source = motion::io::read_clip(Some(Path::new(&asf)), Path::new(&amc)).unwrap();
    let decoded = codecs::codec::decode_any(&stream, &source.skeleton).unwrap();
    let m = codecs::metrics::compare(&source, &decoded).unwrap();
    assert!(m.max_cm <= bound, "{}", m.max_cm);
    // --cr and --max-error-cm are two ways to ask; not both.
    let r = study(&[
        "encode",
        &amc,
        &asf,
        "--codec",
        "spiht",
        "--cr",
        "20",
        "--max-error-cm",
        "1",
        "-o",
        &s(&dir.join("both")),
    ]);
    assert!(!r.status.success());
    std::fs::remove_dir_all(&dir).unwrap();
}
