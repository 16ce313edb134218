//! Synthetic marker captures with ground truth: three markers rigidly offset on every bone of
//! a known clip, moved by its forward kinematics, with Gaussian noise σ and occasional gaps;
//! and range-of-motion (calibration) trials of the same skeleton with the same markers.
//!
//! For an ASF clip a bone's markers sit around the bone (start at its parent's point, world
//! rotation `R_bone`), at 35 %, 60 % and 85 % of its length and `offset_cm` out from its line
//! at 0°, 120° and 240° about it; for a BVH clip the same around the joint's longest child
//! offset. A joint without rotation channels moves rigidly with its parent, so
//! [`segment_map_toml`] merges its markers into the parent's segment. Every segment's true
//! joint centre is an FK point of the clip ([`SynthSegment::truth_point`]).
//!
//! The placement ([`MarkerPlacement`]) is a deterministic function of the skeleton and the
//! offset alone (nothing in it is random), so a motion trial and a range-of-motion trial of
//! one skeleton ([`rom_capture`]) carry exactly the same markers, as one subject wearing one
//! marker set does in a lab. The seed drives only the noise and the gaps; the
//! range-of-motion trial draws them from another stream of the same seed, so the two trials'
//! noise is independent.

use std::fmt::Write as _;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::MarkerError;
use super::data::MarkerSet;
use motion::clip::{Clip, Skeleton, SkeletonFormat};
use motion::fk::Kinematics;
use motion::math::{Vec3, add, mul_vec};

/// Options of a synthetic capture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct SynthOptions {
    /// Standard deviation of the Gaussian noise on each coordinate, mm.
    pub noise_mm: f64,
    /// Probability that a sample is missing.
    pub gap_probability: f64,
    /// Distance of the markers from the bone line, cm.
    pub offset_cm: f64,
    /// Seed of the ChaCha8 generator.
    pub seed: u64,
}

impl Default for SynthOptions {
    fn default() -> Self {
        SynthOptions {
            noise_mm: 2.0,
            gap_probability: 0.005,
            offset_cm: 6.0,
            seed: 9,
        }
    }
}

/// One segment of the generated assignment map.
#[derive(Debug, Clone, PartialEq)]
pub struct SynthSegment {
    /// Segment name (the clip joint that carries its rotation).
    pub name: String,
    /// Parent segment index (`None` for the root).
    pub parent: Option<usize>,
    /// Marker names on the segment.
    pub markers: Vec<String>,
    /// Index of the FK point ([`motion::fk::positions`]) at the segment's centre of rotation
    /// (`None` for the root, which has none).
    pub truth_point: Option<usize>,
    /// True when the joint has exactly one rotation channel (a hinge).
    pub hinge: bool,
}

/// A synthetic capture and its ground truth.
#[derive(Debug, Clone)]
pub struct SynthCapture {
    /// The noisy markers (mm).
    pub markers: MarkerSet,
    /// Noise-free marker positions (mm), same shape as `markers`, without gaps.
    pub exact: MarkerSet,
    /// Segments of the assignment map, root first, parents before children.
    pub segments: Vec<SynthSegment>,
    /// FK points of the clip per frame, in mm: `truth_mm[frame][point]`.
    pub truth_mm: Vec<Vec<Vec3>>,
}

const FRACTIONS: [f64; 3] = [0.35, 0.6, 0.85];

/// Offsets (joint frame, file units) of the three markers on joint `j`.
fn marker_offsets(bone: Vec3, offset_units: f64) -> [Vec3; 3] {
    let len = norm(&bone);
    if len < 1e-9 {
        // No bone (a root): three non-collinear points about the joint.
        return [
            [offset_units, 0.0, 0.0],
            [0.0, offset_units, 0.0],
            [0.0, 0.0, offset_units],
        ];
    }
    let b = [bone[0] / len, bone[1] / len, bone[2] / len];
    // u ⟂ b from the coordinate axis least aligned with b; w = b × u.
    let k = (0..3)
        .min_by(|&i, &j| b[i].abs().total_cmp(&b[j].abs()))
        .unwrap_or(0);
    let mut e = [0.0; 3];
    e[k] = 1.0;
    let cross = |a: Vec3, c: Vec3| {
        [
            a[1] * c[2] - a[2] * c[1],
            a[2] * c[0] - a[0] * c[2],
            a[0] * c[1] - a[1] * c[0],
        ]
    };
    let u = cross(b, e);
    let un = norm(&u);
    let u = [u[0] / un, u[1] / un, u[2] / un];
    let w = cross(b, u);
    let mut out = [[0.0; 3]; 3];
    for (i, o) in out.iter_mut().enumerate() {
        let t = (i as f64) * std::f64::consts::TAU / 3.0;
        let (s, c) = t.sin_cos();
        for a in 0..3 {
            o[a] = FRACTIONS[i] * bone[a] + offset_units * (c * u[a] + s * w[a]);
        }
    }
    out
}

