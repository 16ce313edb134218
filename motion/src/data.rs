//! Where tests and benchmarks find the real clips.
//!
//! The CMU clips are not part of the repository: they are read from `$MOCAP_DATA` or from
//! `../shared/data/mocap` beside the repository. When the environment variable `CI` is set and
//! the folder is missing, [`mocap_dir`] panics, so that a CI run never passes by skipping them.

use std::path::{Path, PathBuf};

/// One real clip: a name, its ASF skeleton (for AMC motion) and its motion file.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClipFiles {
    /// Short name (the motion file's stem, e.g. `02_01`).
    pub name: String,
    /// The ASF skeleton for an AMC motion, `None` for BVH.
    pub asf: Option<PathBuf>,
    /// The motion file (AMC or BVH).
    pub motion: PathBuf,
}

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

/// Every clip in the shared folder: each `.bvh`, and each `.amc` paired with the `.asf` of the
/// same stem or, failing that, the folder's only other ASF (CMU's `02_01.amc` uses `12.asf`).
pub fn shared_clips() -> Vec<ClipFiles> {
    let Some(dir) = mocap_dir() else {
        return Vec::new();
    };
    let mut files: Vec<PathBuf> = std::fs::read_dir(&dir)
        .map(|rd| rd.filter_map(|e| e.ok().map(|e| e.path())).collect())
        .unwrap_or_default();
    files.sort();
    let ext = |p: &Path, e: &str| p.extension().is_some_and(|x| x.eq_ignore_ascii_case(e));
    let asfs: Vec<&PathBuf> = files.iter().filter(|p| ext(p, "asf")).collect();
    let mut out = Vec::new();
    for p in &files {
        let stem = p
            .file_stem()
            .map(|s| s.to_string_lossy().into_owned())
            .unwrap_or_default();
        if ext(p, "bvh") {
            out.push(ClipFiles {
                name: stem,
                asf: None,
                motion: p.clone(),
            });
        } else if ext(p, "amc") {
            let asf = asfs
                .iter()
                .find(|a| {
                    a.file_stem().is_some_and(|s| {
                        let s = s.to_string_lossy();
                        stem.starts_with(s.as_ref())
                    })
                })
                .or_else(|| {
                    // An AMC whose stem names no ASF: pair it with an ASF no other AMC claims.
                    asfs.iter().find(|a| {
                        let s = a.file_stem().map(|s| s.to_string_lossy().into_owned());
                        !files.iter().any(|m| {
                            ext(m, "amc")
                                && m.file_stem().is_some_and(|ms| {
                                    s.as_deref()
                                        .is_some_and(|s| ms.to_string_lossy().starts_with(s))
                                })
                        })
                    })
                });
            if let Some(a) = asf {
                out.push(ClipFiles {
                    name: stem,
                    asf: Some((*a).clone()),
                    motion: p.clone(),
                });
            }
        }
    }
    out
}
