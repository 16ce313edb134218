//! A procedurally generated walking figure for the built-in demo and for tests that must run
//! without the shared clips.
//!
//! The skeleton is an ASF skeleton with CMU bone names and CMU-like proportions (units of
//! 1/0.45 inch), 24 joints and 49 channels; the motion is a periodic gait: hips, knees and
//! ankles follow smooth phase-locked curves, arms swing against the legs, the spine twists and
//! the root moves forward with a vertical bob. It contains no captured data.

use std::f64::consts::TAU;

use crate::bodymap;
use crate::clip::{
    Axis, BodyPart, ChannelKind, Clip, Joint, Rest, Skeleton, SkeletonFormat, Units,
};

/// Parameters of the generated walk.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct WalkParams {
    /// Duration in seconds.
    pub duration_s: f64,
    /// Frame rate in Hz.
    pub frame_rate_hz: f64,
    /// Walking speed in cm/s.
    pub speed_cm_s: f64,
    /// Gait cycles (two steps) per second.
    pub cycle_hz: f64,
    /// Scales every joint amplitude (1 = a normal walk; larger is livelier).
    pub amplitude: f64,
}

impl Default for WalkParams {
    fn default() -> Self {
        WalkParams {
            duration_s: 4.0,
            frame_rate_hz: 120.0,
            speed_cm_s: 120.0,
            cycle_hz: 0.9,
            amplitude: 1.0,
        }
    }
}

const CM_PER_UNIT: f64 = 2.54 / 0.45;

/// One bone of the generated skeleton: name, parent, direction (left side; x is mirrored for
/// the right), length in units, rotation dofs.
struct BoneSpec {
    name: &'static str,
    parent: &'static str,
    dir: [f64; 3],
    length: f64,
    dofs: &'static str,
}

const fn spec(
    name: &'static str,
    parent: &'static str,
    dir: [f64; 3],
    length: f64,
    dofs: &'static str,
) -> BoneSpec {
    BoneSpec {
        name,
        parent,
        dir,
        length,
        dofs,
    }
}

/// Limb bones are listed once without their side letter; torso and head bones have none.
const LIMBS: [BoneSpec; 9] = [
    spec("hipjoint", "root", [0.73, -0.56, 0.39], 2.8, ""),
    spec("femur", "hipjoint", [0.2, -1.0, 0.0], 7.2, "xyz"),
    spec("tibia", "femur", [0.1, -1.0, 0.0], 7.4, "x"),
    spec("foot", "tibia", [0.0, -0.3, 1.0], 2.0, "xz"),
    spec("toes", "foot", [0.0, 0.0, 1.0], 1.0, "x"),
    spec("clavicle", "thorax", [1.0, 0.25, 0.0], 3.4, "yz"),
    spec("humerus", "clavicle", [1.0, 0.0, 0.0], 5.2, "xyz"),
    spec("radius", "humerus", [1.0, 0.0, 0.0], 3.6, "y"),
    spec("hand", "radius", [1.0, 0.0, 0.0], 1.6, "z"),
];
const SPINE: [BoneSpec; 5] = [
    spec("lowerback", "root", [0.0, 1.0, -0.05], 2.1, "xyz"),
    spec("upperback", "lowerback", [0.0, 1.0, 0.0], 2.1, "xyz"),
    spec("thorax", "upperback", [0.0, 1.0, 0.0], 2.1, "xyz"),
    spec("lowerneck", "thorax", [0.0, 1.0, 0.05], 1.7, "xyz"),
    spec("head", "lowerneck", [0.0, 1.0, 0.0], 1.9, "xyz"),
];

/// The generated skeleton (CMU bone names, ASF conventions): root, both legs, the spine to
/// the head, both arms, in that order.
pub fn walker_skeleton() -> Skeleton {
    let t = ChannelKind::Translation;
    let r = ChannelKind::Rotation;
    let root_dofs = vec![
        t(Axis::X),
        t(Axis::Y),
        t(Axis::Z),
        r(Axis::X),
        r(Axis::Y),
        r(Axis::Z),
    ];
    let mut joints = vec![Joint::new(
        "root".into(),
        None,
        Rest::Offset([0.0; 3]),
        root_dofs,
    )];
    let legs = &LIMBS[..5];
    let arms = &LIMBS[5..];
    let sides = [("l", 1.0), ("r", -1.0)];
    let groups: [(&[BoneSpec], bool); 3] = [(legs, true), (&SPINE, false), (arms, true)];
    for (specs, sided) in groups {
        for (side, mirror) in if sided { &sides[..] } else { &sides[..1] } {
            for b in specs {
                let prefix = if sided { *side } else { "" };
                let name = format!("{prefix}{}", b.name);
                let parent_name = if LIMBS.iter().any(|l| l.name == b.parent) {
                    format!("{prefix}{}", b.parent)
                } else {
                    b.parent.to_string()
                };
                let parent = joints.iter().position(|j| j.name == parent_name);
                let dir = [b.dir[0] * mirror, b.dir[1], b.dir[2]];
                let norm = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
                let rest = Rest::Bone {
                    direction: dir.map(|d| d / norm),
                    length: b.length,
                };
                let dofs = b
                    .dofs
                    .chars()
                    .filter_map(Axis::from_letter)
                    .map(r)
                    .collect();
                joints.push(Joint::new(name, parent, rest, dofs));
            }
        }
    }
    let mut skeleton = Skeleton {
        name: "synthetic-walker".into(),
        format: SkeletonFormat::Asf,
        units: Units {
            cm_per_unit: CM_PER_UNIT,
            asf_length: 0.45,
            asf_mass: 1.0,
            declared: true,
        },
        joints,
        documentation: vec!["procedurally generated walking figure (no captured data)".into()],
    };
    bodymap::assign(&mut skeleton);
    skeleton
}

