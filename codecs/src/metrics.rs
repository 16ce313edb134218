//! Objective error of a decoded clip against its reference, via forward kinematics.
//!
//! - joint position error in cm (FK points × `cm_per_unit`): RMS and max per joint and overall,
//!   and the RMS and max over joints of every frame (the per-frame error curves), from which
//!   [`Metrics::windows`] and [`Metrics::worst_window`] give the error of consecutive windows
//!   of frames, and [`Metrics::worst_stretch`] the worst stretch starting at any frame (RMS over
//!   a whole clip hides a broken stretch: a codec's short last window);
//! - mean angle error in degrees: for every joint with rotation channels and every frame, the
//!   angle of the rotation between the reference's and the decoded local rotation (geodesic,
//!   0-180°), averaged. Comparing the Euler channels one by one would count a pose written
//!   with another, equivalent triplet (a codec that works on quaternions may decode
//!   `(x+180, 180−y, z+180)` for `(x, y, z)`) as a large error although nothing moved;
//! - foot sliding: on the reference, a foot (the deepest point of each leg chain) is in contact
//!   in frames where it is within [`CONTACT_HEIGHT_CM`] of its lowest height (y up); the
//!   metric is the difference (decoded − reference) of the mean horizontal foot speed over
//!   those frames, in cm/s. Positive means the decoded clip slides more.

use motion::clip::{BodyPart, Clip};
use motion::fk;
use motion::math::Vec3;

/// A foot within this height of its lowest point counts as in contact.
pub const CONTACT_HEIGHT_CM: f64 = 4.0;

/// Error metrics of a decoded clip.
#[derive(Debug, Clone, PartialEq)]
pub struct Metrics {
    /// Joint position RMS over all joints and frames, cm.
    pub rms_cm: f64,
    /// Largest joint position error, cm.
    pub max_cm: f64,
    /// Mean geodesic angle between reference and decoded local joint rotations over joints
    /// with rotation channels and frames, degrees.
    pub mean_angle_deg: f64,
    /// Foot-sliding difference (decoded − reference mean contact speed), cm/s; `None` when the
    /// skeleton has no leg chains.
    pub foot_slide_cm_s: Option<f64>,
    /// Joint names, in FK point order.
    pub joint_names: Vec<String>,
    /// RMS error per joint, cm.
    pub joint_rms_cm: Vec<f64>,
    /// Max error per joint, cm.
    pub joint_max_cm: Vec<f64>,
    /// RMS error over joints of each frame, cm.
    pub frame_rms_cm: Vec<f64>,
    /// Largest joint error of each frame, cm.
    pub frame_max_cm: Vec<f64>,
}

/// The joint position error of one window of consecutive frames ([`Metrics::windows`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WindowError {
    /// First frame of the window (0-based).
    pub start_frame: usize,
    /// Frames in the window: the window length asked for, fewer in the clip's last window.
    pub frames: usize,
    /// Joint position RMS over all joints and the window's frames, cm.
    pub rms_cm: f64,
    /// Largest joint position error in the window, cm.
    pub max_cm: f64,
}