/// One placed marker: rigid with a joint's frame.
#[derive(Debug, Clone, PartialEq)]
pub struct PlacedMarker {
    /// Marker name, `<joint>_1..3`.
    pub name: String,
    /// Joint whose world rotation carries the marker.
    pub joint: usize,
    /// FK point the offset starts from: the bone's start (the parent's point) for ASF, the
    /// joint's own point for BVH.
    pub anchor_point: usize,
    /// Offset in the joint's frame, file units.
    pub offset: Vec3,
}

/// Where [`synth_capture`] and [`rom_capture`] put the markers on a skeleton, and the
/// segment map they make: a deterministic function of the skeleton and the offset.
#[derive(Debug, Clone, PartialEq)]
pub struct MarkerPlacement {
    /// Markers in column order: three per joint that is not an end site, skeleton order.
    pub markers: Vec<PlacedMarker>,
    /// Segments of the assignment map, root first, parents before children.
    pub segments: Vec<SynthSegment>,
}

impl MarkerPlacement {
    /// Places three markers on every bone of `skeleton`, `offset_cm` from its line.
    ///
    /// # Errors
    /// [`MarkerError::Solve`] when the offset is not a positive finite number of cm.
    pub fn new(skeleton: &Skeleton, offset_cm: f64) -> Result<MarkerPlacement, MarkerError> {
        if !(offset_cm.is_finite() && offset_cm > 0.0) {
            return Err(MarkerError::Solve {
                segment: skeleton.name.clone(),
                reason: "marker offset must be a positive number of cm".into(),
            });
        }
        let offset_units = offset_cm / skeleton.units.cm_per_unit;
        let mut markers = Vec::new();
        for (j, joint) in skeleton.joints.iter().enumerate() {
            if joint.end_site {
                continue;
            }
            let bone = match skeleton.format {
                SkeletonFormat::Asf if joint.parent.is_some() => joint.rest.vector(),
                SkeletonFormat::Asf => [0.0; 3],
                SkeletonFormat::Bvh => skeleton
                    .children(j)
                    .map(|c| skeleton.joints[c].rest.vector())
                    .max_by(|a, b| norm(a).total_cmp(&norm(b)))
                    .unwrap_or([0.0; 3]),
            };
            let anchor_point = match (skeleton.format, joint.parent) {
                (SkeletonFormat::Asf, Some(p)) => p,
                _ => j,
            };
            for (k, offset) in marker_offsets(bone, offset_units).into_iter().enumerate() {
                markers.push(PlacedMarker {
                    name: format!("{}_{}", joint.name, k + 1),
                    joint: j,
                    anchor_point,
                    offset,
                });
            }
        }
        Ok(MarkerPlacement {
            markers,
            segments: segments_of(skeleton),
        })
    }

    /// Marker names in column order.
    pub fn names(&self) -> Vec<String> {
        self.markers.iter().map(|m| m.name.clone()).collect()
    }
}

