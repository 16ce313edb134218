//! Preflight: a stimulus set with one file deleted and one corrupted is refused before any
//! trial, every problem listed at once, each naming its file; an intact set passes.
#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic, missing_docs)]

use std::path::{Path, PathBuf};

use lab::StudyFile;
use motion::synth::WalkParams;

fn scratch(name: &str) -> PathBuf {
    let d = Path::new(env!("CARGO_TARGET_TMPDIR"))
        .join(format!("preflight-{}-{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The generated walk swept with SPIHT at 10:1 and 20:1, and a MOS study over it.
fn study(dir: &Path) -> PathBuf {
    let walk = WalkParams {
        duration_s: 1.0,
        ..WalkParams::default()
    };
    lab::generated::walk_stimuli(dir, &walk, &["spiht"], &[10.0, 20.0]).unwrap();
    let path = dir.join("study.toml");
    std::fs::write(
        &path,
        "format_version = 1\nname = \"pre\"\nprotocol = \"mos\"\nstimuli = \"stimuli/stimuli.json\"\n\
         seed = 1\n[conditions]\nclips = [\"walk\"]\ncodecs = [\"spiht\"]\ntarget_cr = [10, 20]\n",
    )
    .unwrap();
    path
}

#[test]
fn an_intact_set_passes_and_counts_what_it_read() {
    let dir = scratch("intact");
    let file = StudyFile::load(&study(&dir)).unwrap();
    let seen = std::cell::Cell::new(0);
    let checked = lab::preflight::verify(&file, &|done, total| {
        assert!(done <= total);
        seen.set(done);
    })
    .unwrap();
    // The reference and the two test stimuli; both streams decoded.
    assert_eq!((checked.stimuli, checked.decoded), (3, 2), "{checked:?}");
    assert_eq!(seen.get(), 3);
}

#[test]
fn a_missing_and_a_corrupt_stimulus_are_both_named() {
    let dir = scratch("broken");
    let path = study(&dir);
    let walk = dir.join("stimuli/walk");
    let missing = walk.join("spiht-cr10.amc");
    std::fs::remove_file(&missing).unwrap();
    // Cut the other decoded clip in the middle of a frame.
    let corrupt = walk.join("spiht-cr20.amc");
    let text = std::fs::read_to_string(&corrupt).unwrap();
    std::fs::write(&corrupt, &text[..text.len() / 2]).unwrap();
    // And flip a byte of its bitstream.
    let mcz = walk.join("spiht-cr20.mcz");
    let mut bytes = std::fs::read(&mcz).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x55;
    std::fs::write(&mcz, bytes).unwrap();
    let file = StudyFile::load(&path).unwrap();
    let (_, problems) = lab::preflight::check(&file, &|_, _| {});
    let files: Vec<&Path> = problems.iter().map(|p| p.file.as_path()).collect();
    assert!(files.contains(&missing.as_path()), "{problems:#?}");
    assert!(files.contains(&corrupt.as_path()), "{problems:#?}");
    let err = lab::preflight::verify(&file, &|_, _| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("spiht-cr10.amc") && err.contains("missing") && err.contains("spiht-cr20.amc"),
        "{err}"
    );
    assert!(
        err.contains("walk/spiht/cr10") && err.contains("walk/spiht/cr20"),
        "{err}"
    );
}

#[test]
fn a_stimulus_of_another_length_or_skeleton_is_refused() {
    let dir = scratch("mismatch");
    let path = study(&dir);
    // A two-second walk under the 10:1 stimulus' name: same skeleton, twice the frames.
    let longer = motion::synth::walking_clip(&WalkParams {
        duration_s: 2.0,
        ..WalkParams::default()
    });
    let walk = dir.join("stimuli/walk");
    motion::io::write_clip(
        &longer,
        &walk.join("spiht-cr10.amc"),
        None,
        files::Mode::Replace,
    )
    .unwrap();
    let file = StudyFile::load(&path).unwrap();
    let err = lab::preflight::verify(&file, &|_, _| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("spiht-cr10.amc") && err.contains("frames, its reference"),
        "{err}"
    );
}

/// The manifest of the set at `dir`, edited by `edit` and written back.
fn edit_manifest(dir: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let path = dir.join("stimuli/stimuli.json");
    let mut m: serde_json::Value = serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    edit(&mut m);
    std::fs::write(&path, serde_json::to_vec_pretty(&m).unwrap()).unwrap();
}

/// The stimulus `id` of manifest `m`.
fn entry<'m>(m: &'m mut serde_json::Value, id: &str) -> &'m mut serde_json::Value {
    m["stimuli"]
        .as_array_mut()
        .unwrap()
        .iter_mut()
        .find(|s| s["id"] == id)
        .unwrap()
}

/// Issue 38's manifest checks: files swapped after the sweep, a "compressed" stimulus whose
/// file is its reference's, a ratio or size that is not its bitstream's, and metrics that
/// cannot be true are each refused, naming the file or the manifest key.
#[test]
fn swapped_files_a_reference_as_stimulus_and_impossible_values_are_refused() {
    // Swapped: the two test stimuli's decoded files trade places (both parse, both match
    // the reference's skeleton, frames and rate: only their content tells them apart).
    let dir = scratch("swapped");
    let path = study(&dir);
    let walk = dir.join("stimuli/walk");
    let (a, b) = (walk.join("spiht-cr10.amc"), walk.join("spiht-cr20.amc"));
    let (ta, tb) = (std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
    assert_ne!(ta, tb);
    std::fs::write(&a, &tb).unwrap();
    std::fs::write(&b, &ta).unwrap();
    let file = StudyFile::load(&path).unwrap();
    let (_, problems) = lab::preflight::check(&file, &|_, _| {});
    let swapped: Vec<&Path> = problems
        .iter()
        .filter(|p| {
            p.message
                .contains("is not the file the manifest was written with")
        })
        .map(|p| p.file.as_path())
        .collect();
    assert_eq!(swapped, [a.as_path(), b.as_path()], "{problems:#?}");

    // The reference's file given as a compressed stimulus' (its hash recorded for it, as a
    // hand-written manifest would): refused, its metrics claiming an error it cannot have.
    let dir = scratch("reference-as-stimulus");
    let path = study(&dir);
    edit_manifest(&dir, |m| {
        let reference = entry(m, "walk/reference").clone();
        let s = entry(m, "walk/spiht/cr10");
        s["file"] = reference["file"].clone();
        s["sha256"] = reference["sha256"].clone();
    });
    let file = StudyFile::load(&path).unwrap();
    let err = lab::preflight::verify(&file, &|_, _| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("is byte-identical to the file of its reference \"walk/reference\"")
            && err.contains("walk/spiht/cr10")
            && err.contains("largest error of"),
        "{err}"
    );
    assert_eq!(err.matches("byte-identical").count(), 1, "{err}");

    // A ratio and a size that are not the bitstream's.
    let dir = scratch("ratio");
    let path = study(&dir);
    edit_manifest(&dir, |m| {
        let s = entry(m, "walk/spiht/cr20");
        s["achieved_cr"] = serde_json::json!(40.0);
        s["bytes"] = serde_json::json!(7);
    });
    let file = StudyFile::load(&path).unwrap();
    let err = lab::preflight::verify(&file, &|_, _| {})
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("spiht-cr20.mcz")
            && err.contains("achieved_cr: the manifest says 40, the bitstream gives")
            && err.contains("bytes: the manifest says 7, the bitstream file holds"),
        "{err}"
    );

    // Metrics that cannot be true: the study does not load, each value named by its key.
    let dir = scratch("metrics");
    let path = study(&dir);
    edit_manifest(&dir, |m| {
        let s = entry(m, "walk/spiht/cr10");
        s["metrics"]["rms_cm"] = serde_json::json!(-0.5);
        let s = entry(m, "walk/spiht/cr20");
        s["metrics"]["max_cm"] = serde_json::json!(0.001);
        s["sha256"] = serde_json::json!("not a hash");
    });
    let err = StudyFile::load(&path).unwrap_err().to_string();
    for want in [
        "stimuli.json: stimuli[1] (\"walk/spiht/cr10\").metrics.rms_cm: -0.5 is not a finite number 0 or more",
        "(\"walk/spiht/cr20\").metrics.rms_cm:",
        "is above metrics.max_cm 0.001",
        "(\"walk/spiht/cr20\").sha256: \"not a hash\" is not 64 lowercase hex digits",
    ] {
        assert!(err.contains(want), "{want}\n{err}");
    }
}
