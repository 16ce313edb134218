//! `study stimuli add`: clips decoded by a codec this project does not have (a lab's own, run
//! elsewhere) become stimuli of a manifest, measured exactly as the project's own: the same
//! FK and metrics as `study sweep` and `study encode` (joint RMS and max, the worst 1-s
//! window, angle error, foot sliding) against the clip's reference, and the compression ratio
//! from the stream's size on the same basis (`4 bytes × channels × frames / bytes`).
//!
//! A clip's reference is added first (`--reference`), which creates the manifest when there
//! is none. A stimulus whose skeleton, frame count or frame rate is not its reference's is
//! refused naming both files, as is one that names its reference's file. Every file must lie
//! in the manifest's folder (the set moves as one); the manifest is rewritten atomically, with
//! the files' SHA-256, so every preflight finds a file changed or swapped afterwards.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use motion::Clip;
use protocols::manifest::{
    MANIFEST_VERSION, REFERENCE_CODEC, Stimulus, StimulusManifest, variant_label,
};

use crate::error::{Context as _, Result, io_error, refused};
use crate::stimulus;

/// The size a stimulus' stream takes: the file the codec wrote, or its byte count.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Size {
    /// The stream file (any format: only its size is read, and its SHA-256 kept).
    Stream(PathBuf),
    /// The stream's size in bytes, where the file is not at hand.
    Bytes(u64),
    /// Not known: the stimulus is measured and can be previewed, but its compression ratio
    /// is `null` ("CR unknown") and no study shows it until its size is given.
    Unknown,
}

/// What to add to a manifest.
#[derive(Debug, Clone, PartialEq)]
pub enum Added {
    /// A clip's reference (the source the codec was given).
    Reference {
        /// The motion file.
        file: PathBuf,
        /// Its ASF skeleton, for an AMC file.
        skeleton: Option<PathBuf>,
    },
    /// A decoded clip.
    Decoded {
        /// The codec's name (not `reference`).
        codec: String,
        /// The decoded motion file.
        file: PathBuf,
        /// Its ASF skeleton, for an AMC file.
        skeleton: Option<PathBuf>,
        /// The stream's size.
        size: Size,
        /// The codec's parameters (they also tell variants apart: the id and the analysis'
        /// condition labels carry them).
        params: BTreeMap<String, f64>,
        /// The id (default `CLIP/CODEC[/VARIANT]`).
        id: Option<String>,
    },
}

/// Adds `what` of clip `clip` to the manifest at `manifest` (created by a reference when
/// missing); returns the stimulus as written.
///
/// # Errors
/// A manifest that does not read or whose values cannot be true; a file outside the manifest's
/// folder, missing or unreadable; a clip without a reference, or with one already (for a
/// reference); a decoded clip whose skeleton, frames or rate are not its reference's, or that
/// is its reference's file; an id already there; a stream of no bytes; I/O errors.
pub fn add(manifest: &Path, clip: &str, what: &Added) -> Result<Stimulus> {
    let dir = manifest
        .parent()
        .filter(|d| !d.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut m = if manifest.exists() {
        read_manifest(manifest)?
    } else if matches!(what, Added::Reference { .. }) {
        StimulusManifest {
            version: MANIFEST_VERSION,
            cr_basis: protocols::manifest::CrBasis::File,
            stimuli: Vec::new(),
        }
    } else {
        return Err(refused(format!(
            "{}: no such manifest; add the clip's reference first (--reference FILE), which \
             creates it",
            manifest.display()
        )));
    };
    let st = match what {
        Added::Reference { file, skeleton } => {
            if let Some(r) = m.reference_of(clip) {
                return Err(refused(format!(
                    "{}: clip {clip:?} has a reference already ({:?}, {})",
                    manifest.display(),
                    r.id,
                    r.file
                )));
            }
            read(file, skeleton.as_deref())?;
            let home = dir.canonicalize().map_err(io_error(dir))?;
            let at = skeleton.as_deref().map(|s| inside(dir, s)).transpose()?;
            let mut st =
                crate::sweep::reference_stimulus(&home, clip, &inside(dir, file)?, at.as_deref());
            st.sha256 = Some(stimulus::sha256_file(file)?);
            st
        }
        Added::Decoded {
            codec,
            file,
            skeleton,
            size,
            params,
            id,
        } => decoded(
            dir,
            &m,
            clip,
            &Decoded {
                codec,
                file,
                skeleton: skeleton.as_deref(),
                size,
                params,
                id: id.as_deref(),
            },
        )?,
    };
    if m.get(&st.id).is_some() {
        return Err(refused(format!(
            "{}: a stimulus {:?} is there already (give another --id)",
            manifest.display(),
            st.id
        )));
    }
    m.version = MANIFEST_VERSION;
    m.stimuli.push(st.clone());
    let json = serde_json::to_string_pretty(&m)? + "\n";
    files::write(manifest, json, files::Mode::Replace)?;
    Ok(st)
}

/// [`Added::Decoded`]'s fields, borrowed.
struct Decoded<'a> {
    codec: &'a str,
    file: &'a Path,
    skeleton: Option<&'a Path>,
    size: &'a Size,
    params: &'a BTreeMap<String, f64>,
    id: Option<&'a str>,
}

