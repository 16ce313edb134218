//! Segmentation of a joint's quaternion track (thesis ch. 5.3.2).
//!
//! Angular velocity `ω(i) = 2·log(q(i−1)⁻¹·q(i))` (eq. 5.1) and acceleration
//! `α(i) = (ω(i) − ω(i−1))/h` (eq. 5.2) are vectors; the text chops at "zero-crossings of the
//! angular acceleration", which for a vector we read as sign changes of the acceleration's
//! component along the velocity, `α(i)·ω̂(i)`, i.e. the frames where the angular speed stops
//! rising or falling (the motion beats of KPS03). A segment ends at the first such crossing
//! at least `min_frames` (15) after its start, or after `max_frames` (`S_M`) frames if none
//! comes; the rest of the clip forms the last, possibly shorter, segment.
//!
//! [`segment_body`] cuts the whole body at once (thesis ch. 4, whose primitives are whole-body
//! moves) by the same rule on one signal: the sum over joints of each joint's tangential
//! acceleration weighted by the length its rotation swings, i.e. the rate of change of
//! `Σ_j l_j·|ω_j|`, a proxy for how fast the bones' ends move (ch. 4.4 proposes weighting
//! joints by bone length so that fingers count less than legs). It cuts only where that
//! speed passes a minimum (the acceleration crosses zero from below): ch. 4 follows SI08, whose
//! key poses are where "dancers clearly stop their movements", and the decoder blends the
//! joins, which shows least where the body moves least.

use std::ops::Range;

use motion::quat::Quat;

/// Frames of a normalized segment (a power of two, for the 4-level wavelet of ch. 5.3.4).
pub const NORMALIZED_FRAMES: usize = 16;

/// Segmentation parameters.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct SegmentParams {
    /// Shortest segment in frames (15 in the thesis).
    pub min_frames: usize,
    /// Longest segment in frames, `S_M` of Table 5.4 (16, 32 or 64).
    pub max_frames: usize,
}

impl Default for SegmentParams {
    fn default() -> Self {
        SegmentParams {
            min_frames: 15,
            max_frames: 32,
        }
    }
}

/// One segment of a track: its frame range and its 16-frame normalized form.
#[derive(Debug, Clone, PartialEq)]
pub struct Segment {
    /// First frame (inclusive).
    pub start: usize,
    /// One past the last frame.
    pub end: usize,
    /// The segment resampled to [`NORMALIZED_FRAMES`] frames by SLERP, first and last frames
    /// kept exactly.
    pub normalized: [Quat; NORMALIZED_FRAMES],
}

impl Segment {
    /// Number of source frames.
    pub fn len(&self) -> usize {
        self.end - self.start
    }

    /// True if the segment has no frames (never produced by [`segment_track`]).
    pub fn is_empty(&self) -> bool {
        self.end == self.start
    }
}

/// Samples `track` (len ≥ 1) at fractional frame `x` by SLERP between neighbours.
pub fn sample(track: &[Quat], x: f64) -> Quat {
    let last = track.len() - 1;
    let x = x.clamp(0.0, last as f64);
    let i = (x.floor() as usize).min(last);
    if i == last {
        return track[last];
    }
    track[i].slerp(track[i + 1], x - i as f64)
}

/// Resamples frames `[start, end)` of a track to [`NORMALIZED_FRAMES`] frames.
pub fn normalize(track: &[Quat]) -> [Quat; NORMALIZED_FRAMES] {
    let mut out = [Quat::IDENTITY; NORMALIZED_FRAMES];
    let span = (track.len().max(1) - 1) as f64;
    for (n, o) in out.iter_mut().enumerate() {
        *o = sample(track, n as f64 * span / (NORMALIZED_FRAMES - 1) as f64);
    }
    out
}

/// Resamples a normalized segment back to `len` frames (the decoder's inverse of
/// [`normalize`]).
pub fn denormalize(seg: &[Quat; NORMALIZED_FRAMES], len: usize, out: &mut Vec<Quat>) {
    out.clear();
    if len == 1 {
        out.push(seg[0]);
        return;
    }
    let scale = (NORMALIZED_FRAMES - 1) as f64 / (len - 1) as f64;
    out.extend((0..len).map(|m| sample(seg, m as f64 * scale)));
}

/// The signed angular acceleration along the velocity at each frame (0 where undefined).
fn tangential_acceleration(track: &[Quat], dt_s: f64) -> Vec<f64> {
    let n = track.len();
    let mut omega = vec![[0.0; 3]; n];
    for i in 1..n {
        let l = (track[i - 1].conj() * track[i]).log();
        omega[i] = [2.0 * l[0] / dt_s, 2.0 * l[1] / dt_s, 2.0 * l[2] / dt_s];
    }
    let mut acc = vec![0.0; n];
    for i in 2..n {
        let a = [
            (omega[i][0] - omega[i - 1][0]) / dt_s,
            (omega[i][1] - omega[i - 1][1]) / dt_s,
            (omega[i][2] - omega[i - 1][2]) / dt_s,
        ];
        let w = omega[i];
        let speed = (w[0] * w[0] + w[1] * w[1] + w[2] * w[2]).sqrt();
        acc[i] = if speed > 1e-12 {
            (a[0] * w[0] + a[1] * w[1] + a[2] * w[2]) / speed
        } else {
            0.0
        };
    }
    acc
}

