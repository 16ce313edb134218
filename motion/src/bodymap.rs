//! Which kinematic chain each joint belongs to, and a BVH file's length unit.
//!
//! The perceptual codecs weight channels by body part (thesis ch. 6: legs 1, arms, torso and
//! head 0.5) and by depth within a chain (eq. 6.2). Joints are classified by name first: CMU
//! ASF names (`lfemur`, `rclavicle`, `lowerneck`, ...) and common BVH names (`Hips`, `Spine`,
//! `LeftUpLeg`, `RightForeArm`, `LHipJoint`, ...). When any joint's name is not recognised, the
//! whole skeleton is classified by topology instead: subtrees of the root that hang below it are
//! legs, the one that rises is the spine; at the spine's branching joint the highest subtree is
//! the head and the others are arms. Sides follow the sign of x (CMU and BVH: +x is the
//! subject's left) and y is up.

use crate::clip::{BodyPart, Skeleton, Units};
use crate::math::{Vec3, add};

const LEG: &[&str] = &[
    "hip", "upleg", "upperleg", "thigh", "femur", "knee", "leg", "tibia", "shin", "calf", "ankle",
    "foot", "toe", "heel",
];
const ARM: &[&str] = &[
    "clavicle", "collar", "shoulder", "scapula", "humerus", "arm", "elbow", "radius", "ulna",
    "wrist", "hand", "finger", "thumb", "index", "middle", "ring", "pinky",
];
const HEAD: &[&str] = &["neck", "head", "skull", "jaw", "eye", "nose"];
const TORSO: &[&str] = &[
    "hips", "pelvis", "root", "spine", "chest", "back", "thorax", "abdomen", "waist", "torso",
];

#[derive(Clone, Copy, PartialEq)]
enum Side {
    Left,
    Right,
}

fn has(s: &str, words: &[&str]) -> bool {
    words.iter().any(|w| s.contains(w))
}

fn starts(s: &str, words: &[&str]) -> bool {
    words.iter().any(|w| s.starts_with(w))
}

/// Classifies one joint name, or `None` when the name says nothing known.
pub fn part_from_name(name: &str) -> Option<BodyPart> {
    let mut n: String = name.chars().filter(char::is_ascii_alphanumeric).collect();
    n.make_ascii_lowercase();
    for prefix in ["mixamorig", "bip01", "bip001", "character1"] {
        if let Some(rest) = n.strip_prefix(prefix) {
            n = rest.to_string();
        }
    }
    let limb = |rest: &str| starts(rest, LEG) || starts(rest, ARM);
    let side = if let Some(rest) = n.strip_prefix("left") {
        Some((Side::Left, rest.to_string()))
    } else if let Some(rest) = n.strip_prefix("right") {
        Some((Side::Right, rest.to_string()))
    } else if n.contains("left") {
        Some((Side::Left, n.clone()))
    } else if n.contains("right") {
        Some((Side::Right, n.clone()))
    } else if n.len() > 1 && n.starts_with('l') && limb(&n[1..]) {
        Some((Side::Left, n[1..].to_string()))
    } else if n.len() > 1 && n.starts_with('r') && limb(&n[1..]) {
        Some((Side::Right, n[1..].to_string()))
    } else {
        None
    };
    if let Some((side, rest)) = side {
        // Check arms before legs: "forearm" and "upperarm" say arm, while leg words such as
        // "leg" never occur in arm names.
        let leg = has(&rest, LEG) && !has(&rest, &["arm", "hand", "finger", "thumb"]);
        if leg {
            return Some(if side == Side::Left {
                BodyPart::LeftLeg
            } else {
                BodyPart::RightLeg
            });
        }
        if has(&rest, ARM) {
            return Some(if side == Side::Left {
                BodyPart::LeftArm
            } else {
                BodyPart::RightArm
            });
        }
        if has(&rest, HEAD) {
            return Some(BodyPart::Head);
        }
        return None;
    }
    if has(&n, HEAD) {
        return Some(BodyPart::Head);
    }
    if has(&n, TORSO) {
        return Some(BodyPart::Torso);
    }
    None
}

/// Rest-pose points of every joint in file units (the pose with all channels zero).
pub fn rest_points(skeleton: &Skeleton) -> Vec<Vec3> {
    let mut pts: Vec<Vec3> = Vec::with_capacity(skeleton.joints.len());
    for j in &skeleton.joints {
        let base = j.parent.map_or([0.0; 3], |p| pts[p]);
        let v = j.rest.vector();
        pts.push(add(&base, &v));
    }
    pts
}