impl Metrics {
    /// The error of every window of `window_frames` consecutive frames, in order: windows
    /// start at frames 0, `window_frames`, `2·window_frames`, ..., and the last holds what is
    /// left of the clip, so it is shorter when the clip's length is not a multiple of
    /// `window_frames`. That short window is measured on its own, not merged into the one
    /// before: a windowed codec's short last slice (issue 20) shows there, and would be
    /// diluted otherwise. Empty when `window_frames` is 0 or the clip has no frames. Costs
    /// O(frames).
    pub fn windows(&self, window_frames: usize) -> impl Iterator<Item = WindowError> + '_ {
        let frames = self.frame_rms_cm.len();
        let starts = if window_frames == 0 {
            0
        } else {
            frames.div_ceil(window_frames)
        };
        (0..starts).map(move |k| {
            let start_frame = k * window_frames;
            let end = (start_frame + window_frames).min(frames);
            let sq: f64 = self.frame_rms_cm[start_frame..end]
                .iter()
                .map(|v| v * v)
                .sum();
            let max_cm = self.frame_max_cm[start_frame..end]
                .iter()
                .copied()
                .fold(0.0, f64::max);
            WindowError {
                start_frame,
                frames: end - start_frame,
                rms_cm: (sq / (end - start_frame) as f64).sqrt(),
                max_cm,
            }
        })
    }

    /// The window of [`Metrics::windows`] with the largest RMS (the first of equals), `None`
    /// when there is none (`window_frames` 0, or no frames). For a codec with windows of `W`
    /// frames, `worst_window(W)` is its worst window; for what a viewer sees, a second of
    /// frames (`frame_rate_hz` rounded) is a natural length.
    ///
    /// ```
    /// use codecs::metrics::compare;
    /// use motion::synth::{WalkParams, walking_clip};
    ///
    /// let clip = walking_clip(&WalkParams { duration_s: 1.0, ..WalkParams::default() });
    /// let mut decoded = clip.clone();
    /// // Move the root 1 unit along its first translation channel in the last 10 frames.
    /// let tx = clip.channels().iter().position(|c| !c.kind.is_rotation()).unwrap();
    /// let n = clip.frames();
    /// for v in &mut decoded.channel_mut(tx)[n - 10..] {
    ///     *v += 1.0;
    /// }
    /// let m = compare(&clip, &decoded).unwrap();
    /// let worst = m.worst_window(32).unwrap();
    /// assert_eq!(worst.start_frame + worst.frames, n);
    /// assert!(worst.rms_cm > m.rms_cm);
    /// ```
    pub fn worst_window(&self, window_frames: usize) -> Option<WindowError> {
        self.windows(window_frames)
            .fold(None, |worst: Option<WindowError>, w| match worst {
                Some(b) if b.rms_cm >= w.rms_cm => Some(b),
                _ => Some(w),
            })
    }

    /// The worst stretch of `window_frames` consecutive frames starting at any frame (a
    /// sliding window, so that it does not depend on where a codec's own windows fall): the
    /// one whose RMS `sqrt(mean over its frames of frame_rms_cm²)` is largest (the earliest on
    /// a tie), with its largest joint error. A clip shorter than the window is one window;
    /// `None` when there are no frames or `window_frames` is 0. This is what a viewer sees at
    /// its worst: the sweep, `rd.csv`, `stimuli.json` and `study encode` report it for a
    /// second of frames.
    pub fn worst_stretch(&self, window_frames: usize) -> Option<WindowError> {
        let sq: Vec<f64> = self.frame_rms_cm.iter().map(|r| r * r).collect();
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
        let max_cm = self
            .frame_max_cm
            .get(start..start + w)
            .map_or(0.0, |m| m.iter().copied().fold(0.0, f64::max));
        Some(WindowError {
            start_frame: start,
            frames: w,
            rms_cm: (sum / w as f64).sqrt(),
            max_cm,
        })
    }
}

/// Why two clips cannot be compared.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum MetricsError {
    /// The clips differ in skeleton or shape.
    #[error("clips differ: {0}")]
    Mismatch(String),
}

