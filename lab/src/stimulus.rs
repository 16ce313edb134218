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
    /// The worst 1-s window of the error ([`worst_window`] over [`window_frames`] of the
    /// clip's rate); `None` for a clip without frames.
    pub worst_window: Option<WorstWindow>,
}

/// The stretch of a clip where the decoded motion is worst: the window of frames with the
/// largest joint position RMS error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WorstWindow {
    /// First frame of the window (0-based).
    pub start_frame: usize,
    /// Frames in it (the window asked for, or the whole clip when it is shorter).
    pub frames: usize,
    /// Joint position RMS error over the window's joints and frames, cm.
    pub rms_cm: f64,
}

impl WorstWindow {
    /// The window's start in seconds at `frame_rate_hz`.
    pub fn start_s(&self, frame_rate_hz: f64) -> f64 {
        self.start_frame as f64 / frame_rate_hz
    }
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

/// The worst window of `window_frames` consecutive frames of `metrics`: over every start
/// frame (a sliding window, so that it does not depend on where a codec's own windows fall),
/// the one whose RMS error `sqrt(mean over its frames of frame_rms_cm²)` is largest (the
/// earliest on a tie); a clip shorter than the window is one window. `frame_rms_cm` is the
/// RMS over joints of each frame, so the window's value is the RMS over its joints and
/// frames. `None` when there are no frames (or `window_frames` is 0).
///
/// This is the one place the sweep, `rd.csv`, `stimuli.json` and `study encode` take the
/// worst window from (the codecs crate's own helper can replace its body).
pub fn worst_window(metrics: &Metrics, window_frames: usize) -> Option<WorstWindow> {
    let sq: Vec<f64> = metrics.frame_rms_cm.iter().map(|r| r * r).collect();
    if sq.is_empty() || window_frames == 0 {
        return None;
    }
    let w = window_frames.min(sq.len());
    // Each window's sum is taken afresh (O(frames × window), 1.5 M additions for a 100-s
    // clip at 120 Hz): a running sum would carry its rounding from one window to the next.
    let (start, sum) = (0..=sq.len() - w)
        .map(|i| (i, sq[i..i + w].iter().sum::<f64>()))
        .fold((0, f64::NEG_INFINITY), |best, (i, s)| {
            if s > best.1 { (i, s) } else { best }
        });
    Some(WorstWindow {
        start_frame: start,
        frames: w,
        rms_cm: (sum / w as f64).sqrt(),
    })
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
    let worst_window = worst_window(&metrics, window_frames(clip.frame_rate_hz));
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

#[cfg(test)]
mod tests {
    use super::*;
    use motion::synth::{WalkParams, walking_clip};

    /// Metrics of a clip against itself, with the per-frame curve replaced by `frame_rms`.
    fn with_curve(frame_rms: Vec<f64>) -> Metrics {
        let clip = walking_clip(&WalkParams {
            duration_s: 0.1,
            ..WalkParams::default()
        });
        let mut m = metrics::compare(&clip, &clip).unwrap();
        m.frame_rms_cm = frame_rms;
        m
    }

    #[test]
    fn the_worst_window_is_the_rms_of_the_worst_stretch() {
        // A 2-frame window over 1, 1, 3, 4, 1: frames 2-3, sqrt((9 + 16) / 2).
        let m = with_curve(vec![1.0, 1.0, 3.0, 4.0, 1.0]);
        let w = worst_window(&m, 2).unwrap();
        assert_eq!((w.start_frame, w.frames), (2, 2));
        assert!((w.rms_cm - 12.5f64.sqrt()).abs() < 1e-12, "{}", w.rms_cm);
        // A flat curve: the earliest window, at the curve's value.
        let w = worst_window(&with_curve(vec![0.5; 300]), 120).unwrap();
        assert_eq!((w.start_frame, w.frames), (0, 120));
        assert!((w.rms_cm - 0.5).abs() < 1e-12);
        // A broken tail shows although the clip's RMS hides it.
        let mut curve = vec![0.1; 1558];
        for v in &mut curve[1536..] {
            *v = 4.2;
        }
        let w = worst_window(&with_curve(curve), 120).unwrap();
        assert_eq!(w.start_frame, 1558 - 120);
        assert!(w.rms_cm > 1.5, "{}", w.rms_cm);
        // Shorter than the window: the whole clip; no frames: none.
        let w = worst_window(&with_curve(vec![3.0, 4.0]), 120).unwrap();
        assert_eq!((w.start_frame, w.frames), (0, 2));
        assert!((w.rms_cm - 12.5f64.sqrt()).abs() < 1e-12);
        assert_eq!(worst_window(&with_curve(Vec::new()), 120), None);
        assert_eq!(worst_window(&with_curve(vec![1.0]), 0), None);
    }

    #[test]
    fn the_window_is_one_second_of_frames() {
        assert_eq!(window_frames(120.0), 120);
        assert_eq!(window_frames(29.97), 30);
        assert_eq!(window_frames(0.0), 1);
        assert_eq!(window_frames(f64::NAN), 1);
    }
}
