//! One stimulus made from a clip: encode (to a target compression ratio, or with the given
//! parameters), decode, measure the error, and time both halves. `study encode`, the sweep and
//! the live staircase all make their stimuli here ([`crate::bounded`] makes the smallest one
//! within an error bound from the same steps).
//!
//! Besides the clip-wide metrics, a stimulus reports its worst window ([`worst_window`]):
//! an RMS over the whole clip hides a broken second (a codec's short last window decoding to
//! zeros), which a subject sees as the figure jumping at the end of the loop.

use std::path::{Path, PathBuf};
use std::time::Instant;

use codecs::bitstream::Bitstream;
use codecs::codec::{Codec, Params};
use codecs::metrics::{self, Metrics, WindowError};
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
    /// The worst 1-s window of the error ([`worst_window`] over [`window_frames`] of the
    /// clip's rate); `None` for a clip without frames.
    pub worst_window: Option<WindowError>,
}

/// Frames in the worst-window metric's window at `frame_rate_hz`: one second, the rate
/// rounded, at least 1 (120 at CMU's 120 Hz).
pub fn window_frames(frame_rate_hz: f64) -> usize {
    if frame_rate_hz.is_finite() && frame_rate_hz >= 1.0 {
        frame_rate_hz.round() as usize
    } else {
        1
    }
}

/// The worst 1-s stretch of `metrics` ([`Metrics::worst_stretch`] over [`window_frames`] of
/// `frame_rate_hz`): the one place the sweep, `rd.csv`, `stimuli.json` and `study encode`
/// take the worst window from.
pub fn worst_window(metrics: &Metrics, frame_rate_hz: f64) -> Option<WindowError> {
    metrics.worst_stretch(window_frames(frame_rate_hz))
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
    let worst_window = worst_window(&metrics, clip.frame_rate_hz);
    Ok(Made {
        stream,
        bytes,
        decoded,
        metrics,
        encode_ms,
        decode_ms,
        worst_window,
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

/// A stimulus' metrics as the manifest records them: the clip-wide errors of `m` and the
/// worst window `worst`.
pub fn manifest_metrics(
    m: &Metrics,
    worst: Option<WindowError>,
) -> protocols::manifest::StimulusMetrics {
    protocols::manifest::StimulusMetrics {
        rms_cm: m.rms_cm,
        max_cm: m.max_cm,
        mean_angle_deg: m.mean_angle_deg,
        foot_slide_cm_s: m.foot_slide_cm_s,
        worst_window_rms_cm: worst.map(|w| w.rms_cm),
        worst_window_start_frame: worst.map(|w| w.start_frame as u64),
        worst_window_frames: worst.map(|w| w.frames as u64),
    }
}

/// `worst 1-s window RMS 0.412 cm, max 1.210 cm, at 12.93 s (frames 1552-1671)`
/// (docs/codecs.md).
pub fn worst_window_text(worst: Option<WindowError>, frame_rate_hz: f64) -> String {
    let Some(w) = worst else {
        return "no frames".to_string();
    };
    let span = if w.frames == window_frames(frame_rate_hz) {
        "1-s window".to_string()
    } else {
        format!(
            "window (the whole {:.2}-s clip)",
            w.frames as f64 / frame_rate_hz
        )
    };
    format!(
        "worst {span} RMS {:.3} cm, max {:.3} cm, at {:.2} s (frames {}-{})",
        w.rms_cm,
        w.max_cm,
        w.start_frame as f64 / frame_rate_hz,
        w.start_frame,
        w.start_frame + w.frames - 1
    )
}

/// SHA-256 of the file at `path`, as 64 lowercase hex digits (a stimulus' `sha256` in the
/// manifest).
///
/// # Errors
/// The file cannot be read (named).
pub fn sha256_file(path: &Path) -> Result<String> {
    use sha2::{Digest as _, Sha256};
    let bytes = std::fs::read(path).map_err(crate::error::io_error(path))?;
    Ok(Sha256::digest(&bytes)
        .iter()
        .fold(String::with_capacity(64), |mut hex, b| {
            use std::fmt::Write as _;
            let _ = write!(hex, "{b:02x}");
            hex
        }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use motion::synth::{WalkParams, walking_clip};

    #[test]
    fn the_worst_window_is_the_worst_second() {
        let clip = walking_clip(&WalkParams {
            duration_s: 3.0,
            ..WalkParams::default()
        });
        let mut m = metrics::compare(&clip, &clip).unwrap();
        m.frame_rms_cm = vec![0.1; clip.frames()];
        m.frame_max_cm = vec![0.2; clip.frames()];
        let n = clip.frames();
        m.frame_rms_cm[n - 10] = 5.0;
        let w = worst_window(&m, clip.frame_rate_hz).unwrap();
        assert_eq!(w.frames, window_frames(clip.frame_rate_hz));
        assert!(
            w.start_frame <= n - 10 && n - 10 < w.start_frame + w.frames,
            "{w:?}"
        );
    }

    #[test]
    fn the_window_is_one_second_of_frames() {
        assert_eq!(window_frames(120.0), 120);
        assert_eq!(window_frames(29.97), 30);
        assert_eq!(window_frames(0.0), 1);
        assert_eq!(window_frames(f64::NAN), 1);
    }
}