/// The segments of the assignment map: one per joint with rotation channels (and the root);
/// a joint without them rides on its parent's segment.
fn segments_of(sk: &Skeleton) -> Vec<SynthSegment> {
    let mut segment_of = vec![0usize; sk.joints.len()];
    let mut segments: Vec<SynthSegment> = Vec::new();
    for (j, joint) in sk.joints.iter().enumerate() {
        if joint.end_site {
            segment_of[j] = joint.parent.map_or(0, |p| segment_of[p]);
            continue;
        }
        let names: Vec<String> = (1..=3).map(|k| format!("{}_{k}", joint.name)).collect();
        let rotations = joint.dofs.iter().filter(|d| d.is_rotation()).count();
        match joint.parent {
            Some(p) if rotations > 0 => {
                segment_of[j] = segments.len();
                segments.push(SynthSegment {
                    name: joint.name.clone(),
                    parent: Some(segment_of[p]),
                    markers: names,
                    truth_point: Some(match sk.format {
                        SkeletonFormat::Asf => p,
                        SkeletonFormat::Bvh => j,
                    }),
                    hinge: rotations == 1,
                });
            }
            Some(p) => {
                segment_of[j] = segment_of[p];
                segments[segment_of[p]].markers.extend(names);
            }
            None => {
                segment_of[j] = segments.len();
                segments.push(SynthSegment {
                    name: joint.name.clone(),
                    parent: None,
                    markers: names,
                    truth_point: None,
                    hinge: false,
                });
            }
        }
    }
    segments
}

/// The assignment file (TOML) for the markers [`synth_capture`] puts on `clip`.
pub fn segment_map_toml(clip: &Clip) -> String {
    let segments = segments_of(&clip.skeleton);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Segments of the `{}` skeleton for markers from `study markers synth`:\n\
         # three markers per bone named <bone>_1..3; bones without rotation channels ride on\n\
         # their parent's segment.",
        clip.skeleton.name
    );
    for seg in &segments {
        s.push_str("\n[[segment]]\n");
        let _ = writeln!(s, "name = {:?}", seg.name);
        if let Some(p) = seg.parent {
            let _ = writeln!(s, "parent = {:?}", segments[p].name);
        }
        if seg.hinge {
            s.push_str("joint = \"hinge\"\n");
        }
        let quoted: Vec<String> = seg.markers.iter().map(|m| format!("{m:?}")).collect();
        let _ = writeln!(s, "markers = [{}]", quoted.join(", "));
    }
    s
}

/// Standard normal deviate by the Box-Muller transform.
fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// The ChaCha8 stream of a motion trial's noise.
const MOTION_STREAM: u64 = 0;
/// The ChaCha8 stream of a range-of-motion trial's noise (same seed, independent noise).
const ROM_STREAM: u64 = 1;

/// Generates markers on every bone of `clip` (see the module docs), in mm.
///
/// # Errors
/// [`MarkerError::Solve`] when the options are not finite and non-negative or the gap
/// probability is not below 1.
pub fn synth_capture(clip: &Clip, options: &SynthOptions) -> Result<SynthCapture, MarkerError> {
    let placement = MarkerPlacement::new(&clip.skeleton, options.offset_cm)?;
    capture_with(clip, &placement, options, MOTION_STREAM)
}

fn capture_with(
    clip: &Clip,
    placement: &MarkerPlacement,
    options: &SynthOptions,
    stream: u64,
) -> Result<SynthCapture, MarkerError> {
    let bad = |reason: &str| MarkerError::Solve {
        segment: clip.skeleton.name.clone(),
        reason: reason.to_string(),
    };
    if !(options.noise_mm.is_finite() && options.noise_mm >= 0.0) {
        return Err(bad("noise σ must be a finite non-negative number of mm"));
    }
    if !(options.gap_probability >= 0.0 && options.gap_probability < 1.0) {
        return Err(bad("gap probability must be in [0, 1)"));
    }
    let sk = &clip.skeleton;
    if placement
        .markers
        .iter()
        .any(|m| m.joint >= sk.joints.len() || m.anchor_point >= sk.joints.len())
    {
        return Err(bad("the marker placement is for another skeleton"));
    }
    let mm_per_unit = sk.units.cm_per_unit * 10.0;
    let names = placement.names();
    let frames = clip.frames();
    let mut exact = MarkerSet::new(names.clone(), frames, clip.frame_rate_hz);
    let mut markers = MarkerSet::new(names, frames, clip.frame_rate_hz);
    let kin = Kinematics::new(sk);
    let mut values = Vec::with_capacity(clip.channel_count());
    let mut local = Vec::new();
    let mut points = Vec::new();
    let mut rotations = Vec::new();
    let mut truth_mm = Vec::with_capacity(frames);
    let mut rng = ChaCha8Rng::seed_from_u64(options.seed);
    rng.set_stream(stream);
    for f in 0..frames {
        clip.frame_into(f, &mut values);
        kin.local_transforms(&values, &mut local);
        kin.world(&local, &mut points, &mut rotations);
        for (m, pm) in placement.markers.iter().enumerate() {
            let p = add(
                &points[pm.anchor_point],
                &mul_vec(&rotations[pm.joint], &pm.offset),
            )
            .map(|v| v * mm_per_unit);
            exact.set(f, m, Some(p));
            let noisy = [
                p[0] + options.noise_mm * gaussian(&mut rng),
                p[1] + options.noise_mm * gaussian(&mut rng),
                p[2] + options.noise_mm * gaussian(&mut rng),
            ];
            let gap = rng.random::<f64>() < options.gap_probability;
            markers.set(f, m, (!gap).then_some(noisy));
        }
        truth_mm.push(points.iter().map(|p| p.map(|v| v * mm_per_unit)).collect());
    }
    Ok(SynthCapture {
        markers,
        exact,
        segments: placement.segments.clone(),
        truth_mm,
    })
}