/// The stimulus of decoded clip `d` of `clip`, measured against its reference in `m`.
fn decoded(dir: &Path, m: &StimulusManifest, clip: &str, d: &Decoded<'_>) -> Result<Stimulus> {
    if d.codec.is_empty() || d.codec == REFERENCE_CODEC {
        return Err(refused(format!(
            "--codec: give the codec's name (not {REFERENCE_CODEC:?}: a reference is added with \
             --reference)"
        )));
    }
    let Some(r) = m.reference_of(clip) else {
        return Err(refused(format!(
            "{}: clip {clip:?} has no reference; add it first (--reference FILE)",
            dir.join(crate::sweep::MANIFEST_FILE).display()
        )));
    };
    let reference_file = dir.join(&r.file);
    let file = rel(dir, d.file)?;
    if file == r.file {
        return Err(refused(format!(
            "{}: is the file of its reference {:?}: a decoded clip is the codec's output",
            d.file.display(),
            r.id
        )));
    }
    let reference = read(
        &reference_file,
        r.skeleton.as_ref().map(|s| dir.join(s)).as_deref(),
    )?;
    let decoded = read(d.file, d.skeleton)?;
    let problems = crate::preflight::mismatch(&decoded, &reference, &r.id);
    if !problems.is_empty() {
        return Err(refused(format!(
            "{} does not fit its reference {}: {}",
            d.file.display(),
            reference_file.display(),
            problems.join("; ")
        )));
    }
    let (bytes, stream_sha256) = match d.size {
        Size::Stream(path) => {
            let meta = std::fs::metadata(path).map_err(io_error(path))?;
            (meta.len(), Some(stimulus::sha256_file(path)?))
        }
        Size::Bytes(n) => (*n, None),
        Size::Unknown => (0, None),
    };
    if bytes == 0 && *d.size != Size::Unknown {
        return Err(refused(format!(
            "{}: a stream of 0 bytes has no compression ratio",
            match d.size {
                Size::Stream(p) => p.display().to_string(),
                Size::Bytes(_) | Size::Unknown => "--bytes".to_string(),
            }
        )));
    }
    let metrics = codecs::metrics::compare(&reference, &decoded).map_err(|e| {
        refused(format!(
            "{} against {}: {e}",
            d.file.display(),
            reference_file.display()
        ))
    })?;
    let w = stimulus::worst_window(&metrics, reference.frame_rate_hz);
    // The manifest's basis: a set made with `--cr-basis seed` counts the seeds' channels.
    let channels = crate::sweep::codec_basis(m.cr_basis)
        .channels(&reference.skeleton)
        .map_err(|e| refused(format!("{}: {e}", reference_file.display())))?;
    let raw = 4.0 * channels as f64 * reference.frames() as f64;
    let id = d.id.map_or_else(
        || {
            if d.params.is_empty() {
                format!("{clip}/{}", d.codec)
            } else {
                format!("{clip}/{}/{}", d.codec, variant_label(d.params))
            }
        },
        str::to_owned,
    );
    Ok(Stimulus {
        id,
        clip: clip.to_owned(),
        codec: d.codec.to_owned(),
        params: d.params.clone(),
        variant: d.params.clone(),
        target_cr: None,
        target_max_error_cm: None,
        achieved_cr: (bytes > 0).then(|| raw / bytes as f64),
        bytes,
        file,
        skeleton: d.skeleton.map(|s| rel(dir, s)).transpose()?,
        // Another codec's stream is no container this project decodes: its size and hash
        // are kept, not its path.
        bitstream: None,
        sha256: Some(stimulus::sha256_file(d.file)?),
        bitstream_sha256: stream_sha256,
        metrics: Some(stimulus::manifest_metrics(&metrics, w)),
        encode_ms: None,
        decode_ms: None,
        scene: None,
    })
}

/// The manifest at `path`, refused (naming it) where it does not parse or holds values that
/// cannot be true.
fn read_manifest(path: &Path) -> Result<StimulusManifest> {
    let text = std::fs::read_to_string(path).map_err(io_error(path))?;
    let m: StimulusManifest =
        serde_json::from_str(&text).map_err(|e| refused(format!("{}: {e}", path.display())))?;
    let problems = m.problems();
    if !problems.is_empty() {
        return Err(refused(format!(
            "{}: {}",
            path.display(),
            problems.join(&format!("\n{}: ", path.display()))
        )));
    }
    Ok(m)
}

/// The clip in `file` (with `skeleton` for an AMC file); its errors name the file.
fn read(file: &Path, skeleton: Option<&Path>) -> Result<Clip> {
    motion::io::read_clip(skeleton, file).context(|| format!("reading {}", file.display()))
}

/// `path`, which must lie in the manifest's folder `dir`, as it is there.
fn inside(dir: &Path, path: &Path) -> Result<PathBuf> {
    let canon = |p: &Path| p.canonicalize().map_err(io_error(p));
    let (d, p) = (canon(dir)?, canon(path)?);
    if p.starts_with(&d) {
        Ok(p)
    } else {
        Err(refused(format!(
            "{}: not in the manifest's folder {} (a stimulus set moves as one folder: copy the \
             file there)",
            path.display(),
            dir.display()
        )))
    }
}

/// `path` relative to the manifest's folder `dir`, with `/` separators.
fn rel(dir: &Path, path: &Path) -> Result<String> {
    let d = dir.canonicalize().map_err(io_error(dir))?;
    let p = inside(dir, path)?;
    Ok(crate::sweep::rel(&d, &p))
}
