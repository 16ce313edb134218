//! Synthetic marker captures with ground truth: three markers rigidly offset on every bone of
//! a known clip, moved by its forward kinematics, with Gaussian noise σ and occasional gaps.
//!
//! For an ASF clip a bone's markers sit around the bone (start at its parent's point, world
//! rotation `R_bone`), at 35 %, 60 % and 85 % of its length and `offset_cm` out from its line
//! at 0°, 120° and 240° about it; for a BVH clip the same around the joint's longest child
//! offset. A joint without rotation channels moves rigidly with its parent, so
//! [`segment_map_toml`] merges its markers into the parent's segment. Every segment's true
//! joint centre is an FK point of the clip ([`SynthSegment::truth_point`]).

use std::fmt::Write as _;

use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::MarkerError;
use super::data::MarkerSet;
use crate::clip::{Clip, SkeletonFormat};
use crate::fk::Kinematics;
use crate::math::{Vec3, add, mul_vec};

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
    /// Index of the FK point ([`crate::fk::positions`]) at the segment's centre of rotation
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
    let len = (bone[0] * bone[0] + bone[1] * bone[1] + bone[2] * bone[2]).sqrt();
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
    let un = (u[0] * u[0] + u[1] * u[1] + u[2] * u[2]).sqrt();
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

/// Which joints carry markers, the marker names, and each joint's segment.
struct Layout {
    /// Joints with markers, in skeleton order.
    carriers: Vec<usize>,
    /// Segment index of each joint.
    segment_of: Vec<usize>,
    segments: Vec<SynthSegment>,
}

fn layout(clip: &Clip) -> Layout {
    let sk = &clip.skeleton;
    let mut carriers = Vec::new();
    let mut segment_of = vec![0usize; sk.joints.len()];
    let mut segments: Vec<SynthSegment> = Vec::new();
    for (j, joint) in sk.joints.iter().enumerate() {
        if joint.end_site {
            segment_of[j] = joint.parent.map_or(0, |p| segment_of[p]);
            continue;
        }
        carriers.push(j);
        let names: Vec<String> = (1..=3).map(|k| format!("{}_{k}", joint.name)).collect();
        let rotations = joint.dofs.iter().filter(|d| d.is_rotation()).count();
        let rotates = rotations > 0;
        match joint.parent {
            Some(p) if rotates => {
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
    Layout {
        carriers,
        segment_of,
        segments,
    }
}

/// The assignment file (TOML) for the markers [`synth_capture`] puts on `clip`.
pub fn segment_map_toml(clip: &Clip) -> String {
    let lay = layout(clip);
    let mut s = String::new();
    let _ = writeln!(
        s,
        "# Segments of the `{}` skeleton for markers from `study markers synth`:\n\
         # three markers per bone named <bone>_1..3; bones without rotation channels ride on\n\
         # their parent's segment.",
        clip.skeleton.name
    );
    for seg in &lay.segments {
        s.push_str("\n[[segment]]\n");
        let _ = writeln!(s, "name = {:?}", seg.name);
        if let Some(p) = seg.parent {
            let _ = writeln!(s, "parent = {:?}", lay.segments[p].name);
        }
        if seg.hinge {
            s.push_str("joint = \"hinge\"\n");
        }
        let quoted: Vec<String> = seg.markers.iter().map(|m| format!("{m:?}")).collect();
        let _ = writeln!(s, "markers = [{}]", quoted.join(", "));
    }
    debug_assert!(lay.segment_of.len() == clip.skeleton.joints.len());
    s
}

/// Standard normal deviate by the Box-Muller transform.
fn gaussian(rng: &mut ChaCha8Rng) -> f64 {
    let u1: f64 = 1.0 - rng.random::<f64>();
    let u2: f64 = rng.random::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

/// Generates markers on every bone of `clip` (see the module docs), in mm.
///
/// # Errors
/// [`MarkerError::Solve`] when the options are not finite and non-negative or the gap
/// probability is not below 1.
pub fn synth_capture(clip: &Clip, options: &SynthOptions) -> Result<SynthCapture, MarkerError> {
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
    if !(options.offset_cm.is_finite() && options.offset_cm > 0.0) {
        return Err(bad("marker offset must be a positive number of cm"));
    }
    let sk = &clip.skeleton;
    let mm_per_unit = sk.units.cm_per_unit * 10.0;
    let offset_units = options.offset_cm / sk.units.cm_per_unit;
    let lay = layout(clip);
    // Each carrier's marker offsets in its joint frame.
    let offsets: Vec<[Vec3; 3]> = lay
        .carriers
        .iter()
        .map(|&j| {
            let bone = match sk.format {
                SkeletonFormat::Asf if sk.joints[j].parent.is_some() => sk.joints[j].rest.vector(),
                SkeletonFormat::Asf => [0.0; 3],
                SkeletonFormat::Bvh => sk
                    .children(j)
                    .map(|c| sk.joints[c].rest.vector())
                    .max_by(|a, b| norm(a).total_cmp(&norm(b)))
                    .unwrap_or([0.0; 3]),
            };
            marker_offsets(bone, offset_units)
        })
        .collect();
    let names: Vec<String> = lay
        .carriers
        .iter()
        .flat_map(|&j| (1..=3).map(move |k| format!("{}_{k}", sk.joints[j].name)))
        .collect();
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
    for f in 0..frames {
        clip.frame_into(f, &mut values);
        kin.local_transforms(&values, &mut local);
        kin.world(&local, &mut points, &mut rotations);
        for (c, &j) in lay.carriers.iter().enumerate() {
            let anchor = match (sk.format, sk.joints[j].parent) {
                (SkeletonFormat::Asf, Some(p)) => points[p],
                _ => points[j],
            };
            for (k, off) in offsets[c].iter().enumerate() {
                let p = add(&anchor, &mul_vec(&rotations[j], off)).map(|v| v * mm_per_unit);
                let m = 3 * c + k;
                exact.set(f, m, Some(p));
                let noisy = [
                    p[0] + options.noise_mm * gaussian(&mut rng),
                    p[1] + options.noise_mm * gaussian(&mut rng),
                    p[2] + options.noise_mm * gaussian(&mut rng),
                ];
                let gap = rng.random::<f64>() < options.gap_probability;
                markers.set(f, m, (!gap).then_some(noisy));
            }
        }
        truth_mm.push(points.iter().map(|p| p.map(|v| v * mm_per_unit)).collect());
    }
    Ok(SynthCapture {
        markers,
        exact,
        segments: lay.segments,
        truth_mm,
    })
}

fn norm(v: &Vec3) -> f64 {
    (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt()
}