/// Sets `body_part` and `chain_depth` of every joint (by name, else by topology).
pub fn assign(skeleton: &mut Skeleton) {
    let n = skeleton.joints.len();
    let mut parts: Vec<Option<BodyPart>> = Vec::with_capacity(n);
    for j in &skeleton.joints {
        let part = if j.parent.is_none() {
            Some(BodyPart::Torso)
        } else if j.end_site {
            // End sites belong to their parent's chain.
            j.parent.and_then(|p| parts[p])
        } else {
            part_from_name(&j.name)
        };
        parts.push(part);
    }
    let parts: Vec<BodyPart> = if parts.iter().all(Option::is_some) {
        parts
            .into_iter()
            .map(|p| p.unwrap_or(BodyPart::Torso))
            .collect()
    } else {
        by_topology(skeleton)
    };
    for i in 0..n {
        let depth = match skeleton.joints[i].parent {
            Some(p) if parts[p] == parts[i] => skeleton.joints[p].chain_depth + 1,
            _ => 0,
        };
        skeleton.joints[i].body_part = parts[i];
        skeleton.joints[i].chain_depth = depth;
    }
}

fn subtree(skeleton: &Skeleton, top: usize) -> Vec<usize> {
    let mut out = vec![top];
    let mut k = 0;
    while k < out.len() {
        let i = out[k];
        out.extend(skeleton.children(i));
        k += 1;
    }
    out
}

fn mean_point(pts: &[Vec3], idx: &[usize]) -> Vec3 {
    let mut m = [0.0; 3];
    for &i in idx {
        for a in 0..3 {
            m[a] += pts[i][a] / idx.len() as f64;
        }
    }
    m
}

fn by_topology(skeleton: &Skeleton) -> Vec<BodyPart> {
    let pts = rest_points(skeleton);
    let mut parts = vec![BodyPart::Torso; skeleton.joints.len()];
    let root_y = pts[0][1];
    let mut spine = None;
    let mut best_rise = f64::NEG_INFINITY;
    for c in skeleton.children(0).collect::<Vec<_>>() {
        let sub = subtree(skeleton, c);
        let m = mean_point(&pts, &sub);
        if m[1] < root_y {
            let part = if m[0] >= pts[0][0] {
                BodyPart::LeftLeg
            } else {
                BodyPart::RightLeg
            };
            for i in sub {
                parts[i] = part;
            }
        } else if m[1] - root_y > best_rise {
            best_rise = m[1] - root_y;
            spine = Some(c);
        }
    }
    // Walk up the spine to its first branching joint.
    let Some(mut s) = spine else { return parts };
    loop {
        let kids: Vec<usize> = skeleton.children(s).collect();
        if kids.len() == 1 {
            s = kids[0];
            continue;
        }
        if kids.len() < 2 {
            break;
        }
        let mut scored: Vec<(usize, Vec3)> = kids
            .iter()
            .map(|&k| (k, mean_point(&pts, &subtree(skeleton, k))))
            .collect();
        scored.sort_by(|a, b| b.1[1].total_cmp(&a.1[1]));
        for (rank, (k, m)) in scored.into_iter().enumerate() {
            let part = if rank == 0 {
                BodyPart::Head
            } else if m[0] >= pts[s][0] {
                BodyPart::LeftArm
            } else {
                BodyPart::RightArm
            };
            for i in subtree(skeleton, k) {
                parts[i] = part;
            }
        }
        break;
    }
    parts
}

/// Guesses a BVH file's length unit, which the format does not state.
///
/// The rest pose's height (feet to head, y up) is compared with a 170 cm person under each
/// candidate unit (centimetre, metre, millimetre, inch, and the CMU unit of 1/0.45 inch that
/// CMU's BVH conversions keep), and the closest is taken. `declared` is false so that reports
/// say the unit was inferred.
pub fn infer_bvh_units(skeleton: &Skeleton) -> Units {
    let pts = rest_points(skeleton);
    let (lo, hi) = pts
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), p| {
            (l.min(p[1]), h.max(p[1]))
        });
    let height = hi - lo;
    let mut best = 1.0;
    if height.is_finite() && height > 0.0 {
        let mut err = f64::INFINITY;
        for cm in [1.0, 100.0, 0.1, 2.54, 2.54 / 0.45] {
            let e = (height * cm / 170.0).ln().abs();
            if e < err {
                err = e;
                best = cm;
            }
        }
    }
    Units {
        cm_per_unit: best,
        asf_length: 1.0,
        asf_mass: 1.0,
        declared: false,
    }
}