/// Compares `decoded` with `reference`.
///
/// # Errors
/// [`MetricsError::Mismatch`] when the skeletons or shapes differ.
pub fn compare(reference: &Clip, decoded: &Clip) -> Result<Metrics, MetricsError> {
    if reference.frames() != decoded.frames()
        || reference.channel_count() != decoded.channel_count()
    {
        return Err(MetricsError::Mismatch(format!(
            "{}×{} vs {}×{}",
            reference.channel_count(),
            reference.frames(),
            decoded.channel_count(),
            decoded.frames()
        )));
    }
    if reference.skeleton.fingerprint() != decoded.skeleton.fingerprint() {
        return Err(MetricsError::Mismatch(
            "skeleton fingerprints differ".into(),
        ));
    }
    // Forward kinematics of both clips in one pass: the local rotations it computes on the
    // way also give the angle error.
    let (a, b, mean_angle_deg) = kinematics(reference, decoded);
    let cm = reference.skeleton.units.cm_per_unit;
    let (frames, joints) = (a.frames(), a.joint_count());
    let mut joint_sq = vec![0.0; joints];
    let mut joint_max = vec![0.0f64; joints];
    let mut frame_rms = Vec::with_capacity(frames);
    let mut frame_max = Vec::with_capacity(frames);
    let mut total_sq = 0.0;
    for f in 0..frames {
        let mut fs = 0.0;
        let mut fm = 0.0f64;
        for j in 0..joints {
            let (p, q) = (a.point(f, j), b.point(f, j));
            let d2 =
                ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)) * cm * cm;
            joint_sq[j] += d2;
            joint_max[j] = joint_max[j].max(d2.sqrt());
            fm = fm.max(d2);
            fs += d2;
        }
        frame_max.push(fm.sqrt());
        total_sq += fs;
        frame_rms.push(if joints > 0 {
            (fs / joints as f64).sqrt()
        } else {
            0.0
        });
    }
    let nf = frames.max(1) as f64;
    let joint_rms: Vec<f64> = joint_sq.iter().map(|s| (s / nf).sqrt()).collect();
    let rms_cm = (total_sq / (nf * joints.max(1) as f64)).sqrt();
    let max_cm = joint_max.iter().copied().fold(0.0, f64::max);

    let feet: Vec<usize> = [BodyPart::LeftLeg, BodyPart::RightLeg]
        .iter()
        .filter_map(|&part| {
            let sk = &reference.skeleton;
            (0..sk.joints.len())
                .filter(|&j| sk.joints[j].body_part == part)
                .max_by_key(|&j| sk.joints[j].chain_depth)
        })
        .collect();
    let foot_slide_cm_s = if feet.is_empty() || frames < 2 {
        None
    } else {
        let rate = reference.frame_rate_hz;
        let (mut ra, mut rb, mut n) = (0.0, 0.0, 0usize);
        for &j in &feet {
            let low = (0..frames)
                .map(|f| a.point(f, j)[1])
                .fold(f64::INFINITY, f64::min);
            for f in 1..frames {
                if (a.point(f, j)[1] - low) * cm <= CONTACT_HEIGHT_CM {
                    let speed = |p: &Points| {
                        let (u, v) = (p.point(f, j), p.point(f - 1, j));
                        ((u[0] - v[0]).powi(2) + (u[2] - v[2]).powi(2)).sqrt() * cm * rate
                    };
                    ra += speed(&a);
                    rb += speed(&b);
                    n += 1;
                }
            }
        }
        (n > 0).then(|| (rb - ra) / n as f64)
    };
    Ok(Metrics {
        rms_cm,
        max_cm,
        mean_angle_deg,
        foot_slide_cm_s,
        joint_names: reference
            .skeleton
            .joints
            .iter()
            .map(|j| j.name.clone())
            .collect(),
        joint_rms_cm: joint_rms,
        joint_max_cm: joint_max,
        frame_rms_cm: frame_rms,
        frame_max_cm: frame_max,
    })
}

/// World points of every joint of one clip, frame-major, in file units (what
/// [`fk::positions`] computes, filled by [`kinematics`]).
struct Points {
    frames: usize,
    joints: usize,
    xyz: Vec<Vec3>,
}

impl Points {
    fn frames(&self) -> usize {
        self.frames
    }

    fn joint_count(&self) -> usize {
        self.joints
    }

    fn point(&self, frame: usize, joint: usize) -> Vec3 {
        self.xyz[frame * self.joints + joint]
    }
}

