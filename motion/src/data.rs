//! Where tests and benchmarks find the real clips.
//!
//! The CMU clips are not part of the repository: they are read from `$MOCAP_DATA` or from
//! `../shared/data/mocap` beside the repository. When the environment variable `CI` is set and
//! the folder is missing, [`mocap_dir`] panics, so that a CI run never passes by skipping them.

use std::path::{Path, PathBuf};

use crate::pairing::ClipSource;

/// The folder holding the shared clips, or `None` when it is absent outside CI.
///
/// # Panics
/// When `CI` is set and the folder does not exist: tests that need real clips must fail there.
pub fn mocap_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("MOCAP_DATA").map_or_else(
        || Path::new(env!("CARGO_MANIFEST_DIR")).join("../../shared/data/mocap"),
        PathBuf::from,
    );
    if dir.is_dir() {
        return Some(dir);
    }
    // Tests must fail, not skip, when CI lacks the data.
    assert!(
        std::env::var_os("CI").is_none(),
        "CI is set but the mocap clips are missing at {} (set MOCAP_DATA)",
        dir.display()
    );
    None
}

/// Every clip in the shared folder, paired by the one rule of [`crate::pairing`] (each
/// `.bvh`; each `.amc` with the `.asf` named after it, or the folder's one ASF no other motion
/// is named after: CMU's `02_01.amc` uses `12.asf`).
///
/// # Panics
/// As [`mocap_dir`], and when the folder's files do not pair (a test must not run on clips
/// read with the wrong skeleton).
#[expect(
    clippy::panic,
    reason = "a helper of tests and benchmarks, which must stop on clips read with the wrong skeleton"
)]
pub fn shared_clips() -> Vec<ClipSource> {
    let Some(dir) = mocap_dir() else {
        return Vec::new();
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map(|rd| rd.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    files.retain(|p| {
        p.extension().is_some_and(|x| {
            ["asf", "amc", "bvh"]
                .iter()
                .any(|e| x.eq_ignore_ascii_case(e))
        })
    });
    files.sort();
    match crate::pairing::pair(&files, None) {
        Ok(clips) => clips,
        Err(e) => panic!("the clips in {} do not pair: {e}", dir.display()),
    }
}
