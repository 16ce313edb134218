//! Which skeleton an AMC motion is read with: one rule for every command that takes clip files.
//!
//! An AMC file holds joint angles only; the bone lengths and axes come from an ASF file, and
//! nothing in the AMC names it. Read with the wrong ASF (two CMU subjects share joint names),
//! the motion loads without a word and every position is wrong. So every command pairs files
//! the same way, and refuses what it cannot pair for certain:
//!
//! 1. an ASF among the files whose stem is the AMC's (`lambada.asf` for `lambada.amc`);
//! 2. else an ASF among the files whose stem begins the AMC's (`charleston.asf` for
//!    `charleston1.amc`, CMU's `02.asf` for `02_01.amc`);
//! 3. else the ASF given for every motion (`--asf`), if any;
//! 4. else the ASF beside the AMC on disk with its stem (`dir/02_01.asf` for `dir/02_01.amc`);
//! 5. else the one ASF among the files that no other motion is named after (CMU's
//!    `02_01.amc` with `12.asf`).
//!
//! Two candidates at the same step, no candidate at all, or an ASF among the files that no
//! motion uses, is an error naming the files. BVH files carry their own skeleton.

use std::path::{Path, PathBuf};

/// One clip's files: the motion and, for an AMC, the ASF skeleton it is read with.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClipSource {
    /// Short name: the motion file's stem (`02_01`).
    pub name: String,
    /// The ASF skeleton of an AMC motion; `None` for BVH.
    pub asf: Option<PathBuf>,
    /// The motion file (`.amc` or `.bvh`).
    pub motion: PathBuf,
}

/// Why a list of files does not name clips for certain.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum PairingError {
    /// No ASF can be paired with an AMC.
    #[error("{}: no ASF skeleton for this motion: {hint}", motion.display())]
    NoSkeleton {
        /// The AMC.
        motion: PathBuf,
        /// What was given and why none of it applies.
        hint: String,
    },
    /// Several ASFs fit an AMC equally well.
    #[error("{}: more than one ASF skeleton fits it ({}); name the ASF after the motion, or give fewer", motion.display(), list(candidates))]
    Ambiguous {
        /// The AMC.
        motion: PathBuf,
        /// The ASFs that fit.
        candidates: Vec<PathBuf>,
    },
    /// An ASF was given that no motion is read with.
    #[error("{}: no AMC motion among the files uses this skeleton", asf.display())]
    UnusedSkeleton {
        /// The ASF.
        asf: PathBuf,
    },
    /// A file is neither a motion nor a skeleton.
    #[error("{}: expected .amc, .bvh or .asf", path.display())]
    UnknownType {
        /// The file.
        path: PathBuf,
    },
    /// The files name no motion at all.
    #[error("no motion file given (.amc with its .asf, or .bvh)")]
    NoMotion,
}