/// Clips from this many frames on are measured on two threads, each taking half the frames.
/// The split depends on the frame count alone, so the sums (and the metrics) are the same on
/// any machine.
const TWO_THREADS_FROM_FRAMES: usize = 512;

/// The world points of both clips and the mean, over joints with rotation channels and
/// frames, of the angle between their local rotations in degrees.
///
/// One FK pass per clip and frame: the local transforms it computes for the points give the
/// angles too (computing them apart was half of `compare`, itself a quarter of `study
/// encode`).
fn kinematics(reference: &Clip, decoded: &Clip) -> (Points, Points, f64) {
    let sk = &reference.skeleton;
    let kin = fk::Kinematics::new(sk);
    let rotating: Vec<usize> = (0..sk.joints.len())
        .filter(|&j| sk.joints[j].dofs.iter().any(|d| d.is_rotation()))
        .collect();
    let frames = reference.frames();
    let n = kin.joint_count();
    // Both clips' points, filled in place (half each by two threads for a long clip).
    let mut a = vec![[0.0; 3]; n * frames];
    let mut b = vec![[0.0; 3]; n * frames];
    let part = |from: usize, pa: &mut [Vec3], pb: &mut [Vec3]| {
        fk_frames(&kin, &rotating, reference, decoded, from, pa, pb)
    };
    let sum = if frames >= TWO_THREADS_FROM_FRAMES {
        let mid = frames / 2;
        let (a0, a1) = a.split_at_mut(mid * n);
        let (b0, b1) = b.split_at_mut(mid * n);
        let (early, late) = std::thread::scope(|s| {
            let late = s.spawn(|| part(mid, &mut *a1, &mut *b1));
            (part(0, a0, b0), late.join())
        });
        // A panic in FK would be a bug; the second half is then measured here.
        early + late.unwrap_or_else(|_| part(mid, a1, b1))
    } else {
        part(0, &mut a, &mut b)
    };
    let joints = n;
    let mean = if rotating.is_empty() || frames == 0 {
        0.0
    } else {
        (sum / (frames * rotating.len()) as f64).to_degrees()
    };
    (
        Points {
            frames,
            joints,
            xyz: a,
        },
        Points {
            frames,
            joints,
            xyz: b,
        },
        mean,
    )
}

/// [`kinematics`] over the frames from `from` on that `pa` and `pb` hold (one point per
/// joint and frame): both clips' points, and the summed angle (radians).
fn fk_frames(
    kin: &fk::Kinematics,
    rotating: &[usize],
    reference: &Clip,
    decoded: &Clip,
    from: usize,
    pa: &mut [Vec3],
    pb: &mut [Vec3],
) -> f64 {
    let n = kin.joint_count().max(1);
    let (mut va, mut vb) = (Vec::new(), Vec::new());
    let (mut la, mut lb) = (Vec::new(), Vec::new());
    let (mut frame, mut rotations) = (Vec::with_capacity(n), Vec::with_capacity(n));
    let mut sum = 0.0;
    for (f, (qa, qb)) in (from..).zip(pa.chunks_exact_mut(n).zip(pb.chunks_exact_mut(n))) {
        reference.frame_into(f, &mut va);
        decoded.frame_into(f, &mut vb);
        kin.local_transforms(&va, &mut la);
        kin.local_transforms(&vb, &mut lb);
        kin.world(&la, &mut frame, &mut rotations);
        qa.copy_from_slice(&frame);
        kin.world(&lb, &mut frame, &mut rotations);
        qb.copy_from_slice(&frame);
        for &j in rotating {
            sum += angle_between(&la[j].rotation, &lb[j].rotation);
        }
    }
    sum
}

