//! One stimulus made from a clip: encode (to a target compression ratio, or with the given
//! parameters), decode, measure the error, and time both halves. `study encode`, the sweep and
//! the live staircase all make their stimuli here.

use std::path::{Path, PathBuf};
use std::time::Instant;

use codecs::bitstream::Bitstream;
use codecs::codec::{Codec, Params};
use codecs::metrics::{self, Metrics};
use codecs::rate;
use motion::{Clip, SkeletonFormat};

use crate::error::{Context as _, Result};

/// What to make: the codec's parameters and, optionally, a target compression ratio that rate
/// control reaches (within ±2 %) over them.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Request {
    /// Codec parameters (those not given take the codec's defaults).
    pub params: Params,
    /// Target compression ratio (4 bytes × channels × frames / bitstream bytes).
    pub target_cr: Option<f64>,
}

/// A stimulus: the bitstream, its bytes, the decoded clip, its error against the source and
/// how long encoding and decoding took.
#[derive(Debug, Clone)]
pub struct Made {
    /// The container.
    pub stream: Bitstream,
    /// The container as written to disk.
    pub bytes: Vec<u8>,
    /// The clip the stream decodes to.
    pub decoded: Clip,
    /// Error of `decoded` against the source.
    pub metrics: Metrics,
    /// Encoding time (the whole rate search for a target), ms.
    pub encode_ms: f64,
    /// Decoding time, ms.
    pub decode_ms: f64,
}

impl Made {
    /// Compression ratio reached.
    pub fn achieved_cr(&self) -> f64 {
        self.stream.compression_ratio()
    }
}

/// Encodes `clip` with `codec` as `request` asks, decodes the stream and measures it.
///
/// # Errors
/// The codec refuses the parameters or cannot reach the target, or the stream does not
/// decode.
pub fn make(codec: &dyn Codec, clip: &Clip, request: &Request) -> Result<Made> {
    let t0 = Instant::now();
    let stream = match request.target_cr {
        Some(t) => rate::encode_to_cr(codec, clip, &request.params, t)?,
        None => codec.encode(clip, &request.params)?,
    };
    let encode_ms = t0.elapsed().as_secs_f64() * 1e3;
    let bytes = stream.to_bytes()?;
    let t1 = Instant::now();
    let decoded = codec
        .decode(&stream, &clip.skeleton)
        .context(|| format!("decoding what {} encoded", codec.name()))?;
    let decode_ms = t1.elapsed().as_secs_f64() * 1e3;
    let metrics = metrics::compare(clip, &decoded)?;
    Ok(Made {
        stream,
        bytes,
        decoded,
        metrics,
        encode_ms,
        decode_ms,
    })
}

/// The files [`write_clip_as`] writes for `clip`: `<dir>/<stem>.bvh`, or `<dir>/<stem>.amc`
/// with its skeleton, `asf` if given (an existing file, not written) else `<dir>/<stem>.asf`;
/// as (motion file, skeleton file, whether the skeleton is written).
pub fn clip_files(
    clip: &Clip,
    dir: &Path,
    stem: &str,
    asf: Option<&Path>,
) -> (PathBuf, Option<PathBuf>, bool) {
    match clip.skeleton.format {
        SkeletonFormat::Bvh => (dir.join(format!("{stem}.bvh")), None, false),
        SkeletonFormat::Asf => (
            dir.join(format!("{stem}.amc")),
            Some(asf.map_or_else(|| dir.join(format!("{stem}.asf")), Path::to_path_buf)),
            asf.is_none(),
        ),
    }
}

/// Writes `clip` in its own format as `<dir>/<stem>.bvh`, or `<dir>/<stem>.amc` with its
/// skeleton: `asf` names an existing skeleton file the motion refers to (the sweep's
/// reference skeleton, a decoded stream's input skeleton), which is not written; without it
/// the skeleton is written to `<dir>/<stem>.asf`. Returns the motion file and the ASF, if any
/// ([`clip_files`]). Files are written whole or not at all; existing ones are replaced only
/// with [`files::Mode::Replace`].
///
/// # Errors
/// The files cannot be written, or exist under [`files::Mode::New`].
pub fn write_clip_as(
    clip: &Clip,
    dir: &Path,
    stem: &str,
    asf: Option<&Path>,
    mode: files::Mode,
) -> Result<(PathBuf, Option<PathBuf>)> {
    let (m, a, write_asf) = clip_files(clip, dir, stem, asf);
    let written_asf = a.as_deref().filter(|_| write_asf);
    // The writer's errors name the file already.
    motion::io::write_clip(clip, &m, written_asf, mode)?;
    Ok((m, a))
}