fn list(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

fn has_ext(p: &Path, e: &str) -> bool {
    p.extension().is_some_and(|x| x.eq_ignore_ascii_case(e))
}

fn stem(p: &Path) -> String {
    p.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default()
}

/// Pairs `files` (motions and skeletons, in any order) into clips, in the order their motion
/// files come; `default_asf` is the skeleton given for every AMC (`--asf`), used after the
/// ASFs named after a motion (rules in the module docs).
///
/// # Errors
/// [`PairingError`] naming the files when a motion has no skeleton or several, a skeleton is
/// used by no motion, a file has an unknown type, or no motion is given.
pub fn pair(
    files: &[PathBuf],
    default_asf: Option<&Path>,
) -> Result<Vec<ClipSource>, PairingError> {
    let mut asfs: Vec<&PathBuf> = Vec::new();
    let mut motions: Vec<&PathBuf> = Vec::new();
    for f in files {
        if has_ext(f, "asf") {
            asfs.push(f);
        } else if has_ext(f, "amc") || has_ext(f, "bvh") {
            motions.push(f);
        } else {
            return Err(PairingError::UnknownType { path: f.clone() });
        }
    }
    if motions.is_empty() {
        return Err(PairingError::NoMotion);
    }
    let amcs: Vec<&PathBuf> = motions
        .iter()
        .copied()
        .filter(|m| has_ext(m, "amc"))
        .collect();
    // ASFs named after some AMC (rules 1 and 2) belong to it; only the rest may serve as the
    // one leftover skeleton of rule 5.
    let named_after = |a: &PathBuf| amcs.iter().any(|m| stem(m).starts_with(&stem(a)));
    let unclaimed: Vec<&PathBuf> = asfs.iter().copied().filter(|a| !named_after(a)).collect();
    let mut used: Vec<&PathBuf> = Vec::new();
    let mut out = Vec::with_capacity(motions.len());
    for m in motions {
        let name = stem(m);
        if has_ext(m, "bvh") {
            out.push(ClipSource {
                name,
                asf: None,
                motion: m.clone(),
            });
            continue;
        }
        let asf = skeleton_for(m, &name, &asfs, &unclaimed, default_asf)?;
        if let Some(a) = asfs.iter().find(|a| ***a == asf) {
            used.push(a);
        }
        out.push(ClipSource {
            name,
            asf: Some(asf),
            motion: m.clone(),
        });
    }
    if let Some(a) = asfs.iter().find(|a| !used.contains(a)) {
        return Err(PairingError::UnusedSkeleton { asf: (*a).clone() });
    }
    Ok(out)
}

/// The skeleton of AMC `m` (stem `name`) by rules 1-5.
fn skeleton_for(
    m: &Path,
    name: &str,
    asfs: &[&PathBuf],
    unclaimed: &[&PathBuf],
    default_asf: Option<&Path>,
) -> Result<PathBuf, PairingError> {
    let one = |found: Vec<&PathBuf>| -> Result<Option<PathBuf>, PairingError> {
        match found.as_slice() {
            [] => Ok(None),
            [a] => Ok(Some((*a).clone())),
            _ => Err(PairingError::Ambiguous {
                motion: m.to_path_buf(),
                candidates: found.into_iter().cloned().collect(),
            }),
        }
    };
    let exact = asfs.iter().copied().filter(|a| stem(a) == name).collect();
    if let Some(a) = one(exact)? {
        return Ok(a);
    }
    let prefix = asfs
        .iter()
        .copied()
        .filter(|a| name.starts_with(&stem(a)))
        .collect();
    if let Some(a) = one(prefix)? {
        return Ok(a);
    }
    if let Some(a) = default_asf {
        return Ok(a.to_path_buf());
    }
    let beside = m.with_file_name(format!("{name}.asf"));
    if beside.is_file() {
        return Ok(beside);
    }
    if let Some(a) = one(unclaimed.to_vec())? {
        return Ok(a);
    }
    let hint = if asfs.is_empty() {
        format!("give {name}.asf (or --asf SKEL)")
    } else {
        format!(
            "every ASF given ({}) is named after another motion; give {name}.asf, or --asf SKEL",
            list(&asfs.iter().map(|a| (*a).clone()).collect::<Vec<_>>())
        )
    };
    Err(PairingError::NoSkeleton {
        motion: m.to_path_buf(),
        hint,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(s: &str) -> PathBuf {
        PathBuf::from(format!("/nonexistent-pairing-test/{s}"))
    }

    fn pairs(
        files: &[&str],
        default: Option<&str>,
    ) -> Result<Vec<(String, Option<String>)>, PairingError> {
        let files: Vec<PathBuf> = files.iter().map(|f| p(f)).collect();
        let d = default.map(p);
        Ok(pair(&files, d.as_deref())?
            .into_iter()
            .map(|c| (c.name, c.asf.map(|a| stem(&a))))
            .collect())
    }

    fn named(v: &[(&str, Option<&str>)]) -> Vec<(String, Option<String>)> {
        v.iter()
            .map(|(n, a)| ((*n).to_string(), a.map(str::to_string)))
            .collect()
    }

    #[test]
    fn the_shared_clips_pair_as_cmu_names_them() {
        let got = pairs(
            &[
                "12.asf",
                "02_01.amc",
                "131_01.bvh",
                "charleston.asf",
                "charleston1.amc",
                "lambada.amc",
                "lambada.asf",
            ],
            None,
        )
        .unwrap();
        assert_eq!(
            got,
            named(&[
                ("02_01", Some("12")),
                ("131_01", None),
                ("charleston1", Some("charleston")),
                ("lambada", Some("lambada")),
            ])
        );
    }

    #[test]
    fn a_motion_is_never_read_with_a_skeleton_named_after_another() {
        let err = pairs(&["zombie.amc", "backflip.amc", "backflip.asf"], None).unwrap_err();
        assert!(
            matches!(&err, PairingError::NoSkeleton { motion, .. } if stem(motion) == "zombie"),
            "{err}"
        );
        assert!(err.to_string().contains("backflip.asf"), "{err}");
        // Named after it, it pairs; --asf says which skeleton to use for the others.
        assert_eq!(
            pairs(
                &["zombie.amc", "backflip.amc", "backflip.asf", "zombie.asf"],
                None
            )
            .unwrap(),
            named(&[("zombie", Some("zombie")), ("backflip", Some("backflip"))])
        );
        assert_eq!(
            pairs(&["zombie.amc", "backflip.amc"], Some("backflip.asf")).unwrap(),
            named(&[("zombie", Some("backflip")), ("backflip", Some("backflip"))])
        );
    }

    #[test]
    fn ambiguity_and_leftovers_are_errors() {
        assert!(matches!(
            pairs(&["02_01.amc", "12.asf", "13.asf"], None),
            Err(PairingError::Ambiguous { candidates, .. }) if candidates.len() == 2
        ));
        assert!(matches!(
            pairs(&["02_01.amc", "0.asf", "02.asf"], None),
            Err(PairingError::Ambiguous { .. })
        ));
        assert!(matches!(
            pairs(&["a.amc", "a.asf", "b.asf"], None),
            Err(PairingError::UnusedSkeleton { asf }) if stem(&asf) == "b"
        ));
        assert!(matches!(
            pairs(&["a.bvh", "a.asf"], None),
            Err(PairingError::UnusedSkeleton { .. })
        ));
        assert!(matches!(
            pairs(&["a.asf"], None),
            Err(PairingError::NoMotion)
        ));
        assert!(matches!(
            pairs(&["a.c3d"], None),
            Err(PairingError::UnknownType { .. })
        ));
        assert!(matches!(
            pairs(&["a.amc"], None),
            Err(PairingError::NoSkeleton { .. })
        ));
    }

    #[test]
    fn an_asf_beside_the_motion_is_found_on_disk() {
        let dir = std::env::temp_dir().join(format!("pairing-beside-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        std::fs::write(dir.join("walk.asf"), "").unwrap();
        let got = pair(&[dir.join("walk.amc")], None).unwrap();
        assert_eq!(got[0].asf.as_deref(), Some(dir.join("walk.asf").as_path()));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