/// The angle (radians, 0..=π) of the rotation `aᵀ·b`, from its cosine (trace) and sine (skew
/// part) together, which stays accurate near 0 and π where `acos` alone does not.
fn angle_between(a: &motion::math::Mat3, b: &motion::math::Mat3) -> f64 {
    let r = motion::math::mul(&motion::math::transpose(a), b);
    let cos = (r[0][0] + r[1][1] + r[2][2] - 1.0) / 2.0;
    let sin =
        ((r[2][1] - r[1][2]).powi(2) + (r[0][2] - r[2][0]).powi(2) + (r[1][0] - r[0][1]).powi(2))
            .sqrt()
            / 2.0;
    sin.atan2(cos)
}

#[cfg(test)]
mod tests {
    use super::*;
    use motion::synth::{WalkParams, walking_clip};

    #[test]
    fn identical_clips_have_zero_error() {
        let clip = walking_clip(&WalkParams {
            duration_s: 1.0,
            ..WalkParams::default()
        });
        let m = compare(&clip, &clip).unwrap();
        assert!(m.rms_cm.abs() < 1e-12 && m.max_cm.abs() < 1e-12 && m.mean_angle_deg.abs() < 1e-12);
        assert!(m.foot_slide_cm_s.unwrap().abs() < 1e-12);
        assert_eq!(m.frame_rms_cm.len(), clip.frames());
    }

    /// Metrics of a clip against itself, with the per-frame curves replaced by `frame_rms`
    /// (and a max of twice it).
    fn with_curve(frame_rms: Vec<f64>) -> Metrics {
        let clip = walking_clip(&WalkParams {
            duration_s: 0.1,
            ..WalkParams::default()
        });
        let mut m = compare(&clip, &clip).unwrap();
        m.frame_max_cm = frame_rms.iter().map(|v| 2.0 * v).collect();
        m.frame_rms_cm = frame_rms;
        m
    }

    #[test]
    fn the_worst_stretch_is_the_rms_of_the_worst_consecutive_frames() {
        // A 2-frame window over 1, 1, 3, 4, 1: frames 2-3, sqrt((9 + 16) / 2).
        let m = with_curve(vec![1.0, 1.0, 3.0, 4.0, 1.0]);
        let w = m.worst_stretch(2).unwrap();
        assert_eq!((w.start_frame, w.frames), (2, 2));
        assert!((w.rms_cm - 12.5f64.sqrt()).abs() < 1e-12, "{}", w.rms_cm);
        assert!((w.max_cm - 8.0).abs() < 1e-12, "{}", w.max_cm);
        // A flat curve: the earliest window, at the curve's value.
        let w = with_curve(vec![0.5; 300]).worst_stretch(120).unwrap();
        assert_eq!((w.start_frame, w.frames), (0, 120));
        assert!((w.rms_cm - 0.5).abs() < 1e-12);
        // A broken tail shows although the clip's RMS hides it.
        let mut curve = vec![0.1; 1558];
        for v in &mut curve[1536..] {
            *v = 4.2;
        }
        let w = with_curve(curve).worst_stretch(120).unwrap();
        assert_eq!(w.start_frame, 1558 - 120);
        assert!(w.rms_cm > 1.5, "{}", w.rms_cm);
        // Shorter than the window: the whole clip; no frames: none.
        let w = with_curve(vec![3.0, 4.0]).worst_stretch(120).unwrap();
        assert_eq!((w.start_frame, w.frames), (0, 2));
        assert!((w.rms_cm - 12.5f64.sqrt()).abs() < 1e-12);
        assert_eq!(with_curve(Vec::new()).worst_stretch(120), None);
        assert_eq!(with_curve(vec![1.0]).worst_stretch(0), None);
    }