/// Which zero crossings of the acceleration may end a segment.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Crossing {
    /// Either sign change: a speed maximum or minimum (ch. 5).
    Any,
    /// From negative to positive only: a speed minimum (ch. 4's key poses).
    Rising,
}

/// The frame step in seconds of a clip at `frame_rate_hz` (1 for a rate that is not positive).
fn frame_step(frame_rate_hz: f64) -> f64 {
    if frame_rate_hz > 0.0 {
        1.0 / frame_rate_hz
    } else {
        1.0
    }
}

/// Cuts `0..acc.len()` into segments of `params.min_frames..=params.max_frames` frames (the
/// last one possibly shorter), each ending at the first `crossing` of `acc` that is at least
/// `min_frames` after its start.
fn chop(acc: &[f64], params: SegmentParams, crossing: Crossing) -> Vec<Range<usize>> {
    let n = acc.len();
    let min = params.min_frames.max(1);
    let max = params.max_frames.max(min);
    let mut out = Vec::with_capacity(n / min + 1);
    let mut start = 0;
    while start < n {
        let mut end = (start + max).min(n);
        for i in (start + min)..end {
            let cut = match crossing {
                Crossing::Any => acc[i - 1] * acc[i] < 0.0,
                Crossing::Rising => acc[i - 1] < 0.0 && acc[i] > 0.0,
            };
            if cut {
                end = i;
                break;
            }
        }
        out.push(start..end);
        start = end;
    }
    out
}

/// Splits a joint's track into segments (see the module docs).
pub fn segment_track(track: &[Quat], frame_rate_hz: f64, params: SegmentParams) -> Vec<Segment> {
    let acc = tangential_acceleration(track, frame_step(frame_rate_hz));
    chop(&acc, params, Crossing::Any)
        .into_iter()
        .map(|r| Segment {
            start: r.start,
            end: r.end,
            normalized: normalize(&track[r]),
        })
        .collect()
}

/// Splits a whole body into segments (thesis ch. 4, see the module docs): `tracks[k]` is the
/// `k`-th rotating joint's track (`frames` long), `weights[k]` the length its rotation swings.
/// Returns the segments' frame ranges, which tile `0..frames`.
pub fn segment_body(
    tracks: &[Vec<Quat>],
    weights: &[f64],
    frames: usize,
    frame_rate_hz: f64,
    params: SegmentParams,
) -> Vec<Range<usize>> {
    let n = frames;
    let dt = frame_step(frame_rate_hz);
    let mut acc = vec![0.0; n];
    for (track, &w) in tracks.iter().zip(weights) {
        let track = &track[..n.min(track.len())];
        for (a, t) in acc.iter_mut().zip(tangential_acceleration(track, dt)) {
            *a += w * t;
        }
    }
    chop(&acc, params, Crossing::Rising)
}

#[cfg(test)]
mod tests {
    use super::*;
    use motion::clip::Axis;

    fn swing(n: usize) -> Vec<Quat> {
        (0..n)
            .map(|i| Quat::from_axis(Axis::X, 40.0 * (i as f64 * 0.08).sin()))
            .collect()
    }

    #[test]
    fn segments_cover_the_track_and_respect_their_bounds() {
        let track = swing(500);
        for max in [16, 32, 64] {
            let p = SegmentParams {
                min_frames: 15,
                max_frames: max,
            };
            let segs = segment_track(&track, 120.0, p);
            assert_eq!(segs[0].start, 0);
            assert_eq!(segs.last().map(|s| s.end), Some(500));
            for w in segs.windows(2) {
                assert_eq!(w[0].end, w[1].start);
            }
            for s in &segs[..segs.len() - 1] {
                assert!(
                    s.len() >= 15 && s.len() <= max,
                    "{} frames with S_M {max}",
                    s.len()
                );
            }
        }
    }

    #[test]
    fn chops_fall_on_beats_of_a_periodic_swing() {
        // A sine swing: speed extrema every half period (39.3 frames), so with S_M = 64
        // segments end on beats, not on the S_M cap.
        let track = swing(400);
        let segs = segment_track(
            &track,
            120.0,
            SegmentParams {
                min_frames: 15,
                max_frames: 64,
            },
        );
        let lens: Vec<usize> = segs.iter().map(Segment::len).collect();
        assert!(lens[1..lens.len() - 1].iter().all(|&l| l < 64), "{lens:?}");
    }

    #[test]
    fn normalize_keeps_endpoints_and_denormalize_inverts_a_linear_motion() {
        let track: Vec<Quat> = (0..30)
            .map(|i| Quat::from_axis(Axis::Y, i as f64))
            .collect();
        let n = normalize(&track);
        assert!(n[0].distance(track[0]) < 1e-12);
        assert!(n[15].distance(track[29]) < 1e-7);
        let mut back = Vec::new();
        denormalize(&n, 30, &mut back);
        for (a, b) in back.iter().zip(&track) {
            assert!(a.distance(*b) < 1e-7);
        }
        denormalize(&n, 1, &mut back);
        assert_eq!(back.len(), 1);
    }
}