/// Generates the walking clip.
///
/// Non-positive or non-finite durations and rates fall back to the defaults, so the result is
/// always a valid clip of at least two frames.
pub fn walking_clip(params: &WalkParams) -> Clip {
    let d = WalkParams::default();
    let ok = |v: f64, def: f64| if v.is_finite() && v > 0.0 { v } else { def };
    let rate = ok(params.frame_rate_hz, d.frame_rate_hz);
    let duration = ok(params.duration_s, d.duration_s).min(3600.0);
    let cycle = ok(params.cycle_hz, d.cycle_hz);
    let amp = if params.amplitude.is_finite() {
        params.amplitude
    } else {
        1.0
    };
    let speed = if params.speed_cm_s.is_finite() {
        params.speed_cm_s
    } else {
        d.speed_cm_s
    };
    let skeleton = walker_skeleton();
    let frames = ((duration * rate).round() as usize).max(2);
    let layout = skeleton.channel_layout();
    let mut data = vec![0.0; layout.len() * frames];
    for f in 0..frames {
        let t = f as f64 / rate;
        let ph = TAU * cycle * t;
        for (c, ch) in layout.iter().enumerate() {
            let j = &skeleton.joints[ch.joint];
            let limb = !matches!(j.body_part, BodyPart::Torso | BodyPart::Head);
            // Limb bones are `l...`/`r...`; match on the name without the side letter.
            let base = if limb {
                j.name.get(1..).unwrap_or("")
            } else {
                j.name.as_str()
            };
            let side = if limb && j.name.starts_with('r') {
                0.5
            } else {
                0.0
            };
            let p = ph + TAU * side; // right limbs half a cycle later
            let v = match (base, ch.kind) {
                _ if j.name == "root" => match ch.kind {
                    ChannelKind::Translation(Axis::X) => 0.4 * amp * ph.sin(),
                    ChannelKind::Translation(Axis::Y) => 16.6 + 0.18 * amp * (2.0 * ph).cos(),
                    ChannelKind::Translation(Axis::Z) => speed / CM_PER_UNIT * t,
                    ChannelKind::Rotation(Axis::X) => 3.0,
                    ChannelKind::Rotation(Axis::Y) => 6.0 * amp * ph.sin(),
                    ChannelKind::Rotation(Axis::Z) => 2.5 * amp * ph.cos(),
                },
                ("femur", ChannelKind::Rotation(Axis::X)) => -6.0 - 22.0 * amp * p.sin(),
                ("femur", ChannelKind::Rotation(Axis::Y)) => 3.0 * amp * p.cos(),
                ("femur", ChannelKind::Rotation(Axis::Z)) => 2.0 * amp * p.sin(),
                ("tibia", _) => 6.0 + 30.0 * amp * (0.5 + 0.5 * (p + 1.1).sin()).powi(2),
                ("foot", ChannelKind::Rotation(Axis::X)) => -8.0 * amp * (p + 0.6).sin(),
                ("toes", _) => 10.0 * amp * (0.5 + 0.5 * (p + 2.4).sin()).powi(3),
                ("humerus", ChannelKind::Rotation(Axis::Y)) => {
                    let s = if side == 0.0 { 1.0 } else { -1.0 };
                    s * 16.0 * amp * p.sin()
                }
                ("humerus", ChannelKind::Rotation(Axis::Z)) => {
                    if side == 0.0 {
                        -72.0
                    } else {
                        72.0
                    }
                }
                ("radius", _) => {
                    let s = if side == 0.0 { -1.0 } else { 1.0 };
                    s * (18.0 + 8.0 * amp * (p + 0.4).sin())
                }
                ("clavicle", ChannelKind::Rotation(Axis::Z)) => 2.0 * amp * (2.0 * p).sin(),
                ("lowerback", ChannelKind::Rotation(Axis::Y)) => -3.0 * amp * ph.sin(),
                ("thorax", ChannelKind::Rotation(Axis::Y)) => -4.0 * amp * ph.sin(),
                ("head", ChannelKind::Rotation(Axis::X)) => 2.0 * amp * (2.0 * ph).sin(),
                ("lowerneck", ChannelKind::Rotation(Axis::Y)) => 2.0 * amp * ph.sin(),
                _ => 0.0,
            };
            data[c * frames + f] = v;
        }
    }
    Clip::from_valid_parts(skeleton, rate, frames, data)
}