    /// Windows tile the clip from frame 0, the last one shorter; their RMS and max agree with
    /// the per-frame curves, and together they give the clip's RMS and max.
    #[test]
    fn windows_tile_the_clip_and_the_worst_is_the_broken_one() {
        let clip = walking_clip(&WalkParams {
            duration_s: 1.0,
            ..WalkParams::default()
        });
        let n = clip.frames();
        let mut decoded = clip.clone();
        for c in 0..clip.channel_count() {
            for (f, v) in decoded.channel_mut(c).iter_mut().enumerate() {
                *v += 0.01 * ((f * 7 + c) % 5) as f64;
            }
        }
        let rx = clip
            .channels()
            .iter()
            .position(|c| c.kind.is_rotation())
            .unwrap();
        for v in &mut decoded.channel_mut(rx)[n - 3..] {
            *v += 20.0;
        }
        let m = compare(&clip, &decoded).unwrap();
        assert_eq!(m.frame_max_cm.len(), n);
        let w = 16;
        let all: Vec<WindowError> = m.windows(w).collect();
        assert_eq!(all.len(), n.div_ceil(w));
        assert_eq!(all.iter().map(|x| x.frames).sum::<usize>(), n);
        assert_eq!(
            all.last().unwrap().frames,
            if n.is_multiple_of(w) { w } else { n % w }
        );
        let sq: f64 = all
            .iter()
            .map(|x| x.rms_cm * x.rms_cm * x.frames as f64)
            .sum();
        assert!(((sq / n as f64).sqrt() - m.rms_cm).abs() < 1e-9);
        let max = all.iter().map(|x| x.max_cm).fold(0.0, f64::max);
        assert!((max - m.max_cm).abs() < 1e-12);
        let worst = m.worst_window(w).unwrap();
        assert_eq!(worst, *all.last().unwrap());
        assert!(worst.rms_cm > 2.0 * m.rms_cm, "{worst:?} vs {}", m.rms_cm);
        // One window holding the whole clip is the clip.
        let whole = m.worst_window(n + 5).unwrap();
        assert_eq!((whole.start_frame, whole.frames), (0, n));
        assert!((whole.rms_cm - m.rms_cm).abs() < 1e-9);
        assert_eq!(m.worst_window(0), None);
    }

