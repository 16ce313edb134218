//! Clip sets: the files a command names, paired by [`motion::pairing`]'s one rule and read.

use std::path::{Path, PathBuf};

use motion::Clip;
use motion::pairing::{self, ClipSource};

use crate::error::{Result, refused};

/// How a set of clip files is read.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ClipOptions {
    /// The ASF skeleton given for every AMC not named after an ASF of the set (`--asf`).
    pub asf: Option<PathBuf>,
    /// Length unit of BVH files in cm, overriding the one inferred from the skeleton's height
    /// (BVH states no unit).
    pub bvh_unit_cm: Option<f64>,
}

/// A clip read from its files.
#[derive(Debug, Clone)]
pub struct LoadedClip {
    /// Where it came from (its name is the motion file's stem).
    pub source: ClipSource,
    /// The clip.
    pub clip: Clip,
}

/// Pairs `files` (motions and skeletons in any order) without reading them.
///
/// # Errors
/// Files that do not pair for certain ([`motion::pairing::PairingError`]).
pub fn sources(files: &[PathBuf], options: &ClipOptions) -> Result<Vec<ClipSource>> {
    Ok(pairing::pair(files, options.asf.as_deref())?)
}

/// Pairs and reads every clip `files` name.
///
/// # Errors
/// Files that do not pair, cannot be read, or a bad BVH unit.
pub fn load(files: &[PathBuf], options: &ClipOptions) -> Result<Vec<LoadedClip>> {
    if let Some(cm) = options.bvh_unit_cm
        && !(cm.is_finite() && cm > 0.0)
    {
        return Err(refused(
            "--bvh-unit-cm must be a positive number of centimetres",
        ));
    }
    sources(files, options)?
        .into_iter()
        .map(|source| {
            let clip = read(&source, options.bvh_unit_cm)?;
            Ok(LoadedClip { source, clip })
        })
        .collect()
}

/// Pairs and reads the one clip `files` name.
///
/// # Errors
/// As [`load`], and when the files name no clip or several.
pub fn load_one(files: &[PathBuf], options: &ClipOptions) -> Result<LoadedClip> {
    let mut all = load(files, options)?;
    if all.len() != 1 {
        return Err(refused(format!(
            "expected one clip, the files name {}",
            all.len()
        )));
    }
    Ok(all.remove(0))
}

/// Reads one paired clip; `bvh_unit_cm` overrides a BVH file's inferred unit. What the
/// readers changed while reading (an ASF bone direction normalised) is said on stderr, each
/// warning naming its file and line.
///
/// # Errors
/// The files cannot be read.
pub fn read(source: &ClipSource, bvh_unit_cm: Option<f64>) -> Result<Clip> {
    let (mut clip, warnings) =
        motion::io::read_clip_with_warnings(source.asf.as_deref(), &source.motion)?;
    for w in warnings {
        eprintln!("warning: {w}");
    }
    if let Some(cm) = bvh_unit_cm
        && clip.skeleton.format == motion::SkeletonFormat::Bvh
    {
        clip.skeleton.units.cm_per_unit = cm;
        clip.skeleton.units.declared = true;
    }
    Ok(clip)
}

/// The file name of `p` without its extension (`clip` when it has none).
pub fn stem_of(p: &Path) -> String {
    p.file_stem()
        .map_or_else(|| "clip".into(), |s| s.to_string_lossy().into_owned())
}

/// FK positions as CSV `frame,joint,x,y,z` (`study clip positions`), each value times `scale`.
pub fn positions_csv(pos: &motion::fk::Positions, scale: f64) -> String {
    let mut w = csv::Writer::from_writer(Vec::with_capacity(pos.frames() * pos.joint_count() * 48));
    // Writing into memory cannot fail.
    let _ = w.write_record(["frame", "joint", "x", "y", "z"]);
    for f in 0..pos.frames() {
        let frame = f.to_string();
        for (j, name) in pos.names.iter().enumerate() {
            let p = pos.point(f, j);
            let _ = w.write_record([
                frame.as_str(),
                name,
                &(p[0] * scale).to_string(),
                &(p[1] * scale).to_string(),
                &(p[2] * scale).to_string(),
            ]);
        }
    }
    String::from_utf8(w.into_inner().unwrap_or_default()).unwrap_or_default()
}

/// A NumPy v1.0 `.npy` file of little-endian float64, shape (frames, joints, 3).
///
/// # Errors
/// A header longer than the format holds (65,535 bytes).
pub fn positions_npy(pos: &motion::fk::Positions, scale: f64) -> Result<Vec<u8>> {
    let mut header = format!(
        "{{'descr': '<f8', 'fortran_order': False, 'shape': ({}, {}, 3), }}",
        pos.frames(),
        pos.joint_count()
    );
    // Magic (6) + version (2) + header length (2) + header, padded with spaces to a multiple
    // of 64 and ended by a newline.
    let total = 10 + header.len() + 1;
    header.push_str(&" ".repeat((64 - total % 64) % 64));
    header.push('\n');
    let mut bytes = Vec::with_capacity(10 + header.len() + pos.frames() * pos.joint_count() * 24);
    bytes.extend_from_slice(b"\x93NUMPY\x01\x00");
    let len = u16::try_from(header.len())
        .map_err(|_| crate::error::refused("an .npy header over 65,535 bytes"))?;
    bytes.extend_from_slice(&len.to_le_bytes());
    bytes.extend_from_slice(header.as_bytes());
    for f in 0..pos.frames() {
        for p in pos.frame(f) {
            for v in p {
                bytes.extend_from_slice(&(v * scale).to_le_bytes());
            }
        }
    }
    Ok(bytes)
}
