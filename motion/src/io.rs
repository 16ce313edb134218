//! Reading and writing clips by file name: `.asf` + `.amc`, or one `.bvh`.

use std::path::Path;

use files::Mode;

use crate::clip::{Clip, SkeletonFormat};
use crate::error::{Limits, ParseError, ReadWarning, WriteError};
use crate::{amc, asf, bvh, convert, text};

fn has_ext(p: &Path, e: &str) -> bool {
    p.extension().is_some_and(|x| x.eq_ignore_ascii_case(e))
}

/// Reads a clip: an AMC motion with its ASF skeleton, or a BVH file (`asf` must then be
/// `None`). AMC clips get CMU's 120 Hz. The readers' warnings are dropped; see
/// [`read_clip_with_warnings`] to show them.
///
/// # Errors
/// A [`ParseError`] naming the file, line and reason; also when the pair of files does not
/// make sense (an AMC without an ASF, a BVH with one, an unknown extension).
pub fn read_clip(asf_path: Option<&Path>, motion: &Path) -> Result<Clip, ParseError> {
    read_clip_with_warnings(asf_path, motion).map(|(clip, _)| clip)
}

/// As [`read_clip`], with what the readers changed while reading (an ASF bone direction
/// normalised), each naming its file and line.
///
/// # Errors
/// As [`read_clip`].
pub fn read_clip_with_warnings(
    asf_path: Option<&Path>,
    motion: &Path,
) -> Result<(Clip, Vec<ReadWarning>), ParseError> {
    let limits = Limits::default();
    if has_ext(motion, "bvh") {
        if let Some(a) = asf_path {
            return Err(text::syntax(
                a,
                0,
                "a BVH file carries its own skeleton; give no ASF",
            ));
        }
        return Ok((bvh::read_bvh_with(motion, &limits)?, Vec::new()));
    }
    if has_ext(motion, "amc") {
        let Some(a) = asf_path else {
            return Err(text::syntax(
                motion,
                0,
                "an AMC motion needs its ASF skeleton (--asf)",
            ));
        };
        let (skeleton, warnings) = asf::read_asf_with_warnings(a, &limits)?;
        let clip = amc::read_amc_with(motion, &skeleton, amc::CMU_FRAME_RATE_HZ, &limits)?;
        return Ok((clip, warnings));
    }
    Err(text::syntax(
        motion,
        0,
        "unknown motion file type: expected .amc or .bvh",
    ))
}

/// Writes a clip by the motion file's extension: `.bvh` (an ASF clip is converted), or `.amc`
/// (with its skeleton written to `asf_path` when given). Each file is written whole or not at
/// all ([`files::write`]); with [`Mode::New`] an existing motion or skeleton file is refused
/// before either is written, with [`Mode::Replace`] both are replaced.
///
/// # Errors
/// [`WriteError::File`] on I/O failure or an existing file under [`Mode::New`];
/// [`WriteError::Unsupported`] when the clip cannot be expressed in that format (a BVH clip as
/// AMC).
pub fn write_clip(
    clip: &Clip,
    motion: &Path,
    asf_path: Option<&Path>,
    mode: Mode,
) -> Result<(), WriteError> {
    if has_ext(motion, "bvh") {
        let bvh_clip = if clip.skeleton.format == SkeletonFormat::Asf {
            convert::asf_to_bvh(clip).map_err(|e| WriteError::Unsupported {
                path: motion.to_path_buf(),
                reason: e.to_string(),
            })?
        } else {
            clip.clone()
        };
        let text = bvh::write_bvh(&bvh_clip, motion)?;
        files::write(motion, text, mode)?;
        return Ok(());
    }
    if has_ext(motion, "amc") {
        let text = amc::write_amc(clip, motion)?;
        let skeleton = asf_path
            .map(|a| Ok::<_, WriteError>((a, asf::write_asf(&clip.skeleton, a)?)))
            .transpose()?;
        // Both names are checked before either file is written, so a refusal leaves no half
        // pair behind.
        files::check_new(motion, mode)?;
        if let Some((a, text)) = skeleton {
            files::check_new(a, mode)?;
            files::write(a, text, mode)?;
        }
        files::write(motion, text, mode)?;
        return Ok(());
    }
    Err(WriteError::Unsupported {
        path: motion.to_path_buf(),
        reason: "unknown motion file type: expected .amc or .bvh".into(),
    })
}