    /// Long clips are measured on two threads: the same figures as FK by
    /// `fk::positions` and the angle loop computed apart, frame by frame.
    #[test]
    fn two_thread_pass_measures_what_separate_passes_do() {
        let clip = walking_clip(&WalkParams {
            duration_s: 8.0,
            ..WalkParams::default()
        });
        assert!(clip.frames() >= TWO_THREADS_FROM_FRAMES);
        let mut bent = clip.clone();
        for c in 0..clip.channel_count() {
            for (f, v) in bent.channel_mut(c).iter_mut().enumerate() {
                *v += 0.3 * ((f * (c + 1)) as f64 * 0.01).sin();
            }
        }
        let m = compare(&clip, &bent).unwrap();
        let (a, b) = (fk::positions(&clip), fk::positions(&bent));
        let cm = clip.skeleton.units.cm_per_unit;
        let (mut sq, mut max) = (0.0, 0.0f64);
        for f in 0..a.frames() {
            for j in 0..a.joint_count() {
                let (p, q) = (a.point(f, j), b.point(f, j));
                let d2 = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2))
                    * cm
                    * cm;
                sq += d2;
                max = max.max(d2.sqrt());
            }
        }
        let rms = (sq / (a.frames() * a.joint_count()) as f64).sqrt();
        let sk = &clip.skeleton;
        let kin = fk::Kinematics::new(sk);
        let rotating: Vec<usize> = (0..sk.joints.len())
            .filter(|&j| sk.joints[j].dofs.iter().any(|d| d.is_rotation()))
            .collect();
        let (mut va, mut vb, mut la, mut lb) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
        let mut angle = 0.0;
        for f in 0..clip.frames() {
            clip.frame_into(f, &mut va);
            bent.frame_into(f, &mut vb);
            kin.local_transforms(&va, &mut la);
            kin.local_transforms(&vb, &mut lb);
            for &j in &rotating {
                angle += angle_between(&la[j].rotation, &lb[j].rotation);
            }
        }
        let angle = (angle / (clip.frames() * rotating.len()) as f64).to_degrees();
        assert!(m.rms_cm > 0.1, "{}", m.rms_cm);
        assert!(
            (m.rms_cm - rms).abs() < 1e-12 * rms,
            "{} vs {rms}",
            m.rms_cm
        );
        assert_eq!(m.max_cm.to_bits(), max.to_bits());
        assert!((m.mean_angle_deg - angle).abs() < 1e-12 * angle);
        assert_eq!(m.joint_names, a.names);
        assert_eq!(m.frame_rms_cm.len(), clip.frames());
    }

    #[test]
    fn root_offset_is_measured_in_cm() {
        let clip = walking_clip(&WalkParams {
            duration_s: 1.0,
            ..WalkParams::default()
        });
        let mut moved = clip.clone();
        let tx = clip
            .channels()
            .iter()
            .position(|c| !c.kind.is_rotation())
            .unwrap();
        for v in moved.channel_mut(tx) {
            *v += 1.0;
        }
        let m = compare(&clip, &moved).unwrap();
        let cm = clip.skeleton.units.cm_per_unit;
        assert!(
            (m.rms_cm - cm).abs() < 1e-9 && (m.max_cm - cm).abs() < 1e-9,
            "{m:?}"
        );
        assert!(m.mean_angle_deg.abs() < 1e-12);
        // 360° apart is no angle error.
        let mut turned = clip.clone();
        let rx = clip
            .channels()
            .iter()
            .position(|c| c.kind.is_rotation())
            .unwrap();
        for v in turned.channel_mut(rx) {
            *v += 360.0;
        }
        assert!(compare(&clip, &turned).unwrap().mean_angle_deg < 1e-9);
    }

    /// The same pose written with the other Euler triplet is no angle error; a real turn of
    /// one joint is measured by its size, spread over the rotating joints.
    #[test]
    fn equivalent_euler_triplets_are_no_angle_error() {
        let clip = walking_clip(&WalkParams {
            duration_s: 1.0,
            ..WalkParams::default()
        });
        let sk = &clip.skeleton;
        let j = (0..sk.joints.len())
            .find(|&j| {
                sk.joints[j].parent.is_some()
                    && sk.joints[j].dofs.iter().filter(|d| d.is_rotation()).count() == 3
            })
            .unwrap();
        let first = sk.joints[..j].iter().map(|jt| jt.dofs.len()).sum::<usize>();
        let mut flipped = clip.clone();
        // Fixed-axis X, Y, Z (any order of three distinct axes): (a, b, c) and
        // (a + 180, 180 − b, c + 180) are the same rotation.
        for f in 0..clip.frames() {
            let (a, b, c) = (
                clip.value(first, f),
                clip.value(first + 1, f),
                clip.value(first + 2, f),
            );
            flipped.channel_mut(first)[f] = a + 180.0;
            flipped.channel_mut(first + 1)[f] = 180.0 - b;
            flipped.channel_mut(first + 2)[f] = c + 180.0;
        }
        let m = compare(&clip, &flipped).unwrap();
        assert!(m.rms_cm < 1e-9, "{}", m.rms_cm);
        assert!(m.mean_angle_deg < 1e-9, "{}", m.mean_angle_deg);
        // 10° more about the joint's first channel axis: a 10° rotation at one joint.
        let mut bent = clip.clone();
        for v in bent.channel_mut(first) {
            *v += 10.0;
        }
        let rotating = sk
            .joints
            .iter()
            .filter(|jt| jt.dofs.iter().any(|d| d.is_rotation()))
            .count();
        let m = compare(&clip, &bent).unwrap();
        assert!(
            (m.mean_angle_deg - 10.0 / rotating as f64).abs() < 1e-9,
            "{} vs {}",
            m.mean_angle_deg,
            10.0 / rotating as f64
        );
    }
}
