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