fn norm(v: &Vec3) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}

/// The pose a range-of-motion trial starts from and returns to between swings.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum RomBase {
    /// The motion clip's first frame (the subject stands as in the motion trial).
    #[default]
    FirstFrame,
    /// Every channel zero: the skeleton's rest pose, at the origin.
    Rest,
}

/// Options of a range-of-motion (functional calibration) trial; see [`rom_clip`].
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RomOptions {
    /// Swing each side of the base pose on every rotation axis, degrees (less where the
    /// skeleton's joint limits stop it).
    pub amplitude_deg: f64,
    /// Duration of one axis's swing (one sine period: out to one side, through the base
    /// pose to the other side and back), seconds.
    pub seconds_per_axis: f64,
    /// Base pose.
    pub base: RomBase,
    /// Cut the swings at the skeleton's joint limits (ASF `limits`) where it has them.
    pub respect_limits: bool,
}

impl Default for RomOptions {
    fn default() -> Self {
        RomOptions {
            amplitude_deg: 40.0,
            seconds_per_axis: 2.0,
            base: RomBase::FirstFrame,
            respect_limits: true,
        }
    }
}

/// The order in which a range-of-motion trial exercises the joints: groups of joints that
/// swing at the same time, each joint with rotation channels (not the root) in exactly one
/// group. Joints are taken in skeleton order and put into the first group that holds none
/// of their ancestors or descendants, so that while a joint swings its parent segment holds
/// still (a clean arc of the joint alone, as a lab's calibration protocol asks of the
/// subject), and far-apart joints (the two hips, a knee and an elbow) share the time.
pub fn rom_groups(skeleton: &Skeleton) -> Vec<Vec<usize>> {
    let related = |a: usize, b: usize| {
        let is_ancestor = |anc: usize, mut j: usize| {
            while let Some(p) = skeleton.joints[j].parent {
                if p == anc {
                    return true;
                }
                j = p;
            }
            false
        };
        a == b || is_ancestor(a, b) || is_ancestor(b, a)
    };
    let mut groups: Vec<Vec<usize>> = Vec::new();
    for (j, joint) in skeleton.joints.iter().enumerate() {
        if joint.parent.is_none() || !joint.dofs.iter().any(|d| d.is_rotation()) {
            continue;
        }
        match groups
            .iter_mut()
            .find(|g| g.iter().all(|&k| !related(j, k)))
        {
            Some(g) => g.push(j),
            None => groups.push(vec![j]),
        }
    }
    groups
}

