//! A procedurally generated walking figure for the built-in demo and for tests that must run
//! without the shared clips.
//!
//! The skeleton is an ASF skeleton with CMU bone names and CMU-like proportions (units of
//! 1/0.45 inch), 25 joints and 47 channels; the motion is a periodic gait: hips, knees and
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

fn rx() -> ChannelKind {
    ChannelKind::Rotation(Axis::X)
}
fn ry() -> ChannelKind {
    ChannelKind::Rotation(Axis::Y)
}
fn rz() -> ChannelKind {
    ChannelKind::Rotation(Axis::Z)
}

fn bone(name: &str, parent: usize, dir: [f64; 3], length: f64, dofs: Vec<ChannelKind>) -> Joint {
    let n = (dir[0] * dir[0] + dir[1] * dir[1] + dir[2] * dir[2]).sqrt();
    Joint {
        name: name.into(),
        parent: Some(parent),
        rest: Rest::Bone {
            direction: dir.map(|d| d / n),
            length,
        },
        dofs,
        axis_deg: [0.0; 3],
        axis_order: [Axis::X, Axis::Y, Axis::Z],
        limits: Vec::new(),
        id: None,
        end_site: false,
        body_part: BodyPart::Torso,
        chain_depth: 0,
    }
}

/// The generated skeleton (CMU bone names, ASF conventions).
pub fn walker_skeleton() -> Skeleton {
    let t = ChannelKind::Translation;
    let mut joints = vec![Joint {
        name: "root".into(),
        parent: None,
        rest: Rest::Offset([0.0; 3]),
        dofs: vec![t(Axis::X), t(Axis::Y), t(Axis::Z), rx(), ry(), rz()],
        axis_deg: [0.0; 3],
        axis_order: [Axis::X, Axis::Y, Axis::Z],
        limits: Vec::new(),
        id: None,
        end_site: false,
        body_part: BodyPart::Torso,
        chain_depth: 0,
    }];
    let mut add = |j: Joint| {
        joints.push(j);
        joints.len() - 1
    };
    for (side, s) in [("l", 1.0), ("r", -1.0)] {
        let hip = add(bone(
            &format!("{side}hipjoint"),
            0,
            [0.73 * s, -0.56, 0.39],
            2.8,
            vec![],
        ));
        let femur = add(bone(
            &format!("{side}femur"),
            hip,
            [0.2 * s, -1.0, 0.0],
            7.2,
            vec![rx(), ry(), rz()],
        ));
        let tibia = add(bone(
            &format!("{side}tibia"),
            femur,
            [0.1 * s, -1.0, 0.0],
            7.4,
            vec![rx()],
        ));
        let foot = add(bone(
            &format!("{side}foot"),
            tibia,
            [0.0, -0.3, 1.0],
            2.0,
            vec![rx(), rz()],
        ));
        add(bone(
            &format!("{side}toes"),
            foot,
            [0.0, 0.0, 1.0],
            1.0,
            vec![rx()],
        ));
    }
    let lowerback = add(bone(
        "lowerback",
        0,
        [0.0, 1.0, -0.05],
        2.1,
        vec![rx(), ry(), rz()],
    ));
    let upperback = add(bone(
        "upperback",
        lowerback,
        [0.0, 1.0, 0.0],
        2.1,
        vec![rx(), ry(), rz()],
    ));
    let thorax = add(bone(
        "thorax",
        upperback,
        [0.0, 1.0, 0.0],
        2.1,
        vec![rx(), ry(), rz()],
    ));
    let neck = add(bone(
        "lowerneck",
        thorax,
        [0.0, 1.0, 0.05],
        1.7,
        vec![rx(), ry(), rz()],
    ));
    add(bone(
        "head",
        neck,
        [0.0, 1.0, 0.0],
        1.9,
        vec![rx(), ry(), rz()],
    ));
    for (side, s) in [("l", 1.0), ("r", -1.0)] {
        let clav = add(bone(
            &format!("{side}clavicle"),
            thorax,
            [s, 0.25, 0.0],
            3.4,
            vec![ry(), rz()],
        ));
        let hum = add(bone(
            &format!("{side}humerus"),
            clav,
            [s, 0.0, 0.0],
            5.2,
            vec![rx(), ry(), rz()],
        ));
        let rad = add(bone(
            &format!("{side}radius"),
            hum,
            [s, 0.0, 0.0],
            3.6,
            vec![ry()],
        ));
        add(bone(
            &format!("{side}hand"),
            rad,
            [s, 0.0, 0.0],
            1.6,
            vec![rz()],
        ));
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