/// A range-of-motion (functional calibration) trial of `clip`'s skeleton: from the base pose
/// the joints of each of [`rom_groups`] in turn swing through their range, one rotation
/// channel after another (a sine period of `seconds_per_axis` on that channel alone, so a
/// hinge moves only about its axis), while every other channel, the root's included, holds
/// the base pose. The swing is `amplitude_deg` each side, cut (with `respect_limits`) at the
/// joint's limits where the skeleton has them (ASF `limits`; a base value already past a
/// limit is kept, and that side does not swing). Same skeleton and frame rate as `clip`.
///
/// # Errors
/// [`MarkerError::Solve`] when the amplitude or the duration is not a positive finite number,
/// the clip has no frame to take the base pose from, or the trial would exceed 10⁷ frames.
pub fn rom_clip(clip: &Clip, options: &RomOptions) -> Result<Clip, MarkerError> {
    let sk = &clip.skeleton;
    let bad = |reason: String| MarkerError::Solve {
        segment: sk.name.clone(),
        reason,
    };
    if !(options.amplitude_deg.is_finite() && options.amplitude_deg > 0.0) {
        return Err(bad(
            "range-of-motion amplitude must be a positive number of degrees".into(),
        ));
    }
    if !(options.seconds_per_axis.is_finite() && options.seconds_per_axis > 0.0) {
        return Err(bad(
            "range-of-motion swing must last a positive number of seconds".into(),
        ));
    }
    let per_axis = (options.seconds_per_axis * clip.frame_rate_hz).round();
    if !(4.0..=1e7).contains(&per_axis) {
        return Err(bad(format!(
            "a swing of {} s at {} Hz is {per_axis} frames, not between 4 and 10⁷",
            options.seconds_per_axis, clip.frame_rate_hz
        )));
    }
    let per_axis = per_axis as usize;
    let channels = clip.channels();
    let mut base = vec![0.0; channels.len()];
    if options.base == RomBase::FirstFrame {
        if clip.frames() == 0 {
            return Err(bad(
                "the clip has no frame to take the base pose from".into()
            ));
        }
        clip.frame_into(0, &mut base);
    }
    // Rotation channels of each joint, with the range of their swing.
    let swings = |j: usize| -> Vec<(usize, f64, f64)> {
        let joint = &sk.joints[j];
        let limits = (options.respect_limits && joint.limits.len() == joint.dofs.len())
            .then_some(&joint.limits);
        channels
            .iter()
            .enumerate()
            .filter(|(_, ch)| ch.joint == j && ch.kind.is_rotation())
            .map(|(c, ch)| {
                let b = base[c];
                let (mut lo, mut hi) = (b - options.amplitude_deg, b + options.amplitude_deg);
                let dof = joint.dofs.iter().position(|d| *d == ch.kind);
                if let (Some(l), Some(d)) = (limits, dof) {
                    let (a, z) = l[d];
                    lo = lo.max(a.min(z)).min(b);
                    hi = hi.min(a.max(z)).max(b);
                }
                (c, lo - b, hi - b)
            })
            .collect()
    };
    let groups = rom_groups(sk);
    let plan: Vec<Vec<Vec<(usize, f64, f64)>>> = groups
        .iter()
        .map(|g| g.iter().map(|&j| swings(j)).collect())
        .collect();
    let frames: usize = plan
        .iter()
        .map(|g| g.iter().map(Vec::len).max().unwrap_or(0) * per_axis)
        .sum();
    if frames == 0 || frames > 10_000_000 {
        return Err(bad(format!(
            "a range-of-motion trial of {frames} frames (no joint to exercise, or over 10⁷)"
        )));
    }
    let mut data = Vec::with_capacity(channels.len() * frames);
    for &b in &base {
        data.extend(std::iter::repeat_n(b, frames));
    }
    let mut start = 0;
    for group in &plan {
        let len = group.iter().map(Vec::len).max().unwrap_or(0) * per_axis;
        for joint in group {
            for (axis, &(c, down, up)) in joint.iter().enumerate() {
                for i in 0..per_axis {
                    let s = (std::f64::consts::TAU * i as f64 / per_axis as f64).sin();
                    let f = start + axis * per_axis + i;
                    data[c * frames + f] += if s >= 0.0 { s * up } else { -s * down };
                }
            }
        }
        start += len;
    }
    clip.with_data(frames, data)
        .map_err(|e| bad(format!("cannot build the range-of-motion clip: {e}")))
}

/// Markers of a range-of-motion trial of `clip` ([`rom_clip`]): the same placement as
/// [`synth_capture`] with the same `synth` options gives the motion trial (same names, same
/// rigid offsets), with noise and gaps from another stream of the same seed.
///
/// # Errors
/// As [`rom_clip`] and [`synth_capture`].
pub fn rom_capture(
    clip: &Clip,
    rom: &RomOptions,
    synth: &SynthOptions,
) -> Result<SynthCapture, MarkerError> {
    let trial = rom_clip(clip, rom)?;
    let placement = MarkerPlacement::new(&clip.skeleton, synth.offset_cm)?;
    capture_with(&trial, &placement, synth, ROM_STREAM)
}
